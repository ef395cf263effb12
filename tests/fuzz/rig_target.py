"""Character rigs a user downloads as BVH (``--character rig.bvh``) and the bone maps (``--bone-map``, TOML)
that name a rig's bones: the ``character_bvh`` and ``character_bonemap`` fuzz targets (what they mutate and
what counts as sane: ``fuzz.character_target``'s docstring, whose checks they share).
"""

from __future__ import annotations

import json
import random
from pathlib import Path

from .character_target import HOSTILE_VALUES, CharacterTarget
from .harness import HOSTILE_NUMBERS, Case, mutate_bytes, rng_for


class BvhRigTarget(CharacterTarget):
    name = "character_bvh"
    mutates = "BVH rigs (Mixamo cm, mannequin, CMU): lines, bytes, renamed joints, collapsed legs, root OFFSETs, chains"

    def cases(self, n: int, seed: int, workdir: Path) -> list[Case]:
        from .bvh_target import _mutate_lines

        rng = rng_for(seed, self.name)
        out = []
        for i in range(n):
            seed_name = ("rig_mixamo.bvh", "rig_mannequin.bvh", "rig_cmu.bvh")[i % 3]
            text = self.seed(workdir, seed_name).decode()
            family = ("bytes", "lines", "rig", "rig", "rig", "rig")[i % 6]
            if family == "bytes":
                data, how = mutate_bytes(rng, text.encode(), n_edits=1)
            elif family == "lines":
                text, how = _mutate_lines(rng, text)
                data = text.encode("latin-1", "replace")
            else:
                text, how = _mutate_rig(rng, text)
                data = text.encode("utf-8", "surrogateescape")
            out.append(Case(f"{seed_name} {family}: {how}", ("rig.bvh", {"rig.bvh": data}, None)))
        return out


def _mutate_rig(rng: random.Random, text: str) -> tuple[str, str]:
    """Damage a BVH rig where a character needs it: names, leg offsets, the root's OFFSET and channels."""
    lines = text.split("\n")
    joints = [k for k, ln in enumerate(lines) if ln.strip().startswith(("JOINT", "ROOT"))]
    op = rng.choice(("rename", "zero_offset", "same_point", "root_offset", "root_position", "flip", "huge",
                     "units", "units", "pose", "pose"))
    k = rng.choice(joints)
    if op == "units":   # the same rig in another unit: every length scaled
        factor = rng.choice((0.01, 0.1, 2.54, 10.0, 1e-4, 1e4))
        for j, ln in enumerate(lines):
            if "OFFSET" in ln:
                head, _, nums = ln.partition("OFFSET")
                lines[j] = head + "OFFSET " + " ".join(f"{float(v) * factor:.6g}" for v in nums.split())
    elif op == "pose":   # a rest pose turned at one joint, and frames that move
        last = len(lines) - 1
        while last > 0 and not lines[last].strip():
            last -= 1
        values = lines[last].split()
        for _ in range(rng.randrange(1, 6)):
            if len(values) > 3:
                values[rng.randrange(3, len(values))] = f"{rng.uniform(-180, 180):.3f}"
        lines[last] = " ".join(values)
    elif op == "rename":
        for k in rng.sample(joints, rng.randrange(1, len(joints) + 1)):
            word = lines[k].split()[0]
            lines[k] = f"{word} {rng.choice(('Head', 'Hips', 'LeftFoot', 'LeftHand', 'x', 'RightFoot', 'Neck'))}"
    elif op in ("zero_offset", "same_point", "huge", "flip"):
        legs = [j for j in joints if any(w in lines[j].lower() for w in ("leg", "thigh", "femur", "knee", "foot",
                                                                           "hip"))] or joints
        for j in rng.sample(legs, rng.randrange(1, len(legs) + 1)):
            at = j + 2
            if "OFFSET" in lines[at]:
                pad = lines[at][:len(lines[at]) - len(lines[at].lstrip())]
                value = {"zero_offset": "0 0 0", "same_point": "0 -5 0", "huge": "1e300 0 0",
                         "flip": "0 50 0"}[op]
                lines[at] = f"{pad}OFFSET {value}"
    elif op == "root_offset":   # Blender/Mixamo-style: the root's OFFSET at its rest height
        for j, ln in enumerate(lines):
            if "OFFSET" in ln:
                lines[j] = ln.split("OFFSET")[0] + f"OFFSET 0 {rng.choice((92, 0.92, -100, 1e6))} 0"
                break
    elif op == "root_position":
        last = len(lines) - 1
        while last > 0 and not lines[last].strip():
            last -= 1
        values = lines[last].split()
        if len(values) >= 3:
            values[1] = rng.choice(HOSTILE_NUMBERS[:8] + ["92", "-92"])
            lines[last] = " ".join(values)
    return "\n".join(lines), f"{op} line {k}"


BONE_NAMES = ["hips", "spine", "chest", "upperChest", "neck", "head", "leftUpperLeg", "leftLowerLeg", "leftFoot",
              "rightUpperLeg", "rightLowerLeg", "rightFoot", "leftUpperArm", "leftLowerArm", "leftHand",
              "rightUpperArm", "rightLowerArm", "rightHand", "leftToes", "leftShoulder", "jaw", "tail", ""]


class BoneMapTarget(CharacterTarget):
    name = "character_bonemap"
    suffix = ".toml"
    mutates = "bone-map TOML for a BVH rig and a .glb: wrong, repeated and swapped joints, any value type, deep " \
              "nesting, bad UTF-8, bytes; /dev/zero and a FIFO as the map"

    def cases(self, n: int, seed: int, workdir: Path) -> list[Case]:
        from dancesynth.retarget.character import load_character

        rng = rng_for(seed, self.name)
        rigs = {}
        for name in ("rig_mixamo.bvh", "rig_cmu.bvh", "model.glb"):
            character = load_character(workdir / "seeds" / name)
            names = character.skeleton.names
            rigs[name] = list(names), {b: names[j] for b, j in character.bones.items()}
        out = []
        for i in range(n):
            main = ("rig_mixamo.bvh", "rig_cmu.bvh", "model.glb")[i % 3]
            names, right = rigs[main]
            files = {main: self.seed(workdir, main)}
            family = ("map", "map", "map", "values", "bytes", "special")[i % 6]
            if family == "special":
                kind = rng.choice(("/dev/zero", "/dev/urandom", "fifo", "/dev/stdin", "sparse", "nest", "huge"))
                if kind == "fifo":
                    files["map.toml"] = "fifo"
                elif kind == "sparse":
                    files["map.toml"] = "sparse:" + str(2 ** 30)
                elif kind == "nest":
                    files["map.toml"] = ("[bones]\nhips = " + "[" * 5000 + "]" * 5000 + "\n").encode()
                elif kind == "huge":
                    files["map.toml"] = ("[bones]\n" + "# padding\n" * 150_000).encode()
                else:
                    files["map.toml"] = kind
                out.append(Case(f"{main} special {kind}", (main, files, "map.toml")))
                continue
            # Mostly what a user writes: some of the right bones, one or two of them wrong.
            table = dict(rng.sample(sorted(right.items()), rng.randrange(1, len(right) + 1)))
            if family == "values" or rng.random() < 0.5:
                table = {}
            for _ in range(rng.randrange(0, 8) if table == {} else rng.choice((0, 0, 1, 2))):
                bone = rng.choice(BONE_NAMES)
                if family == "values":
                    table[bone] = rng.choice(HOSTILE_VALUES + HOSTILE_NUMBERS)
                else:
                    table[bone] = rng.choice(names + ["nope", "", names[0]])
            if rng.random() < 0.2:
                table["head"] = names[0]   # the head on the hips
            text = "[bones]\n" + "".join(f"{json.dumps(b)} = {_toml(v)}\n" for b, v in table.items())
            if rng.random() < 0.1:
                text = rng.choice(("", "bones = 3\n", "[bones]\n", "[[bones]]\nx = 1\n", "[bones.x]\ny = 1\n")) + text
            data = text.encode()
            if family == "bytes":
                data, how = mutate_bytes(rng, data)
                text = f"bytes {how}"
            files["map.toml"] = data
            out.append(Case(f"{main} {family}: {text[:120]!r}", (main, files, "map.toml")))
        return out


def _toml(v) -> str:
    from .toml_target import toml_value

    def no_none(x):   # TOML has no null
        if isinstance(x, dict):
            return {k: no_none(y) for k, y in x.items()}
        if isinstance(x, list):
            return [no_none(y) for y in x]
        return "" if x is None else x

    return toml_value(no_none(v))


BVH_RIG, BONE_MAP = BvhRigTarget(), BoneMapTarget()

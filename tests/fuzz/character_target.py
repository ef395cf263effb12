"""Character files a user downloads (``--character model.glb|.gltf|.vrm|.bvh``, ``--bone-map``): one
target per format, each as hostile as an attacker can make it.

Mutates, per target:
- ``character_gltf``: a skinned, textured glTF written two ways (a .glb; a .gltf with its buffer and
  texture in files): bytes flipped and cut; the JSON's values replaced by hostile ones (wrong types,
  out-of-range indices, huge counts, NaN/Infinity, deep nesting, null extensions); the rig's geometry
  (collapsed legs, both upper legs on one point, zero scales, chains 300 deep, 10,000 nodes, cycles);
  and every buffer and image URI pointed outside the model's folder (absolute paths, ``../``, its
  percent-encodings, backslashes, ``file:``, symlinks out, ``/dev/zero``, ``/dev/stdin``, ``/proc``,
  a FIFO, a NUL byte), at a texture of 13,000 x 13,000 pixels, or at a huge data: URI.
- ``character_vrm``: VRM 0.x and 1.0 avatars: the same, plus their humanoid tables (bones missing,
  duplicated, swapped, on the wrong node or no node, of the wrong type).
- ``character_bvh``: BVH rigs (Mixamo-style in centimetres, our mannequin, a CMU rig): lines and
  bytes mutated, joints renamed, leg offsets collapsed, a root OFFSET at the rest hips, deep chains.
- ``character_bonemap``: bone maps (TOML) for a BVH rig and a glTF model: bones on missing, repeated
  or wrong joints (the head on the hips), values of every type, deep nesting, bad UTF-8, byte
  mutations, and a bone map that is ``/dev/zero`` or a FIFO.

Sane: the character loads and a short dance is put on it and written as .bvh, .glb and .vrma, every
value finite; or our one-line error. No output holds a byte of the marker files planted outside the
model's folder (or of the process's environment), and no warning is printed (warnings are errors).
"""

from __future__ import annotations

import copy
import json
import os
import random
import re
import shutil
import struct
import warnings
from pathlib import Path

import numpy as np

from .harness import Case, Insane, Target, mutate_bytes, rng_for, write_file

MARKER = b"DANCESYNTH-SECRET-7f3a9c"          # in the files outside the model's folder
ENV_MARKER = "DANCESYNTH-ENVIRON-51be04"      # in the process's environment (/proc/self/environ)
DANCE_FRAMES = 8
HOSTILE_VALUES = [None, -1, 0, 1, 2, 3, 7, 255, 65535, 2 ** 31, 2 ** 32 + 1, 2 ** 63, -2 ** 63, 10 ** 30, 1.5,
                  -0.0, 1e308, -1e308, 1e-320, "x", "", "../x", True, False, [], {}, [0, 0], [None], {"x": 1},
                  [1e308] * 3, [0.0, 0.0, 0.0, 0.0], [0, 0, 0, 1], [1, 1, 1], [0, 0, 0], 4_000_001, 50_000_000]


def glb_container(doc, blob: bytes | None) -> bytes:
    """A GLB file of a JSON document (or its text) and its binary chunk (written here, as another tool would)."""
    text = (doc if isinstance(doc, str) else json.dumps(doc, allow_nan=True)).encode("utf-8")
    text += b" " * (-len(text) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text
    if blob is not None:
        blob = blob + b"\0" * (-len(blob) % 4)
        chunks += struct.pack("<II", len(blob), 0x004E4942) + blob
    return struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks


def split_glb(data: bytes) -> tuple[dict, bytes]:
    (json_len,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20:20 + json_len])
    at = 20 + json_len
    (bin_len,) = struct.unpack_from("<I", data, at)
    return doc, data[at + 8:at + 8 + bin_len]


def _paths(value, prefix=()):
    """Every (path, value) in a JSON tree."""
    out = [(prefix, value)]
    if isinstance(value, dict):
        for k, v in value.items():
            out += _paths(v, prefix + (k,))
    elif isinstance(value, list):
        for k, v in enumerate(value[:64]):   # an accessor's min/max, not a mesh's worth of numbers
            out += _paths(v, prefix + (k,))
    return out


def _set(doc, path, value):
    node = doc
    for k in path[:-1]:
        node = node[k]
    if value is _DELETE:
        del node[path[-1]]
    else:
        node[path[-1]] = value


_DELETE = object()


def _nested(depth: int) -> str:
    """A placeholder that ``_json_text`` turns into ``depth`` nested arrays (json.dumps itself would recurse)."""
    return f"__NEST_{depth}__"


_NEST = re.compile(r'"__NEST_(\d+)__"')
_ZERO = re.compile(r"(?<=[\[,: ])0\.0(?=[,\]}])")


def _json_text(doc, rng: random.Random, nan: bool) -> str:
    text = _NEST.sub(lambda m: "[" * int(m.group(1)) + "]" * int(m.group(1)), json.dumps(doc, allow_nan=True))
    if nan:   # NaN and Infinity written into the JSON text where a number stood
        text = _ZERO.sub(rng.choice(("NaN", "Infinity", "-Infinity")), text, count=1)
    return text


# ----------------------------------------------------------------------------- the seeds


def make_seeds(seeds: Path) -> None:
    """The seed models, rigs, the dance and the texture bomb under ``seeds``."""
    from PIL import Image

    from dancesynth.export.formats import encode_dance
    from dancesynth.export.vrm import vrm_bytes
    from dancesynth.io.bvh import format_bvh, read_bvh
    from dancesynth.retarget import on_character
    from dancesynth.retarget.character import load_character
    from dancesynth.retarget.rigs import rig_skeleton
    from dancesynth.rotations import IDENTITY
    from dancesynth.types import MotionClip

    repo = Path(__file__).resolve().parents[2]
    seeds.mkdir(parents=True, exist_ok=True)
    dance = read_bvh(repo / "tests" / "data" / "mocap" / "cmu_daz_salsa" / "60_01_scaled.bvh").frames(0, DANCE_FRAMES)
    (seeds / "dance.bvh").write_text(format_bvh(dance))
    mannequin = load_character("mannequin")
    moved, _ = on_character(dance, mannequin)
    glb = encode_dance(".glb", moved, mannequin)
    (seeds / "model.glb").write_bytes(glb)
    # The .gltf: buffer and a texture in files, the texture on the body's material.
    doc, blob = split_glb(glb)
    doc["buffers"] = [{"uri": "model.bin", "byteLength": len(blob)}]
    doc["images"] = [{"uri": "skin.png"}]
    doc["textures"] = [{"source": 0}]
    for material in doc.get("materials", []):
        material.setdefault("pbrMetallicRoughness", {})["baseColorTexture"] = {"index": 0}
    (seeds / "model.gltf").write_text(json.dumps(doc))
    (seeds / "model.bin").write_bytes(blob)
    Image.new("RGB", (8, 8), (200, 120, 40)).save(seeds / "skin.png")
    Image.new("L", (13_000, 13_000)).save(seeds / "bomb.png", optimize=True)   # ~170 kB, 169 Mpixels
    vrm1 = vrm_bytes(mannequin)
    (seeds / "avatar1.vrm").write_bytes(vrm1)
    doc, blob = split_glb(vrm1)
    table = doc["extensions"].pop("VRMC_vrm")["humanoid"]["humanBones"]
    doc["extensionsUsed"] = ["VRM"]
    doc["extensions"] = {"VRM": {"meta": {"title": "fuzz 0.x"}, "humanoid": {"humanBones": [
        {"bone": b, "node": e["node"]} for b, e in table.items()]}}}
    (seeds / "avatar0.vrm").write_bytes(glb_container(doc, blob))
    for name in ("mixamo", "mannequin", "cmu"):
        sk, _ = rig_skeleton(name)
        scale = 100.0 if name == "mixamo" else 1.0
        rest = MotionClip(sk.scaled(scale), 30.0, sk.offsets[:1] * scale, np.tile(IDENTITY, (1, sk.n_joints, 1)))
        (seeds / f"rig_{name}.bvh").write_text(format_bvh(rest))


# ----------------------------------------------------------------------------- running one case


class CharacterTarget(Target):
    """What the four targets share: writing a case's files into a fresh folder and checking the dance."""

    suffix = ".txt"
    sane = "loads; a dance put on it is finite and writes as .bvh/.glb/.vrma; no marker byte in any output"

    def prepare(self, workdir: Path) -> None:
        seeds = workdir / "seeds"
        if not (seeds / "rig_cmu.bvh").is_file():
            make_seeds(seeds)
        outside = workdir / "outside"
        outside.mkdir(exist_ok=True)
        for name in ("secret.txt", "secret.png", "secret.bin"):
            (outside / name).write_bytes(MARKER * 64)
        os.environ["DANCESYNTH_FUZZ_SECRET"] = ENV_MARKER   # what /proc/self/environ would leak

    def seed(self, workdir: Path, name: str) -> bytes:
        return (workdir / "seeds" / name).read_bytes()

    def run(self, case: Case, workdir: Path) -> None:
        from dancesynth.export.formats import encode_dance
        from dancesynth.io.bvh import read_bvh
        from dancesynth.retarget import on_character
        from dancesynth.retarget.character import load_character

        main, files, bone_map = case.data
        folder = workdir / "case"
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir()
        for name, content in files.items():
            path = folder / name
            path.parent.mkdir(parents=True, exist_ok=True)
            if isinstance(content, bytes):
                path.write_bytes(content)
            elif content == "fifo":
                os.mkfifo(path)
            elif content.startswith("sparse:"):
                with open(path, "wb") as fh:
                    fh.truncate(int(content[7:]))
            else:   # a symlink; "outside/..." is the planted folder
                target = workdir / content[8:] if content.startswith("outside:") else Path(content)
                os.symlink(target, path)
        dance = read_bvh(workdir / "seeds" / "dance.bvh")
        with warnings.catch_warnings():
            warnings.simplefilter("error")   # a warning on the user's terminal is a failure too
            character = load_character(folder / main, bone_map=None if bone_map is None else folder / bone_map)
            moved, character = on_character(dance, character)
            if not (np.isfinite(moved.root_pos).all() and np.isfinite(moved.local_rot).all()):
                raise Insane("the dance on the character is not finite")
            for suffix in (".bvh", ".glb", ".vrma"):
                data = encode_dance(suffix, moved, character)
                if MARKER in data or ENV_MARKER.encode() in data:
                    raise Insane(f"a file outside the model's folder reached the {suffix} output")

    def save(self, case: Case, folder: Path, stem: str) -> Path:
        main, files, bone_map = case.data
        out = folder / stem
        out.mkdir(parents=True, exist_ok=True)
        for name, content in files.items():
            write_file(out, name.replace("/", "_"), content if isinstance(content, bytes)
                       else f"(not a file: {content})\n".encode())
        return write_file(out, "CASE.txt", f"character {main}, bone map {bone_map}: {case.label}\n".encode())


# ----------------------------------------------------------------------------- glTF and VRM


HOSTILE_URIS = ["/ABS/outside/secret.png", "../outside/secret.png", "%2e%2e/outside/secret.png",
                "..%2Foutside%2Fsecret.png", "sub/../../outside/secret.png", "..\\outside\\secret.png",
                "%2E%2E%5Coutside%5Csecret.png", "file:///ABS/outside/secret.png", "file://localhost/etc/passwd",
                "http://127.0.0.1:9/x.png", "//127.0.0.1/x.png", "/etc/passwd", "/proc/self/environ", "/dev/zero",
                "/dev/urandom", "/dev/stdin", "link.png", "linkdir/secret.png", "fifo.png", "sparse.bin",
                "skin.png\0.png", "", ".", "sub/", "missing.png", "C:\\Windows\\win.ini", "data:,",
                "data:application/octet-stream;base64,!!!!", "data:image/png;base64,", "BOMB", "BIGDATA",
                "%00", "skin.png?x=1#y", "ski%6E.png", "./skin.png"]


def _place_uri(rng: random.Random, workdir: Path, files: dict) -> str:
    """A hostile URI, with whatever it needs next to the model (a symlink out, a FIFO, the bomb)."""
    uri = rng.choice(HOSTILE_URIS).replace("/ABS/", str(workdir.resolve()) + "/")
    if uri == "link.png":
        files["link.png"] = "outside:outside/secret.png"
    elif uri == "linkdir/secret.png":
        files["linkdir"] = "outside:outside"
    elif uri == "fifo.png":
        files["fifo.png"] = "fifo"
    elif uri == "sparse.bin":
        files["sparse.bin"] = "sparse:" + str(rng.choice((2 ** 30, 100 * 2 ** 20)))
    elif uri == "BOMB":
        files["bomb.png"] = (workdir / "seeds" / "bomb.png").read_bytes()
        uri = "bomb.png"
    elif uri == "BIGDATA":
        uri = "data:application/octet-stream;base64," + "A" * rng.choice((4, 4 * 2 ** 18, 4 * 2 ** 20))
    files.setdefault("skin.png", (workdir / "seeds" / "skin.png").read_bytes())
    return uri


def _mutate_json(rng: random.Random, doc: dict) -> str:
    """Replace, delete or duplicate values anywhere in a glTF document; what was done."""
    done = []
    for _ in range(rng.choice((1, 1, 2, 3, 5))):
        paths = [p for p, _ in _paths(doc) if p]
        path = rng.choice(paths)
        op = rng.random()
        if op < 0.15:
            _set(doc, path, _DELETE)
            done.append(f"del {'/'.join(map(str, path))}")
        elif op < 0.2:
            _set(doc, path, _nested(rng.choice((70, 1000, 5000))))
            done.append(f"nest {'/'.join(map(str, path))}")
        else:
            value = copy.deepcopy(rng.choice(HOSTILE_VALUES))
            _set(doc, path, value)
            done.append(f"{'/'.join(map(str, path))}={value!r}"[:80])
    return "; ".join(done)


def _mutate_geometry(rng: random.Random, doc: dict) -> str:
    """Rig-level damage: collapsed or coincident bones, zero scales, deep chains, many nodes, cycles."""
    nodes = doc["nodes"]
    named = {n.get("name"): i for i, n in enumerate(nodes)}
    legs = [named.get(n) for n in ("leftUpperLeg", "rightUpperLeg", "leftLowerLeg", "rightLowerLeg",
                                   "leftFoot", "rightFoot") if named.get(n) is not None] or [1]
    op = rng.choice(("zero_leg", "same_hips", "zero_scale", "huge", "deep", "many", "cycle", "self", "tiny",
                     "matrix", "nan_text"))
    i = rng.choice(legs)
    if op == "zero_leg":
        for j in rng.sample(legs, rng.randrange(1, len(legs) + 1)):
            nodes[j]["translation"] = [0.0, 0.0, 0.0]
    elif op == "same_hips":
        for j in legs[:2]:
            nodes[j]["translation"] = [0.0, -0.05, 0.0]
    elif op == "zero_scale":
        nodes[i]["scale"] = [0.0, 0.0, 0.0]
    elif op == "huge":
        nodes[i]["translation"] = [rng.choice((1e30, 3e38, 1e300)), 0.0, 0.0]
    elif op == "tiny":
        for n in nodes:
            if "translation" in n:
                n["translation"] = [v * 1e-9 for v in n["translation"]]
    elif op in ("deep", "many"):
        count = rng.choice((300, 1000, 5000)) if op == "deep" else rng.choice((2000, 10_000))
        first = len(nodes)
        for k in range(count):
            child = [first + k + 1] if op == "deep" and k + 1 < count else []
            nodes.append({"name": f"extra{k}", "translation": [0, 0.01, 0], "children": child})
        roots = [first] if op == "deep" else list(range(first, first + count))
        nodes[i].setdefault("children", []).extend(roots)
        for skin in doc.get("skins", []):
            skin["joints"] = skin["joints"] + list(range(first, first + count))
    elif op == "cycle":
        nodes[i].setdefault("children", []).append(0)
    elif op == "self":
        nodes[i].setdefault("children", []).append(i)
    elif op == "matrix":
        nodes[i]["matrix"] = rng.choice(([0.0] * 16, [1.0] * 16, [-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]))
    else:
        return "nan_text"
    return f"{op} node {i}"


class GltfTarget(CharacterTarget):
    name = "character_gltf"
    mutates = ("a skinned textured .glb and .gltf: bytes, JSON values, rig geometry, hostile buffer and image "
               "URIs (outside the folder, devices, FIFOs, a 169-Mpixel texture)")
    seeds = ("model.glb", "model.gltf")

    def cases(self, n: int, seed: int, workdir: Path) -> list[Case]:
        rng = rng_for(seed, self.name)
        out = []
        families = ("bytes", "json", "json", "geometry", "uri", "uri") + self.extra_families
        for i in range(n):
            family = families[i % len(families)]
            out.append(self.make(rng, family, rng.choice(self.seeds), workdir))
        return out

    extra_families: tuple = ()

    def make(self, rng, family: str, seed_name: str, workdir: Path) -> Case:
        files = {}
        data = self.seed(workdir, seed_name)
        gltf = seed_name.endswith(".gltf")
        if gltf:
            files["model.bin"] = self.seed(workdir, "model.bin")
            files["skin.png"] = self.seed(workdir, "skin.png")
        if family == "bytes":
            data, how = mutate_bytes(rng, data)
            files[seed_name] = data
            return Case(f"{seed_name} bytes:{how}", (seed_name, files, None))
        doc, blob = (json.loads(data), None) if gltf else split_glb(data)
        if family == "json":
            how = _mutate_json(rng, doc)
        elif family == "geometry":
            how = _mutate_geometry(rng, doc)
        elif family == "uri":
            how = self._uris(rng, doc, workdir, files, gltf)
        else:
            how = self.family(rng, family, doc)
        nan = how == "nan_text" or rng.random() < 0.03
        text = _json_text(doc, rng, nan)
        how += " +NaN text" if nan else ""
        files[seed_name] = text.encode() if gltf else glb_container(text, blob)
        return Case(f"{seed_name} {family}: {how}", (seed_name, files, None))

    def _uris(self, rng, doc: dict, workdir: Path, files: dict, gltf: bool) -> str:
        if not gltf or rng.random() < 0.3:   # an image by URI in a .glb (the exporter then copies it in)
            doc.setdefault("images", []).append({"uri": ""})
            doc.setdefault("textures", []).append({"source": len(doc["images"]) - 1})
            for material in doc.get("materials", []):
                material.setdefault("pbrMetallicRoughness", {})["baseColorTexture"] = {"index": len(doc["textures"]) - 1}
        where = []
        for item in [doc["images"][-1]] + (doc.get("buffers", [])[:1] if gltf and rng.random() < 0.5 else []):
            item["uri"] = _place_uri(rng, workdir, files)
            if rng.random() < 0.3 and len(doc["images"]) < 8:   # several textures of one image (the 7 GB case)
                for _ in range(6):
                    doc["images"].append(dict(doc["images"][-1]))
                    doc["textures"].append({"source": len(doc["images"]) - 1})
            where.append(repr(item["uri"][:60]))
        return "uris " + ", ".join(where)

    def family(self, rng, family: str, doc: dict) -> str:
        raise ValueError(family)


class VrmTarget(GltfTarget):
    name = "character_vrm"
    mutates = "VRM 0.x and 1.0 avatars: bytes, JSON values, humanoid tables, rig geometry, hostile image URIs"
    seeds = ("avatar0.vrm", "avatar1.vrm")
    extra_families = ("humanoid", "humanoid", "humanoid")

    def family(self, rng, family: str, doc: dict) -> str:
        ext = doc["extensions"]
        n_nodes = len(doc["nodes"])
        if "VRM" in ext:
            table = ext["VRM"]["humanoid"]["humanBones"]
            entries = [(e["bone"], e) for e in table]
        else:
            table = ext["VRMC_vrm"]["humanoid"]["humanBones"]
            entries = list(table.items())
        done = []
        for _ in range(rng.choice((1, 1, 2, 4))):
            bone, entry = rng.choice(entries)
            op = rng.choice(("drop", "dup", "swap", "wrong", "none", "type", "leg", "head_on_hips", "empty"))
            other = rng.choice(entries)[1]
            if op == "drop":
                if isinstance(table, list):
                    table[:] = [e for e in table if e.get("bone") != bone]
                else:
                    table.pop(bone, None)
            elif op == "dup":
                entry["node"] = other.get("node")
            elif op == "swap":
                entry["node"], other["node"] = other.get("node"), entry.get("node")
            elif op == "wrong":
                entry["node"] = rng.choice((-1, n_nodes, n_nodes + 5, 2 ** 40, rng.randrange(n_nodes)))
            elif op == "none":
                entry.pop("node", None)
            elif op == "type":
                entry["node"] = copy.deepcopy(rng.choice(HOSTILE_VALUES))
            elif op == "leg":   # a leg bone gone: the 73 KeyErrors
                leg = rng.choice(("leftUpperLeg", "rightLowerLeg", "leftFoot", "rightUpperLeg"))
                if isinstance(table, list):
                    table[:] = [e for e in table if e.get("bone") != leg]
                else:
                    table.pop(leg, None)
                bone = leg
            elif op == "head_on_hips":
                nodes = {b: e.get("node") for b, e in entries}
                for b, e in entries:
                    if b == "head":
                        e["node"] = nodes.get("hips")
                bone = "head"
            else:
                if isinstance(table, list):
                    table.clear()
                else:
                    table.clear()
                bone = "all"
            done.append(f"{op} {bone}")
        return ", ".join(done)


GLTF, VRM = GltfTarget(), VrmTarget()

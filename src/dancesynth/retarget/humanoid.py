"""Find the humanoid bones of any rig: VRM 1.0 humanoid bone names -> joint indices.

Rigs name their joints differently and even disagree on what a name means: Mixamo's
``LeftShoulder`` is the collar bone, CMU's and Perfume's ``LeftShoulder`` is the upper
arm (their collar bone is ``LeftCollar``). So names find only the unambiguous ends --
each side's hand (``wrist`` before ``hand``), foot (``ankle`` before ``foot``) and the
head -- and the hierarchy does the rest: the two joints above a hand are the lower and
upper arm, a sided joint above those is the shoulder; likewise for legs; the hips join
the legs; the joints between hips and head split at the arms' branch into spine bones
and neck. This reads CMU (both BVH layouts), Daz, Mixamo, VRM/VRoid, SMPL, Character
Creator and Perfume rigs alike. A TOML table (``[bones]`` bone = "joint") overrides it.
"""

from __future__ import annotations

import re

import numpy as np

from ..errors import InputError
from ..motion.roles import _side_and_part
from ..types import Skeleton

SIDES = ("left", "right")
LIMB_BONES = ("Shoulder", "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot", "Toes")
# Fingers, VRM's names: the thumb's three bones start at its metacarpal, the others' at the proximal.
FINGERS = {"Thumb": ("thumb",), "Index": ("index",), "Middle": ("middle", "mid"), "Ring": ("ring",),
           "Little": ("little", "pinky")}
FINGER_BONES = {f: (("Metacarpal", "Proximal", "Distal") if f == "Thumb" else ("Proximal", "Intermediate", "Distal"))
                for f in FINGERS}
BONES = ("hips", "spine", "chest", "upperChest", "neck", "head") + tuple(s + b for s in SIDES for b in LIMB_BONES) \
    + tuple(s + f + p for s in SIDES for f, parts in FINGER_BONES.items() for p in parts)
REQUIRED = ("hips", "spine", "head") + tuple(
    s + b for s in SIDES for b in ("UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot"))

# The bone whose joint ends each bone's segment, in order of preference: a bone's direction
# is the line from its joint to the first of these both rigs have.
SEGMENT_END = {"hips": ("spine", "chest", "upperChest", "neck", "head"),
               "spine": ("chest", "upperChest", "neck", "head"), "chest": ("upperChest", "neck", "head"),
               "upperChest": ("neck", "head"), "neck": ("head",)}
for _s in SIDES:
    SEGMENT_END.update({_s + "Shoulder": (_s + "UpperArm",), _s + "UpperArm": (_s + "LowerArm",),
                        _s + "LowerArm": (_s + "Hand",), _s + "UpperLeg": (_s + "LowerLeg",),
                        _s + "LowerLeg": (_s + "Foot",), _s + "Foot": (_s + "Toes",)})
    for _f, _parts in FINGER_BONES.items():
        SEGMENT_END.update({_s + _f + a: (_s + _f + b,) for a, b in zip(_parts, _parts[1:])})

_SKIP = ("twist", "roll", "share")   # helper joints inside a limb chain that carry no bone
_VROID = re.compile(r"^j_(?:bip|adj|sec)_([clr])_(.*)$", re.IGNORECASE)


def side_and_part(name: str) -> tuple[str, str]:
    """('l' | 'r' | '', lower-case body part) of a joint name, VRoid's ``J_Bip_L_Hand`` included."""
    m = _VROID.match(name)
    if m:
        side = m.group(1).lower()
        return ("" if side == "c" else side), m.group(2).lower()
    return _side_and_part(name)


def find_bones(skeleton: Skeleton, overrides: dict[str, str] | None = None, *, what: str = "the rig") -> dict[str, int]:
    """Humanoid bone -> joint index for ``skeleton``; ``overrides`` (bone -> joint name) win.

    Raises ``InputError`` naming the required bones that could not be found, with the TOML
    that would name them.
    """
    overrides = dict(overrides or {})
    _check_overrides(skeleton, overrides, what)
    parsed = [side_and_part(n) for n in skeleton.names]
    parents = skeleton.parents
    bones: dict[str, int] = {}

    def named(side: str, parts) -> int:
        for part in parts:
            for j, (s, p) in enumerate(parsed):
                if s == side and p == part:
                    return j
        return -1

    def up(j: int) -> int:
        """The next joint above ``j`` that is not a twist/roll helper."""
        j = parents[j]
        while j >= 0 and any(k in parsed[j][1] for k in _SKIP):
            j = parents[j]
        return j

    for s, side in zip("lr", SIDES):
        for end, names, mid, top, extra in ((side + "Hand", ("wrist", "hand"), side + "LowerArm",
                                              side + "UpperArm", side + "Shoulder"),
                                             (side + "Foot", ("ankle", "foot"), side + "LowerLeg",
                                              side + "UpperLeg", None)):
            j = overrides.get(end) or named(s, names)
            j = skeleton.index(j) if isinstance(j, str) else j
            if j < 0 or up(j) < 0 or up(up(j)) < 0:
                continue
            bones[end], bones[mid], bones[top] = j, up(j), up(up(j))
            above = up(up(up(j)))
            if extra and above >= 0 and parsed[above][0] == s:
                bones[extra] = above
        foot = bones.get(side + "Foot")
        if foot is not None:
            kids = [int(k) for k in skeleton.children(foot) if not any(x in parsed[k][1] for x in _SKIP)]
            toes = [k for k in kids if any(t in parsed[k][1] for t in ("toe", "foot", "ball"))]
            if toes or len(kids) == 1:
                bones[side + "Toes"] = (toes or kids)[0]

    head = overrides.get("head") or next((j for j, (s, p) in enumerate(parsed) if s == "" and p == "head"), -1)
    head = skeleton.index(head) if isinstance(head, str) else head
    legs = [bones.get(s + "UpperLeg") for s in SIDES]
    if head >= 0:
        bones["head"] = head
    if None not in legs:   # where legs and spine meet (CC rigs hang the legs from a pelvis below it)
        hips = _common_ancestor(parents, *legs)
        bones["hips"] = _common_ancestor(parents, hips, head) if head >= 0 else hips
    if head >= 0 and "hips" in bones and bones["hips"] != head and _is_ancestor(parents, bones["hips"], head):
        _spine(parents, bones, head)

    for s, side in zip("lr", SIDES):
        if side + "Hand" in bones:
            bones.update(_fingers(skeleton, parsed, bones[side + "Hand"], side))
    for bone, joint in overrides.items():
        bones[bone] = skeleton.index(joint)
    _distinct(skeleton, bones, what)   # a bone map that puts two bones on one joint says so first
    missing = [b for b in REQUIRED if b not in bones]
    if missing:
        table = "\n".join(f'{b} = "<joint name>"' for b in missing)
        raise InputError(
            f"cannot find the humanoid bones {', '.join(missing)} in {what} (joints: "
            f"{', '.join(skeleton.names[:12])}{', ...' if skeleton.n_joints > 12 else ''}); name them in a TOML "
            f"file given with --bone-map, e.g.: [bones] {table.replace(chr(10), ' ')}")
    return bones


# Each chain's bones, top down: every one must hang below the one before it.
CHAINS = (("hips", "spine", "chest", "upperChest", "neck", "head"),) + tuple(
    c for s in SIDES for c in (("hips", s + "UpperLeg", s + "LowerLeg", s + "Foot", s + "Toes"),
                                ("spine", s + "Shoulder", s + "UpperArm", s + "LowerArm", s + "Hand")))
MIN_LEG_M = 0.05          # shorter legs are no body's (and give the retargeter nothing to scale by)
MIN_PART_OF_LEG = 0.1     # a thigh or shin shorter than this share of the leg is collapsed
MIN_HIP_WIDTH = 0.02      # the upper legs this far apart across, as a share of the leg, or no left and right
MAX_EXTENT_M = 1e4        # no joint of a rest pose farther from the origin (a giant is 100 m; beyond, numbers overflow)


def check_bones(skeleton: Skeleton, bones: dict[str, int], rest: np.ndarray, *, what: str = "the rig") -> None:
    """Refuse a humanoid mapping a dance cannot be put on, before any dance is made: a required bone
    missing, two bones on one joint, a bone not below the bone above it (the head on the hips), or a
    rest pose (``rest``: (J, 3) world positions, Y up) with collapsed legs, the upper legs on one
    point, or the head not above the hips."""
    missing = [b for b in REQUIRED if b not in bones]
    if missing:
        raise InputError(f"{what} has no {', '.join(missing)} bone; name them in a TOML file given with --bone-map")
    _distinct(skeleton, bones, what)
    for chain in CHAINS:
        present = [b for b in chain if b in bones]
        for above, below in zip(present, present[1:]):
            if not _is_ancestor(skeleton.parents, bones[above], bones[below]):
                raise InputError(f"{what}: bone {below} ({skeleton.names[bones[below]]}) does not hang below {above} "
                                 f"({skeleton.names[bones[above]]}); fix the bone map or the rig's hierarchy")
    if not np.all(np.isfinite(rest)) or np.abs(rest).max() > MAX_EXTENT_M:
        raise InputError(f"{what}'s rest pose is not finite or reaches over {MAX_EXTENT_M:g} m from its origin")
    leg = leg_length(rest, bones)
    if not leg >= MIN_LEG_M:
        raise InputError(f"{what}'s legs are {leg * 100:.1f} cm long in its rest pose; a character needs legs "
                         f"(at least {MIN_LEG_M * 100:g} cm)")
    for s in SIDES:
        for top, end in (("UpperLeg", "LowerLeg"), ("LowerLeg", "Foot")):
            size = np.linalg.norm(rest[bones[s + end]] - rest[bones[s + top]])
            if size < MIN_PART_OF_LEG * leg:
                raise InputError(f"{what}'s {s} {'thigh' if top == 'UpperLeg' else 'shin'} is "
                                 f"{size * 100:.1f} cm long against a {leg * 100:.0f} cm leg: collapsed bones")
    across = rest[bones["leftUpperLeg"]] - rest[bones["rightUpperLeg"]]
    if np.hypot(across[0], across[2]) < MIN_HIP_WIDTH * leg:
        raise InputError(f"{what}'s left and right upper legs are on one point (or one above the other) in its rest "
                         "pose: it has no left and right to dance with")
    if rest[bones["head"], 1] - rest[bones["hips"], 1] < MIN_PART_OF_LEG * leg:
        raise InputError(f"{what}'s head is not above its hips in the rest pose; a character stands upright, Y up")


def _distinct(skeleton: Skeleton, bones: dict[str, int], what: str) -> None:
    seen = {}
    for bone in BONES:
        j = bones.get(bone)
        if j is None:
            continue
        if not 0 <= j < skeleton.n_joints:
            raise InputError(f"{what}: bone {bone} is joint {j}, which does not exist")
        if j in seen:
            raise InputError(f"{what}: bones {seen[j]} and {bone} are one joint ({skeleton.names[j]}); each humanoid "
                             "bone needs its own")
        seen[j] = bone


def _fingers(skeleton: Skeleton, parsed, hand: int, side: str) -> dict[str, int]:
    """The finger bones below ``hand``: each finger's topmost joint named for it (``lIndex1``,
    ``CC_Base_L_Mid1``, ``LeftHandIndex1``), then down its chain, one bone per joint."""
    out = {}
    below = [j for j in range(hand + 1, skeleton.n_joints) if _is_ancestor(skeleton.parents, hand, j)]
    for finger, words in FINGERS.items():
        named = [j for j in below if any(w in parsed[j][1] for w in words)
                 and not any(x in parsed[j][1] for x in _SKIP)]
        tops = [j for j in named if skeleton.parents[j] not in named]
        if len(tops) != 1:      # no such finger, or two candidates: leave the finger at rest
            continue
        j = tops[0]
        for part in FINGER_BONES[finger]:
            out[side + finger + part] = j
            kids = [int(k) for k in skeleton.children(j) if int(k) in named]
            if not kids:
                break
            j = kids[0]
    return out


def _check_overrides(skeleton: Skeleton, overrides: dict, what: str) -> None:
    for bone, joint in overrides.items():
        if bone not in BONES:
            raise InputError(f"bone map: unknown humanoid bone {bone!r}; use VRM names: {', '.join(BONES)}")
        if not isinstance(joint, str) or joint not in skeleton.names:
            raise InputError(f"bone map: {bone} = {joint!r} is not a joint of {what}")


def _ancestors(parents, j: int) -> list[int]:
    out = []
    while j >= 0:
        out.append(int(j))
        j = parents[j]
    return out


def _is_ancestor(parents, a: int, j: int) -> bool:
    return a in _ancestors(parents, j)


def _common_ancestor(parents, a: int, b: int) -> int:
    above_b = set(_ancestors(parents, b))
    return next(j for j in _ancestors(parents, a) if j in above_b)


def _spine(parents, bones: dict, head: int) -> None:
    """Spine, chest, upper chest and neck: the joints between hips and head, split where the arms branch."""
    path = _ancestors(parents, head)[1:]                  # head's parent ... hips
    path = path[:path.index(bones["hips"])][::-1]         # hips' child ... head's parent
    arms = [bones.get(s + "Shoulder", bones.get(s + "UpperArm")) for s in SIDES]
    branch = _common_ancestor(parents, *arms) if None not in arms else -1
    cut = path.index(branch) + 1 if branch in path else len(path)
    trunk, neck = path[:cut], path[cut:]
    if trunk:
        bones["spine"] = trunk[0]
    if len(trunk) >= 2:
        bones["chest"] = trunk[len(trunk) // 2] if len(trunk) >= 3 else trunk[1]
    if len(trunk) >= 3:
        bones["upperChest"] = trunk[-1]
    if neck:
        bones["neck"] = neck[0]


MAX_BONE_MAP_BYTES = 1 << 20   # a bone map names about 50 bones: a few kB


def read_bone_map(path) -> dict[str, str]:
    """The ``[bones]`` table of a TOML bone-map file."""
    import tomllib

    from ..io.files import read_user_file

    data = read_user_file(path, limit=MAX_BONE_MAP_BYTES, what=f"bone map {path}")
    try:
        data = tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError:
        raise InputError(f"bone map {path} is not UTF-8 text") from None
    except RecursionError:
        raise InputError(f"bone map {path} nests too deep to be a bone map") from None
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"bone map {path} is not valid TOML: {str(e).splitlines()[0] if str(e) else e}") from None
    table = data.get("bones")
    if not isinstance(table, dict) or not table:
        raise InputError(f'bone map {path} needs a [bones] table, e.g. [bones] hips = "pelvis"')
    return table


def segment_ends(source: dict[str, int], target: dict[str, int]) -> dict[str, str]:
    """For each bone both rigs have: the bone ending its segment in both (absent: none does)."""
    shared = source.keys() & target.keys()
    return {b: next(e for e in SEGMENT_END[b] if e in shared)
            for b in shared if any(e in shared for e in SEGMENT_END.get(b, ()))}


def mapped_pairs(source: dict[str, int], target: dict[str, int]) -> list[tuple[str, int, int]]:
    """(bone, source joint, target joint) for every bone both rigs have, in canonical order."""
    return [(b, source[b], target[b]) for b in BONES if b in source and b in target]


def leg_length(positions: np.ndarray, bones: dict[str, int]) -> float:
    """Mean thigh + shin length (m) of a rest pose ``positions`` (J, 3)."""
    total = 0.0
    for s in SIDES:
        hip, knee, ankle = (positions[bones[s + b]] for b in ("UpperLeg", "LowerLeg", "Foot"))
        total += np.linalg.norm(knee - hip) + np.linalg.norm(ankle - knee)
    return total / 2

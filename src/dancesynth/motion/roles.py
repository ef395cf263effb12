"""Find the joints that matter (feet, knees, hands, head) in any BVH skeleton by name.

Skeletons name their joints differently (``lFoot``, ``LeftAnkle``, ``CC_Base_L_Foot``,
``LeftFoot``); we read the side and the body part from the name, then walk the
hierarchy from the end effector up so that a chain is always parent-linked.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from .. import rotations as rot
from ..errors import ModelError
from ..types import Skeleton

_PREFIXES = ("cc_base_", "mixamorig:", "mixamorig_", "bip01_", "bip01 ")


def _side_and_part(name: str) -> tuple[str, str]:
    """Split a joint name into ('l' | 'r' | '', lower-case body part)."""
    base = name
    low = base.lower()
    for p in _PREFIXES:
        if low.startswith(p):
            base = base[len(p):]
            low = base.lower()
    m = re.match(r"^(left|right)[_\s.]?(.*)$", low)
    if m:
        return m.group(1)[0], m.group(2)
    # A single-letter side needs a separator or a capital next ("lFoot", "L_Foot", "LHipJoint"),
    # so that "lowerback" is not read as a left "owerback".
    m = re.match(r"^([lLrR])(?:[_\s.](.+)|([A-Z].*))$", base)
    if m:
        return m.group(1).lower(), (m.group(2) or m.group(3)).lower()
    m = re.match(r"^(.*?)[_\s.]?(left|right|l|r)$", low)
    if m and m.group(1):
        return m.group(2)[0], m.group(1)
    return "", low


@dataclass(frozen=True)
class JointRoles:
    """Indices of the joints the motion analysis and clean-up need (-1 where absent)."""

    root: int
    head: int
    hips: tuple[int, int]      # upper-leg joints (left, right)
    knees: tuple[int, int]
    ankles: tuple[int, int]
    toes: tuple[int, int]      # -1 when the foot ends in an End Site
    shoulders: tuple[int, int]  # upper-arm joints
    elbows: tuple[int, int]
    wrists: tuple[int, int]


def _find(parts_by_side, side: str, candidates) -> int:
    for cand in candidates:
        for j, (s, part) in parts_by_side:
            if s == side and part == cand:
                return j
    return -1


def find_roles(skeleton: Skeleton) -> JointRoles:
    """Joint roles of ``skeleton``; raises ``ModelError`` if it has no recognisable legs."""
    parsed = [(j, _side_and_part(n)) for j, n in enumerate(skeleton.names)]
    parents = skeleton.parents

    def chain(side, effector_names):
        end = _find(parsed, side, effector_names)
        if end < 0:
            return -1, -1, -1
        mid = parents[end]
        top = parents[mid] if mid >= 0 else -1
        return top, mid, end

    legs = [chain(s, ("ankle", "foot")) for s in "lr"]
    arms = [chain(s, ("wrist", "hand")) for s in "lr"]
    if min(legs[0] + legs[1]) < 0:
        raise ModelError(
            f"cannot find both legs in skeleton ({', '.join(skeleton.names[:8])}, ...): "
            "name the ankles e.g. LeftFoot/RightFoot or LeftAnkle/RightAnkle; a robot-style skeleton of "
            "one-axis joints needs a chain map ([rigs] in genres.toml, e.g. scripts/g1_chains.toml)")
    toes = []
    for _, _, ankle in legs:
        kids = skeleton.children(ankle)
        parts = [_side_and_part(skeleton.names[k])[1] for k in kids]
        exact = [k for k, p in zip(kids, parts) if p in ("toe", "toebase", "toes")]
        named = exact or [k for k, p in zip(kids, parts) if "toe" in p]
        toes.append(int(named[0]) if named else (int(kids[0]) if len(kids) else -1))
    head = next((j for j, (s, p) in parsed if p == "head"), -1)
    return JointRoles(
        root=0, head=head,
        hips=(legs[0][0], legs[1][0]), knees=(legs[0][1], legs[1][1]), ankles=(legs[0][2], legs[1][2]),
        toes=(toes[0], toes[1]),
        shoulders=(arms[0][0], arms[1][0]), elbows=(arms[0][1], arms[1][1]), wrists=(arms[0][2], arms[1][2]))


def head_centre(skeleton: Skeleton, head: int, global_rot, global_pos) -> tuple[np.ndarray, np.ndarray]:
    """(F, 3) centre and top of the head joint ``head``: the centre is the midpoint of the eyes when the head
    has children named like eyes, else the middle of the head bone (the head joint to its End Site), else
    the head joint itself; the top is the eyes' midpoint or the End Site (the head joint when neither)."""
    pos = np.asarray(global_pos, dtype=np.float64)
    joint = pos[:, head]
    eyes = [int(k) for k in skeleton.children(head) if "eye" in skeleton.names[k].lower()]
    if eyes:
        top = pos[:, eyes].mean(axis=1)
        return top, top
    if head in skeleton.end_sites:
        top = joint + rot.apply(np.asarray(global_rot)[:, head], skeleton.end_sites[head])
        return 0.5 * (joint + top), top
    return joint, joint


def bone_masses(skeleton: Skeleton, body_mass_kg: float = 70.0) -> np.ndarray:
    """A mass per joint proportional to the length of the bone ending at it.

    A skeleton-agnostic stand-in for segment masses: long bones (thighs, spine)
    weigh more than fingers, and zero-length helper joints weigh nothing.
    """
    lengths = np.linalg.norm(skeleton.offsets, axis=1)
    lengths[0] = 0.0
    total = lengths.sum()
    if total <= 0:
        return np.full(skeleton.n_joints, body_mass_kg / skeleton.n_joints)
    return body_mass_kg * lengths / total

"""Left-right mirroring of motion: mirrored takes in the database, and data augmentation for the
neural pose generator.

A motion is reflected across the character's sagittal plane: the world axis its left and right
sides lie along (``lateral_axis``: X for a character facing +Z, as most rigs; Z for the G1 robot,
which faces +X) changes sign. With that reflection M a rotation R becomes M R M; for the
quaternion (v, w) that is (-M v, w), e.g. (x, -y, -z, w) across X. Each joint takes the reflected
local rotation of its left/right counterpart (``mirror_pairs``), the root's position is reflected
and the (left, right) foot contacts swap. The result is exact when the skeleton is
mirror-symmetric (the offset of a joint's counterpart is its reflected offset);
``symmetry_error`` says how far a skeleton is from that, so a caller can decide whether
mirroring its motion is valid.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..types import Skeleton
from .roles import _side_and_part


def lateral_axis(skeleton: Skeleton) -> int:
    """The rest pose's left-right axis (0 = X, 1 = Y, 2 = Z): the one along which the paired joints'
    offsets differ most (the hips and shoulders stand apart sideways)."""
    pairs = mirror_pairs(skeleton)
    spread = np.abs(skeleton.offsets - skeleton.offsets[pairs]).sum(axis=0)
    return int(np.argmax(spread)) if spread.any() else 0


def _reflection(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """The reflection of positions (3,) and of quaternions (4,) across the skeleton's sagittal plane."""
    vec = np.ones(3)
    vec[lateral_axis(skeleton)] = -1.0
    return vec, np.r_[-vec, 1.0]


def mirror_pairs(skeleton: Skeleton) -> np.ndarray:
    """Index of each joint's left/right counterpart (J,), the joint itself for centre joints.

    Joints are matched by name (``lFoot``/``rFoot``, ``LeftHand``/``RightHand``, ``thigh_l``/
    ``thigh_r``, with prefixes such as ``mixamorig:``): the same side-and-part reading as
    ``roles``. A sided joint without a counterpart maps to itself.
    """
    parsed = [_side_and_part(n) for n in skeleton.names]
    pairs = np.arange(skeleton.n_joints)
    by_key: dict[tuple[str, str], list[int]] = {}
    for j, key in enumerate(parsed):
        by_key.setdefault(key, []).append(j)
    for j, (side, part) in enumerate(parsed):
        if side == "l":
            lefts, rights = by_key[("l", part)], by_key.get(("r", part), [])
            k = lefts.index(j)   # the k-th left joint of a part pairs with the k-th right one
            if k < len(rights):
                pairs[j], pairs[rights[k]] = rights[k], j
    return pairs


def symmetry_error(skeleton: Skeleton) -> float:
    """Largest |offset[pair(j)] - M offset[j]| (skeleton units, metres here) over non-root joints.

    0 for a mirror-symmetric skeleton; mirrored joint positions are off by at most this
    times the depth of the hierarchy.
    """
    pairs = mirror_pairs(skeleton)
    off = skeleton.offsets
    err = np.linalg.norm(off[pairs] - off * _reflection(skeleton)[0], axis=-1)[skeleton.parents >= 0]
    return float(err.max()) if err.size else 0.0


def mirror_motion(skeleton: Skeleton, local_rot, root_pos, contacts=None):
    """Reflect a motion across the sagittal plane: ``(local_rot_m, root_pos_m, contacts_m)``.

    ``local_rot`` (..., J, 4) scalar-last quaternions, ``root_pos`` (..., 3), ``contacts``
    (..., 2) as (left, right) or None (then None comes back). Mirroring twice gives the input.
    Raises ``InputError`` when the skeleton's joint names give no left/right pairs, or the
    pairs do not match its hierarchy.
    """
    pairs = mirror_pairs(skeleton)
    if np.all(pairs == np.arange(skeleton.n_joints)):
        raise InputError(
            f"cannot mirror: no left/right joint pairs found in skeleton ({', '.join(skeleton.names[:8])}, ...); "
            "name paired joints e.g. LeftHand/RightHand, lHand/rHand or hand_l/hand_r")
    parents = skeleton.parents
    mapped = np.where(parents >= 0, pairs[np.maximum(parents, 0)], -1)
    bad = np.flatnonzero(parents[pairs] != mapped)
    if bad.size:
        j = int(bad[0])
        raise InputError(
            f"cannot mirror: joint '{skeleton.names[j]}' pairs with '{skeleton.names[pairs[j]]}', "
            "but their parents are not a left/right pair; the skeleton's two sides must have the same hierarchy")
    local_rot = np.asarray(local_rot, dtype=np.float64)
    if local_rot.shape[-2:] != (skeleton.n_joints, 4):
        raise InputError(f"local_rot must be (..., {skeleton.n_joints}, 4), got {local_rot.shape}")
    vec, quat = _reflection(skeleton)
    local_rot_m = local_rot[..., pairs, :] * quat
    root_pos_m = np.asarray(root_pos, dtype=np.float64) * vec
    contacts_m = None if contacts is None else np.asarray(contacts)[..., ::-1].copy()
    return local_rot_m, root_pos_m, contacts_m

"""A character a dance can be put on: a rig (skeleton, rest pose, humanoid bones), maybe a skinned mesh.

``load_character(spec)`` takes a built-in's name (``rigs.LAYOUTS``) or a file: a BVH (its
joint names, hierarchy and offsets are the rig; its rest pose is the zero rotation), or a
glTF/GLB/VRM (0.x or 1.0) model, whose skin's joints, node rest pose and, for VRM, humanoid
bone table define the target. Bones are found by ``humanoid.find_bones``; a TOML file
(``[bones]``, humanoid bone = joint name) overrides what it finds.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..types import Skeleton


@dataclass(frozen=True, eq=False)
class Mesh:
    """A skinned triangle mesh bound to a character's skeleton in its rest pose.

    Positions and normals are in metres, in the rest pose (the bind pose), in the
    character's world frame (Y up). ``joints``/``weights``: up to four skeleton joints per
    vertex with weights summing to 1. ``colours``: linear RGB per vertex, 0..1.
    """

    positions: np.ndarray   # (V, 3) float32
    normals: np.ndarray     # (V, 3) float32, unit
    indices: np.ndarray     # (T, 3) uint32, counter-clockwise seen from outside
    joints: np.ndarray      # (V, 4) uint16
    weights: np.ndarray     # (V, 4) float32
    colours: np.ndarray     # (V, 3) float32


@dataclass(frozen=True, eq=False)
class Character:
    """A retargeting target.

    ``skeleton`` is rooted at the character's hips, offsets in metres. ``rest_rot`` (J, 4)
    holds each joint's local rotation in the rest pose (identity for a BVH rig; a glTF
    model's node rotations; the root's includes the rotation of everything above the
    hips), so forward kinematics of ``rest_rot`` at ``rest_root`` is the rest pose in world
    space. ``bones`` maps VRM humanoid bone names to joint indices. A file character keeps
    the file (``source``) and each joint's glTF node (``nodes``) so the dance can be added to
    the user's own model; ``armature`` is the 4x4 world transform of the hips' parent node
    (metres), which the exporter undoes for the hips' animated translation.
    """

    name: str
    skeleton: Skeleton
    bones: dict[str, int]
    rest_rot: np.ndarray
    rest_root: np.ndarray
    mesh: Mesh | None = None
    source: Path | None = None
    nodes: tuple[int, ...] | None = None
    armature: np.ndarray = field(default_factory=lambda: np.eye(4))
    kind: str = "builtin"     # "builtin" | "bvh" | "gltf" | "vrm0" | "vrm1"

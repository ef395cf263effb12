"""What to draw of a skeleton: its points (joints, then End Sites), the bones between them, their
thicknesses and colours (left blue, right orange), and where they are in a clip's frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import rotations as rot
from ..errors import ModelError
from ..kinematics import fk
from ..motion.roles import find_roles
from ..types import MotionClip

COLOURS = {"l": (40, 110, 210), "r": (226, 92, 46), "": (72, 78, 92)}


@dataclass(frozen=True)
class Figure:
    """What to draw of a skeleton: points (joints then End Sites) and bones between them."""

    end_joints: np.ndarray     # (E,) joint of each End Site
    end_offsets: np.ndarray    # (E, 3)
    bones: np.ndarray          # (B, 2) point indices (parent, child)
    bone_radius: np.ndarray    # (B,) metres
    bone_colour: np.ndarray    # (B, 3) float
    joint_radius: np.ndarray   # (P,) metres, 0: no disc
    joint_colour: np.ndarray   # (P, 3) float
    head_points: np.ndarray    # points whose mean is the head's centre (empty: no head)
    head_radius: float

    @property
    def n_points(self) -> int:
        return len(self.joint_radius)


def build_figure(skeleton, body_height: float | None = None) -> Figure:
    """Choose bones, thicknesses and colours (left blue, right orange) for a skeleton.

    Thicknesses scale with ``body_height`` (metres; default: the rest pose's height).
    """
    parents = skeleton.parents
    end_joints = np.array(sorted(skeleton.end_sites), dtype=np.int64)
    end_offsets = np.array([skeleton.end_sites[j] for j in end_joints]).reshape(-1, 3)
    point_parent = np.concatenate([parents, end_joints])
    offsets = np.vstack([skeleton.offsets, end_offsets])
    n_p = len(point_parent)

    def subtree(top):
        inside = np.zeros(n_p, bool)
        if top < 0:
            return inside
        inside[top] = True
        for p in range(n_p):  # parents come before children; End Sites after all joints
            if point_parent[p] >= 0 and inside[point_parent[p]]:
                inside[p] = True
        return inside

    side = np.full(n_p, "", dtype=object)
    head = -1
    try:
        roles = find_roles(skeleton)
        head = roles.head
        for k, s in enumerate("lr"):
            for top in (roles.hips[k], roles.shoulders[k]):
                side[subtree(top)] = s
    except ModelError:
        pass
    if head < 0:
        head = next((j for j, n in enumerate(skeleton.names) if "head" in n.lower()), -1)
    in_head = subtree(head)
    if head >= 0:
        in_head[head] = False

    if body_height is None:
        body_height = _rest_height(skeleton, offsets, point_parent)
    scale = max(body_height, 1e-6) / 1.7  # a 1.7 m person: scale 1
    bones, radius, colour = [], [], []
    for p in range(1, n_p):
        a = int(point_parent[p])
        length = float(np.linalg.norm(offsets[p]))
        if a < 0 or in_head[p] or length < 1e-3 * scale:
            continue
        r = float(np.clip(0.1 * length, 0.007 * scale, 0.03 * scale))
        if side[p] == "":
            r *= 1.3
        bones.append((a, p))
        radius.append(r)
        colour.append(COLOURS[side[p]])
    bones = np.array(bones, dtype=np.int64).reshape(-1, 2)
    radius = np.array(radius, dtype=np.float64)
    joint_radius = np.zeros(n_p)
    for (a, b), r in zip(bones, radius):
        joint_radius[a] = max(joint_radius[a], 1.2 * r)
        joint_radius[b] = max(joint_radius[b], 1.2 * r)
    joint_radius[joint_radius < 0.014 * scale] = 0.0  # no beads on fingers
    joint_colour = np.array([COLOURS[s] for s in side], dtype=np.float64) * 0.7
    head_points = np.flatnonzero(subtree(head)) if head >= 0 else np.zeros(0, np.int64)
    return Figure(end_joints, end_offsets, bones, radius, np.array(colour, np.float64).reshape(-1, 3),
                  joint_radius, joint_colour, head_points, 0.1 * scale)


def _rest_height(skeleton, offsets, point_parent) -> float:
    pos = np.zeros((len(point_parent), 3))
    for p in range(1, len(point_parent)):
        pos[p] = pos[point_parent[p]] + offsets[p]
    return float(np.ptp(pos[:, 1])) if len(pos) > 1 else 1.0


def clip_pose(clip: MotionClip, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global joint rotations (len(frames), J, 4) and positions (len(frames), J, 3) of the given frames."""
    sk = clip.skeleton
    local_pos = None if clip.local_pos is None else clip.local_pos[frames]
    return fk(clip.local_rot[frames], clip.root_pos[frames], sk.offsets, sk.parents, local_pos)


def pose_points(g_rot: np.ndarray, g_pos: np.ndarray, fig: Figure) -> np.ndarray:
    """World positions (..., P, 3) of joints and End Sites, from global joint rotations and positions."""
    if len(fig.end_joints) == 0:
        return g_pos
    ends = g_pos[..., fig.end_joints, :] + rot.apply(g_rot[..., fig.end_joints, :], fig.end_offsets)
    return np.concatenate([g_pos, ends], axis=-2)


def figure_points(clip: MotionClip, fig: Figure, frames: np.ndarray) -> np.ndarray:
    """World positions (len(frames), P, 3) of joints and End Sites of the given frames."""
    return pose_points(*clip_pose(clip, frames), fig)

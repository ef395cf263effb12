"""Keep planted feet where the source motion kept them.

Time-warping never makes a foot slide: it only changes when a pose is shown. Blending
across a jump does, because the pose is pulled from the old motion towards the new.
So while the source says a foot is in contact, the ankle is made to follow the
source's own ankle motion from where the contact began (the source's pivots and
slides stay; the drift the blend adds goes), by two-bone leg IK. When the contact
ends the correction fades out over ``release_s``. The pass is incremental
(``FootLockState``) so the streaming engine applies it segment by segment.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import rotations as rot
from ..kinematics import fk, two_bone_ik
from ..motion.roles import JointRoles
from ..types import Skeleton
from .stitch import Rendered


@dataclass(frozen=True)
class FootLockState:
    locked: np.ndarray = field(default_factory=lambda: np.zeros(2, dtype=bool))
    target: np.ndarray = field(default_factory=lambda: np.zeros((2, 3)))     # where the ankle should be now
    raw_prev: np.ndarray = field(default_factory=lambda: np.zeros((2, 3)))   # last raw ankle position
    release_left: np.ndarray = field(default_factory=lambda: np.zeros(2))   # fade-out frames left
    release_delta: np.ndarray = field(default_factory=lambda: np.zeros((2, 3)))


def lock_feet(skeleton: Skeleton, roles: JointRoles, frames: Rendered, state: FootLockState, *,
              fps: float, release_s: float = 0.2):
    """Return ``(local_rot, state)``: ``frames.local_rot`` with planted feet held."""
    local_rot = frames.local_rot
    n = len(local_rot)
    if n == 0:
        return local_rot, state
    ankles = list(roles.ankles)
    g_rot, g_pos = fk(local_rot, frames.root_pos, skeleton.offsets, skeleton.parents, only=ankles)
    _, raw_pos = fk(frames.raw_local, frames.raw_root, skeleton.offsets, skeleton.parents, only=ankles)
    release_frames = max(1.0, release_s * fps)
    locked, target = state.locked.copy(), state.target.copy()
    raw_prev, rel_left, rel_delta = state.raw_prev.copy(), state.release_left.copy(), state.release_delta.copy()
    out = local_rot.copy()
    for side in range(2):
        chain = (roles.hips[side], roles.knees[side], roles.ankles[side])
        ankle, raw = g_pos[:, chain[2]], raw_pos[:, chain[2]]
        delta = np.zeros((n, 3))
        for t in range(n):
            if frames.contacts[t, side]:
                if not locked[side]:
                    locked[side], target[side], rel_left[side] = True, ankle[t], 0.0
                elif not frames.new_run[t]:
                    target[side] = target[side] + (raw[t] - raw_prev[side])  # the source's own foot motion
                delta[t] = target[side] - ankle[t]
            else:
                if locked[side]:
                    locked[side] = False
                    rel_delta[side] = delta[t - 1] if t > 0 else target[side] - ankle[t]
                    rel_left[side] = release_frames
                if rel_left[side] > 0:
                    delta[t] = rel_delta[side] * (rel_left[side] / release_frames)
                    rel_left[side] -= 1.0
            raw_prev[side] = raw[t]
        sel = np.flatnonzero(np.linalg.norm(delta, axis=-1) > 1e-5)
        if not sel.size:
            continue
        g_rot_s, g_pos_s = fk(local_rot[sel], frames.root_pos[sel], skeleton.offsets, skeleton.parents,
                              only=[chain[2]])
        new = two_bone_ik(g_rot_s, g_pos_s, chain, ankle[sel] + delta[sel])
        parent = skeleton.parents[chain[0]]
        out[sel, chain[0]] = rot.mul(rot.inv(g_rot_s[:, parent]), new[:, 0])
        out[sel, chain[1]] = rot.mul(rot.inv(new[:, 0]), new[:, 1])
        out[sel, chain[2]] = rot.mul(rot.inv(new[:, 1]), new[:, 2])
    return out, FootLockState(locked, target, raw_prev, rel_left, rel_delta)

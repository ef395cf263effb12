"""Keep the hands out of the head: a two-bone arm IK that moves a wrist out to a clearance sphere.

A generated dance (the neural engine) sometimes brings a wrist into the head, which mocap
never does. Where a wrist comes nearer the head's centre than ``clearance``, the arm is bent
and swung (``kinematics.two_bone_ik`` on shoulder, elbow, wrist) so that the wrist sits on
the sphere of that radius instead. The push is eased in and out over ``ease_s`` on each side
(a dilated, then Hann-smoothed envelope that never falls below what a frame needs), along one
direction per visit, so the arm never jumps; frames away from a visit are left exactly as they were.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import label, maximum_filter1d

from ..kinematics import chain_local_rotations, fk, two_bone_ik
from ..motion.roles import JointRoles, head_centre
from ..types import Skeleton

CLEARANCE_M = 0.12   # the eval counts a wrist within 8 cm of the head's centre as inside it
EASE_S = 0.2


def _envelope(need: np.ndarray, radius: int) -> np.ndarray:
    """At least ``need`` at every frame, rising and falling smoothly over ``radius`` frames."""
    dilated = maximum_filter1d(need, 2 * radius + 1, mode="constant")
    window = np.hanning(2 * radius + 3)[1:-1]
    # Each smoothed frame averages dilated frames within ``radius``, all >= its own need.
    return np.convolve(np.pad(dilated, radius, mode="edge"), window / window.sum(), mode="valid")


def _push(away: np.ndarray, direction: np.ndarray, clearance: float) -> np.ndarray:
    """How far along ``direction`` (unit) a wrist at ``away`` from the head's centre must move to reach the
    clearance sphere (0 where it is outside already): the positive root of |away + s d| = clearance."""
    along, gap = away @ direction, clearance ** 2 - np.einsum("ij,ij->i", away, away)
    return np.where(gap > 0, -along + np.sqrt(np.maximum(along ** 2 + gap, 0.0)), 0.0)


def keep_hands_out_of_head(skeleton: Skeleton, roles: JointRoles, local_rot: np.ndarray, root_pos: np.ndarray,
                           fps: float, *, clearance: float = CLEARANCE_M, ease_s: float = EASE_S) -> np.ndarray:
    """Local rotations with every wrist kept at least ``clearance`` metres from the head's centre.

    Each visit of a wrist to the head is pushed out along one direction, the mean of where the wrist
    is inside the sphere (weighted by how deep): a wrist that sweeps through the head's centre would
    flip a per-frame "straight out" direction from one side to the other.
    """
    if roles.head < 0 or min(roles.shoulders + roles.elbows + roles.wrists) < 0:
        return local_rot
    g_rot, g_pos = fk(local_rot, root_pos, skeleton.offsets, skeleton.parents)
    centre, _ = head_centre(skeleton, roles.head, g_rot, g_pos)
    radius = max(int(round(ease_s * fps)), 1)
    out = local_rot.copy()
    for chain in zip(roles.shoulders, roles.elbows, roles.wrists):
        away = g_pos[:, chain[2]] - centre
        depth = np.maximum(clearance - np.linalg.norm(away, axis=-1), 0.0)
        visits, n = label(_envelope(depth, radius) > 1e-9)
        shift = np.zeros_like(away)
        for v in range(1, n + 1):
            frames = np.flatnonzero(visits == v)
            mean = (away[frames] * depth[frames, None]).sum(axis=0)
            if np.linalg.norm(mean) < 1e-6:   # a wrist exactly at the centre: out past its shoulder
                mean = (g_pos[frames, chain[0]] - centre[frames]).mean(axis=0)
            direction = mean / np.linalg.norm(mean)
            need = np.zeros(len(away))
            need[frames] = _push(away[frames], direction, clearance)
            shift += _envelope(need, radius)[:, None] * direction
        sel = np.flatnonzero(np.abs(shift).sum(axis=1) > 1e-9)
        if not sel.size:
            continue
        rows, cols = sel[:, None], np.array(chain)
        new = two_bone_ik(g_rot[rows, cols], g_pos[rows, cols], (0, 1, 2), g_pos[sel, chain[2]] + shift[sel])
        out[rows, cols] = chain_local_rotations(g_rot[sel, skeleton.parents[chain[0]]], new)
    return out

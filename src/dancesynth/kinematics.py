"""Forward kinematics and small analytic IK, batched over frames."""

from __future__ import annotations

import numpy as np

from . import rotations as rot


def fk(local_rot, root_pos, offsets, parents, local_pos=None):
    """Global joint rotations and positions.

    ``local_rot`` (..., J, 4), ``root_pos`` (..., 3), ``offsets`` (J, 3), ``parents`` (J,).
    ``local_pos`` (..., J, 3), when given, replaces the offsets (animated translations).
    Returns ``(global_rot (..., J, 4), global_pos (..., J, 3))``.
    """
    local_rot = np.asarray(local_rot, dtype=np.float64)
    n_joints = local_rot.shape[-2]
    g_rot = np.empty_like(local_rot)
    g_pos = np.empty(local_rot.shape[:-1] + (3,))
    for j in range(n_joints):
        p = parents[j]
        if p < 0:
            g_rot[..., j, :] = local_rot[..., j, :]
            g_pos[..., j, :] = root_pos
            continue
        off = offsets[j] if local_pos is None else local_pos[..., j, :]
        g_rot[..., j, :] = rot.mul(g_rot[..., p, :], local_rot[..., j, :])
        g_pos[..., j, :] = g_pos[..., p, :] + rot.apply(g_rot[..., p, :], off)
    return g_rot, g_pos


def clip_fk(clip):
    """``fk`` of a ``MotionClip``."""
    sk = clip.skeleton
    return fk(clip.local_rot, clip.root_pos, sk.offsets, sk.parents, clip.local_pos)

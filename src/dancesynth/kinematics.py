"""Forward kinematics and small analytic IK, batched over frames."""

from __future__ import annotations

import numpy as np

from . import rotations as rot


def fk(local_rot, root_pos, offsets, parents, local_pos=None, only=None):
    """Global joint rotations and positions.

    ``local_rot`` (..., J, 4), ``root_pos`` (..., 3), ``offsets`` (J, 3), ``parents`` (J,).
    ``local_pos`` (..., J, 3), when given, replaces the offsets (animated translations).
    ``only``: compute just these joints and their ancestors (the rest is NaN).
    Returns ``(global_rot (..., J, 4), global_pos (..., J, 3))``.
    """
    local_rot = np.asarray(local_rot, dtype=np.float64)
    n_joints = local_rot.shape[-2]
    g_rot = np.full_like(local_rot, np.nan)
    g_pos = np.full(local_rot.shape[:-1] + (3,), np.nan)
    needed = range(n_joints)
    if only is not None:
        keep = set()
        for j in only:
            while j >= 0 and j not in keep:
                keep.add(int(j))
                j = parents[j]
        needed = sorted(keep)
    for j in needed:
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


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _rotation_between(u, v):
    """Shortest-arc quaternions turning directions ``u`` into ``v`` (..., 3)."""
    u, v = _unit(u), _unit(v)
    axis = np.cross(u, v)
    w = 1.0 + np.sum(u * v, axis=-1, keepdims=True)
    q = np.concatenate([axis, w], axis=-1)
    # Opposite directions: turn 180 degrees about any axis perpendicular to u.
    opposite = w[..., 0] < 1e-9
    if np.any(opposite):
        perp = np.cross(u[opposite], [1.0, 0.0, 0.0])
        bad = np.linalg.norm(perp, axis=-1) < 1e-6
        perp[bad] = np.cross(u[opposite][bad], [0.0, 1.0, 0.0])
        q[opposite] = np.concatenate([_unit(perp), np.zeros((len(perp), 1))], axis=-1)
    return _unit(q)


def two_bone_ik(g_rot, g_pos, chain, target, hinge_axis=(1.0, 0.0, 0.0)):
    """Bend and swing a two-bone chain (e.g. hip-knee-ankle) so its end reaches ``target``.

    ``g_rot`` (F, J, 4) and ``g_pos`` (F, J, 3) are global transforms, ``chain`` the
    (top, middle, end) joint indices, ``target`` (F, 3). The middle joint's interior
    angle is set by the law of cosines (bending in the chain's own plane), then the
    top joint swings the chain onto the target; the end keeps its global orientation.
    Targets out of reach are approached as closely as the bone lengths allow.
    Returns new global rotations (F, 3, 4) of (top, middle, end).
    """
    top, mid, end = chain
    h, k, a = g_pos[:, top], g_pos[:, mid], g_pos[:, end]
    len_a = np.linalg.norm(k - h, axis=-1)
    len_b = np.linalg.norm(a - k, axis=-1)
    c = np.clip(np.linalg.norm(target - h, axis=-1), np.abs(len_a - len_b) + 1e-6, len_a + len_b - 1e-6)
    u, v = h - k, a - k
    cur = np.arccos(np.clip(np.sum(_unit(u) * _unit(v), axis=-1), -1.0, 1.0))
    want = np.arccos(np.clip((len_a**2 + len_b**2 - c**2) / (2 * len_a * len_b), -1.0, 1.0))
    n = np.cross(u, v)
    straight = np.linalg.norm(n, axis=-1) < 1e-8
    if np.any(straight):
        n[straight] = rot.apply(g_rot[straight, mid], np.asarray(hinge_axis, dtype=float))
    bend = rot.exp(_unit(n) * (want - cur)[:, None])
    mid_rot = rot.mul(bend, g_rot[:, mid])
    a1 = k + rot.apply(bend, v)
    swing = _rotation_between(a1 - h, target - h)
    new_top = rot.mul(swing, g_rot[:, top])
    new_mid = rot.mul(swing, mid_rot)
    return np.stack([new_top, new_mid, g_rot[:, end]], axis=1)

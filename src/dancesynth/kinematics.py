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


def bend_axis(g_rot, g_pos, chain) -> np.ndarray:
    """The axis (3,), in the top joint's frame, about which a two-bone chain bends (a knee's hinge).

    Each frame's bend-plane normal ``(top - mid) x (end - mid)`` is taken into the
    top joint's frame and the normals are summed: a hinge bends one way, so bent
    frames agree and nearly straight ones (short normals) hardly count. Zero when
    no frame bends.
    """
    top, mid, end = chain
    n = np.cross(g_pos[:, top] - g_pos[:, mid], g_pos[:, end] - g_pos[:, mid])
    total = rot.apply(rot.inv(g_rot[:, top]), n).sum(axis=0)
    norm = np.linalg.norm(total)
    return total / norm if norm > 1e-9 else np.zeros(3)


def two_bone_ik(g_rot, g_pos, chain, target, hinge_axis=None, *, bend_toward=None, pole_weight: float = 1.0,
                soft: float = 0.03, pole_sin: float = 0.17):
    """Bend and swing a two-bone chain (e.g. hip-knee-ankle) so its end reaches ``target``.

    ``g_rot`` (F, J, 4) and ``g_pos`` (F, J, 3) are global transforms, ``chain`` the
    (top, middle, end) joint indices, ``target`` (F, 3). The middle joint's interior
    angle is set by the law of cosines, bending in the chain's own plane, then the
    top joint swings the chain onto the target; the end keeps its global orientation.
    A target at the end's current position changes nothing (for a chain bent the
    right way).

    Two things keep the result continuous from frame to frame:

    - the pole: a nearly straight chain has no plane of its own (its normal is
      noise), so within ``pole_sin`` (sine of the angle from straight) the bend
      leans smoothly towards the side the middle joint belongs on, and a chain bent
      the wrong way is read as bent the right way, so the middle joint never flips
      sides (a target at the end then still turns a wrong-way chain round). That
      side is ``bend_toward`` (F, 3), a world direction per frame (a knee points
      over the toes), else the hinge ``hinge_axis`` (3,) in the top joint's frame,
      else ``bend_axis`` of these frames. ``pole_weight`` (0 to 1) says how far to
      trust it: below 1 a wrong-way bend is only partly turned round;
    - soft reach: beyond the farther of the current reach and ``(1 - soft)`` of
      full length the reach approaches full length exponentially instead of being
      clamped, so the middle joint never snaps straight when a target passes out
      of reach (the end then stops short of the target, along its line).

    Returns new global rotations (F, 3, 4) of (top, middle, end).
    """
    top, mid, end = chain
    h, k, a = g_pos[:, top], g_pos[:, mid], g_pos[:, end]
    len_a = np.linalg.norm(k - h, axis=-1)
    len_b = np.linalg.norm(a - k, axis=-1)
    full = len_a + len_b
    reach = np.linalg.norm(target - h, axis=-1)
    soft_from = np.maximum(full * (1.0 - soft), np.linalg.norm(a - h, axis=-1))
    zone = np.maximum(full - soft_from, 1e-9)
    beyond = np.maximum(reach - soft_from, 0.0)
    reach = np.where(beyond > 0, soft_from + zone * (1.0 - np.exp(-beyond / zone)), reach)
    reach = np.clip(reach, np.abs(len_a - len_b) + 1e-6, full - 1e-9)
    want = np.arccos(np.clip((len_a**2 + len_b**2 - reach**2) / (2 * len_a * len_b), -1.0, 1.0))
    u = _unit(h - k)
    v = _unit(a - k)
    n = np.cross(u, v)
    if bend_toward is not None:
        # A middle joint displaced towards d bends the chain about d x (top - end); its length
        # says how well d defines a side (not at all along the chain), and weighs the pole.
        pole = np.cross(_unit(np.asarray(bend_toward, float)), _unit(h - a))
        strength = np.clip(np.linalg.norm(pole, axis=-1, keepdims=True) / 0.5, 0.0, 1.0)
        pole = _unit(pole)
    else:
        hinge = bend_axis(g_rot, g_pos, chain) if hinge_axis is None else _unit(np.asarray(hinge_axis, float))
        pole = rot.apply(g_rot[:, top], hinge if np.any(hinge) else np.array([1.0, 0.0, 0.0]))
        strength = np.ones(n.shape[:-1] + (1,))
    # Bent the wrong way past straight (mocap knees do, by a few degrees, and blends through straight
    # more): mirror onto the pole's side. A slight wrong-way bend is turned round fully, or a target
    # asking for more bend than the input has would bend the knee backwards, and swing it from one
    # side to the other as the input passes through straight; a clear one (beyond ~2 pole_sin) only
    # by ``pole_weight``, as a leg bent that way means the pole (the toes) is the poor guide there.
    # Mirroring every wrong-way bend by an amount continuous in the bend keeps the result continuous.
    along = np.sum(n * pole, axis=-1, keepdims=True)
    slight = np.clip(1.0 - np.linalg.norm(n, axis=-1, keepdims=True) / (2.0 * pole_sin), 0.0, 1.0)
    n = n - 2.0 * strength * (pole_weight + (1.0 - pole_weight) * slight) * np.minimum(along, 0.0) * pole
    # A nearly straight chain's plane is noise: it leans towards the pole by ``pole_weight``, and
    # fully where the target asks for much more bend than the chain has (its plane would then
    # show, and swing as the noise does).
    more = np.clip((np.arccos(np.clip(np.sum(u * v, axis=-1), -1.0, 1.0)) - want) / np.radians(20.0), 0.0, 1.0)
    lean = strength * (pole_weight + (1.0 - pole_weight) * more[:, None]) * np.clip(
        1.0 - np.linalg.norm(n, axis=-1, keepdims=True) / pole_sin, 0.0, 1.0) ** 2
    side = _unit(np.cross(n + pole_sin * lean * pole, u))  # where the lower bone leaves the upper bone's line
    w = np.cos(want)[:, None] * u + np.sin(want)[:, None] * side
    bend = _rotation_between(v, w)
    mid_rot = rot.mul(bend, g_rot[:, mid])
    a1 = k + len_b[:, None] * w
    swing = _rotation_between(a1 - h, target - h)
    new_top = rot.mul(swing, g_rot[:, top])
    new_mid = rot.mul(swing, mid_rot)
    return np.stack([new_top, new_mid, g_rot[:, end]], axis=1)


def chain_local_rotations(parent_rot, chain_rot):
    """Local rotations (F, 3, 4) of a (top, middle, end) chain from its solved global ones (``two_bone_ik``)
    and the global rotation (F, 4) of the top joint's parent."""
    return rot.mul(rot.inv(np.stack([parent_rot, chain_rot[:, 0], chain_rot[:, 1]], axis=1)), chain_rot)

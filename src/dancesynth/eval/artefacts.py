"""Visible artefacts of a rendered motion: one-frame snaps and hands inside the head.

Pure functions of the motion (no files, no printing), in the style of
``motion_metrics``: they take a ``MotionClip`` and return arrays or numbers. The
floor artefact (feet below the floor) is ``motion_metrics.ground_penetration``.
"""

from __future__ import annotations

import numpy as np

from .. import rotations as rot
from ..errors import InputError
from ..kinematics import clip_fk
from ..motion.roles import find_roles
from ..types import MotionClip
from .motion_metrics import check_motion

#: A snap's neighbouring frame pairs may turn the joint at most this share of the snap.
CALM_FRACTION = 1.0 / 3.0
DEFAULT_STEP_DEG = 30.0
#: A dance plays its source at most about twice as fast (accent timing 1.6x times a 1.25x warp),
#: so a source turning a joint by half the dance's snap over the same frame pair explains it.
SOURCE_SHARE = 0.5
DEFAULT_HEAD_RADIUS_M = 0.08  # about half an adult head's width


def joint_steps_deg(local_rot) -> np.ndarray:
    """Geodesic angle (degrees) each joint turns from frame f to f+1: shape (F-1, J).

    ``local_rot`` (F, J, 4) unit quaternions, or a ``MotionClip``.
    """
    q = _local_rot(local_rot)
    return np.degrees(rot.angle(q[1:], q[:-1]))


def one_frame_steps(motion, *, threshold_deg: float = DEFAULT_STEP_DEG) -> np.ndarray:
    """Isolated one-frame snaps of single joints: ``(N, 2)`` int array of ``(frame, joint)``.

    With ``d(f)`` the angle joint j turns between frames f and f+1
    (``joint_steps_deg``) and ``T = threshold_deg``, two shapes count, each once:

    - a *step* at ``f``: ``d(f) > T`` while ``d(f-1) <= d(f) / 3`` and
      ``d(f+1) <= d(f) / 3`` -- the joint jumps to a new rotation in one frame and
      is calm before and after (a knee pole flipping and staying flipped);
    - a *pop* at ``f``: frame f+1 is out of line -- ``d(f) > T`` and ``d(f+1) > T``,
      yet frames f and f+2 differ by at most ``m / 3`` with ``m = min(d(f), d(f+1))``,
      and ``d(f-1) <= m / 3`` and ``d(f+2) <= m / 3`` (one bad frame, there and back).

    A frame pair beyond either end of the motion counts as calm (turn 0). A fast
    but smooth rotation (a spin) turns by similar angles every frame and never
    counts. The reported ``frame`` is f: the snap happens between frames f and f+1.
    Rows are sorted by frame, then joint. ``motion`` is a ``MotionClip`` or its
    ``local_rot`` (F, J, 4); rotations are local (relative to the parent joint),
    the root's is its global orientation.
    """
    threshold = float(threshold_deg)
    if not threshold > 0:
        raise InputError(f"threshold_deg must be a positive angle in degrees, got {threshold_deg!r}")
    q = _local_rot(motion)
    d = joint_steps_deg(q)
    if not d.size:
        return np.zeros((0, 2), dtype=np.int64)
    pad = np.zeros((2,) + d.shape[1:])
    dp = np.concatenate([pad, d, pad])       # dp[f + 2] = d(f); beyond the ends: calm
    prev1, here, next1, next2 = dp[1:-3], dp[2:-2], dp[3:-1], dp[4:]
    step = (here > threshold) & (prev1 <= here * CALM_FRACTION) & (next1 <= here * CALM_FRACTION)
    m = np.minimum(here, next1)
    across = np.full_like(d, np.inf)         # angle between frames f and f+2
    if len(q) >= 3:
        across[:-1] = np.degrees(rot.angle(q[2:], q[:-2]))
    pop = ((here > threshold) & (next1 > threshold) & (across <= m * CALM_FRACTION)
           & (prev1 <= m * CALM_FRACTION) & (next2 <= m * CALM_FRACTION))
    return np.argwhere(step | pop).astype(np.int64)


def new_steps(motion, source, *, threshold_deg: float = DEFAULT_STEP_DEG, cuts=None) -> np.ndarray:
    """The ``one_frame_steps`` of ``motion`` that ``source`` does not explain: ``(N, 2)`` (frame, joint).

    ``source`` (F, J, 4) local rotations (or a ``MotionClip``) of what ``motion``
    shows before any clean-up, frame for frame -- for a dance, the mocap sampled at
    its source frames (``clip.meta["source_frames"]``). A snap of ``motion`` at
    (f, j) is the source's own when ``source`` turns joint j over the same frame
    pair f by more than ``threshold_deg``, or by at least ``SOURCE_SHARE`` of the
    snap (a glitch in the capture, played faster), unless f is in ``cuts``: frame
    pairs where ``source`` jumps from one piece of mocap to another, which no
    captured motion explains.
    """
    steps = one_frame_steps(motion, threshold_deg=threshold_deg)
    src = _local_rot(source)
    if src.shape != _local_rot(motion).shape:
        raise InputError(f"source must have the motion's shape {_local_rot(motion).shape}, got {src.shape}")
    if not len(steps):
        return steps
    f, j = steps[:, 0], steps[:, 1]
    q = _local_rot(motion)
    own = np.degrees(rot.angle(src[f + 1, j], src[f, j]))
    snap = np.degrees(rot.angle(q[f + 1, j], q[f, j]))
    explained = (own > float(threshold_deg)) | (own >= SOURCE_SHARE * snap)
    if cuts is not None:
        explained &= ~np.isin(f, np.asarray(cuts, dtype=np.int64))
    return steps[~explained]


def hand_in_head_frames(motion: MotionClip, *, radius_m: float | None = DEFAULT_HEAD_RADIUS_M,
                        global_rot=None, global_pos=None) -> float:
    """Share of frames (0 to 1) in which a wrist is inside the head.

    A wrist (``motion.roles.find_roles``: the end of either arm chain) is inside
    when it is within ``radius_m`` of the head's centre: the midpoint of the eyes
    when the head joint has children named like eyes, else the middle of the head
    bone (the head joint to its End Site), else the head joint itself. With
    ``radius_m=None`` the radius is half the head bone (the head joint to the
    eyes' midpoint or to its End Site, median over frames), for skeletons of
    unknown scale. ``global_rot`` / ``global_pos`` may be passed from
    ``kinematics.clip_fk``. NaN for a skeleton without a recognisable head or arms.
    """
    check_motion(motion)
    sk = motion.skeleton
    roles = find_roles(sk)
    wrists = [w for w in roles.wrists if w >= 0]
    if roles.head < 0 or not wrists:
        return float("nan")
    if global_rot is None or global_pos is None:
        global_rot, global_pos = clip_fk(motion)
    pos = np.asarray(global_pos, dtype=np.float64)
    if pos.shape != motion.local_rot.shape[:2] + (3,):
        raise InputError(f"global_pos must be (frames, joints, 3) = {motion.local_rot.shape[:2] + (3,)}, "
                         f"got {pos.shape}; pass kinematics.clip_fk(motion)[1]")
    head = pos[:, roles.head]
    eyes = [int(k) for k in sk.children(roles.head) if "eye" in sk.names[k].lower()]
    if eyes:
        top = pos[:, eyes].mean(axis=1)
        centre = top
    elif roles.head in sk.end_sites:
        top = head + rot.apply(np.asarray(global_rot)[:, roles.head], sk.end_sites[roles.head])
        centre = 0.5 * (head + top)
    else:
        top = centre = head
    if radius_m is None:
        radius = 0.5 * float(np.median(np.linalg.norm(top - head, axis=-1)))
        if not radius > 0:
            return float("nan")
    else:
        radius = float(radius_m)
        if not radius > 0:
            raise InputError(f"radius_m must be a positive distance in metres (or None: half the head), "
                             f"got {radius_m!r}")
    dist = np.linalg.norm(pos[:, wrists] - centre[:, None], axis=-1)
    return float(np.mean((dist < radius).any(axis=1)))


def _local_rot(motion) -> np.ndarray:
    if isinstance(motion, MotionClip):
        return np.asarray(check_motion(motion).local_rot, dtype=np.float64)
    q = np.asarray(motion, dtype=np.float64)
    if q.ndim != 3 or q.shape[-1] != 4:
        raise InputError(f"motion must be a MotionClip or local rotations (frames, joints, 4), got shape {q.shape}")
    if not np.all(np.isfinite(q)):
        raise InputError("local rotations have NaN or infinite values; repair or trim the motion")
    return q

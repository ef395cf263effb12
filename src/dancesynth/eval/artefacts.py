"""Visible artefacts of a rendered motion: one-frame snaps, hands inside the head, and the
foot sliding a dance adds to the source frames it plays.

Pure functions of the motion (no files, no printing), in the style of
``motion_metrics``: they take a ``MotionClip`` and return arrays or numbers. The
floor artefact (feet below the floor) is ``motion_metrics.ground_penetration``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .. import rotations as rot
from ..errors import InputError
from ..kinematics import clip_fk
from ..motion.resample import resample_clip_arrays
from ..motion.roles import find_roles, head_centre
from ..types import MotionClip
from .motion_metrics import check_motion, foot_skate, pfc

#: A snap's neighbouring frame pairs may turn the joint at most this share of the snap.
CALM_FRACTION = 1.0 / 3.0
DEFAULT_STEP_DEG = 30.0
#: A dance plays its source at most about twice as fast (accent timing 1.6x times a 1.25x warp),
#: so a source turning a joint by half the dance's snap over the same frame pair explains it.
SOURCE_SHARE = 0.5
DEFAULT_HEAD_RADIUS_M = 0.08  # about half an adult head's width
#: A run of a dance that plays one source clip forward, without a cut, counts when it lasts this long
#: (PFC and floor speed need some seconds to mean anything).
MIN_RUN_S = 1.0


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
    centre, top = head_centre(sk, roles.head, global_rot, pos)
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


def feet_vs_source(motion: MotionClip, source_frames, clips, clip_starts, *, min_run_s: float = MIN_RUN_S) -> dict:
    """Floor foot speed and PFC of a dance beside the same source frames played as captured.

    A dance's feet can slide because of the pieces it picks (a style's hops and slides)
    or because of what rendering does to them (time warp, accent timing, blends, the foot
    lock). The style's average mocap mixes both; this isolates the second. The dance is
    cut into runs that play one source clip forward without a cut (``source_frames`` (F,),
    flat source frame shown at each frame, as ``meta["source_frames"]``; ``clips`` the
    source clips as ``MotionClip`` in flat order, ``clip_starts`` their first flat frames,
    with one more entry at the end), each run at least ``min_run_s`` long. Each run is
    scored, and so are the source frames it spans at the source's own speed; the means are
    weighted by run length. Returns ``foot_skate`` and ``pfc`` for the dance, the same for
    the source (``source_``), their ratios (``_vs_source``), and the share of the dance's
    frames the runs cover. Values are None when no run is long enough.
    """
    check_motion(motion)
    src = np.asarray(source_frames, dtype=np.float64)
    if src.shape != (motion.n_frames,):
        raise InputError(f"source_frames needs one source frame per dance frame ({motion.n_frames}), "
                         f"got shape {src.shape}")
    starts = np.asarray(clip_starts, dtype=np.int64)
    step = clips[0].fps / motion.fps if clips else 1.0
    cut = np.flatnonzero((np.diff(src) <= 0) | (np.diff(src) > 2.5 * step)) + 1
    rows = []
    for run in np.split(np.arange(motion.n_frames), cut):
        if len(run) < max(min_run_s * motion.fps, 3):
            continue
        a, b = int(np.floor(src[run[0]])), int(np.ceil(src[run[-1]])) + 1
        c = int(np.searchsorted(starts, a, side="right") - 1)
        if c < 0 or c >= len(clips) or b > starts[c + 1]:
            continue  # a run that crosses clips is not one captured take
        whole, i, j = clips[c], a - starts[c], b - starts[c]
        # At the dance's frame rate: speeds and PFC by finite differences depend on it.
        local, root, _ = resample_clip_arrays(whole.local_rot[i:j], whole.root_pos[i:j], None, whole.fps, motion.fps)
        raw = replace(whole, fps=motion.fps, local_rot=local, root_pos=root, contacts=None, meta={})
        part = replace(motion, local_rot=motion.local_rot[run[0]:run[-1] + 1],
                       root_pos=motion.root_pos[run[0]:run[-1] + 1], contacts=None, meta={})
        rows.append((len(run), foot_skate(part), pfc(part), foot_skate(raw), pfc(raw)))
    rows = [r for r in rows if all(np.isfinite(r[1:]))]
    out = {"foot_skate": None, "pfc": None, "source_foot_skate": None, "source_pfc": None,
           "foot_skate_vs_source": None, "pfc_vs_source": None,
           "share": float(sum(r[0] for r in rows) / motion.n_frames) if rows else 0.0}
    if not rows:
        return out
    w = np.array([r[0] for r in rows], dtype=np.float64)
    mean = [float(np.average([r[i] for r in rows], weights=w)) for i in (1, 2, 3, 4)]
    out.update(foot_skate=mean[0], pfc=mean[1], source_foot_skate=mean[2], source_pfc=mean[3],
               foot_skate_vs_source=mean[0] / mean[2] if mean[2] > 0 else None,
               pfc_vs_source=mean[1] / mean[3] if mean[3] > 0 else None)
    return out


def _local_rot(motion) -> np.ndarray:
    if isinstance(motion, MotionClip):
        return np.asarray(check_motion(motion).local_rot, dtype=np.float64)
    q = np.asarray(motion, dtype=np.float64)
    if q.ndim != 3 or q.shape[-1] != 4:
        raise InputError(f"motion must be a MotionClip or local rotations (frames, joints, 4), got shape {q.shape}")
    if not np.all(np.isfinite(q)):
        raise InputError("local rotations have NaN or infinite values; repair or trim the motion")
    return q

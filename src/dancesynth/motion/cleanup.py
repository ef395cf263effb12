"""Mend a capture's one-frame glitches before it goes into the database.

A retargeting solver or a markerless tracker sometimes jumps: a joint turns 40-90 degrees
between two frames and stays there (a *step*: the arm's solution flipped), or one frame is
out of line (a *pop*), and the root may shift a few centimetres in one frame. Played back,
each is a visible snap. ``remove_snaps`` finds them with the same rule the artefact guard
uses (``eval.artefacts.one_frame_steps``: a turn much larger than the frames either side)
and mends them without touching the motion around: a pop's frame becomes the midpoint of its
neighbours; a step's jump is spread over ``window_s`` either side (half of it added, with a
cosine ramp, to the frames before and half taken from the frames after), so the pose before
and after is unchanged and the jump becomes a quick movement. A jump made over two frames with
calm frames around (the G1 retarget's arm flips, 50-70 degrees in 1/30 s: a one-frame snap once
the dance is sampled at 30 fps) is made a one-frame step first, then mended as one.
"""

from __future__ import annotations

import numpy as np

from .. import rotations as rot
from ..types import MotionClip

SNAP_DEG = 15.0          # a one-frame turn this large, with calm frames around it, is a glitch
ROOT_SNAP_M = 0.02       # likewise a one-frame shift of the root (at 60 fps: 1.2 m/s more than its neighbours)
CALM = 1.0 / 3.0
WINDOW_S = 0.1
MAX_PASSES = 3


def _isolated(d: np.ndarray, across: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray]:
    """(steps, pops): boolean (F-1, ...) masks of the frame pairs f whose change d(f) is a step
    (calm before and after) and of those starting a pop (f and f+1 large, f-1 and f+2 calm, and
    frame f+2 back where f was: ``across`` (F-2, ...), the change from f to f+2, small)."""
    pad = np.zeros((2,) + d.shape[1:])
    dp = np.concatenate([pad, d, pad])
    prev1, here, next1, next2 = dp[1:-3], dp[2:-2], dp[3:-1], dp[4:]
    step = (here > threshold) & (prev1 <= here * CALM) & (next1 <= here * CALM)
    m = np.minimum(here, next1)
    back = np.concatenate([across, np.full((1,) + d.shape[1:], np.inf)])   # no f+2 after the last pair
    pop = (here > threshold) & (next1 > threshold) & (prev1 <= m * CALM) & (next2 <= m * CALM) & (back <= m * CALM)
    return step, pop


def _two_frame_steps(q: np.ndarray, d: np.ndarray, threshold: float, taken: np.ndarray) -> np.ndarray:
    """(frame f, joint) of jumps made over frames f..f+2 with calm turns two frames either side: the turn
    from f to f+2 exceeds ``2 * threshold``, both single turns in it are large, and it is not one of the
    one-frame snaps in ``taken``."""
    if len(q) < 3:
        return np.zeros((0, 2), dtype=np.int64)
    d2 = np.degrees(rot.angle(q[2:], q[:-2]))
    pad = np.zeros((2,) + d2.shape[1:])
    dp = np.concatenate([pad, d2, pad])
    before, here, after = dp[:-4], dp[2:-2], dp[4:]
    found = ((here > 2 * threshold) & (before <= here * CALM) & (after <= here * CALM)
             & (d[:-1] > threshold) & (d[1:] > threshold) & ~taken[:-1] & ~taken[1:])
    return np.argwhere(found)


def _ramp(n: int) -> np.ndarray:
    """n weights rising smoothly from ~0 to 1 (the last is 1)."""
    return 0.5 - 0.5 * np.cos(np.pi * np.arange(1, n + 1) / n)


def remove_snaps(clip: MotionClip, *, threshold_deg: float = SNAP_DEG, window_s: float = WINDOW_S) -> tuple[MotionClip, int]:
    """``clip`` with its one-frame snaps mended, and how many were mended."""
    q = np.array(clip.local_rot, dtype=np.float64)
    p = np.array(clip.root_pos, dtype=np.float64)
    w = max(1, int(round(window_s * clip.fps)))
    n, mended = len(q), 0
    for _ in range(MAX_PASSES):
        found = 0
        d = np.degrees(rot.angle(q[1:], q[:-1]))
        steps, pops = _isolated(d, np.degrees(rot.angle(q[2:], q[:-2])), threshold_deg)
        for f, j in np.argwhere(pops):
            if f + 2 < n:
                q[f + 1, j] = rot.nlerp(q[f, j], q[f + 2, j], 0.5)
                found += 1
        for f, j in _two_frame_steps(q, d, threshold_deg, steps | pops):
            q[f + 1, j] = q[f, j]          # the whole jump between f+1 and f+2: a one-frame step, next pass
            found += 1
        for f, j in np.argwhere(steps & ~pops):
            jump = rot.mul(q[f + 1, j], rot.inv(q[f, j]))        # in the parent's frame
            half = rot.log(jump) * 0.5
            a, b = max(0, f - w + 1), min(n, f + 1 + w)
            before, after = _ramp(f + 1 - a), _ramp(b - f - 1)[::-1]
            q[a:f + 1, j] = rot.mul(rot.exp(half * before[:, None]), q[a:f + 1, j])
            q[f + 1:b, j] = rot.mul(rot.exp(-half * after[:, None]), q[f + 1:b, j])
            found += 1
        v = np.diff(p, axis=0)
        steps, pops = _isolated(np.linalg.norm(v, axis=1), np.linalg.norm(p[2:] - p[:-2], axis=1), ROOT_SNAP_M)
        for f in np.flatnonzero(steps | pops):
            # The shift beyond the root's own velocity (that of the frames either side) is the glitch.
            own = 0.5 * (v[max(f - 1, 0)] + v[min(f + 1, len(v) - 1)]) if not pops[f] else v[max(f - 1, 0)]
            excess = (v[f] - own) * 0.5
            a, b = max(0, f - w + 1), min(n, f + 1 + w)
            p[a:f + 1] += excess * _ramp(f + 1 - a)[:, None]
            p[f + 1:b] -= excess * _ramp(b - f - 1)[::-1][:, None]
            found += 1
        mended += found
        if not found:
            break
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    out = MotionClip(clip.skeleton, clip.fps, p, q, clip.local_pos, clip.contacts, dict(clip.meta))
    return out, mended

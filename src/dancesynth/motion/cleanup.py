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
the dance is sampled at 30 fps), or over three (its lower arms' 40-55 degree twists in 1/20 s, which
the accent timing plays within one frame at 30 fps), is made a one-frame step first, then mended as one.
"""

from __future__ import annotations

import numpy as np

from .. import rotations as rot
from ..types import MotionClip

SNAP_DEG = 15.0          # a one-frame turn this large, with calm frames around it, is a glitch
ROOT_SNAP_M = 0.02       # likewise a one-frame shift of the root (at 60 fps: 1.2 m/s more than its neighbours)
CALM = 1.0 / 3.0
WINDOW_S = 0.1
MAX_PASSES = 8           # until nothing is left: a jump over frames takes two passes (made a step, then mended),
                         # and a mend can bare another (J_Dance12_LushLife needs 6)
SPANS = (2, 3)           # jumps made over this many frames are mended too (at 60 fps: one frame at 30 fps)


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


def _short_jumps(q: np.ndarray, d: np.ndarray, threshold: float, taken: np.ndarray, n: int) -> np.ndarray:
    """(frame f, joint) of jumps made over frames f..f+n with calm turns n frames either side: the turn
    from f to f+n exceeds ``2 * threshold``, each single turn in it exceeds ``2 * threshold / n``, and
    none is one of the one-frame snaps in ``taken``."""
    if len(q) <= n:
        return np.zeros((0, 2), dtype=np.int64)
    dn = np.degrees(rot.angle(q[n:], q[:-n]))
    pad = np.zeros((n,) + dn.shape[1:])
    dp = np.concatenate([pad, dn, pad])
    before, here, after = dp[:-2 * n], dp[n:-n], dp[2 * n:]
    found = (here > 2 * threshold) & (before <= here * CALM) & (after <= here * CALM)
    for k in range(n):   # every single turn of the jump is large, and none a snap of its own
        found &= (d[k:len(d) - n + 1 + k] > 2 * threshold / n) & ~taken[k:len(d) - n + 1 + k]
    return np.argwhere(found)


def _ramp(n: int) -> np.ndarray:
    """n weights rising smoothly from ~0 to 1 (the last is 1)."""
    return 0.5 - 0.5 * np.cos(np.pi * np.arange(1, n + 1) / n)


def spread_step(q: np.ndarray, f: int, j: int, w: int) -> None:
    """Mend, in place, joint ``j``'s jump from frame f to f+1 of ``q`` (F, J, 4): half of it is added before,
    half taken after, each with a cosine ramp over ``w`` frames, so the poses beyond are unchanged and
    the jump becomes a quick movement."""
    n = len(q)
    half = rot.log(rot.mul(q[f + 1, j], rot.inv(q[f, j]))) * 0.5   # in the parent's frame
    a, b = max(0, f - w + 1), min(n, f + 1 + w)
    before, after = _ramp(f + 1 - a), _ramp(b - f - 1)[::-1]
    q[a:f + 1, j] = rot.mul(rot.exp(half * before[:, None]), q[a:f + 1, j])
    q[f + 1:b, j] = rot.mul(rot.exp(-half * after[:, None]), q[f + 1:b, j])


def _mend_pops(q: np.ndarray, pops: np.ndarray) -> int:
    """Each pop's frame (f+1) becomes the midpoint of its neighbours, in place; how many."""
    found = 0
    for f, j in np.argwhere(pops):
        if f + 2 < len(q):
            q[f + 1, j] = rot.nlerp(q[f, j], q[f + 2, j], 0.5)
            found += 1
    return found


def _spread_all(q: np.ndarray, steps: np.ndarray, w: int) -> int:
    """``spread_step`` at every (frame, joint) of ``steps``, in place; how many."""
    where = np.argwhere(steps)
    for f, j in where:
        spread_step(q, f, j, w)
    return len(where)


def spread_steps(q: np.ndarray, fps: float, *, threshold_deg: float = 20.0,
                 window_s: float = WINDOW_S) -> np.ndarray:
    """``q`` (F, J, 4) without isolated one-frame snaps over ``threshold_deg``: a step is spread over
    ``window_s`` either side (``spread_step``), a pop's frame becomes the midpoint of its neighbours. What
    a dance's last pass does to whatever made them (a quick twist of the capture played faster, an IK
    that swaps solutions)."""
    if len(q) < 3:
        return q
    d = np.degrees(rot.angle(q[1:], q[:-1]))
    steps, pops = _isolated(d, np.degrees(rot.angle(q[2:], q[:-2])), threshold_deg)
    if not (steps.any() or pops.any()):
        return q
    out = np.array(q, dtype=np.float64)
    _mend_pops(out, pops)
    _spread_all(out, steps & ~pops, max(1, int(round(window_s * fps))))
    return out


def remove_snaps(clip: MotionClip, *, threshold_deg: float = SNAP_DEG,
                 window_s: float = WINDOW_S) -> tuple[MotionClip, int]:
    """``clip`` with its one-frame snaps mended, and how many were mended."""
    q = np.array(clip.local_rot, dtype=np.float64)
    p = np.array(clip.root_pos, dtype=np.float64)
    w = max(1, int(round(window_s * clip.fps)))
    n, mended = len(q), 0
    for _ in range(MAX_PASSES):
        d = np.degrees(rot.angle(q[1:], q[:-1]))
        steps, pops = _isolated(d, np.degrees(rot.angle(q[2:], q[:-2])), threshold_deg)
        found = _mend_pops(q, pops)
        taken = steps | pops
        for span in SPANS:
            for f, j in _short_jumps(q, d, threshold_deg, taken, span):
                q[f + 1:f + span, j] = q[f, j]   # the whole jump in its last frame: a one-frame step, next pass
                taken[f:f + span, j] = True      # not a longer jump's part as well
                found += 1
        found += _spread_all(q, steps & ~pops, w)
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

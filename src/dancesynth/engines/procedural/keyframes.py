"""Keyframes of the right hand, Loi & Li §V.B, eq. (6)-(8), and the rescaling of Fig. 8.

One keyframe per melody note, reached at the note's onset, plus one at the end of
the last note. Positions are in arm lengths, relative to the shoulder, in the frame
the upper arm hangs from (x towards the body's midline, y up, z forward):

- x (eq. 6-7): each segment sweeps ``sweep_width`` across (less if it is too quick
  for the speed limit), back and forth alternately; the step to a note is the share of the segment's time the previous
  note took (the hand travels while a note sounds). A segment's sweep ends on its
  last note, the turning point that the segmentation put on a beat or a rest.
- y (eq. 8): ``(pitch - segment's median pitch) * y_scale`` about mid height; louder
  notes move further (``intensity_gain``).
- z: a constant distance in front of the shoulder (the paper's plane of Fig. 4).

Fig. 8 lines 4-6: when a segment's keyframes leave the reachable sphere, its
heights are scaled down about the mid height until they fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...music.notes import NoteSequence
from .config import ProceduralConfig

# The workspace, in arm lengths from the shoulder: the middle of the sweep, its height and depth.
X_CENTER = 0.1
Y_MID = -0.25
Z_FRONT = 0.5


@dataclass(frozen=True)
class Keyframes:
    """Keyframe times (K,), positions (K, 3), whether each is a corner (beat/rest), and its note."""

    times_s: np.ndarray
    pos: np.ndarray
    corner: np.ndarray
    intensity: np.ndarray     # 0..1, chooses between G1 and G2 at a corner
    segment: np.ndarray       # segment index of each keyframe
    y_scale: np.ndarray       # the height factor each segment kept after rescaling (Fig. 8)


def max_height_scale(pos: np.ndarray, radius: float, y_mid: float = Y_MID) -> float:
    """Largest ``s`` in [0, 1] such that every point with its height ``y_mid + s (y - y_mid)`` is within ``radius``."""
    room = radius ** 2 - pos[:, 0] ** 2 - pos[:, 2] ** 2
    dy = pos[:, 1] - y_mid
    with np.errstate(divide="ignore", invalid="ignore"):
        # (y_mid + s dy)^2 <= room, for s >= 0: s <= (sqrt(room) - y_mid sign) / |dy|
        limit = np.where(dy > 0, (np.sqrt(np.maximum(room, 0)) - y_mid) / dy,
                         np.where(dy < 0, (-np.sqrt(np.maximum(room, 0)) - y_mid) / dy, np.inf))
    return float(np.clip(np.min(limit, initial=1.0), 0.0, 1.0))


def plan_keyframes(notes: NoteSequence, bounds: list[tuple[int, int]], cfg: ProceduralConfig) -> Keyframes:
    """Keyframes for every note (and the song's end) from the segmentation ``bounds``."""
    n = notes.n_notes
    dur = notes.duration_16
    seg_of = np.zeros(n, dtype=np.int64)
    for k, (a, b) in enumerate(bounds):
        seg_of[a:b] = k
    x = np.zeros(n + 1)
    lo, hi = X_CENTER - cfg.sweep_width / 2.0, X_CENTER + cfg.sweep_width / 2.0
    edge = lo
    direction = 1.0
    for k, (a, b) in enumerate(bounds):
        first = max(a - 1, 0)                      # the previous turning point (or the first note)
        steps = dur[first:b - 1]
        total = steps.sum()
        frac = np.cumsum(steps) / total if total > 0 else np.linspace(1, 1, len(steps))
        # Across to the other edge, unless the segment is too quick for that under the speed limit.
        target = hi if direction > 0 else lo
        width = min(abs(target - edge), cfg.speed_limit * (notes.onset_s[b - 1] - notes.onset_s[first]) / 3.0)
        x[first] = edge
        x[first + 1:b] = edge + direction * width * frac
        edge = edge + direction * width if total > 0 else edge
        direction = -direction
    # After the last note the hand comes back halfway to the middle of the sweep.
    x[n] = 0.5 * (x[n - 1] + X_CENTER)

    loud = notes.intensity / 127.0
    gain = cfg.y_scale * (1.0 + cfg.intensity_gain * (loud - 0.5))
    y = np.zeros(n + 1)
    for a, b in bounds:
        y[a:b] = (notes.pitch[a:b] - np.median(notes.pitch[a:b])) * gain[a:b]
    pos = np.stack([x, Y_MID + y, np.full(n + 1, Z_FRONT)], axis=1)
    pos[n, 1] = Y_MID - 0.1

    # Fig. 8: a segment that leaves the reachable sphere is flattened until it fits.
    kept = np.ones(len(bounds))
    for k, (a, b) in enumerate(bounds):
        s = max_height_scale(pos[a:b], cfg.reach * 0.97)
        if s < 1.0:
            pos[a:b, 1] = Y_MID + s * (pos[a:b, 1] - Y_MID)
            kept[k] = s
    # The hand settles after the last note, taking at least half a second for it.
    times = np.append(notes.onset_s, max(notes.offset_s[-1], notes.onset_s[-1] + 0.5))
    corner = np.append(notes.is_beat | notes.rest_after, True)
    corner[0] = True  # the hand starts from rest
    return Keyframes(times, pos, corner, np.append(loud, 0.5), np.append(seg_of, seg_of[-1]), kept)

"""Music segmentation, Loi & Li §IV: cut the melody into phrases the hand can sweep.

A segment ``s = [n_1 .. n_m]`` costs (eq. 1-5, each term normalised to [0, 1],
smaller is better)::

    f1 = 0 if n_m is a beat note or a rest follows it, else 1   (turn on a beat)
    f2 = |pitch range(s) - ideal_range| / ideal_range           (fits the height)
    f3 = |beat density(s) - song's| / song's                    (even rhythm)
    f4 = |total duration(s) - ideal_duration| / ideal_duration  (fits the width)
    f  = (w1 f1 + w2 f2 + w3 f3 + w4 f4) / (w1 + w2 + w3 + w4)

and a segmentation costs the note-weighted mean of its segments' ``f``: the
"normalize" of Fig. 2 combines two halves by their lengths in notes.

``segment_fig2`` is the paper's Fig. 2 bottom-up table over every (start, length)
and every split point, O(n^3). It is vectorised: for one length, all starts and all
split points are one numpy operation, reading the left halves from a table indexed
by start and the right halves from one indexed by end, so both are plain slices.
``segment_prefix`` solves the same problem in O(n * max_segment_notes): because
the objective is a sum over segments, the best cut of notes 0..j is the best cut of
0..i plus one segment i..j. Both return the same optimum; the prefix DP is the
default, the table is kept as the paper's reference (and both are benchmarked).
Every segment has at most ``max_segment_notes`` notes (the reachable space bounds
a segment), which is what keeps the costs of all candidate segments a small array.
"""

from __future__ import annotations

import numpy as np

from ...music.notes import NoteSequence
from .config import ProceduralConfig
from ...errors import InputError


def segment_costs(notes: NoteSequence, cfg: ProceduralConfig) -> np.ndarray:
    """``C[m - 1, i]``: eq. (5) for the segment of ``m`` notes starting at note ``i`` (inf if past the end)."""
    n, lmax = notes.n_notes, min(cfg.max_segment_notes, notes.n_notes)
    pitch, dur = notes.pitch, notes.duration_16
    beat = notes.is_beat.astype(np.float64)
    ends_well = (notes.is_beat | notes.rest_after).astype(np.float64)
    cum_dur = np.concatenate(([0.0], np.cumsum(dur)))
    cum_beat = np.concatenate(([0.0], np.cumsum(beat)))
    song_density = cum_beat[-1] / max(cum_dur[-1], 1e-9)
    w = np.asarray(cfg.weights, dtype=np.float64)
    C = np.full((lmax, n), np.inf)
    hi = pitch.copy()
    lo = pitch.copy()
    for m in range(1, lmax + 1):
        i = np.arange(n - m + 1)
        if m > 1:  # running max / min over the window: pitch range by extension, O(n) per length
            hi = np.maximum(hi[:-1], pitch[m - 1:])
            lo = np.minimum(lo[:-1], pitch[m - 1:])
        total = cum_dur[i + m] - cum_dur[i]
        f1 = 1.0 - ends_well[i + m - 1]
        f2 = np.minimum(np.abs((hi - lo) - cfg.ideal_range) / cfg.ideal_range, 1.0)
        if song_density > 0:
            density = (cum_beat[i + m] - cum_beat[i]) / np.maximum(total, 1e-9)
            f3 = np.minimum(np.abs(density - song_density) / song_density, 1.0)
        else:
            f3 = np.zeros_like(total)
        f4 = np.minimum(np.abs(total - cfg.ideal_duration) / cfg.ideal_duration, 1.0)
        C[m - 1, :n - m + 1] = (w[0] * f1 + w[1] * f2 + w[2] * f3 + w[3] * f4) / w.sum()
    return C


def segmentation_cost(costs: np.ndarray, bounds: list[tuple[int, int]]) -> float:
    """Note-weighted mean of eq. (5) over the segments ``[(start, stop), ...]``."""
    n = bounds[-1][1]
    return float(sum((b - a) * costs[b - a - 1, a] for a, b in bounds) / n)


def segment_prefix(costs: np.ndarray) -> list[tuple[int, int]]:
    """Best segmentation by the O(n * L) prefix DP: ``best[j] = min_m best[j-m] + m f(j-m, m)``."""
    lmax, n = costs.shape
    best = np.full(n + 1, np.inf)
    best[0] = 0.0
    back = np.zeros(n + 1, dtype=np.int64)
    m_all = np.arange(1, lmax + 1)
    for j in range(1, n + 1):
        m = m_all[:min(lmax, j)]
        cand = best[j - m] + m * costs[m - 1, j - m]
        k = int(np.argmin(cand))
        best[j], back[j] = cand[k], m[k]
    if not np.isfinite(best[n]):
        raise InputError("no segmentation: every segment is longer than max_segment_notes")
    bounds, j = [], n
    while j > 0:
        bounds.append((j - int(back[j]), j))
        j -= int(back[j])
    return bounds[::-1]


def segment_fig2(costs: np.ndarray) -> list[tuple[int, int]]:
    """Best segmentation by Fig. 2's table over (start, length) and split point, O(n^3), vectorised.

    ``by_start[L, i]`` and ``by_end[L, j]`` hold the best summed cost of notes
    ``i..i+L`` and ``j-L..j``; a length-``L`` entry is either one segment or the
    best split ``k``: ``by_start[k, i] + by_end[L-k, i+L]``.
    """
    lmax, n = costs.shape
    by_start = np.full((n + 1, n + 1), np.inf)
    by_end = np.full((n + 1, n + 1), np.inf)
    split = np.zeros((n + 1, n + 1), dtype=np.int32)
    for length in range(1, n + 1):
        starts = n - length + 1
        single = length * costs[length - 1, :starts] if length <= lmax else np.full(starts, np.inf)
        if length > 1:
            left = by_start[1:length, :starts]                         # k = 1 .. L-1
            right = by_end[length - 1:0:-1, length:n + 1]              # lengths L-1 .. 1, ending at i+L
            total = left + right
            k = np.argmin(total, axis=0)
            value = total[k, np.arange(starts)]
            better = value < single
            single = np.where(better, value, single)
            split[length, :starts] = np.where(better, k + 1, 0)
        by_start[length, :starts] = single
        by_end[length, length:n + 1] = single
    if not np.isfinite(by_start[n, 0]):
        raise InputError("no segmentation: every segment is longer than max_segment_notes")
    bounds, stack = [], [(0, n)]
    while stack:
        a, b = stack.pop()
        k = int(split[b - a, a])
        if k == 0:
            bounds.append((a, b))
        else:
            stack += [(a + k, b), (a, a + k)]
    return sorted(bounds)


METHODS = {"prefix": segment_prefix, "fig2": segment_fig2}


def segment(notes: NoteSequence, cfg: ProceduralConfig, method: str = "prefix") -> list[tuple[int, int]]:
    """Segments of ``notes`` as ``[(first note, one past the last), ...]`` covering the melody."""
    return METHODS[method](segment_costs(notes, cfg))

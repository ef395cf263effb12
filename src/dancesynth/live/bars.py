"""Bar positions of a live stream's beats: counting on from the latest metre decision.

Each time beats are given, the beat intervals they close join a bounded history of
``music.metre.beat_features`` rows; ``music.metre.estimate_metre`` on that history
decides the metre and the phase, and each new beat gets its bar position by counting
on from the latest decision. Until ``BAR_MIN_BEATS`` intervals are known the count is
4/4 from the first beat; a decision with no confidence keeps the count going.
Positions given are never revised: when the phase changes, the count jumps.
"""

from __future__ import annotations

import numpy as np

from ..music.metre import DEFAULT_BEATS_PER_BAR, N_FEATURES, estimate_metre

# The metre is decided on the features of the last this many beat intervals
# (32 s at 120 bpm: several periodicity windows, and enough bars to outvote a fill).
BAR_HISTORY_BEATS = 64
# The first decision comes after two bars of 4 (offline waits for three): on the generated
# songs updated every 5 s this gives every downbeat after 5 s (mean F 1.00 where 12 gives 0.99).
BAR_MIN_BEATS = 8


class BarCounter:
    """The count in force: beat k (counted from the stream's first) sits at ``(k - ref) % metre``."""

    def __init__(self):
        self.rows = np.full((BAR_HISTORY_BEATS, N_FEATURES), np.nan)  # oldest first; NaN: none yet
        self.known, self.given = 0, 0
        self.metre, self.ref, self.confidence = DEFAULT_BEATS_PER_BAR, 0, 0.0

    def count(self, rows: np.ndarray, n_new: int) -> np.ndarray:
        """Positions of ``n_new`` new beats, after ``rows`` (the intervals they close) join the history."""
        if n_new == 0:
            return np.zeros(0, dtype=np.int64)
        if rows.shape[0]:
            self.rows = np.concatenate((self.rows, rows))[-BAR_HISTORY_BEATS:]
            self.known = min(self.known + rows.shape[0], BAR_HISTORY_BEATS)
            if self.known >= BAR_MIN_BEATS:
                metre, path, confidence = estimate_metre(self.rows[-self.known:], min_beats=BAR_MIN_BEATS)
                if confidence > 0:
                    # The last row is the interval of the beat before the newest one.
                    self.metre, self.confidence = metre, confidence
                    self.ref = self.given + n_new - 2 - int(path[-1])
        index = self.given + np.arange(n_new)
        self.given += n_new
        return (index - self.ref) % self.metre

"""The one place where seconds, frames and beats are converted into each other."""

from __future__ import annotations

import numpy as np


def frames_to_seconds(frames, fps: float):
    """Frame index (may be fractional) to time in seconds."""
    return np.asarray(frames, dtype=float) / fps


def bpm_from_intervals(intervals_s) -> float:
    """Tempo in beats per minute from beat intervals (median, robust to outliers)."""
    intervals_s = np.asarray(intervals_s, dtype=float)
    intervals_s = intervals_s[intervals_s > 0]
    if intervals_s.size == 0:
        return 0.0
    return float(60.0 / np.median(intervals_s))

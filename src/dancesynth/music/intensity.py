"""Music intensity: the sound pressure level of each beat interval (Xu et al. §3.3).

Levels are in dB relative to digital full scale, ``20 log10(RMS)``, so a
full-scale square wave is 0 dB and a full-scale sine -3.01 dB. Silence would be
-inf; it is floored (``FLOOR_DB``) so that every value stays finite and the
engines' z-scoring never meets an infinity.
"""

from __future__ import annotations

import numpy as np
from ..errors import InputError

FLOOR_DB = -100.0
# Samples per block of ``cumulative_energy`` (2 MB of float64).
_ENERGY_BLOCK = 1 << 18


def rms_db(rms, *, floor_db: float = FLOOR_DB):
    """``20 log10(rms)`` floored at ``floor_db``."""
    rms = np.asarray(rms, dtype=np.float64)
    with np.errstate(divide="ignore"):
        db = 20.0 * np.log10(np.maximum(rms, 0.0))
    return np.maximum(db, floor_db)


def cumulative_energy(y: np.ndarray, at, *, block: int = _ENERGY_BLOCK) -> np.ndarray:
    """``sum(y[:i] ** 2)`` for every ``i`` in ``at`` (``0 <= i <= len(y)``), float64.

    The same numbers as indexing ``concatenate(([0], cumsum(square(y, dtype=float64))))``
    (the running sum is carried from block to block in the same order), without a
    float64 copy of the whole signal: memory is one block.
    """
    y = np.asarray(y)
    at = np.asarray(at, dtype=np.int64)
    out = np.zeros(at.shape)
    if at.size == 0:
        return out
    flat = at.ravel()
    order = np.argsort(flat, kind="stable")
    wanted = flat[order]
    if wanted[0] < 0 or wanted[-1] > len(y):
        raise InputError("cumulative_energy: an index is outside the signal")
    values = np.zeros(flat.size)
    carry = 0.0
    for start in range(0, len(y), block):
        stop = min(start + block, len(y))
        lo, hi = np.searchsorted(wanted, [start, stop], side="left")
        if stop == len(y):
            hi = wanted.size
        running = np.cumsum(np.concatenate(([carry], np.square(y[start:stop], dtype=np.float64))))
        values[order[lo:hi]] = running[wanted[lo:hi] - start]
        carry = running[-1]
    out[...] = values.reshape(at.shape)
    return out


def beat_intensity_db(y: np.ndarray, sr: float, beat_times_s, *, floor_db: float = FLOOR_DB) -> np.ndarray:
    """Sound pressure level (dB re full scale) of every interval between two beats.

    Parameters
    ----------
    y : (n,) mono samples
    sr : sample rate of ``y``
    beat_times_s : (B,) increasing beat instants in seconds

    Returns
    -------
    (B-1,) float64: the RMS level of ``y[beat_k : beat_k+1]`` in dB, at least
    ``floor_db``. Beats outside the signal are clipped to its ends.
    """
    y = np.asarray(y)
    if y.ndim != 1:
        raise InputError("beat_intensity_db expects mono samples of shape (n,)")
    beats = np.asarray(beat_times_s, dtype=np.float64)
    if beats.size < 2:
        return np.zeros(0)
    edges = np.clip(np.round(beats * sr).astype(np.int64), 0, len(y))
    # One cumulative sum of squares (in float64: float32 would lose the quiet
    # intervals of a long song to rounding) gives every interval's energy in O(n).
    energy = cumulative_energy(y, edges)
    counts = np.diff(edges)
    sums = energy[1:] - energy[:-1]
    mean_square = np.where(counts > 0, np.maximum(sums, 0.0) / np.maximum(counts, 1), 0.0)
    return rms_db(np.sqrt(mean_square), floor_db=floor_db)

"""How fast the hand moves along its path, Loi & Li §V.E and Fig. 7.

Each piece's distance travelled over time, ``s(t)``, is a cubic Bezier in (time,
arc length) with control values ``0, v0 T/3, S - v1 T/3, S`` -- the speeds at its
ends are ``v0`` and ``v1``:

(a) into a beat or rest note: accelerate, arriving at ``beat_acceleration`` times
    the piece's mean speed, then a sudden stop (the next piece starts from rest);
(b) between regular notes: the speed at a regular keyframe is the mean of its two
    pieces' mean speeds, the same on both sides, so the motion is C1 there and
    constant when the notes are even;
(c) after a beat: from rest.

Speeds are kept at most 3 S / T so that ``s(t)`` never runs backwards.
"""

from __future__ import annotations

import numpy as np

from .bezier import BezierPath, bezier_points
from .config import ProceduralConfig


def end_speeds(path: BezierPath, cfg: ProceduralConfig) -> tuple[np.ndarray, np.ndarray]:
    """Speeds ``(v0, v1)`` at the start and end of every piece (arm lengths per second)."""
    T = path.t1 - path.t0
    S = path.length
    mean = S / np.maximum(T, 1e-9)
    # The speed through each keyframe between two pieces (regular keyframes only use it).
    through = np.zeros(len(S) + 1)
    through[1:-1] = np.minimum(0.5 * (mean[:-1] + mean[1:]), 3.0 * np.minimum(mean[:-1], mean[1:]))
    corner = path.corner
    v0 = np.where(corner[:-1], 0.0, through[:-1])
    v1 = np.where(corner[1:], cfg.beat_acceleration * mean, through[1:])
    return np.minimum(v0, 3.0 * mean), np.minimum(v1, 3.0 * mean)


def peak_speeds(path: BezierPath, cfg: ProceduralConfig) -> np.ndarray:
    """An upper estimate of each piece's fastest moment: its end speeds, or 1.5 x its mean (a cubic's bulge)."""
    v0, v1 = end_speeds(path, cfg)
    mean = path.length / np.maximum(path.t1 - path.t0, 1e-9)
    return np.maximum(np.maximum(v0, v1), 1.5 * mean)


def arc_length_at(path: BezierPath, v0: np.ndarray, v1: np.ndarray, piece: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Distance travelled along ``piece`` after ``tau`` seconds (the Fig. 7 Bezier in time)."""
    T = np.maximum(path.t1 - path.t0, 1e-9)[piece]
    S = path.length[piece]
    u = np.clip(tau / T, 0.0, 1.0)
    c1 = v0[piece] * T / 3.0
    c2 = S - v1[piece] * T / 3.0
    return 3 * u * (1 - u) ** 2 * c1 + 3 * u ** 2 * (1 - u) * c2 + u ** 3 * S


def sample_path(path: BezierPath, cfg: ProceduralConfig, times_s: np.ndarray) -> np.ndarray:
    """Hand positions (F, 3) at ``times_s``: the speed profile, then arc length back to the curve.

    Before the first keyframe the hand waits at it; after the last it stays.
    """
    v0, v1 = end_speeds(path, cfg)
    piece = np.clip(np.searchsorted(path.t1, times_s, side="right"), 0, len(path.t0) - 1)
    tau = np.clip(times_s - path.t0[piece], 0.0, None)
    s = arc_length_at(path, v0, v1, piece, tau)
    u = invert_arc(path, piece, s)
    return bezier_points(path.ctrl[piece], u[:, None])[:, 0, :]


def invert_arc(path: BezierPath, piece: np.ndarray, s: np.ndarray) -> np.ndarray:
    """The parameter ``u`` where piece ``piece`` has run ``s`` along its curve.

    Cubic Hermite interpolation of the arc-length table with the exact slopes
    ``du/ds = 1 / |B'(u)|`` at its nodes: the speed at every keyframe is exactly the
    speed profile's, so regular keyframes stay C1.
    """
    table, rate = path.arc[piece], path.rate[piece]                      # (F, A)
    rows = np.arange(len(s))
    a = table.shape[1]
    j = np.clip(np.sum(table < s[:, None], axis=1), 1, a - 1) - 1        # node below s
    s0, s1 = table[rows, j], table[rows, j + 1]
    h = s1 - s0
    du = 1.0 / (a - 1)
    x = np.where(h > 1e-12, np.clip((s - s0) / np.maximum(h, 1e-12), 0.0, 1.0), 0.0)
    m0 = np.where(rate[rows, j] > 1e-9, h / np.maximum(rate[rows, j], 1e-9), du) / du
    m1 = np.where(rate[rows, j + 1] > 1e-9, h / np.maximum(rate[rows, j + 1], 1e-9), du) / du
    m0, m1 = np.minimum(m0, 3.0), np.minimum(m1, 3.0)                    # keep it monotone
    frac = (-2 * x**3 + 3 * x**2) + (x**3 - 2 * x**2 + x) * m0 + (x**3 - x**2) * m1
    return (j + np.clip(frac, 0.0, 1.0)) * du

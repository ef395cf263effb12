"""The right hand's path, Loi & Li §V.D: cubic Bezier pieces between keyframes.

Piece ``i`` runs from keyframe ``K_i`` to ``K_i+1`` with control points ``A_i``
(leaving ``K_i``) and ``B_i`` (arriving at ``K_i+1``).

- A *regular* keyframe (Fig. 5): the two control points around it lie on one line
  through it, along ``K_i+1 - K_i-1``, each a third of its piece's chord away, so
  the path is smooth (G1; with the speed profile's continuous speed, C1 in time).
- A *beat or rest* keyframe (Fig. 6): the way out leaves towards ``P2``, a mix of
  ``G1 = K + L1 d_out`` (on along the next chord) and ``G2 = K + L2 up`` (a rebound)
  chosen by the note's intensity; ``L1`` is capped so that the hand's speed limit
  holds over the next note's time. The way in arrives from ``P1``, which lies
  between ``K`` and the mirror image of ``P2`` across the vertical plane through
  ``K`` (behind, along the incoming chord, at the same height): ``bounce`` says how
  far. The hand drops into the beat and bounces out of it: a sharp corner.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .config import ProceduralConfig
from .keyframes import Keyframes, max_height_scale
from ...errors import InputError

UP = np.array([0.0, 1.0, 0.0])
ARC_SAMPLES = 48


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(n > 1e-12, v / np.maximum(n, 1e-12), 0.0)


@dataclass(frozen=True)
class BezierPath:
    """Cubic pieces ``(K_i, A_i, B_i, K_i+1)`` with their times and arc-length tables."""

    ctrl: np.ndarray         # (P, 4, 3)
    t0: np.ndarray           # (P,) start time of each piece
    t1: np.ndarray
    arc: np.ndarray          # (P, ARC_SAMPLES) arc length at u = linspace(0, 1)
    rate: np.ndarray         # (P, ARC_SAMPLES) |dB/du| there
    corner: np.ndarray       # (P + 1,) keyframe kinds

    @property
    def length(self) -> np.ndarray:
        return self.arc[:, -1]


def bezier_points(ctrl: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Points of cubic pieces ``ctrl`` (..., 4, 3) at parameters ``u`` (..., k) -> (..., k, 3)."""
    basis = np.stack([(1 - u) ** 3, 3 * u * (1 - u) ** 2, 3 * u ** 2 * (1 - u), u ** 3], axis=-1)  # (..., k, 4)
    return basis @ ctrl


def bezier_tangents(ctrl: np.ndarray, u: np.ndarray) -> np.ndarray:
    """d/du of cubic pieces at ``u``."""
    basis = np.stack([(1 - u) ** 2, 2 * u * (1 - u), u ** 2], axis=-1)
    return basis @ (np.diff(ctrl, axis=-2) * 3.0)


def corner_point(key: np.ndarray, d_out: np.ndarray, intensity: float, l1: float, l2: float) -> np.ndarray:
    """Fig. 6: ``P2`` between ``G1 = K + L1 d_out`` and ``G2 = K + L2 up``, chosen by intensity (0..1)."""
    return (1.0 - intensity) * (key + l1 * d_out) + intensity * (key + l2 * UP)


def mirror_back(vec: np.ndarray, d_in: np.ndarray, d_out: np.ndarray) -> np.ndarray:
    """Mirror a handle across the vertical plane through the keyframe: forward along ``d_out``
    becomes backward along ``d_in``; the height is kept."""
    h_out = d_out - UP * (d_out @ UP)
    h_in = d_in - UP * (d_in @ UP)
    horizontal = vec - UP * (vec @ UP)
    along = np.linalg.norm(horizontal)
    back = _unit(h_in) if np.linalg.norm(h_in) > 1e-9 else -_unit(h_out)
    return -along * back + UP * (vec @ UP)


def build_path(keys: Keyframes, cfg: ProceduralConfig) -> BezierPath:
    """Control points for every piece between consecutive keyframes (see the module docstring)."""
    K, t = keys.pos, keys.times_s
    n = len(K)
    if n < 2:
        raise InputError("a path needs at least two keyframes")
    dt = np.diff(t)
    chord = np.diff(K, axis=0)
    A = K[:-1] + chord / 3.0     # straight pieces by default
    B = K[1:] - chord / 3.0
    for i in range(n):
        has_in, has_out = i > 0, i < n - 1
        if keys.corner[i]:
            d_out = _unit(chord[i]) if has_out else np.zeros(3)
            d_in = _unit(chord[i - 1]) if has_in else -d_out
            if has_out:
                # L1 from the note's time under the speed limit: a handle h gives speed 3 h / T.
                l1 = min(cfg.l1, cfg.speed_limit * dt[i] / 3.0, np.linalg.norm(chord[i]))
                l2 = min(cfg.l2, cfg.speed_limit * dt[i] / 3.0)
                p2 = corner_point(K[i], d_out, float(keys.intensity[i]), l1, l2)
                A[i] = p2
            else:
                p2 = K[i] + cfg.l2 * 0.5 * UP
            if has_in:
                P1 = K[i] + cfg.bounce * mirror_back(p2 - K[i], d_in, d_out)
                # Never further back than half the incoming chord, nor than the speed limit allows.
                span = min(np.linalg.norm(chord[i - 1]) / 2.0, cfg.speed_limit * dt[i - 1] / 3.0)
                off = P1 - K[i]
                if np.linalg.norm(off) > span:
                    P1 = K[i] + off * span / np.linalg.norm(off)
                B[i - 1] = P1
        elif has_in and has_out:
            tangent = _unit(K[i + 1] - K[i - 1])
            A[i] = K[i] + tangent * np.linalg.norm(chord[i]) / 3.0
            B[i - 1] = K[i] - tangent * np.linalg.norm(chord[i - 1]) / 3.0
    ctrl = np.stack([K[:-1], A, B, K[1:]], axis=1)
    # Arc length by Simpson's rule on |B'(u)|, which the speed profile also needs at the nodes.
    u = np.linspace(0.0, 1.0, 2 * ARC_SAMPLES - 1)
    rate = np.linalg.norm(bezier_tangents(ctrl, u), axis=-1)
    steps = (rate[:, :-2:2] + 4.0 * rate[:, 1:-1:2] + rate[:, 2::2]) * (u[2] - u[0]) / 6.0
    arc = np.concatenate([np.zeros((n - 1, 1)), np.cumsum(steps, axis=1)], axis=1)
    return BezierPath(ctrl, t[:-1], t[1:], arc, rate[:, ::2], keys.corner.copy())


def rescale_heights(keys: Keyframes, path: BezierPath, cfg: ProceduralConfig, y_mid: float,
                    peak_speed: np.ndarray | None = None) -> Keyframes | None:
    """Fig. 8 lines 12-14: segments whose path leaves the reach get their heights scaled down.

    With ``peak_speed`` (per piece), a segment whose hand would outrun ``speed_limit``
    is flattened likewise. Returns the new keyframes, or ``None`` when nothing changed.
    """
    pts = bezier_points(path.ctrl, np.linspace(0.0, 1.0, 17))     # (P, 17, 3)
    pos = keys.pos.copy()
    changed = False
    for k in np.unique(keys.segment[:-1]):
        pieces = np.flatnonzero(keys.segment[:-1] == k)
        s = max_height_scale(pts[pieces].reshape(-1, 3), cfg.reach)
        if peak_speed is not None:
            s = min(s, cfg.speed_limit / max(float(np.max(peak_speed[pieces])), 1e-9))
        if s < 1.0:
            idx = np.flatnonzero(keys.segment == k)
            pos[idx, 1] = y_mid + max(s * 0.95, 0.0) * (pos[idx, 1] - y_mid)
            changed = True
    return replace(keys, pos=pos) if changed else None

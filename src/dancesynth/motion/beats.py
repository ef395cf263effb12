"""Motion beats: the frames where a dance movement turns.

Two detectors:

- ``pca_beats`` -- the short-term PCA method of Xu, Takagi & Yoneyama (2010), used by
  the meta-motion-graph paper: over short overlapping windows the body pose is
  projected on its first principal component (the dominant movement in that
  window); where that projection turns (its velocity changes sign) the movement
  changes direction. The turning strengths of all windows are overlap-added into a
  "motion onset" curve, and a regular beat sequence is induced from it with the
  same dynamic-programming beat tracker we use for music (``beat_tracking``).
- ``kinematic_beats`` -- local minima of the summed joint speed after
  Savitzky-Golay smoothing (Aristidou et al. §5.2.1; Kim et al. 2003). Irregular but
  simple; the evaluation metrics use these.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from .. import rotations as rot
from ..beat_tracking import dp_beat_track


def pose_features(global_pos: np.ndarray, global_root_rot: np.ndarray) -> np.ndarray:
    """Joint positions relative to the root, in the root's heading frame: (F, 3J).

    Removing the root's travel and heading keeps what the body does, not where it goes.
    """
    yaw = rot.heading(global_root_rot)
    rel = global_pos - global_pos[:, :1]
    rel = rot.apply(rot.about_y(-yaw)[:, None, :], rel)
    return rel.reshape(len(global_pos), -1)


def pca_turn_envelope(features: np.ndarray, fps: float, *, window_s: float = 1.0,
                      hop_s: float = 0.1) -> np.ndarray:
    """Overlap-added turning strength of the first principal component, per frame."""
    n = len(features)
    win = max(4, int(round(window_s * fps)))
    hop = max(1, int(round(hop_s * fps)))
    env = np.zeros(n)
    weight = np.zeros(n)
    if n < win:
        win = n
    taper = np.hanning(win + 2)[1:-1]
    reach = max(1, win // 8)
    for start in range(0, n - win + 1, hop):
        x = features[start:start + win]
        x = x - x.mean(axis=0)
        # First right-singular vector = first principal axis of this window.
        _, _, vt = np.linalg.svd(x, full_matrices=False)
        v = np.gradient(x @ vt[0]) * fps
        turns = np.flatnonzero(np.signbit(v[1:]) != np.signbit(v[:-1]))  # (an exact 0 counts as +)
        if turns.size:
            speed = np.abs(v)
            before = ndimage.maximum_filter1d(speed, reach + 1, origin=reach // 2)
            after = ndimage.maximum_filter1d(speed, reach + 1, origin=-((reach + 1) // 2))
            # A turn is strong when the movement was fast before it and fast after it.
            strength = before[turns] + after[np.minimum(turns + 1, win - 1)]
            np.add.at(env, start + turns, strength * taper[turns])
        weight[start:start + win] += taper
    env /= np.maximum(weight, 1e-9)
    return np.convolve(env, np.hanning(5) / np.hanning(5).sum(), mode="same")


def induce_beats(envelope: np.ndarray, fps: float, *, start_bpm: float = 110.0, std_bpm: float = 1.0) -> np.ndarray:
    """A regular beat sequence (frame indices) from a motion onset envelope.

    The same dynamic-programming tracker as for music; ``start_bpm`` and ``std_bpm``
    (octaves) set its tempo prior.
    """
    if envelope.size < 4 or not np.any(envelope > 0):
        return np.zeros(0, dtype=np.int64)
    frames, _ = dp_beat_track(envelope, fps, start_bpm=start_bpm, std_bpm=std_bpm)
    return np.unique(np.asarray(frames, dtype=np.int64))


def pca_beats(global_pos: np.ndarray, global_root_rot: np.ndarray, fps: float, **prior) -> np.ndarray:
    """Motion beat frames by short-term PCA (see module docstring); ``prior`` goes to ``induce_beats``."""
    env = pca_turn_envelope(pose_features(global_pos, global_root_rot), fps)
    return induce_beats(env, fps, **prior)


def summed_speed(global_pos: np.ndarray, fps: float) -> np.ndarray:
    """Sum over joints of the joint speed (m/s), per frame."""
    if len(global_pos) < 2:
        return np.zeros(len(global_pos))
    return np.linalg.norm(np.gradient(global_pos, axis=0), axis=-1).sum(axis=1) * fps


# Kinematic beats (Aristidou et al. §5.2.1), one set of parameters for analysis and evaluation alike.
SMOOTH_S = 0.15              # Savitzky-Golay window
POLYORDER = 2
MIN_SEPARATION_S = 0.1       # a minimum must be the lowest within +-half of this
MIN_PROMINENCE_FRAC = 0.05   # of the clip's mean smoothed speed


def kinematic_beats(speed: np.ndarray, fps: float, *, smooth_s: float = SMOOTH_S, polyorder: int = POLYORDER,
                    min_separation_s: float = MIN_SEPARATION_S, min_prominence_frac: float = MIN_PROMINENCE_FRAC,
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Frames of local minima of the Savitzky-Golay-smoothed speed curve, and that curve.

    A minimum must be the lowest frame within +-``min_separation_s / 2`` and dip at
    least ``min_prominence_frac`` times the mean smoothed speed below the lower of
    its two neighbouring peaks (sensor noise on a still body makes tiny dips that
    are not movement accents; 0 keeps every minimum). A curve not longer than the
    smoothing window has no minima (and is returned unsmoothed).
    """
    from scipy import signal  # costs ~0.8 s to import; only analysis needs it

    speed = np.asarray(speed, dtype=np.float64)
    win = max(int(round(smooth_s * fps)) | 1, polyorder + 1 + polyorder % 2)
    if speed.size <= win:
        return np.zeros(0, dtype=np.int64), speed.copy()
    smooth = signal.savgol_filter(speed, win, polyorder)
    order = max(1, int(round(min_separation_s * fps / 2)))
    frames = signal.argrelmin(smooth, order=order)[0]
    if frames.size and min_prominence_frac > 0:
        prominence = signal.peak_prominences(-smooth, frames)[0]
        frames = frames[prominence >= min_prominence_frac * float(np.mean(smooth))]
    return frames.astype(np.int64), smooth


def stop_depths(smooth: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """How nearly each speed minimum stops the body, 0..1: one minus the speed at the minimum over
    the lower of its two neighbouring peaks (the peaks of its prominence: the highest speed on each
    side before the curve falls lower than this minimum). 1 is a full stop between two movements;
    a body gliding on with a small dip scores near 0, however regular the dips are."""
    from scipy import signal

    smooth = np.asarray(smooth, dtype=np.float64)
    frames = np.asarray(frames, dtype=np.int64)
    if frames.size == 0:
        return np.zeros(0)
    prominence = signal.peak_prominences(-smooth, frames)[0]
    peak = smooth[frames] + prominence
    return np.where(peak > 0, prominence / np.where(peak > 0, peak, 1.0), 0.0)


def snap_beats(beat_frames: np.ndarray, accents: np.ndarray, *, fraction: float) -> np.ndarray:
    """Move each beat to the nearest accent frame within ``fraction`` of its beat period.

    Beats induced as a regular grid (``pca_beats``) sit near, not on, the frames
    where the movement visibly stops (speed minima, ``kinematic_beats``); the
    renderer puts beat frames exactly on music beats, so snapping makes the stops
    land on the music. A beat with no accent near it, or whose accent another beat
    took, stays; beats stay strictly increasing.
    """
    beats = np.asarray(beat_frames, dtype=np.int64)
    accents = np.asarray(accents, dtype=np.int64)
    if fraction <= 0 or beats.size < 2 or accents.size == 0:
        return beats
    period = np.gradient(beats.astype(np.float64))
    nearest = np.clip(np.searchsorted(accents, beats), 1, accents.size) - 1
    candidates = np.stack([accents[nearest], accents[np.minimum(nearest + 1, accents.size - 1)]])
    best = candidates[np.argmin(np.abs(candidates - beats), axis=0), np.arange(beats.size)]
    snapped = np.where(np.abs(best - beats) <= fraction * period, best, beats)
    # Two beats on one accent, or crossing: keep the original beats there.
    bad = np.zeros(beats.size, dtype=bool)
    clash = np.diff(snapped) <= 0
    bad[:-1] |= clash
    bad[1:] |= clash
    return np.where(bad, beats, snapped)

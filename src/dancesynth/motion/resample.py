"""Sampling motion at fractional frame positions (time-warping and frame-rate changes)."""

from __future__ import annotations

import numpy as np

from .. import rotations as rot


def sample_frames(local_rot: np.ndarray, root_pos: np.ndarray, positions: np.ndarray,
                  contacts: np.ndarray | None = None):
    """Interpolate poses at fractional frame ``positions`` (must lie within the arrays).

    Rotations use normalised lerp on the shorter arc, which equals slerp to well
    under a degree between neighbouring mocap frames and is much faster.
    Returns ``(local_rot, root_pos, contacts)``; contacts take the nearest frame.
    """
    positions = np.asarray(positions, dtype=np.float64)
    last = len(local_rot) - 1
    lo = np.clip(np.floor(positions).astype(np.int64), 0, max(last - 1, 0))
    hi = np.minimum(lo + 1, last)
    a = np.clip(positions - lo, 0.0, 1.0)
    rots = rot.nlerp(local_rot[lo], local_rot[hi], a[:, None] * np.ones(local_rot.shape[1]))
    pos = root_pos[lo] * (1.0 - a[:, None]) + root_pos[hi] * a[:, None]
    cont = None
    if contacts is not None:
        cont = contacts[np.where(a < 0.5, lo, hi)]
    return rots, pos, cont


def resample_clip_arrays(local_rot, root_pos, contacts, fps_in: float, fps_out: float):
    """Resample whole arrays from ``fps_in`` to ``fps_out`` (integer decimation when exact)."""
    if abs(fps_in - fps_out) < 1e-6 * fps_in:
        return local_rot, root_pos, contacts
    step = fps_in / fps_out
    if abs(step - round(step)) < 1e-3:
        s = int(round(step))
        return local_rot[::s], root_pos[::s], None if contacts is None else contacts[::s]
    n_out = int(np.floor((len(local_rot) - 1) / step)) + 1
    return sample_frames(local_rot, root_pos, np.arange(n_out) * step, contacts)

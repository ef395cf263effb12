"""Per-frame motion features: joint speeds, kinetic energy, foot contacts.

All functions take arrays (global joint positions from ``kinematics.fk``) and a
frame rate, and return arrays; none reads files.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from .. import rotations as rot
from ..types import MotionClip
from .roles import JointRoles


def velocities(global_pos: np.ndarray, fps: float) -> np.ndarray:
    """Joint velocities (F, J, 3) in m/s by central differences (one-sided at the ends)."""
    if global_pos.shape[0] < 2:
        return np.zeros_like(global_pos)
    return np.gradient(global_pos, axis=0) * fps


def kinetic_energy(global_pos: np.ndarray, fps: float, masses: np.ndarray) -> np.ndarray:
    """Kinetic energy per frame (F,) in joules: ``0.5 * sum_j m_j |v_j|^2``."""
    v = velocities(global_pos, fps)
    return 0.5 * np.einsum("j,fj->f", masses, np.sum(v * v, axis=-1))


def interval_energy(energy: np.ndarray, beat_frames: np.ndarray, fps: float) -> np.ndarray:
    """Motion intensity of Xu et al.: total kinetic energy between neighbouring beats (J*s).

    ``beat_frames`` are increasing frame indices; returns ``len(beat_frames) - 1`` values.
    """
    beat_frames = np.asarray(beat_frames, dtype=np.int64)
    if beat_frames.size < 2:
        return np.zeros(0)
    cum = np.concatenate([[0.0], np.cumsum(energy)])
    return (cum[beat_frames[1:]] - cum[beat_frames[:-1]]) / fps


def foot_points(clip: MotionClip, roles: JointRoles, global_rot=None, global_pos=None) -> np.ndarray:
    """World positions (F, 2, 2, 3) of (left, right) x (ankle, toe tip) for contact tests."""
    from ..kinematics import clip_fk  # local import keeps module import light

    if global_pos is None:
        global_rot, global_pos = clip_fk(clip)
    out = np.empty((clip.n_frames, 2, 2, 3))
    for side, (ankle, toe) in enumerate(zip(roles.ankles, roles.toes)):
        out[:, side, 0] = global_pos[:, ankle]
        if toe >= 0:
            tip = toe
            end = clip.skeleton.end_sites.get(toe)
            out[:, side, 1] = global_pos[:, tip] if end is None else \
                global_pos[:, tip] + rot.apply(global_rot[:, tip], end)
        else:
            end = clip.skeleton.end_sites.get(ankle)
            out[:, side, 1] = global_pos[:, ankle] if end is None else \
                global_pos[:, ankle] + rot.apply(global_rot[:, ankle], end)
    return out


CONTACT_HEIGHT_M = 0.05  # a foot this close to the floor is on it (contacts, foot sliding, the evaluation)


def foot_contacts(feet: np.ndarray, fps: float, *, height_tol_m: float = CONTACT_HEIGHT_M,
                  speed_tol_m_s: float = 0.35, min_frames: int = 3) -> np.ndarray:
    """(F, 2) booleans: the (left, right) foot is planted.

    A foot is planted when its lowest point (ankle or toe tip) is within
    ``height_tol_m`` of the clip's floor and moves slower than ``speed_tol_m_s``
    horizontally. The floor is a low percentile of all foot heights, so clips whose
    floor is not at y = 0 work too. Short flickers are removed.
    """
    n = feet.shape[0]
    low = feet[..., 1].min(axis=2)  # (F, 2) height of the lower foot point
    floor = np.percentile(low, 5) if n else 0.0
    horiz = feet[..., [0, 2]]
    speed = np.linalg.norm(np.gradient(horiz, axis=0), axis=-1).min(axis=2) * fps if n > 1 else np.zeros((n, 2))
    contact = (low < floor + height_tol_m) & (speed < speed_tol_m_s)
    if min_frames > 1 and n:
        # Close short gaps, then drop short flickers; pad with the edge values so the
        # first and last frames keep their state.
        st = np.ones((min_frames, 1), dtype=bool)
        padded = np.pad(contact, ((min_frames, min_frames), (0, 0)), mode="edge")
        padded = ndimage.binary_opening(ndimage.binary_closing(padded, structure=st), structure=st)
        contact = padded[min_frames:-min_frames]
    return contact

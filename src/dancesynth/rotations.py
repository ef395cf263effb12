"""Quaternion helpers over SciPy's ``Rotation`` for arrays of any leading shape.

Quaternions are (x, y, z, w) numpy arrays; SciPy does the algebra. Euler angles
appear only at file boundaries (``from_euler`` / ``to_euler``).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def _R(q) -> Rotation:
    return Rotation.from_quat(np.asarray(q, dtype=np.float64))


def _q(r: Rotation) -> np.ndarray:
    return r.as_quat(canonical=False)


def mul(a, b) -> np.ndarray:
    """Hamilton product ``a * b`` (apply ``b`` first, then ``a``)."""
    return _q(_R(a) * _R(b))


def inv(q) -> np.ndarray:
    q = np.array(q, dtype=np.float64)
    q[..., :3] *= -1.0
    return q


def apply(q, v) -> np.ndarray:
    """Rotate vectors ``v`` (..., 3) by quaternions ``q`` (..., 4); leading shapes broadcast."""
    q = np.asarray(q, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    shape = np.broadcast_shapes(q.shape[:-1], v.shape[:-1])
    return _R(np.broadcast_to(q, shape + (4,)).copy()).apply(np.broadcast_to(v, shape + (3,)).copy())


def log(q) -> np.ndarray:
    """Rotation vector (axis * angle, radians)."""
    return _R(q).as_rotvec()


def exp(rotvec) -> np.ndarray:
    return _q(Rotation.from_rotvec(np.asarray(rotvec, dtype=np.float64)))


def angle(a, b) -> np.ndarray:
    """Geodesic angle (radians) between rotations ``a`` and ``b``.

    Computed as 4 atan2(|a - b|, |a + b|) (b on a's hemisphere), which stays accurate
    for nearly equal rotations where 2 arccos(a . b) loses all precision.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    b = np.where(np.sum(a * b, axis=-1, keepdims=True) < 0, -b, b)
    return 4.0 * np.arctan2(np.linalg.norm(a - b, axis=-1), np.linalg.norm(a + b, axis=-1))


def nlerp(a, b, t) -> np.ndarray:
    """Normalised linear interpolation along the shorter arc (fast; fine for close rotations)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)[..., None]
    b = np.where(np.sum(a * b, axis=-1, keepdims=True) < 0, -b, b)
    q = a * (1.0 - t) + b * t
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def about_y(yaw) -> np.ndarray:
    """Rotations about the vertical (Y) axis by ``yaw`` radians."""
    yaw = np.asarray(yaw, dtype=np.float64)
    q = np.zeros(yaw.shape + (4,))
    q[..., 1] = np.sin(yaw / 2.0)
    q[..., 3] = np.cos(yaw / 2.0)
    return q


def heading(q, forward=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Yaw angle (radians about +Y) of the direction ``forward`` after rotation ``q``."""
    f = apply(q, np.asarray(forward, dtype=np.float64))
    return np.arctan2(f[..., 0], f[..., 2]) - np.arctan2(forward[0], forward[2])


def from_euler(angles_deg, order: str) -> np.ndarray:
    """Quaternions from BVH Euler angles (degrees) in intrinsic channel ``order``, e.g. ``"ZXY"``.

    Composes the per-axis quaternions directly: the same numbers (sign included) as
    SciPy's ``from_euler``, several times faster on the ~10^5 joint-frames of a file.
    """
    angles = np.radians(np.asarray(angles_deg, dtype=np.float64)) / 2.0
    if len(order) == 1 and angles.ndim <= 1:  # one axis: scalars or a list of angles, as in SciPy
        angles = angles[..., None]
    q = None
    for k, axis in enumerate(order.upper()):
        a = np.zeros(angles.shape[:-1] + (4,))
        a[..., "XYZ".index(axis)] = np.sin(angles[..., k])
        a[..., 3] = np.cos(angles[..., k])
        q = a if q is None else _hamilton(q, a)
    return q


def _hamilton(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz], axis=-1)


def to_euler(q, order: str) -> np.ndarray:
    """BVH Euler angles (degrees, intrinsic ``order``) that vary continuously along axis 0.

    Every rotation has two Euler triples (plus 360-degree wraps). Animation tools
    interpolate the numbers, so we pick, frame by frame, the triple closest to the
    previous frame; the first frame uses SciPy's canonical range.
    """
    order = order.upper()
    e = Rotation.from_quat(np.asarray(q, dtype=np.float64)).as_euler(order, degrees=True)
    if e.ndim < 2 or e.shape[0] < 2:
        return e
    # The other triple of a proper (Tait-Bryan) order: (a + 180, 180 - b, c + 180);
    # for a symmetric order such as ZXZ it is (a + 180, -b, c + 180).
    alt = e.copy()
    alt[..., 0] += 180.0
    alt[..., 1] = (180.0 - e[..., 1]) if len(set(order)) == 3 else -e[..., 1]
    alt[..., 2] += 180.0
    out = np.empty_like(e)
    out[0] = e[0]
    for i in range(1, e.shape[0]):
        prev = out[i - 1]
        best = None
        for cand in (e[i], alt[i]):
            cand = cand + 360.0 * np.round((prev - cand) / 360.0)
            if best is None:
                best = cand
            else:
                closer = np.sum(np.abs(cand - prev), axis=-1) < np.sum(np.abs(best - prev), axis=-1)
                best = np.where(closer[..., None], cand, best)
        out[i] = best
    return out

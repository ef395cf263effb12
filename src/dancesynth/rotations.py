"""Quaternion helpers for arrays of any leading shape.

Quaternions are (x, y, z, w) numpy arrays. The algebra is written out in numpy: SciPy's
``Rotation`` gives the same numbers but costs ~0.2 ms of checks per call, which the few
thousand small calls of a song's stitching, foot lock and retargeting added up to a second.
Euler angles appear only at file boundaries (``from_euler`` / ``to_euler``).
"""

from __future__ import annotations

import numpy as np

IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def _unit(q) -> np.ndarray:
    """``q`` as float64 unit quaternions (as SciPy's ``from_quat`` normalises its input)."""
    q = np.asarray(q, dtype=np.float64)
    return q / np.sqrt(np.einsum("...i,...i->...", q, q))[..., None]


def mul(a, b) -> np.ndarray:
    """Hamilton product ``a * b`` (apply ``b`` first, then ``a``); leading shapes broadcast."""
    return _hamilton(_unit(a), _unit(b))


def inv(q) -> np.ndarray:
    q = np.array(q, dtype=np.float64)
    q[..., :3] *= -1.0
    return q


def apply(q, v) -> np.ndarray:
    """Rotate vectors ``v`` (..., 3) by quaternions ``q`` (..., 4); leading shapes broadcast."""
    q = _unit(q)
    v = np.asarray(v, dtype=np.float64)
    u, w = q[..., :3], q[..., 3:]
    t = 2.0 * _cross(u, v)
    return v + w * t + _cross(u, t)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` for (..., 3) arrays without its axis handling, which dominated small calls."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def log(q) -> np.ndarray:
    """Rotation vector (axis * angle, radians), the angle in [0, pi]."""
    q = _unit(q)
    q = np.where(q[..., 3:] < 0, -q, q)   # the shorter way round
    s = np.linalg.norm(q[..., :3], axis=-1)
    half = np.arctan2(s, q[..., 3])
    # angle / sin(angle / 2), by its series where sin is tiny (as SciPy does)
    small = half < 1e-3
    safe = np.where(small, 1.0, s)
    scale = np.where(small, 2.0 + half ** 2 / 3.0 + 7.0 * half ** 4 / 180.0, 2.0 * half / safe)
    return q[..., :3] * scale[..., None]


def exp(rotvec) -> np.ndarray:
    """Unit quaternions from rotation vectors (axis * angle, radians)."""
    v = np.asarray(rotvec, dtype=np.float64)
    angle = np.linalg.norm(v, axis=-1)
    small = angle <= 1e-3
    safe = np.where(small, 1.0, angle)
    scale = np.where(small, 0.5 - angle ** 2 / 48.0 + angle ** 4 / 3840.0, np.sin(angle / 2.0) / safe)
    return np.concatenate([v * scale[..., None], np.cos(angle / 2.0)[..., None]], axis=-1)


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
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz], axis=-1)


def to_euler(q, order: str, *, prev=None) -> np.ndarray:
    """BVH Euler angles (degrees, intrinsic ``order``) that vary continuously along axis 0.

    Every rotation has two Euler triples (plus 360-degree wraps). Animation tools
    interpolate the numbers, so we pick, frame by frame, the triple closest to the
    previous frame; the first frame uses SciPy's canonical range. SciPy converts
    ``EULER_CHUNK`` frames at a time: a 30-minute dance at once took 230 MB. ``prev``, the
    angles of the frame before ``q[0]``, continues a sequence converted in pieces.
    """
    q = np.asarray(q, dtype=np.float64)
    if (q.ndim < 2 or q.shape[0] < 2) and prev is None:
        return _euler(q, order.upper())
    out = np.empty(q.shape[:-1] + (3,))
    for a in range(0, q.shape[0], EULER_CHUNK):
        b = min(a + EULER_CHUNK, q.shape[0])
        out[a:b] = _continuous(_euler(q[a:b], order.upper()), order.upper(), out[a - 1] if a else prev)
    return out


EULER_CHUNK = 4096


def _euler(q: np.ndarray, order: str) -> np.ndarray:
    from scipy.spatial.transform import Rotation  # here: the command line's start-up never needs it

    return Rotation.from_quat(q).as_euler(order, degrees=True)


def _continuous(e: np.ndarray, order: str, prev: np.ndarray | None) -> np.ndarray:
    """``e``'s frames, each as the Euler triple closest to the frame before (``prev`` before the first)."""
    # The other triple of a proper (Tait-Bryan) order: (a + 180, 180 - b, c + 180);
    # for a symmetric order such as ZXZ it is (a + 180, -b, c + 180).
    alt = e.copy()
    alt[..., 0] += 180.0
    alt[..., 1] = (180.0 - e[..., 1]) if len(set(order)) == 3 else -e[..., 1]
    alt[..., 2] += 180.0
    out = np.empty_like(e)
    start = 0
    if prev is None:
        out[0], prev, start = e[0], e[0], 1
    for i in range(start, e.shape[0]):
        best = None
        for cand in (e[i], alt[i]):
            cand = cand + 360.0 * np.round((prev - cand) / 360.0)
            if best is None:
                best = cand
            else:
                closer = np.sum(np.abs(cand - prev), axis=-1) < np.sum(np.abs(best - prev), axis=-1)
                best = np.where(closer[..., None], cand, best)
        out[i] = prev = best
    return out

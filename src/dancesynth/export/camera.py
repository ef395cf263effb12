"""The camera of a dance video: a pinhole camera at a fixed elevation and a 3/4 front view of the
dancer's facing, low-passed over a few seconds (a turn is followed round slowly, a spin not at all, so
she faces the viewer most of the time), following the root horizontally through a zero-phase Gaussian
low-pass (no jitter, no lag), at a fixed height so the floor does not bob.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from .. import rotations as rot
from ..errors import ModelError
from ..motion.roles import find_roles
from ..types import MotionClip
from .figure import Figure, clip_pose, pose_points

FOV_Y_DEG = 30.0             # vertical field of view
ELEVATION_DEG = 12.0         # camera looks down at the dancer by this much
AZIMUTH_DEG = 35.0           # 3/4 view: this far round from the dancer's mean facing
FOLLOW_SIGMA_S = 0.6         # low-pass of the root path the camera follows
FACING_SIGMA_S = 2.0         # low-pass of the facing the camera turns with ...
MAX_TURN_DEG_S = 60.0        # ... turning at most this fast (where the low-passed facing is weak, it swings)


@dataclass(frozen=True)
class Camera:
    """A pinhole camera; ``project`` maps world points to output pixels (at the drawing scale)."""

    position: np.ndarray   # (3,)
    right: np.ndarray      # (3,)
    up: np.ndarray         # (3,)
    back: np.ndarray       # (3,) from the target towards the camera
    focal_px: float
    centre: tuple[float, float]

    def to_camera(self, p):
        d = np.asarray(p, dtype=np.float64) - self.position
        return np.stack([d @ self.right, d @ self.up, -(d @ self.back)], axis=-1)

    def to_pixels(self, c):
        depth = np.maximum(c[..., 2], 1e-9)
        u = self.centre[0] + self.focal_px * c[..., 0] / depth
        v = self.centre[1] - self.focal_px * c[..., 1] / depth
        return np.stack([u, v], axis=-1)


@dataclass(frozen=True)
class Shot:
    """Camera placement for a whole clip: fixed direction, target following the root."""

    target_xz: np.ndarray   # (F, 2) low-passed root path
    target_y: float
    floor_y: float
    direction: np.ndarray   # (F, 3) unit, target -> camera, per frame
    distance: float
    body_height: float


def plan_shot(clip: MotionClip, fig: Figure, aspect: float, body=None) -> Shot:
    """Floor height, body size, mean facing and the smoothed path the camera follows.

    ``body(g_rot, g_pos)``: the points (F, P, 3) whose extent is the body (default: the
    figure's joints and End Sites), e.g. a skinned mesh's vertices, whose soles stand below the ankles.
    """
    n = clip.n_frames
    sample = np.unique(np.linspace(0, n - 1, min(n, 240)).astype(np.int64))
    g_rot, g_pos = clip_pose(clip, sample)
    pts = pose_points(g_rot, g_pos, fig)
    extent = pts if body is None else body(g_rot, g_pos)
    lowest = extent[..., 1].min(axis=1)
    floor_y = float(np.percentile(lowest, 5))
    height = float(np.median(extent[..., 1].max(axis=1) - lowest))
    height = height if np.isfinite(height) and height > 1e-3 else 1.7
    yaw = _facing_yaw(clip, sample, pts) + np.radians(AZIMUTH_DEG)   # per frame, about +y from +z
    el = np.radians(ELEVATION_DEG)
    direction = np.stack([np.cos(el) * np.sin(yaw), np.full(n, np.sin(el)), np.cos(el) * np.cos(yaw)], axis=1)
    # Frame about 1.6 body heights vertically (raised arms, the floor under the feet).
    half_extent = max(0.78 * height, 0.5 * height / max(aspect, 1e-3))
    distance = half_extent / np.tan(np.radians(FOV_Y_DEG) / 2) + 0.3 * height
    xz = clip.root_pos[:, [0, 2]]
    sigma = FOLLOW_SIGMA_S * clip.fps
    target = gaussian_filter1d(xz, sigma, axis=0, mode="nearest") if n > 1 else xz.copy()
    return Shot(target, floor_y + 0.5 * height, floor_y, direction, float(distance), height)


def follow_yaw(clip: MotionClip) -> np.ndarray:
    """Per frame, where a following camera stands (radians about +y from +z, from the dancer): the video's
    3/4 view of her low-passed facing (``plan_shot``), for a player that frames the dance as the video does."""
    sample = np.unique(np.linspace(0, clip.n_frames - 1, min(clip.n_frames, 240)).astype(np.int64))
    _, g_pos = clip_pose(clip, sample)
    return _facing_yaw(clip, sample, g_pos) + np.radians(AZIMUTH_DEG)


def _facings(clip, sample, pts) -> np.ndarray:
    """Horizontal unit facing at the ``sample`` frames (0 where unknown), from the hips (left hip minus
    right hip, crossed with up), else the root's +z."""
    try:
        roles = find_roles(clip.skeleton)
        across = pts[:, roles.hips[0]] - pts[:, roles.hips[1]]
        fwd = np.cross(across, [0.0, 1.0, 0.0])
    except ModelError:
        fwd = rot.apply(clip.local_rot[sample, 0], np.array([0.0, 0.0, 1.0]))
    fwd[:, 1] = 0.0
    norm = np.linalg.norm(fwd, axis=1, keepdims=True)
    return np.where(norm > 1e-9, fwd / np.maximum(norm, 1e-9), 0.0)


def _facing_yaw(clip, sample, pts) -> np.ndarray:
    """The facing the camera turns with, per frame: the sampled facings low-passed over ``FACING_SIGMA_S``
    (as vectors, so a spin cancels out), as a yaw angle about +y from +z, unwrapped and interpolated."""
    fwd = _facings(clip, sample, pts)
    if len(sample) > 1:
        step_s = float(np.mean(np.diff(sample))) / clip.fps
        fwd = gaussian_filter1d(fwd, max(FACING_SIGMA_S / step_s, 1e-3), axis=0, mode="nearest")
    mean = fwd.sum(axis=0)
    fallback = np.arctan2(mean[0], mean[2]) if np.linalg.norm(mean) > 1e-6 else 0.0
    weak = np.linalg.norm(fwd, axis=1) < 1e-6   # no facing to follow here: hold the overall one
    yaw = np.unwrap(np.where(weak, fallback, np.arctan2(fwd[:, 0], fwd[:, 2])))
    yaw = np.interp(np.arange(clip.n_frames), sample, yaw)
    step = np.radians(MAX_TURN_DEG_S) / clip.fps
    for i in range(1, yaw.size):   # a slew limit: the camera never whips round
        yaw[i] = yaw[i - 1] + np.clip(yaw[i] - yaw[i - 1], -step, step)
    return yaw

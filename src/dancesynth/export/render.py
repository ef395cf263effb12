"""A small software renderer for dance videos: numpy projection, PIL rasterisation.

The scene is the dancer on a floor grid with a line every 0.5 m, seen by a perspective
camera at a fixed elevation from a 3/4 front view. The dancer is a character's skinned
mesh (``skinned``: z-buffered, smoothly lit triangles) or a stick figure (bones as thick
lines, joints as discs, a disc for the head); either casts a shadow of thick bones
straight down onto the floor. The camera keeps its orientation for the whole clip and
follows the root horizontally through a zero-phase Gaussian low-pass (no jitter, no
lag); its height stays fixed so the floor does not bob. Everything is drawn at twice
the output size (up to full HD) and box-filtered down, which anti-aliases edges.

Frames are produced one at a time (``FrameRenderer.frames``), with forward
kinematics (and skinning) done in chunks, so memory does not grow with the clip's length.
Y is up and lengths are metres, as everywhere in dancesynth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from PIL import Image, ImageDraw
from scipy.ndimage import gaussian_filter1d

from .. import rotations as rot
from ..errors import ModelError
from ..kinematics import fk
from ..motion.roles import find_roles
from ..types import MotionClip
from .skinned import paint

SUPERSAMPLE = 2              # draw at 2x, box-filter down: cheap anti-aliasing ...
SUPERSAMPLE_MAX_PIXELS = 1920 * 1080  # ... up to full HD; larger pictures have small enough pixels
CHUNK_FRAMES = 64            # forward kinematics per chunk of output frames
FOV_Y_DEG = 30.0             # vertical field of view
ELEVATION_DEG = 12.0         # camera looks down at the dancer by this much
AZIMUTH_DEG = 35.0           # 3/4 view: this far round from the dancer's mean facing
FOLLOW_SIGMA_S = 0.6         # low-pass of the root path the camera follows
GRID_STEP_M = 0.5            # floor grid spacing
GRID_RADIUS_M = 5.0          # grid fades out at this distance from the dancer
NEAR_M = 0.2                 # near clipping plane
MAX_SHADOW_RADIUS_M = 0.2    # no shadow bone is thicker than a torso

SKY_TOP = (214, 224, 236)
SKY_HORIZON = (244, 246, 249)
FLOOR = (241, 240, 236)
GRID_MINOR = (200, 200, 202)  # every 0.5 m
GRID_MAJOR = (172, 173, 178)  # every 1 m
SHADOW = (206, 205, 203)
COLOURS = {"l": (40, 110, 210), "r": (226, 92, 46), "": (72, 78, 92)}
HEAD = (96, 102, 116)


@dataclass(frozen=True)
class Figure:
    """What to draw of a skeleton: points (joints then End Sites) and bones between them."""

    end_joints: np.ndarray     # (E,) joint of each End Site
    end_offsets: np.ndarray    # (E, 3)
    bones: np.ndarray          # (B, 2) point indices (parent, child)
    bone_radius: np.ndarray    # (B,) metres
    bone_colour: np.ndarray    # (B, 3) float
    joint_radius: np.ndarray   # (P,) metres, 0: no disc
    joint_colour: np.ndarray   # (P, 3) float
    head_points: np.ndarray    # points whose mean is the head's centre (empty: no head)
    head_radius: float

    @property
    def n_points(self) -> int:
        return len(self.joint_radius)


def build_figure(skeleton, body_height: float | None = None) -> Figure:
    """Choose bones, thicknesses and colours (left blue, right orange) for a skeleton.

    Thicknesses scale with ``body_height`` (metres; default: the rest pose's height).
    """
    parents = skeleton.parents
    end_joints = np.array(sorted(skeleton.end_sites), dtype=np.int64)
    end_offsets = np.array([skeleton.end_sites[j] for j in end_joints]).reshape(-1, 3)
    point_parent = np.concatenate([parents, end_joints])
    offsets = np.vstack([skeleton.offsets, end_offsets])
    n_p = len(point_parent)

    def subtree(top):
        inside = np.zeros(n_p, bool)
        if top < 0:
            return inside
        inside[top] = True
        for p in range(n_p):  # parents come before children; End Sites after all joints
            if point_parent[p] >= 0 and inside[point_parent[p]]:
                inside[p] = True
        return inside

    side = np.full(n_p, "", dtype=object)
    head = -1
    try:
        roles = find_roles(skeleton)
        head = roles.head
        for k, s in enumerate("lr"):
            for top in (roles.hips[k], roles.shoulders[k]):
                side[subtree(top)] = s
    except ModelError:
        pass
    if head < 0:
        head = next((j for j, n in enumerate(skeleton.names) if "head" in n.lower()), -1)
    in_head = subtree(head)
    if head >= 0:
        in_head[head] = False

    if body_height is None:
        body_height = _rest_height(skeleton, offsets, point_parent)
    scale = max(body_height, 1e-6) / 1.7  # a 1.7 m person: scale 1
    bones, radius, colour = [], [], []
    for p in range(1, n_p):
        a = int(point_parent[p])
        length = float(np.linalg.norm(offsets[p]))
        if a < 0 or in_head[p] or length < 1e-3 * scale:
            continue
        r = float(np.clip(0.1 * length, 0.007 * scale, 0.03 * scale))
        if side[p] == "":
            r *= 1.3
        bones.append((a, p))
        radius.append(r)
        colour.append(COLOURS[side[p]])
    bones = np.array(bones, dtype=np.int64).reshape(-1, 2)
    radius = np.array(radius, dtype=np.float64)
    joint_radius = np.zeros(n_p)
    for (a, b), r in zip(bones, radius):
        joint_radius[a] = max(joint_radius[a], 1.2 * r)
        joint_radius[b] = max(joint_radius[b], 1.2 * r)
    joint_radius[joint_radius < 0.014 * scale] = 0.0  # no beads on fingers
    joint_colour = np.array([COLOURS[s] for s in side], dtype=np.float64) * 0.7
    head_points = np.flatnonzero(subtree(head)) if head >= 0 else np.zeros(0, np.int64)
    return Figure(end_joints, end_offsets, bones, radius, np.array(colour, np.float64).reshape(-1, 3),
                  joint_radius, joint_colour, head_points, 0.1 * scale)


def _rest_height(skeleton, offsets, point_parent) -> float:
    pos = np.zeros((len(point_parent), 3))
    for p in range(1, len(point_parent)):
        pos[p] = pos[point_parent[p]] + offsets[p]
    return float(np.ptp(pos[:, 1])) if len(pos) > 1 else 1.0


def clip_pose(clip: MotionClip, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global joint rotations (len(frames), J, 4) and positions (len(frames), J, 3) of the given frames."""
    sk = clip.skeleton
    local_pos = None if clip.local_pos is None else clip.local_pos[frames]
    return fk(clip.local_rot[frames], clip.root_pos[frames], sk.offsets, sk.parents, local_pos)


def pose_points(g_rot: np.ndarray, g_pos: np.ndarray, fig: Figure) -> np.ndarray:
    """World positions (..., P, 3) of joints and End Sites, from global joint rotations and positions."""
    if len(fig.end_joints) == 0:
        return g_pos
    ends = g_pos[..., fig.end_joints, :] + rot.apply(g_rot[..., fig.end_joints, :], fig.end_offsets)
    return np.concatenate([g_pos, ends], axis=-2)


def figure_points(clip: MotionClip, fig: Figure, frames: np.ndarray) -> np.ndarray:
    """World positions (len(frames), P, 3) of joints and End Sites of the given frames."""
    return pose_points(*clip_pose(clip, frames), fig)


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
    direction: np.ndarray   # (3,) unit, target -> camera
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
    forward = _mean_facing(clip, sample, pts)
    left = np.cross([0.0, 1.0, 0.0], forward)
    az, el = np.radians(AZIMUTH_DEG), np.radians(ELEVATION_DEG)
    horizontal = np.cos(az) * forward + np.sin(az) * left
    direction = np.cos(el) * horizontal + np.array([0.0, np.sin(el), 0.0])
    # Frame about 1.6 body heights vertically (raised arms, the floor under the feet).
    half_extent = max(0.78 * height, 0.5 * height / max(aspect, 1e-3))
    distance = half_extent / np.tan(np.radians(FOV_Y_DEG) / 2) + 0.3 * height
    xz = clip.root_pos[:, [0, 2]]
    sigma = FOLLOW_SIGMA_S * clip.fps
    target = gaussian_filter1d(xz, sigma, axis=0, mode="nearest") if n > 1 else xz.copy()
    return Shot(target, floor_y + 0.5 * height, floor_y, direction, float(distance), height)


def _mean_facing(clip, sample, pts) -> np.ndarray:
    """Mean horizontal facing, from the hips (left hip minus right hip, crossed with up)."""
    try:
        roles = find_roles(clip.skeleton)
        across = pts[:, roles.hips[0]] - pts[:, roles.hips[1]]
        fwd = np.cross(across, [0.0, 1.0, 0.0])
    except ModelError:
        fwd = rot.apply(clip.local_rot[sample, 0], np.array([0.0, 0.0, 1.0]))
    fwd[:, 1] = 0.0
    norm = np.linalg.norm(fwd, axis=1, keepdims=True)
    mean = (fwd / np.maximum(norm, 1e-9))[norm[:, 0] > 1e-9].sum(axis=0)
    if not np.isfinite(mean).all() or np.linalg.norm(mean) < 1e-6:
        return np.array([0.0, 0.0, 1.0])
    return mean / np.linalg.norm(mean)


class FrameRenderer:
    """Draws the frames of one clip at a given size; ``frames`` yields RGB bytes one frame at a time.

    ``mesh`` (a ``skinned.SkinnedMesh`` bound to the clip's skeleton) draws the dancer as that
    character; without it the dancer is a stick figure.
    """

    def __init__(self, clip: MotionClip, width: int, height: int, mesh=None):
        self.clip, self.width, self.height, self.mesh = clip, int(width), int(height), mesh
        self.shot = plan_shot(clip, build_figure(clip.skeleton), width / height,
                              None if mesh is None else mesh.plan_points)
        # Some rigs do not stand up in their rest pose: size the bones by the dancing body.
        self.fig = build_figure(clip.skeleton, self.shot.body_height)
        self.shadow_bones, self.shadow_radius = self.fig.bones, self.fig.bone_radius
        if mesh is not None:
            self.shadow_bones, self.shadow_radius = _mesh_shadow(mesh, self.fig, clip.skeleton)
        s = self.supersample = SUPERSAMPLE if self.width * self.height <= SUPERSAMPLE_MAX_PIXELS else 1
        self.size = (self.width * s, self.height * s)
        self.focal = (self.height * s / 2) / np.tan(np.radians(FOV_Y_DEG) / 2)
        back = self.shot.direction
        right = np.cross([0.0, 1.0, 0.0], back)
        right /= np.linalg.norm(right)
        self.basis = (right, np.cross(back, right), back)
        self.background = self._background()
        self.canvas = self.background.copy()  # drawn on afresh each frame: no new 6 MB image per frame

    def camera(self, frame: int) -> Camera:
        tx, tz = self.shot.target_xz[frame]
        target = np.array([tx, self.shot.target_y, tz])
        right, up, back = self.basis
        return Camera(target + self.shot.distance * back, right, up, back, self.focal,
                      (self.size[0] / 2, self.size[1] / 2))

    def _background(self) -> Image.Image:
        """Sky gradient above the horizon, plain floor below (the horizon row never moves)."""
        w, h = self.size
        horizon = h / 2 - self.focal * np.tan(np.radians(ELEVATION_DEG))
        rows = np.arange(h, dtype=np.float64)
        t = np.clip(rows / max(horizon, 1.0), 0.0, 1.0)[:, None]
        sky = np.array(SKY_TOP) * (1 - t) + np.array(SKY_HORIZON) * t
        col = np.where((rows < horizon)[:, None], sky, np.array(FLOOR, dtype=np.float64))
        img = np.broadcast_to(col[:, None, :].round().astype(np.uint8), (h, w, 3))
        return Image.fromarray(np.ascontiguousarray(img), "RGB")

    def frames(self, source_frames):
        """Yield each frame (``source_frames``: clip frame indices) as packed RGB bytes."""
        source_frames = np.asarray(source_frames, dtype=np.int64)
        for start in range(0, len(source_frames), CHUNK_FRAMES):
            idx = source_frames[start:start + CHUNK_FRAMES]
            g_rot, g_pos = clip_pose(self.clip, idx)
            pts = pose_points(g_rot, g_pos, self.fig)
            posed = [None] * len(idx)
            if self.mesh is not None:
                posed = self.mesh.pose(g_rot, g_pos, [self.camera(int(f)) for f in idx], NEAR_M)
            for k, f in enumerate(idx):
                yield self.draw(int(f), pts[k], posed[k]).tobytes()

    def draw(self, frame: int, points: np.ndarray, posed=None) -> Image.Image:
        """One frame as an image of the output size; ``points`` (P, 3) from ``figure_points``;
        ``posed``: the mesh's frame from ``SkinnedMesh.pose`` (``None``: draw the stick figure)."""
        cam = self.camera(frame)
        img = self.canvas
        img.paste(self.background)
        d = ImageDraw.Draw(img)
        self._draw_grid(d, cam)
        self._draw_shadow(d, cam, points)
        if posed is None:
            self._draw_figure(d, cam, points)
        else:
            paint(img, self.mesh, posed)
        return img.reduce(self.supersample) if self.supersample > 1 else img.copy()

    def _draw_grid(self, d, cam: Camera) -> None:
        step, radius = GRID_STEP_M, GRID_RADIUS_M
        target = cam.position - self.shot.distance * cam.back
        tx, tz = target[0], target[2]
        ticks_x = np.arange(np.ceil((tx - radius) / step), np.floor((tx + radius) / step) + 1) * step
        ticks_z = np.arange(np.ceil((tz - radius) / step), np.floor((tz + radius) / step) + 1) * step
        y = self.shot.floor_y
        segs = []
        # Lines of constant x run along z, cut into grid-cell pieces so each can fade on its own.
        for along_x, ticks, across in ((False, ticks_x, ticks_z), (True, ticks_z, ticks_x)):
            a, b = np.meshgrid(ticks, across[:-1], indexing="ij")
            a, b = a.ravel(), b.ravel()
            p0 = np.stack([b, np.full_like(a, y), a] if along_x else [a, np.full_like(a, y), b], axis=-1)
            p1 = p0.copy()
            p1[:, 0 if along_x else 2] += step
            major = np.abs(a - np.round(a)) < 1e-6  # whole metres
            segs.append((p0, p1, major))
        p0 = np.concatenate([s[0] for s in segs])
        p1 = np.concatenate([s[1] for s in segs])
        major = np.concatenate([s[2] for s in segs])
        mid = (p0 + p1) / 2
        dist = np.hypot(mid[:, 0] - tx, mid[:, 2] - tz)
        alpha = np.clip((radius - dist) / (0.5 * radius), 0.0, 1.0)
        keep = alpha > 0.02
        c0, c1 = _clip_near(cam.to_camera(p0[keep]), cam.to_camera(p1[keep]))
        ok = np.isfinite(c0[:, 0])
        uv0, uv1 = cam.to_pixels(c0[ok]), cam.to_pixels(c1[ok])
        alpha, major = alpha[keep][ok], major[keep][ok]
        floor = np.array(FLOOR, dtype=np.float64)
        lines = np.where(major[:, None], np.array(GRID_MAJOR, float), np.array(GRID_MINOR, float))
        cols = np.rint(floor + alpha[:, None] * (lines - floor)).astype(np.int64)
        inks = cols[:, 0] | cols[:, 1] << 8 | cols[:, 2] << 16  # packed RGB: PIL takes it as is, no tuples
        width, line = self.supersample, d.line
        for xy, ink in zip(np.concatenate([uv0, uv1], axis=1).tolist(), inks.tolist()):
            line(xy, fill=ink, width=width)

    def _draw_shadow(self, d, cam: Camera, points: np.ndarray) -> None:
        flat = points.copy()
        flat[:, 1] = self.shot.floor_y
        c = cam.to_camera(flat)
        if np.any(c[:, 2] < NEAR_M):
            return
        uv = cam.to_pixels(c).tolist()
        px = self.focal / c[:, 2]
        for (a, b), r in zip(self.shadow_bones.tolist(), self.shadow_radius.tolist()):
            w = max(1.0, 2 * r * px[b])
            d.line((*uv[a], *uv[b]), fill=SHADOW, width=int(round(w)))
            _disc(d, uv[b], w / 2, SHADOW)

    def _draw_figure(self, d, cam: Camera, points: np.ndarray) -> None:
        fig = self.fig
        c = cam.to_camera(points)
        depth = c[:, 2]
        if np.any(depth < NEAR_M):
            return
        uv = cam.to_pixels(c)
        px = self.focal / depth
        bg = np.array(FLOOR, dtype=np.float64)
        root_depth = depth[0]
        # Farther parts fade a little towards the background: a cheap depth cue.
        fade = 0.35 * np.clip((depth - root_depth) / (0.5 * self.shot.body_height), 0.0, 1.0)[:, None]
        items = []  # (depth, kind, index)
        a, b = fig.bones[:, 0], fig.bones[:, 1]
        bone_depth = (depth[a] + depth[b]) / 2
        items += [(bd, 0, i) for i, bd in enumerate(bone_depth.tolist())]
        discs = np.flatnonzero(fig.joint_radius > 0)
        items += [(depth[j] - 1e-3, 1, int(j)) for j in discs]
        if len(fig.head_points):
            head_c = c[fig.head_points].mean(axis=0)
            items.append((head_c[2] - 0.05, 2, 0))
        items.sort(key=lambda t: -t[0])  # far first (painter's algorithm)
        uvl = uv.tolist()
        for _, kind, i in items:
            if kind == 0:
                pa, pb = int(a[i]), int(b[i])
                f = (fade[pa] + fade[pb]) / 2
                col = _rgb(fig.bone_colour[i] * (1 - f) + bg * f)
                w = max(1.0, 2 * fig.bone_radius[i] * (px[pa] + px[pb]) / 2)
                d.line((*uvl[pa], *uvl[pb]), fill=col, width=int(round(w)))
                _disc(d, uvl[pa], w / 2, col)
                _disc(d, uvl[pb], w / 2, col)
            elif kind == 1:
                col = _rgb(fig.joint_colour[i] * (1 - fade[i]) + bg * fade[i])
                _disc(d, uvl[i], fig.joint_radius[i] * px[i], col)
            else:
                (u, v), = cam.to_pixels(head_c[None]).tolist()
                f = 0.35 * np.clip((head_c[2] - root_depth) / (0.5 * self.shot.body_height), 0.0, 1.0)
                col = _rgb(np.array(HEAD, float) * (1 - f) + bg * f)
                _disc(d, (u, v), fig.head_radius * self.focal / head_c[2], col)


def _mesh_shadow(mesh, fig: Figure, skeleton) -> tuple[np.ndarray, np.ndarray]:
    """Shadow bones (every joint to each child point, the head's too) as thick as the mesh around them."""
    point_parent = np.concatenate([skeleton.parents, fig.end_joints])
    bones = np.stack([point_parent[1:], np.arange(1, len(point_parent))], axis=1)
    rest = pose_points(mesh.bind_rot, mesh.bind_pos, fig)
    # Capped at a body's half-width: a prop hanging from a bone (a VRM's flat panel) is not a limb.
    radius = np.minimum(mesh.shadow_radii(rest, bones), MAX_SHADOW_RADIUS_M)
    keep = radius > 0
    return bones[keep], radius[keep]


def _rgb(c) -> tuple[int, int, int]:
    r, g, b = np.rint(c).astype(int).tolist()
    return (r, g, b)


def _disc(d, centre, r: float, fill) -> None:
    if r < 0.75:
        return
    u, v = centre
    d.ellipse((u - r, v - r, u + r, v + r), fill=fill)


def _clip_near(c0: np.ndarray, c1: np.ndarray):
    """Clip segments (camera coordinates) to depth >= NEAR_M; dropped ones become NaN."""
    c0, c1 = c0.copy(), c1.copy()
    d0, d1 = c0[:, 2] - NEAR_M, c1[:, 2] - NEAR_M
    gone = (d0 < 0) & (d1 < 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = d0 / (d0 - d1)
    cut0 = (d0 < 0) & ~gone
    cut1 = (d1 < 0) & ~gone
    c0[cut0] = c0[cut0] + t[cut0, None] * (c1[cut0] - c0[cut0])
    c1[cut1] = c0[cut1] + t[cut1, None] * (c1[cut1] - c0[cut1])
    c0[gone] = np.nan
    c1[gone] = np.nan
    return c0, c1

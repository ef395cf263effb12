"""A small software renderer for dance videos: numpy projection and rasterisation, PIL for discs and thick lines
(what to draw of a skeleton is in ``figure``, the camera in ``camera``, the pixel helpers in ``raster``).

The scene is the dancer on a floor grid with a line every 0.5 m, seen by a perspective
camera at a fixed elevation from a 3/4 front view. The dancer is a character's skinned
mesh (``skinned``: z-buffered, smoothly lit triangles) or a stick figure (bones as thick
lines, joints as discs, a disc for the head); either casts a shadow of thick bones
straight down onto the floor. The camera keeps its orientation for the whole clip and
follows the root horizontally through a zero-phase Gaussian low-pass (no jitter, no
lag); its height stays fixed so the floor does not bob. The dancer and the shadow are
drawn at twice the output size (up to full HD) and box-filtered down, which anti-aliases
their edges; the grid's lines are drawn anti-aliased at the output size.

Frames are produced one at a time (``FrameRenderer.frames``), with forward
kinematics (and skinning) done in chunks, so memory does not grow with the clip's length.
They come as RGB, or already as the Y'CbCr planes an H.264 encoder takes (``pix_fmt``), so
that ffmpeg, running beside the renderer on the other core, only encodes.
Y is up and lengths are metres, as everywhere in dancesynth.
"""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw

from ..types import MotionClip
from .camera import ELEVATION_DEG, FOV_Y_DEG, Camera, plan_shot
from .figure import Figure, build_figure, clip_pose, pose_points
from .raster import box_reduce, disc, image_planes, luma, pack, packed_image, smooth_lines, to_ycbcr, unpack, upsample
from .skinned import rasterise

SUPERSAMPLE = 2              # draw at 2x, box-filter down: cheap anti-aliasing ...
SUPERSAMPLE_MAX_PIXELS = 1920 * 1080  # ... up to full HD; larger pictures have small enough pixels
CHUNK_FRAMES = 64            # forward kinematics per chunk of output frames
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
PIX_FMTS = ("rgb24", "yuv420p")
HEAD = (96, 102, 116)


class FrameRenderer:
    """Draws the frames of one clip at a given size; ``frames`` yields them one at a time as bytes.

    ``mesh`` (a ``skinned.SkinnedMesh`` bound to the clip's skeleton) draws the dancer as that
    character; without it the dancer is a stick figure. ``pix_fmt``: what ``frames`` yields,
    ``"rgb24"`` (packed RGB) or ``"yuv420p"`` (the planes H.264 encodes: BT.601 limited-range
    Y'CbCr with chroma at half size, as ffmpeg would convert the RGB frame, so it has nothing to convert).

    How a frame is drawn, cheaply: the floor (its grid and the dancer's shadow, all greys on one line
    through the floor's colour) is one 8-bit channel, its luma, at the output size: the grid's lines are
    drawn anti-aliased straight into it, the shadow at the drawing scale in its own box. The rows of sky
    above the floor never change and are drawn once. Only the box round the dancer is drawn in colour at
    the drawing scale, over the floor under it, and box-filtered down.
    """

    def __init__(self, clip: MotionClip, width: int, height: int, mesh=None, pix_fmt: str = "rgb24"):
        if pix_fmt not in PIX_FMTS:
            raise ValueError(f"pix_fmt must be one of {PIX_FMTS}, got {pix_fmt!r}")
        self.clip, self.width, self.height, self.mesh, self.pix_fmt = clip, int(width), int(height), mesh, pix_fmt
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
        self._colours = to_ycbcr if pix_fmt == "yuv420p" else (lambda rgb: np.asarray(rgb, dtype=np.float64))
        self.shades = None
        if mesh is not None:
            self.shades = mesh.shades if pix_fmt == "rgb24" else pack(self._colours(unpack(mesh.shades)))
        self._prepare_background()

    def camera(self, frame: int) -> Camera:
        tx, tz = self.shot.target_xz[frame]
        target = np.array([tx, self.shot.target_y, tz])
        back = self.shot.direction[frame]
        right = np.cross([0.0, 1.0, 0.0], back)
        right /= np.linalg.norm(right)
        up = np.cross(back, right)
        return Camera(target + self.shot.distance * back, right, up, back, self.focal,
                      (self.size[0] / 2, self.size[1] / 2))

    # ---------------------------------------------------------------- what does not move

    def _prepare_background(self) -> None:
        """The sky band (drawn once) and how the floor's luma turns into colours."""
        s, w = self.supersample, self.size[0]
        horizon = self.size[1] / 2 - self.focal * np.tan(np.radians(ELEVATION_DEG))
        # The band: whole chroma rows (2 output rows) down to below the horizon. The floor's grid ends
        # GRID_RADIUS_M from the dancer, far below the horizon: nothing but the dancer is drawn over the band.
        self.band = band = int(min(self.height, max(0, 2 * np.ceil(horizon / (2 * s)))))   # output rows
        rows = np.arange(band * s, dtype=np.float64)
        t = np.clip(rows / max(horizon, 1.0), 0.0, 1.0)[:, None]
        sky = np.array(SKY_TOP) * (1 - t) + np.array(SKY_HORIZON) * t
        col = np.where((rows < horizon)[:, None], sky.round(), np.array(FLOOR, dtype=np.float64))
        self.band_packed = np.ascontiguousarray(np.broadcast_to(pack(self._colours(col))[:, None], (band * s, w)))
        band_out = box_reduce(packed_image(self.band_packed), s)
        if self.pix_fmt == "yuv420p":
            self.band_yuv = image_planes(band_out)
        else:
            self.band_rgb = band_out.convert("RGB")

        # The floor holds luma (BT.601, limited range); its colours lie on the line from the floor's
        # colour to the major grid lines', so a luma value says which colour it is.
        self.floor_y = float(luma(FLOOR))
        self.floor = np.full((self.height, self.width), int(round(self.floor_y)), np.uint8)
        level = np.arange(256, dtype=np.float64)
        along = (self.floor_y - level) / (self.floor_y - float(luma(GRID_MAJOR)))
        floor_rgb = np.clip(np.array(FLOOR, float) + along[:, None] * (np.array(GRID_MAJOR, float) - FLOOR), 0, 255)
        if self.pix_fmt == "yuv420p":
            ycc = to_ycbcr(floor_rgb)
            ycc[:, 0] = level  # the floor's value is the luma itself
            self.floor_packed = pack(ycc)
            self.floor_uv = [np.clip(np.rint(ycc[:, k]), 0, 255).astype(np.uint8) for k in (1, 2)]
        else:
            self.floor_packed = pack(floor_rgb)
            self.floor_palette = np.rint(floor_rgb).astype(np.uint8).tobytes()

    def _ink(self, rgb) -> int:
        """An sRGB colour (3,) as a packed ink in this renderer's colour space."""
        return int(pack(self._colours(rgb)))

    # ---------------------------------------------------------------- frames

    def frames(self, source_frames):
        """Yield each frame (``source_frames``: clip frame indices) in ``pix_fmt``: ``bytes`` (rgb24), or a
        uint8 array holding the Y, Cb and Cr planes one after the other (yuv420p; a new one each frame)."""
        source_frames = np.asarray(source_frames, dtype=np.int64)
        for start in range(0, len(source_frames), CHUNK_FRAMES):
            idx = source_frames[start:start + CHUNK_FRAMES]
            g_rot, g_pos = clip_pose(self.clip, idx)
            pts = pose_points(g_rot, g_pos, self.fig)
            posed = [None] * len(idx)
            if self.mesh is not None:
                posed = self.mesh.pose(g_rot, g_pos, [self.camera(int(f)) for f in idx], NEAR_M)
            for k, f in enumerate(idx):
                if self.pix_fmt == "rgb24":
                    yield self._rgb(*self._render(int(f), pts[k], posed[k], self.floor)).tobytes()
                else:
                    w, h = self.width, self.height
                    frame = np.empty(w * h * 3 // 2, np.uint8)
                    planes = [frame[:w * h].reshape(h, w), frame[w * h:w * h * 5 // 4].reshape(h // 2, w // 2),
                              frame[w * h * 5 // 4:].reshape(h // 2, w // 2)]
                    _, box, patch = self._render(int(f), pts[k], posed[k], planes[0])  # the floor is the Y plane
                    self._yuv(planes, box, patch)
                    yield frame

    def draw(self, frame: int, points: np.ndarray, posed=None) -> Image.Image:
        """One frame as an RGB image of the output size (an ``rgb24`` renderer's); ``points`` (P, 3) from
        ``figure.figure_points``; ``posed``: the mesh's frame from ``SkinnedMesh.pose`` (``None``: the stick figure)."""
        if self.pix_fmt != "rgb24":
            raise ValueError("draw() makes RGB pictures: use a renderer with pix_fmt='rgb24'")
        return self._rgb(*self._render(frame, points, posed, self.floor))

    def _render(self, frame: int, points: np.ndarray, posed, floor: np.ndarray):
        """Draw the frame's floor into ``floor`` (output size, luma; above the band: left as it is); return
        it, the dancer's box (output pixels) and the dancer's picture there (RGBX, this colour space)."""
        cam = self.camera(frame)
        floor[self.band:] = int(round(self.floor_y))
        self._draw_grid(floor, cam)
        self._draw_shadow(floor, cam, points)
        box = self._figure_box(cam, points) if posed is None else self._mesh_box(posed)
        if box is None:
            return floor, None, None
        canvas = self._underlay(box, floor)
        if posed is None:
            img = packed_image(canvas)
            self._draw_figure(ImageDraw.Draw(img), cam, points, box[:2])
        else:
            rasterise(canvas, self.mesh, posed, self.shades, box[:2])
            img = packed_image(canvas)
        s = self.supersample
        return floor, tuple(v // s for v in box), box_reduce(img, s)

    def _rgb(self, floor: np.ndarray, box, patch) -> Image.Image:
        img = Image.frombuffer("L", (self.width, self.height), floor, "raw", "L", 0, 1)
        img = img.copy()
        img.putpalette(self.floor_palette, "RGB")
        img = img.convert("RGB")
        if self.band:
            img.paste(self.band_rgb, (0, 0))
        if patch is not None:
            img.paste(patch.convert("RGB"), box[:2])
        return img

    def _yuv(self, planes: list[np.ndarray], box, patch) -> None:
        """Fill in the planes of a frame (Y, Cb, Cr) whose Y plane holds the floor drawn by ``_render``."""
        y = np.ascontiguousarray(planes[0])
        quarter = np.asarray(Image.frombuffer("L", (self.width, self.height), y, "raw", "L", 0, 1).reduce(2))
        for plane, lut in zip(planes[1:], self.floor_uv):
            np.take(lut, quarter, out=plane)
        if self.band:
            for plane, band in zip(planes, self.band_yuv):
                plane[:len(band)] = band
        if patch is not None:
            x0, y0 = box[0], box[1]
            for k, part in enumerate(image_planes(patch)):
                d = 1 if k == 0 else 2
                planes[k][y0 // d:y0 // d + part.shape[0], x0 // d:x0 // d + part.shape[1]] = part

    # ---------------------------------------------------------------- the dancer's box

    def _align(self, x0, y0, x1, y1):
        """A box (drawing pixels) grown to whole chroma pixels and cut to the picture; None if empty."""
        a = 2 * self.supersample
        w, h = self.size
        box = (max(0, int(np.floor(x0 / a)) * a), max(0, int(np.floor(y0 / a)) * a),
               min(w, int(np.ceil(x1 / a)) * a), min(h, int(np.ceil(y1 / a)) * a))
        return box if box[2] > box[0] and box[3] > box[1] else None

    def _mesh_box(self, posed):
        if self.mesh is None:
            return None
        u, v = posed[0], posed[1]
        ok = np.isfinite(u) & np.isfinite(v)
        if not ok.any():
            return None
        u, v = u[ok], v[ok]
        return self._align(float(u.min()) - 1, float(v.min()) - 1, float(u.max()) + 2, float(v.max()) + 2)

    def _figure_box(self, cam: Camera, points: np.ndarray):
        c = cam.to_camera(points)
        if np.any(c[:, 2] < NEAR_M):
            return None
        uv = cam.to_pixels(c)
        fig = self.fig
        biggest = max(float(fig.bone_radius.max(initial=0.0)), float(fig.joint_radius.max(initial=0.0)),
                      fig.head_radius)
        r = 1.2 * biggest * self.focal / float(c[:, 2].min()) + 2
        return self._align(uv[:, 0].min() - r, uv[:, 1].min() - r, uv[:, 0].max() + r, uv[:, 1].max() + r)

    def _underlay(self, box, floor: np.ndarray) -> np.ndarray:
        """What is drawn under a box (drawing pixels, aligned): packed colours (H, W) uint32, sky and ``floor``."""
        s = self.supersample
        x0, y0, x1, y1 = box
        out = np.empty((y1 - y0, x1 - x0), np.uint32)
        split = min(max(self.band * s, y0), y1)
        if split > y0:
            out[:split - y0] = self.band_packed[y0:split, x0:x1]
        if y1 > split:
            out[split - y0:] = upsample(np.take(self.floor_packed, floor[split // s:y1 // s, x0 // s:x1 // s]), s)
        return out

    # ---------------------------------------------------------------- drawing

    def _draw_grid(self, floor: np.ndarray, cam: Camera) -> None:
        """The floor's grid, lines a pixel wide, anti-aliased, into the floor (output size, luma)."""
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
        s = self.supersample
        uv0, uv1 = cam.to_pixels(c0[ok]) / s, cam.to_pixels(c1[ok]) / s
        alpha, major = alpha[keep][ok], major[keep][ok]
        # Each line darkens the floor's luma by its own colour's, faded into the floor's.
        lines = np.where(major, float(luma(GRID_MAJOR)), float(luma(GRID_MINOR)))
        smooth_lines(floor, uv0, uv1, alpha * (self.floor_y - lines), self.floor_y)

    def _draw_shadow(self, floor: np.ndarray, cam: Camera, points: np.ndarray) -> None:
        """The shadow (thick bones straight down on the floor), drawn at the drawing scale in its box."""
        flat = points.copy()
        flat[:, 1] = self.shot.floor_y
        c = cam.to_camera(flat)
        if np.any(c[:, 2] < NEAR_M):
            return
        uv = cam.to_pixels(c)
        px = self.focal / c[:, 2]
        bones, radius = self.shadow_bones, self.shadow_radius
        if len(bones) == 0:
            return
        reach = float((np.maximum(1.0, 2 * radius * px[bones[:, 1]]) / 2).max()) + 2
        box = self._align(uv[:, 0].min() - reach, uv[:, 1].min() - reach, uv[:, 0].max() + reach,
                          uv[:, 1].max() + reach)
        if box is None:
            return
        s = self.supersample
        x0, y0, x1, y1 = (v // s for v in box)
        under = floor[y0:y1, x0:x1]
        img = Image.fromarray(upsample(under, s))
        d = ImageDraw.Draw(img)
        uv = (uv - box[:2]).tolist()
        ink = int(round(float(luma(SHADOW))))  # into the floor, as luma
        for (a, b), r in zip(bones.tolist(), radius.tolist()):
            w = max(1.0, 2 * r * px[b])
            d.line((*uv[a], *uv[b]), fill=ink, width=int(round(w)))
            disc(d, uv[b], w / 2, ink)
        under[:] = np.asarray(box_reduce(img, s))

    def _draw_figure(self, d, cam: Camera, points: np.ndarray, offset=(0, 0)) -> None:
        """The stick figure, into the dancer's box whose top left corner is at ``offset`` (drawing pixels)."""
        fig = self.fig
        c = cam.to_camera(points)
        depth = c[:, 2]
        if np.any(depth < NEAR_M):
            return
        uv = cam.to_pixels(c) - offset
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
                col = self._ink(fig.bone_colour[i] * (1 - f) + bg * f)
                w = max(1.0, 2 * fig.bone_radius[i] * (px[pa] + px[pb]) / 2)
                d.line((*uvl[pa], *uvl[pb]), fill=col, width=int(round(w)))
                disc(d, uvl[pa], w / 2, col)
                disc(d, uvl[pb], w / 2, col)
            elif kind == 1:
                col = self._ink(fig.joint_colour[i] * (1 - fade[i]) + bg * fade[i])
                disc(d, uvl[i], fig.joint_radius[i] * px[i], col)
            else:
                (u, v), = (cam.to_pixels(head_c[None]) - offset).tolist()
                f = 0.35 * np.clip((head_c[2] - root_depth) / (0.5 * self.shot.body_height), 0.0, 1.0)
                col = self._ink(np.array(HEAD, float) * (1 - f) + bg * f)
                disc(d, (u, v), fig.head_radius * self.focal / head_c[2], col)


def _mesh_shadow(mesh, fig: Figure, skeleton) -> tuple[np.ndarray, np.ndarray]:
    """Shadow bones (every joint to each child point, the head's too) as thick as the mesh around them."""
    point_parent = np.concatenate([skeleton.parents, fig.end_joints])
    bones = np.stack([point_parent[1:], np.arange(1, len(point_parent))], axis=1)
    rest = pose_points(mesh.bind_rot, mesh.bind_pos, fig)
    # Capped at a body's half-width: a prop hanging from a bone (a VRM's flat panel) is not a limb.
    radius = np.minimum(mesh.shadow_radii(rest, bones), MAX_SHADOW_RADIUS_M)
    keep = radius > 0
    return bones[keep], radius[keep]


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

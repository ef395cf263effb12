"""The skinned character of dance videos: linear blend skinning and a z-buffered triangle rasteriser in numpy.

``SkinnedMesh.from_character`` makes a ``Character``'s mesh ready to draw: it checks the
mesh against the skeleton and gives each joint its inverse bind transform from the
character's rest pose.

``SkinnedMesh.pose`` does the per-vertex work for a chunk of frames at once: skinning
(each vertex's blend of its joints' transforms, gathered rather than a matrix product,
so no BLAS threads spin against ffmpeg; arrays are component-major, (F, 3, V), so each
step runs over contiguous memory), Lambert lighting of every vertex (a key light, a
weaker fill and a sky/ground ambient, placed by the camera's orientation, which is
fixed for the clip) and projection.

``rasterise`` then draws one frame into a canvas of packed colours (the renderer's box round
the dancer, at its supersampled scale): the triangles facing the camera (back faces are
culled) are cut into two trapezoids each and those into pixel runs along each row, every
pixel gets its depth (1/z, which is linear on the screen) and light interpolated from the
corners, and a z-buffer keeps the nearest: one ``np.maximum.at`` over keys that hold the
depth's bits above the pixel's colour (albedo x light, looked up in a table of sRGB, or of
another colour space's, values). A z-buffer, unlike the painter's algorithm, has no ordering
errors to flicker where limbs cross or where the parts of a body that overlap (an arm's
ball inside the shoulder, a body under its clothes) meet; interpolating the light
(Gouraud) hides the facets. ``paint`` does the same into a PIL image.

The shadow is the stick figure's (thick bones projected onto the floor), each bone as
thick as the mesh around it (``shadow_radii``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from PIL import Image
from scipy.spatial.transform import Rotation

from ..errors import InputError
from ..kinematics import fk

# Light directions (towards the light) in the camera's basis (right, up, back): the key
# light is above the camera and to its left, the fill comes from the right.
KEY_LIGHT = (-0.6, 0.7, 0.4)
FILL_LIGHT = (0.8, 0.0, 0.3)
KEY, FILL = 0.85, 0.2
SKY_AMBIENT, GROUND_AMBIENT = 0.32, 0.12   # ambient from above / from below (a hemisphere light)
SHADOW_RADIUS_PERCENTILE = 75              # how thick a bone's shadow is, of its vertices' distances
PLAN_VERTICES = 1500                       # vertices skinned to find the floor and the body's size
LIGHT_LEVELS, MAX_LIGHT = 256, 1.5          # light is looked up in this many steps from 0 to MAX_LIGHT
MAX_COLOURS = 4096                         # distinct albedos kept (fewer bits per channel if a mesh has more)


def _srgb(linear: np.ndarray) -> np.ndarray:
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def _linear(srgb: np.ndarray) -> np.ndarray:
    return np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)


def _shade_table(albedo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each triangle's colour index (T,), and colour c under light level q as 8-bit sRGB packed in a
    uint32 (red in the low byte) at c * LIGHT_LEVELS + q: a pixel's colour is then one lookup."""
    for bits in (8, 6, 5, 4):
        steps = (1 << bits) - 1
        colours, index = np.unique(np.rint(_srgb(albedo) * steps), axis=0, return_inverse=True)
        if len(colours) <= MAX_COLOURS:
            break
    light = np.linspace(0.0, MAX_LIGHT, LIGHT_LEVELS)
    rgb = np.rint(255 * _srgb(_linear(colours / steps)[:, None, :] * light[None, :, None]))
    rgb = rgb.astype(np.uint32).reshape(-1, 3)
    return index.reshape(-1).astype(np.int32), rgb[:, 0] | rgb[:, 1] << 8 | rgb[:, 2] << 16


@dataclass(frozen=True, eq=False)
class SkinnedMesh:
    """A character's mesh prepared for drawing (float32 unless noted)."""

    positions: np.ndarray       # (V, 3) bind pose
    normals: np.ndarray         # (V, 3) bind pose, unit
    corners: np.ndarray         # (3, T) int64 each triangle's vertices, counter-clockwise seen from outside
    joints: np.ndarray          # (V, K) int64: the joints that move each vertex (K <= 4) ...
    weights: np.ndarray         # (V, K) ... and how much; rows sum to 1
    colour: np.ndarray          # (T,) int32 each triangle's colour (its corners' mean) in ``shades``
    shades: np.ndarray          # (C * LIGHT_LEVELS,) uint32 packed sRGB of each colour under each light level
    bind_rot: np.ndarray        # (J, 4) global joint rotations in the rest pose (float64)
    bind_pos: np.ndarray        # (J, 3) global joint positions in the rest pose (float64)
    inverse_bind: np.ndarray    # (J, 3, 4) world -> joint frame in the rest pose (float64)

    @classmethod
    def from_character(cls, character) -> "SkinnedMesh":
        """Check ``character.mesh`` against its skeleton (``InputError`` naming what is wrong) and prepare it."""
        mesh, sk = character.mesh, character.skeleton
        n_joints = sk.n_joints
        positions = np.asarray(mesh.positions, dtype=np.float32)
        n = len(positions)
        triangles = np.asarray(mesh.indices, dtype=np.int64).reshape(-1, 3)
        joints = np.array(mesh.joints, dtype=np.int64)
        weights = np.array(mesh.weights, dtype=np.float32)
        problem = None
        if positions.shape != (n, 3) or n == 0 or len(triangles) == 0:
            problem = "it has no vertices or no triangles"
        elif np.shape(mesh.normals) != (n, 3) or np.shape(mesh.colours) != (n, 3):
            problem = "its normals or colours do not match its vertices"
        elif joints.shape != weights.shape or joints.ndim != 2 or len(joints) != n:
            problem = "its skinning joints and weights do not match its vertices"
        elif triangles.min() < 0 or triangles.max() >= n:
            problem = "a triangle refers to a vertex it does not have"
        elif joints.min() < 0 or joints.max() >= n_joints:
            problem = f"a vertex is bound to a joint its {n_joints}-joint skeleton does not have"
        elif not all(np.isfinite(a).all() for a in (positions, mesh.normals, weights, mesh.colours)):
            problem = "it contains NaN or infinite values"
        if problem:
            raise InputError(f"character {character.name!r}: cannot draw its mesh: {problem}")

        weights = np.maximum(weights, 0.0)
        unbound = weights.sum(axis=1) <= 0  # follows the root rather than collapsing to the origin
        joints[unbound, 0], weights[unbound, 0] = 0, 1.0
        weights /= weights.sum(axis=1, keepdims=True)
        used = weights.any(axis=0)  # influences no vertex uses cost time and add nothing
        rest_rot, rest_pos = fk(np.asarray(character.rest_rot)[None], np.asarray(character.rest_root)[None],
                                sk.offsets, sk.parents)
        inv_r = np.swapaxes(_matrices(rest_rot[0]), -1, -2)
        inverse_bind = np.concatenate([inv_r, -(inv_r @ rest_pos[0][..., None])], axis=-1)
        normals = np.asarray(mesh.normals, dtype=np.float32)
        normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        colours = np.clip(np.asarray(mesh.colours, dtype=np.float32), 0.0, 1.0)
        return cls(positions, normals, np.ascontiguousarray(triangles.T), joints[:, used], weights[:, used],
                   *_shade_table(colours[triangles].mean(axis=1)), rest_rot[0], rest_pos[0], inverse_bind)

    def skin(self, g_rot: np.ndarray, g_pos: np.ndarray, vertices=slice(None)):
        """Skinned positions and (not normalised) normals, each (F, 3, V), from global joint
        rotations (F, J, 4) and positions (F, J, 3); ``vertices`` picks a subset."""
        r = _matrices(g_rot)                                                 # (F, J, 3, 3)
        joint = np.concatenate([r @ self.inverse_bind[..., :3], r @ self.inverse_bind[..., 3:] + g_pos[..., None]],
                               axis=-1)                                      # (F, J, 3, 4)
        f, j = joint.shape[:2]
        per_joint = np.ascontiguousarray(joint.reshape(f, j, 12).transpose(0, 2, 1), dtype=np.float32)
        idx, w = self.joints[vertices], self.weights[vertices]
        blend = per_joint[:, :, idx[:, 0]] * w[:, 0]                         # (F, 12, V)
        for k in range(1, idx.shape[1]):
            blend += per_joint[:, :, idx[:, k]] * w[:, k]
        blend = blend.reshape(f, 3, 4, -1)
        (x, y, z), (nx, ny, nz) = self.positions[vertices].T, self.normals[vertices].T
        pos = blend[:, :, 0] * x + blend[:, :, 1] * y + blend[:, :, 2] * z + blend[:, :, 3]
        nrm = blend[:, :, 0] * nx + blend[:, :, 1] * ny + blend[:, :, 2] * nz
        return pos, nrm

    def plan_points(self, g_rot: np.ndarray, g_pos: np.ndarray) -> np.ndarray:
        """Skinned positions (F, P, 3) of up to ``PLAN_VERTICES`` vertices spread over the mesh (to size the shot)."""
        step = max(1, len(self.positions) // PLAN_VERTICES)
        return self.skin(g_rot, g_pos, slice(None, None, step))[0].transpose(0, 2, 1)

    def pose(self, g_rot: np.ndarray, g_pos: np.ndarray, cameras, near: float) -> list:
        """What ``paint`` needs of each frame of a chunk: ``(u, v, w, light)``, each vertex's pixel
        coordinates, 1/depth and light (V,) float32; NaN for a vertex nearer than ``near``.

        ``g_rot`` (F, J, 4), ``g_pos`` (F, J, 3): the frames' global joint rotations and positions;
        ``cameras``: each frame's ``camera.Camera`` (one focal length and centre; each its own place and
        orientation); nothing nearer than ``near``."""
        pos, nrm = self.skin(g_rot, g_pos)
        cam = cameras[0]
        pos -= np.stack([c.position for c in cameras]).astype(np.float32)[:, :, None]
        right, up, back = (np.stack([getattr(c, axis) for c in cameras]) for axis in ("right", "up", "back"))
        right, up, ahead = (_along(pos, axis) for axis in (right, up, -back))  # (F, V) each
        with np.errstate(divide="ignore", invalid="ignore"):
            w = np.where(ahead > near, 1.0 / ahead, np.float32(np.nan))
        u, v = cam.centre[0] + cam.focal_px * right * w, cam.centre[1] - cam.focal_px * up * w
        light = self._light(nrm, cameras)
        return [(u[k], v[k], w[k], light[k]) for k in range(len(cameras))]

    def _light(self, nrm: np.ndarray, cameras) -> np.ndarray:
        """Light (F, V) falling on each vertex with normals ``nrm`` (F, 3, V), lights placed by each frame's
        camera's basis."""
        size = np.sqrt(nrm[:, 0] ** 2 + nrm[:, 1] ** 2 + nrm[:, 2] ** 2)
        nrm /= np.maximum(size, 1e-12)[:, None]
        to_world = np.stack([np.stack([c.right, c.up, c.back], axis=1) for c in cameras])   # (F, 3, 3)
        key, fill = (to_world @ _unit(d) for d in (KEY_LIGHT, FILL_LIGHT))
        up = nrm[:, 1]
        return (SKY_AMBIENT * (0.5 + 0.5 * up) + GROUND_AMBIENT * (0.5 - 0.5 * up)
                + KEY * np.maximum(_along(nrm, key), 0.0) + FILL * np.maximum(_along(nrm, fill), 0.0))

    def shadow_radii(self, rest_points: np.ndarray, bones: np.ndarray) -> np.ndarray:
        """How thick (radius, m) each bone (parent joint, child point) of a ``figure.Figure`` is in the mesh:
        a percentile of the distance to the bone of the vertices its parent joint moves most (0: none)."""
        owner = self.joints[np.arange(len(self.joints)), self.weights.argmax(axis=1)]
        radius = np.zeros(len(bones))
        for k, (a, p) in enumerate(bones.tolist()):
            v = self.positions[owner == a].astype(np.float64)
            if len(v):
                radius[k] = np.percentile(_segment_distance(v, rest_points[a], rest_points[p]),
                                          SHADOW_RADIUS_PERCENTILE)
        return radius


def paint(img: Image.Image, mesh: SkinnedMesh, posed) -> None:
    """Draw one frame of ``mesh`` (``posed``: its entry from ``SkinnedMesh.pose``) into the RGB image ``img``."""
    canvas = np.frombuffer(img.convert("RGBX").tobytes(), np.uint32).reshape(img.height, img.width).copy()
    if rasterise(canvas, mesh, posed):
        img.paste(Image.frombuffer("RGBX", img.size, canvas, "raw", "RGBX", 0, 1).convert(img.mode))


def rasterise(canvas: np.ndarray, mesh: SkinnedMesh, posed, shades: np.ndarray | None = None,
              offset: tuple[float, float] = (0.0, 0.0)) -> bool:
    """Draw one frame of ``mesh`` into ``canvas`` (H, W) uint32 of packed colours (red, or Y, in
    the low byte); ``posed``: its entry from ``SkinnedMesh.pose``, whose pixel (x, y) is the canvas's
    (x - offset[0], y - offset[1]); ``shades``: the colour table (default ``mesh.shades``, sRGB; another colour
    space's, e.g. Y'CbCr, for the same colours and light levels). Returns False if nothing was drawn.

    Every step works on whole arrays, per triangle, per run of pixels or per pixel; per-run values are
    spread over their pixels with ``np.repeat`` (a sequential copy) rather than gathered by index."""
    shades = mesh.shades if shades is None else shades
    u, v, w, light = posed
    height, width = canvas.shape
    x = u[mesh.corners].astype(np.float64) - offset[0]                                  # (3, T) each
    y = v[mesh.corners].astype(np.float64) - offset[1]
    # Counter-clockwise as seen from outside: a negative signed area in (y-down) pixels faces us (a
    # triangle with a corner nearer than the near plane has NaNs: no area). Triangles off the canvas go too.
    with np.errstate(invalid="ignore"):
        shown = np.flatnonzero(((x[1] - x[0]) * (y[2] - y[0]) - (y[1] - y[0]) * (x[2] - x[0]) < 0)
                               & (x.max(axis=0) >= 0.5) & (x.min(axis=0) <= width - 0.5)
                               & (y.max(axis=0) >= 0.5) & (y.min(axis=0) <= height - 0.5))
    if len(shown) == 0:
        return False
    x, y = x[:, shown], y[:, shown]
    tri = mesh.corners[:, shown]
    # Depth (1/z: linear on the screen) and light are planes over each triangle through its corners' values;
    # light is kept in steps of the shade table.
    depth_plane, light_plane = _planes(x, y, w[tri], light[tri] * np.float32((LIGHT_LEVELS - 1) / MAX_LIGHT))
    base = mesh.colour[shown] * LIGHT_LEVELS

    # Each triangle is two trapezoids, split at its middle corner's height, each bounded by one edge on
    # either side: the long edge (top to bottom corner) and a short one. A pixel is inside where its
    # centre (+0.5) is, edges included, so triangles that share an edge leave no crack between them.
    n = len(shown)
    top, bottom = y.argmin(axis=0), y.argmax(axis=0)  # (a level triangle, whose top is its bottom, has no area)
    corner = (top, 3 - top - bottom, bottom)
    span = np.arange(n)
    (x0, x1, x2), (y0, y1, y2) = ([a[k, span] for k in corner] for a in (x, y))
    with np.errstate(divide="ignore", invalid="ignore"):
        long_slope = np.where(y2 > y0, (x2 - x0) / (y2 - y0), 0.0)
        up_slope = np.where(y1 > y0, (x1 - x0) / (y1 - y0), 0.0)
        down_slope = np.where(y2 > y1, (x2 - x1) / (y2 - y1), 0.0)
    long_left = x0 + long_slope * (y1 - y0) < x1  # the long edge bounds the trapezoids on the left
    first_row = np.maximum(np.ceil(y0 - 0.5), 0)
    end_row = np.maximum(np.minimum(np.floor(y2 - 0.5), height - 1) + 1, first_row)
    mid_row = np.clip(np.ceil(y1 - 0.5), first_row, end_row)
    # The upper trapezoids, then the lower ones, each as one record: where its runs start, its first row,
    # its left and right edges' x at that row's centre and their steps per row, and its triangle's depth
    # and light at the row's x = 0 and their steps per row and per column; its colour.
    trapezoid = np.empty((2, n, 13))
    trapezoid[0, :, 1], trapezoid[1, :, 1] = first_row, mid_row
    rows = np.stack([mid_row - first_row, end_row - mid_row]).astype(np.int64)
    yc = trapezoid[:, :, 1] + 0.5                                                       # (2, T) each
    long_x = x0 + long_slope * (yc - y0)
    short_x = np.stack([x0 + up_slope * (yc[0] - y0), x1 + down_slope * (yc[1] - y1)])
    short_step = np.stack([up_slope, down_slope])
    trapezoid[:, :, 2] = np.where(long_left, long_x, short_x)
    trapezoid[:, :, 3] = np.where(long_left, long_slope, short_step)
    trapezoid[:, :, 4] = np.where(long_left, short_x, long_x)
    trapezoid[:, :, 5] = np.where(long_left, short_step, long_slope)
    (c, gx, gy), (lc, lgx, lgy) = depth_plane, light_plane
    trapezoid[:, :, 6] = c + gy * yc
    trapezoid[:, :, 7] = gy
    trapezoid[:, :, 8] = gx
    trapezoid[:, :, 9] = lc + lgy * yc + 0.5  # + 0.5: truncating the shade rounds the light
    trapezoid[:, :, 10] = lgy
    trapezoid[:, :, 11] = lgx
    trapezoid[:, :, 12] = base
    trapezoid, rows = trapezoid.reshape(-1, 13), rows.reshape(-1)
    trapezoid[:, 0] = np.cumsum(rows) - rows

    # One run of pixels per (trapezoid, row): a single np.repeat spreads the records over them.
    r = np.repeat(trapezoid, rows, axis=0)
    down = np.arange(len(r)) - r[:, 0]
    row = r[:, 1] + down
    first = np.maximum(np.ceil(r[:, 2] + r[:, 3] * down - 0.5), 0)
    count = (np.minimum(np.floor(r[:, 4] + r[:, 5] * down - 0.5), width - 1) - first + 1).astype(np.int64)
    np.maximum(count, 0, out=count)
    total = int(count.sum())
    if total == 0:
        return False
    # The z-buffer spans the rows and columns the triangles do, in the canvas.
    top, bottom = int(first_row.min()), int(end_row.max())
    left, right = max(0, int(np.floor(x.min())) - 1), min(width, int(np.ceil(x.max())) + 1)
    span = right - left
    xc = first + 0.5
    # One record per run (int32 and float32 side by side), spread over its pixels by a single np.repeat.
    start = np.cumsum(count) - count
    record = np.empty((len(count), 8), np.int32)
    record[:, 0] = start
    record[:, 1] = (row - top) * span + (first - left) - start
    values = record.view(np.float32)
    values[:, 3] = r[:, 6] + r[:, 7] * down + r[:, 8] * xc
    values[:, 4] = r[:, 8]
    # The shade: the colour's row of the table plus the light, kept within the table along the whole run
    # (interpolated light leaves its corners' range only by rounding, at the edges).
    lit0 = np.clip(r[:, 9] + r[:, 10] * down + r[:, 11] * xc, 0, LIGHT_LEVELS - 1)
    lit1 = np.clip(lit0 + r[:, 11] * np.maximum(count - 1, 0), 0, LIGHT_LEVELS - 1)
    values[:, 5] = r[:, 12] + lit0
    values[:, 6] = (lit1 - lit0) / np.maximum(count - 1, 1)

    # Every pixel of every run: its place in the z-buffer, its depth and its shade.
    pixels = np.repeat(record, count, axis=0)
    values = pixels.view(np.float32)
    index = np.arange(total, dtype=np.int32)  # one dtype throughout: mixed ones make numpy convert in chunks
    at = index + pixels[:, 1]
    along = index - pixels[:, 0]
    along = along.astype(np.float32)
    depth = values[:, 4] * along
    depth += values[:, 3]
    np.maximum(depth, np.float32(0), out=depth)
    shade = values[:, 6] * along
    shade += values[:, 5]
    shade = shade.astype(np.int32)

    # The z-buffer: each pixel's key is its depth's bits (a positive float32's order is its bits' order)
    # over its colour, so the largest key is the nearest surface's colour. What is drawn already has depth 0.
    key = depth.view(np.uint32).astype(np.uint64)
    key <<= np.uint64(32)
    key |= np.take(shades, shade)
    drawn = canvas[top:bottom, left:right]
    nearest = drawn.astype(np.uint64)
    np.maximum.at(nearest.reshape(-1), at, key)
    np.copyto(drawn, nearest, casting="unsafe")  # the low 32 bits: the colour
    return True


def _planes(x: np.ndarray, y: np.ndarray, *values: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """``(c, gx, gy)`` per triangle with a = c + gx X + gy Y through its corners' values ``a`` (3, T),
    for each of ``values``."""
    dx1, dy1, dx2, dy2 = x[1] - x[0], y[1] - y[0], x[2] - x[0], y[2] - y[0]
    det = dx1 * dy2 - dx2 * dy1
    det = np.where(np.abs(det) < 1e-9, -1e-9, det)  # a sliver: it covers no pixel centre anyway
    dx1, dy1, dx2, dy2 = dx1 / det, dy1 / det, dx2 / det, dy2 / det
    planes = []
    for a in values:
        da1, da2 = a[1] - a[0], a[2] - a[0]
        gx = da1 * dy2 - da2 * dy1
        gy = da2 * dx1 - da1 * dx2
        planes.append((a[0] - gx * x[0] - gy * y[0], gx, gy))
    return planes


def _along(vectors: np.ndarray, axis) -> np.ndarray:
    """Components (F, V) of component-major vectors (F, 3, V) along ``axis``: one (3,), or one a frame (F, 3)."""
    a = np.asarray(axis, dtype=np.float32)
    a = a[:, :, None] if a.ndim == 2 else a[None, :, None]
    return a[:, 0] * vectors[:, 0] + a[:, 1] * vectors[:, 1] + a[:, 2] * vectors[:, 2]


def _matrices(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4)."""
    q = np.asarray(q, dtype=np.float64)
    return Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(q.shape[:-1] + (3, 3))


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip((p - a) @ ab / max(float(ab @ ab), 1e-12), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)

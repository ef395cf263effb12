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

``paint`` then draws one frame into the renderer's (supersampled) PIL image: the
triangles facing the camera (back faces are culled) are cut into pixel runs along
each row, every pixel gets
its depth (1/z, which is linear on the screen) and light interpolated from the
corners, a z-buffer keeps the nearest (``np.maximum.at``), and the winners are coloured
albedo x light in sRGB. A z-buffer, unlike the painter's algorithm, has no ordering
errors to flicker where limbs cross or where the parts of a body that overlap (an arm's
ball inside the shoulder, a body under its clothes) meet; interpolating the light
(Gouraud) hides the facets.

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
        ``cameras``: each frame's ``render.Camera`` (all of one orientation); nothing nearer than ``near``."""
        pos, nrm = self.skin(g_rot, g_pos)
        cam = cameras[0]
        pos -= np.stack([c.position for c in cameras]).astype(np.float32)[:, :, None]
        right, up, ahead = (_along(pos, axis) for axis in (cam.right, cam.up, -cam.back))  # (F, V) each
        with np.errstate(divide="ignore", invalid="ignore"):
            w = np.where(ahead > near, 1.0 / ahead, np.float32(np.nan))
        u, v = cam.centre[0] + cam.focal_px * right * w, cam.centre[1] - cam.focal_px * up * w
        light = self._light(nrm, cam)
        return [(u[k], v[k], w[k], light[k]) for k in range(len(cameras))]

    def _light(self, nrm: np.ndarray, cam) -> np.ndarray:
        """Light (F, V) falling on each vertex with normals ``nrm`` (F, 3, V), lights placed by ``cam``'s basis."""
        size = np.sqrt(nrm[:, 0] ** 2 + nrm[:, 1] ** 2 + nrm[:, 2] ** 2)
        nrm /= np.maximum(size, 1e-12)[:, None]
        to_world = np.stack([cam.right, cam.up, cam.back], axis=1)
        key, fill = (to_world @ _unit(d) for d in (KEY_LIGHT, FILL_LIGHT))
        up = nrm[:, 1]
        return (SKY_AMBIENT * (0.5 + 0.5 * up) + GROUND_AMBIENT * (0.5 - 0.5 * up)
                + KEY * np.maximum(_along(nrm, key), 0.0) + FILL * np.maximum(_along(nrm, fill), 0.0))

    def shadow_radii(self, rest_points: np.ndarray, bones: np.ndarray) -> np.ndarray:
        """How thick (radius, m) each bone (parent joint, child point) of a ``render.Figure`` is in the mesh:
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
    u, v, w, light = posed
    x, y = u[mesh.corners].astype(np.float64), v[mesh.corners].astype(np.float64)   # (3, T) each
    # Counter-clockwise as seen from outside: a negative signed area in (y-down) pixels faces us (a
    # triangle with a corner nearer than the near plane has NaNs: no area).
    shown = np.flatnonzero((x[1] - x[0]) * (y[2] - y[0]) - (y[1] - y[0]) * (x[2] - x[0]) < 0)
    tri, x, y = mesh.corners[:, shown], x[:, shown], y[:, shown]
    # The rows whose pixel centres (+0.5) each triangle spans, inside the image.
    top = np.maximum(np.ceil(y.min(axis=0) - 0.5), 0).astype(np.int64)
    rows = np.maximum(np.minimum(np.floor(y.max(axis=0) - 0.5), img.height - 1).astype(np.int64) - top + 1, 0)

    # One run of pixels per (triangle, row): where the row's centre line is inside all three edges.
    # Front faces run counter-clockwise as seen, so each edge k -> k+1 has the inside on its left:
    # x >= the edge where it runs down the picture, x <= the edge where it runs up; a level edge lies
    # on the first or last row's boundary and bounds nothing.
    t = np.repeat(np.arange(len(shown)), rows)
    yc = top[t] + np.arange(len(t)) - np.repeat(np.cumsum(rows) - rows, rows) + 0.5
    lo, hi = np.full(len(t), -np.inf), np.full(len(t), np.inf)
    for k in range(3):
        dy = y[(k + 1) % 3] - y[k]
        with np.errstate(divide="ignore", invalid="ignore"):
            slope = np.where(dy != 0, (x[(k + 1) % 3] - x[k]) / dy, 0.0)
        bound = (x[k] - slope * y[k])[t] + slope[t] * yc
        down = dy[t]
        lo = np.where(down > 0, np.maximum(lo, bound), lo)
        hi = np.where(down < 0, np.minimum(hi, bound), hi)
    first = np.maximum(np.ceil(lo - 0.5), 0)
    count = np.maximum(np.minimum(np.floor(hi - 0.5), img.width - 1) - first + 1, 0).astype(np.int64)
    run = np.repeat(np.arange(len(t)), count)
    if len(run) == 0:
        return

    # Depth (1/z: linear on the screen) and light at each pixel, from each triangle's plane through its
    # corners' values: found at each run's first pixel, then stepped along it.
    step = np.arange(len(run)) - np.repeat(np.cumsum(count) - count, count)
    px = first.astype(np.int64)[run] + step
    py = (yc[run] - 0.5).astype(np.int64)
    along = step.astype(np.float32)
    depth = _along_runs(_plane(x, y, w[tri]), t, first + 0.5, yc, run, along)
    lit = _along_runs(_plane(x, y, light[tri]), t, first + 0.5, yc, run, along)

    # Z-buffer over the box the pixels span: the nearest (largest 1/z) wins each pixel.
    bx0, by0 = int(px.min()), int(py.min())
    bw, bh = int(px.max()) - bx0 + 1, int(py.max()) - by0 + 1
    at = (py - by0) * bw + (px - bx0)
    nearest = np.full(bw * bh, -np.inf, np.float32)
    np.maximum.at(nearest, at, depth)
    win = depth >= nearest[at]
    level = np.clip(lit[win] * ((LIGHT_LEVELS - 1) / MAX_LIGHT) + 0.5, 0, LIGHT_LEVELS - 1).astype(np.int32)
    colour = mesh.colour[shown][t][run[win]]
    # Paste the box's covered pixels over what is drawn already (the floor, the grid, the shadow).
    at = at[win]
    patch, cover = np.zeros(bw * bh, np.uint32), np.zeros(bw * bh, np.uint8)
    patch[at], cover[at] = mesh.shades[colour * LIGHT_LEVELS + level], 255
    img.paste(Image.frombuffer("RGB", (bw, bh), patch, "raw", "RGBX", 0, 1), (bx0, by0, bx0 + bw, by0 + bh),
              Image.frombuffer("L", (bw, bh), cover, "raw", "L", 0, 1))


def _plane(x: np.ndarray, y: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(c, gx, gy)`` per triangle with a = c + gx X + gy Y through its corners' values ``a`` (3, T)."""
    dx1, dy1, dx2, dy2 = x[1] - x[0], y[1] - y[0], x[2] - x[0], y[2] - y[0]
    da1, da2 = a[1] - a[0], a[2] - a[0]
    det = dx1 * dy2 - dx2 * dy1
    det = np.where(np.abs(det) < 1e-9, -1e-9, det)  # a sliver: it covers no pixel centre anyway
    gx = (da1 * dy2 - da2 * dy1) / det
    gy = (da2 * dx1 - da1 * dx2) / det
    return a[0] - gx * x[0] - gy * y[0], gx, gy


def _along_runs(plane, t, x0, y, run, step) -> np.ndarray:
    """Values (float32) on each run's triangle's ``plane``: at ``x0, y`` (per run), plus ``step`` pixels."""
    c, gx, gy = plane
    start = (c[t] + gx[t] * x0 + gy[t] * y).astype(np.float32)
    slope = gx[t].astype(np.float32)
    return start[run] + slope[run] * step


def _along(vectors: np.ndarray, axis) -> np.ndarray:
    """Components (F, V) of component-major vectors (F, 3, V) along ``axis`` (3,)."""
    x, y, z = (float(a) for a in axis)
    return x * vectors[:, 0] + y * vectors[:, 1] + z * vectors[:, 2]


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

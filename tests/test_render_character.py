"""Videos of a skinned character: linear blend skinning, the z-buffered rasteriser, the stick figure on request.

Most tests dress the mannequin rig in a mesh of eight-sided tubes, one round each bone,
each moved rigidly by its bone: simple enough to reason about, closed like a real body,
in colours no stick figure uses. One test draws the built-in mannequin itself.
"""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest
from PIL import Image, ImageDraw
from scipy.ndimage import binary_fill_holes

from dancesynth import rotations as rot
from dancesynth.errors import InputError
from dancesynth.export import render_video, render_video_files
from dancesynth.export import render as render_mod
from dancesynth.export.raster import smooth_lines, upsample
from dancesynth.export.figure import COLOURS, clip_pose
from dancesynth.export.render import FrameRenderer
from dancesynth.export.skinned import SkinnedMesh, paint, rasterise
from dancesynth.retarget.character import Character, Mesh
from dancesynth.retarget.rigs import rig_skeleton
from dancesynth.types import MotionClip

W, H = 320, 180
SIDES = 8
# Linear albedo of the tubes: the left side green, the right side purple, the rest teal; in none
# of them are the channels ordered as in a stick-figure colour (blue: B > G > R, orange: R > G > B).
ALBEDO = {"left": (0.12, 0.55, 0.08), "right": (0.45, 0.08, 0.55), "": (0.08, 0.40, 0.32)}

needs_ffmpeg = pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="ffmpeg not installed")


def tube(a: np.ndarray, b: np.ndarray, radius: float):
    """Positions, normals and triangles (counter-clockwise outside) of a capped eight-sided tube from a to b."""
    axis = (b - a) / np.linalg.norm(b - a)
    side = np.cross(axis, [0.0, 1.0, 0.0] if abs(axis[1]) < 0.9 else [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    other = np.cross(axis, side)
    ang = 2 * np.pi * np.arange(SIDES) / SIDES
    ring = np.cos(ang)[:, None] * side + np.sin(ang)[:, None] * other          # (S, 3) unit, round the axis
    pos = np.concatenate([a + radius * ring, b + radius * ring, a + radius * ring, b + radius * ring, [a, b]])
    nrm = np.concatenate([ring, ring, np.tile(-axis, (SIDES, 1)), np.tile(axis, (SIDES, 1)), [-axis, axis]])
    s = np.arange(SIDES)
    t = (s + 1) % SIDES
    tris = [np.stack([s, t, SIDES + t], 1), np.stack([s, SIDES + t, SIDES + s], 1),     # the sides
            np.stack([np.full(SIDES, 4 * SIDES), 2 * SIDES + t, 2 * SIDES + s], 1),     # cap at a
            np.stack([np.full(SIDES, 4 * SIDES + 1), 3 * SIDES + s, 3 * SIDES + t], 1)]  # cap at b
    return pos, nrm, np.concatenate(tris)


def tube_character(with_mesh: bool = True) -> Character:
    """The mannequin rig in a mesh of tubes, each bound rigidly to the joint at its top."""
    sk, bones = rig_skeleton("mannequin")
    world = np.zeros((sk.n_joints, 3))
    for j, p in enumerate(sk.parents):
        world[j] = sk.offsets[j] + (world[p] if p >= 0 else 0.0)
    pos, nrm, tris, joints, cols = [], [], [], [], []
    for j, name in enumerate(sk.names):
        ends = [world[c] for c in sk.children(j)] + ([world[j] + sk.end_sites[j]] if j in sk.end_sites else [])
        side = "left" if name.startswith("left") else "right" if name.startswith("right") else ""
        radius = 0.03 if any(part in name for part in ("Hand", "Foot", "Toes")) else 0.065 if side else 0.15
        for end in ends:
            if np.linalg.norm(end - world[j]) > 0.05:
                p, n, t = tube(world[j], end, 0.09 if name == "head" else radius)
                tris.append(t + sum(len(q) for q in pos))
                pos.append(p)
                nrm.append(n)
                joints.append(np.full((len(p), 4), j))
                cols.append(np.tile(ALBEDO[side], (len(p), 1)))
    weights = np.zeros((sum(len(p) for p in pos), 4), np.float32)
    weights[:, 0] = 1.0
    mesh = Mesh(np.concatenate(pos).astype(np.float32), np.concatenate(nrm).astype(np.float32),
                np.concatenate(tris).astype(np.uint32), np.concatenate(joints).astype(np.uint16), weights,
                np.concatenate(cols).astype(np.float32))
    return Character("tubes", sk, bones, np.tile(rot.IDENTITY, (sk.n_joints, 1)), sk.offsets[0].copy(),
                     mesh if with_mesh else None)


def waving_dance(character: Character, seconds: float = 3.0, fps: float = 30.0) -> MotionClip:
    """The character turning on the spot, bobbing and waving its arms up and down."""
    sk = character.skeleton
    n = int(seconds * fps)
    t = np.arange(n) / fps
    local = np.tile(rot.IDENTITY, (n, sk.n_joints, 1))
    local[:, 0] = rot.about_y(0.6 * t)
    for side, sign in (("left", 1.0), ("right", -1.0)):
        local[:, sk.index(side + "UpperArm")] = rot.exp(np.outer(sign * 0.9 * np.sin(2 * np.pi * t), [0, 0, 1]))
        local[:, sk.index(side + "LowerLeg")] = rot.exp(np.outer(0.3 + 0.3 * np.sin(2 * np.pi * t), [1, 0, 0]))
    root = np.tile(sk.offsets[0], (n, 1))
    root[:, 1] -= 0.05 * (1 + np.sin(2 * np.pi * t))
    return MotionClip(sk, fps, root, local)


@pytest.fixture(scope="module")
def character():
    return tube_character()


@pytest.fixture(scope="module")
def dance(character):
    return waving_dance(character)


def frame(path, n: int, size=(W, H)) -> np.ndarray:
    """Decoded frame ``n`` of a video as an (H, W, 3) uint8 array."""
    proc = subprocess.run(["ffmpeg", "-v", "error", "-i", str(path), "-vf", f"select=eq(n\\,{n})", "-frames:v", "1",
                           "-f", "rawvideo", "-pix_fmt", "rgb24", "pipe:1"], capture_output=True, check=True)
    return np.frombuffer(proc.stdout, np.uint8).reshape(size[1], size[0], 3)


def shaded(img: np.ndarray, albedo, tol: float = 16.0) -> np.ndarray:
    """Pixels that show the linear colour ``albedo`` under some amount of light (as 8-bit sRGB)."""
    img = img.astype(np.float64)
    nearest = np.full(img.shape[:2], np.inf)
    for light in np.linspace(0.05, 1.5, 100):
        x = np.minimum(light * np.asarray(albedo), 1.0)
        srgb = 255 * np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
        nearest = np.minimum(nearest, np.abs(img - srgb).max(axis=-1))
    return nearest < tol


def drawn(img: np.ndarray, albedo) -> int:
    return int(shaded(img, albedo).sum())


def stick_drawn(img: np.ndarray, colour) -> int:
    """Pixels of the stick figure's ``colour`` (sRGB; faded towards the floor colour with depth)."""
    img = img.astype(int)
    lo, mid, hi = (img[..., k] for k in np.argsort(colour))
    return int(((hi - lo > 60) & (hi >= mid) & (mid >= lo)).sum())


def render_frames(dance, mesh, frames) -> list[np.ndarray]:
    r = FrameRenderer(dance, W, H, mesh=mesh)
    return [np.frombuffer(b, np.uint8).reshape(H, W, 3) for b in r.frames(frames)]


# --------------------------------------------------------------------------- skinning

def test_skinning_in_the_rest_pose_gives_the_mesh_as_modelled(character):
    mesh = SkinnedMesh.from_character(character)
    sk = character.skeleton
    rest = MotionClip(sk, 30.0, character.rest_root[None], character.rest_rot[None])
    pos, nrm = mesh.skin(*clip_pose(rest, np.array([0])))
    np.testing.assert_allclose(pos[0].T, character.mesh.positions, atol=1e-5)
    np.testing.assert_allclose(nrm[0].T, character.mesh.normals, atol=1e-5)


def test_skinning_follows_each_bone_and_blends_between_them(character):
    """A vertex bound half to each of two joints lands half-way between where each would carry it."""
    mesh = SkinnedMesh.from_character(character)
    sk = character.skeleton
    clip = waving_dance(character, seconds=0.5)
    g_rot, g_pos = clip_pose(clip, np.arange(clip.n_frames))
    pos, _ = mesh.skin(g_rot, g_pos)
    v = len(mesh.positions) - 1  # bound rigidly to its joint: carried by that joint's motion from the rest pose
    j = int(character.mesh.joints[v, 0])
    rest = mesh.positions[v] - mesh.bind_pos[j]
    expected = g_pos[:, j] + rot.apply(g_rot[:, j], rot.apply(rot.inv(mesh.bind_rot[j]), rest))
    np.testing.assert_allclose(pos[:, :, v], expected, atol=1e-4)

    def bound(joints, weights):
        n = len(mesh.positions)
        return SkinnedMesh(**{**vars(mesh), "joints": np.tile(joints, (n, 1)),
                              "weights": np.tile(np.float32(weights), (n, 1))})

    hand, lower = sk.index("leftHand"), sk.index("leftLowerArm")
    half, only_hand, only_lower = bound([hand, lower], [0.5, 0.5]), bound([hand], [1]), bound([lower], [1])
    np.testing.assert_allclose(half.skin(g_rot, g_pos)[0],
                               (only_hand.skin(g_rot, g_pos)[0] + only_lower.skin(g_rot, g_pos)[0]) / 2, atol=1e-4)


def test_a_broken_mesh_is_refused_with_a_message(character):
    mesh = character.mesh
    bad = Mesh(mesh.positions, mesh.normals, mesh.indices, np.full_like(mesh.joints, 99), mesh.weights, mesh.colours)
    broken = Character("broken", character.skeleton, character.bones, character.rest_rot, character.rest_root, bad)
    with pytest.raises(InputError, match="'broken'.*joint"):
        SkinnedMesh.from_character(broken)


# --------------------------------------------------------------------------- drawing

def flat_mesh(corners: np.ndarray, colours) -> SkinnedMesh:
    """A SkinnedMesh of loose triangles (corners (T, 3, 3)), one colour each, on the mannequin rig."""
    sk, bones = rig_skeleton("mannequin")
    n = corners.size // 3
    mesh = Mesh(corners.reshape(-1, 3).astype(np.float32), np.tile(np.float32([0, 0, 1]), (n, 1)),
                np.arange(n, dtype=np.uint32).reshape(-1, 3), np.zeros((n, 4), np.uint16),
                np.tile(np.float32([1, 0, 0, 0]), (n, 1)), np.repeat(np.float32(colours), 3, axis=0))
    return SkinnedMesh.from_character(Character("flat", sk, bones, np.tile(rot.IDENTITY, (sk.n_joints, 1)),
                                                sk.offsets[0].copy(), mesh))


def painted(mesh: SkinnedMesh, uv: np.ndarray, w: np.ndarray, size=(64, 48)) -> np.ndarray:
    """The mesh drawn with paint at pixel corners ``uv`` (V, 2) and 1/depth ``w`` (V,), full light, on black."""
    img = Image.new("RGB", size)
    posed = (uv[:, 0].astype(np.float32), uv[:, 1].astype(np.float32), w.astype(np.float32),
             np.ones(len(uv), np.float32))
    paint(img, mesh, posed)
    return np.asarray(img)


# Counter-clockwise as seen, as front faces are once projected.
TRIANGLE = np.array([[10.3, 5.2], [8.1, 40.4], [40.7, 30.6]])


def test_a_triangle_covers_what_pil_fills():
    mesh = flat_mesh(np.zeros((1, 3, 3)), [(1.0, 1.0, 1.0)])
    ours = painted(mesh, TRIANGLE, np.ones(3)).max(axis=-1) > 0
    pil = Image.new("L", (64, 48))
    ImageDraw.Draw(pil).polygon(TRIANGLE.ravel().tolist(), fill=255)
    theirs = np.asarray(pil) > 0
    assert ours.sum() > 400
    assert (ours != theirs).sum() < 0.1 * theirs.sum()  # they differ at most along the edges


def test_the_nearest_triangle_wins_whatever_the_order():
    red, blue = (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)
    shifted = TRIANGLE + [8, 2]
    for colours, uv, w in [((red, blue), np.vstack([TRIANGLE, shifted]), [2, 2, 2, 1, 1, 1]),
                           ((blue, red), np.vstack([shifted, TRIANGLE]), [1, 1, 1, 2, 2, 2])]:
        img = painted(flat_mesh(np.zeros((2, 3, 3)), colours), uv, np.array(w, float))
        assert tuple(img[25, 20]) == (255, 0, 0)  # inside both: the red one is nearer
        assert img[31, 44, 2] == 255              # only inside the blue one


def test_crossing_triangles_meet_along_their_intersection():
    """Each of two triangles that pass through each other shows where it is the nearer (no painter's order)."""
    red, blue = (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)
    uv = np.vstack([TRIANGLE, TRIANGLE])
    img = painted(flat_mesh(np.zeros((2, 3, 3)), (red, blue)), uv, np.array([3, 1, 1, 1, 3, 3], float))
    inside = img.max(axis=-1) > 0
    reds, blues = inside & (img[..., 0] > 0), inside & (img[..., 2] > 0)
    assert reds.sum() > 100 and blues.sum() > 100
    assert reds[7, 12] and blues[36, 11]  # near the red one's nearest corner, near the blue one's


def test_back_faces_and_triangles_through_the_near_plane_are_not_drawn():
    mesh = flat_mesh(np.zeros((1, 3, 3)), [(1.0, 1.0, 1.0)])
    assert painted(mesh, TRIANGLE, np.ones(3)).any()
    assert not painted(mesh, TRIANGLE[::-1], np.ones(3)).any()
    behind = TRIANGLE.copy()
    behind[2] = np.nan  # as pose marks a corner nearer than the near plane
    assert not painted(mesh, behind, np.array([1.0, 1.0, np.nan])).any()


def test_triangles_off_the_picture_are_clipped():
    mesh = flat_mesh(np.zeros((1, 3, 3)), [(1.0, 1.0, 1.0)])
    img = painted(mesh, TRIANGLE * 3 - [40, 30], np.ones(3))
    assert img.max(axis=-1).any() and not painted(mesh, TRIANGLE + [200, 0], np.ones(3)).any()



def test_a_box_of_the_canvas_gets_what_the_whole_canvas_would():
    """The renderer rasterises only the box round the dancer, with the box's corner as the offset."""
    mesh = flat_mesh(np.zeros((2, 3, 3)), [(1.0, 0.5, 0.2), (0.2, 0.5, 1.0)])
    uv = np.vstack([TRIANGLE, TRIANGLE + [8, 2]])
    posed = (uv[:, 0].astype(np.float32), uv[:, 1].astype(np.float32), np.float32([2, 2, 2, 1, 1, 1]),
             np.ones(6, np.float32))
    whole = np.zeros((48, 64), np.uint32)
    assert rasterise(whole, mesh, posed)
    box = np.full((30, 40), 7, np.uint32)  # the picture's pixels (6..46, 4..34), with something drawn already
    assert rasterise(box, mesh, posed, offset=(6, 4))
    expected = whole[4:34, 6:46]
    np.testing.assert_array_equal(box, np.where(expected > 0, expected, 7))
    assert not rasterise(np.zeros((10, 10), np.uint32), mesh, posed, offset=(100, 100))  # off the box


def test_grid_lines_are_one_pixel_wide_at_any_slope_and_stay_on_the_picture():
    base = 200.0
    for end in [(60, 20.0), (60, 45.0), (35, 70), (20.5, 75)]:  # from level to steep
        img = np.full((80, 80), int(base), np.uint8)
        start = np.array([[20.0, 20.0]])
        smooth_lines(img, start, np.array([end], float), np.array([100.0]), base)
        dark = (base - img.astype(float)) / 100.0  # 1 where a pixel is wholly covered
        length = float(np.hypot(*(np.array(end) - start[0])))
        assert dark.sum() == pytest.approx(length, rel=0.1)  # area = length x 1 pixel
        assert dark.max() <= 1.0 + 1e-6
    img = np.full((40, 40), 200, np.uint8)  # lines that leave the picture, or never enter it
    smooth_lines(img, np.array([[-50.0, 10.0], [10.0, -30.0], [-10.0, -10.0]]),
                  np.array([[90.0, 30.0], [15.0, 90.0], [-5.0, -40.0]]), np.array([50.0, 50.0, 50.0]), 200.0)
    assert (img < 200).sum() > 60


@pytest.mark.parametrize("dtype", [np.uint8, np.uint32, np.int16])
@pytest.mark.parametrize("factor", [1, 2, 3])
def test_upsampling_makes_each_pixel_a_block(dtype, factor):
    a = np.arange(35).reshape(5, 7).astype(dtype) * 3
    np.testing.assert_array_equal(upsample(a, factor), a.repeat(factor, axis=0).repeat(factor, axis=1))


def raised_dance(character: Character) -> MotionClip:
    """The waving dance, lifted 1.5 m in its last third: the dancer rises into the sky above the horizon."""
    clip = waving_dance(character)
    root = clip.root_pos.copy()
    root[2 * clip.n_frames // 3:, 1] += 1.5
    return MotionClip(clip.skeleton, clip.fps, root, clip.local_rot)


def yuv_to_rgb(frame: np.ndarray, w: int, h: int) -> np.ndarray:
    """An (H, W, 3) float RGB picture from yuv420p planes (BT.601, limited range; chroma repeated)."""
    y = frame[:w * h].reshape(h, w).astype(float)
    cb, cr = (frame[w * h + k * (w * h // 4):w * h + (k + 1) * (w * h // 4)].reshape(h // 2, w // 2)
              .repeat(2, 0).repeat(2, 1).astype(float) - 128.0 for k in (0, 1))
    y = (y - 16.0) * 255.0 / 219.0
    cb, cr = cb * 255.0 / 224.0, cr * 255.0 / 224.0
    return np.stack([y + 1.402 * cr, y - 0.344136 * cb - 0.714136 * cr, y + 1.772 * cb], axis=-1)


@pytest.mark.parametrize("with_mesh", [True, False])
def test_the_planes_for_the_encoder_show_the_rgb_picture(character, with_mesh):
    """yuv420p frames are the rgb24 frames as ffmpeg would convert them, in the sky band above the floor too."""
    dance = raised_dance(character)
    mesh = SkinnedMesh.from_character(character) if with_mesh else None
    frames = [10, 80]
    rgb = render_frames(dance, mesh, frames)
    yuv = list(FrameRenderer(dance, W, H, mesh=mesh, pix_fmt="yuv420p").frames(frames))
    for a, b in zip(rgb, yuv):
        assert b.dtype == np.uint8 and b.size == W * H * 3 // 2
        diff = np.abs(yuv_to_rgb(b, W, H) - a).max(axis=-1)
        assert np.median(diff) <= 1.5 and np.percentile(diff, 95) < 12  # chroma at half size blurs colour edges


def test_the_dancer_is_drawn_over_the_sky_too(character, monkeypatch):
    """The rows above the floor are drawn once; a dancer who rises into them is still drawn there."""
    dance = raised_dance(character)
    r = FrameRenderer(dance, W, H, mesh=SkinnedMesh.from_character(character))
    assert 0 < r.band < H // 2
    for mesh in (SkinnedMesh.from_character(character), None):
        (_, low), (_, high) = figure_masks(dance, mesh, [10, 80], monkeypatch)
        assert not low[:r.band].any() and high[:r.band].sum() > 30


def figure_masks(dance, mesh, frames, monkeypatch) -> list[tuple[np.ndarray, np.ndarray]]:
    """Each frame, and the pixels where the figure is: those that differ from the frame drawn without it."""
    shown = render_frames(dance, mesh, frames)
    with monkeypatch.context() as m:
        m.setattr(render_mod, "rasterise", lambda *args: None)
        m.setattr(FrameRenderer, "_draw_figure", lambda *args: None)
        empty = render_frames(dance, mesh, frames)  # with the figure's shadow
    return [(img, np.abs(img.astype(int) - bg).sum(axis=-1) > 30) for img, bg in zip(shown, empty)]


def test_every_part_of_the_character_is_drawn_in_its_colours(character, dance):
    for img in render_frames(dance, SkinnedMesh.from_character(character), [15, 45]):
        in_colour = {k: drawn(img, albedo) for k, albedo in ALBEDO.items()}
        assert min(in_colour.values()) > 150, f"parts of the body are missing: {in_colour} pixels"
        assert stick_drawn(img, COLOURS["l"]) < 20  # no stick figure on top


def test_the_mannequin_covers_many_more_pixels_than_a_stick_figure(monkeypatch):
    mannequin = pytest.importorskip("dancesynth.retarget.mannequin")
    character = mannequin.mannequin_character()
    dance = waving_dance(character)
    body = figure_masks(dance, SkinnedMesh.from_character(character), [15, 45], monkeypatch)
    stick = figure_masks(dance, None, [15, 45], monkeypatch)
    for (img, mask), (_, stick_mask) in zip(body, stick):
        assert mask.sum() > 1.5 * stick_mask.sum() > 500
        in_colour = np.zeros_like(mask)
        for albedo in mannequin.PALETTE.values():
            in_colour |= shaded(img, albedo, tol=10)
        assert (in_colour & mask).sum() > 0.6 * mask.sum(), "the figure is not in the mesh's colours"


def test_the_silhouette_has_no_holes(character, dance, monkeypatch):
    """Neighbouring polygons meet without a crack of background between them (the tubes overlap at joints)."""
    for _, body in figure_masks(dance, SkinnedMesh.from_character(character), [0, 30, 60], monkeypatch):
        holes = binary_fill_holes(body) & ~body
        assert holes.sum() <= 0.002 * body.sum()


# --------------------------------------------------------------------------- videos

@needs_ffmpeg
def test_video_of_the_character_shows_the_mesh_moving(character, dance, tmp_path):
    out = tmp_path / "character.mp4"
    info = render_video(dance, None, out, width=W, height=H, character=character)
    assert info["figure"] == "character" and info["frames"] == dance.n_frames
    a, b = frame(out, 15), frame(out, 45)
    assert drawn(a, ALBEDO[""]) > 500 and drawn(b, ALBEDO[""]) > 500
    moved = shaded(a, ALBEDO["left"]) != shaded(b, ALBEDO["left"])
    assert moved.sum() > 100, "the arms did not move"


@needs_ffmpeg
def test_stick_figure_on_request_and_from_a_bvh(character, dance, tmp_path):
    import dancesynth

    bvh = tmp_path / "dance.bvh"
    dancesynth.write_bvh(bvh, dance)  # joints depth first: not the character's order
    out = tmp_path / "stick.mp4"
    info = render_video_files(bvh, None, out, width=W, height=H, character=character, figure="stick")
    assert info["figure"] == "stick"
    img = frame(out, 15)
    assert drawn(img, ALBEDO[""]) < 50 < stick_drawn(img, COLOURS["l"])
    out = tmp_path / "mesh.mp4"
    assert render_video_files(bvh, None, out, width=W, height=H, character=character)["figure"] == "character"
    assert drawn(frame(out, 15), ALBEDO[""]) > 500


@needs_ffmpeg
def test_a_character_without_a_mesh_is_drawn_as_the_stick_figure(dance, tmp_path):
    out = tmp_path / "bare.mp4"
    info = render_video(dance, None, out, width=W, height=H, character=tube_character(with_mesh=False))
    assert info["figure"] == "stick"
    assert stick_drawn(frame(out, 15), COLOURS["l"]) > 50


@pytest.mark.parametrize("kwargs, words", [
    ({"figure": "mesh"}, ["unknown figure 'mesh'", "character, stick"]),
    ({"figure": None}, ["unknown figure"]),
    ({"character": "mannequin"}, ["expected a Character"]),
])
def test_bad_figure_or_character(dance, tmp_path, kwargs, words):
    out = tmp_path / "dance.mp4"
    with pytest.raises(InputError) as err:
        render_video(dance, None, out, **kwargs)
    msg = str(err.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg
    assert not out.exists()


@pytest.mark.parametrize("rig, words", [("mixamo", "the dance has no joint 'hips'"),
                                         ("smpl", "the dance has no joint 'hips'")])
def test_a_character_on_another_skeleton_is_refused(character, tmp_path, rig, words):
    other, _ = rig_skeleton(rig)
    n = other.n_joints
    clip = MotionClip(other, 30.0, np.tile(other.offsets[0], (10, 1)), np.tile(rot.IDENTITY, (10, n, 1)))
    with pytest.raises(InputError, match="retarget the dance onto the character") as err:
        render_video(clip, None, tmp_path / "dance.mp4", character=character)
    assert words in str(err.value)


def test_a_dance_with_the_characters_joints_in_another_order_is_reordered(character, dance):
    from dancesynth.export.video import on_skeleton_of

    sk = character.skeleton
    order, stack = [], [0]
    while stack:  # depth first, the last child first: another valid order of the same tree
        order.append(stack.pop())
        stack += sk.children(order[-1]).tolist()
    order = np.array(order)
    assert not np.array_equal(order, np.arange(sk.n_joints))
    new = {int(old): k for k, old in enumerate(order)}
    shuffled_sk = type(sk)(tuple(sk.names[j] for j in order),
                           np.array([new[int(sk.parents[j])] if sk.parents[j] >= 0 else -1 for j in order]),
                           sk.offsets[order], tuple(sk.channels[j] for j in order),
                           {new[j]: o for j, o in sk.end_sites.items()})
    shuffled = MotionClip(shuffled_sk, dance.fps, dance.root_pos, dance.local_rot[:, order])
    back = on_skeleton_of(shuffled, character)
    assert back.skeleton.names == sk.names
    np.testing.assert_array_equal(back.local_rot, dance.local_rot)
    np.testing.assert_allclose(clip_pose(back, np.arange(5))[1], clip_pose(dance, np.arange(5))[1])

    moved = type(sk)(sk.names, np.where(np.arange(sk.n_joints) == 6, 0, sk.parents), sk.offsets, sk.channels,
                     sk.end_sites)  # leftShoulder hanging from the hips
    with pytest.raises(InputError, match="joint 'leftShoulder' hangs from 'hips' in the dance, from 'upperChest'"):
        on_skeleton_of(MotionClip(moved, dance.fps, dance.root_pos, dance.local_rot), character)

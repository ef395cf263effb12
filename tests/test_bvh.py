"""BVH reading and writing: the shared mocap set, the trimmed copies in tests/data, small
hand-made files with known answers, and every malformed-file error."""

from __future__ import annotations


import numpy as np
import pytest

from bvh_samples import TWO_JOINTS
from conftest import REPO, SHARED_MOCAP, requires_shared, shared_mocap_files
from dancesynth import kinematics
from dancesynth import rotations as rot
from dancesynth.errors import InputError
from dancesynth.io import bvh
from dancesynth.io.bvh import format_bvh, parse_bvh, read_bvh, standing_height, write_bvh
from dancesynth.types import ROTATION_CHANNELS, MotionClip, Skeleton

FIXTURES = REPO / "tests" / "data" / "mocap"
FIXTURE_FILES = sorted(FIXTURES.glob("*/*.bvh"))
ALL_FILES = [pytest.param(p, id=f"data/{p.parent.name}/{p.name}") for p in FIXTURE_FILES] + [
    pytest.param(p, id=f"shared/{p.parent.name}/{p.name}") for p in shared_mocap_files()]

# What each folder of the shared set is, from its SOURCES.md and from the data:
# (unit, frame 0 is a converter T-pose, joint counts).
# SOURCES.md says the cgspeed 3dsMax files start with a T-pose too, but none of the four
# files in cmu_max_cgspeed does (frame 0 differs from frame 1 by a normal step and is far
# from the rest pose), so the expectation follows the data.
FOLDERS = {
    "cmu_daz_salsa": ("daz128", False, {43}),
    "cmu_max_cgspeed": ("asf", False, {31}),
    "cmu_mb_fbx2bvh": ("asf", True, {31}),
    "perfume_mit": ("cm", True, {23}),
    "cmu_iclone_cc": ("cm", False, {100, 101}),
    "g1_moves_ccby": ("cm", False, {31}),   # the Unitree G1 robot's kinematics (its README): 1.29 m
}
# Standing heights (rest pose, joints and End Sites) of adults are 1.4-2.1 m; CMU subject
# 94's skeleton is 1.33 m in ASF units x 0.056444 (the top joint is mid-head).
HEIGHT_RANGE_M = (1.4, 2.1)
SHORT_SKELETONS = {"94_01": 1.3, **{p.stem: 1.25 for p in shared_mocap_files() if p.parent.name == "g1_moves_ccby"}}
ROUND_TRIP_FRAMES = 300


def _frame_count(path) -> int:
    for line in path.read_text().splitlines():
        if line.strip().lower().startswith("frames"):
            return int(line.split(":")[1])
    raise AssertionError("no Frames line")


# ----------------------------------------------------------------------------- real files


def test_fixtures_present():
    assert {p.parent.name for p in FIXTURE_FILES} == {"cmu_daz_salsa", "cmu_max_cgspeed", "cmu_mb_fbx2bvh"}
    for licence in ("CMU_LICENSE.txt", "README.md"):
        assert (FIXTURES.parent / licence).is_file()


@requires_shared
def test_shared_set_has_what_the_product_needs():
    """What the product reads from the shared set is there: every genre pattern the default database
    is built from matches files, every clip the bundled database names exists, and every folder of
    BVH files has its expectations below (so a new folder is read by these tests, not skipped)."""
    import tomllib

    from dancesynth.motion.database import open_database

    genres = tomllib.loads((REPO / "scripts" / "default_genres.toml").read_text())["genres"]
    for genre, patterns in genres.items():
        for pattern in [patterns] if isinstance(patterns, str) else patterns:
            assert sorted(SHARED_MOCAP.glob(pattern)), f"{genre}: {pattern} matches nothing in {SHARED_MOCAP}"
    for style in open_database().styles.values():
        for source in style.clip_sources:
            assert (SHARED_MOCAP / source).is_file(), f"{style.name} was built from {source}, missing in {SHARED_MOCAP}"
    unknown = {p.parent.name for p in shared_mocap_files()} - FOLDERS.keys()
    assert not unknown, f"shared mocap folders without expectations in FOLDERS: {sorted(unknown)}"


@pytest.mark.parametrize("path", ALL_FILES)
def test_read_real_file(path):
    unit, has_tpose, joint_counts = FOLDERS[path.parent.name]
    clip = read_bvh(path)
    sk = clip.skeleton
    assert sk.n_joints in joint_counts
    assert clip.meta["name"] == path.stem and clip.meta["source"] == str(path)
    assert clip.meta["source_units"] == unit
    assert clip.meta["metres_per_unit"] == bvh.UNITS[unit]
    assert clip.meta["dropped_tpose"] is has_tpose
    assert clip.n_frames == _frame_count(path) - has_tpose
    assert clip.fps in (40.0, 60.0, 120.0)
    assert np.all(sk.offsets[0] == 0.0)
    assert sk.end_sites and clip.local_pos is None
    assert np.all(np.isfinite(clip.local_rot)) and np.allclose(np.linalg.norm(clip.local_rot, axis=-1), 1.0)
    height = standing_height(sk, clip)
    low = SHORT_SKELETONS.get(path.stem, HEIGHT_RANGE_M[0])
    assert low <= height <= HEIGHT_RANGE_M[1], f"{path.name}: standing height {height:.2f} m"
    # The root stays within a dance floor and near the ground.
    assert np.abs(clip.root_pos).max() < 15.0
    assert 0.3 < np.median(clip.root_pos[:, 1]) < 1.3 or path.stem.startswith("002_")


@pytest.mark.parametrize("path", ALL_FILES)
def test_round_trip_is_lossless(path, tmp_path):
    """read (metres) -> write -> read gives the same skeleton and the same motion."""
    source_text = path.read_text()
    first = read_bvh(path)
    clip = first.frames(0, ROUND_TRIP_FRAMES)
    out = tmp_path / "out.bvh"
    write_bvh(out, clip)
    again = read_bvh(out)  # default unit detection must see metres

    assert again.meta["source_units"] == "m" and not again.meta["dropped_tpose"]
    a, b = clip.skeleton, again.skeleton
    assert a.names == b.names and a.channels == b.channels
    assert np.array_equal(a.parents, b.parents)
    assert np.abs(a.offsets - b.offsets).max() < 1e-6
    assert a.end_sites.keys() == b.end_sites.keys()
    assert all(np.abs(a.end_sites[j] - b.end_sites[j]).max() < 1e-6 for j in a.end_sites)
    assert again.n_frames == clip.n_frames and again.fps == clip.fps
    assert np.abs(again.root_pos - clip.root_pos).max() < 1e-6
    assert np.degrees(rot.angle(again.local_rot, clip.local_rot)).max() < 1e-4

    # Euler channels: every written triple is the source's triple, up to 360-degree wraps
    # and the other triple of the same rotation that rotations.to_euler picks to stay
    # continuous. Within 0.6 degrees of gimbal lock (middle angle +-90) the split between
    # the first and third angle is ill-conditioned (and free at the lock itself), so there
    # the quaternion comparison above is the test.
    first_raw = bvh._parse(source_text, "source")
    out_raw = bvh._parse(out.read_text(), "out")
    skip = int(first.meta["dropped_tpose"])
    src = first_raw.values[skip:skip + clip.n_frames]
    written = out_raw.values
    col = 0
    for j, chans in enumerate(a.channels):
        cols = [col + k for k, c in enumerate(chans) if c in ROTATION_CHANNELS]
        col += len(chans)
        if len(cols) != 3:
            continue
        e_src, e_out = src[:, cols], written[:, cols]
        alt = e_src + [180.0, 0.0, 180.0]
        alt[:, 1] = 180.0 - e_src[:, 1]

        def same(x, y):
            return np.all(np.abs((x - y + 180.0) % 360.0 - 180.0) < 1e-4, axis=1)

        gimbal = np.abs(np.cos(np.radians(e_src[:, 1]))) < 1e-2
        ok = same(e_src, e_out) | same(alt, e_out) | gimbal
        assert ok.all(), f"joint {a.names[j]}: frames {np.flatnonzero(~ok)[:5]}"

    # Our own files are a fixed point: writing the re-read clip gives the same numbers.
    rewritten = bvh._parse(format_bvh(again), "rewritten").values
    assert np.abs(rewritten - written).max() < 1e-4


def test_a_long_file_parses_whole():
    """3600 frames x 43 joints (the salsa fixture repeated) parse to every frame and joint. (It takes
    about 0.2 s on an idle 2-core machine; speed is not asserted here: a loaded machine makes any
    wall-clock bound flaky.)"""
    text = (FIXTURES / "cmu_daz_salsa" / "60_01_scaled.bvh").read_text()
    head, body = text.split("Frame Time:", 1)
    frame_time_line, data = body.split("\n", 1)
    lines = data.strip("\n").split("\n")
    big = (head.replace("Frames: 120", "Frames: 3600") + "Frame Time:" + frame_time_line + "\n"
           + "\n".join(lines * 30) + "\n")
    clip = parse_bvh(big)
    assert clip.n_frames == 3600 and clip.skeleton.n_joints == 43
    small = parse_bvh(text)
    np.testing.assert_allclose(clip.local_rot[3480:], small.local_rot, atol=1e-12)  # the last copy is the file


# ----------------------------------------------------------------------------- small files

def test_parse_values_and_conventions():
    clip = parse_bvh(TWO_JOINTS, to_metres=False, drop_tpose=False)
    sk = clip.skeleton
    assert sk.names == ("Hips", "Spine") and list(sk.parents) == [-1, 0]
    assert sk.channels[1] == ("Yrotation", "Xrotation", "Zrotation")
    assert sk.rotation_order(0) == "ZXY" and sk.rotation_order(1) == "YXZ"
    assert np.array_equal(sk.offsets, [[0, 0, 0], [0, 10, 0]])  # root OFFSET folded into root_pos
    assert np.array_equal(sk.end_sites[1], [0, 5, 0])
    assert np.array_equal(clip.root_pos, [[1, 2, 3], [2, 4, 6]])
    assert clip.fps == 25.0 and clip.local_pos is None
    expected = np.stack([rot.from_euler([[10, 20, 30], [-10, -20, -30]], "ZXY"),
                         rot.from_euler([[40, 50, 60], [-40, -50, -60]], "YXZ")], axis=1)
    assert np.allclose(clip.local_rot, expected, atol=1e-12)
    # Intrinsic order: Zrotation applied first in the parent frame, then X, then Y.
    z, x, y = (rot.from_euler(a, ax) for a, ax in ((10, "Z"), (20, "X"), (30, "Y")))
    assert np.allclose(clip.local_rot[0, 0], rot.mul(rot.mul(z, x), y))


@pytest.mark.parametrize("order", ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX", "Z", "XY"])
def test_fast_euler_matches_scipy(order):
    from scipy.spatial.transform import Rotation

    angles = np.random.default_rng(1).uniform(-400, 400, (50, 7, len(order)))
    ours = rot.from_euler(angles, order)
    ref = Rotation.from_euler(order, angles.reshape(-1, len(order)), degrees=True).as_quat(canonical=False)
    assert np.allclose(ours.reshape(-1, 4), ref, atol=1e-12)


def test_whitespace_variants():
    messy = TWO_JOINTS.replace("  ", "\t").replace("\n", "  \r\n").replace("MOTION", "\r\n\r\nMOTION   ")
    messy = messy.replace("Frame Time: 0.04", "Frame Time:    .04").replace("0 0 0 10", "\r\n0   0 \t0 10")
    a = parse_bvh(TWO_JOINTS, to_metres=False)
    b = parse_bvh(messy, to_metres=False)
    assert a.skeleton.names == b.skeleton.names and a.fps == b.fps
    assert np.array_equal(a.local_rot, b.local_rot) and np.array_equal(a.root_pos, b.root_pos)
    # Bare CR line endings (old Mac exporters) and a trailing blank tail.
    c = parse_bvh(TWO_JOINTS.replace("\n", "\r") + "\r\r", to_metres=False)
    assert np.array_equal(a.local_rot, c.local_rot)


def test_frame_time_snaps_to_whole_rates():
    assert bvh._fps_from_frame_time(0.016667, "0.016667") == 60.0
    assert bvh._fps_from_frame_time(0.0083333, ".0083333") == 120.0
    assert bvh._fps_from_frame_time(0.01666667, "0.01666667") == 60.0
    assert bvh._fps_from_frame_time(0.016683, "0.016683") == pytest.approx(1 / 0.016683)


def test_joint_name_with_spaces_becomes_one_word():
    clip = parse_bvh(TWO_JOINTS.replace("JOINT Spine", "JOINT Upper Spine"), to_metres=False)
    assert clip.skeleton.names[1] == "Upper_Spine"


NONROOT_POSITIONS = """HIERARCHY
ROOT root
{
\tOFFSET 0 0 0
\tCHANNELS 3 Xposition Yposition Zposition
\tJOINT slider
\t{
\t\tOFFSET 0 1 0
\t\tCHANNELS 4 Zrotation Yposition Xrotation Yrotation
\t\tJOINT twist
\t\t{
\t\t\tOFFSET 0 1 0
\t\t\tCHANNELS 1 Zrotation
\t\t\tEnd Site
\t\t\t{
\t\t\t\tOFFSET 0 1 0
\t\t\t}
\t\t}
\t}
}
MOTION
Frames: 3
Frame Time: 0.1
0 1 0 10 0.5 20 30 45
0 1 0 15 0.25 25 35 50
0 1 0 20 0 30 40 55
"""


def test_nonroot_position_channels_and_partial_rotations(tmp_path):
    clip = parse_bvh(NONROOT_POSITIONS, to_metres=False, drop_tpose=False)
    assert clip.local_pos is not None
    assert np.allclose(clip.local_pos[:, 1], [[0, 1.5, 0], [0, 1.25, 0], [0, 1.0, 0]])
    assert np.allclose(clip.local_pos[:, 2], [[0, 1, 0]] * 3)
    assert np.allclose(clip.local_rot[:, 0], rot.IDENTITY)  # a joint without rotation channels
    assert np.allclose(clip.local_rot[:, 1], rot.from_euler([[10, 20, 30], [15, 25, 35], [20, 30, 40]], "ZXY"))
    assert np.allclose(clip.local_rot[:, 2], rot.from_euler([[45], [50], [55]], "Z"))
    # FK uses local_pos directly.
    _, pos = kinematics.clip_fk(clip)
    assert np.allclose(pos[:, 0], [0, 1, 0])
    assert np.allclose(np.linalg.norm(pos[:, 1] - pos[:, 0], axis=-1), [1.5, 1.25, 1.0])

    out = tmp_path / "slider.bvh"
    write_bvh(out, clip)
    text = out.read_text()
    assert "CHANNELS 4 Zrotation Yposition Xrotation Yrotation" in text and "CHANNELS 1 Zrotation" in text
    again = read_bvh(out, units="m", drop_tpose=False)
    assert np.allclose(again.local_pos, clip.local_pos, atol=1e-6)
    assert np.degrees(rot.angle(again.local_rot, clip.local_rot)).max() < 1e-4
    assert np.allclose(bvh._parse(text, "x").values, bvh._parse(NONROOT_POSITIONS, "y").values, atol=1e-6)


def test_root_offset_folded_and_written_as_zero(tmp_path):
    clip = parse_bvh(TWO_JOINTS, to_metres=False, drop_tpose=False)
    text = format_bvh(clip)
    lines = text.splitlines()
    assert lines[:4] == ["HIERARCHY", "ROOT Hips", "{", "\tOFFSET 0.000000 0.000000 0.000000"]
    assert "Frame Time: 0.04000000" in lines and "Frames: 2" in lines
    assert "\t\tEnd Site" in lines
    assert lines[-2].split()[:3] == ["1.000000", "2.000000", "3.000000"]
    # Without root position channels, the (constant) root position goes into the OFFSET.
    static = TWO_JOINTS.replace("CHANNELS 6 Xposition Yposition Zposition Zrotation", "CHANNELS 3 Zrotation")
    static = static.replace("0 0 0 10 20 30", "10 20 30").replace("1 2 3 -10 -20 -30", "-10 -20 -30")
    clip = parse_bvh(static, to_metres=False, drop_tpose=False)
    assert np.array_equal(clip.root_pos, [[1, 2, 3], [1, 2, 3]])
    assert "\tOFFSET 1.000000 2.000000 3.000000" in format_bvh(clip).splitlines()
    again = parse_bvh(format_bvh(clip), to_metres=False, drop_tpose=False)
    assert np.allclose(again.root_pos, clip.root_pos)


def test_precision_and_frame_time_digits():
    clip = parse_bvh(TWO_JOINTS, to_metres=False, drop_tpose=False)
    text = format_bvh(clip, precision=3)
    assert text.splitlines()[-1].split()[0] == "2.000"
    with pytest.raises(InputError, match="precision"):
        format_bvh(clip, precision=-1)
    clip.fps = 60.0
    assert "Frame Time: 0.01666667" in format_bvh(clip)


def test_write_is_atomic(tmp_path):
    clip = parse_bvh(TWO_JOINTS, to_metres=False, drop_tpose=False)
    out = tmp_path / "keep.bvh"
    out.write_text("previous contents")
    bad = MotionClip(clip.skeleton, clip.fps, clip.root_pos * np.nan, clip.local_rot)
    with pytest.raises(InputError, match="NaN"):
        write_bvh(out, bad)
    assert out.read_text() == "previous contents"
    assert [p.name for p in tmp_path.iterdir()] == ["keep.bvh"]
    with pytest.raises(InputError, match="does not exist"):
        write_bvh(tmp_path / "missing" / "x.bvh", clip)


def test_write_follows_hierarchy_order_for_skeletons_built_in_code():
    # Breadth-first indices: 0 -> (1, 2), 1 -> 3, 2 -> 4. BVH lists channels depth first.
    chans = (("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"),) + \
        (("Zrotation", "Xrotation", "Yrotation"),) * 4
    sk = Skeleton(("root", "a", "b", "a2", "b2"), [-1, 0, 0, 1, 2],
                  [[0, 0, 0], [0, 1, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0]], chans, {3: np.array([0, 1, 0])})
    angles = np.random.default_rng(2).uniform(-60, 60, (4, 5, 3))
    clip = MotionClip(sk, 30.0, np.zeros((4, 3)), rot.from_euler(angles.reshape(-1, 3), "ZXY").reshape(4, 5, 4))
    again = parse_bvh(format_bvh(clip), to_metres=False, drop_tpose=False)
    assert again.skeleton.names == ("root", "a", "a2", "b", "b2")
    for name in sk.names:
        i, k = sk.index(name), again.skeleton.index(name)
        assert np.degrees(rot.angle(clip.local_rot[:, i], again.local_rot[:, k])).max() < 1e-4
        assert np.allclose(sk.offsets[i], again.skeleton.offsets[k])
    _, p1 = kinematics.clip_fk(clip)
    _, p2 = kinematics.clip_fk(again)
    assert np.allclose(p1[:, [0, 1, 3, 2, 4]], p2, atol=1e-5)


@pytest.mark.parametrize("names, channels, expected", [
    (("root", "left arm"), None, "one word"),
    (("root", "root"), None, "appears twice"),
    (("root", "a"), ((), ()), "no joint of the skeleton has channels"),
])
def test_write_rejects_what_bvh_cannot_say(names, channels, expected):
    chans = channels or (("Zrotation", "Xrotation", "Yrotation"),) * 2
    sk = Skeleton(names, [-1, 0], [[0, 0, 0], [0, 1, 0]], chans)
    clip = MotionClip(sk, 30.0, np.zeros((2, 3)), np.tile(rot.IDENTITY, (2, 2, 1)))
    with pytest.raises(InputError, match=expected):
        format_bvh(clip)

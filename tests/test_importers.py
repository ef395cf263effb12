"""Importers of the public mocap sets: AIST++ pickles, CMU ASF/AMC, and the genre in their names.

Fixtures (tests/fixtures/importers, written by make_fixtures.py there) are small files in
each format's published layout; tests that need a variant write it to tmp_path.
"""

from __future__ import annotations

import os
import pickle
import shutil

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dancesynth.errors import InputError
from dancesynth.io import aist, asf_amc
from dancesynth.io.bvh import format_bvh, parse_bvh
from dancesynth.io.motion_files import MOTION_SUFFIXES, cmu_fps_fix, genre_from_name, read_motion
from dancesynth.io.skeleton_units import standing_height
from dancesynth.kinematics import clip_fk
from dancesynth.motion.roles import find_roles
from dancesynth.retarget.humanoid import find_bones

from conftest import REPO

FIX = REPO / "tests" / "fixtures" / "importers"
ASF = FIX / "05.asf"
AMC = FIX / "05_02.amc"
CGSPEED_BVH = FIX / "60_01.bvh"
AIST_PKL = FIX / "gBR_sBM_cAll_d04_mBR0_ch01.pkl"
ASF_M = 0.0254 / 0.45   # CMU's length unit in metres


def _check_humanoid(clip):
    """What every reader must give: a 1.5-2 m body, Y up, both legs and arms found by both finders."""
    roles = find_roles(clip.skeleton)
    bones = find_bones(clip.skeleton)
    for side in ("left", "right"):
        for part in ("UpperLeg", "LowerLeg", "Foot", "UpperArm", "LowerArm", "Hand"):
            assert side + part in bones
    assert all(j >= 0 for pair in (roles.hips, roles.knees, roles.ankles) for j in pair)
    assert roles.ankles[0] != roles.ankles[1]
    assert 1.5 <= standing_height(clip.skeleton) <= 2.0
    _, g = clip_fk(clip)
    head, feet = g[:, roles.head, 1], g[:, list(roles.ankles), 1].max(axis=1)
    assert np.all(head > feet + 1.0)                       # Y up: the head well above the feet
    assert np.all(np.abs(np.linalg.norm(clip.local_rot, axis=-1) - 1) < 1e-9)
    return roles, g


# --------------------------------------------------------------------------- CMU ASF/AMC


def test_asf_reads_cmus_31_bone_skeleton():
    sk = asf_amc.read_asf(ASF)
    assert sk.n_joints == 31 and sk.names[0] == "root"
    assert sk.length_unit == 0.45 and sk.angle_deg
    assert all(p < j for j, p in enumerate(sk.parents) if j)
    femur = sk.names.index("lfemur")
    assert sk.names[sk.parents[femur]] == "lhipjoint"
    assert np.allclose(sk.directions[femur], [0.34202, -0.939693, 0], atol=1e-6)
    assert sk.dofs[sk.names.index("ltibia")] == ("rx",) and sk.dofs[0] == ("tx", "ty", "tz", "rx", "ry", "rz")
    assert np.allclose(sk.axes[femur].as_euler("xyz", degrees=True), [0, 0, 20])


def test_amc_reads_frames_fps_metres_and_humanoid_names():
    clip = asf_amc.read_amc(AMC)                       # 05.asf is found beside it
    assert clip.n_frames == 8 and clip.fps == 120.0
    assert clip.skeleton.n_joints == 31
    assert clip.skeleton.names[:3] == ("Hips", "LHipJoint", "LeftUpLeg")
    assert clip.meta["asf_names"][:3] == ("root", "lhipjoint", "lfemur")
    assert clip.meta["metres_per_unit"] == pytest.approx(0.056444, abs=1e-6)
    # The root's AMC position (ASF units, first frame) in metres.
    root_line = next(line for line in AMC.read_text().splitlines() if line.startswith("root "))
    assert np.allclose(clip.root_pos[0], np.array(root_line.split()[1:4], float) * ASF_M)
    roles, g = _check_humanoid(clip)
    assert clip.skeleton.names[roles.ankles[0]] == "LeftFoot"
    assert 0.0 < g[..., 1].min() < 0.15                # the feet near the floor at y = 0


def _amc(tmp_path, values: dict, *, name="05_09.amc", frames=1):
    """A CMU-layout AMC beside a copy of the fixture ASF: ``values`` bone -> dof values, others 0."""
    sk = asf_amc.read_asf(ASF)
    shutil.copy(ASF, tmp_path / "05.asf")
    lines = [":FULLY-SPECIFIED", ":DEGREES"]
    for f in range(1, frames + 1):
        lines.append(str(f))
        for j, bone in enumerate(sk.names):
            if sk.dofs[j]:
                v = values.get(bone, [0.0, 17.8, 0.0, 0.0, 0.0, 0.0] if bone == "root" else [0.0] * len(sk.dofs[j]))
                lines.append(bone + " " + " ".join(f"{x:g}" for x in v))
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def test_amc_knee_bent_90_degrees_puts_the_ankle_behind_the_knee(tmp_path):
    # CMU's tibia: axis 0 0 20 XYZ, so rx turns about the hinge (cos20, sin20, 0), square to the
    # splayed shin (sin20, -cos20, 0); +90 (flexion: CMU's limits are -10..170) swings the shin to
    # point straight back, -Z (the skeleton faces +Z, its toes point +Z).
    clip = asf_amc.read_amc(_amc(tmp_path, {"ltibia": [90.0], "rtibia": [90.0]}))
    _, g = clip_fk(clip)
    roles = find_roles(clip.skeleton)
    shin = 7.6 * ASF_M
    for knee, ankle in zip(roles.knees, roles.ankles):
        assert np.allclose(g[0, ankle] - g[0, knee], [0.0, 0.0, -shin], atol=1e-5)   # 6-digit ASF numbers
    toe = roles.toes[0]
    assert g[0, toe, 2] < g[0, roles.ankles[0], 2]     # the foot turned with the shin: toes point down/back


def test_amc_rest_pose_and_root_turn(tmp_path):
    rest = asf_amc.read_amc(_amc(tmp_path, {}))
    _, g = clip_fk(rest)
    roles = find_roles(rest.skeleton)
    ankle, toe = roles.ankles[0], roles.toes[0]
    assert g[0, toe, 2] > g[0, ankle, 2]               # the rest pose faces +Z
    hip, knee = roles.hips[0], roles.knees[0]
    thigh = (g[0, knee] - g[0, hip]) / np.linalg.norm(g[0, knee] - g[0, hip])
    assert np.allclose(thigh, [0.34202, -0.939693, 0], atol=1e-6)   # the ASF direction, unrotated
    wl, wr = roles.wrists
    assert g[0, wl, 0] > 0.5 and g[0, wr, 0] < -0.5    # arms out to the sides: left towards +X
    turned = asf_amc.read_amc(_amc(tmp_path, {"root": [0, 17.8, 0, 0, 90, 0]}, name="05_10.amc"))
    _, g2 = clip_fk(turned)
    assert g2[0, toe, 0] > g2[0, ankle, 0] + 0.05      # RY 90 turns the body to face +X
    assert np.allclose(g2[0, toe, 2], g2[0, ankle, 2], atol=0.03)


def test_amc_matches_an_independent_acclaim_fk(tmp_path):
    """The clip's FK equals the textbook Acclaim chain (CMU's viewer; CalciferZh/AMCParser):
    ``W = W_parent C M C^-1``, bone end = start + length * W direction, M = Rz Ry Rx of the dofs."""
    sk = asf_amc.read_asf(ASF)
    rng = np.random.default_rng(7)
    values = {b: list(rng.uniform(-40, 40, len(sk.dofs[j])).round(3)) for j, b in enumerate(sk.names) if sk.dofs[j]}
    values["root"] = [3.0, 17.0, -2.0, *rng.uniform(-60, 60, 3).round(3)]
    clip = asf_amc.read_amc(_amc(tmp_path, values))
    _, g = clip_fk(clip)

    def mat(axis, angle):
        return Rotation.from_euler(axis, angle, degrees=True).as_matrix()

    world, ends = {}, {}
    for j, bone in enumerate(sk.names):
        c = sk.axes[j].as_matrix()
        m = np.eye(3)
        for d, v in zip(sk.dofs[j], values.get(bone, [])):
            if d[0] == "r":
                m = mat(d[1], v) @ m                   # first listed dof applied first
        local = c @ m @ c.T
        if j == 0:
            world[j], start = local, np.array(values["root"][:3])
        else:
            p = sk.parents[j]
            world[j], start = world[p] @ local, ends[p]
        ends[j] = start + sk.lengths[j] * world[j] @ sk.directions[j]
        start_m = start * ASF_M
        assert np.allclose(g[0, j], start_m, atol=1e-9), bone      # each joint sits at its bone's start


def test_amc_frame_rate_follows_cmus_table(tmp_path):
    for subject, fps in (("60", 60.0), ("61", 60.0), ("05", 120.0), ("94", 120.0)):
        folder = tmp_path / subject
        folder.mkdir()
        shutil.copy(ASF, folder / f"{subject}.asf")
        shutil.copy(AMC, folder / f"{subject}_01.amc")
        assert asf_amc.read_amc(folder / f"{subject}_01.amc").fps == fps
    assert asf_amc.read_amc(tmp_path / "60" / "60_01.amc", fps=30).fps == 30


def test_find_asf_beside_the_amc(tmp_path):
    shutil.copy(AMC, tmp_path / "07_03.amc")
    with pytest.raises(InputError, match="07.asf"):
        asf_amc.find_asf(tmp_path / "07_03.amc")
    shutil.copy(ASF, tmp_path / "subject.asf")            # the only .asf in the folder
    assert asf_amc.find_asf(tmp_path / "07_03.amc").name == "subject.asf"
    assert read_motion(tmp_path / "07_03.amc").n_frames == 8
    shutil.copy(ASF, tmp_path / "other.asf")
    with pytest.raises(InputError, match="2 .asf files"):
        asf_amc.find_asf(tmp_path / "07_03.amc")


@pytest.mark.parametrize("damage", ["truncated_mid_frame", "truncated_mid_line", "garbage_text", "binary",
                                    "empty", "unknown_bone", "not_a_number", "skipped_frame"])
def test_damaged_amc_is_an_input_error(tmp_path, damage):
    shutil.copy(ASF, tmp_path / "05.asf")
    text = AMC.read_text()
    path = tmp_path / "05_02.amc"
    if damage == "truncated_mid_frame":
        data = text[: text.index("\n8\n") + 60].encode()
    elif damage == "truncated_mid_line":
        data = text.rstrip()[:-9].encode()
    elif damage == "garbage_text":
        data = b"this is not a motion file\nat all\n"
    elif damage == "binary":
        data = os.urandom(2000) + b"\x00"
    elif damage == "empty":
        data = b""
    elif damage == "unknown_bone":
        data = text.replace("lradius", "lradiusX", 1).encode()
    elif damage == "not_a_number":
        data = text.replace("rthumb 0 0", "rthumb 0 zero", 1).encode()
    else:
        data = text.replace("\n3\n", "\n4\n", 1).encode()
    path.write_bytes(data)
    with pytest.raises(InputError, match="05_02.amc"):
        asf_amc.read_amc(path)


@pytest.mark.parametrize("damage", ["truncated", "no_hierarchy", "loop", "bad_number", "unknown_child"])
def test_damaged_asf_is_an_input_error(tmp_path, damage):
    text = ASF.read_text()
    if damage == "truncated":
        text = text[: text.index("name lradius") + 40]
    elif damage == "no_hierarchy":
        text = text[: text.index(":hierarchy")]
    elif damage == "loop":
        text = text.replace("    lhand lfingers\n", "    lhand lfingers\n    lfingers lwrist\n")
    elif damage == "bad_number":
        text = text.replace("length 7.6", "length seven", 1)
    else:
        text = text.replace("lhand lfingers", "lhand lpinky")
    (tmp_path / "05.asf").write_text(text)
    shutil.copy(AMC, tmp_path / "05_02.amc")
    with pytest.raises(InputError, match="05.asf"):
        asf_amc.read_amc(tmp_path / "05_02.amc")


# --------------------------------------------------------------------------- cgspeed BVH and the 60-fps fix


def test_cgspeed_bvh_of_a_60fps_subject_reads_at_60(tmp_path):
    clip = read_motion(CGSPEED_BVH)                       # Frame Time .0083333, named 60_01
    assert clip.fps == 60.0 and clip.meta["fps_in_file"] == 120.0
    assert clip.meta["dropped_tpose"] and clip.n_frames == 8
    _check_humanoid(clip)
    shutil.copy(CGSPEED_BVH, tmp_path / "94_01.bvh")      # subject 94 is at 120 fps in CMU's table
    assert read_motion(tmp_path / "94_01.bvh").fps == 120.0
    # The BVH conversion and the AMC original are the same motion, in the same metres.
    _, g_bvh = clip_fk(clip)
    _, g_amc = clip_fk(asf_amc.read_amc(AMC))
    assert np.abs(g_bvh - g_amc).max() < 1e-4


def test_cmu_fps_fix():
    assert cmu_fps_fix("60_01.bvh", 120.0) == 60.0
    assert cmu_fps_fix("/data/cmu/61/61_15.bvh", 120.0) == 60.0
    assert cmu_fps_fix("60_01_scaled.bvh", 60.0) == 60.0      # already right: unchanged
    assert cmu_fps_fix("60_01.bvh", 30.0) == 30.0
    assert cmu_fps_fix("94_01.bvh", 120.0) == 120.0
    assert cmu_fps_fix("05_02.amc", 120.0) == 120.0
    assert cmu_fps_fix("salsa_60_01.bvh", 120.0) == 120.0     # not a CMU trial name
    assert cmu_fps_fix("600_01.bvh", 120.0) == 120.0
    assert cmu_fps_fix("136_19.bvh", 120.0) == 60.0           # CMU's table: one 60-fps trial of subject 136
    assert cmu_fps_fix("136_18.bvh", 120.0) == 120.0


# --------------------------------------------------------------------------- AIST++


def test_aist_pickle_reads_onto_the_smpl_rig():
    clip = read_motion(AIST_PKL)
    assert clip.n_frames == 24 and clip.fps == 60.0 and clip.skeleton.n_joints == 24
    assert clip.skeleton.names[:3] == ("pelvis", "left_hip", "right_hip")
    roles, g = _check_humanoid(clip)
    # smpl_trans / smpl_scaling is the root's path in metres (x, z as stored; y put on the floor).
    assert np.allclose(clip.root_pos[0, [0, 2]], [0.12, -0.40], atol=1e-5)
    assert np.allclose(np.diff(clip.root_pos[:, 0]), 0.3 / 60.0, atol=1e-5)
    lowest = g[..., 1].min(axis=1)
    assert np.percentile(lowest, 5) == pytest.approx(0.015, abs=1e-6)   # the rig's rest toe height
    assert clip.meta["smpl_scaling"] == pytest.approx(93.47, abs=1e-3)
    # The knees bend as the poses say: SMPL joint 4 (left_knee) local rotation about +X.
    knee = Rotation.from_quat(clip.local_rot[:, 4]).as_rotvec()
    assert knee[:, 0].max() > 0.5
    # A dance read from AIST++ can be written as BVH and read back the same.
    back = parse_bvh(format_bvh(clip), units="m")
    order = [back.skeleton.index(n) for n in clip.skeleton.names]     # BVH lists joints depth first
    assert np.abs(clip_fk(back)[1][:, order] - g).max() < 1e-3


def _aist_dict(n=10, poses_shape=None):
    poses = np.zeros((n, 72), np.float32)
    poses[:, 16 * 3 + 2] = -1.0
    if poses_shape:
        poses = poses.reshape(poses_shape)
    return {"smpl_poses": poses, "smpl_trans": np.tile(np.float32([0.0, 80.0, 0.0]), (n, 1)),
            "smpl_scaling": np.array([90.0], np.float32), "smpl_loss": 0.02}


@pytest.mark.parametrize("protocol", [2, 4, 5])
def test_aist_pickles_of_any_protocol_and_pose_layout(tmp_path, protocol):
    path = tmp_path / "gPO_sBM_cAll_d10_mPO1_ch02.pkl"
    path.write_bytes(pickle.dumps(_aist_dict(10, (10, 24, 3)), protocol=protocol))
    clip = read_motion(path)
    assert clip.n_frames == 10 and clip.fps == 60.0
    _check_humanoid(clip)


class _Evil:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


class _HugeArray:
    def __reduce__(self):
        from numpy._core.multiarray import _reconstruct

        return _reconstruct, (np.ndarray, (10**12,), b"b")


def test_pickle_guard_refuses_code_and_runs_nothing(tmp_path):
    marker = tmp_path / "pwned"
    evil = _aist_dict()
    evil["smpl_loss"] = _Evil(marker)
    for protocol in (0, 2, 4, 5):
        path = tmp_path / f"gBR_evil_{protocol}.pkl"
        path.write_bytes(pickle.dumps(evil, protocol=protocol))
        with pytest.raises(InputError, match="system"):
            read_motion(path)
        assert not marker.exists()                       # os.system was never called
    # An allowed numpy function called with arguments numpy never writes (a 1 TB array) is refused too.
    path = tmp_path / "huge.pkl"
    path.write_bytes(pickle.dumps({"smpl_poses": _HugeArray()}, protocol=4))
    with pytest.raises(InputError, match="refused"):
        aist.read_aist(path)
    path.write_bytes(pickle.dumps({"smpl_poses": np.array([1, 2], dtype=object)}, protocol=4))
    with pytest.raises(InputError):
        aist.read_aist(path)


@pytest.mark.parametrize("damage", ["truncated", "garbage", "empty", "list", "keypoints", "nan", "frames_disagree",
                                    "zero_scale", "strings"])
def test_damaged_aist_pickle_is_an_input_error(tmp_path, damage):
    path = tmp_path / "gBR_sBM_cAll_d04_mBR0_ch01.pkl"
    d = _aist_dict()
    if damage == "truncated":
        data = AIST_PKL.read_bytes()[:3000]
    elif damage == "garbage":
        data = b"\x80\x04garbage that is not a pickle" * 10
    elif damage == "empty":
        data = b""
    elif damage == "list":
        data = pickle.dumps([1, 2, 3])
    elif damage == "keypoints":
        data = pickle.dumps({"keypoints3d": np.zeros((3, 17, 3)), "keypoints3d_optim": np.zeros((3, 17, 3))})
    else:
        if damage == "nan":
            d["smpl_poses"][3, 5] = np.nan
        elif damage == "frames_disagree":
            d["smpl_trans"] = d["smpl_trans"][:5]
        elif damage == "zero_scale":
            d["smpl_scaling"] = np.array([0.0])
        else:
            d["smpl_poses"] = "not an array"
        data = pickle.dumps(d, protocol=4)
    path.write_bytes(data)
    with pytest.raises(InputError, match="gBR_sBM") as exc:
        read_motion(path)
    if damage == "keypoints":
        assert "motions/" in str(exc.value)


def test_pickle_size_is_bounded(tmp_path):
    path = tmp_path / "big.pkl"
    path.write_bytes(pickle.dumps(_aist_dict(200), protocol=4))
    with pytest.raises(InputError, match="MB"):
        aist.load_pickle_arrays(path, max_bytes=10_000)


# --------------------------------------------------------------------------- dispatch and genres


def test_read_motion_dispatch():
    assert MOTION_SUFFIXES == (".bvh", ".pkl", ".amc")
    with pytest.raises(InputError, match="skeleton"):
        read_motion(ASF)
    with pytest.raises(InputError, match="unknown motion format"):
        read_motion(FIX / "make_fixtures.py")
    with pytest.raises(InputError, match="no such"):
        read_motion(FIX / "missing.amc")


@pytest.mark.parametrize("name, genre", [
    # AIST++ sequence names (and AIST Dance DB video names), all ten genres
    ("gBR_sBM_cAll_d04_mBR0_ch01.pkl", "break"), ("gPO_sBM_cAll_d10_mPO1_ch02.pkl", "pop"),
    ("gLO_sFM_cAll_d13_mLO2_ch02.pkl", "lock"), ("gMH_sBM_cAll_d22_mMH3_ch04.pkl", "middle-hiphop"),
    ("gLH_sFM_cAll_d16_mLH4_ch05.pkl", "la-hiphop"), ("gHO_sBM_cAll_d19_mHO0_ch08.pkl", "house"),
    ("gWA_sFM_c01_d27_mWA2_ch21", "waack"), ("gKR_sBM_cAll_d28_mKR2_ch01.pkl", "krump"),
    ("gJS_sFM_cAll_d01_mJS3_ch03.pkl", "street-jazz"), ("gJB_sBM_cAll_d08_mJB5_ch10.pkl", "ballet-jazz"),
    # Motorica Dance (file names from ListenDenoiseAction's data lists)
    ("kthjazz_gCH_sFM_cAll_d02_mCH_ch01_beatlestreetwashboardbandfortyandtight_003.bvh", "charleston"),
    ("kthjazz_gJZ_sFM_cAll_d02_mJZ_ch01_bennygoodmanairmailspecial_002.bvh", "jazz"),
    ("kthjazz_gTP_sFM_sngl_d02_015.bvh", "tap"), ("kthmisc_gCA_sFM_cAll_d01_mCA_ch24.bvh", "casual"),
    ("kthstreet_gKR_sFM_cAll_d01_mKR_ch01_chargedcableupyour_001.bvh", "krump"),
    ("kthstreet_gLH_sFM_cAll_d02_mLH_ch01_lala_001.bvh", "hiphop"),
    ("kthstreet_gLO_sFM_cAll_d02_mLO_ch01_arethafranklinrocksteady_002.bvh", "lock"),
    ("kthstreet_gPO_sFM_cAll_d01_mPO_ch01_bombom_002.bvh", "pop"),
    # LaFAN1
    ("dance1_subject1.bvh", "dance"), ("dance2_subject3.bvh", "dance"), ("walk1_subject1.bvh", None),
    ("fightAndSports1_subject4.bvh", None), ("aiming2_subject5.bvh", None),
    # Bandai Namco Research Motion Dataset
    ("dataset-1_dance-long_normal_001.bvh", "dance"), ("dataset-1_dance-short_normal_001.bvh", "dance"),
    ("dataset-1_walk_not-confident_001.bvh", None), ("dataset-2_raise-up-both-hands_active_001.bvh", None),
    # CMU (cgspeed, the Daz release, FBX conversions, iClone's zero-padded names, ASF/AMC)
    ("60_01.bvh", "salsa"), ("61_15.bvh", "salsa"), ("60_01_scaled.bvh", "salsa"), ("05_02.amc", "modern"),
    ("005_03.bvh", "modern"), ("05_01.bvh", None), ("94_01.bvh", "indian"), ("131_01.bvh", "mj"),
    ("55_01_cmu.bvh", "whirl"), ("55_02.bvh", "lambada"), ("55_03.bvh", None), ("07_01_cmu.bvh", None),
    ("93_03.amc", "charleston"), ("103_06.bvh", "lindy-hop"), ("85_12.bvh", "break"), ("90_30.bvh", "russian"),
    ("49_09.amc", "modern"), ("49_06.amc", None),
    # anything else
    ("my_dance.bvh", None), ("A_test.bvh", None), ("J_Dance2_Salsa.bvh", None),
])
def test_genre_from_name(name, genre):
    assert genre_from_name(name) == genre
    assert genre_from_name(f"/some/folder/{name}") == genre

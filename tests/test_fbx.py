"""A dance as FBX (issue 14): Blender writes it from our .glb, and Blender's own FBX importer, a
reader independent of the writer's settings, finds the rig's bones, every frame, and every joint
where our forward kinematics puts it; the raw file is Y up, in centimetres, its armature node
untransformed and its joints in the rest pose. Without Blender, or when Blender fails or hangs,
the user gets one line and no file."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import REPO
from test_cli import TRUMPET, assert_clean_failure, cli
from test_gltf import _blender_has_numpy
from dancesynth.errors import InputError
from dancesynth.export import fbx
from dancesynth.export.gltf import glb_bytes
from dancesynth.kinematics import clip_fk
from dancesynth.retarget.rigs import rig_skeleton
from dancesynth.types import MotionClip

CLIENTS = REPO / "tests" / "clients"
FBX_MAGIC = b"Kaydara FBX Binary"
CM_PER_M = 100.0


def waving_clip(n_frames: int = 61, fps: float = 30.0) -> MotionClip:
    """Two seconds on the mixamo rig: arms waving, elbows and knees bending, the body turning and travelling."""
    sk, bones = rig_skeleton("mixamo")
    t = np.arange(n_frames) / fps
    turn = np.zeros((n_frames, sk.n_joints, 3))        # rotation vectors, radians
    for side, sign in (("left", 1.0), ("right", -1.0)):
        turn[:, bones[side + "UpperArm"], 2] = -sign * 0.8 * np.sin(2 * np.pi * t)
        turn[:, bones[side + "LowerArm"], 1] = 0.6 * np.sin(4 * np.pi * t)
        turn[:, bones[side + "UpperLeg"], 0] = -0.4 * (1 - np.cos(2 * np.pi * t))
        turn[:, bones[side + "LowerLeg"], 0] = 0.7 * (1 - np.cos(2 * np.pi * t))
    turn[:, 0, 1] = 0.5 * t
    local_rot = Rotation.from_rotvec(turn.reshape(-1, 3)).as_quat().reshape(n_frames, sk.n_joints, 4)
    root = np.stack([0.3 * np.sin(t), 0.96 - 0.05 * (1 - np.cos(2 * np.pi * t)), 0.2 * t], axis=1)
    return MotionClip(sk, fps, root, local_rot)


def in_blender(positions: np.ndarray) -> np.ndarray:
    """Our Y-up positions in Blender's Z-up world (both in metres)."""
    return np.stack([positions[..., 0], -positions[..., 2], positions[..., 1]], axis=-1)


@pytest.fixture(scope="module")
def blender():
    if not _blender_has_numpy():
        pytest.skip("needs blender with numpy for its glTF importer (bash scripts/setup.sh --test installs "
                    "python3-numpy)")


def read_back(path, frames, tmp_path) -> dict:
    """What Blender's FBX importer and the raw FBX records say about ``path``."""
    report_file = tmp_path / f"{path.name}.json"
    subprocess.run(["blender", "-b", "--factory-startup", "--python", str(CLIENTS / "blender_fbx_import.py"), "--",
                    str(path), str(report_file), ",".join(map(str, frames))],
                   capture_output=True, text=True, timeout=300)
    report = json.loads(report_file.read_text())
    assert report["errors"] == []
    return report


def assert_poses_match(clip: MotionClip, report: dict, tolerance_m: float) -> None:
    _, ours = clip_fk(clip)
    for f, got in report["positions"].items():
        got = np.array([got[name] for name in clip.skeleton.names])
        assert np.abs(got - in_blender(ours[int(f)])).max() < tolerance_m, f


def assert_frames_match(clip: MotionClip, report: dict) -> None:
    n = clip.n_frames
    assert report["fps"] == pytest.approx(clip.fps)
    assert report["frame_range"] == [0, n - 1]
    assert report["keys_per_curve"] == [n]         # a key on every frame, on every curve
    assert list(report["raw"]["take_seconds"].values()) == [pytest.approx((n - 1) / clip.fps)]


@pytest.fixture(scope="module")
def waving(blender, tmp_path_factory):
    """The waving clip written as FBX and read back at its first, middle and last frames."""
    clip = waving_clip()
    folder = tmp_path_factory.mktemp("fbx")
    path = fbx.write_fbx(folder / "wave.fbx", glb_bytes(clip), fps=clip.fps, name="wave")
    return clip, path, read_back(path, (0, clip.n_frames // 2, clip.n_frames - 1), folder)


@pytest.mark.blender
def test_blender_reads_our_fbx_back_with_the_mixamo_bones_every_frame_and_every_pose(waving):
    clip, path, report = waving
    assert path.read_bytes().startswith(FBX_MAGIC)
    assert report["objects"] == {"Armature": "ARMATURE"}           # only the armature: no End Site empties
    assert report["bones"] == list(clip.skeleton.names)            # mixamorig:Hips ..., no added leaf bones
    assert report["bones"][0] == "mixamorig:Hips"
    assert report["action"].endswith("wave")
    assert_frames_match(clip, report)
    assert_poses_match(clip, report, 1e-4)


@pytest.mark.blender
def test_the_raw_fbx_is_y_up_in_centimetres_with_a_plain_armature_node_and_joints_at_rest(waving):
    clip, _, report = waving
    raw = report["raw"]
    settings = raw["settings"]
    # Y up, front +Z, right-handed X: what Unity and Unreal read without turning the character.
    assert (settings["UpAxis"], settings["UpAxisSign"], settings["FrontAxis"], settings["FrontAxisSign"],
            settings["CoordAxis"], settings["CoordAxisSign"]) == (1, 1, 2, 1, 0, 1)
    assert settings["UnitScaleFactor"] == 1.0                      # centimetres, like Mixamo's files
    assert list(raw["take_seconds"]) == ["wave"]
    models = raw["models"]
    armature = models.pop("Armature")
    assert armature["type"] == "Null"
    np.testing.assert_allclose(armature["Lcl Translation"], 0, atol=1e-6)
    np.testing.assert_allclose(armature["Lcl Rotation"], 0, atol=1e-4)      # degrees
    np.testing.assert_allclose(armature["Lcl Scaling"], 1, atol=1e-6)
    sk = clip.skeleton
    assert set(models) == set(sk.names) and {m["type"] for m in models.values()} == {"LimbNode"}
    # Each joint's own transform is the rest pose: no turn, its offset from its parent, in centimetres.
    rest = np.array([clip.root_pos[0], *sk.offsets[1:]]) * CM_PER_M
    np.testing.assert_allclose([models[n]["Lcl Translation"] for n in sk.names], rest, atol=1e-3)
    np.testing.assert_allclose([models[n]["Lcl Rotation"] for n in sk.names], 0, atol=1e-3)


@pytest.mark.blender
@pytest.mark.slow
def test_a_real_dance_retargeted_onto_the_mixamo_rig_reads_back_as_we_made_it(blender, bundled_db, bundled_song,
                                                                               tmp_path):
    from dancesynth.api import dance
    from dancesynth.retarget.character import load_character
    from dancesynth.retarget.solve import retarget

    clip = retarget(dance(bundled_song, database=bundled_db, style="salsa-133-150bpm", seed=2),
                    load_character("mixamo"))
    path = tmp_path / "salsa.fbx"
    path.write_bytes(fbx.fbx_bytes(glb_bytes(clip), fps=clip.fps, name="salsa"))
    report = read_back(path, (0, clip.n_frames // 2, clip.n_frames - 1), tmp_path)
    assert report["bones"] == list(clip.skeleton.names)
    assert_frames_match(clip, report)
    assert_poses_match(clip, report, 1e-3)


@pytest.mark.blender
def test_dance_writes_fbx_for_the_mixamo_character(blender, tmp_path):
    out = tmp_path / "dance.fbx"
    proc = cli("dance", TRUMPET, "--character", "mixamo", "-o", out, "-q")
    assert proc.returncode == 0, proc.stderr
    report = read_back(out, (0,), tmp_path)
    assert report["objects"] == {"Armature": "ARMATURE"}
    assert report["bones"][0] == "mixamorig:Hips" and "mixamorig:LeftForeArm" in report["bones"]
    assert report["frame_range"][0] == 0 and report["keys_per_curve"] == [report["frame_range"][1] + 1]


# Without Blender, or with a Blender that fails: one line, and no file.

def test_without_blender_fbx_is_an_input_error_and_no_file(monkeypatch, tmp_path):
    out = tmp_path / "dance.fbx"
    glb = glb_bytes(waving_clip(5))
    monkeypatch.setenv(fbx.BLENDER_ENV, str(tmp_path / "no-such-blender"))
    with pytest.raises(InputError, match=r"needs Blender \(apt-get install blender.*no-such-blender not found; "
                                         r"write \.glb instead") as info:
        fbx.write_fbx(out, glb, fps=30.0)
    assert "\n" not in str(info.value)
    monkeypatch.delenv(fbx.BLENDER_ENV)
    monkeypatch.setenv("PATH", str(tmp_path))                       # a PATH with no blender on it
    with pytest.raises(InputError, match="blender on PATH not found"):
        fbx.fbx_bytes(glb, fps=30.0)
    assert list(tmp_path.iterdir()) == []                           # neither the file nor a partial one


def test_dance_without_blender_says_so_in_one_line_and_writes_nothing(monkeypatch, tmp_path):
    monkeypatch.setenv(fbx.BLENDER_ENV, str(tmp_path / "no-such-blender"))
    out = tmp_path / "dance.fbx"
    assert_clean_failure(cli("dance", TRUMPET, "--character", "mixamo", "-o", out, "-q"), out,
                         "needs Blender", "write .glb instead")


def fake_blender(tmp_path, monkeypatch, body: str):
    """A stand-in for Blender: a shell script, named by DANCESYNTH_BLENDER."""
    program = tmp_path / "fake-blender"
    program.write_text("#!/bin/sh\n" + body + "\n")
    program.chmod(0o755)
    monkeypatch.setenv(fbx.BLENDER_ENV, str(program))


@pytest.mark.parametrize("body, said", [
    ("echo 'Blender 3.4.1'; echo 'Error: Not freed memory blocks' >&2; exit 1", "Error: Not freed memory blocks"),
    (f"echo '{fbx.ERROR_MARK}KeyError: no armature'; echo 'Blender quit' >&2; exit 3", "KeyError: no armature"),
    ("echo 'Blender quit'; exit 0", "exit code 0"),                 # finished, but wrote nothing
])
def test_a_failing_blender_is_one_line_naming_its_error_and_leaves_no_file(tmp_path, monkeypatch, body, said):
    fake_blender(tmp_path, monkeypatch, body)
    out = tmp_path / "out" / "dance.fbx"
    out.parent.mkdir()
    with pytest.raises(InputError, match="Blender could not write the FBX") as info:
        fbx.write_fbx(out, glb_bytes(waving_clip(5)), fps=30.0)
    assert said in str(info.value) and "\n" not in str(info.value)
    assert list(out.parent.iterdir()) == []


def test_a_hanging_blender_is_stopped_at_the_time_limit(tmp_path, monkeypatch):
    fake_blender(tmp_path, monkeypatch, "exec sleep 60")
    monkeypatch.setattr(fbx, "TIMEOUT_S", 0.5)
    monkeypatch.setattr(fbx, "TIMEOUT_PER_KEY_S", 0.0)
    out = tmp_path / "out" / "dance.fbx"
    out.parent.mkdir()
    with pytest.raises(InputError, match=r"did not write the FBX within 0\.5 s"):
        fbx.write_fbx(out, glb_bytes(waving_clip(5)), fps=30.0)
    assert list(out.parent.iterdir()) == []


def test_the_time_limit_grows_with_frames_and_joints():
    assert fbx.timeout_s(0, 22) == fbx.TIMEOUT_S
    assert fbx.TIMEOUT_S + 20 < fbx.timeout_s(5400, 22) < fbx.TIMEOUT_S + 30   # 3 minutes at 30 fps, mixamo


def test_blender_gets_a_skin_over_every_joint_bound_in_the_zero_rotation_pose():
    """Blender's glTF importer makes bones only of a skin's joints; our skeleton-only .glb has none."""
    import pygltflib

    clip = waving_clip(7)
    glb, n_frames, n_joints = fbx._skinned(glb_bytes(clip), clip.fps)
    assert (n_frames, n_joints) == (7, clip.skeleton.n_joints)
    gltf = pygltflib.GLTF2.load_from_bytes(glb)
    (skin,) = gltf.skins
    assert [gltf.nodes[j].name for j in skin.joints] == list(clip.skeleton.names)   # no End Site leaves
    acc = gltf.accessors[skin.inverseBindMatrices]
    view = gltf.bufferViews[acc.bufferView]
    ibm = np.frombuffer(gltf.binary_blob(), np.float32, 16 * acc.count, view.byteOffset).reshape(-1, 4, 4)
    rest = clip_fk(MotionClip(clip.skeleton, clip.fps, clip.root_pos[:1],
                              np.tile([0.0, 0.0, 0.0, 1.0], (1, clip.skeleton.n_joints, 1))))[1][0]
    np.testing.assert_allclose(ibm[:, :3, :3], np.tile(np.eye(3), (n_joints, 1, 1)), atol=1e-6)
    np.testing.assert_allclose(ibm[:, 3, :3], -rest, atol=1e-6)    # column-major: the translation is the last row

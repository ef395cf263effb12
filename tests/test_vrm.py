"""VRM (issue 14): our dance as a VRM Animation (.vrma) and the mannequin as a VRM 1.0 avatar (.vrm).

Read back by an independent reader the .vrma holds the humanoid bones in the T-pose and moves them as
our forward kinematics does; the Khronos validator finds no error in either file; our .vrm loads back as
a character with the mannequin's bones and rest pose; and in headless Chromium, pixiv's three-vrm loads
our avatar (and a VRM 0.x one written by the tests) and three-vrm-animation plays our .vrma on it: the
rendered avatar is there and moves, and every humanoid bone is where our forward kinematics puts it.
Screenshots are kept in /tmp/vrm_shots/ to look at.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gltf_models import MANNEQUIN, MANNEQUIN_BONES, rest_positions, write_vrm0_mannequin
from test_gltf_character import CLIENTS, assert_same_rest, node_world_poses, validate
from dancesynth.errors import InputError
from dancesynth.export.vrm import vrm_bytes, vrma_bytes
from dancesynth.kinematics import clip_fk
from dancesynth.retarget.gltf_character import load_gltf_character
from dancesynth.retarget.mannequin import mannequin_character
from dancesynth.retarget.rigs import rig_skeleton
from dancesynth.rotations import IDENTITY, about_y, exp
from dancesynth.types import MotionClip

SHOTS = Path("/tmp/vrm_shots")
FPS = 30.0
FRAMES = (15, 38, 60)      # where three-vrm's pose is compared with ours (and screenshots taken)


def mannequin_dance(n_frames: int = 90) -> MotionClip:
    """Three seconds on the mannequin: arms waving, elbows and knees bending, the body turning and travelling."""
    t = np.arange(n_frames) / FPS
    rot = np.tile(IDENTITY, (n_frames, MANNEQUIN.n_joints, 1))
    wave, bend = np.sin(2 * np.pi * t), 0.5 * (1 - np.cos(2 * np.pi * t))

    def turn(bone, axis, angle):
        rot[:, MANNEQUIN_BONES[bone]] = exp(np.outer(angle, axis))

    for side, s in (("left", 1.0), ("right", -1.0)):
        turn(side + "UpperArm", [0, 0, 1], s * (0.9 * wave + 0.2))      # up and down
        turn(side + "LowerArm", [0, 1, 0], -s * 0.6 * (1 + wave))       # elbow bends forward
        turn(side + "UpperLeg", [1, 0, 0], -0.6 * bend)                 # thigh forward
        turn(side + "LowerLeg", [1, 0, 0], 1.2 * bend)                  # shin back
    turn("spine", [0, 1, 0], 0.3 * np.sin(np.pi * t))
    rot[:, 0] = about_y(0.5 * np.sin(0.5 * np.pi * t))
    root = MANNEQUIN.offsets[0] + np.stack([0.3 * np.sin(np.pi * t / 1.5), -0.1 * bend, 0.2 * t], axis=1)
    return MotionClip(MANNEQUIN, FPS, root, rot)


@pytest.fixture(scope="module")
def dance():
    return mannequin_dance()


@pytest.fixture(scope="module")
def files(dance, tmp_path_factory):
    folder = tmp_path_factory.mktemp("vrm")
    avatar, animation, avatar0 = folder / "mannequin.vrm", folder / "dance.vrma", folder / "mannequin-0x.vrm"
    avatar.write_bytes(vrm_bytes(mannequin_character()))
    animation.write_bytes(vrma_bytes(dance, MANNEQUIN_BONES))
    write_vrm0_mannequin(avatar0)
    return avatar, animation, avatar0


def test_the_vrma_holds_t_posed_humanoid_bones_and_moves_them_as_our_dance_does(dance, files):
    import pygltflib

    gltf = pygltflib.GLTF2.load_from_bytes(files[1].read_bytes())
    ext = gltf.extensions["VRMC_vrm_animation"]
    assert gltf.extensionsUsed == ["VRMC_vrm_animation"] and ext["specVersion"] == "1.0"
    table = {bone: entry["node"] for bone, entry in ext["humanoid"]["humanBones"].items()}
    assert {b: gltf.nodes[i].name for b, i in table.items()} == {b: MANNEQUIN.names[j] for b, j in
                                                                   MANNEQUIN_BONES.items()}
    assert all(nd.rotation in (None, [0, 0, 0, 1]) for nd in gltf.nodes)      # the rest pose is the T-pose
    assert np.allclose(gltf.nodes[table["hips"]].translation, MANNEQUIN.offsets[0])
    assert [len(a.channels) for a in gltf.animations] == [len(table) + 1]
    poses = node_world_poses(files[1])
    g_rot, g_pos = clip_fk(dance)
    for bone, j in MANNEQUIN_BONES.items():
        rot, pos = poses[MANNEQUIN.names[j]]
        assert np.abs(pos - g_pos[:, j]).max() < 1e-5, bone
        assert np.degrees((rot.inv() * Rotation.from_quat(g_rot[:, j])).magnitude()).max() < 0.01, bone


def test_a_vrma_folds_the_joints_between_humanoid_bones_into_their_rotations(tmp_path):
    """CMU's rig has joints that are no humanoid bone (LHipJoint, Neck1, ...): every bone still turns as it does."""
    cmu, bones = rig_skeleton("cmu")
    rng = np.random.default_rng(5)
    n = 20
    clip = MotionClip(cmu, FPS, cmu.offsets[0] + rng.normal(0, 0.05, (n, 3)),
                      exp(rng.normal(0, 0.4, (n, cmu.n_joints, 3))))
    path = tmp_path / "cmu.vrma"
    path.write_bytes(vrma_bytes(clip, bones))
    poses = node_world_poses(path)
    assert set(poses) == {cmu.names[j] for j in bones.values()}
    g_rot, g_pos = clip_fk(clip)
    for bone, j in bones.items():
        rot, pos = poses[cmu.names[j]]
        assert np.degrees((rot.inv() * Rotation.from_quat(g_rot[:, j])).magnitude()).max() < 0.01, bone
    assert np.abs(poses["Hips"][1] - g_pos[:, bones["hips"]]).max() < 1e-5


@pytest.mark.skipif(shutil.which("node") is None or not (CLIENTS / "node_modules" / "gltf-validator").is_dir(),
                    reason="needs node and the npm gltf-validator (bash scripts/setup.sh --test installs them)")
def test_the_khronos_validator_finds_no_error_in_our_vrm_or_vrma(files):
    for path in files[:2]:
        report = validate(path)
        assert report["numErrors"] == 0 and report["numWarnings"] == 0, (path.name, report["messages"][:5])


def test_our_vrm_loads_back_as_a_vrm1_character_with_the_mannequins_bones_and_rest_pose(files):
    character = load_gltf_character(files[0])
    assert character.kind == "vrm1" and character.name == "dancesynth mannequin"
    assert character.bones == MANNEQUIN_BONES
    assert_same_rest(character, MANNEQUIN)
    mannequin = mannequin_character()
    assert np.abs(rest_positions(character.skeleton, character.rest_rot, character.rest_root)
                  - rest_positions(mannequin.skeleton, mannequin.rest_rot, mannequin.rest_root)).max() < 1e-5


def test_vrm_export_refuses_a_character_without_a_mesh_or_bones_and_vrma_a_rig_without_them(dance):
    mannequin = mannequin_character()
    with pytest.raises(InputError, match="no mesh"):
        vrm_bytes(type(mannequin)(mannequin.name, mannequin.skeleton, mannequin.bones, mannequin.rest_rot,
                                  mannequin.rest_root))
    without_head = {b: j for b, j in MANNEQUIN_BONES.items() if b != "head"}
    with pytest.raises(InputError, match="head"):
        vrma_bytes(dance, without_head)


def _lit_and_changed(shots: list[Path], background) -> tuple[list[float], list[float]]:
    """Per shot, the share of pixels that are not background; per consecutive pair, the share that changed."""
    from PIL import Image

    images = [np.asarray(Image.open(p).convert("RGB"), dtype=np.int16) for p in shots]
    lit = [float((np.abs(im - background).max(axis=2) > 12).mean()) for im in images]
    changed = [float((np.abs(a - b).max(axis=2) > 12).mean()) for a, b in zip(images, images[1:])]
    return lit, changed


@pytest.mark.skipif(shutil.which("node") is None or not (CLIENTS / "node_modules" / "@pixiv" / "three-vrm").is_dir()
                    or not Path("/usr/bin/chromium").exists(),
                    reason="needs node, chromium and the npm clients (bash scripts/setup.sh --test installs them)")
def test_three_vrm_plays_our_vrma_on_our_avatars_in_chromium_with_every_bone_where_we_have_it(dance, files,
                                                                                                tmp_path):
    avatar, animation, avatar0 = files
    times = [f / FPS for f in FRAMES]
    proc = subprocess.run(["node", str(CLIENTS / "vrm_check.mjs"), str(tmp_path), str(animation),
                           ",".join(f"{t:.9g}" for t in times), f"{avatar},{avatar0}", "/usr/bin/chromium"],
                          capture_output=True, text=True, cwd=CLIENTS, timeout=240)
    report = json.loads(proc.stdout)
    assert report["ok"] and report["errors"] == [], report["errors"]
    assert [a["metaVersion"] for a in report["avatars"]] == ["1", "0"]
    assert [a["name"] for a in report["avatars"]] == ["dancesynth mannequin", "mannequin 0.x"]
    _, ours = clip_fk(dance)
    SHOTS.mkdir(exist_ok=True)
    for i, entry in enumerate(report["avatars"]):
        assert set(entry["bones"]) == set(MANNEQUIN_BONES)
        assert entry["duration"] == pytest.approx(dance.duration_s, abs=1e-4)
        for t, f in zip(times, FRAMES):
            got = entry["positions"][f"{t:.9g}"]
            error = max(np.linalg.norm(np.array(got[b]) - ours[f, j]) for b, j in MANNEQUIN_BONES.items())
            assert error < 0.003, (entry["file"], f, error)     # metres; a VRM 0.x avatar is turned round too
        shots = [tmp_path / f"{i}_{k}.png" for k in range(len(times))]
        lit, changed = _lit_and_changed(shots, np.array(report["background"]))
        assert min(lit) > 0.02, (entry["file"], lit)            # the avatar is drawn
        assert min(changed) > 0.005, (entry["file"], changed)   # and it moves
        for k, shot in enumerate(shots):
            shutil.copy(shot, SHOTS / f"{'vrm1' if i == 0 else 'vrm0'}_t{times[k]:.2f}s.png")

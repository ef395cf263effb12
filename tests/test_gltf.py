"""A dance as glTF (issue 14, first part): read back by an independent reader (pygltflib's arrays,
SciPy's rotations, a forward kinematics written here) it puts every joint where ours does, and the
Khronos validator finds nothing wrong with it."""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import REPO
from test_cli import TRUMPET, assert_clean_failure, cli
from dancesynth.export.gltf import write_glb
from dancesynth.kinematics import clip_fk

CLIENTS = REPO / "tests" / "clients"


@pytest.fixture(scope="module")
def salsa(bundled_db, bundled_song):
    from dancesynth.api import dance

    return dance(bundled_song, database=bundled_db, style="salsa-120-150bpm", seed=2)


def read_joint_positions(path) -> tuple[list[str], np.ndarray]:
    """Every node's world position at every key time, from the file alone."""
    import pygltflib

    gltf = pygltflib.GLTF2.load(str(path))
    blob = gltf.binary_blob()

    def values(index: int) -> np.ndarray:
        acc = gltf.accessors[index]
        view = gltf.bufferViews[acc.bufferView]
        width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[acc.type]
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        return np.frombuffer(blob, np.float32, acc.count * width, start).reshape(acc.count, width)

    anim = gltf.animations[0]
    times = values(anim.samplers[0].input)[:, 0]
    n, nodes = len(times), gltf.nodes
    trans = np.array([np.tile(nd.translation or [0, 0, 0], (n, 1)) for nd in nodes], dtype=np.float64)
    quats = np.array([np.tile(nd.rotation or [0, 0, 0, 1], (n, 1)) for nd in nodes], dtype=np.float64)
    for ch in anim.channels:
        data = values(anim.samplers[ch.sampler].output)
        (trans if ch.target.path == "translation" else quats)[ch.target.node] = data
    parent = {c: i for i, nd in enumerate(nodes) for c in (nd.children or [])}
    world_rot, world_pos = [None] * len(nodes), np.zeros((len(nodes), n, 3))
    for i in range(len(nodes)):  # parents come first: the exporter writes them so
        local = Rotation.from_quat(quats[i])
        if i in parent:
            p = parent[i]
            world_pos[i] = world_pos[p] + world_rot[p].apply(trans[i])
            world_rot[i] = world_rot[p] * local
        else:
            world_pos[i], world_rot[i] = trans[i], local
    return [nd.name for nd in nodes], world_pos.transpose(1, 0, 2)


def test_a_glb_read_back_puts_every_joint_where_the_dance_has_it(salsa, tmp_path):
    path = write_glb(tmp_path / "dance.glb", salsa)
    names, pos = read_joint_positions(path)
    _, ours = clip_fk(salsa)
    j = salsa.skeleton.n_joints
    assert names[:j] == list(salsa.skeleton.names)
    assert pos.shape[0] == salsa.n_frames
    assert np.max(np.abs(pos[:, :j] - ours)) < 1e-4    # metres, every joint, every frame
    assert len(names) == j + len(salsa.skeleton.end_sites)


@pytest.mark.skipif(shutil.which("node") is None or not (CLIENTS / "node_modules" / "gltf-validator").is_dir(),
                    reason="needs node and the npm gltf-validator (bash scripts/setup.sh --test installs them)")
def test_the_khronos_validator_finds_no_error_or_warning(salsa, tmp_path):
    path = write_glb(tmp_path / "dance.glb", salsa)
    out = subprocess.run(["node", str(CLIENTS / "validate_gltf.mjs"), str(path)], capture_output=True, text=True,
                         cwd=CLIENTS, timeout=120, check=True)
    issues = json.loads(out.stdout)["issues"]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"][:5]


def test_dance_writes_glb_when_asked_and_refuses_formats_it_does_not_write(tmp_path):
    out = tmp_path / "dance.glb"
    proc = cli("dance", TRUMPET, "-o", out, "-q")
    assert proc.returncode == 0, proc.stderr
    assert out.read_bytes()[:4] == b"glTF"
    names, pos = read_joint_positions(out)
    assert len(names) > 10 and np.all(np.isfinite(pos))
    bad = tmp_path / "dance.fbx"
    assert_clean_failure(cli("dance", TRUMPET, "-o", bad), bad, ".bvh", ".glb")


def _blender_has_numpy() -> bool:
    """Debian's Blender runs on the system Python, whose glTF importer needs python3-numpy."""
    if shutil.which("blender") is None:
        return False
    probe = subprocess.run(["blender", "-b", "--factory-startup", "--python-expr", "import numpy"],
                           capture_output=True, text=True, timeout=120)
    return "ModuleNotFoundError" not in probe.stdout + probe.stderr


@pytest.mark.blender
def test_blender_imports_the_glb_and_poses_every_joint_as_we_do(salsa, tmp_path):
    if not _blender_has_numpy():
        pytest.skip("needs blender with numpy for its glTF importer (bash scripts/setup.sh --test installs "
                    "python3-numpy)")
    path = write_glb(tmp_path / "dance.glb", salsa)
    frames = (0, salsa.n_frames // 2, salsa.n_frames - 1)
    report_file = tmp_path / "blender.json"
    subprocess.run(["blender", "-b", "--factory-startup", "--python", str(CLIENTS / "blender_gltf_import.py"), "--",
                    str(path), str(salsa.fps), str(report_file), ",".join(map(str, frames))],
                   capture_output=True, text=True, timeout=300)
    report = json.loads(report_file.read_text())
    assert report["errors"] == []
    assert report["actions"] > 0 and set(salsa.skeleton.names) <= set(report["objects"])
    _, ours = clip_fk(salsa)
    for f in frames:
        got = np.array([report["positions"][str(f)][n] for n in salsa.skeleton.names])
        expected = np.stack([ours[f, :, 0], -ours[f, :, 2], ours[f, :, 1]], axis=1)  # Y-up to Blender's Z-up
        assert np.abs(got - expected).max() < 1e-4, f


@pytest.mark.skipif(shutil.which("node") is None or not (CLIENTS / "node_modules" / "three").is_dir(),
                    reason="needs node and three.js (bash scripts/setup.sh --test installs them)")
def test_three_js_plays_the_glb_with_every_joint_where_we_have_it(salsa, tmp_path):
    path = write_glb(tmp_path / "dance.glb", salsa)
    frames = (0, salsa.n_frames // 2, salsa.n_frames - 1)
    out = subprocess.run(["node", str(CLIENTS / "three_gltf_import.mjs"), str(path), str(salsa.fps),
                          ",".join(map(str, frames))], capture_output=True, text=True, cwd=CLIENTS, timeout=120,
                         check=True)
    report = json.loads(out.stdout)
    assert report["errors"] == [] and report["animations"] == 1
    assert report["duration"] == pytest.approx(salsa.duration_s, abs=1e-4)
    _, ours = clip_fk(salsa)
    for f in frames:
        got = np.array([report["positions"][str(f)][n] for n in salsa.skeleton.names])
        assert np.abs(got - ours[f]).max() < 1e-4, f

"""The BVH files we write import in Blender and in three.js, and pose the same skeleton.

Needs, and skips without:
- ``blender`` on PATH (tested with Blender 3.4.1);
- ``node`` and three.js in tests/clients/node_modules. Install it with
      cd tests/clients && npm ci
  (package.json pins three exactly; package-lock.json is committed).

Each test writes a clip read from the trimmed fixtures in tests/data, imports it with the
client, and compares the world position of every joint at a few frames with our forward
kinematics.
"""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest

from conftest import REPO
from dancesynth.io.bvh import read_bvh, write_bvh
from dancesynth.kinematics import clip_fk

CLIENTS = REPO / "tests" / "clients"
FIXTURES = REPO / "tests" / "data" / "mocap"
FIXTURE_FILES = [pytest.param(p, id=f"{p.parent.name}/{p.name}") for p in sorted(FIXTURES.glob("*/*.bvh"))]
N_FRAMES = 60
SAMPLE = (0, 29, N_FRAMES - 1)
TIMEOUT_S = 120
# Both clients work in float32: joints agree to 1e-6..3e-5 m on the fixtures.
TOLERANCE_M = 1e-4

BLENDER = shutil.which("blender")
NODE = shutil.which("node")
THREE = CLIENTS / "node_modules" / "three" / "package.json"


def _written_clip(path, tmp_path):
    clip = read_bvh(path).frames(0, N_FRAMES)
    out = tmp_path / f"{path.stem}.bvh"
    write_bvh(out, clip)
    _, positions = clip_fk(clip)
    return clip, out, positions


needs_blender = pytest.mark.skipif(BLENDER is None, reason="blender is not on PATH")
needs_three = [pytest.mark.skipif(NODE is None, reason="node is not on PATH"),
               pytest.mark.skipif(not THREE.is_file(), reason="three.js not installed: run `npm ci` in tests/clients")]


@pytest.fixture(scope="module")
def dance_file(tmp_path_factory):
    """A dance made by the product from a bundled song, written as BVH."""
    from conftest import BUNDLED_MUSIC
    from dancesynth.api import dance

    clip = dance(BUNDLED_MUSIC / "sorohanro_-_solo-trumpet-06.ogg")
    out = tmp_path_factory.mktemp("dance") / "trumpet.bvh"
    write_bvh(out, clip)
    written = read_bvh(out)
    _, positions = clip_fk(written)
    return written, out, positions


@pytest.mark.blender
@needs_blender
@pytest.mark.parametrize("path", FIXTURE_FILES)
def test_blender_imports_written_bvh(path, tmp_path):
    check_blender(*_written_clip(path, tmp_path), tmp_path, SAMPLE)


@pytest.mark.blender
@needs_blender
def test_blender_imports_a_dance(dance_file, tmp_path):
    clip = dance_file[0]
    check_blender(*dance_file, tmp_path, (0, clip.n_frames // 2, clip.n_frames - 1))


def check_blender(clip, bvh_file, positions, tmp_path, sample):
    report_file = tmp_path / "blender.json"
    cmd = [BLENDER, "-b", "--factory-startup", "--python", str(CLIENTS / "blender_import.py"), "--",
           str(bvh_file), str(clip.n_frames), str(report_file), ",".join(map(str, sample))]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT_S, check=False)
    assert report_file.is_file(), f"Blender wrote no report:\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}"
    report = json.loads(report_file.read_text())
    assert report["errors"] == [], "\n".join(report["errors"])
    assert report["imported_frames"] == clip.n_frames
    assert report["frame_range"] == [1.0, float(clip.n_frames)]
    assert report["bones"] == list(clip.skeleton.names)
    # Blender's importer turns BVH's Y-up, -Z-forward world into its Z-up world:
    # (x, y, z) -> (x, -z, y); global_scale=1 keeps metres.
    for f in sample:
        got = report["head_positions"][str(f)]
        ours = positions[f]
        blender = np.array([got[name] for name in clip.skeleton.names])
        expected = np.stack([ours[:, 0], -ours[:, 2], ours[:, 1]], axis=1)
        err = np.abs(blender - expected).max()
        assert err < TOLERANCE_M, f"frame {f}: joints differ by up to {err:.2e} m"


@pytest.mark.parametrize("path", FIXTURE_FILES)
@needs_three[0]
@needs_three[1]
def test_threejs_imports_written_bvh(path, tmp_path):
    check_three(*_written_clip(path, tmp_path), SAMPLE)


@needs_three[0]
@needs_three[1]
def test_threejs_imports_a_dance(dance_file):
    clip = dance_file[0]
    check_three(*dance_file, (0, clip.n_frames // 2, clip.n_frames - 1))


def check_three(clip, bvh_file, positions, sample):
    proc = subprocess.run([NODE, str(CLIENTS / "three_import.mjs"), str(bvh_file), ",".join(map(str, sample))],
                          capture_output=True, text=True, timeout=TIMEOUT_S, check=False, cwd=CLIENTS)
    assert proc.returncode == 0, proc.stderr[-2000:]
    report = json.loads(proc.stdout)
    assert report["errors"] == [], "\n".join(report["errors"])
    sk = clip.skeleton
    # three.js makes a bone per joint and per End Site (named ENDSITE), two tracks per joint.
    assert report["bone_count"] == sk.n_joints + len(sk.end_sites)
    assert [b for b in report["bones"] if b != "ENDSITE"] == list(sk.names)
    assert report["track_count"] == 2 * sk.n_joints
    assert report["duration"] == pytest.approx(clip.duration_s, abs=1e-5)
    assert report["frame_time"] == pytest.approx(1.0 / clip.fps, abs=1e-6)
    for f in sample:
        got = report["positions"][str(f)]
        three = np.array([got[name] for name in sk.names])
        err = np.abs(three - positions[f]).max()
        assert err < TOLERANCE_M, f"frame {f}: joints differ by up to {err:.2e} m"

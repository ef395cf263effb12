"""Issue 13: a full disk is a one-line error naming the file, exit 2 and nothing left behind, for
every command that writes. The disk fills for real: each command runs in a process whose files
may not grow past a few hundred bytes (RLIMIT_FSIZE; Python then gets EFBIG, "File too large",
where a full disk gives ENOSPC), so no root and no special file system is needed."""

from __future__ import annotations

import os
import resource
import shutil
import subprocess
import sys

import pytest

from conftest import REPO, SHARED_MOCAP
from test_cli import TRUMPET, assert_clean_failure

LIMIT_BYTES = 400


@pytest.fixture(scope="module")
def dance_bvh(tmp_path_factory):
    out = tmp_path_factory.mktemp("dance") / "trumpet.bvh"
    subprocess.run([sys.executable, "-m", "dancesynth.cli", "dance", str(TRUMPET), "-o", str(out), "-q"], check=True)
    return out


@pytest.fixture(scope="module")
def two_captures(tmp_path_factory):
    folder = tmp_path_factory.mktemp("mocap") / "salsa"
    folder.mkdir()
    for bvh in sorted((SHARED_MOCAP / "cmu_daz_salsa").glob("*.bvh"))[:2]:
        shutil.copy(bvh, folder / bvh.name)
    return folder.parent


def run_on_a_full_disk(*args, numba_cache=None):
    env = dict(os.environ)
    env.setdefault("NUMBA_CACHE_DIR", str(REPO / ".cache" / "numba"))  # caches are read, not written, here
    if numba_cache is not None:
        env["NUMBA_CACHE_DIR"] = str(numba_cache)

    def small_files():
        resource.setrlimit(resource.RLIMIT_FSIZE, (LIMIT_BYTES, LIMIT_BYTES))

    return subprocess.run([sys.executable, "-m", "dancesynth.cli", *map(str, args)], capture_output=True, text=True,
                          env=env, timeout=300, preexec_fn=small_files)


@pytest.mark.parametrize("command, output", [
    (("dance", TRUMPET, "-o", "{out}"), "out.bvh"),
    (("dance", TRUMPET, "-o", "{tmp}/d.bvh", "--report", "{out}"), "report.json"),
    (("conduct", TRUMPET, "-o", "{out}"), "out.bvh"),
    (("eval", "{dance}", TRUMPET, "--json", "{out}"), "eval.json"),
    (("eval", "{dance}", TRUMPET, "--plot", "{out}"), "eval.png"),
    (("motifs", "{dance}", "--json", "{out}"), "motifs.json"),
    (("beats", TRUMPET, "--json", "{out}"), "beats.json"),
    (("render", "{dance}", TRUMPET, "-o", "{out}", "--width", "320", "--height", "240"), "video.mp4"),
    (("build-db", "{mocap}", "-o", "{out}"), "database"),
])
def test_a_full_disk_is_a_one_line_error_naming_the_file(tmp_path, dance_bvh, two_captures, command, output):
    out = tmp_path / output
    args = [str(a).format(out=out, tmp=tmp_path, dance=dance_bvh, mocap=two_captures) for a in command]
    proc = run_on_a_full_disk(*args)
    assert proc.returncode == 2, proc.stderr
    assert_clean_failure(proc, out, "cannot write", "File too large")
    assert sorted(p.name for p in tmp_path.iterdir()) == [], "a partial output was left behind"


def test_a_full_disk_under_a_librarys_cache_is_the_same_one_line_error(tmp_path, tmp_path_factory):
    """librosa's JIT cache (numba) written on a full disk was an internal error, exit 70."""
    out = tmp_path / "out.bvh"
    proc = run_on_a_full_disk("conduct", TRUMPET, "-o", out, numba_cache=tmp_path_factory.mktemp("cold-cache"))
    assert proc.returncode == 2, proc.stderr
    assert_clean_failure(proc, out, "cannot write", "File too large", "disk space")

"""Atomic output files."""

from __future__ import annotations

import os

import pytest

from dancesynth.errors import InputError
from dancesynth.io.files import atomic_output


def test_a_finished_file_has_ordinary_permissions(tmp_path):
    with atomic_output(tmp_path / "out.txt") as fh:
        fh.write("hello")
    umask = os.umask(0)
    os.umask(umask)
    assert (tmp_path / "out.txt").stat().st_mode & 0o777 == 0o666 & ~umask
    assert (tmp_path / "out.txt").read_text() == "hello"


def test_a_failure_leaves_nothing_behind(tmp_path):
    (tmp_path / "out.txt").write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_output(tmp_path / "out.txt") as fh:
            fh.write("half")
            raise RuntimeError("boom")
    assert (tmp_path / "out.txt").read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_a_missing_folder_is_a_clear_error(tmp_path):
    with pytest.raises(InputError, match="does not exist"):
        with atomic_output(tmp_path / "nope" / "out.txt"):
            pass


def test_sigterm_during_a_write_leaves_nothing_behind(tmp_path):
    """Issue 13: SIGTERM while a BVH was being written left a hidden '.part' file."""
    import signal
    import subprocess
    import sys

    script = (
        "import sys, time\n"
        "from dancesynth.io.files import stop_cleanly_on_sigterm\n"
        "from dancesynth.io.files import atomic_output\n"
        "stop_cleanly_on_sigterm()\n"
        "with atomic_output(sys.argv[1]) as fh:\n"
        "    fh.write('HIERARCHY')\n"
        "    print('writing', flush=True)\n"
        "    time.sleep(60)\n")
    proc = subprocess.Popen([sys.executable, "-c", script, str(tmp_path / "dance.bvh")], stdout=subprocess.PIPE,
                            text=True)
    try:
        assert proc.stdout.readline().strip() == "writing"
        assert len(list(tmp_path.iterdir())) == 1  # the .part file, while it is written
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=20) == 128 + signal.SIGTERM
    finally:
        proc.kill()
    assert list(tmp_path.iterdir()) == []

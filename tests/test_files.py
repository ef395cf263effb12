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

"""The MOTION rows formatted by numpy (bvh_writer.format_rows) are Python's "%.Nf" byte for byte,
and a file written block by block is the same text as format_bvh."""

from __future__ import annotations

import numpy as np
import pytest

from bvh_samples import TWO_JOINTS
from dancesynth import rotations as rot
from dancesynth.io.bvh import format_bvh, parse_bvh, write_bvh
from dancesynth.io.bvh_writer import BVHStreamWriter, bvh_parts, format_rows, row_blocks
from dancesynth.types import MotionClip

EDGES = [0.0, -0.0, 1 / 128, -1 / 128, 3 / 128, 0.5, 1.5, 2.5, -2.5, 5e-7, -5e-7, 1e-7, -1e-7, 0.0000005,
         9.9999995, 0.9999995, 99.9999996, 123456.5, 999999.9999999, 4.5e9, -1e17, 1e300, -1e-300,
         np.nextafter(0.5, 1), np.nextafter(0.5, 0), 2.0 ** 52, 2.0 ** 53 + 2]


def python_rows(values: np.ndarray, precision: int) -> str:
    row = " ".join([f"%.{precision}f"] * values.shape[1])
    return "".join(row % tuple(v) + "\n" for v in values.tolist())


@pytest.mark.parametrize("precision", [0, 1, 3, 6, 8, 9, 12, 17])
def test_rows_are_pythons_formatting_byte_for_byte(precision):
    rng = np.random.default_rng(precision)
    blocks = [rng.normal(scale=100, size=(40, 17)),
              rng.normal(scale=1e-6, size=(9, 5)),
              np.array([EDGES]),
              np.round(rng.normal(scale=100, size=(30, 8)), 7),                      # many near-ties
              (rng.integers(-10 ** 9, 10 ** 9, size=(30, 6)) + 0.5) / 10 ** 6,       # exact ties at 6
              rng.integers(-1000, 1000, size=(20, 3)) / 1024,                       # exact binary fractions
              rng.normal(scale=1e4, size=(10, 10)) ** 3,                            # wide range of widths
              np.zeros((3, 1))]
    for values in blocks:
        assert format_rows(values, precision) == python_rows(values, precision)


def test_empty_blocks():
    assert format_rows(np.zeros((0, 4))) == ""
    assert format_rows(np.zeros((2, 0))) == "\n\n"


def _clip(n_frames: int, seed: int = 0) -> MotionClip:
    sk = parse_bvh(TWO_JOINTS, to_metres=False, drop_tpose=False).skeleton
    rng = np.random.default_rng(seed)
    local = rot.exp(rng.normal(size=(n_frames, sk.n_joints, 3)))
    return MotionClip(sk, 30.0, rng.normal(size=(n_frames, 3)), local)


def test_a_file_written_block_by_block_is_format_bvh(tmp_path):
    clip = _clip(3 * 64 + 5)  # several blocks and a short last one
    write_bvh(tmp_path / "a.bvh", clip)
    assert (tmp_path / "a.bvh").read_text() == format_bvh(clip)
    hierarchy, rows = bvh_parts(clip)
    assert format_bvh(clip).endswith("\n".join(rows) + "\n")
    assert len(rows) == clip.n_frames
    assert list(row_blocks(np.zeros((130, 2)), 6, block=64)) == [format_rows(np.zeros((n, 2))) for n in (64, 64, 2)]


def test_a_growing_file_holds_the_same_rows(tmp_path):
    clip = _clip(100, seed=1)
    with BVHStreamWriter(tmp_path / "s.bvh") as writer:
        writer.append(MotionClip(clip.skeleton, clip.fps, clip.root_pos[:70], clip.local_rot[:70]))
        writer.append(MotionClip(clip.skeleton, clip.fps, clip.root_pos[70:], clip.local_rot[70:]))
    text = (tmp_path / "s.bvh").read_text()
    _, first = bvh_parts(MotionClip(clip.skeleton, clip.fps, clip.root_pos[:70], clip.local_rot[:70]))
    _, second = bvh_parts(MotionClip(clip.skeleton, clip.fps, clip.root_pos[70:], clip.local_rot[70:]))
    assert text.endswith("\n".join(first + second) + "\n")
    assert "Frames: 100 " in text

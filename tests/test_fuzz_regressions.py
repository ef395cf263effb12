"""Inputs the fuzzer (tests/fuzz, scripts/fuzz.py) found that ended in something other than our error."""

from __future__ import annotations

import io
import json
import os
import shutil

import numpy as np
import pytest

from bvh_samples import TWO_JOINTS
from dancesynth.engines.procedural.config import load_config
from dancesynth.errors import DanceSynthError, InputError
from dancesynth.io.bvh import parse_bvh
from dancesynth.motion.database import BUNDLED_DATABASE, load_database, open_database
from dancesynth.motion.sources import collect_sources


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", '"nan"', '"inf"'])
def test_conduct_config_with_a_non_finite_segment_length_is_an_input_error(tmp_path, value):
    # int(nan) and int(inf) raised ValueError / OverflowError: 'internal error' for conduct --config.
    path = tmp_path / "look.toml"
    path.write_text(f"max_segment_notes = {value}\n")
    with pytest.raises(InputError, match="max_segment_notes"):
        load_config(path)


@pytest.fixture
def saved_db(tmp_path):
    """A saved database of the smallest bundled style, to damage."""
    index = json.loads((BUNDLED_DATABASE / "database.json").read_text())
    index["styles"] = {"whirl": index["styles"]["whirl"]}
    folder = tmp_path / "db"
    folder.mkdir()
    (folder / "database.json").write_text(json.dumps(index))
    shutil.copy(BUNDLED_DATABASE / "whirl.npz", folder / "whirl.npz")
    assert load_database(folder).styles["whirl"].n_clips > 0
    return folder


def _edit_npz(folder, **changes):
    with np.load(folder / "whirl.npz") as z:
        arr = {k: z[k] for k in z.files}
    for key, fn in changes.items():
        if fn is None:
            del arr[key]
        else:
            arr[key] = fn(arr[key])
    buf = io.BytesIO()
    np.savez(buf, **arr)
    (folder / "whirl.npz").write_bytes(buf.getvalue())


def _flip_byte(path, at):
    data = bytearray(path.read_bytes())
    data[at] ^= 0xFF
    path.write_bytes(bytes(data))


def _edit_json(folder, fn):
    index = json.loads((folder / "database.json").read_text())
    fn(index)
    (folder / "database.json").write_text(json.dumps(index))


@pytest.mark.parametrize("damage", [
    lambda f: _edit_npz(f, energy=None),                                    # KeyError
    lambda f: _edit_npz(f, rot_q=lambda a: a[: len(a) // 2]),               # ValueError: shape mismatch
    lambda f: _edit_npz(f, moving=lambda a: a[:, None]),                    # IndexError
    lambda f: _edit_npz(f, beat_frames=lambda a: np.array(["x"] * len(a))),  # UFuncTypeError later
    lambda f: _edit_npz(f, energy=lambda a: np.full(a.shape, np.nan)),      # NaN accepted
    lambda f: _edit_npz(f, clip_starts=lambda a: a[:0]),                    # clips not covering the frames
    lambda f: _edit_npz(f, static_rot=lambda a: np.full(a.shape, np.nan)),  # NaN rotations accepted
    lambda f: _edit_json(f, lambda d: d.update(styles="x")),               # AttributeError
    lambda f: _edit_json(f, lambda d: d["styles"]["whirl"].update(fps=2 ** 70)),
    lambda f: _edit_json(f, lambda d: d["styles"]["whirl"]["skeleton"].update(end_sites={"x": [0]})),
    lambda f: _edit_json(f, lambda d: d["styles"]["whirl"]["skeleton"]["parents"].__setitem__(3, 99)),
    lambda f: (shutil.copy(f / "whirl.npz", f.parent / "whirl.npz"),  # read from beside the folder
               _edit_json(f, lambda d: d.update(styles={"../whirl": d["styles"]["whirl"]}))),
    lambda f: _edit_json(f, lambda d: d.update(styles={})),                 # a database with no styles
    lambda f: _flip_byte(f / "whirl.npz", 33904),                           # zlib.error: a broken deflate stream
])
def test_a_damaged_saved_database_is_our_error(saved_db, damage):
    damage(saved_db)
    with pytest.raises(DanceSynthError, match="rebuild the database"):
        open_database(saved_db)


def test_a_database_folder_that_cannot_be_listed_is_an_input_error(tmp_path):
    # Paths past PATH_MAX (4096) cannot be listed: os.scandir fails with ENAMETOOLONG, as /proc's vanishing
    # entries made 'dancesynth styles --database /proc' fail with FileNotFoundError (an internal error).
    here = os.getcwd()
    os.chdir(tmp_path)
    try:
        for _ in range(18):
            os.mkdir("d" * 250)
            os.chdir("d" * 250)
    finally:
        os.chdir(here)
    with pytest.raises(InputError, match="cannot list the files"):
        collect_sources(tmp_path)


def test_a_bvh_hierarchy_of_megabytes_is_refused_before_it_is_tokenised():
    # 15 MB of HIERARCHY took 3 s to tokenise before the joint limit was even checked.
    text = TWO_JOINTS.replace("JOINT Spine", "JOINT " + "S" * 3_000_000)
    with pytest.raises(InputError, match="HIERARCHY section is 3.0 MB"):
        parse_bvh(text)


def test_float_samples_that_overflow_the_resampler_are_an_input_error(tmp_path):
    # A float WAV of samples near the float32 maximum is finite as read but became inf when resampled,
    # and load_audio returned it (the check stood before the resampling).
    import soundfile as sf

    from dancesynth.io.audio import load_audio

    path = tmp_path / "loud.wav"
    y = np.where(np.arange(5 * 8000) % 2 == 0, 3e38, -3e38).astype(np.float32)
    sf.write(path, y, 8000, subtype="FLOAT")
    with pytest.raises(InputError, match="absurdly large"):
        load_audio(path, sr=22050)

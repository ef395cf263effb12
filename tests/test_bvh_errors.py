"""Every malformed BVH file gets a clear, one-line error naming the file and line."""

from __future__ import annotations

import re
import warnings

import pytest

from bvh_samples import TWO_JOINTS
from dancesynth.errors import InputError
from dancesynth.io.bvh import format_bvh, parse_bvh, read_bvh

# ----------------------------------------------------------------------------- errors


def _write(tmp_path, text, name="bad.bvh"):
    p = tmp_path / name
    p.write_bytes(text.encode() if isinstance(text, str) else text)
    return p


def _error(tmp_path, text) -> str:
    p = _write(tmp_path, text)
    with pytest.raises(InputError) as info:
        read_bvh(p)
    msg = str(info.value)
    assert str(p) in msg
    return msg


def test_error_missing_file(tmp_path):
    with pytest.raises(InputError, match="no such BVH file"):
        read_bvh(tmp_path / "nope.bvh")
    with pytest.raises(InputError, match="folder"):
        read_bvh(tmp_path)


@pytest.mark.parametrize("text, expected", [
    ("", "empty"),
    ("  \n\n\t\n", "empty"),
    (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", "binary"),
    ("Hello, this is a text file\nnot motion capture\n", "not a BVH file: expected HIERARCHY"),
    (TWO_JOINTS.replace("HIERARCHY\n", ""), "line 1: not a BVH file: expected HIERARCHY, found 'ROOT'"),
    (TWO_JOINTS.replace("ROOT Hips", "JOINT Hips"), "line 2: expected ROOT"),
    (TWO_JOINTS.replace("    }\n  }\n}\nMOTION", "    }\n  }\nMOTION"), "unbalanced braces"),
    (TWO_JOINTS.replace("  }\n}\nMOTION", "  }\n}\n}\nMOTION"), "line 16: unbalanced braces: '}' closes nothing"),
    (TWO_JOINTS.replace("CHANNELS 3 Y", "CHANNELS 4 Y"), "line 9: CHANNELS says 4 channels but lists 3"),
    (TWO_JOINTS.replace("CHANNELS 6 Xposition Yposition", "CHANNELS 6 Xposition Wposition"),
     "line 5: unknown channel 'Wposition'"),
    (TWO_JOINTS.replace("JOINT Spine", "JOINT Hips"), "line 6: duplicate joint name 'Hips'"),
    (TWO_JOINTS.replace("OFFSET 0.0 10.0 0.0", "OFFSET 0.0 ten 0.0"), "line 8: expected a number"),
    (TWO_JOINTS.split("MOTION")[0], "no MOTION section"),
    (TWO_JOINTS.replace("Frames: 2", "Frames: 3"), "truncated"),
    (TWO_JOINTS[:-12] + "\n", "truncated"),
    (TWO_JOINTS + "0 0 0 0 0 0 0 0 0\n", "line 21: extra values"),
    (TWO_JOINTS.replace("0 0 0 10 20 30 40 50 60", "0 0 0 10 20 30 40 50"),
     "line 19: 8 values on a frame line, but the HIERARCHY declares 9 channels"),
    (TWO_JOINTS.replace("0 0 0 10 20 30 40 50 60", "0 0 0 10 20 30 40 50 60 70"), "line 19: 10 values"),
    (TWO_JOINTS.replace("-40 -50", "-40 abc"), "line 20: 'abc' is not a number"),
    (TWO_JOINTS.replace("-40 -50", "-40 nan"), "line 20: value nan .* not finite"),
    (TWO_JOINTS.replace("-40 -50", "-40 inf"), "line 20: value inf .* not finite"),
    (TWO_JOINTS.replace("Frames: 2", "Frames: 0"), "line 17: 'Frames: 0'"),
    (TWO_JOINTS.replace("Frames: 2", "Frames: -4"), "line 17: 'Frames: -4'"),
    (TWO_JOINTS.replace("Frames: 2", "Frames: two"), "line 17: 'Frames:' needs a whole number"),
    (TWO_JOINTS.replace("Frame Time: 0.04", "Frame Time: 0"), "line 18: Frame Time 0 must be a number of seconds"),
    # Issue 13: 10^300 fps once read, then was written back in a form the reader refused.
    (TWO_JOINTS.replace("Frame Time: 0.04", "Frame Time: 1e-300"), "line 18: Frame Time 1e-300 .*[(]1-1000 fps"),
    (TWO_JOINTS.replace("Frame Time: 0.04", "Frame Time: 5"), "line 18: Frame Time 5 .*[(]1-1000 fps"),
    # ... and a root offset of 1e308 made every position infinite.
    (TWO_JOINTS.replace("OFFSET 1.0 2.0 3.0", "OFFSET 1e308 2.0 3.0"), "line 4: OFFSET x is 1e308; .* within"),
    (TWO_JOINTS.replace("-40 -50", "-40 1e300"), "line 20: value 1e.300 .* beyond"),
    (TWO_JOINTS.replace("Frame Time: 0.04", "Frame Time: -0.04"), "line 18: Frame Time -0.04 must be"),
    (TWO_JOINTS.replace("Frame Time: 0.04\n", ""), "line 18: expected 'Frame Time: seconds'"),
    (TWO_JOINTS.replace("Frames: 2\n", ""), "line 17: expected 'Frames: N'"),
])
def test_errors(tmp_path, text, expected):
    msg = _error(tmp_path, text)
    assert re.search(expected, msg), msg


def test_error_messages_say_what_to_do(tmp_path):
    msg = _error(tmp_path, TWO_JOINTS.replace("Frames: 2", "Frames: 3"))
    assert "re-export" in msg or "correct the Frames count" in msg
    msg = _error(tmp_path, TWO_JOINTS.replace("JOINT Spine", "JOINT Hips"))
    assert "rename" in msg


def test_parse_bvh_names_the_source_in_errors():
    with pytest.raises(InputError, match="^my-upload: "):
        parse_bvh("HIERARCHY\n", name="my-upload")


def test_gimbal_warning_not_leaked():
    clip = parse_bvh(TWO_JOINTS.replace("10 20 30 40", "10 90 30 40"), to_metres=False, drop_tpose=False)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        format_bvh(clip)


def _chain(n: int) -> str:
    """A BVH of one chain of ``n`` joints, two frames."""
    lines = ["HIERARCHY", "ROOT j0", "{", "OFFSET 0 0 0",
             "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"]
    for i in range(1, n):
        lines += [f"JOINT j{i}", "{", "OFFSET 0 1 0", "CHANNELS 3 Zrotation Xrotation Yrotation"]
    lines += ["End Site", "{", "OFFSET 0 1 0", "}"] + ["}"] * n
    row = " ".join(["0"] * (6 + 3 * (n - 1)))
    return "\n".join(lines + ["MOTION", "Frames: 2", "Frame Time: 0.033333", row, row]) + "\n"


def test_deep_skeletons_up_to_the_limit_read_and_write_back_and_deeper_ones_are_refused():
    """Issue 13: a 1,000-joint chain read but could not be written (recursion); 20,000 took 11 s."""
    from dancesynth.io.bvh import MAX_JOINTS

    clip = parse_bvh(_chain(MAX_JOINTS))
    assert parse_bvh(format_bvh(clip)).skeleton.n_joints == MAX_JOINTS
    with pytest.raises(InputError, match=f"more than {MAX_JOINTS} joints"):
        parse_bvh(_chain(MAX_JOINTS + 1))

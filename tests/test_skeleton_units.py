"""Guessing a BVH skeleton's length unit, and dropping converter T-pose frames."""

from __future__ import annotations


import numpy as np
import pytest

from bvh_samples import TWO_JOINTS
from dancesynth import rotations as rot
from dancesynth.errors import InputError
from dancesynth.io import bvh
from dancesynth.io.bvh import detect_units, parse_bvh, standing_height
from dancesynth.types import MotionClip, Skeleton

# ----------------------------------------------------------------------------- units


def _human(scale: float) -> Skeleton:
    """A stick figure standing 1.53 m (the salsa skeleton's rest height) times ``scale``."""
    names = ("hips", "spine", "head", "lleg", "lshin", "rleg", "rshin")
    parents = [-1, 0, 1, 0, 3, 0, 5]
    offsets = np.array([[0, 0, 0], [0, 0.3, 0], [0, 0.3, 0], [0.1, 0, 0], [0, -0.8, 0], [-0.1, 0, 0],
                        [0, -0.8, 0]]) * scale
    ends = {2: np.array([0, 0.13, 0]) * scale, 4: np.array([0, 0, 0.1]) * scale,
            6: np.array([0, 0, 0.1]) * scale}
    return Skeleton(names, parents, offsets, (("Xposition", "Yposition", "Zposition", "Zrotation",
                                               "Xrotation", "Yrotation"),) + (("Zrotation", "Xrotation",
                                                                               "Yrotation"),) * 6, ends)


@pytest.mark.parametrize("unit", ["m", "cm", "mm", "in", "asf", "daz128"])
def test_detect_units(unit):
    sk = _human(1.0 / bvh.UNITS[unit])
    assert standing_height(sk) * bvh.UNITS[unit] == pytest.approx(1.53, rel=1e-6)
    assert detect_units(sk) == (unit, bvh.UNITS[unit])


def test_detect_units_prefers_metres_for_small_dancers():
    # A 1.3 m skeleton in metres is closer to 1.7 m as Daz/128 (1.66 m), but we write
    # metres, so a plausible human height in metres stays metres.
    assert detect_units(_human(1.3 / 1.53))[0] == "m"
    assert detect_units(_human(1.0), height=1.2) == ("daz128", 1.28)


def test_units_override_and_file_units():
    text = TWO_JOINTS
    assert parse_bvh(text, units="cm").meta["source_units"] == "cm"
    clip = parse_bvh(text, units="cm", drop_tpose=False)
    assert np.allclose(clip.root_pos[1], [0.02, 0.04, 0.06]) and np.allclose(clip.skeleton.offsets[1], [0, 0.1, 0])
    clip = parse_bvh(text, units=0.5, drop_tpose=False)
    assert clip.meta["source_units"] == "0.5 m" and clip.meta["metres_per_unit"] == 0.5
    assert parse_bvh(text, units=0.0254).meta["source_units"] == "in"
    raw = parse_bvh(text, to_metres=False, units="asf", drop_tpose=False)
    assert raw.meta["source_units"] == "asf" and raw.meta["in_metres"] is False
    assert np.array_equal(raw.root_pos[1], [2, 4, 6])
    for bad in ("furlong", -1.0, float("nan"), True):
        with pytest.raises(InputError, match="units"):
            parse_bvh(text, units=bad)


def test_standing_height_of_rig_that_does_not_stand_in_rest_pose():
    # Legs along +Y in the rest pose (Character Creator style): the rest extent is wrong,
    # the animated pose (legs rotated down by 180 degrees) is right.
    names = ("hips", "spine", "leg", "shin")
    sk = Skeleton(names, [-1, 0, 0, 2], [[0, 0, 0], [0, 70, 0], [10, 0, 0], [0, 90, 0]],
                  (("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"),)
                  + (("Zrotation", "Xrotation", "Yrotation"),) * 3, {1: np.array([0, 20, 0]),
                                                                     3: np.array([0, 10, 0])})
    rot_ = np.tile(rot.IDENTITY, (5, 4, 1))
    rot_[:, 2] = rot.from_euler([180, 0, 0], "ZXY")
    clip = MotionClip(sk, 30.0, np.tile([0, 100, 0], (5, 1)), rot_)
    assert standing_height(sk, clip) == pytest.approx(190.0)
    assert detect_units(sk, clip=clip)[0] == "cm"


# ----------------------------------------------------------------------------- T-pose


def _tpose_clip(first_frame: str) -> str:
    """A one-joint-chain file whose frames 1.. move smoothly and frame 0 is ``first_frame``."""
    rows = [first_frame] + [f"0 0 0 0 0 0 {30 + i} {20 - i * 0.5} {10 + i * 0.3}" for i in range(30)]
    return TWO_JOINTS.replace("Frames: 2", f"Frames: {len(rows)}").split("Frame Time: 0.04\n")[0] + \
        "Frame Time: 0.04\n" + "\n".join(rows) + "\n"


def test_tpose_frame_dropped():
    text = _tpose_clip("0 0 0 0 0 0 0 0 0")
    clip = parse_bvh(text, to_metres=False)
    assert clip.meta["dropped_tpose"] is True and clip.n_frames == 30
    assert np.allclose(clip.local_rot[0, 1], rot.from_euler([30, 20, 10], "YXZ"))
    kept = parse_bvh(text, to_metres=False, drop_tpose=False)
    assert kept.meta["dropped_tpose"] is False and kept.n_frames == 31


def test_tpose_not_dropped_without_jump_or_when_not_rest():
    # Frame 0 continues the motion: no jump.
    assert not parse_bvh(_tpose_clip("0 0 0 0 0 0 29 20.5 9.7"), to_metres=False).meta["dropped_tpose"]
    # Frame 0 jumps but is not the rest pose (a glitch, not a T-pose).
    assert not parse_bvh(_tpose_clip("0 0 0 0 0 0 -60 80 0"), to_metres=False).meta["dropped_tpose"]
    # Easing out of the rest pose over several frames (the CMU salsa files) is motion.
    rows = ["0 0 0 0 0 0 0 0 0"] + [f"0 0 0 0 0 0 {30 * min(i, 4) / 4 + i} 0 0" for i in range(1, 30)]
    text = TWO_JOINTS.replace("Frames: 2", "Frames: 30").split("Frame Time: 0.04\n")[0] + \
        "Frame Time: 0.04\n" + "\n".join(rows) + "\n"
    assert not parse_bvh(text, to_metres=False).meta["dropped_tpose"]

"""Rigs the way a user's tools write them, for the retargeting tests and benchmark (issue 14)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dancesynth import rotations as rot
from dancesynth.io.bvh import format_bvh
from dancesynth.retarget.rigs import rig_skeleton
from dancesynth.types import MotionClip, Skeleton


def apose_mixamo_bvh(folder: Path, scale: float = 100.0) -> Path:
    """A Mixamo-named BVH in centimetres resting in an A-pose (arms 40 degrees down), legs 10 % longer
    and arms 10 % shorter than our body; its one frame stands on the floor."""
    sk, bones = rig_skeleton("mixamo")
    offsets = sk.offsets.copy()
    ends = dict(sk.end_sites)
    for side, sign in (("left", 1.0), ("right", -1.0)):
        down = rot.exp(np.array([0.0, 0.0, -sign * np.radians(40.0)]))
        for part in ("LowerArm", "Hand"):
            offsets[bones[side + part]] = rot.apply(down, offsets[bones[side + part]]) * 0.9
        ends[bones[side + "Hand"]] = rot.apply(down, ends[bones[side + "Hand"]]) * 0.9
        for part in ("LowerLeg", "Foot"):
            offsets[bones[side + part]] *= 1.1
    shin_and_thigh = sk.offsets[bones["leftLowerLeg"]][1] + sk.offsets[bones["leftFoot"]][1]
    offsets[0, 1] -= 0.1 * shin_and_thigh            # the longer legs lift the hips (offsets point down)
    rig = Skeleton(sk.names, sk.parents, offsets * scale, sk.channels, {j: o * scale for j, o in ends.items()})
    path = Path(folder) / "my_rig.bvh"
    path.write_text(format_bvh(MotionClip(rig, 30.0, offsets[:1] * scale, np.tile(rot.IDENTITY, (1, sk.n_joints, 1)))))
    return path


def blender_style_bvh(folder: Path, scale: float = 100.0) -> Path:
    """A Mixamo-named T-pose rig in centimetres as Blender, Mixamo and MotionBuilder write it: the root's
    OFFSET is its rest position (the hips 0.9 m up) and its position channels hold the absolute position
    (the same 90 cm), not an addition to it; its one frame stands on the floor."""
    sk, _ = rig_skeleton("mixamo")
    rig = sk.scaled(scale)
    text = format_bvh(MotionClip(rig, 30.0, sk.offsets[:1] * scale, np.tile(rot.IDENTITY, (1, sk.n_joints, 1))))
    hips = sk.offsets[0] * scale
    lines = text.splitlines()
    at = next(i for i, line in enumerate(lines) if line.strip().startswith("OFFSET"))   # the root's
    lines[at] = lines[at].split("OFFSET")[0] + f"OFFSET {hips[0]:.6f} {hips[1]:.6f} {hips[2]:.6f}"
    path = Path(folder) / "blender_rig.bvh"
    path.write_text("\n".join(lines) + "\n")
    return path

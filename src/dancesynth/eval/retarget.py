"""How faithful a retargeted dance is to its source: pure functions of the two motions.

- Bone directions: the angle between each bone segment both rigs have (upper arm, shin,
  spine, ...) in the source and in the target, every frame; median and 95th percentile.
- Foot skating: the ankles' mean horizontal speed over the frames the source's foot is
  planted, per leg length (so a smaller character that slides proportionally less is not
  credited for its size), source and target.
- Ground penetration: how far an ankle or toe goes below the height it has when standing
  (the source's measured on its own floor), metres.
- Root height: the upper legs' mid-point height over the floor, per leg length (median).
"""

from __future__ import annotations

import numpy as np

from ..kinematics import clip_fk
from ..retarget.humanoid import SIDES, leg_length, segment_ends

MIN_SEGMENT_M = 0.01      # shorter segments have no direction
PLANTED_HEIGHT_M = 0.03   # an ankle within this of its standing height ...
PLANTED_SPEED = 0.6       # ... moving slower than this many leg lengths per second is planted


def retarget_quality(source, target, source_bones: dict[str, int], target_bones: dict[str, int]) -> dict:
    """Metrics of ``target`` (a MotionClip) as a retargeting of ``source``; see the module docstring."""
    _, ps = clip_fk(source)
    _, pt = clip_fk(target)
    angles = []
    for bone, end in segment_ends(source_bones, target_bones).items():
        if bone == "hips":       # the hips turn with the body frame, not by a segment of their own
            continue
        a = ps[:, source_bones[end]] - ps[:, source_bones[bone]]
        b = pt[:, target_bones[end]] - pt[:, target_bones[bone]]
        if min(np.median(np.linalg.norm(a, axis=-1)), np.median(np.linalg.norm(b, axis=-1))) < MIN_SEGMENT_M:
            continue   # a joint sitting on its parent (CMU's lowerneck) has no direction to compare
        cos = np.sum(a * b, -1) / np.maximum(np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1), 1e-12)
        angles.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    angles = np.concatenate(angles)
    leg_s, leg_t = _leg(source, source_bones), _leg(target, target_bones)
    planted = _planted(ps, source_bones, leg_s, source.fps)
    return {
        "bone_direction_median_deg": float(np.median(angles)),
        "bone_direction_p95_deg": float(np.percentile(angles, 95)),
        "skate_source": _skate(ps, source_bones, planted, leg_s, source.fps),
        "skate_target": _skate(pt, target_bones, planted, leg_t, target.fps),
        "penetration_source_m": _penetration(ps, source_bones),
        "penetration_target_m": _penetration(pt, target_bones),
        "root_height_source": _root_height(ps, source_bones, leg_s),
        "root_height_target": _root_height(pt, target_bones, leg_t),
        "planted_fraction": float(planted.mean()),
    }


def _leg(clip, bones) -> float:
    from ..kinematics import fk
    from ..rotations import IDENTITY

    sk = clip.skeleton
    _, rest = fk(np.tile(IDENTITY, (sk.n_joints, 1)), np.zeros(3), sk.offsets, sk.parents)
    return leg_length(rest, bones)


def _ankles(p, bones) -> np.ndarray:
    return p[:, [bones[s + "Foot"] for s in SIDES]]          # (F, 2, 3)


def _standing(heights: np.ndarray) -> np.ndarray:
    """Each ankle's (or toe's) height when standing: a low percentile of its heights."""
    return np.percentile(heights, 1.0, axis=0)


def _planted(p, bones, leg: float, fps: float) -> np.ndarray:
    """(F-1, 2): frames where the source's ankle is near its standing height and nearly still."""
    ankles = _ankles(p, bones)
    near = ankles[:, :, 1] - _standing(ankles[:, :, 1]) < PLANTED_HEIGHT_M
    speed = np.linalg.norm(np.diff(ankles[:, :, [0, 2]], axis=0), axis=-1) * fps / leg
    return near[1:] & near[:-1] & (speed < PLANTED_SPEED)


def _skate(p, bones, planted, leg: float, fps: float) -> float:
    speed = np.linalg.norm(np.diff(_ankles(p, bones)[:, :, [0, 2]], axis=0), axis=-1) * fps / leg
    return float(speed[planted].mean()) if planted.any() else 0.0


def _penetration(p, bones) -> float:
    """Deepest dip of an ankle or toe below its standing height, the floor being where the lower
    ankle stands (metres)."""
    ankles = _ankles(p, bones)[:, :, 1]
    floor = np.percentile(ankles.min(axis=1), 1.0)
    depth = [floor - ankles.min(axis=1)]
    for s in SIDES:
        toe = bones.get(s + "Toes")
        if toe is not None:
            # a toe's standing height relative to its ankle's, taken from the frames where the foot is flattest
            rel = p[:, toe, 1] - p[:, bones[s + "Foot"], 1]
            depth.append(floor + np.percentile(rel, 1.0) - p[:, toe, 1])
    return float(max(0.0, max(float(d.max()) for d in depth)))


def _root_height(p, bones, leg: float) -> float:
    mid = p[:, [bones[s + "UpperLeg"] for s in SIDES], 1].mean(axis=1)
    floor = np.percentile(_ankles(p, bones)[:, :, 1].min(axis=1), 1.0)
    return float(np.median(mid - floor) / leg)

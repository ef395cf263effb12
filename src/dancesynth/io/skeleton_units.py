"""Guess the length unit of a BVH skeleton, and spot the T-pose frame converters add.

``detect_units`` measures the standing height of the rest pose (or, for skeletons whose
rest pose does not stand, of the motion) and picks the known unit system that makes it
human-sized; ``is_tpose_first_frame`` recognises a first frame in the rest pose that the
motion then leaves abruptly.
"""

from __future__ import annotations

import math

import numpy as np

from .. import kinematics
from .. import rotations as rot
from ..errors import InputError
from ..types import MotionClip, Skeleton

#: Known unit systems of BVH files, as metres per file unit. "asf" is CMU's ASF length
#: unit; "daz128" that of the rescaled CMU salsa files (the Daz-friendly release is in
#: centimetres, divided by 128 there: 1 unit = 1.28 m).
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "asf": 0.056444, "daz128": 1.28}
#: Unit names also accepted by ``units=``.
_UNIT_ALIASES = {"metres": "m", "meters": "m", "metre": "m", "meter": "m", "centimetres": "cm",
                 "centimeters": "cm", "millimetres": "mm", "millimeters": "mm", "inches": "in",
                 "inch": "in", "daz/128": "daz128"}
#: Standing height (m) that ``detect_units`` aims for.
TYPICAL_HEIGHT_M = 1.7

# T-pose detection (see is_tpose_first_frame): frame 0 within this many degrees of the
# rest pose at every joint, and its step to frame 1 this many times the median step
# and the next step.
_TPOSE_REST_DEG = 20.0
_TPOSE_JUMP_RATIO = 8.0
_TPOSE_ISOLATED_RATIO = 4.0
# Units: a rest pose "stands" when its lowest point is this far below the root and
# its highest this far above (fractions of the vertical extent).
_UPRIGHT_BELOW, _UPRIGHT_ABOVE = 0.25, 0.2
_VERTICAL_BONE = 0.8  # cosine to the vertical above which a bone counts at full length
# Standing heights (file units) read as metres without further ado; see detect_units.
_METRES_PLAUSIBLE = (1.25, 2.5)


def resolve_units(units, name: str) -> tuple[str, float]:
    if isinstance(units, (int, float)) and not isinstance(units, bool):
        if not (math.isfinite(units) and units > 0):
            raise InputError(f"{name}: units={units!r}; give metres per file unit as a positive number")
        for key, value in UNITS.items():
            if math.isclose(value, units, rel_tol=1e-9):
                return key, value
        return f"{float(units):g} m", float(units)
    if isinstance(units, str):
        key = _UNIT_ALIASES.get(units.strip().lower(), units.strip().lower())
        if key in UNITS:
            return key, UNITS[key]
    raise InputError(f"{name}: unknown units {units!r}; use one of {', '.join(UNITS)} or metres per unit as a number")


# --------------------------------------------------------------------------- units


def _rest_positions(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """Rest-pose world positions of the joints (J, 3) and of the End Sites (E, 3)."""
    n = skeleton.n_joints
    pos = np.zeros((n, 3))
    for j in range(1, n):
        pos[j] = pos[skeleton.parents[j]] + skeleton.offsets[j]
    ends = np.array([pos[j] + o for j, o in skeleton.end_sites.items()]).reshape(-1, 3)
    return pos, ends


def _straight_drop(skeleton: Skeleton, pos: np.ndarray, leaf_pos: np.ndarray, leaf_parent: int, sign: float) -> float:
    """Vertical distance from the root to a point, with nearly vertical bones counted at full length.

    CMU's ASF rest pose splays the legs about 20 degrees; counting such bones at
    their length measures the standing leg instead of the splayed one.
    """
    total = 0.0
    child_pos, j = leaf_pos, leaf_parent
    while j >= 0:
        bone = child_pos - pos[j]
        length = float(np.linalg.norm(bone))
        rise = sign * bone[1]
        total += length if rise >= _VERTICAL_BONE * length else rise
        child_pos, j = pos[j], int(skeleton.parents[j])
    return total


def standing_height(skeleton: Skeleton, clip: MotionClip | None = None) -> float:
    """Standing height of a skeleton in its own length unit.

    From the rest pose: the head-to-feet vertical extent of all joints and End
    Sites, measured along the chains from the root to the lowest and to the highest
    point (see ``_straight_drop``). Some rigs do not stand upright in their rest
    pose (Character Creator exports keep every bone along its local Y axis, so the
    legs point up); for those, when ``clip`` is given, the median vertical extent of
    the animated pose over a sample of frames is used instead.
    """
    pos, ends = _rest_positions(skeleton)
    pts = np.vstack([pos, ends])
    # The chain above a joint starts at its parent; above an End Site, at its own joint.
    point_parent = [int(p) for p in skeleton.parents] + list(skeleton.end_sites)
    low, high = int(np.argmin(pts[:, 1])), int(np.argmax(pts[:, 1]))
    extent = float(pts[high, 1] - pts[low, 1])
    upright = extent > 0 and -pts[low, 1] >= _UPRIGHT_BELOW * extent and pts[high, 1] >= _UPRIGHT_ABOVE * extent
    if upright:
        return (_straight_drop(skeleton, pos, pts[low], point_parent[low], -1.0)
                + _straight_drop(skeleton, pos, pts[high], point_parent[high], 1.0))
    if clip is None or clip.n_frames == 0:
        return extent
    frames = np.unique(np.linspace(0, clip.n_frames - 1, min(clip.n_frames, 32)).astype(int))
    local_pos = None if clip.local_pos is None else clip.local_pos[frames]
    g_rot, g_pos = kinematics.fk(clip.local_rot[frames], clip.root_pos[frames], skeleton.offsets,
                                 skeleton.parents, local_pos)
    y = g_pos[..., 1]
    if skeleton.end_sites:
        js = list(skeleton.end_sites)
        end_off = np.array([skeleton.end_sites[j] for j in js])
        y = np.concatenate([y, g_pos[:, js, 1] + rot.apply(g_rot[:, js], end_off)[..., 1]], axis=1)
    return float(np.median(y.max(axis=1) - y.min(axis=1)))


def detect_units(skeleton: Skeleton, *, clip: MotionClip | None = None,
                 height: float | None = None) -> tuple[str, float]:
    """Guess the length unit of ``skeleton`` as ``(name, metres_per_unit)``, a key and value of ``UNITS``.

    The unit is the one that makes ``standing_height`` closest to 1.7 m in log
    ratio, with one exception: metres win whenever they give a plausible human
    (1.25 to 2.5 m). Metres is what dancesynth writes, and the Daz/128 unit of the
    salsa files (1.28 m) is otherwise too close to metres for small dancers: CMU
    subject 94 (1.33 m in its rest pose) would be read back 1.28 times too big.
    The salsa skeleton itself measures 1.20 units (up to the eyes), below that
    window, so it is still found. ``units=`` in ``read_bvh`` overrides any guess;
    ``height`` (in file units) here skips the estimate.
    """
    h = standing_height(skeleton, clip) if height is None else float(height)
    if not (math.isfinite(h) and h > 0):
        return "m", 1.0
    if _METRES_PLAUSIBLE[0] <= h <= _METRES_PLAUSIBLE[1]:
        return "m", 1.0
    return min(UNITS.items(), key=lambda kv: abs(math.log(h * kv[1] / TYPICAL_HEIGHT_M)))


# --------------------------------------------------------------------------- T-pose


def is_tpose_first_frame(clip: MotionClip) -> bool:
    """Whether frame 0 is a converter's T-pose rather than motion.

    Two signs, both needed: every non-root joint of frame 0 is within 20 degrees of
    the rest pose, and the pose jumps from frame 0 to frame 1 far more than between
    later frames (at least 8x the median step and 4x the next step). The second
    test tells a lone T-pose frame from a clip that eases out of the rest pose over
    several frames, such as the CMU salsa files.
    """
    if clip.n_frames < 3 or clip.skeleton.n_joints < 2:
        return False
    q = clip.local_rot[:, 1:]
    if np.degrees(rot.angle(q[0], rot.IDENTITY)).max() > _TPOSE_REST_DEG:
        return False
    step = rot.angle(q[1:], q[:-1]).mean(axis=1)
    first, typical = step[0], float(np.median(step[1:]))
    return bool(first > _TPOSE_JUMP_RATIO * typical and first > _TPOSE_ISOLATED_RATIO * step[1])

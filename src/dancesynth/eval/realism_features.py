"""The AIST++ motion features behind FID_k / FID_g: kinetic and geometric, and the SMPL joint map.

Li et al. 2021 (*AI Choreographer*, AIST++) define the features that ``eval.realism``
turns into FID and diversity; here they are computed on our BVH skeletons:

- **kinetic features** (``kinetic_features``): per joint the average horizontal and
  vertical kinetic energy (mean squared velocity, m²/s², no mass) and the average
  energy expenditure (mean acceleration magnitude, m/s²), velocities and accelerations
  averaged over ±2 frames at 60 fps as in the AIST++ API (``features/kinetic.py``).
  3 numbers per mapped joint, 72 for all 24 SMPL joints.
- **geometric features** (``geometric_features``): the fraction of frames in which each
  of the 32 boolean relations of the AIST++ API (``features/manual.py``, after Müller
  et al. 2005) holds: a hand in front of the body, a foot raised, a knee bent, ...
  (``GEOMETRIC_FEATURES`` lists them). Thresholds are in units of the skeleton's own
  humerus length, shoulder width and hip width, as Müller defines them.

Where we knowingly differ from the AIST++ code (see docs/metrics.md): the energy
expenditure uses the second difference of positions (the API's formula divides only
one term by the frame time, which makes it a position feature); speeds are in true
m/s (the API's geometric features divide one-frame displacements at 60 fps by 1/120 s);
the relations are Müller's generic ones on the API's joints and thresholds (the API's
``f_move`` ignores its fourth joint, its plane normals point the other way, and some
left/right pairs are mirrored inconsistently), so each relation means what its name
says.

Joints: each skeleton is mapped onto the SMPL joints that ``motion.roles`` and the
hierarchy reveal (``smpl_joint_map``); joints a skeleton lacks are left out, so two
motions of one skeleton always have features of one length.

The private helpers ``_joint_positions``, ``_kinetic``, ``_geometric_layout`` and
``_relations`` work on positions already at 60 fps, so ``eval.realism`` can cut a
motion into windows after resampling it once. Pure functions: no files, no printing.
Bad input raises ``InputError``.
"""

from __future__ import annotations

import re

import numpy as np

from ..errors import InputError, ModelError
from ..kinematics import fk
from ..motion.roles import find_roles
from ..types import MotionClip, Skeleton
from .motion_metrics import check_motion

#: Frame rate the features are computed at (the AIST++ features assume 60 fps).
FEATURE_FPS = 60.0
#: Shortest motion ``kinetic_features`` / ``geometric_features`` accept (6 frames at 60 fps).
MIN_DURATION_S = 0.1
#: The AIST++ API averages velocities and accelerations over ±2 frames.
_SLIDING_FRAMES = 2

#: The 24 SMPL joints, in SMPL order.
SMPL_JOINTS = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle",
    "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head",
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
    "left_hand", "right_hand")

# (name, kind, points, threshold). Points are mapped joints (AIST++ names) or the virtual
# points "zero", "y_unit", "minus_y_unit" and "y_min" (the lowest joint's height). A
# threshold is (body unit, factor) or an angle range in degrees. Kinds (Müller's generic
# relations; n = unit normal, q the last point):
#   plane:      q lies more than θ in front of the plane through p1, p2, p3, n ∝ (p1 - p3) × (p2 - p3)
#   nplane:     q lies more than θ beyond the plane through p3 with normal p2 - p1
#   move_plane: q moves faster than θ relative to p3 along the normal of the plane (p1, p2, p3)
#   move_dir:   q moves faster than θ relative to p3 along p2 - p1
#   angle:      the angle between p2 - p1 and q2 - q1 lies strictly inside the range
#   fast:       q's speed exceeds θ
GEOMETRIC_FEATURES = (
    ("right_hand_moving_forward", "move_plane", ("neck", "rhip", "lhip", "rwrist"), ("hl", 1.8)),
    ("left_hand_moving_forward", "move_plane", ("neck", "rhip", "lhip", "lwrist"), ("hl", 1.8)),
    ("right_hand_above_neck", "nplane", ("chest", "neck", "neck", "rwrist"), ("hl", 0.2)),
    ("left_hand_above_neck", "nplane", ("chest", "neck", "neck", "lwrist"), ("hl", 0.2)),
    ("right_hand_moving_up", "move_dir", ("belly", "chest", "chest", "rwrist"), ("hl", 1.8)),
    ("left_hand_moving_up", "move_dir", ("belly", "chest", "chest", "lwrist"), ("hl", 1.8)),
    ("right_elbow_bent", "angle", ("relbow", "rshoulder", "relbow", "rwrist"), (0.0, 110.0)),
    ("left_elbow_bent", "angle", ("lelbow", "lshoulder", "lelbow", "lwrist"), (0.0, 110.0)),
    ("hands_far_apart", "nplane", ("lshoulder", "rshoulder", "lwrist", "rwrist"), ("sw", 2.5)),
    ("hands_approaching", "move_dir", ("lwrist", "rwrist", "rwrist", "lwrist"), ("hl", 1.4)),
    ("right_hand_leaving_root", "move_dir", ("rwrist", "root", "rwrist", "root"), ("hl", 1.4)),
    ("left_hand_leaving_root", "move_dir", ("lwrist", "root", "lwrist", "root"), ("hl", 1.4)),
    ("right_hand_fast", "fast", ("rwrist",), ("hl", 2.5)),
    ("left_hand_fast", "fast", ("lwrist",), ("hl", 2.5)),
    ("right_foot_behind_left_leg", "plane", ("root", "lhip", "ltoes", "rankle"), ("hl", 0.38)),
    ("left_foot_behind_right_leg", "plane", ("root", "rtoes", "rhip", "lankle"), ("hl", 0.38)),
    ("right_foot_raised", "nplane", ("zero", "y_unit", "y_min", "rankle"), ("hl", 1.2)),
    ("left_foot_raised", "nplane", ("zero", "y_unit", "y_min", "lankle"), ("hl", 1.2)),
    ("feet_far_apart", "nplane", ("lhip", "rhip", "lankle", "rankle"), ("hw", 2.1)),
    ("right_knee_bent", "angle", ("rknee", "rhip", "rknee", "rankle"), (0.0, 110.0)),
    ("left_knee_bent", "angle", ("lknee", "lhip", "lknee", "lankle"), (0.0, 110.0)),
    ("right_foot_fast", "fast", ("rankle",), ("hl", 2.5)),
    ("left_foot_fast", "fast", ("lankle",), ("hl", 2.5)),
    ("right_arm_raised", "angle", ("neck", "root", "rshoulder", "relbow"), (25.0, 180.0)),
    ("left_arm_raised", "angle", ("neck", "root", "lshoulder", "lelbow"), (25.0, 180.0)),
    ("right_leg_raised", "angle", ("neck", "root", "rhip", "rknee"), (50.0, 180.0)),
    ("left_leg_raised", "angle", ("neck", "root", "lhip", "lknee"), (50.0, 180.0)),
    ("root_behind_feet", "plane", ("rankle", "neck", "lankle", "root"), ("hl", 0.5)),
    ("spine_horizontal", "angle", ("neck", "root", "zero", "y_unit"), (70.0, 110.0)),
    ("right_hand_low", "nplane", ("zero", "minus_y_unit", "y_min", "rwrist"), ("hl", -1.2)),
    ("left_hand_low", "nplane", ("zero", "minus_y_unit", "y_min", "lwrist"), ("hl", -1.2)),
    ("root_fast", "fast", ("root",), ("hl", 2.3)),
)

# AIST++ point names of the geometric features -> SMPL joints, with the stand-in used
# when a skeleton lacks the joint (Müller's own foot relations use the ankle).
_GEOMETRIC_POINTS = {
    "root": ("pelvis",), "lhip": ("left_hip",), "rhip": ("right_hip",), "belly": ("spine1",),
    "chest": ("spine3",), "neck": ("neck", "head"), "lknee": ("left_knee",), "rknee": ("right_knee",),
    "lankle": ("left_ankle",), "rankle": ("right_ankle",), "ltoes": ("left_foot", "left_ankle"),
    "rtoes": ("right_foot", "right_ankle"), "lshoulder": ("left_shoulder",), "rshoulder": ("right_shoulder",),
    "lelbow": ("left_elbow",), "relbow": ("right_elbow",), "lwrist": ("left_wrist",), "rwrist": ("right_wrist",),
}
# Names a hand joint (SMPL's "hand" sits at the knuckles) may have below the wrist.
_HAND_PARTS = ("hand", "fingerbase", "fingers", "finger", "mid1", "middle1", "handmiddle1", "index1",
               "handindex1")
_TOL = 1e-12


# ---------------------------------------------------------------------------------------------
# Joints


def _path_up(parents, joint: int) -> list[int]:
    """``joint`` and its ancestors up to the root."""
    out = []
    while joint >= 0:
        out.append(int(joint))
        joint = parents[joint]
    return out


def _common_ancestor(parents, a: int, b: int) -> int:
    up = set(_path_up(parents, a))
    return next(j for j in _path_up(parents, b) if j in up)


def _between(parents, top: int, joint: int) -> list[int]:
    """Joints strictly between ancestor ``top`` and ``joint``, top-down."""
    path = _path_up(parents, joint)
    if top not in path:
        return []
    return path[1:path.index(top)][::-1]


def smpl_joint_map(skeleton: Skeleton) -> dict[str, int]:
    """The SMPL joints found in ``skeleton``: SMPL name -> joint index, in SMPL order.

    Limbs come from ``motion.roles.find_roles`` (hips = upper legs, shoulders = upper
    arms, ankles, wrists, toes, head by name); the rest from the hierarchy:

    - ``pelvis``: the common ancestor of the two hips (so an extra root bone is skipped);
    - ``spine3`` (chest): the common ancestor of the two shoulders; ``spine1`` and
      ``spine2``: the first and the middle joint strictly between pelvis and chest;
    - ``neck``: the first joint strictly between chest and head;
    - ``left/right_collar``: the first joint strictly between chest and shoulder;
    - ``left/right_foot``: the toe joint (``roles.toes``);
    - ``left/right_hand``: a child of the wrist named like a hand, finger base or middle
      or index finger (never the thumb).

    Joints that cannot be found are left out: a Daz salsa skeleton (43 joints) maps
    onto 21 SMPL joints (no spine2, no toe joints), the CMU cgspeed skeletons (31)
    onto all 24, the Perfume skeleton (23) onto 22 (no hand joints). Raises
    ``InputError`` when the skeleton has no recognisable legs.
    """
    try:
        roles = find_roles(skeleton)
    except ModelError as exc:
        raise InputError(f"realism features need a humanoid skeleton: {exc}") from None
    parents = skeleton.parents
    found: dict[str, int] = {}
    (lh, rh), (lk, rk), (la, ra) = roles.hips, roles.knees, roles.ankles
    pelvis = _common_ancestor(parents, lh, rh)
    found.update(pelvis=pelvis, left_hip=lh, right_hip=rh, left_knee=lk, right_knee=rk, left_ankle=la,
                 right_ankle=ra)
    if roles.toes[0] >= 0 and roles.toes[1] >= 0:
        found.update(left_foot=roles.toes[0], right_foot=roles.toes[1])
    ls, rs = roles.shoulders
    if min(ls, rs, *roles.elbows, *roles.wrists) >= 0:
        chest = _common_ancestor(parents, ls, rs)
        found.update(spine3=chest, left_shoulder=ls, right_shoulder=rs, left_elbow=roles.elbows[0],
                     right_elbow=roles.elbows[1], left_wrist=roles.wrists[0], right_wrist=roles.wrists[1])
        spine = _between(parents, pelvis, chest)
        if spine:
            found["spine1"] = spine[0]
        if len(spine) >= 2:
            found["spine2"] = spine[max(1, len(spine) // 2)]
        for side, shoulder in (("left", ls), ("right", rs)):
            collar = _between(parents, chest, shoulder)
            if collar:
                found[f"{side}_collar"] = collar[0]
        if roles.head >= 0:
            neck = _between(parents, chest, roles.head)
            if neck:
                found["neck"] = neck[0]
        hands = [_hand_joint(skeleton, w) for w in roles.wrists]
        if min(hands) >= 0:
            found.update(left_hand=hands[0], right_hand=hands[1])
    if roles.head >= 0:
        found["head"] = roles.head
    return {name: int(found[name]) for name in SMPL_JOINTS if name in found}


def _hand_joint(skeleton: Skeleton, wrist: int) -> int:
    kids = [int(k) for k in skeleton.children(wrist)]
    parts = {k: re.sub(r"[^a-z0-9]", "", skeleton.names[k].lower()) for k in kids}
    for want in _HAND_PARTS:
        for k in kids:
            if "thumb" not in parts[k] and parts[k].endswith(want):
                return k
    return -1


def _rest_positions(skeleton: Skeleton) -> np.ndarray:
    pos = np.zeros((skeleton.n_joints, 3))
    for j in range(1, skeleton.n_joints):
        pos[j] = pos[skeleton.parents[j]] + skeleton.offsets[j]
    return pos


def _body_units(skeleton: Skeleton, joints: dict[str, int]) -> dict[str, float]:
    """Humerus length, shoulder width and hip width of the rest pose (metres), Müller's yardsticks."""
    rest = _rest_positions(skeleton)

    def dist(a, b):
        return float(np.linalg.norm(rest[joints[a]] - rest[joints[b]]))

    units = {"hl": 0.5 * (dist("left_shoulder", "left_elbow") + dist("right_shoulder", "right_elbow")),
             "sw": dist("left_shoulder", "right_shoulder"), "hw": dist("left_hip", "right_hip")}
    bad = [k for k, v in units.items() if not v > 1e-6]
    if bad:
        raise InputError(f"geometric features need non-zero {', '.join(bad)} in the rest pose of the skeleton "
                         f"({', '.join(skeleton.names[:6])}, ...): its arm or hip bones have no length")
    return units


# ---------------------------------------------------------------------------------------------
# Positions at the feature frame rate


def _joint_positions(motion: MotionClip, joints: np.ndarray) -> np.ndarray:
    """Global positions (F60, J, 3) of ``joints`` resampled to ``FEATURE_FPS`` by a cubic spline.

    Positions rather than rotations are resampled: a cubic keeps accelerations
    continuous, so energy expenditure hardly depends on the source frame rate.
    """
    sk = motion.skeleton
    _, pos = fk(motion.local_rot, motion.root_pos, sk.offsets, sk.parents, motion.local_pos, only=joints)
    pos = pos[:, joints]
    if abs(motion.fps - FEATURE_FPS) < 1e-6 * FEATURE_FPS:
        return pos
    from scipy.interpolate import CubicSpline

    t_in = np.arange(motion.n_frames) / motion.fps
    t_out = np.arange(int(np.floor(t_in[-1] * FEATURE_FPS + 1e-6)) + 1) / FEATURE_FPS
    return CubicSpline(t_in, pos, axis=0)(t_out)


def _usable(motion, name: str) -> MotionClip:
    check_motion(motion, name)
    if motion.duration_s < MIN_DURATION_S or motion.n_frames < 4:
        raise InputError(f"{name} is too short ({motion.n_frames} frames, {motion.duration_s:.3f} s): "
                         f"realism features need at least {MIN_DURATION_S} s and 4 frames")
    return motion


# ---------------------------------------------------------------------------------------------
# Kinetic features


def _centred_mean(x: np.ndarray, n_centres: int, half: int) -> np.ndarray:
    """Mean of ``x[c-half : c+half+1]`` (clipped to ``x``) for c = 0 .. n_centres-1."""
    c = np.arange(n_centres)
    lo = np.clip(c - half, 0, len(x) - 1)
    hi = np.clip(c + half, 0, len(x) - 1)
    cum = np.concatenate([np.zeros_like(x[:1]), np.cumsum(x, axis=0)])
    return (cum[hi + 1] - cum[lo]) / (hi - lo + 1).reshape((-1,) + (1,) * (x.ndim - 1))


def _kinetic(pos: np.ndarray) -> np.ndarray:
    """Kinetic features of positions (F, J, 3) at ``FEATURE_FPS``: (J * 3,), per joint (KE_h, KE_v, EE).

    As the AIST++ API: frame i = 1 .. F-1 averages the one-frame velocities of frames
    i-2 .. i+2 (those that exist) and the accelerations (second differences) likewise.
    """
    dt = 1.0 / FEATURE_FPS
    step = np.diff(pos, axis=0)                                   # step[c] moves frame c to c+1
    vel = _centred_mean(step, len(step), _SLIDING_FRAMES) / dt
    second = pos[2:] - 2.0 * pos[1:-1] + pos[:-2]                 # second[c] is centred on frame c+1
    acc = _centred_mean(second, len(step), _SLIDING_FRAMES) / dt ** 2
    ke_h = np.mean(vel[..., 0] ** 2 + vel[..., 2] ** 2, axis=0)  # Y is up: x and z are horizontal
    ke_v = np.mean(vel[..., 1] ** 2, axis=0)
    ee = np.mean(np.linalg.norm(acc, axis=-1), axis=0)
    return np.stack([ke_h, ke_v, ee], axis=1).reshape(-1)


def kinetic_features(motion: MotionClip) -> np.ndarray:
    """Kinetic features of a whole motion: ``(3 * J,)`` for the ``J`` SMPL joints ``smpl_joint_map`` finds.

    Per joint, in SMPL order: mean horizontal kinetic energy ``mean(v_x² + v_z²)`` and
    vertical ``mean(v_y²)`` (m²/s², unit mass, no ½), and energy expenditure
    ``mean(|a|)`` (m/s²), with ``v`` and ``a`` averaged over ±2 frames (AIST++ API).
    The motion is first resampled to 60 fps (cubic spline of joint positions), so the
    frame rate the motion comes at barely changes the numbers.
    """
    _usable(motion, "motion")
    joints = np.array(list(smpl_joint_map(motion.skeleton).values()))
    return _kinetic(_joint_positions(motion, joints))


# ---------------------------------------------------------------------------------------------
# Geometric features


def _geometric_layout(skeleton: Skeleton):
    """Joints whose positions the geometric features need, each feature point's column, body units."""
    joints = smpl_joint_map(skeleton)
    missing = [p for p, cands in _GEOMETRIC_POINTS.items()
               if p != "belly" and not any(c in joints for c in cands)]
    if missing:
        raise InputError(f"geometric features need arms, legs, chest and a neck or head; cannot find "
                         f"{', '.join(missing)} in the skeleton ({', '.join(skeleton.names[:6])}, ...)")
    names = list(joints)
    column = {p: (names.index(next(c for c in cands if c in joints)) if any(c in joints for c in cands) else None)
              for p, cands in _GEOMETRIC_POINTS.items()}  # belly None: no joint between pelvis and chest
    return np.array(list(joints.values())), column, _body_units(skeleton, joints)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), _TOL)


def _relations(pos: np.ndarray, column: dict, units: dict[str, float]) -> np.ndarray:
    """Per-frame booleans (F, 32) of ``GEOMETRIC_FEATURES`` for positions (F, J, 3) at 60 fps."""
    n = len(pos)
    pts = {p: pos[:, c] for p, c in column.items() if c is not None}
    if column["belly"] is None:  # half way from pelvis to chest
        pts["belly"] = 0.5 * (pts["root"] + pts["chest"])
    pts["zero"] = np.zeros((n, 3))
    pts["y_unit"] = np.tile([0.0, 1.0, 0.0], (n, 1))
    pts["minus_y_unit"] = -pts["y_unit"]
    pts["y_min"] = np.zeros((n, 3))
    pts["y_min"][:, 1] = pos[..., 1].min(axis=1)
    velocity = {}

    def vel(p):  # central differences, m/s
        if p not in velocity:
            velocity[p] = np.gradient(pts[p], axis=0) * FEATURE_FPS if n > 1 else np.zeros((n, 3))
        return velocity[p]

    out = np.zeros((n, len(GEOMETRIC_FEATURES)), dtype=bool)
    for f, (_, kind, names, threshold) in enumerate(GEOMETRIC_FEATURES):
        p = [pts[k] for k in names]
        if kind == "angle":
            lo, hi = threshold
            cos = np.sum(_unit(p[1] - p[0]) * _unit(p[3] - p[2]), axis=-1)
            deg = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
            out[:, f] = (deg > lo) & (deg < hi)
            continue
        theta = units[threshold[0]] * threshold[1]
        if kind == "fast":
            value = np.linalg.norm(vel(names[0]), axis=-1)
        elif kind == "plane":
            normal = _unit(np.cross(p[0] - p[2], p[1] - p[2]))
            value = np.sum(normal * (p[3] - p[2]), axis=-1)
        elif kind == "nplane":
            value = np.sum(_unit(p[1] - p[0]) * (p[3] - p[2]), axis=-1)
        elif kind == "move_plane":
            normal = _unit(np.cross(p[0] - p[2], p[1] - p[2]))
            value = np.sum(normal * (vel(names[3]) - vel(names[2])), axis=-1)
        else:  # move_dir
            value = np.sum(_unit(p[1] - p[0]) * (vel(names[3]) - vel(names[2])), axis=-1)
        out[:, f] = value > theta
    return out


def geometric_features(motion: MotionClip) -> np.ndarray:
    """Geometric features of a whole motion: ``(32,)``, the fraction of frames each relation holds.

    The 32 boolean relations of the AIST++ API (``GEOMETRIC_FEATURES``: name, kind,
    points, threshold), evaluated at 60 fps (cubic resampling) with velocities by
    central differences in m/s; thresholds scale with the skeleton's humerus length,
    shoulder width and hip width measured in its rest pose. Stand-ins: the head for a
    missing neck, the ankle for missing toes, half way from pelvis to chest for a
    missing belly (spine1) joint. Needs arms, legs and a head or neck (else ``InputError``).
    """
    _usable(motion, "motion")
    joints, column, units = _geometric_layout(motion.skeleton)
    return _relations(_joint_positions(motion, joints), column, units).mean(axis=0)

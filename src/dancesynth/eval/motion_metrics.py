"""Metrics computed from a ``MotionClip``: kinematic beats, smoothness, foot contact.

Pure functions of the motion (no files, no printing). Lengths are metres, times
seconds, angles degrees in the results. Each function takes the clip and,
optionally, precomputed forward kinematics (``global_rot``, ``global_pos`` from
``dancesynth.kinematics.clip_fk``) so that ``evaluate`` runs FK once. A clip with no
frames or with NaN raises ``InputError``; a clip too short for a metric gives NaN.
"""

from __future__ import annotations

import numpy as np

from .. import rotations as rot
from ..errors import InputError
from ..kinematics import clip_fk, fk
from ..motion import beats as motion_beats
from ..motion.beats import kinematic_beats as motion_kinematic_beats
from ..motion.beats import summed_speed
from ..motion.features import CONTACT_HEIGHT_M, foot_points, interval_energy, kinetic_energy
from ..motion.roles import bone_masses, find_roles
from ..types import MotionClip
from .beat_metrics import as_times, as_values, check_seconds

#: Defaults shared with ``evaluate.EvalParams`` (one source).
DEFAULT_SMOOTH_S = motion_beats.SMOOTH_S    # kinematic beats as the analysis finds them
DEFAULT_POLYORDER = motion_beats.POLYORDER
DEFAULT_MIN_SEPARATION_S = motion_beats.MIN_SEPARATION_S
DEFAULT_MIN_PROMINENCE_FRAC = motion_beats.MIN_PROMINENCE_FRAC
# A visible accent stops the body at least this much (motion.beats.stop_depths): the median stop depth of
# the bundled mocap's kinematic beats on its own motion beats (0.401 over 1,440 of them, 7 styles, 30 fps;
# their quartiles 0.18 / 0.66). Set from the mocap alone, never from a dance. benchmarks/stop_depth.py
VISIBLE_STOP_DEPTH = 0.4
DEFAULT_TRANSITION_RADIUS_S = 0.035  # +-2 frames at 60 fps, +-1 at 30 fps
DEFAULT_CONTACT_HEIGHT_M = CONTACT_HEIGHT_M  # motion.features': one contact height everywhere
EDGE_FPS = 30.0                    # EDGE's PFC measures foot motion per 1/30 s frame
PFC_WINDOW_S = 5.0                 # ... on 5-second clips, averaged
_STEADY_M_S2 = 1e-6                # a root accelerating less than this does not accelerate
_NAN = float("nan")


def check_motion(motion, name: str = "motion") -> MotionClip:
    """``motion`` if it is a usable ``MotionClip`` (frames, finite values), else ``InputError``."""
    if not isinstance(motion, MotionClip):
        raise InputError(f"{name} must be a dancesynth MotionClip (e.g. from dancesynth.io.bvh.read_bvh), "
                         f"got {type(motion).__name__}")
    if motion.n_frames == 0:
        raise InputError(f"{name} has no frames; evaluate a clip with at least one frame")
    for field, arr in (("root_pos", motion.root_pos), ("local_rot", motion.local_rot),
                       ("local_pos", motion.local_pos)):
        if arr is None:
            continue
        bad = ~np.isfinite(np.asarray(arr, dtype=np.float64))
        if bad.any():
            frame = int(np.argwhere(bad)[0][0])
            raise InputError(f"{name}.{field} has NaN or infinite values (first at frame {frame}); "
                             "repair or trim the clip")
    norms = np.linalg.norm(motion.local_rot, axis=-1)
    if np.any(norms < 1e-6):
        frame = int(np.argwhere(norms < 1e-6)[0][0])
        raise InputError(f"{name}.local_rot has zero quaternions (first at frame {frame}); "
                         "rotations must be unit quaternions (x, y, z, w)")
    return motion


def _posed(motion, global_rot, global_pos):
    """``(global_rot, global_pos)``: the ones given (checked), else ``clip_fk(motion)``."""
    if global_rot is None or global_pos is None:
        return clip_fk(motion)
    return global_rot, _positions(motion, global_pos)


def _positions(motion, global_pos) -> np.ndarray:
    if global_pos is None:
        return clip_fk(motion)[1]
    want = motion.local_rot.shape[:2] + (3,)
    if np.shape(global_pos) != want:
        raise InputError(f"global_pos must be (frames, joints, 3) = {want}, got {np.shape(global_pos)}; "
                         "pass kinematics.clip_fk(motion)[1]")
    return np.asarray(global_pos, dtype=np.float64)


# ---------------------------------------------------------------------------------------------
# Kinematic beats and motion intensity


def kinematic_beats(motion: MotionClip, *, smooth_s: float = DEFAULT_SMOOTH_S, polyorder: int = DEFAULT_POLYORDER,
                    min_separation_s: float = DEFAULT_MIN_SEPARATION_S,
                    min_prominence_frac: float = DEFAULT_MIN_PROMINENCE_FRAC,
                    global_pos=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Kinematic beats: local minima of the smoothed summed joint speed.

    Aristidou et al., Rhythm is a Dancer, §5.2.1 (after Davis & Agrawala 2018):
    "the Euclidean distance between two consecutive frames (the sum over all joint
    positions) ... apply the Savitzky-Golay filter ... set kinematic offsets at the
    local minima". Here:

    1. ``speed[t] = sum_j |d p_j / dt|`` (m/s) over all joints' global positions,
       central differences (``motion.beats.summed_speed``; a forward difference
       would shift every beat by half a frame);
    2. Savitzky-Golay smoothing, window ``smooth_s`` (rounded to an odd number of
       frames, at least ``polyorder + 1``), polynomial order ``polyorder``;
    3. frames lower than every other frame within +-``min_separation_s / 2``;
    4. minima whose prominence (depth of the dip below the lower of the two
       surrounding peaks, ``scipy.signal.peak_prominences``) is less than
       ``min_prominence_frac`` times the clip's mean smoothed speed are dropped:
       when the body is nearly still, sensor noise makes tiny dips that are not
       movement accents. ``min_prominence_frac=0`` keeps every minimum (the paper).

    Returns ``(beat_times_s, speed, smoothed_speed)``; the curves (F,) in m/s are
    those of the paper's Fig. 7. A clip not longer than the smoothing window has no
    beats (and ``smoothed_speed`` is ``speed``).
    """
    check_motion(motion)
    check_seconds(smooth_s, "smooth_s")
    check_seconds(min_separation_s, "min_separation_s")
    if int(polyorder) != polyorder or polyorder < 0:
        raise InputError(f"polyorder must be a non-negative integer (2 = quadratic), got {polyorder!r}")
    if not min_prominence_frac >= 0:
        raise InputError(f"min_prominence_frac must be >= 0 (0 keeps every minimum), got {min_prominence_frac!r}")
    fps = motion.fps
    speed = summed_speed(_positions(motion, global_pos), fps)
    frames, smooth = motion_kinematic_beats(speed, fps, smooth_s=smooth_s, polyorder=int(polyorder),
                                            min_separation_s=min_separation_s,
                                            min_prominence_frac=min_prominence_frac)
    return frames / fps, speed, smooth


def beat_interval_energy(motion: MotionClip, beat_times_s, *, global_pos=None, masses=None) -> np.ndarray:
    """Kinetic energy of the motion over each interval between consecutive beats (J*s).

    Xu et al.'s motion intensity ("the total kinetic energy between two neighboring
    beats"): ``sum_{t in [b_k, b_k+1)} 0.5 sum_j m_j |v_j(t)|^2 / fps`` with beats
    rounded to frames, via ``motion.features.kinetic_energy`` / ``interval_energy``.
    ``masses`` default to ``motion.roles.bone_masses`` (70 kg spread over the bones
    by length). Returns ``len(beat_times_s) - 1`` values in beat order; NaN for an
    interval that is not entirely inside the motion.
    """
    check_motion(motion)
    beats = as_times(beat_times_s, "beat_times_s")
    if beats.size < 2:
        return np.zeros(0)
    masses = bone_masses(motion.skeleton) if masses is None else as_values(masses, "masses")
    if masses.shape != (motion.skeleton.n_joints,):
        raise InputError(f"masses needs one value per joint ({motion.skeleton.n_joints}), got {masses.size}")
    n = motion.n_frames
    energy = (_chunked_energy(motion, masses) if global_pos is None
              else kinetic_energy(_positions(motion, global_pos), motion.fps, masses))
    frames = np.round(beats * motion.fps).astype(np.int64)
    out = interval_energy(energy, np.clip(frames, 0, n), motion.fps)
    out[(frames[:-1] < 0) | (frames[1:] > n)] = np.nan
    return out


#: Frames of forward kinematics at a time: a 30-minute dance's positions at once were 100 MB.
ENERGY_CHUNK = 4096


def _chunked_energy(motion: MotionClip, masses: np.ndarray) -> np.ndarray:
    """``kinetic_energy`` of the clip's forward kinematics, a chunk of frames at a time. Each chunk
    is computed with one frame more on either side, so the central differences, and the result,
    are exactly those of the whole clip at once."""
    from ..kinematics import fk

    n, sk = motion.n_frames, motion.skeleton
    out = np.empty(n)
    for a in range(0, n, ENERGY_CHUNK):
        b = min(a + ENERGY_CHUNK, n)
        lo, hi = max(a - 1, 0), min(b + 1, n)
        local_pos = None if motion.local_pos is None else motion.local_pos[lo:hi]
        pos = fk(motion.local_rot[lo:hi], motion.root_pos[lo:hi], sk.offsets, sk.parents, local_pos)[1]
        out[a:b] = kinetic_energy(pos, motion.fps, masses)[a - lo:a - lo + b - a]
    return out


def beat_accent_strength(beat_times_s, kinematic_beats_s, smoothed_speed, fps: float, *,
                         window_s: float = 0.05) -> np.ndarray:
    """How strongly the dance marks each beat: the deepest visible stop within +-``window_s``.

    For each beat, the largest prominence (m/s, the depth of the speed dip below the
    lower of its two neighbouring peaks) of the kinematic beats within the window;
    0 where the dance does not stop there. ``kinematic_beats_s`` and
    ``smoothed_speed`` are what ``kinematic_beats`` returns.
    """
    from scipy import signal  # costs ~0.8 s to import; only analysis needs it

    beats = as_times(beat_times_s, "beat_times_s")
    kin = as_times(kinematic_beats_s, "kinematic_beats_s")
    smooth = as_values(smoothed_speed, "smoothed_speed")
    window = check_seconds(window_s, "window_s", allow_zero=True)
    out = np.zeros(beats.size)
    if kin.size == 0 or beats.size == 0:
        return out
    frames = np.clip(np.round(kin * fps).astype(np.int64), 0, smooth.size - 1)
    prominence = signal.peak_prominences(-smooth, frames)[0]
    lo = np.searchsorted(kin, beats - window - 1e-9)
    hi = np.searchsorted(kin, beats + window + 1e-9)
    for b in np.flatnonzero(hi > lo):
        out[b] = prominence[lo[b]:hi[b]].max()
    return out


# ---------------------------------------------------------------------------------------------
# Smoothness


def angular_velocity_jumps(motion: MotionClip) -> np.ndarray:
    """Per frame, the largest change of any joint's angular velocity (deg/s), shape (F,).

    ``omega_j(t) = log(q_j(t+1) q_j(t)^-1) * fps`` is joint j's angular velocity
    from frame t to t+1 (local rotations, so expressed in the parent's frame; the
    root's is its global turning), and::

        jump(t) = max_j |omega_j(t) - omega_j(t-1)|          (t = 1 .. F-2)

    converted to degrees per second. A smooth motion changes its angular velocity
    a little every frame; a visible pop at a transition changes it a lot in one
    frame. ``jump`` is 0 at the first and last frame (nothing to compare). The value
    scales with the frame rate (it is an acceleration times one frame), so compare
    clips at the same rate -- ``evaluate`` resamples the reference mocap.
    """
    check_motion(motion)
    q = motion.local_rot
    out = np.zeros(motion.n_frames)
    if motion.n_frames < 3:
        return out
    step = rot.mul(q[1:], rot.inv(q[:-1]))                 # (F-1, J, 4) turn from t to t+1
    omega = rot.log(step) * motion.fps                      # rad/s
    out[1:-1] = np.degrees(np.linalg.norm(np.diff(omega, axis=0), axis=-1).max(axis=1))
    return out


def transition_jumps(motion: MotionClip, transitions_s, *, radius_s: float = DEFAULT_TRANSITION_RADIUS_S,
                     jumps_deg_s=None) -> np.ndarray:
    """For each transition time, the largest angular-velocity jump within +-``radius_s`` (deg/s).

    ``jumps_deg_s`` (F,) may be passed from ``angular_velocity_jumps``. Frames whose
    time is within ``radius_s`` of the transition are searched (at least the nearest
    frame): the default 35 ms covers +-2 frames at 60 fps and +-1 frame at 30 fps,
    where the pop of a badly joined transition shows. Returns one value per
    transition, in the order given; transitions outside the motion raise ``InputError``.
    """
    check_motion(motion)
    times = as_times(transitions_s, "transitions_s", sort=False)
    radius = check_seconds(radius_s, "radius_s", allow_zero=True)
    n, fps = motion.n_frames, motion.fps
    if jumps_deg_s is None:
        jumps = angular_velocity_jumps(motion)
    else:
        jumps = as_values(jumps_deg_s, "jumps_deg_s")
        if jumps.size != n:
            raise InputError(f"jumps_deg_s has {jumps.size} values for {n} frames; "
                             "pass angular_velocity_jumps(motion)")
    outside = (times < -radius) | (times > motion.duration_s + radius)
    if outside.any():
        raise InputError(f"transition at {times[outside][0]:g} s lies outside the motion "
                         f"(0 to {motion.duration_s:g} s); transition times are in seconds, not frames")
    lo = np.clip(np.ceil((times - radius) * fps - 1e-6), 0, n - 1).astype(np.int64)
    hi = np.clip(np.floor((times + radius) * fps + 1e-6), 0, n - 1).astype(np.int64)
    nearest = np.clip(np.round(times * fps), 0, n - 1).astype(np.int64)
    lo, hi = np.minimum(lo, nearest), np.maximum(hi, nearest)
    return np.array([jumps[a:b + 1].max() for a, b in zip(lo, hi)], dtype=np.float64)


def transition_jump(motion: MotionClip, transitions_s, *, radius_s: float = DEFAULT_TRANSITION_RADIUS_S,
                    jumps_deg_s=None) -> float:
    """The largest angular-velocity jump near any transition (deg/s): ``max(transition_jumps(...))``.

    NaN when there are no transitions. See ``transition_jumps`` and
    ``angular_velocity_jumps`` for the definition.
    """
    values = transition_jumps(motion, transitions_s, radius_s=radius_s, jumps_deg_s=jumps_deg_s)
    return float(values.max()) if values.size else _NAN


def mean_jerk(motion: MotionClip, *, global_pos=None) -> float:
    """Mean magnitude of the jerk of the joint positions (m/s^3).

    ``jerk_j(t) = (p_j(t+3) - 3 p_j(t+2) + 3 p_j(t+1) - p_j(t)) * fps^3`` (third
    finite difference of the global positions), averaged over all joints and the
    F-3 frame windows. Jerk amplifies high-frequency noise, so it grows with the
    frame rate of noisy data: compare clips at one rate. NaN below 4 frames.
    """
    check_motion(motion)
    if motion.n_frames < 4:
        return _NAN
    p = _positions(motion, global_pos)
    jerk = (p[3:] - 3.0 * p[2:-1] + 3.0 * p[1:-2] - p[:-3]) * motion.fps ** 3
    return float(np.mean(np.linalg.norm(jerk, axis=-1)))


def joint_speeds(motion: MotionClip, *, global_pos=None) -> np.ndarray:
    """Linear speed of every joint between consecutive frames (m/s), (F-1, J).

    Its upper percentiles say how fast the dance moves: a dance retimed onto the beats
    must not get much faster or slower than the mocap it came from.
    """
    check_motion(motion)
    p = _positions(motion, global_pos)
    return np.linalg.norm(np.diff(p, axis=0), axis=-1) * motion.fps


def root_travel_speed(motion: MotionClip) -> float:
    """Mean speed of the root across the floor (m/s): how much the dance travels. NaN below 2 frames."""
    check_motion(motion)
    if motion.n_frames < 2:
        return _NAN
    step = np.diff(np.asarray(motion.root_pos, dtype=np.float64)[:, [0, 2]], axis=0)
    return float(np.mean(np.linalg.norm(step, axis=-1)) * motion.fps)


# ---------------------------------------------------------------------------------------------
# Feet and floor


def feet_of(motion: MotionClip, *, global_rot=None, global_pos=None) -> np.ndarray:
    """World positions (F, 2, 2, 3) of (left, right) x (ankle, toe tip).

    Joints are found by name (``motion.roles.find_roles``, ``ModelError`` for a
    skeleton without recognisable legs); see ``motion.features.foot_points``.
    """
    check_motion(motion)
    global_rot, global_pos = _posed(motion, global_rot, global_pos)
    return foot_points(motion, find_roles(motion.skeleton), global_rot, global_pos)


def floor_height(feet: np.ndarray) -> float:
    """Estimated floor height (m): the median over frames of the lowest foot point.

    A dancer has a foot on the floor most of the time, so the level the lowest
    foot point sits at in the median frame is the floor; airborne frames (a
    minority) and the odd dip do not move it.
    """
    return float(np.median(np.asarray(feet)[..., 1].min(axis=(1, 2))))


def _floor(feet, floor_m) -> float:
    if floor_m is None:
        return floor_height(feet)
    try:
        value = float(floor_m)
    except (TypeError, ValueError) as exc:
        raise InputError(f"floor_m must be a height in metres (or None to estimate it), got {floor_m!r}") from exc
    if not np.isfinite(value):
        raise InputError(f"floor_m must be a finite height in metres, got {floor_m!r}")
    return value


def foot_skate(motion: MotionClip, *, height_tol_m: float = DEFAULT_CONTACT_HEIGHT_M, floor_m=None,
               contacts=None, global_rot=None, global_pos=None) -> float:
    """Mean horizontal foot speed while the foot is on the floor (m/s); 0 = no skating.

    Per frame and foot, the foot's speed is the slower of its two points (ankle,
    toe tip) in the horizontal (x, z) plane, by central differences -- a foot
    rolling over its toe or pivoting on its heel is not sliding. A foot is on the
    floor when its lower point is within ``height_tol_m`` of the floor
    (``floor_m``, default ``floor_height``); the mean runs over all (frame, foot)
    pairs on the floor. ``contacts`` (F, 2) booleans replace that test (e.g. a
    dance's own contact labels).

    Unlike ``motion.features.foot_contacts`` the default test ignores speed: that
    detector calls a foot planted only when it moves slower than 0.35 m/s, which
    would hide exactly the sliding measured here. NaN when no foot touches the
    floor or the clip has one frame.
    """
    check_motion(motion)
    tol = float(height_tol_m)
    if not tol >= 0:
        raise InputError(f"height_tol_m must be a non-negative height in metres, got {height_tol_m!r}")
    feet = feet_of(motion, global_rot=global_rot, global_pos=global_pos)
    if motion.n_frames < 2:
        return _NAN
    speed = np.linalg.norm(np.gradient(feet[..., [0, 2]], axis=0), axis=-1).min(axis=2) * motion.fps
    if contacts is None:
        contact = feet[..., 1].min(axis=2) <= _floor(feet, floor_m) + tol
    else:
        contact = np.asarray(contacts)
        if contact.shape != (motion.n_frames, 2):
            raise InputError(f"contacts must be (frames, 2) = ({motion.n_frames}, 2) booleans (left, right), "
                             f"got shape {contact.shape}")
        contact = contact.astype(bool)
    return float(speed[contact].mean()) if contact.any() else _NAN


def pfc(motion: MotionClip, *, window_s: float | None = PFC_WINDOW_S, global_rot=None, global_pos=None) -> float:
    """Physical Foot Contact score (PFC) of EDGE (Tseng et al., CVPR 2023); lower is better.

    EDGE's ``calc_physical_score``: a body whose root accelerates must push against
    the floor, so at least one foot should be static. With the root (joint 0)
    acceleration ``a(t)`` by second differences, its upward component clamped at 0
    (falling needs no support), ``a_hat = |a| / max_t |a|``, and each foot's
    horizontal speed the slower of its (ankle, toe) points::

        PFC = 10^4 * mean_t( v_left(t) * v_right(t) * a_hat(t) )

    over the F-2 interior frames, with EDGE's indexing (foot displacement from
    frame t+1 to t+2 against the acceleration centred on t+1). EDGE measures foot
    speed in metres per frame at 30 fps; we use metres per 1/30 s (displacement per
    frame * fps / 30), so a 30 fps clip scores exactly as in EDGE's code and other
    frame rates are comparable. Differences from EDGE: Y is up (EDGE's SMPL joints
    are Z-up); the foot points are ankle and toe tip (SMPL: ankle and foot joints).

    EDGE scores 5-second clips and averages them; so does this, over consecutive
    ``window_s`` windows (a shorter tail joins the window before it): ``max_t |a|``
    is a window's, so one hard acceleration does not rescale a whole song. ``None``:
    the whole clip as one window. A window whose root never accelerates (|a| <= 1e-6
    m/s^2: EDGE's code would normalise floating-point noise by itself) scores 0.0;
    NaN below 3 frames.
    """
    check_motion(motion)
    global_rot, global_pos = _posed(motion, global_rot, global_pos)
    feet = feet_of(motion, global_rot=global_rot, global_pos=global_pos)
    if motion.n_frames < 3:
        return _NAN
    fps = motion.fps
    n = motion.n_frames
    size = n if window_s is None else max(int(round(float(window_s) * fps)), 3)
    starts = list(range(0, n, size))
    if len(starts) > 1 and n - starts[-1] < size:
        starts.pop()  # the short tail joins the window before it
    bounds = list(zip(starts, starts[1:] + [n]))
    return float(np.mean([_pfc_window(global_pos[a:b, 0], feet[a:b], fps) for a, b in bounds]))


def _pfc_window(root: np.ndarray, feet: np.ndarray, fps: float) -> float:
    """EDGE's PFC of one window: ``root`` (F, 3) positions, ``feet`` (F, 2, points, 3)."""
    acc = np.diff(root, n=2, axis=0) * fps * fps
    acc[:, 1] = np.maximum(acc[:, 1], 0.0)
    acc = np.linalg.norm(acc, axis=-1)
    if not acc.max() > _STEADY_M_S2:  # only rounding noise: EDGE would divide noise by noise
        return 0.0
    acc /= acc.max()
    step = np.linalg.norm(feet[2:, ..., [0, 2]] - feet[1:-1, ..., [0, 2]], axis=-1) * (fps / EDGE_FPS)
    slowest = step.min(axis=2)                                  # (F-2, 2) per foot
    return float(np.mean(slowest[:, 0] * slowest[:, 1] * acc) * 1e4)


def ground_penetration(motion: MotionClip, *, floor_m=None, statistic: str = "mean",
                       global_rot=None, global_pos=None) -> float:
    """Depth of the lowest foot point below the floor (m): mean over frames, or max.

    ``depth(t) = max(0, floor - min over both feet's ankle and toe tip of y(t))``;
    ``statistic="mean"`` averages it over all frames, ``"max"`` takes the deepest.
    The floor is ``floor_m`` if given (e.g. 0.0 for a scene with its floor at y = 0),
    else ``floor_height`` (the median lowest foot point), so the value says how far
    the feet sink below where they usually stand -- the mocap itself scores a few
    millimetres from noise. Foot points are joints, not the skin: a sole some
    centimetres below the ankle is not modelled.
    """
    check_motion(motion)
    if statistic not in ("mean", "max"):
        raise InputError(f"statistic must be 'mean' or 'max', got {statistic!r}")
    feet = feet_of(motion, global_rot=global_rot, global_pos=global_pos)
    depth = np.maximum(_floor(feet, floor_m) - feet[..., 1].min(axis=(1, 2)), 0.0)
    return float(depth.mean() if statistic == "mean" else depth.max())

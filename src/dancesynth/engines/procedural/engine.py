"""The whole song to a ``MotionClip``: Loi & Li's pipeline (their Fig. 1) end to end.

notes -> segmentation (§IV) -> keyframes (§V.B) -> Bezier path (§V.D, with the
Fig. 8 rescaling) -> speed profile (§V.E) -> right arm IK; left hand, head, torso
(§V.G); legs standing. No motion capture is used: only a skeleton, by default the
bundled database's ``mj`` style (the CMU 31-joint skeleton: full arm chains with
collars, a two-joint neck and a head).
"""

from __future__ import annotations

import time

import numpy as np

from ... import rotations as rot
from ...errors import InputError, ModelError
from ...kinematics import fk
from ...motion.roles import find_roles
from ...music.notes import NoteSequence
from ...types import MotionClip, Skeleton
from .arm_ik import pose_chain, solve_arm
from .bezier import build_path, rescale_heights
from .body import left_hand_targets, nod_angles, sway_angles
from .config import ProceduralConfig, config_dict
from .keyframes import Y_MID, plan_keyframes
from .segment import segment
from .speed import end_speeds, peak_speeds, sample_path

DEFAULT_STYLE = "mj"
TAIL_S = 0.5            # motion after the music ends, so the last gesture can finish
MAX_RESCALES = 4


def default_skeleton(db) -> Skeleton:
    """The skeleton of the database's ``mj`` style, else of its first style with two arms and a head."""
    if DEFAULT_STYLE in db.styles:
        return db.styles[DEFAULT_STYLE].skeleton
    for name in sorted(db.styles):
        roles = find_roles(db.styles[name].skeleton)
        if min(roles.wrists) >= 0 and roles.head >= 0:
            return db.styles[name].skeleton
    raise ModelError("no style in the database has a skeleton with two arms and a head")


def _chain_between(parents: np.ndarray, top: int, bottom: int) -> list[int]:
    """Joints from ``bottom`` up to (not including) ``top``, top first."""
    out, j = [], bottom
    while j >= 0 and j != top:
        out.append(j)
        j = parents[j]
    return out[::-1] if j == top else []


class _Rig:
    """What the procedural dancer needs to know about a skeleton."""

    def __init__(self, sk: Skeleton):
        roles = find_roles(sk)
        if min(roles.shoulders + roles.elbows + roles.wrists) < 0 or roles.head < 0:
            raise ModelError("the skeleton needs two arms (shoulder, elbow, wrist) and a head for conducting")
        self.sk, self.roles = sk, roles
        ident = np.tile(rot.IDENTITY, (sk.n_joints, 1))
        _, rest = fk(ident, np.zeros(3), sk.offsets, sk.parents)
        self.rest = rest
        collars = [int(sk.parents[s]) for s in roles.shoulders]
        self.collars = collars
        # The spine swings the torso: the joints from the root to the collars' parent.
        self.spine = _chain_between(sk.parents, 0, int(sk.parents[collars[0]]))
        # The neck and head nod: the joints above the spine up to the head.
        self.neck = _chain_between(sk.parents, self.spine[-1] if self.spine else 0, roles.head)
        self.arm_length = [float(np.linalg.norm(sk.offsets[e]) + np.linalg.norm(sk.offsets[w]))
                           for e, w in zip(roles.elbows, roles.wrists)]

    def outward(self, side: int) -> np.ndarray:
        """Unit vector from the body's midline towards arm ``side`` (0 left, 1 right)."""
        x = self.rest[self.roles.shoulders[side], 0] - self.rest[0, 0]
        return np.array([np.sign(x) if x != 0 else (1.0 - 2.0 * side), 0.0, 0.0])


def _axis_rotation(axis, degrees: np.ndarray) -> np.ndarray:
    return rot.exp(np.asarray(axis, dtype=float) * np.radians(degrees)[:, None])


def _stance(rig: _Rig, local: np.ndarray, cfg: ProceduralConfig) -> np.ndarray:
    """Legs under the hips, knees bent by ``knee_bend``, feet flat; returns the root height."""
    sk, roles = rig.sk, rig.roles
    h = np.radians(cfg.knee_bend) / 2.0
    thigh = np.array([[0.0, -np.cos(h), np.sin(h)]])
    shin = np.array([[0.0, -np.cos(h), -np.sin(h)]])
    hinge = np.cross(thigh, shin) if h > 0 else np.array([[1.0, 0.0, 0.0]])
    for hip, knee, ankle in zip(roles.hips, roles.knees, roles.ankles):
        q_hip, q_knee = pose_chain(sk.offsets[knee], sk.offsets[ankle], thigh, shin, hinge, bends_forward=False)
        local[:, hip] = q_hip[0]
        local[:, knee] = q_knee[0]
        local[:, ankle] = rot.inv(rot.mul(q_hip[0], q_knee[0]))  # the foot stays as in the rest pose
    _, pos = fk(local[0], np.zeros(3), sk.offsets, sk.parents)
    feet = [j for j in roles.ankles + roles.toes if j >= 0]
    return float(-np.min(pos[feet, 1]))


def plan_right_hand(notes: NoteSequence, bounds, cfg: ProceduralConfig):
    """Fig. 8: keyframes per segment, then the path, flattened while any part leaves the reach
    (or, our addition, would outrun the speed limit).

    Returns ``(keyframes, path, number of rescaling passes)``.
    """
    keys = plan_keyframes(notes, bounds, cfg)
    path = build_path(keys, cfg)
    rescales = 0
    while rescales < MAX_RESCALES:
        fixed = rescale_heights(keys, path, cfg, Y_MID, peak_speeds(path, cfg))
        if fixed is None:
            break
        keys, path = fixed, build_path(fixed, cfg)
        rescales += 1
    return keys, path, rescales


def conduct_notes(notes: NoteSequence, cfg: ProceduralConfig | None = None, *,
                  skeleton: Skeleton, segment_method: str = "prefix") -> MotionClip:
    """Upper-body motion interpreting ``notes`` (a ``MotionClip`` at ``cfg.fps``) on ``skeleton``
    (``default_skeleton(database)`` is the usual one).

    ``clip.meta`` holds the plan: segments, keyframes (times, positions in arm
    lengths from the shoulder, corners), beat-note times, long and staccato notes,
    and ``stats``: sizes and timings (``api.conduct`` makes them the dance's provenance).
    """
    cfg = cfg or ProceduralConfig()
    if notes.n_notes < 2:
        raise InputError("the melody needs at least two notes to conduct")
    timings = {}
    t = time.perf_counter()
    bounds = segment(notes, cfg, segment_method)
    timings["segment_s"] = time.perf_counter() - t
    t = time.perf_counter()
    keys, path, rescales = plan_right_hand(notes, bounds, cfg)
    timings["plan_s"] = time.perf_counter() - t

    t = time.perf_counter()
    rig = _Rig(skeleton)
    sk, roles = rig.sk, rig.roles
    end_s = max(notes.duration_s, float(keys.times_s[-1])) + TAIL_S
    n_frames = int(np.ceil(end_s * cfg.fps)) + 1
    times = np.arange(n_frames) / cfg.fps
    local = np.tile(rot.IDENTITY, (n_frames, sk.n_joints, 1))
    root_y = _stance(rig, local, cfg)

    # Arms: the right hand draws the melody, the left marks long and staccato notes.
    right_kf = sample_path(path, cfg, times)
    left_kf = left_hand_targets(times, notes, cfg)
    wrists, flexes = [], []
    for side, plan in ((1, right_kf), (0, left_kf)):
        out = rig.outward(side)
        inward_x = -out[0]
        length = rig.arm_length[side]
        shoulder = sk.offsets[roles.shoulders[side]]
        # Plans are in arm lengths; x is towards the midline for the right hand, outwards for the left.
        sign_x = inward_x if side == 1 else out[0]
        target = shoulder + length * np.stack([sign_x * plan[:, 0], plan[:, 1], plan[:, 2]], axis=1)
        q_up, q_el, wrist, flex = solve_arm(
            shoulder, sk.offsets[roles.elbows[side]], sk.offsets[roles.wrists[side]], target, outward=out,
            swivel_deg=cfg.swivel, elbow_min_deg=cfg.elbow_min, elbow_max_deg=cfg.elbow_max,
            max_reach=cfg.reach * length)
        local[:, roles.shoulders[side]] = q_up
        local[:, roles.elbows[side]] = q_el
        wrists.append(wrist)
        flexes.append(flex)

    # Head and torso on the beats.
    beats = notes.beat_times_s
    sway = sway_angles(times, beats, cfg)
    nod = nod_angles(times, beats, cfg)
    for j in rig.spine:
        local[:, j] = rot.mul(_axis_rotation((0, 0, 1), sway / len(rig.spine)), local[:, j])
    neck = rig.neck or [roles.head]
    for j in neck:
        # Each neck joint nods its share and takes back its share of the sway, so the head stays level.
        q = rot.mul(_axis_rotation((1, 0, 0), nod / len(neck)), _axis_rotation((0, 0, 1), -0.7 * sway / len(neck)))
        local[:, j] = rot.mul(q, local[:, j])
    root = np.tile([0.0, root_y, 0.0], (n_frames, 1))
    timings["pose_s"] = time.perf_counter() - t

    v0, v1 = end_speeds(path, cfg)
    stats = {
        "notes": notes.n_notes, "segments": len(bounds), "beat_notes": int(notes.is_beat.sum()),
        "long_notes": int(np.sum(notes.duration_16 > cfg.long_note)), "staccato_notes": int(notes.staccato.sum()),
        "rescaled_segments": int(np.sum(keys.y_scale < 1.0)), "path_rescales": rescales,
        "max_hand_speed": float(np.max(np.concatenate([v0, v1]))) if len(v0) else 0.0,
        "timings_s": timings,
    }
    meta = {
        "stats": stats, "config": config_dict(cfg),
        "segments": np.asarray(bounds), "segment_times_s": notes.onset_s[[b - 1 for _, b in bounds]],
        "keyframe_times_s": keys.times_s, "keyframes": keys.pos, "corner": keys.corner,
        "beat_note_times_s": notes.onset_s[notes.is_beat], "note_onsets_s": notes.onset_s,
        "long_notes_s": np.stack([notes.onset_s, notes.offset_s], 1)[notes.duration_16 > cfg.long_note],
        "staccato_s": notes.onset_s[notes.staccato], "music_beat_times_s": beats,
        "right_hand_plan": right_kf, "left_hand_plan": left_kf, "elbow_flex_deg": np.stack(flexes[::-1], 1),
        "arm_length": rig.arm_length, "source": notes.source,
    }
    return MotionClip(sk, cfg.fps, root, local, meta=meta)

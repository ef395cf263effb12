"""Keep planted feet where the source motion kept them.

Blending across a jump makes a foot slide, because the pose is pulled from the old
motion towards the new; and the capture's own planted feet drift (a contact is any
foot near the floor moving under 0.35 m/s), which time-warping a piece faster only
speeds up. So while the source says a foot is in contact, the ankle is held where
the contact began, by two-bone leg IK (``follow_source`` > 0 lets it follow that share
of the source's own horizontal ankle motion instead: 1 keeps the capture's drift and
removes only what the blend adds, the behaviour before 2026-12-02). Its height stays
the shown motion's, so a foot a blend carries down onto the floor is not held in the
air.

Any jump in the correction is a jump of the whole leg on screen, so it is kept
continuous:

- a foot that lands while a blend still moves it grips over ``grip_s`` instead of
  stopping dead;
- when the contact ends the correction decays to zero (cubic Hermite from its last
  value and velocity) over ``release_s``, longer for a large one;
- a contact that begins during a release takes the released offset over instead of
  dropping it (contact labels flicker for a frame at a time);
- a held foot never pulls more than ``max_offset_m`` away from the shown one (beyond
  that the leg would have to leave its own pose: the foot slides instead);
- the IK result itself is faded in and out over ``ease_s`` (the solved leg can
  differ from the shown one even where the correction is zero: a knee bent the
  wrong way past straight is turned round).

The pass is incremental (``FootLockState``) so the streaming engine applies it
segment by segment.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from .. import rotations as rot
from ..kinematics import fk, two_bone_ik
from ..motion.features import foot_points
from ..motion.roles import JointRoles
from ..types import MotionClip, Skeleton
from .stitch import Rendered, decay_basis


def _per_foot(shape=()):
    return field(default_factory=lambda: np.zeros((2,) + shape))


@dataclass(frozen=True)
class FootLockState:
    """What the pass remembers between segments, per foot (left, right)."""

    locked: np.ndarray = _per_foot()         # 1.0 while the foot is held
    held: np.ndarray = _per_foot()           # frames since it was planted
    target: np.ndarray = _per_foot((3,))     # where the ankle should be now
    raw_prev: np.ndarray = _per_foot((3,))   # last raw ankle position
    ankle_prev: np.ndarray = _per_foot((3,))  # last shown ankle position (before the correction)
    applied: np.ndarray = _per_foot((3,))    # correction shown on the last frame
    applied_vel: np.ndarray = _per_foot((3,))  # its velocity (m/s)
    release_at: np.ndarray = _per_foot()     # frames into the release
    release_len: np.ndarray = _per_foot()    # its length in frames (0: none)
    release_x0: np.ndarray = _per_foot((3,))
    release_v0: np.ndarray = _per_foot((3,))
    weight: np.ndarray = _per_foot()         # how much of the IK result is shown


@dataclass(frozen=True)
class LockParams:
    """The foot lock's tunables (see the module notes); times in seconds, lengths in metres."""

    release_s: float = 0.2
    release_speed_m_s: float = 0.5
    max_offset_m: float = 0.1
    grip_s: float = 0.1
    ease_s: float = 0.15
    pole_weight: float = 0.3   # how firmly the knee is kept over the toes (two_bone_ik): mocap knees stray
    follow_source: float = 0.0  # share of the source's own foot motion kept during a contact


def _released(x0, v0, at, length, fps):
    """The decaying correction ``at`` frames into a release of ``length`` frames."""
    h00, h10 = decay_basis(min(at / length, 1.0))
    return h00 * x0 + h10 * (length / fps) * v0


def _track_foot(foot: dict, contacts, new_run, ankle, raw, fps: float, p: LockParams):
    """Correction ``(n, 3)`` and IK weight ``(n,)`` of one foot over n frames; updates ``foot`` (its state)."""
    n = len(ankle)
    delta, weight = np.zeros((n, 3)), np.zeros(n)
    grip, ease = max(p.grip_s * fps, 1.0), max(p.ease_s * fps, 1.0)
    f = foot
    for t in range(n):
        if contacts[t]:
            if not f["locked"]:
                # Start from where the foot is shown, fading correction included.
                carry = _released(f["release_x0"], f["release_v0"], f["release_at"] + 1, f["release_len"], fps) \
                    if f["release_len"] else 0.0
                f.update(locked=1.0, target=ankle[t] + carry, release_len=0.0, held=0.0)
            else:
                f["held"] += 1.0
                own = 0.0 if new_run[t] else p.follow_source * (raw[t] - f["raw_prev"])  # the source's own
                slip = max(0.0, 1.0 - f["held"] / grip)
                f["target"] = f["target"] + own + slip * (ankle[t] - f["ankle_prev"] - own)
            f["target"][1] = ankle[t, 1]  # the foot's place on the floor is held, its height is the motion's
            delta[t] = f["target"] - ankle[t]
            size = np.linalg.norm(delta[t])
            if size > p.max_offset_m:
                delta[t] *= p.max_offset_m / size
                f["target"] = ankle[t] + delta[t]
            goal = 1.0
        else:
            if f["locked"]:
                x0, vel = f["applied"], f["applied_vel"]
                size = np.linalg.norm(x0)
                length = max(p.release_s, size / p.release_speed_m_s) * fps
                # Carry the correction's velocity on, but never faster than it decays on average.
                v0 = vel * min(1.0, size / (length / fps) / max(np.linalg.norm(vel), 1e-9))
                f.update(locked=0.0, release_x0=x0, release_v0=v0, release_at=0.0, release_len=length)
            goal = 0.0
            if f["release_len"]:
                f["release_at"] += 1.0
                delta[t] = _released(f["release_x0"], f["release_v0"], f["release_at"], f["release_len"], fps)
                goal = min(1.0, (f["release_len"] - f["release_at"]) / ease)
                if f["release_at"] >= f["release_len"]:
                    f["release_len"] = 0.0
        f["weight"] = float(np.clip(goal, f["weight"] - 1.0 / ease, f["weight"] + 1.0 / ease))
        weight[t] = f["weight"]
        f["applied_vel"], f["applied"] = (delta[t] - f["applied"]) * fps, delta[t]
        f["raw_prev"], f["ankle_prev"] = raw[t], ankle[t]
    return delta, weight


def lock_feet(skeleton: Skeleton, roles: JointRoles, frames: Rendered, state: FootLockState, *,
              fps: float, params: LockParams = LockParams()):
    """Return ``(local_rot, state)``: ``frames.local_rot`` with planted feet held."""
    local_rot = frames.local_rot
    n = len(local_rot)
    if n == 0:
        return local_rot, state
    ankles = list(roles.ankles)
    g_rot, g_pos = fk(local_rot, frames.root_pos, skeleton.offsets, skeleton.parents,
                      only=ankles + [t for t in roles.toes if t >= 0])
    _, raw_pos = fk(frames.raw_local, frames.raw_root, skeleton.offsets, skeleton.parents, only=ankles)
    # A knee points over its toes: the pole that keeps the leg IK from flipping the knee.
    feet = foot_points(MotionClip(skeleton, fps, frames.root_pos, local_rot), roles, g_rot, g_pos)
    toward = feet[:, :, 1] - feet[:, :, 0]
    names = [f.name for f in fields(FootLockState)]
    new_state = {k: np.array(getattr(state, k), dtype=np.float64) for k in names}
    out = local_rot.copy()
    for side in range(2):
        chain = (roles.hips[side], roles.knees[side], roles.ankles[side])
        foot = {k: (v[side].copy() if v.ndim > 1 else float(v[side])) for k, v in new_state.items()}
        ankle = g_pos[:, chain[2]]
        delta, weight = _track_foot(foot, frames.contacts[:, side], frames.new_run, ankle, raw_pos[:, chain[2]],
                                    fps, params)
        for k in names:
            new_state[k][side] = foot[k]
        sel = np.flatnonzero(weight > 0)
        if not sel.size:
            continue
        new = two_bone_ik(g_rot[sel], g_pos[sel], chain, ankle[sel] + delta[sel], bend_toward=toward[sel, side],
                          pole_weight=params.pole_weight)
        parent = skeleton.parents[chain[0]]
        solved = np.stack([rot.mul(rot.inv(g_rot[sel, parent]), new[:, 0]), rot.mul(rot.inv(new[:, 0]), new[:, 1]),
                           rot.mul(rot.inv(new[:, 1]), new[:, 2])], axis=1)
        out[sel[:, None], list(chain)] = rot.nlerp(local_rot[sel][:, list(chain)], solved,
                                                   weight[sel, None] * np.ones(3))
    return out, FootLockState(**new_state)

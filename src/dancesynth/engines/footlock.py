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
from ..kinematics import chain_local_rotations, fk, two_bone_ik
from ..motion.cleanup import spread_steps
from ..motion.features import foot_points
from ..motion.roles import JointRoles
from ..types import MotionClip, Skeleton
from .decay import decay_basis
from .stitch import Rendered


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
    """The decaying correction ``at`` frames into a release of ``length`` frames (scalars, or one per
    frame: ``at`` and ``length`` (m,), ``x0`` and ``v0`` (m, 3))."""
    h00, h10 = decay_basis(np.minimum(np.asarray(at, dtype=np.float64) / length, 1.0))
    return h00[..., None] * x0 + (h10 * (length / fps))[..., None] * v0


def _track_foot(foot: dict, contacts, new_run, ankle, raw, fps: float, p: LockParams):
    """Correction ``(n, 3)`` and IK weight ``(n,)`` of one foot over n frames; updates ``foot`` (its state).

    The correction follows the state machine of the module notes frame by frame; it is computed a
    run of frames of one contact label at a time, vectorised where a frame depends on the one before
    only through a running sum: a held foot past its grip (its target moves only by the source's own
    motion, when followed) and a release (a closed-form decay). The few frames that lock a foot, grip
    it or clamp its correction are stepped one by one.
    """
    n = len(ankle)
    delta, goal = np.zeros((n, 3)), np.zeros(n)
    grip, ease = max(p.grip_s * fps, 1.0), max(p.ease_s * fps, 1.0)
    f = foot
    ankle_prev = np.concatenate([f["ankle_prev"][None], ankle[:-1]])
    own = p.follow_source * (raw - np.concatenate([f["raw_prev"][None], raw[:-1]]))  # the source's own motion
    own[new_run] = 0.0
    # A gripping foot's target moves by this share of each frame's motion (times its slip).
    moved = ankle - ankle_prev - own
    cuts = np.flatnonzero(contacts[1:] != contacts[:-1]) + 1
    releases = []  # (frames, frames into the release, x0, v0, length): decays written all at once
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, n]):
        if contacts[a] and b - a == 1:
            _write_releases(releases, delta, goal, ease, fps)  # its velocity needs the frame before it
        before = delta[a - 1] if a else f["applied"]  # the correction shown on the frame before the run
        if contacts[a]:
            _hold(f, a, b, delta, ankle, ankle_prev, own, moved, grip, fps, p)
            goal[a:b] = 1.0
        else:
            _release(f, a, b, releases, p, fps)
            if b < n:
                continue  # the contact after it does not look back (but when it lasts one frame)
            _write_releases(releases, delta, goal, ease, fps)
        f["applied_vel"] = (delta[b - 1] - (delta[b - 2] if b - 1 > a else before)) * fps
        f["applied"] = delta[b - 1].copy()
    _write_releases(releases, delta, goal, ease, fps)
    f["raw_prev"], f["ankle_prev"] = raw[-1].copy(), ankle[-1].copy()
    # The IK result fades in and out at a limited rate.
    weight, w, step = np.empty(n), f["weight"], 1.0 / ease
    for t, g in enumerate(goal.tolist()):
        w = weight[t] = min(max(g, w - step), w + step)
    f["weight"] = float(w)
    return delta, weight


def _hold(f: dict, a: int, b: int, delta, ankle, ankle_prev, own, moved, grip: float, fps: float, p: LockParams):
    """Frames ``a..b-1`` of a contact: the ankle held at its target."""
    follow = p.follow_source != 0.0
    t, pulled = a, False
    while t < b:
        # Stepped one by one: locking, gripping while following the source, and the frames after a
        # clamp while the shown foot keeps pulling away (each clamps again).
        if not f["locked"] or (follow and f["held"] + 1.0 < grip) or pulled:
            pulled = _hold_frame(f, t, delta, ankle, ankle_prev, own, grip, fps, p)
            t += 1
            continue
        # From here each frame moves the target by one term: the share of the shown foot's motion
        # it slips by (gripping; the source's own motion is not followed), or the source's own
        # motion (gripped): a running sum on the floor (x, z), until a correction grows past
        # max_offset_m and the target is pulled along with the shown foot. The correction's
        # height stays 0: the foot's height is the motion's own.
        held = f["held"] + np.arange(1.0, b - t + 1.0)
        step = own[t:b, ::2] if follow else np.maximum(0.0, 1.0 - held / grip)[:, None] * moved[t:b, ::2]
        target = np.cumsum(np.concatenate([f["target"][None, ::2], step]), axis=0)[1:]
        d = target - ankle[t:b, ::2]
        delta[t:b, ::2] = d
        near = np.flatnonzero(np.hypot(d[:, 0], d[:, 1]) > p.max_offset_m * (1.0 - 1e-9))
        # The test that counts is the frame's own norm (as _clamp takes it): the batch's may differ by an ulp.
        over = next((i for i in near.tolist() if np.linalg.norm(delta[t + i]) > p.max_offset_m), None)
        m = b - t if over is None else over + 1
        f["held"] = float(held[m - 1])
        f["target"] = np.array([target[m - 1, 0], ankle[t + m - 1, 1], target[m - 1, 1]])
        if over is not None:
            pulled = _clamp(f, t + m - 1, delta, ankle, p)
        t += m


def _hold_frame(f: dict, t: int, delta, ankle, ankle_prev, own, grip: float, fps: float, p: LockParams) -> bool:
    """One frame of a contact, stepped on its own; whether its correction was clamped."""
    if not f["locked"]:
        # Start from where the foot is shown, fading correction included.
        carry = _released(f["release_x0"], f["release_v0"], f["release_at"] + 1, f["release_len"], fps) \
            if f["release_len"] else 0.0
        f.update(locked=1.0, target=ankle[t] + carry, release_len=0.0, held=0.0)
    else:
        f["held"] += 1.0
        slip = max(0.0, 1.0 - f["held"] / grip)
        f["target"] = f["target"] + own[t] + slip * (ankle[t] - ankle_prev[t] - own[t])
    f["target"][1] = ankle[t, 1]  # the foot's place on the floor is held, its height is the motion's
    delta[t] = f["target"] - ankle[t]
    return _clamp(f, t, delta, ankle, p)


def _clamp(f: dict, t: int, delta, ankle, p: LockParams) -> bool:
    """A held foot never pulls more than ``max_offset_m`` from the shown one: beyond, the target follows.
    Returns whether it did."""
    size = np.linalg.norm(delta[t])
    if size > p.max_offset_m:
        delta[t] *= p.max_offset_m / size
        f["target"] = ankle[t] + delta[t]
        return True
    return False


def _release(f: dict, a: int, b: int, releases: list, p: LockParams, fps: float) -> None:
    """Frames ``a..b-1`` without contact: a correction left by a contact decays to zero (the frames it
    lasts noted in ``releases``, for ``_write_releases``)."""
    if f["locked"]:
        x0, vel = f["applied"], f["applied_vel"]
        size = np.linalg.norm(x0)
        length = max(p.release_s, size / p.release_speed_m_s) * fps
        # Carry the correction's velocity on, but never faster than it decays on average.
        v0 = vel * min(1.0, size / (length / fps) / max(np.linalg.norm(vel), 1e-9))
        f.update(locked=0.0, release_x0=x0, release_v0=v0, release_at=0.0, release_len=length)
    if not f["release_len"]:
        return
    at = f["release_at"] + np.arange(1.0, b - a + 1.0)
    done = np.flatnonzero(at >= f["release_len"])
    m = done[0] + 1 if done.size else b - a  # the release ends on the frame that reaches its length
    releases.append((np.arange(a, a + m), at[:m], f["release_x0"], f["release_v0"], f["release_len"]))
    f["release_at"] = float(at[m - 1])
    if done.size:
        f["release_len"] = 0.0


def _write_releases(releases: list, delta, goal, ease: float, fps: float) -> None:
    """The decaying corrections and IK weight goals of the noted ``releases``, all at once."""
    if not releases:
        return
    frames = np.concatenate([r[0] for r in releases])
    at = np.concatenate([r[1] for r in releases])
    counts = [len(r[0]) for r in releases]
    x0, v0 = (np.repeat(np.stack([r[i] for r in releases]), counts, axis=0) for i in (2, 3))
    length = np.repeat([r[4] for r in releases], counts)
    delta[frames] = _released(x0, v0, at, length, fps)
    goal[frames] = np.minimum(1.0, (length - at) / ease)
    releases.clear()


def _without_snaps(local_rot: np.ndarray, fps: float) -> np.ndarray:
    """The last pass of every engine's motion: an isolated one-frame snap (a joint turning over 20 degrees in
    one frame, calm before and after) is spread over a few frames, as the database's clean-up mends a
    capture's. Two things make them: a quick twist the capture makes over three frames, which the accent
    timing plays within one frame at 30 fps, and the leg IK swapping solutions from one frame to the next
    (a knee swung round as a blend carries the leg through straight). Slowing the easing down for such pieces
    instead cost their transitions the slowdown on the beat that hides each cut (largest transition jump
    0.61 -> 1.01 x the mocap's p99 on Vibe Ace)."""
    return spread_steps(local_rot, fps)


def lock_feet(skeleton: Skeleton, roles: JointRoles, frames: Rendered, state: FootLockState, *,
              fps: float, params: LockParams = LockParams()):
    """Return ``(local_rot, state)``: ``frames.local_rot`` with planted feet held (and no one-frame snap:
    ``_without_snaps``)."""
    local_rot = frames.local_rot
    n = len(local_rot)
    if n == 0:
        return local_rot, state
    ankles = list(roles.ankles)
    # The shown motion's and the raw (unblended) motion's feet in one pass.
    g_rot, g_pos = fk(np.concatenate([local_rot, frames.raw_local]), np.concatenate([frames.root_pos, frames.raw_root]),
                      skeleton.offsets, skeleton.parents, only=ankles + [t for t in roles.toes if t >= 0])
    raw_pos, g_rot, g_pos = g_pos[n:], g_rot[:n], g_pos[:n]
    # A knee points over its toes: the pole that keeps the leg IK from flipping the knee.
    feet = foot_points(MotionClip(skeleton, fps, frames.root_pos, local_rot), roles, g_rot, g_pos)
    toward = feet[:, :, 1] - feet[:, :, 0]
    names = [f.name for f in fields(FootLockState)]
    new_state = {k: np.array(getattr(state, k), dtype=np.float64) for k in names}
    legs = []  # (frames where the IK shows, the leg's joints, its correction and weight there)
    for side in range(2):
        chain = (roles.hips[side], roles.knees[side], roles.ankles[side])
        foot = {k: (v[side].copy() if v.ndim > 1 else float(v[side])) for k, v in new_state.items()}
        ankle = g_pos[:, chain[2]]
        delta, weight = _track_foot(foot, frames.contacts[:, side], frames.new_run, ankle, raw_pos[:, chain[2]],
                                    fps, params)
        for k in names:
            new_state[k][side] = foot[k]
        sel = np.flatnonzero(weight > 0)
        legs.append((sel, list(chain), ankle[sel] + delta[sel], toward[sel, side], weight[sel]))
    # Both legs' IK in one batch: each frame of a leg is solved on its own.
    sel = np.concatenate([leg[0] for leg in legs])
    if not sel.size:
        return _without_snaps(local_rot.copy(), fps), FootLockState(**new_state)
    chains = np.concatenate([np.tile(leg[1], (len(leg[0]), 1)) for leg in legs])  # (m, 3) joint indices
    rows = sel[:, None]
    new = two_bone_ik(g_rot[rows, chains], g_pos[rows, chains], (0, 1, 2),
                      np.concatenate([leg[2] for leg in legs]), bend_toward=np.concatenate([leg[3] for leg in legs]),
                      pole_weight=params.pole_weight)
    solved = chain_local_rotations(g_rot[sel, skeleton.parents[chains[:, 0]]], new)   # hip, knee, ankle
    weight = np.concatenate([leg[4] for leg in legs])
    out = local_rot.copy()
    out[rows, chains] = rot.nlerp(local_rot[rows, chains], solved, weight[:, None] * np.ones(3))
    return _without_snaps(out, fps), FootLockState(**new_state)

"""Turn a sequence of beat-to-beat source pieces into continuous motion.

Every piece plays source frames ``f0 -> f1`` of a style's flat arrays during the
music interval ``t0 -> t1``, time-warped linearly so that the source beat frames
land exactly on the music beats (Xu et al.: "modifying the frame rate between two
nodes"). Where the source changes (a jump), the new motion is

- re-placed on the floor: rotated about the vertical axis to the old heading and
  shifted so that it stands on the old motion's planted foot (or, with no foot
  planted in both, so that its root continues from the old root), and
- blended in by *inertialization* (``decay``): the pose and velocity difference between the
  old and the new motion at the jump, as a rotation-vector offset per joint, decays
  to zero with a cubic Hermite curve, so pose and velocity stay continuous. Each
  joint decays over ``blend_s`` or longer: long enough that the decay never
  accelerates the joint faster than ``BLEND_ACCEL_RAD_S2`` (a big difference
  takes longer to fade than a small one, instead of snapping in a fixed time), and
  a velocity difference is carried only as far as ``BLEND_MAX_SWING_RAD`` allows.
  The difference is measured on frames that are shown, so a mocap glitch in the
  unplayed frames past a piece's end never leaks into the dance.

Rendering is incremental (``StitchState`` carries the placement and any blend in
progress), so the streaming engine can render segment by segment and a segment
boundary is as seamless as any other beat.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .. import rotations as rot
from ..kinematics import fk
from ..motion.database import Style
from ..motion.resample import sample_frames
from ..motion.roles import JointRoles, find_roles
from .decay import (BLEND_ACCEL_M_S2, BLEND_ACCEL_RAD_S2, BLEND_MAX_SWING_RAD, Blend, blends_at, carried_speed,
                    decay_time, limb_reach, unhurried)
from .timing import ease, ease_rate


@dataclass(frozen=True)
class Pieces:
    """K beat-to-beat pieces: music interval [t0, t1) shows source frames [f0, f1].

    ``count0``/``count1``: the music beats counted at t0 and t1 (``BeatGrid.count``; a piece
    on a subdivided grid spans half a beat, on a merged one two). None: one beat each.
    ``ease0``/``ease1``: how much the accent timing (``timing.ease``) slows the motion on the beat
    at t0 and at t1. None: no easing, each piece at one rate (the paper). ``shown`` (K, N), where
    given, replaces the easing's formula: the share of each piece's source shown at N evenly spaced
    points of its music time (``timing.within_room``), linear between.
    """

    t0: np.ndarray
    t1: np.ndarray
    f0: np.ndarray
    f1: np.ndarray
    jump: np.ndarray  # the piece starts somewhere else than the previous piece ended
    count0: np.ndarray | None = None
    count1: np.ndarray | None = None
    ease0: np.ndarray | None = None
    ease1: np.ndarray | None = None
    shown: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t0)

    def timing(self, k) -> tuple:
        """``(count0, count1, ease0, ease1)`` of pieces ``k``, for ``ease`` and ``ease_rate``."""
        shape = np.shape(k)
        c0, c1 = ((np.zeros(shape), np.ones(shape)) if self.count0 is None
                  else (self.count0[k], self.count1[k]))
        e0, e1 = ((np.zeros(shape), np.zeros(shape)) if self.ease0 is None
                  else (self.ease0[k], self.ease1[k]))
        return c0, c1, e0, e1

    def show(self, u: np.ndarray, k: np.ndarray) -> np.ndarray:
        """The share of piece ``k``'s source shown at ``u`` (0..1) of its music time."""
        if self.shown is None:
            return ease(u, *self.timing(k))
        n = self.shown.shape[1] - 1
        x = np.clip(u, 0.0, 1.0) * n
        i = np.minimum(x.astype(np.int64), n - 1)
        return self.shown[k, i] + (x - i) * (self.shown[k, i + 1] - self.shown[k, i])

    def end_rates(self) -> tuple[np.ndarray, np.ndarray]:
        """Each piece's playback rate at its start and its end, relative to its mean."""
        if self.shown is None:
            return tuple(ease_rate(np.array([[0.0], [1.0]]), *self.timing(np.arange(len(self)))))
        n = self.shown.shape[1] - 1
        return (self.shown[:, 1] - self.shown[:, 0]) * n, (self.shown[:, -1] - self.shown[:, -2]) * n


@dataclass(frozen=True)
class Rendered:
    """Output frames of one ``render`` call.

    ``raw_*`` are the same frames before jump blending; ``new_run`` marks the first
    frame after each jump (where the raw motion changes source).
    """

    local_rot: np.ndarray
    root_pos: np.ndarray
    contacts: np.ndarray
    source_pos: np.ndarray
    raw_local: np.ndarray
    raw_root: np.ndarray
    new_run: np.ndarray


@dataclass(frozen=True)
class StitchState:
    """What rendering needs to remember between segments."""

    next_frame: int = 0              # first output frame the next call renders
    yaw: float = 0.0                 # placement of the current source run on the floor
    offset: np.ndarray = field(default_factory=lambda: np.zeros(2))
    blend: Blend | None = None
    last_f0: float | None = None     # the previous piece (source frames and music times)
    last_f1: float | None = None
    last_t0: float | None = None
    last_t1: float | None = None
    last_end_rate: float = 1.0       # its playback rate at its end, relative to its mean (``ease_rate``)


def _place(style: Style, frames, yaw, offset=None):
    """Source poses at fractional ``frames``, turned by ``yaw`` and shifted on the floor by ``offset`` (2,):
    one for all frames or one per frame; ``offset=None`` leaves the shift to the caller."""
    frames = np.atleast_1d(np.asarray(frames, dtype=np.float64))
    local, root, contacts = sample_frames(style.local_rot, style.root_pos, frames, style.contacts)
    turn = rot.about_y(np.broadcast_to(np.asarray(yaw, dtype=np.float64), frames.shape))
    local = local.copy()
    local[:, 0] = rot.mul(turn, local[:, 0])
    root = rot.apply(turn, root)
    if offset is not None:
        root[:, [0, 2]] += offset
    return local, root, contacts


def _shifted(root: np.ndarray, offset) -> np.ndarray:
    """``root`` (n, 3) moved by ``offset`` (2,) on the floor."""
    root = root.copy()
    root[:, [0, 2]] += offset
    return root


def _clamp_frames(style: Style, f: np.ndarray, near: np.ndarray) -> np.ndarray:
    """Keep extrapolated source positions ``f`` (m, k) inside the clip that contains each of ``near`` (m,)."""
    c = style.clip_of_frame(near.astype(np.int64))
    return np.clip(f, style.clip_starts[c][:, None], style.clip_starts[c + 1][:, None] - 1)


@dataclass(frozen=True)
class _Jump:
    """What a jump (a piece starting somewhere else) needs: the piece it leaves and the one it starts."""

    t0: float          # when it happens
    yaw_old: float     # the old motion's placement turn, and the new one's
    yaw: float
    planted: np.ndarray  # (2,) feet planted in both motions at the jump
    t_old: np.ndarray  # output times of the old motion's last two frames before t0 ...
    t_new: np.ndarray  # ... and of the new one's first two
    frames: np.ndarray  # (6,) source frames of the old motion at (t0, t_old), of the new one at (t0, t_new)


def _jumps_of(style: Style, pieces: Pieces, state: StitchState, yaw: float, start_rate, end_rate,
              fps: float) -> dict:
    """The jumps of ``pieces`` by piece index, with their placement turns (each keeps the old motion's
    heading) and the source frames shown around them -- all that does not depend on where a previous
    jump put the dance."""
    k = np.flatnonzero(pieces.jump)
    if state.last_f1 is None:
        k = k[k > 0]  # the very first piece is placed at the origin instead
    if not k.size:
        return {}
    # The piece each jump leaves: the one before it, or the previous call's last.
    f0, f1, t0, t1 = (np.r_[getattr(state, "last_" + name) if state.last_f1 is not None else np.nan,
                            getattr(pieces, name)[:-1]][k] for name in ("f0", "f1", "t0", "t1"))
    rate_old = (f1 - f0) / (t1 - t0) * np.r_[state.last_end_rate, end_rate[:-1]][k]
    new_f0, at = pieces.f0[k], pieces.t0[k]
    rate_new = (pieces.f1[k] - new_f0) / (pieces.t1[k] - at) * start_rate[k]
    ends = np.rint(np.stack([f1, new_f0], axis=1)).astype(np.int64)
    heading = rot.heading(style.local_rot[ends, 0].astype(float))
    planted = style.contacts[ends[:, 0]] & style.contacts[ends[:, 1]]
    # The old motion's last two output frames before the jump and the new one's first two (a frame
    # at t0 shows the new piece), and the source frames they show, extrapolated within each clip.
    dt = 1.0 / fps
    t_new = np.ceil(at * fps - 1e-9)[:, None] / fps + np.array([0.0, dt])
    t_old = t_new[:, :1] - np.array([2 * dt, dt])
    old = _clamp_frames(style, f1[:, None] + rate_old[:, None] * (t_old - at[:, None]), f1)
    new = _clamp_frames(style, new_f0[:, None] + rate_new[:, None] * (t_new - at[:, None]), new_f0)
    frames = np.concatenate([f1[:, None], old, new_f0[:, None], new], axis=1)
    jumps = {}
    for i, kk in enumerate(k.tolist()):
        new_yaw = float(yaw + heading[i, 0] - heading[i, 1])
        jumps[kk] = _Jump(float(at[i]), yaw, new_yaw, planted[i], t_old[i], t_new[i], frames[i])
        yaw = new_yaw
    return jumps


def _blend_rotations(old, new, jumps: list, blend_s: float, fps: float, lever=None):
    """The rotation part of the inertialization at each of ``jumps``: offsets (m, J, 3), their
    velocities and decay times (m, J).

    ``old`` and ``new`` (m, 2, J, 4) are the two motions' poses at their two frames each side of
    each jump (source frames past a piece's end are never shown, and mocap glitches there must
    not be blended in), each extrapolated to ``t0`` at its own angular velocity. The offset is
    ``log(old * new^-1)`` per joint; its velocity is the offset's own rate of change, so decaying
    it in rotation-vector space keeps the shown angular velocity continuous however far apart
    the poses are. ``lever`` (J,): each joint's ``limb_reach`` over the fastest its decay may move the
    limb's end (s per radian; None: as fast as ``blend_s`` asks).
    """
    dt = 1.0 / fps
    both = np.stack([old, new], axis=1)  # (jump, old/new, frame, J, 4)
    w = rot.log(rot.mul(both[:, :, 1], rot.inv(both[:, :, 0]))) / dt
    eps = 1e-3 * dt
    # The offset at t0 and on either side of it (for its velocity), both motions extrapolated there:
    # the old one from its last frame, the new one from its first.
    t = np.array([[j.t0, j.t0 + eps, j.t0 - eps] for j in jumps])
    since = np.stack([t - np.array([j.t_old[1] for j in jumps])[:, None],
                      t - np.array([j.t_new[0] for j in jumps])[:, None]], axis=1)[..., None, None]
    turned = rot.mul(rot.exp(w[:, :, None] * since), np.stack([old[:, 1], new[:, 0]], axis=1)[:, :, None])
    offset = rot.log(rot.mul(turned[:, 0], rot.inv(turned[:, 1])))  # (jump, t0 / after / before, J, 3)
    x0 = offset[:, 0]
    v0 = (offset[:, 1] - offset[:, 2]) / (2 * eps)
    # Near 180 degrees the rotation vector wraps: no velocity there rather than a wrong one.
    v0[np.linalg.norm(v0, axis=-1) * eps > 1.0] = 0.0
    size, speed = np.linalg.norm(x0, axis=-1), np.linalg.norm(v0, axis=-1)
    carried = np.minimum(speed, carried_speed(size, BLEND_ACCEL_RAD_S2, BLEND_MAX_SWING_RAD))
    v0 *= (carried / np.maximum(speed, 1e-9))[..., None]
    duration = decay_time(size, carried, blend_s, BLEND_ACCEL_RAD_S2)
    return x0, v0, duration if lever is None else unhurried(duration, size * lever)


def _blend_positions(old_root, new_root, jump: _Jump, blend_s: float, fps: float):
    """The root-position part of a jump's inertialization, from the roots (2, 3) of the same frames:
    offset, velocity and decay times (3,), across the floor and up or down."""
    dt = 1.0 / fps
    v_old, v_new = (old_root[1] - old_root[0]) / dt, (new_root[1] - new_root[0]) / dt
    p0 = old_root[1] + v_old * (jump.t0 - jump.t_old[1]) - new_root[0] - v_new * (jump.t0 - jump.t_new[0])
    pv0 = v_old - v_new
    across, up = [0, 2], [1]
    size = np.array([np.linalg.norm(p0[across]), np.linalg.norm(p0[up])])
    speed = np.array([np.linalg.norm(pv0[across]), np.linalg.norm(pv0[up])])
    duration = decay_time(size, speed, blend_s, BLEND_ACCEL_M_S2[[0, 1]])   # not ``unhurried``: the body
    return p0, pv0, duration[[0, 1, 0]]                                      # would glide over held feet


def _jump_frames(jumps: dict) -> tuple[np.ndarray, np.ndarray]:
    """The source frames each of ``jumps`` poses (``_Jump.frames``) and their turns, for ``_place``."""
    order = list(jumps.values())
    return (np.concatenate([j.frames for j in order]) if order else np.zeros(0),
            np.array([[j.yaw_old] * 3 + [j.yaw] * 3 for j in order]).ravel())


def _place_jumps(style: Style, jumps: dict, local, root, state: StitchState, ankles, blend_s: float, fps: float,
                 limb_speed: float | None = None):
    """Where each jump puts the new motion on the floor (offset) and its blend, in order; ``local`` and
    ``root`` are the poses of ``_jump_frames``, placed without an offset.

    At a jump the new motion keeps the old one's heading and, where a foot is planted in
    both, stands on the old one's planted foot (both feet: their midpoint): the blend then
    moves the body over the foot instead of dragging the foot, which the foot lock would
    otherwise have to hold against a growing offset. Else the root continues from the old root.

    Each jump depends on the one before: it places the new motion where the previous one put the
    old motion, which it shows with the previous blend. Rotations never depend on where the dance
    stands, so the poses of all jumps are sampled together, then the blends' rotations are found
    (``_chain_rotations``), the feet's joint rotations for all jumps together (``_feet_steps``), and
    the offsets and the blends' positions last (``_chain_positions``). Returns
    ``[(offset (2,), Blend)]`` in the order of ``jumps``.
    """
    if not jumps:
        return []
    order = list(jumps.values())
    m = len(order)
    local, root = local.reshape(m, 2, 3, *local.shape[1:]), root.reshape(m, 2, 3, 3)  # jump, old/new, frame
    times = np.array([np.r_[j.t0, j.t_old] for j in order])  # of the old motion's three frames
    lever = None if limb_speed is None else limb_reach(style.skeleton) / limb_speed
    rotations, shown = _chain_rotations(local[:, 0], local[:, 1], order, times, state.blend, blend_s, fps, lever)
    feet = _feet_steps(style, ankles, order, shown, local[:, 1, 0])
    return _chain_positions(root, order, times, feet, rotations, state, blend_s, fps)


def _chain_rotations(old, new, jumps: list, times, blend: Blend | None, blend_s: float, fps: float, lever, *,
                     batch: bool = True):
    """The rotation part of each jump's blend (``Blend`` without positions), and the old motion's pose at
    each jump's ``t0`` as shown (m, J, 4).

    ``old`` and ``new`` (m, 3, J, 4) are each jump's poses at (t0, two frames each side), ``times`` (m, 3)
    the old ones' times. At a jump the old motion is shown with the previous jump's blend (``blend``: the
    one in progress before the first), so each jump depends on the one before. But a blend lasts at
    most a second and has always run out by the next jump, where it turns every joint by zero: so all
    jumps are first taken as shown through zero offsets, at once, and then checked by applying the
    blends so found where they are shown, again at once. They must give the same poses bit for bit;
    from the first jump where they do not (a blend still running), the jumps are redone one by one
    (``batch=False``: all of them, the reference the batch must equal).
    """
    m = len(jumps)
    prior = np.ones(m, dtype=bool)  # a blend is shown at the jump (all but a first with none in progress)
    prior[0] = blend is not None
    guess = old.copy()
    guess[prior] = rot.mul(rot.IDENTITY, old[prior])  # exp of zero offsets
    found = _blend_rotations(guess[:, 1:], new[:, 1:], jumps, blend_s, fps, lever)
    blends = [Blend(j.t0, found[2][i], found[0][i], found[1][i], None, None, None) for i, j in enumerate(jumps)]
    previous = [blend] + blends[:-1]
    shown = old.copy()
    at = np.flatnonzero(prior)
    if at.size:
        rx = blends_at([previous[i] for i in at], 3, times[at].ravel(), positions=False)
        shown[at] = rot.mul(rot.exp(rx.reshape(at.size, 3, *rx.shape[1:])), old[at])
    same = (shown.view(np.uint64) == guess.view(np.uint64)).reshape(m, -1).all(axis=1) & batch
    for i in range(int(np.argmin(same)) if not same.all() else m, m):
        # One by one from here: the previous blend as it really is.
        if i and not same[i]:
            shown[i] = rot.mul(rot.exp(blends[i - 1].rot_at(times[i])), old[i])
        x0, v0, duration = _blend_rotations(shown[i:i + 1, 1:], new[i:i + 1, 1:], jumps[i:i + 1], blend_s, fps,
                                            lever)
        blends[i] = Blend(jumps[i].t0, duration[0], x0[0], v0[0], None, None, None)
        same[i + 1:] = False
    return blends, shown[:, 0]


def _chain_positions(root, jumps: list, times, feet, rotations: list, state: StitchState, blend_s: float,
                     fps: float):
    """Each jump's offset and whole blend (``rotations`` completed with its positions), as
    ``[(offset (2,), Blend)]``.

    ``root`` (m, 2, 3, 3) holds each jump's root positions as placed without an offset: the old
    motion's at (t0, its last two frames), the new one's at (t0, its first two). Jump by jump: each
    places the new motion where the previous one put the old motion, shown with the previous blend's
    position offsets (unlike its rotations, often still running a beat later).
    """
    new_at_t0 = _shifted(root[:, 1, 0], np.zeros(2))
    out, offset, blend = [], state.offset, state.blend
    for i, jump in enumerate(jumps):
        old = _shifted(root[i, 0], offset)
        unblended = old[0]
        if blend is not None:
            old = old + blend.pos_at(times[i])
        if jump.planted.any():
            old_feet, new_feet = feet(i, old[0], new_at_t0[i], [side for side in range(2) if jump.planted[side]])
            offset = (old_feet - new_feet).mean(axis=0)[[0, 2]]
        else:
            offset = unblended[[0, 2]] - new_at_t0[i, [0, 2]]
        p0, pv0, duration = _blend_positions(old[1:], _shifted(root[i, 1, 1:], offset), jump, blend_s, fps)
        r = rotations[i]
        blend = Blend(r.t0, r.duration, r.rot_x0, r.rot_v0, duration, p0, pv0)
        out.append((offset, blend))
    return out


def _feet_steps(style: Style, ankles, jumps: list, old, new):
    """Forward kinematics of the ankles of the poses ``old`` and ``new`` (m, J, 4) at each jump, split so
    that the root's position can come later: the chain's global rotations and rotated bone offsets are
    found for all jumps at once, and ``feet(i, old_root, new_root, sides)`` sums them from the roots, in
    the order ``kinematics.fk`` does (the same numbers). Returns ``feet``."""
    sk = style.skeleton
    sides = sorted({side for j in jumps for side in range(2) if j.planted[side]})
    if not sides:
        return None
    chains = {}
    for side in sides:
        chain, j = [], ankles[side]
        while sk.parents[j] >= 0:
            chain.append(j)
            j = sk.parents[j]
        chains[side] = chain[::-1]  # from the root's child down to the ankle
    joints = sorted({j for c in chains.values() for j in c})
    column = {j: c for c, j in enumerate(joints)}
    # Global rotations down to the ankles by kinematics.fk (its positions are summed below instead,
    # from the roots), and each joint's bone turned by its parent's.
    poses = np.concatenate([old, new])
    g_rot, _ = fk(poses, np.zeros(poses.shape[:-2] + (3,)), sk.offsets, sk.parents, only=[ankles[s] for s in sides])
    bones = rot.apply(g_rot[:, [sk.parents[j] for j in joints]], sk.offsets[joints])
    bones = bones.reshape(2, len(jumps), len(joints), 3)  # (old/new, jump, joint, 3)

    def feet(i, old_root, new_root, on):
        out = []
        for side in on:
            pos = np.stack([old_root, new_root])
            for j in chains[side]:
                pos = pos + bones[:, i, column[j]]
            out.append(pos)
        return np.stack(out, axis=1)  # (old/new, sides, 3)

    return feet


def _after(state: StitchState, pieces: Pieces, k: int, end_rate: np.ndarray) -> StitchState:
    """``state`` with piece ``k`` as the last one played."""
    return replace(state, last_f0=float(pieces.f0[k]), last_f1=float(pieces.f1[k]), last_t0=float(pieces.t0[k]),
                   last_t1=float(pieces.t1[k]), last_end_rate=float(end_rate[k]))


def render(style: Style, pieces: Pieces, state: StitchState, *, fps: float, end_s: float,
           blend_s: float = 0.3, inclusive_end: bool = False, roles: JointRoles | None = None,
           limb_speed: float | None = None):
    """Render output frames ``state.next_frame ...`` up to time ``end_s``.

    ``limb_speed``: the fastest (m/s) a jump's decay may move the end of a limb by itself: a large offset
    then decays over longer (``unhurried``), so a stitch between different poses does not whip the limb
    across. None: each decay as short as ``blend_s`` and the acceleration limit allow.

    ``roles``: the style's ``find_roles``, when the caller keeps them (else found here).
    Returns ``(state, Rendered)``.
    """
    k_pieces = len(pieces)
    start_rate, end_rate = pieces.end_rates()
    st = state
    if k_pieces and st.last_f1 is None:
        # The very first piece: start at the origin, facing +Z.
        f0 = float(pieces.f0[0])
        yaw = float(-rot.heading(style.local_rot[int(f0), 0].astype(float)))
        _, root, _ = _place(style, [f0], yaw, np.zeros(2))
        st = replace(st, yaw=yaw, offset=-root[0, [0, 2]])
    jumps = _jumps_of(style, pieces, st, st.yaw, start_rate, end_rate, fps)
    # Each piece's turn: the last placement's before it (a jump keeps the old heading, so all are
    # known now; where each jump stands on the floor is found below).
    yaws = np.full(k_pieces, st.yaw)
    for k, jump in jumps.items():
        yaws[k:] = jump.yaw

    # Output frames in this call's time range.
    last = int(np.floor(end_s * fps + 1e-9))
    if not inclusive_end and last / fps >= end_s - 1e-9:
        last -= 1
    idx = np.arange(state.next_frame, last + 1)
    t = idx / fps
    k = np.clip(np.searchsorted(pieces.t1, t, side="right"), 0, k_pieces - 1)
    u = (t - pieces.t0[k]) / (pieces.t1[k] - pieces.t0[k])
    u = pieces.show(u, k)
    src = pieces.f0[k] + u * (pieces.f1[k] - pieces.f0[k])
    clip = style.clip_of_frame(pieces.f0.astype(np.int64))[k]
    src = np.clip(src, style.clip_starts[clip], style.clip_starts[clip + 1] - 1)

    # The frames the jumps are measured on and the output frames, sampled and turned together.
    n = len(idx)
    jump_frames, jump_yaws = _jump_frames(jumps)
    local, root, contacts = _place(style, np.r_[jump_frames, src], np.r_[jump_yaws, yaws[k]])
    ankles = (roles or find_roles(style.skeleton)).ankles if jumps else None
    placed = dict(zip(jumps, _place_jumps(style, jumps, local[:len(jump_frames)], root[:len(jump_frames)], st,
                                          ankles, blend_s, fps, limb_speed)))
    offsets = np.empty((k_pieces, 2))
    blends: list[tuple[float, Blend | None]] = [(-np.inf, st.blend)]
    offset = st.offset  # the placement in force: the last jump's before each piece
    for kk in range(k_pieces):
        if kk in placed:
            offset, blend = placed[kk]
            blends.append((blend.t0, blend))
        offsets[kk] = offset
    if placed:
        st = replace(st, yaw=jumps[max(placed)].yaw, offset=offset, blend=blends[-1][1])
    if k_pieces:
        st = _after(st, pieces, k_pieces - 1, end_rate)
    raw_local, raw_root, contacts = local[len(jump_frames):], root[len(jump_frames):], contacts[len(jump_frames):]
    raw_root[:, [0, 2]] += offsets[k]
    local, root = raw_local.copy(), raw_root.copy()
    # Each frame shows the blend of the last jump before it (if any): each blend's offsets on its
    # frames (a run of them), then all applied at once.
    bounds = np.searchsorted(t, [b[0] for b in blends] + [np.inf], side="left")
    bounds[0] = 0
    first = 0 if blends[0][1] is not None else bounds[1]  # frames from here on show a blend
    if first < n:
        shown = [(blend, hi - lo) for (_, blend), lo, hi in zip(blends, bounds[:-1], bounds[1:])
                 if blend is not None and hi > lo]
        rx, px = blends_at([blend for blend, _ in shown], [count for _, count in shown], t[first:])
        local[first:] = rot.mul(rot.exp(rx), local[first:])
        root[first:] += px
    final_blend = blends[-1][1]
    if final_blend is not None and (n == 0 or t[-1] >= final_blend.end_s):
        final_blend = None
    st = replace(st, next_frame=int(last + 1), blend=final_blend)
    # A new placement starts on the first frame of every piece that begins with a jump.
    jumped = np.flatnonzero(pieces.jump)
    new_run = np.zeros(n, dtype=bool)
    if n:
        first_frame = np.searchsorted(t, pieces.t0[jumped] - 1e-9)
        new_run[first_frame[first_frame < n]] = True
    return st, Rendered(local, root, contacts, src, raw_local, raw_root, new_run)

"""Turn a sequence of beat-to-beat source pieces into continuous motion.

Every piece plays source frames ``f0 -> f1`` of a style's flat arrays during the
music interval ``t0 -> t1``, time-warped linearly so that the source beat frames
land exactly on the music beats (Xu et al.: "modifying the frame rate between two
nodes"). Where the source changes (a jump), the new motion is

- re-placed on the floor: rotated about the vertical axis to the old heading and
  shifted so that it stands on the old motion's planted foot (or, with no foot
  planted in both, so that its root continues from the old root), and
- blended in by *inertialization*: the pose and velocity difference between the
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
from ..errors import InputError
from ..kinematics import fk
from ..motion.database import Style
from ..motion.resample import sample_frames
from ..motion.roles import find_roles


@dataclass(frozen=True)
class Pieces:
    """K beat-to-beat pieces: music interval [t0, t1) shows source frames [f0, f1].

    ``count0``/``count1``: the music beats counted at t0 and t1 (``BeatGrid.count``; a piece
    on a subdivided grid spans half a beat, on a merged one two). None: one beat each.
    ``ease0``/``ease1``: how much the accent timing (``ease``) slows the motion on the beat
    at t0 and at t1. None: no easing, each piece at one rate (the paper).
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


def ease(u, count0, count1, ease0, ease1):
    """Accent timing: where within a piece (``u`` = 0..1 of its music time) its source is shown.

    Played linearly, a piece moves as fast on the beat as between beats, and the beat
    goes by unseen wherever the mocap does not happen to stop there. Eased, the playback
    rate follows ``1 - a(c) cos(2 pi c)`` of the music's beat count ``c``, normalised so
    the piece keeps its length: slower on each beat, faster between. The motion settles
    into every beat and springs out of it -- the accent by speed that Loi & Li give the
    hands on each beat, what a dancer does when "hitting" the count. ``a`` runs linearly
    from ``ease0`` at the piece's start to ``ease1`` at its end, so a beat can be hit
    harder than its neighbours (the bar's "1"). Piece ends stay put: the source beat
    frames still land exactly on their beats. ``ease0 = ease1 = 0`` is linear.
    """
    shown, _ = _timing(u, count0, count1, ease0, ease1)
    return shown


def ease_rate(u, count0, count1, ease0, ease1):
    """d ease / d u: the playback rate at ``u`` relative to the piece's mean rate."""
    _, rate = _timing(u, count0, count1, ease0, ease1)
    return rate


def beat_ease(n: int, bar_position=None, beats_per_bar: int | None = None, *, amount: float,
              downbeat: float = 0.0) -> np.ndarray:
    """How hard ``ease`` hits each of ``n`` grid beats: ``amount``, plus ``downbeat`` on a bar's
    first beat, so the "1" is the bar's strongest accent. (Taking as much off the other beats, so
    that a bar kept its mean, cost them their stops: precision 0.62 against 0.69.) Beats of
    unknown position get ``amount``. Each must stay below 1: at 1 the motion halts on the beat,
    above it would run backwards."""
    if not (0.0 <= amount and 0.0 <= downbeat and amount + downbeat < 1.0):
        raise InputError(f"accent timing needs 0 <= ease_beats, 0 <= ease_downbeat and their sum < 1, got "
                         f"{amount} and {downbeat}")
    out = np.full(n, float(amount))
    if bar_position is None or not beats_per_bar or beats_per_bar < 2 or downbeat == 0:
        return out
    out[np.asarray(bar_position) == 0] += downbeat
    return out


def _timing(u, count0, count1, ease0, ease1):
    """``(ease, ease_rate)`` at ``u``: ``F(u) / F(1)`` and ``span * (1 - a(c) cos 2 pi c) / F(1)``, with
    ``F(u)`` the integral of ``1 - a(c) cos(2 pi c) dc`` from the piece's start, in beats counted from
    the start's whole beat (the wave repeats every beat). Pieces of no span play linearly."""
    u = np.asarray(u, dtype=np.float64)
    c0 = np.asarray(count0, dtype=np.float64)
    span = np.asarray(count1, dtype=np.float64) - c0
    safe = np.where(span > 0, span, 1.0)
    start = c0 - np.floor(c0)
    slope = (np.asarray(ease1, dtype=np.float64) - ease0) / safe  # a(c) = base + slope * c, locally
    base = ease0 - slope * start

    def integral(x):  # x minus the integral of (base + slope c) cos(2 pi c) dc, from start to x
        return x - start - (_wave_integral(x, base, slope) - _wave_integral(start, base, slope))

    c = start + span * u
    total = np.where(span > 0, integral(start + span), 1.0)
    shown = np.where(span > 0, integral(c) / total, u)
    rate = np.where(span > 0, span * (1.0 - (base + slope * c) * np.cos(2 * np.pi * c)) / total, 1.0)
    return shown, rate


def _wave_integral(x, base, slope):
    """Integral of ``(base + slope c) cos(2 pi c) dc`` from 0 to ``x``."""
    w = 2 * np.pi * x
    return base * np.sin(w) / (2 * np.pi) + slope * (x * np.sin(w) / (2 * np.pi) + (np.cos(w) - 1) / (4 * np.pi ** 2))


#: Fastest angular acceleration an inertialization decay may add (rad/s^2): about what
#: the mocap itself reaches in its roughest 1 % of frames, so a decay hides in the motion.
BLEND_ACCEL_RAD_S2 = 300.0
#: Same for the root's position (m/s^2), across the floor and up or down: the body may glide
#: over a planted foot for a while, but a height difference held long sinks the feet into the
#: floor or lifts them off it.
BLEND_ACCEL_M_S2 = np.array([6.0, 30.0, 6.0])
#: No decay lasts longer (s): past this the two motions are mixed for too long.
BLEND_MAX_S = 1.0
#: How far a carried velocity difference may swing a joint past its offset before the
#: decay brings it back (rad): more of a violent difference is dropped instead, so it
#: cannot overshoot into a pose neither motion has.
BLEND_MAX_SWING_RAD = 0.6


@dataclass(frozen=True)
class Blend:
    """An inertialization offset starting at ``t0``: value and velocity, decaying to zero.

    Rotations decay per joint over ``duration`` (J,), the root position per axis over ``pos_duration`` (3,).
    """

    t0: float
    duration: np.ndarray  # (J,) seconds
    rot_x0: np.ndarray    # (J, 3) rotation-vector offsets
    rot_v0: np.ndarray
    pos_duration: np.ndarray  # (3,) seconds
    pos_x0: np.ndarray    # (3,) root position offset
    pos_v0: np.ndarray

    @property
    def end_s(self) -> float:
        return self.t0 + max(float(np.max(self.duration)), float(np.max(self.pos_duration)))

    def at(self, t: np.ndarray):
        dt = np.asarray(t, float)[:, None] - self.t0
        h00, h10 = decay_basis(np.clip(dt / self.duration, 0.0, 1.0))            # (n, J)
        rx = h00[..., None] * self.rot_x0 + (h10 * self.duration)[..., None] * self.rot_v0
        p00, p10 = decay_basis(np.clip(dt / self.pos_duration, 0.0, 1.0))      # (n, 3)
        return rx, p00 * self.pos_x0 + p10 * self.pos_duration * self.pos_v0


def carried_speed(size, accel, swing):
    """Fastest velocity difference a decay of an offset of ``size`` carries.

    A Hermite decay over ``T`` that starts at speed ``v`` swings past its offset by
    up to ``4/27 v T``; with ``T = decay_time(size, v)`` that is ``swing`` at::

        v = 2 sqrt(accel) swing / sqrt(24 k^2 size + 16 k swing),  k = 4/27
    """
    k = 4.0 / 27.0
    return 2.0 * np.sqrt(accel) * swing / np.sqrt(24 * k * k * np.asarray(size, float) + 16 * k * swing)


def decay_time(size, speed, min_s: float, accel):
    """Shortest decay time (>= ``min_s``, <= ``BLEND_MAX_S``) whose Hermite curve from an offset
    of ``size`` moving at ``speed`` never accelerates faster than ``accel``.

    The curve's acceleration peaks at its start, ``(6 size + 4 T speed) / T^2``; solved for T.
    """
    size, speed = np.asarray(size, float), np.asarray(speed, float)
    t = (4 * speed + np.sqrt(16 * speed**2 + 24 * accel * size)) / (2 * accel)
    low = max(min_s, 1e-3)  # a zero blend time would divide by zero
    return np.clip(t, low, max(low, BLEND_MAX_S))


def decay_basis(s):
    """Cubic Hermite weights ``(h00, h10)`` at ``s`` in [0, 1] that take an offset (value x0,
    velocity v0) to rest: ``x(s) = h00 x0 + h10 duration v0``, with x and x' zero at s = 1."""
    s = np.asarray(s, dtype=np.float64)
    return 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s


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


def _place(style: Style, frames, yaw: float, offset: np.ndarray):
    """Source poses at fractional ``frames``, placed on the floor by (yaw, offset)."""
    frames = np.atleast_1d(np.asarray(frames, dtype=np.float64))
    local, root, contacts = sample_frames(style.local_rot, style.root_pos, frames, style.contacts)
    turn = rot.about_y(np.full(len(frames), yaw))
    local = local.copy()
    local[:, 0] = rot.mul(turn, local[:, 0])
    root = rot.apply(turn, root)
    root[:, [0, 2]] += offset
    return local, root, contacts


def _clamp_frame(style: Style, f: float, near: float) -> float:
    """Keep an extrapolated source position inside the clip that contains ``near``."""
    c = int(style.clip_of_frame(int(near)))
    return float(np.clip(f, style.clip_starts[c], style.clip_starts[c + 1] - 1))


def _posed(style, frames, yaw, offset, blend, times):
    """Poses at source ``frames`` placed by (yaw, offset) and shown at ``times``, with ``blend`` applied."""
    local, root, _ = _place(style, frames, yaw, offset)
    if blend is not None:
        rx, px = blend.at(np.asarray(times, float))
        local = rot.mul(rot.exp(rx), local)
        root = root + px
    return local, root


def _shown(style, f_at, rate, t_ref, times, yaw, offset, blend):
    """Poses of a piece that shows source frame ``f_at`` at ``t_ref`` at ``rate``, at output ``times``."""
    frames = [_clamp_frame(style, f_at + rate * (t - t_ref), f_at) for t in times]
    return _posed(style, frames, yaw, offset, blend, times)


def _jump_blend(style, state: StitchState, f_new: float, rate_new: float, yaw, offset, t0, blend_s,
                fps: float) -> Blend:
    """The inertialization offset that carries the old motion's pose and velocity into the new one.

    Only frames that are shown enter it: the old motion's last two output frames
    before ``t0`` and the new one's first two, each extrapolated to ``t0`` at its
    own angular velocity (source frames past a piece's end are never shown, and
    mocap glitches there must not be blended in). The offset is ``log(old * new^-1)``
    per joint; its velocity is the offset's own rate of change, so decaying it in
    rotation-vector space keeps the shown angular velocity continuous however far
    apart the poses are.
    """
    dt = 1.0 / fps
    t_new = np.ceil(t0 * fps - 1e-9) / fps + np.array([0.0, dt])   # a frame at t0 shows the new piece
    t_old = t_new[0] - np.array([2 * dt, dt])
    rate_old = (state.last_f1 - state.last_f0) / (state.last_t1 - state.last_t0) * state.last_end_rate
    old, old_root = _shown(style, state.last_f1, rate_old, t0, t_old, state.yaw, state.offset, state.blend)
    new, new_root = _shown(style, f_new, rate_new, t0, t_new, yaw, offset, None)
    w_old = rot.log(rot.mul(old[1], rot.inv(old[0]))) / dt
    w_new = rot.log(rot.mul(new[1], rot.inv(new[0]))) / dt

    def offset_at(t):
        o = rot.mul(rot.exp(w_old * (t - t_old[1])), old[1])
        n = rot.mul(rot.exp(w_new * (t - t_new[0])), new[0])
        return rot.log(rot.mul(o, rot.inv(n)))

    eps = 1e-3 * dt
    x0 = offset_at(t0)
    v0 = (offset_at(t0 + eps) - offset_at(t0 - eps)) / (2 * eps)
    # Near 180 degrees the rotation vector wraps: no velocity there rather than a wrong one.
    v0[np.linalg.norm(v0, axis=-1) * eps > 1.0] = 0.0
    size, speed = np.linalg.norm(x0, axis=-1), np.linalg.norm(v0, axis=-1)
    carried = np.minimum(speed, carried_speed(size, BLEND_ACCEL_RAD_S2, BLEND_MAX_SWING_RAD))
    v0 *= (carried / np.maximum(speed, 1e-9))[:, None]
    duration = decay_time(size, carried, blend_s, BLEND_ACCEL_RAD_S2)
    v_old, v_new = (old_root[1] - old_root[0]) / dt, (new_root[1] - new_root[0]) / dt
    p0 = old_root[1] + v_old * (t0 - t_old[1]) - new_root[0] - v_new * (t0 - t_new[0])
    pv0 = v_old - v_new
    across, up = [0, 2], [1]
    pos_duration = np.empty(3)
    for axes in (across, up):
        pos_duration[axes] = decay_time(np.linalg.norm(p0[axes]), np.linalg.norm(pv0[axes]), blend_s,
                                        BLEND_ACCEL_M_S2[axes[0]])
    return Blend(float(t0), duration, x0, v0, pos_duration, p0, pv0)


def _aligned_placement(style, state: StitchState, f_new: float, t0: float):
    """(yaw, offset) that puts source frame ``f_new`` where the old motion is at ``t0``, same heading.

    Where a foot is planted in both motions, the new motion stands on the old one's
    planted foot (both feet: their midpoint): the blend then moves the body over the
    foot instead of dragging the foot, which the foot lock would otherwise have to
    hold against a growing offset. Else the root continues from the old root.
    """
    old_yaw = state.yaw + rot.heading(style.local_rot[int(round(state.last_f1)), 0].astype(float))
    new_yaw = rot.heading(style.local_rot[int(round(f_new)), 0].astype(float))
    yaw = float(old_yaw - new_yaw)
    planted = style.contacts[int(round(state.last_f1))] & style.contacts[int(round(f_new))]
    if planted.any():
        ankles = [a for a, p in zip(find_roles(style.skeleton).ankles, planted) if p]
        sk = style.skeleton
        old, old_root = _posed(style, [state.last_f1], state.yaw, state.offset, state.blend, [t0])
        new, new_root = _posed(style, [f_new], yaw, np.zeros(2), None, [t0])
        old_feet = fk(old, old_root, sk.offsets, sk.parents, only=ankles)[1][0, ankles]
        new_feet = fk(new, new_root, sk.offsets, sk.parents, only=ankles)[1][0, ankles]
        return yaw, (old_feet - new_feet).mean(axis=0)[[0, 2]]
    _, old_root, _ = _place(style, [state.last_f1], state.yaw, state.offset)
    _, new_root, _ = _place(style, [f_new], yaw, np.zeros(2))
    return yaw, old_root[0, [0, 2]] - new_root[0, [0, 2]]


def render(style: Style, pieces: Pieces, state: StitchState, *, fps: float, end_s: float,
           blend_s: float = 0.3, inclusive_end: bool = False):
    """Render output frames ``state.next_frame ...`` up to time ``end_s``.

    Returns ``(state, Rendered)``.
    """
    k_pieces = len(pieces)
    yaws = np.empty(k_pieces)
    offsets = np.empty((k_pieces, 2))
    blends: list[tuple[float, Blend | None]] = [(-np.inf, state.blend)]
    st = state
    for k in range(k_pieces):
        f0, f1, t0, t1 = float(pieces.f0[k]), float(pieces.f1[k]), float(pieces.t0[k]), float(pieces.t1[k])
        if st.last_f1 is None:
            # The very first piece: start at the origin, facing +Z.
            heading = rot.heading(style.local_rot[int(f0), 0].astype(float))
            yaw = float(-heading)
            _, root, _ = _place(style, [f0], yaw, np.zeros(2))
            offset = -root[0, [0, 2]]
            st = replace(st, yaw=yaw, offset=offset)
        elif pieces.jump[k]:
            yaw, offset = _aligned_placement(style, st, f0, t0)
            rate = (f1 - f0) / (t1 - t0) * float(ease_rate(0.0, *pieces.timing(k)))
            blend = _jump_blend(style, st, f0, rate, yaw, offset, t0, blend_s, fps)
            st = replace(st, yaw=yaw, offset=offset, blend=blend)
            blends.append((t0, blend))
        yaws[k], offsets[k] = st.yaw, st.offset
        st = replace(st, last_f0=f0, last_f1=f1, last_t0=t0, last_t1=t1,
                     last_end_rate=float(ease_rate(1.0, *pieces.timing(k))))

    # Output frames in this call's time range.
    last = int(np.floor(end_s * fps + 1e-9))
    if not inclusive_end and last / fps >= end_s - 1e-9:
        last -= 1
    idx = np.arange(state.next_frame, last + 1)
    t = idx / fps
    k = np.clip(np.searchsorted(pieces.t1, t, side="right"), 0, k_pieces - 1)
    u = (t - pieces.t0[k]) / (pieces.t1[k] - pieces.t0[k])
    u = ease(u, *pieces.timing(k))
    src = pieces.f0[k] + u * (pieces.f1[k] - pieces.f0[k])
    clip = style.clip_of_frame(pieces.f0.astype(np.int64))[k]
    src = np.clip(src, style.clip_starts[clip], style.clip_starts[clip + 1] - 1)

    n, n_joints = len(idx), style.skeleton.n_joints
    raw_local = np.empty((n, n_joints, 4))
    raw_root = np.empty((n, 3))
    contacts = np.zeros((n, 2), dtype=bool)
    for kk in np.unique(k):
        sel = k == kk
        raw_local[sel], raw_root[sel], contacts[sel] = _place(style, src[sel], yaws[kk], offsets[kk])
    local, root = raw_local.copy(), raw_root.copy()
    starts = np.array([b[0] for b in blends])
    which = np.searchsorted(starts, t, side="right") - 1
    for b_i, (_, blend) in enumerate(blends):
        sel = which == b_i
        if blend is None or not sel.any():
            continue
        rx, px = blend.at(t[sel])
        local[sel] = rot.mul(rot.exp(rx), local[sel])
        root[sel] += px
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

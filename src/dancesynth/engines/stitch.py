"""Turn a sequence of beat-to-beat source pieces into continuous motion.

Every piece plays source frames ``f0 -> f1`` of a style's flat arrays during the
music interval ``t0 -> t1``, time-warped linearly so that the source beat frames
land exactly on the music beats (Xu et al.: "modifying the frame rate between two
nodes"). Where the source changes (a jump), the new motion is

- re-placed on the floor: rotated about the vertical axis and shifted so that its
  root continues from where the old one was, with the same heading, and
- blended in by *inertialization*: the pose and velocity difference between the
  old and the new motion at the jump decays to zero over ``blend_s`` with a cubic
  Hermite curve, so position and velocity stay continuous.

Rendering is incremental (``StitchState`` carries the placement and any blend in
progress), so the streaming engine can render segment by segment and a segment
boundary is as seamless as any other beat.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .. import rotations as rot
from ..motion.database import Style
from ..motion.resample import sample_frames


@dataclass(frozen=True)
class Pieces:
    """K beat-to-beat pieces: music interval [t0, t1) shows source frames [f0, f1]."""

    t0: np.ndarray
    t1: np.ndarray
    f0: np.ndarray
    f1: np.ndarray
    jump: np.ndarray  # the piece starts somewhere else than the previous piece ended

    def __len__(self) -> int:
        return len(self.t0)


@dataclass(frozen=True)
class Blend:
    """An inertialization offset starting at ``t0``: value and velocity, decaying over ``duration``."""

    t0: float
    duration: float
    rot_x0: np.ndarray  # (J, 3) rotation-vector offsets
    rot_v0: np.ndarray
    pos_x0: np.ndarray  # (3,) root position offset
    pos_v0: np.ndarray

    def at(self, t: np.ndarray):
        s = np.clip((np.asarray(t, float) - self.t0) / self.duration, 0.0, 1.0)[:, None]
        h00 = 2 * s**3 - 3 * s**2 + 1
        h10 = (s**3 - 2 * s**2 + s) * self.duration
        return (h00[..., None] * self.rot_x0 + h10[..., None] * self.rot_v0,
                h00 * self.pos_x0 + h10 * self.pos_v0)


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


def _velocity_pair(style, f_a, f_b, yaw, offset, blend, t_a, t_b):
    """Poses at source frames ``f_a`` and ``f_b`` (shown at ``t_a``, ``t_b``), with ``blend`` applied."""
    local, root, _ = _place(style, [f_a, f_b], yaw, offset)
    if blend is not None:
        rx, px = blend.at(np.array([t_a, t_b]))
        local = rot.mul(rot.exp(rx), local)
        root = root + px
    return local, root


def _jump_blend(style, state: StitchState, f_new: float, rate_new: float, yaw, offset, t0, blend_s) -> Blend:
    """The inertialization offset that carries the old motion's pose and velocity into the new one."""
    h = 1.0 / style.fps
    rate_old = (state.last_f1 - state.last_f0) / (state.last_t1 - state.last_t0)
    f_old_prev = _clamp_frame(style, state.last_f1 - rate_old * h, state.last_f1)
    old, old_root = _velocity_pair(style, f_old_prev, state.last_f1, state.yaw, state.offset,
                                   state.blend, t0 - h, t0)
    f_new_next = _clamp_frame(style, f_new + rate_new * h, f_new)
    new, new_root = _velocity_pair(style, f_new, f_new_next, yaw, offset, None, t0, t0 + h)
    x0 = rot.log(rot.mul(old[1], rot.inv(new[0])))
    v_old = rot.log(rot.mul(old[1], rot.inv(old[0]))) / h
    v_new = rot.log(rot.mul(new[1], rot.inv(new[0]))) / h
    v0 = v_old - v_new
    # Cap the velocity term so a violent difference cannot overshoot into a new pose.
    cap = 1.0 / blend_s
    scale = np.minimum(1.0, cap / np.maximum(np.linalg.norm(v0, axis=-1, keepdims=True), 1e-9))
    p0 = old_root[1] - new_root[0]
    pv0 = (old_root[1] - old_root[0]) / h - (new_root[1] - new_root[0]) / h
    return Blend(float(t0), blend_s, x0, v0 * scale, p0, pv0)


def _aligned_placement(style, state: StitchState, f_new: float):
    """(yaw, offset) that puts source frame ``f_new`` where the old motion's last frame is, same heading."""
    _, old_root, _ = _place(style, [state.last_f1], state.yaw, state.offset)
    old_yaw = state.yaw + rot.heading(style.local_rot[int(round(state.last_f1)), 0].astype(float))
    new_yaw = rot.heading(style.local_rot[int(round(f_new)), 0].astype(float))
    yaw = float(old_yaw - new_yaw)
    _, new_root, _ = _place(style, [f_new], yaw, np.zeros(2))
    offset = old_root[0, [0, 2]] - new_root[0, [0, 2]]
    return yaw, offset


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
            yaw, offset = _aligned_placement(style, st, f0)
            blend = _jump_blend(style, st, f0, (f1 - f0) / (t1 - t0), yaw, offset, t0, blend_s)
            st = replace(st, yaw=yaw, offset=offset, blend=blend)
            blends.append((t0, blend))
        yaws[k], offsets[k] = st.yaw, st.offset
        st = replace(st, last_f0=f0, last_f1=f1, last_t0=t0, last_t1=t1)

    # Output frames in this call's time range.
    last = int(np.floor(end_s * fps + 1e-9))
    if not inclusive_end and last / fps >= end_s - 1e-9:
        last -= 1
    idx = np.arange(state.next_frame, last + 1)
    t = idx / fps
    k = np.clip(np.searchsorted(pieces.t1, t, side="right"), 0, k_pieces - 1)
    u = (t - pieces.t0[k]) / (pieces.t1[k] - pieces.t0[k])
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
    if final_blend is not None and (n == 0 or t[-1] >= final_blend.t0 + final_blend.duration):
        final_blend = None
    st = replace(st, next_frame=int(last + 1), blend=final_blend)
    # A new placement starts on the first frame of every piece that begins with a jump.
    jumped = np.flatnonzero(pieces.jump)
    new_run = np.zeros(n, dtype=bool)
    if n:
        first_frame = np.searchsorted(t, pieces.t0[jumped] - 1e-9)
        new_run[first_frame[first_frame < n]] = True
    return st, Rendered(local, root, contacts, src, raw_local, raw_root, new_run)

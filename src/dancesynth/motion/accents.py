"""Visible accents: where a viewer sees the dance mark a beat.

A motion beat found by short-term PCA (``beats.pca_beats``) is where the dominant
movement turns; a viewer reads a dance's accents elsewhere: where the body stops,
the local minima of the summed joint speed (``beats.kinematic_beats``, the same
detector the evaluation uses). In the bundled mocap only about 40 % of the speed
minima fall within 0.15 beat of a PCA beat, and the rest lie at any phase of the
beat, so rendering PCA beats on music beats leaves most visible stops between
beats (the dance scores 1.2-2x chance).

``accent_beats`` moves each motion beat to the most prominent stop near it (the
frame the renderer then puts on the music beat) and says, per beat, how visible
that stop is and how strongly the motion up to the next beat stops *between*
beats. The graph search uses both to prefer beat pieces that stop on their beats
and nowhere else, and ``foot_slide`` to prefer pieces whose feet stay put.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import rotations as rot
from ..kinematics import fk
from ..types import MotionClip
from .beats import kinematic_beats, summed_speed
from .features import CONTACT_HEIGHT_M, foot_points
from .roles import find_roles


@dataclass(frozen=True)
class AccentBeats:
    """Per motion beat (the style's ``beat_frames`` order)."""

    frame: np.ndarray      # (B,) int64 frame of the beat's visible stop (the beat frame where there is none)
    strength: np.ndarray   # (B,) prominence of that stop, 1 = the style's median stop, 0 = none
    offbeat: np.ndarray    # (B,) summed strength of the stops between this beat and the next in its clip
    slide: np.ndarray      # (B,) how much the piece to the next beat slides its feet (``foot_slide``), 1 = mean


@dataclass(frozen=True)
class AccentCosts:
    """Beyond the paper: make the beats a viewer sees land on the music's beats.

    Added to a step's cost: ``unaccented * (1 - strength)`` when the node it arrives at
    shows no clear stop (``strength`` 1 = the style's median stop), ``offbeat * min(s, 2)``
    for the stops ``s`` its piece makes between beats, ``slide`` times the piece's foot
    sliding (``foot_slide``, 1 = the style's mean piece) where it is known, and ``warp`` per unit of
    ``|ln rate|`` beyond ``free_warp`` (a piece played much faster or slower than
    captured looks wrong and moves its stops), ``far_warp`` more beyond 0.8-1.25x.
    """

    unaccented: float = 1.0
    offbeat: float = 1.0
    slide: float = 0.0
    warp: float = 6.0
    free_warp: float = 0.1
    far_warp: float = 10.0       # and this much more per unit of |ln rate| beyond ``warp_limit``
    warp_limit: float = 0.223    # ln 1.25: past 0.8x-1.25x a piece no longer looks like itself

    def warp_cost(self, log_rate: np.ndarray) -> np.ndarray:
        """The cost of playing pieces at ``exp(log_rate)`` times their captured speed."""
        off = np.abs(log_rate)
        return (self.warp * np.maximum(off - self.free_warp, 0.0)
                + self.far_warp * np.maximum(off - self.warp_limit, 0.0))

    def beat_costs(self, strength: np.ndarray, offbeat: np.ndarray,
                   slide: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Per beat: the cost of arriving at it, and of playing the piece from it to the next."""
        played = self.offbeat * np.minimum(offbeat, 2.0)
        if slide is not None and self.slide:
            played = played + self.slide * slide
        return self.unaccented * np.maximum(1.0 - strength, 0.0), played


def _clip_poses(style):
    """``(start, end, global rotations, global positions)`` of each clip of ``style``, one at a time
    (a large style need not sit in memory as global poses)."""
    sk = style.skeleton
    for c in range(style.n_clips):
        a, b = int(style.clip_starts[c]), int(style.clip_starts[c + 1])
        g_rot, g_pos = fk(style.local_rot[a:b].astype(np.float64), style.root_pos[a:b].astype(np.float64),
                          sk.offsets, sk.parents)
        yield a, b, g_rot, g_pos


def visible_accents(style) -> tuple[np.ndarray, np.ndarray]:
    """Flat frames of every speed minimum of ``style`` and its prominence / the clip's mean speed."""
    from scipy import signal  # costs ~0.8 s to import; only analysis needs it

    frames, strength = [], []
    for a, _, _, pos in _clip_poses(style):
        found, smooth = kinematic_beats(summed_speed(pos, style.fps), style.fps)
        if found.size:
            frames.append(found + a)
            strength.append(signal.peak_prominences(-smooth, found)[0] / max(float(np.mean(smooth)), 1e-9))
    if not frames:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    return np.concatenate(frames).astype(np.int64), np.concatenate(strength)


def accent_beats(style, *, window: float = 0.35, margin: float = 0.15) -> AccentBeats:
    """Each motion beat of ``style`` moved to its most visible stop within ``window`` of a beat period.

    A stop is preferred for its prominence, less so the farther it is (so of two
    equal stops the nearer wins). Beats keep their order: where two beats would take
    one stop, or cross, both stay where they were. ``offbeat`` counts the stops that
    lie between a beat's stop and the next beat's, more than ``margin`` of a beat
    from either: they will be seen off the beat. ``window=0`` keeps the beats.
    """
    beats = np.asarray(style.beat_frames, dtype=np.int64)
    n = beats.size
    out = beats.copy()
    strength = np.zeros(n)
    offbeat = np.zeros(n)
    if n < 2:
        return AccentBeats(out, strength, offbeat, np.zeros(n))
    acc, prom = visible_accents(style)
    if acc.size:
        prom = prom / max(float(np.median(prom)), 1e-9)
    clip = style.clip_of_frame(beats)
    acc_clip = style.clip_of_frame(acc)
    same_next = np.r_[clip[1:] == clip[:-1], False]
    gaps = np.diff(beats).astype(np.float64)
    period = np.where(same_next, np.r_[gaps, 0.0], 0.0)
    prev_ok = np.r_[False, same_next[:-1]]
    period = np.where(period > 0, period, np.where(prev_ok, np.r_[0.0, gaps], 1.0))
    if window > 0 and acc.size:
        reach = window * period
        lo = np.searchsorted(acc, beats - reach, side="left")
        hi = np.searchsorted(acc, beats + reach, side="right")
        for i in np.flatnonzero(hi > lo):
            cand = np.arange(lo[i], hi[i])
            cand = cand[acc_clip[cand] == clip[i]]
            if not cand.size:
                continue
            score = prom[cand] * (1.0 - 0.5 * np.abs(acc[cand] - beats[i]) / reach[i])
            best = cand[np.argmax(score)]
            out[i], strength[i] = acc[best], prom[best]
        clash = same_next[:-1] & (np.diff(out) <= 0)
        bad = np.r_[clash, False] | np.r_[False, clash]
        out[bad], strength[bad] = beats[bad], 0.0
    elif acc.size:  # no moving: a beat is accented when a stop sits on it
        at = np.searchsorted(acc, beats)
        hit = (at < acc.size) & (acc[np.minimum(at, acc.size - 1)] == beats)
        strength[hit] = prom[at[hit]]
    if acc.size:
        for i in np.flatnonzero(same_next):
            edge = margin * period[i]
            a, b = np.searchsorted(acc, [out[i] + edge, out[i + 1] - edge], side="right")
            offbeat[i] = prom[a:b].sum() if b > a else 0.0
    slide = np.zeros(n)
    per_frame = np.r_[0.0, np.cumsum(foot_slide(style))]
    span = np.where(same_next, np.r_[np.diff(out), 0], 0)
    ok = span > 0
    slide[ok] = (per_frame[out[ok] + span[ok]] - per_frame[out[ok]]) / span[ok]
    if ok.any() and slide[ok].mean() > 0:
        slide /= slide[ok].mean()
    return AccentBeats(out, strength, offbeat, slide)


def foot_slide(style) -> np.ndarray:
    """(F,) per frame of ``style``: the foot motion a foot lock cannot hold, each term 1 = its style mean.

    The renderer holds a planted foot (``style.contacts``) where it landed, so what a viewer
    still sees slide is a foot near the floor that the capture does not call planted (its
    horizontal speed, the floor foot speed the evaluation measures) and both feet moving
    while the body accelerates (the product EDGE's PFC scores). The floor is the clip's
    median lowest foot point, as the evaluation takes it.
    """
    sk, fps = style.skeleton, style.fps
    roles = find_roles(sk)
    low_speed = np.zeros(style.n_frames)
    both = np.zeros(style.n_frames)
    for a, b, g_rot, g_pos in _clip_poses(style):
        if b - a < 3:
            continue
        local, root = style.local_rot[a:b].astype(np.float64), style.root_pos[a:b].astype(np.float64)
        feet = foot_points(MotionClip(sk, fps, root, local), roles, g_rot, g_pos)
        speed = np.linalg.norm(np.gradient(feet[..., [0, 2]], axis=0), axis=-1).min(axis=2) * fps  # (F, 2)
        height = feet[..., 1].min(axis=2)
        free = ~np.asarray(style.contacts[a:b], dtype=bool)
        low = height <= np.median(height.min(axis=1)) + CONTACT_HEIGHT_M
        low_speed[a:b] = np.where(low & free, speed, 0.0).sum(axis=1)
        accel = np.gradient(np.gradient(root, axis=0), axis=0) * fps * fps
        accel[:, 1] = np.maximum(accel[:, 1], 0.0)  # falling needs no support
        loose = np.where(free, speed, 0.0)
        both[a:b] = loose[:, 0] * loose[:, 1] * np.linalg.norm(accel, axis=1)
    return low_speed / max(low_speed.mean(), 1e-9) + both / max(both.mean(), 1e-9)


def cached_accent_beats(style, *, window: float = 0.35) -> AccentBeats:
    """``accent_beats`` kept on disk by the style's fingerprint (finding the stops runs forward
    kinematics over the whole style, seconds for a large one; every dance needs them)."""
    z = _cached(style, f"{window:g}", lambda: vars(accent_beats(style, window=window)))
    return AccentBeats(z["frame"], z["strength"], z["offbeat"], z["slide"])


def peak_speeds(style) -> np.ndarray:
    """(F,) per frame of ``style``: its fastest joint's speed (m/s) as captured, the faster of the
    steps into and out of the frame. What the accent timing may not push past the style's own
    fast frames (``timing.SpeedRoom``)."""
    out = np.zeros(style.n_frames)
    for a, b, _, pos in _clip_poses(style):
        if b - a < 2:
            continue
        step = np.linalg.norm(np.diff(pos, axis=0), axis=-1).max(axis=1) * style.fps
        out[a:b] = np.maximum(np.r_[step[0], step], np.r_[step, step[-1]])
    return out


def cached_peak_speeds(style) -> np.ndarray:
    """``peak_speeds`` kept on disk by the style's fingerprint, as ``cached_accent_beats``."""
    return _cached(style, "peak-speeds", lambda: {"speed": peak_speeds(style)})["speed"]


def _cached(style, tag: str, compute) -> dict:
    """``compute()`` (a dict of arrays) kept on disk by the style's fingerprint, ``tag`` and this file's code."""
    import hashlib
    import zipfile
    from pathlib import Path

    from ..io.files import atomic_output
    from .database import cache_dir

    if not style.fingerprint:
        return compute()
    code = hashlib.blake2b(Path(__file__).read_bytes(), digest_size=8).hexdigest()
    path = cache_dir() / "accents" / f"{style.name}-{style.fingerprint}-{tag}-{code}.npz"
    if path in _READ:   # a dance asks more than once (the mixer: its words, their pace, the timing)
        return _READ[path]
    try:
        with np.load(path) as z:
            out = {k: z[k] for k in z.files}
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):
        out = None  # not cached yet, or unreadable: compute below
    if out is None:
        out = compute()
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with atomic_output(path, "wb") as fh:
                np.savez(fh, **out)
        except OSError:
            pass  # a read-only cache only costs the analysis next time
    for a in out.values():
        a.flags.writeable = False   # shared by every later caller: none may change it
    _READ[path] = out
    return out


_READ: dict = {}  # what _cached read or computed in this process, by file: a few arrays per style


def limb_turns(style) -> np.ndarray:
    """(F-1,) the largest angle (rad) any joint that moves a limb turns from frame f to f+1."""
    sk = style.skeleton
    reach = np.linalg.norm(sk.offsets, axis=1)
    for j, end in sk.end_sites.items():
        reach[j] += np.linalg.norm(end)
    subtree = reach.copy()
    for j in range(sk.n_joints - 1, 0, -1):
        subtree[sk.parents[j]] += subtree[j]
    joints = np.flatnonzero(subtree > 0.03)  # ignore finger tips and zero-length helpers
    out = np.zeros(max(style.n_frames - 1, 0))
    for a in range(0, len(out), 8192):  # in blocks: a big database need not sit in memory twice
        q = style.local_rot[a:a + 8193, joints].astype(np.float64)
        out[a:a + len(q) - 1] = rot.angle(q[1:], q[:-1]).max(axis=1)
    return out


def fast_beats(style, frames: np.ndarray, percentile: float = 99.0, turns: np.ndarray | None = None) -> np.ndarray:
    """Per flat frame of ``frames`` (beats as shown): whether a limb turns, into or out of it,
    faster than ``percentile`` of the style's fastest-limb turns over all its frames -- a beat
    the mocap whips through (a hit). A cut there would have to carry that speed into other
    motion, which no blend does within its limits: it shows as a pop. ``turns``: ``limb_turns(style)``
    if the caller has it already."""
    turn = (limb_turns(style) if turns is None else turns).copy()
    turn[np.asarray(style.clip_starts[1:-1]) - 1] = 0.0  # nothing turns from a clip's last frame to the next's first
    limit = np.percentile(turn, percentile)
    last = len(turn) - 1
    frames = np.asarray(frames, dtype=np.int64)
    return np.maximum(turn[np.clip(frames - 1, 0, last)], turn[np.clip(frames, 0, last)]) > limit

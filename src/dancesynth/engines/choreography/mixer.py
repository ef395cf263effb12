"""The choreography mixer (Aristidou et al. §5.2.5): real motion words, one per beat.

For each beat interval of the music the choreography level has chosen a motif. Its
cluster members -- the real words of the chosen style that the motif model assigns
to it -- are the candidates; the one whose first poses best continue the previous
word's last poses (joint rotations and their velocities) is danced, time-scaled so
that its two motion beats fall on the interval's two music beats. Where every candidate
would need a stitch, the mocap's own continuation may dance a beat or two of another
motif instead (beyond the paper: stitches on most beats made the dance hectic and glide).

Each chosen word is a "piece" of source frames for ``stitch.render``, which already
does what the paper's blending step needs: a word that does not continue where the
previous one ended in the mocap is re-placed on the floor (heading and position
continue) and blended in by inertialization; planted feet are then held by the
two-bone IK of ``footlock``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from ... import rotations as rot
from ...kinematics import fk
from ...motion.accents import AccentCosts, cached_accent_beats, cached_peak_speeds, fast_beats
from ...motion.database import Style
from ...motion.motifs import style_motifs
from ...motion.roles import find_roles
from ...motion.words import MotionWords
from ..footlock import FootLockState, lock_feet
from ..form import FormPlan
from ..stitch import Pieces, StitchState, render
from ..timing import beat_ease, ease_within, speed_room, within_room


@dataclass(frozen=True)
class MixerConfig:
    blend_s: float = 0.25          # inertialization time where words do not continue each other: at 0.2
                                   # the stitches (nearly one per beat) show as stops between beats, at
                                   # 0.4 the words blur (motifs found again in the motion 0.81 -> 0.66)
    limb_speed: float | None = 1.0  # no stitch's decay moves a limb's end faster than this by itself (m/s;
                                    # stitch.render): 60-80 % of the fastest joint motion lay at stitches.
                                    # Not in the graph engines: live, 3 s segments, it blurred the stops
                                    # (beats lined up 0.71 against 0.84)
    velocity_s: float = 0.1        # a velocity difference counts as the pose change over this time
    tempo_weight: float = 40.0     # cost per (log2 time-warp rate)^2: prefer words of the beat's length
                                   # (40: 97 % of words within 0.8-1.25x on the bench's songs; 20: 88 %; 2: 2 in 3)
    jump_cost: float = 0.5         # added to every stitch that is not the mocap's own continuation
    off_plan_depth: int = 2        # where the plan's words all need a stitch, the mocap's own continuation
    off_plan_cost: float = 4.0     # may dance up to this many beats of another motif, at this cost per beat
                                   # (depth 0, the paper: a stitch on ~70 % of jpop's beats, joint speed 1.6x,
                                   # travel 1.7x, PFC 10x its mocap; docs/choreography.md has the measurements)
    fast_stitch_cost: float = 10.0  # ... and this where a limb whips through the cut (motion.accents.fast_beats):
                                    # no blend carries that speed into another word without a pop
    speed_weight: float = 2.0      # cost per (log2 of a word's mean speed over its style's)^2: a calm word
                                   # stitches cheaply, and without it the plan's words came out calmer than
                                   # the style (pop: p99 joint speed 0.6x its mocap's). 4 slid the feet more
                                   # (floor foot speed 1.02x the mocap's against 0.96x; tune split)
    root_weight: float = 100.0     # cost per m^2 of root-over-feet offset (and per (m/s * velocity_s)^2 of root
                                   # velocity) a stitch leaves for the blend to glide the body across
    foot_lock: bool = True
    unlock_s: float = 0.15         # a foot moved by a stitch is free this long (see ``_released``)
    unlock_tol_m: float = 0.3      # ... if it moves more than this. At 0.05 most stitches freed the feet while
                                   # the blend glided the body: PFC 1.49 / 1.43x the mocap's, 0.88 / 1.02x now
                                   # (the foot lock never pulls a foot more than 0.1 m; beyond, it slides)
    accent_window: float = 0.35    # show each word's beats at their visible stops (motion.accents; 0 = off)
    accent: AccentCosts | None = AccentCosts()  # prefer words that stop on their beats and not between
    ease_beats: float = 0.3        # accent timing on each music beat (engines.timing.ease; 0 = off)
    ease_downbeat: float = 0.3     # ... and this much harder on each bar's first beat
    ease_max_rate: float | None = 1.7  # ... never faster between beats than this times the captured speed
    ease_speed_percentile: float | None = 96.0  # ... nor push a frame past the style's fast ones (timing.within_room)


@dataclass(frozen=True)
class WordBank:
    """A style's words, their motifs, and the poses at their ends for matching.

    ``start_pose``/``end_pose`` are joint rotation matrices flattened (W, J*9) with the
    root's heading removed (the mixer re-places every word facing where the dancer
    faces), so ``‖a − b‖²`` ≈ the summed squared joint angles between two poses;
    ``start_vel``/``end_vel`` are their time derivatives (per second, source time);
    ``start_fast``/``end_fast`` mark the ends where a limb whips through (``fast_beats``).
    """

    words: MotionWords
    motif: np.ndarray        # (W,)
    start_pose: np.ndarray
    end_pose: np.ndarray
    start_vel: np.ndarray
    end_vel: np.ndarray
    fps: float
    start_fast: np.ndarray
    end_fast: np.ndarray
    start_root: np.ndarray   # (W, 6) root over the ankles' midpoint (m) and root velocity (m/s), heading frame
    end_root: np.ndarray

    def __len__(self) -> int:
        return len(self.motif)

    def duration_s(self, w) -> np.ndarray:
        return (self.words.end[w] - self.words.start[w]) / self.fps


def _pose_vectors(style: Style, frames: np.ndarray) -> np.ndarray:
    q = style.local_rot[frames].astype(np.float64)
    root = q[:, 0]
    q = q.copy()
    q[:, 0] = rot.mul(rot.inv(rot.about_y(rot.heading(root))), root)  # tilt only
    mats = Rotation.from_quat(q.reshape(-1, 4)).as_matrix()
    return mats.reshape(len(frames), -1)


def _root_vectors(style: Style, frames: np.ndarray) -> np.ndarray:
    """(F, 6): the root relative to the ankles' midpoint and the root's velocity (source time), both in
    the root's heading frame: what a stitch makes the blend glide the body across."""
    sk = style.skeleton
    ankles = list(find_roles(sk).ankles)
    idx = np.stack([frames, frames + 1])
    _, pos = fk(style.local_rot[idx], style.root_pos[idx], sk.offsets, sk.parents, only=ankles)
    unturn = rot.about_y(-rot.heading(style.local_rot[frames, 0].astype(np.float64)))
    over = rot.apply(unturn, pos[0][:, 0] - pos[0][:, ankles].mean(axis=1))
    vel = rot.apply(unturn, (style.root_pos[frames + 1] - style.root_pos[frames]) * style.fps)
    return np.concatenate([over, vel], axis=1)


def word_bank(style: Style, motif_model, accent_window: float = 0.0) -> WordBank:
    """Every word of ``style``, assigned to the motifs of ``motif_model``; with ``accent_window``,
    its end poses are taken where the mixer cuts it: at its first and last beat's visible stop."""
    words, motif = style_motifs(style, motif_model)
    s, e = words.start, words.end
    if accent_window > 0:
        shown = cached_accent_beats(style, window=accent_window).frame
        s, e = (shown[np.searchsorted(style.beat_frames, f)] for f in (s, e))
    # A word spans at least two frames of one clip, so start+1 and end-1 stay inside it.
    start_pose, after_start = _pose_vectors(style, s), _pose_vectors(style, s + 1)
    end_pose, before_end = _pose_vectors(style, e), _pose_vectors(style, e - 1)
    fast = fast_beats(style, np.r_[s, e])
    return WordBank(words, motif, start_pose, end_pose, (after_start - start_pose) * style.fps,
                    (end_pose - before_end) * style.fps, style.fps, fast[:len(s)], fast[len(s):],
                    _root_vectors(style, s), _root_vectors(style, e - 1))


def substitute_motifs(bank: WordBank, centroids: np.ndarray) -> np.ndarray:
    """``(K,)`` the motif to dance for each motif: itself if the style has a word of it, else
    the motif with words in this style whose centroid is nearest (motifs are shared by
    all genres; a style need not have every one)."""
    centroids = np.asarray(centroids, dtype=float)
    present = np.unique(bank.motif)
    d = np.linalg.norm(centroids[:, None, :] - centroids[None, present, :], axis=-1)
    return present[np.argmin(d, axis=1)]


def _match(bank: WordBank, prev: np.ndarray, cand: np.ndarray, config: "MixerConfig") -> np.ndarray:
    """(len(prev), len(cand)) cost of dancing ``cand`` right after ``prev``: 0 where the mocap
    itself continues that way, else the pose + velocity difference plus ``jump_cost`` (and
    ``fast_stitch_cost`` where a limb whips through either end)."""
    def sq(a, b):  # squared distances between rows, (len(a), len(b))
        return np.maximum((a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * a @ b.T, 0.0)

    scale = np.r_[1.0, 1.0, 1.0, config.velocity_s, config.velocity_s, config.velocity_s]
    cost = (sq(bank.end_pose[prev], bank.start_pose[cand])
            + config.velocity_s ** 2 * sq(bank.end_vel[prev], bank.start_vel[cand]) + config.jump_cost
            + config.root_weight * sq(bank.end_root[prev] * scale, bank.start_root[cand] * scale)
            + config.fast_stitch_cost * (bank.end_fast[prev][:, None] | bank.start_fast[cand][None, :]))
    return np.where(bank.words.end[prev][:, None] == bank.words.start[cand][None, :], 0.0, cost)


def _candidates(bank: WordBank, motifs, members: dict, depth: int, free) -> list:
    """Each beat's candidate words: its motif's members and, where ``free`` allows, the words the mocap
    dances right after the previous beat's candidates, for up to ``depth`` beats after a member.
    Danced after the word they follow they need no stitch; after another word they are stitched
    like any other candidate."""
    next_word = np.searchsorted(bank.words.start, bank.words.end)
    has_next = next_word < len(bank)
    has_next[has_next] &= bank.words.start[next_word[has_next]] == bank.words.end[has_next]
    out, off = [], np.zeros(0, dtype=int)  # off: how many beats after a member of the plan
    for i, m in enumerate(motifs):
        cands, off_now = members[int(m)], np.zeros(len(members[int(m)]), dtype=int)
        if depth and i and (free is None or free[i]):
            prev = out[-1]
            rows = np.flatnonzero(has_next[prev] & (off < depth))
            rows = rows[~np.isin(next_word[prev[rows]], cands)]
            cands, off_now = np.r_[cands, next_word[prev[rows]]], np.r_[off_now, off[rows] + 1]
        out.append(cands)
        off = off_now
    return out


def choose_words(bank: WordBank, motifs: np.ndarray, durations_s: np.ndarray, rng: np.random.Generator,
                 config: MixerConfig = MixerConfig(), word_cost: np.ndarray | None = None,
                 word_s: np.ndarray | None = None, free: np.ndarray | None = None,
                 forced: np.ndarray | None = None) -> np.ndarray:
    """The word (index into ``bank``) danced on each beat interval, as a rule one of that beat's motif.

    The paper picks, beat by beat, the word whose first poses best continue the previous
    word. We minimise the same stitch cost over the whole song at once (Viterbi over
    each beat's candidates), so a choice that leaves the next beat only bad
    continuations is avoided, and runs of words that follow each other in the mocap
    are found wherever the plan allows them. A word's length far from its beat's costs
    ``tempo_weight`` per (log2 time-warp rate)^2, and ``word_cost`` (W,), if given, is
    added per word; the seed breaks ties at the start. ``word_s`` (W,): each word's length as
    it will be played (default: from its first beat to its last). Beyond the paper, where
    ``free`` allows it the mocap's own continuation may stand in for the plan for up to
    ``off_plan_depth`` beats, at ``off_plan_cost`` a beat (``_candidates``). ``forced`` (B,): the word
    each beat must dance (-1: free), e.g. a repeated section's words (``engines/form.py``).
    """
    members = {int(m): np.flatnonzero(bank.motif == m) for m in np.unique(motifs)}
    log_len = np.log2(np.maximum(bank.duration_s(np.arange(len(bank))) if word_s is None else word_s, 1e-3))
    cands = _candidates(bank, motifs, members, config.off_plan_depth, free)
    if forced is not None:
        cands = [c if w < 0 else np.array([w]) for c, w in zip(cands, forced)]
    extra = np.zeros(len(bank)) if word_cost is None else word_cost
    unary = [config.tempo_weight * (log_len[c] - np.log2(d)) ** 2 + extra[c]
             + config.off_plan_cost * (bank.motif[c] != m) for c, d, m in zip(cands, durations_s, motifs)]
    total = unary[0] + 1e-3 * rng.random(len(cands[0]))  # where the dance starts is the seed's choice
    back = []
    for i in range(1, len(motifs)):
        step = total[:, None] + _match(bank, cands[i - 1], cands[i], config)
        back.append(np.argmin(step, axis=0))
        total = step[back[-1], np.arange(len(cands[i]))] + unary[i]
    pick = [int(np.argmin(total))]
    for b in reversed(back):
        pick.append(int(b[pick[-1]]))
    pick.reverse()
    return np.array([c[k] for c, k in zip(cands, pick)], dtype=np.int64)


def _released(style: Style, frames, fps: float, config: MixerConfig) -> np.ndarray:
    """(F, 2) frames where a foot is not held: ``unlock_s`` after a stitch that moves it.

    Words are re-placed at most beats. Where the new word puts a planted foot elsewhere
    than the old word had it (by more than ``unlock_tol_m``), holding it would pull the
    leg towards the old place and the IK would snap it; the hold is released (it fades
    out) and taken up again where the new word plants the foot.
    """
    first = np.flatnonzero(frames.new_run)
    first = first[first > 0]
    out = np.zeros(frames.contacts.shape, dtype=bool)
    if not first.size:
        return out
    sk = style.skeleton
    ankles = list(find_roles(sk).ankles)
    idx = np.r_[first - 1, first]
    _, pos = fk(frames.raw_local[idx], frames.raw_root[idx], sk.offsets, sk.parents, only=ankles)
    moved = np.linalg.norm(pos[len(first):, ankles] - pos[:len(first), ankles], axis=-1) > config.unlock_tol_m
    span = max(1, int(round(config.unlock_s * fps)))
    for f, m in zip(first, moved):
        out[f:f + span, m] = True
    return out


def word_pace(style: Style, bank: WordBank) -> np.ndarray:
    """(W,) log2 of each word's mean fastest-joint speed (``motion.accents.peak_speeds``) over its style's."""
    cum = np.r_[0.0, np.cumsum(cached_peak_speeds(style))]
    start, end = bank.words.start, bank.words.end
    mean = (cum[end] - cum[start]) / np.maximum(end - start, 1)
    return np.log2(np.maximum(mean, 1e-6) / max(cum[-1] / max(len(cum) - 1, 1), 1e-6))


@dataclass(frozen=True)
class Mix:
    local_rot: np.ndarray
    root_pos: np.ndarray
    contacts: np.ndarray
    source_frames: np.ndarray
    pieces: Pieces
    words: np.ndarray        # (B,) index into the bank per beat interval
    motifs: np.ndarray       # (B,) motif of the danced word


def mix(style: Style, bank: WordBank, motifs: np.ndarray, beat_times_s: np.ndarray, end_s: float, *,
        fps: float, rng: np.random.Generator, config: MixerConfig = MixerConfig(),
        beat_count: np.ndarray | None = None, bar_position: np.ndarray | None = None,
        beats_per_bar: int | None = None, free: np.ndarray | None = None, form: FormPlan | None = None) -> Mix:
    """Dance ``motifs[i]`` on beat interval ``beat_times_s[i] → [i+1]``, rendered up to ``end_s``.

    ``beat_count``, ``bar_position``, ``beats_per_bar``: the beats' counts and metre, as in ``BeatGrid``.
    ``free`` (B,): beats where the mocap's own continuation may stand in for the plan (default all;
    ``config.off_plan_depth``). ``form``: the song's form on these beats; a beat of a repeated section
    dances the word its pair danced (the words are chosen twice: the second time with the first's
    words held on both)."""
    times = np.asarray(beat_times_s, dtype=np.float64)
    accents = cached_accent_beats(style, window=config.accent_window) if config.accent_window > 0 else None
    word_cost = word_s = None
    if accents is not None:
        start = np.searchsorted(style.beat_frames, bank.words.start)
        end = np.searchsorted(style.beat_frames, bank.words.end)
        word_s = (accents.frame[end] - accents.frame[start]) / style.fps  # played from stop to stop
        if config.accent:
            arrive, played = config.accent.beat_costs(accents.strength, accents.offbeat)
            word_cost = arrive[end] + played[start]
    if config.speed_weight:
        calm = config.speed_weight * word_pace(style, bank) ** 2
        word_cost = calm if word_cost is None else word_cost + calm
    chosen = choose_words(bank, np.asarray(motifs), np.diff(times), rng, config, word_cost, word_s, free)
    if form is not None and (form.source[:len(chosen)] >= 0).any():
        chosen = choose_words(bank, np.asarray(motifs), np.diff(times), rng, config, word_cost, word_s, free,
                              forced=form.held(chosen))
    f0, f1 = bank.words.start[chosen], bank.words.end[chosen]
    jump = np.r_[False, f0[1:] != f1[:-1]]
    if accents is not None:
        # Words start and end on motion beats; the stop a viewer sees may sit a little off them.
        f0, f1 = (accents.frame[np.searchsorted(style.beat_frames, f)] for f in (f0, f1))
    f0, f1 = f0.astype(np.float64), f1.astype(np.float64)
    count = np.arange(len(times), dtype=np.float64) if beat_count is None else np.asarray(beat_count, float)
    rates = (f1 - f0) / style.fps / np.diff(times)
    ease = ease_within(beat_ease(len(times), bar_position, beats_per_bar, amount=config.ease_beats,
                                 downbeat=config.ease_downbeat), rates, config.ease_max_rate, count)
    room = speed_room(style, config)
    pieces = Pieces(times[:-1], times[1:], f0, f1, jump, count[:-1], count[1:], ease[:-1], ease[1:],
                    None if room is None else within_room(ease, count, f0, f1, rates, room))
    _, frames = render(style, pieces, StitchState(), fps=fps, end_s=end_s, blend_s=config.blend_s,
                       inclusive_end=True, limb_speed=config.limb_speed)
    local = frames.local_rot
    if config.foot_lock:
        held = replace(frames, contacts=frames.contacts & ~_released(style, frames, fps, config))
        local, _ = lock_feet(style.skeleton, find_roles(style.skeleton), held, FootLockState(), fps=fps)
    return Mix(local, frames.root_pos, frames.contacts, frames.source_pos, pieces, chosen, bank.motif[chosen])

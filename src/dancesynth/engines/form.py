"""The song's form in the dance (beyond the three papers): a section that comes back is danced
as it was the first time.

``form_plan`` reads the song's sections (``music.structure``) onto an engine's beat grid:
each beat of a repeated section is paired with the beat at the same place in the section's
first occurrence (bar for bar, beat for beat), so that an engine can dance there what it
danced then. Every engine takes the same plan and keeps it in its own terms: the graph
engines as a reward for arriving at the node they danced on the paired beat (the dynamic
program still pays for the way in and out, so both ends join on the graph's own
transitions), the choreography and neural engines by replaying the paired beat's motif.

``--repeat`` says how: ``same`` replays the moves, ``mirror`` their left-right mirror image
(where the style has mirrored takes), ``vary`` replays the first bars of each 4-bar phrase
and dances the rest anew (``vary`` of them, 0 = same, 1 = all new), ``off`` ignores the form.
Sections heard for the first time after the first one are ``fresh``: the engines there
prefer moves not danced yet.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..types import MusicFeatures, SongStructure

REPEAT_MODES = ("same", "mirror", "vary", "off")
PHRASE_BARS = 4        # phrases repeat, and vary dances the last bars of each anew, in groups of this many
SAME_PHRASE = 0.45     # a phrase sounding at least this like an earlier one (aligned bars' mean similarity)
                       # replays its moves: lower than a section's repeat (music.structure.SAME_SECTION 0.6),
                       # since within a section the chords come round again under a new melody (tune split)


def check_repeat(mode: str, vary: float) -> None:
    if mode not in REPEAT_MODES:
        raise InputError(f"unknown --repeat '{mode}': use one of {', '.join(REPEAT_MODES)}")
    if not 0.0 <= vary <= 1.0:  # NaN too
        raise InputError(f"--vary {vary} is out of range: use 0 (replay every bar) to 1 (every bar new)")


@dataclass(frozen=True)
class FormPlan:
    """What the form asks of each beat of a beat grid (G beats)."""

    mode: str
    source: np.ndarray          # (G,) the earlier grid beat whose move this one replays (-1: none)
    fresh: np.ndarray           # (G,) bool: in a section heard for the first time, after the first section
    section_start: np.ndarray   # (G,) bool: the first beat of a section (after the first)
    sections: tuple = ()        # per section: label, name, start_s, end_s, bars and what it replays
    entry: np.ndarray | None = None  # (G,) bool: a replayed bar's first beat, where the dance may cut
                                     # into the replay (a blend, no graph edge needed)
    flip: np.ndarray | None = None   # (G,) bool: with ``mirror``, the beat shows its source's mirror image (a
                                     # replay of a replay, e.g. a phrase repeated within a chorus that is
                                     # itself repeated, is mirrored twice: the same moves)

    @property
    def mirrored(self) -> bool:
        return self.mode == "mirror"

    @property
    def any(self) -> bool:
        return bool((self.source >= 0).any() or self.fresh.any() or self.section_start.any())

    def targets(self, danced: np.ndarray, first: int, n: int, mirror: np.ndarray | None = None) -> np.ndarray:
        """(n,) for grid beats ``first .. first + n - 1``: the value ``danced`` (what was danced on each
        grid beat so far: a node, a word, a motif; -1 where unknown) holds on the beat each replays,
        through ``mirror`` (a lookup: value -> its mirror image's, -1 none) when the plan mirrors; -1
        where a beat replays nothing or its pair was not danced yet."""
        src = np.full(n, -1, dtype=np.int64)
        have = min(n, max(len(self.source) - first, 0))
        src[:have] = self.source[first:first + have]
        ok = (src >= 0) & (src < len(danced))
        out = np.full(n, -1, dtype=np.int64)
        out[ok] = np.asarray(danced)[src[ok]]
        if self.mirrored and mirror is not None:
            flip = np.ones(n, bool)
            if self.flip is not None:
                flip[:have] = self.flip[first:first + have]
            hit = (out >= 0) & flip
            out[hit] = mirror[out[hit]]
        return out

    def asked_at(self, grid_times_s: np.ndarray, times_s: np.ndarray) -> np.ndarray:
        """(T,) bool: which of ``times_s`` (e.g. the music's beats) the plan asks to replay: on a paired grid
        beat, or between two (a grid at half time)."""
        grid, t = np.asarray(grid_times_s), np.asarray(times_s)
        at = np.clip(np.searchsorted(grid, t + 1e-6, side="right") - 1, 0, len(grid) - 2)
        on = np.abs(grid[at] - t) < 1e-3
        return (self.source[at] >= 0) & (on | (self.source[at + 1] >= 0))

    def held(self, danced: np.ndarray, mirror: np.ndarray | None = None) -> np.ndarray:
        """For a second search over the whole song: the value to hold on every beat a pair ties (the first
        search's ``danced`` on the first occurrence, its replay on the repeat), -1 elsewhere."""
        keep = np.full(len(danced), -1, dtype=np.int64)
        pairs = np.flatnonzero(self.source[:len(keep)] >= 0)
        keep[self.source[pairs]] = np.asarray(danced)[self.source[pairs]]
        keep[pairs] = self.targets(danced, 0, len(keep), mirror)[pairs]
        return keep

    def replayed(self, danced: np.ndarray, mirror: np.ndarray | None = None) -> dict:
        """How much of the dance ``danced`` (a value per grid beat) replays what the plan asked: the
        share of beats in repeated sections whose value is their pair's."""
        danced = np.asarray(danced)
        asked = np.flatnonzero(self.source[:len(danced)] >= 0)
        if not asked.size:
            return {"replay_beats": 0, "replayed_share": None}
        want = self.targets(danced, 0, len(danced), mirror)[asked]
        return {"replay_beats": int(asked.size), "replayed_share": float(np.mean(danced[asked] == want))}

    def summary(self, danced: np.ndarray, mirror: np.ndarray | None = None) -> dict:
        """The dance summary's account of the form: the mode, the sections and what each replays, and
        the share of the paired beats that danced what their pair did (``danced``: a value per grid
        beat, e.g. the graph node; ``mirror`` as in ``targets``)."""
        out = {"repeat": self.mode, "sections": list(self.sections), **self.replayed(danced, mirror)}
        if self.mirrored and mirror is None:
            out["note"] = "no mirrored takes to dance: repeats replay the same moves, not their mirror image"
        return out


def no_plan(n: int, mode: str = "off", sections: tuple = ()) -> FormPlan:
    return FormPlan(mode, np.full(n, -1, dtype=np.int64), np.zeros(n, bool), np.zeros(n, bool), sections,
                    np.zeros(n, bool), np.zeros(n, bool))


def form_plan(music: MusicFeatures, grid_times_s: np.ndarray, mode: str = "same",
              vary: float = 0.5) -> FormPlan:
    """The plan of ``music``'s form (``music.structure``; none: nothing asked) on the beat grid
    ``grid_times_s``: each bar ``bar_pairs`` pairs with an earlier one replays it beat for beat."""
    check_repeat(mode, vary)
    grid = np.asarray(grid_times_s, dtype=np.float64)
    form = music.structure
    beats = np.asarray(music.beat_times_s, dtype=np.float64)
    if form is None or len(form.sections) < 2 or music.beat_in_bar is None or beats.size < 2:
        return no_plan(len(grid), mode)
    bpb = int(music.beats_per_bar)
    downbeats = np.flatnonzero(np.asarray(music.beat_in_bar) == 0).astype(np.float64)
    n_bars = max(s.first_bar + s.n_bars for s in form.sections)
    bar_beat = np.r_[downbeats, downbeats[-1] + bpb * np.arange(1, n_bars - len(downbeats) + 2)][:n_bars + 1]
    pairs = bar_pairs(form, mode, vary)
    position = _beat_position(grid, beats)
    bar = np.searchsorted(bar_beat, position + 1e-6, side="right") - 1     # -1: the pickup
    inside = (bar >= 0) & (bar < n_bars)
    bar = np.clip(bar, 0, n_bars - 1)
    offset = position - bar_beat[bar]                                     # music beats into the bar
    src_bar = np.where(inside, pairs[bar], -1)
    want = bar_beat[np.maximum(src_bar, 0)] + offset                      # the same place in the paired bar
    near = np.clip(np.searchsorted(position, want), 1, len(grid) - 1)
    near = np.where(np.abs(position[near - 1] - want) < np.abs(position[near] - want), near - 1, near)
    replay = (src_bar >= 0) & (np.abs(position[near] - want) < 0.05)
    source = np.where(replay, near, -1)
    hops = (source >= 0).astype(np.int64)
    for g in np.flatnonzero(source >= 0):   # a replay of a replay replays the first (sources come earlier:
        if source[source[g]] >= 0:          # theirs are followed already)
            hops[g] = hops[source[g]] + 1
            source[g] = source[source[g]]
    section = np.array([k for k, s in enumerate(form.sections) for _ in range(s.n_bars)])[bar]
    first_label = {}
    for k, sec in enumerate(form.sections):
        first_label.setdefault(sec.label, k)
    new_label = np.array([first_label[s.label] == k and k > 0 for k, s in enumerate(form.sections)])
    fresh = inside & ~replay & (new_label[section] | (pairs[bar] == -2))
    start = np.zeros(len(grid), bool)
    for k, sec in enumerate(form.sections[1:], 1):
        hit = np.flatnonzero(inside & (section == k))
        start[hit[:1]] = True
    entry = replay & (np.abs(offset) < 0.05)
    report = []
    for k, sec in enumerate(form.sections):
        own = pairs[sec.first_bar:sec.first_bar + sec.n_bars]
        info = {"label": sec.label, "name": sec.name, "start_s": round(sec.start_s, 3),
                "end_s": round(sec.end_s, 3), "bars": sec.n_bars}
        if first_label[sec.label] != k:
            info["repeats"] = first_label[sec.label]
        if mode != "off":
            info["bars_replayed"] = int((own >= 0).sum())
        report.append(info)
    if mode == "off":   # the sections are reported, nothing is asked of the dance
        return no_plan(len(grid), mode, tuple(report))
    return FormPlan(mode, source, fresh, start, tuple(report), entry, hops % 2 == 1)


def bar_pairs(form: SongStructure, mode: str, vary: float) -> np.ndarray:
    """(bars,) the earlier bar each bar replays: -1 none, -2 none and danced anew (``vary``).

    A repeated section's bars pair with its label's first section's, bar for bar; a bar left
    unpaired pairs with the bar at the same place in the earlier phrase of ``PHRASE_BARS``
    that sounds most like its own (``form.similarity``, the mean along the aligned bars, at
    least ``SAME_PHRASE``): music repeats its phrases within a section too, and a dancer
    repeats the moves with them. ``vary``: the last bars of each phrase are danced anew."""
    n = max(s.first_bar + s.n_bars for s in form.sections)
    pairs = np.full(n, -1, dtype=np.int64)
    if mode == "off":
        return pairs
    first_of: dict[str, int] = {}
    for k, sec in enumerate(form.sections):
        j = first_of.setdefault(sec.label, k)
        if j != k:
            m = min(sec.n_bars, form.sections[j].n_bars)
            pairs[sec.first_bar:sec.first_bar + m] = form.sections[j].first_bar + np.arange(m)
    sim = form.similarity
    phrases = [p for p in form.phrases if p.size == PHRASE_BARS]
    if sim is not None and len(sim) >= n:
        for p in phrases:
            if (pairs[p.first_bar:p.first_bar + p.n_bars] >= 0).all():
                continue
            best, best_q = SAME_PHRASE, None
            for q in phrases:
                if q.first_bar >= p.first_bar:
                    break
                m = min(p.n_bars, q.n_bars, p.first_bar - q.first_bar)
                score = float(np.mean(sim[p.first_bar + np.arange(m), q.first_bar + np.arange(m)]))
                if score > best:
                    best, best_q = score, q
            if best_q is not None:
                m = min(p.n_bars, best_q.n_bars, p.first_bar - best_q.first_bar)
                free = pairs[p.first_bar:p.first_bar + m] < 0
                pairs[p.first_bar:p.first_bar + m][free] = (best_q.first_bar + np.arange(m))[free]
    if mode == "vary":
        new_from = int(round(PHRASE_BARS * (1.0 - vary)))
        at = np.zeros(n, dtype=np.int64)   # each bar's place in its phrase
        for p in phrases:
            at[p.first_bar:p.first_bar + p.n_bars] = np.arange(p.n_bars)
        pairs[(pairs >= 0) & (at >= new_from)] = -2
    return pairs


def _beat_position(times_s: np.ndarray, beats_s: np.ndarray) -> np.ndarray:
    """Music beats counted at each time (fractions between beats; before the first and after the
    last beat, counted on at the first and last beat's period)."""
    pos = np.interp(times_s, beats_s, np.arange(beats_s.size, dtype=np.float64))
    before, after = times_s < beats_s[0], times_s > beats_s[-1]
    pos[before] = (times_s[before] - beats_s[0]) / (beats_s[1] - beats_s[0])
    pos[after] = beats_s.size - 1 + (times_s[after] - beats_s[-1]) / (beats_s[-1] - beats_s[-2])
    return pos


def _bar_beat(downbeats: np.ndarray, bar: int, bpb: int) -> float:
    """The music beat (index) bar ``bar`` starts at, counting on past the last downbeat."""
    if bar < len(downbeats):
        return float(downbeats[bar])
    return float(downbeats[-1] + (bar - len(downbeats) + 1) * bpb)


def graph_mirror(style, graph) -> np.ndarray | None:
    """(N,) each graph node's mirror-image node (-1: none), for a style danced with mirrored takes
    (``Style.material``: the mirrored clips follow the captured ones, beat for beat); None otherwise."""
    if not style.n_mirrored:
        return None
    half = int(style.clip_starts[style.n_clips - style.n_mirrored])
    frames = np.asarray(graph.node_frame, dtype=np.int64)
    twin = np.where(frames < half, frames + half, frames - half)
    order = np.argsort(frames)
    at = np.clip(np.searchsorted(frames[order], twin), 0, len(frames) - 1)
    return np.where(frames[order][at] == twin, order[at], -1)


def replay_motion(clip, grid_times_s: np.ndarray, plan: FormPlan, *, blend_s: float = 0.3):
    """``clip`` (a ``MotionClip`` an engine made itself, not picked from mocap: the neural generator's)
    with every beat the plan pairs showing the frames of its pair, re-timed to its own beats; where a
    replay starts or ends the motion is re-placed and blended as between two mocap pieces
    (``stitch.render``). Returns the new clip and its render (for the foot lock)."""
    from ..motion.database import Style
    from ..types import MotionClip
    from .stitch import Pieces, StitchState, render

    grid = np.asarray(grid_times_s, dtype=np.float64)
    fps, n = clip.fps, clip.n_frames
    src = np.where(plan.source[:len(grid) - 1] >= 0, plan.source[:len(grid) - 1], np.arange(len(grid) - 1))
    f0 = np.clip(grid[src] * fps, 0, n - 1)
    f1 = np.clip(grid[src + 1] * fps, 0, n - 1)
    jump = np.r_[False, np.abs(f0[1:] - f1[:-1]) > 1e-6]
    as_source = Style("generated", "", clip.skeleton, fps, ("generated",), ("",), np.array([0, n]),
                      clip.local_rot, clip.root_pos,
                      clip.contacts if clip.contacts is not None else np.zeros((n, 2), bool),
                      np.zeros(n, np.float32), np.rint(np.clip(grid, 0, (n - 1) / fps) * fps).astype(np.int64),
                      np.zeros(1))
    _, frames = render(as_source, Pieces(grid[:-1], grid[1:], f0, f1, jump), StitchState(), fps=fps,
                       end_s=(n - 1) / fps, blend_s=blend_s, inclusive_end=True)
    return MotionClip(clip.skeleton, fps, frames.root_pos, frames.local_rot, contacts=frames.contacts,
                      meta=dict(clip.meta)), frames

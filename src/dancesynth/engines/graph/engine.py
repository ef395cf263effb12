"""The streaming meta-motion-graph engine (§3.3) and its global-DP baseline.

Streaming: music arrives as segments of beats. For each segment the engine runs the
path search from the previous segment's last node (InitS for the first), with music
intensities standardised by what has been heard so far, ending at a node whose
capacity covers the music still to come (THC), and renders the segment. ``step`` is
pure: it returns a new state and the segment's frames; offline synthesis runs the
same step over a whole song.

Global (the authors' earlier, offline method, our baseline): one search over the
whole song with intensities standardised over the whole song.

With a ``SignatureTarget`` (``signature.py``, beyond the paper) the streaming step
also favours words whose motif the dance owes its genre's template, and counts the
motifs it danced in its state.

With a ``FormPlan`` (``engines/form.py``, beyond the paper) both follow the song's form:
a beat of a repeated section is rewarded for arriving at the node its pair in the first
occurrence arrived at, a section heard for the first time avoids every node danced so far,
and a section's first beat asks for a bigger move.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from ...motion.database import Style
from ...motion.roles import JointRoles, find_roles
from ...types import DEFAULT_FPS
from ..footlock import FootLockState, lock_feet
from ..form import FormPlan, graph_mirror
from ..stitch import Pieces, Rendered, StitchState, render
from ..timing import SpeedRoom, beat_ease, ease_within, speed_room, within_room
from .meta_graph import MetaMotionGraph
from .search import AccentCosts, Path, StepCosts, search
from .signature import DEFAULT_WEIGHT, SignatureTarget


@dataclass(frozen=True)
class MusicSegment:
    """K beat intervals of music: ``beat_times_s`` (K+1,) -- the first is the previous
    segment's last beat -- and their intensities (K,) in dB.

    ``remaining_beats`` is how many beats follow this segment, when known (THC);
    ``end_s`` marks the last segment and says up to when to render. ``bar_position``
    (K+1,), when the metre is known, is the position of each beat in its bar (0 = the
    downbeat, -1 = unknown) and ``beats_per_bar`` the bar's length. ``music_beat``
    (K+1,) says which beats are the music's (False: a subdivision, when a slow song is
    danced at double time). ``beat_count`` (K+1,) counts the music's beats at each of
    them (``BeatGrid.count``; None: each is one music beat), for the accent timing.

    ``ahead``: the last ``ahead`` of the K intervals are music still to come, searched
    but not danced (a receding horizon: the segment is chosen knowing what follows it,
    where the music is known, as a file's is); ``remaining_beats`` counts from the end
    of the danced part.

    ``form``: the song's form as heard when the segment was cut (``live.form``), over every beat
    danced so far and this segment's; None: the engine's own plan (a file's, known in advance).
    """

    beat_times_s: np.ndarray
    intensity_db: np.ndarray
    remaining_beats: int | None = None
    end_s: float | None = None
    bar_position: np.ndarray | None = None
    beats_per_bar: int | None = None
    music_beat: np.ndarray | None = None
    beat_count: np.ndarray | None = None
    ahead: int = 0
    form: FormPlan | None = None


@dataclass(frozen=True)
class EngineConfig:
    blend_s: float = 0.3              # inertialization time at a jump
    repeat_penalty: float = 8.0       # cost of arriving at a beat danced within repeat_window_s (0 = paper): about
                                      # one z unit of intensity mismatch (intensity_weight), so a fresh beat as
                                      # good as a replayed one wins (tuned on the tuning songs, docs/vocabulary.md)
    repeat_window_s: float = 60.0     # ... what a viewer remembers: eval.repetition counts replays within it
    repeat_retries: int = 2           # ... and a segment whose path loops back onto its own beats is searched
                                      # again with them charged, at most this often (0 = one search a segment)
    global_retries: int = 8           # ... the global DP's whole path likewise (engine.revisit_penalty)
    foot_lock: bool = True            # hold planted feet still through blends (leg IK)
    jump_cost: float = 1.0            # added to every jump (0 = paper): fewer, better-motivated jumps (each jump's
                                      # blend slides the feet; 0.25 before the larger database)
    signature_weight: float = DEFAULT_WEIGHT  # cost scale of a motif not owed, when following a signature
    # prefer pieces that stop on their beats and keep their feet (None = paper); the warp costs scale
    # with intensity_weight
    accent: AccentCosts | None = AccentCosts(warp=16.0, far_warp=30.0, slide=4.5)
    bar_accent: float = 0.5           # ask for this much more intensity (z units) on each bar's first beat,
                                      # less on the others: the big moves start on the "1" (0 = paper)
    downbeat_stop: float = 0.5        # on a bar's first beat, a stop of strength s costs s x this less
    ease_beats: float = 0.3           # accent timing: play slower on each music beat, faster between
                                      # (timing.ease; 0 = the paper's constant rate per piece)
    ease_downbeat: float = 0.45       # ... and this much harder on each bar's first beat
    ease_max_rate: float | None = 1.7  # ... but never faster between beats than this times the captured speed
                                       # (timing.ease_within; None = no limit)
    ease_speed_percentile: float | None = 96.0  # ... nor push a frame past this percentile of the style's
                                       # fastest-joint speeds (timing.within_room; None = no limit). Chosen on
                                       # the tune split: 93 costs more accents, 98 left a song at 1.25x p99
    intensity_weight: float = 8.0     # eq. (8)'s intensity match against the stop, jump and repeat costs
                                      # beyond the paper (1 = the weight they were tuned at)
    shown_intensity: bool = True      # match the intensity each piece shows at the song's tempo against the
                                      # style's own (MetaMotionGraph.shown_intensity_z; False = eq. 5's w1_z)
    replay_reward: float = 40.0       # the song's form: arriving on a repeated section's beat at the node
                                      # danced on its pair (engines/form.py); above repeat_penalty, which the
                                      # first occurrence's nodes still carry
    section_accent: float = 0.5       # ... and a section's first beat asks for this much more intensity (z)
    entry_cost: float = 12.0          # ... and a replayed bar may start with a cut into its pair's node, blended,
                                      # at this cost: the graph's own ways back to a move took ~20 beats

    @classmethod
    def paper(cls) -> "EngineConfig":
        """The objective of eq. (4)-(9) alone: no repeat penalty, no jump cost, no accent costs."""
        return cls(repeat_penalty=0.0, jump_cost=0.0, accent=None, bar_accent=0.0, downbeat_stop=0.0,
                   ease_beats=0.0, ease_downbeat=0.0, intensity_weight=1.0, replay_reward=0.0, section_accent=0.0,
                   shown_intensity=False)

    def beat_ease(self, n: int, bar_position, beats_per_bar) -> np.ndarray:
        """The accent timing of each of ``n`` beats (``timing.beat_ease``)."""
        return beat_ease(n, bar_position, beats_per_bar, amount=self.ease_beats, downbeat=self.ease_downbeat)


@dataclass(frozen=True)
class StreamState:
    node: int | None = None             # the last node of the previous segment
    prev_duration_s: float | None = None  # its last beat interval (for eq. 6)
    n_heard: int = 0                    # running statistics of music intensity (Welford)
    mean_db: float = 0.0
    m2_db: float = 0.0
    start_nodes: np.ndarray | None = None  # InitS, or the one start a seed picked
    last_seen_s: np.ndarray | None = None  # (N,) when each node was last danced (-inf: never), for repeat_penalty
    stitch: StitchState = field(default_factory=StitchState)
    feet: FootLockState = field(default_factory=FootLockState)
    segments: int = 0
    motif_counts: np.ndarray | None = None  # (K,) motifs danced so far, when the engine has a signature
    danced: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # the node of every beat so far

    @property
    def beat(self) -> int:
        """The grid beat the next segment starts at (the last one danced)."""
        return max(len(self.danced) - 1, 0)


@dataclass(frozen=True)
class SegmentFrames:
    """Frames rendered for one segment, with what produced them."""

    local_rot: np.ndarray
    root_pos: np.ndarray
    contacts: np.ndarray
    source_pos: np.ndarray
    path: Path
    pieces: Pieces
    search_s: float = 0.0   # time spent in the path search (the paper's "synthesis")
    render_s: float = 0.0   # time spent turning the path into frames (stitching and foot lock)
    foot_lock_s: float = 0.0  # the foot lock's part of render_s
    motifs: np.ndarray | None = None  # (beats,) motif of the word danced on each beat, when known

    @classmethod
    def of(cls, frames: Rendered, local_rot: np.ndarray, path: Path, pieces: Pieces,
           search_s: float, render_s: float, signature: SignatureTarget | None = None, *,
           foot_lock_s: float = 0.0) -> "SegmentFrames":
        motifs = None if signature is None else signature.node_motif[path.nodes[1:]]
        return cls(local_rot, frames.root_pos, frames.contacts, frames.source_pos, path, pieces, search_s, render_s,
                   foot_lock_s, motifs)

    def warp_rates(self, source_fps: float) -> np.ndarray:
        """Playback rate of each beat piece (source seconds per music second)."""
        return (self.pieces.f1 - self.pieces.f0) / (self.pieces.t1 - self.pieces.t0) / source_fps


def bar_shape(bar_position: np.ndarray | None, beats_per_bar: int | None, amount: float) -> np.ndarray | float:
    """What the metre adds to the standardised music intensity of each beat interval.

    ``+amount`` on a bar's first beat and ``-amount / (beats_per_bar - 1)`` on its others,
    so a bar keeps its mean: the intensity match then starts the big moves on the "1"
    and the dance's energy repeats with the bar (three beats in a waltz).
    """
    if bar_position is None or not beats_per_bar or beats_per_bar < 2 or amount == 0:
        return 0.0
    pos = np.asarray(bar_position)
    return np.where(pos == 0, amount, np.where(pos > 0, -amount / (beats_per_bar - 1), 0.0))


def standardise(values: np.ndarray, mean: float, std: float) -> np.ndarray:
    return (values - mean) / std if std > 1e-9 else np.zeros_like(values)


def revisits(nodes: np.ndarray, beat_times_s: np.ndarray, window_s: float,
             source: np.ndarray | None = None) -> tuple[dict[int, int], int]:
    """The nodes ``nodes`` (one per beat) comes back to within ``window_s``, each with the beat of its
    first visit, and how many beats come back. The form's replays (``source`` >= 0, FormPlan.source)
    are asked for: not counted."""
    nodes = np.asarray(nodes)
    times = np.asarray(beat_times_s, dtype=np.float64)[:len(nodes)]
    free = _form_replays(len(nodes), source)
    first: dict[int, int] = {}
    looped: dict[int, int] = {}
    count = 0
    for b in range(1, len(nodes)):
        n = int(nodes[b])
        if free[b]:
            continue
        if n in first and times[b] - times[first[n]] <= window_s:
            looped.setdefault(n, first[n])
            count += 1
        else:
            first[n] = b
    return looped, count


def revisit_penalty(nodes: np.ndarray, looped: dict[int, int], cost: float,
                    source: np.ndarray | None = None) -> tuple:
    """``search``'s ``beat_penalty`` charging each ``looped`` node (``revisits``) ``cost`` on every beat
    but its first visit: charged only near that visit, a loop would move on to another minute of the
    song. Beats the form replays are not charged."""
    free = _form_replays(len(nodes), source)
    beats = np.flatnonzero(~free)
    beats = beats[beats > 0]
    at = [beats[beats != b0] for b0 in looped.values()]
    on = [np.full(len(a), n) for n, a in zip(looped, at)]
    at, on = np.concatenate(at), np.concatenate(on)
    return at, on, np.full(len(at), float(cost))


def _form_replays(n: int, source: np.ndarray | None) -> np.ndarray:
    free = np.zeros(n, bool)
    if source is not None:
        free[:min(n, len(source))] = np.asarray(source)[:n] >= 0
    return free


def pieces_from_path(graph: MetaMotionGraph, path: Path, beat_times_s: np.ndarray,
                     beat_count: np.ndarray | None = None, ease: np.ndarray | None = None,
                     ease_max_rate: float | None = None, room: SpeedRoom | None = None) -> Pieces:
    """The path's beat pieces; ``beat_count`` and ``ease`` (K+1,) per beat as in ``Pieces``, the easing
    kept within ``ease_max_rate`` times the captured speed and ``room`` (``timing.ease_within``)."""
    f0 = graph.render_frame[path.via].astype(np.float64)
    f1 = graph.render_frame[path.nodes[1:]].astype(np.float64)
    count = np.arange(len(beat_times_s), dtype=np.float64) if beat_count is None else \
        np.asarray(beat_count, dtype=np.float64)
    shown = None
    if ease is not None:
        rates = (f1 - f0) / graph.fps / np.diff(beat_times_s)
        ease = ease_within(ease, rates, ease_max_rate, count)
        shown = None if room is None else within_room(ease, count, f0, f1, rates, room)
    return Pieces(beat_times_s[:-1].astype(float), beat_times_s[1:].astype(float), f0, f1, path.jump.copy(),
                  None if beat_count is None else count[:-1], None if beat_count is None else count[1:],
                  None if ease is None else ease[:-1], None if ease is None else ease[1:], shown)


@dataclass(frozen=True)
class GraphEngine:
    style: Style
    graph: MetaMotionGraph
    config: EngineConfig = EngineConfig()
    fps: float = DEFAULT_FPS
    signature: SignatureTarget | None = None  # follow a genre's motif signature (signature.py)
    form: FormPlan | None = None              # follow the song's form, on the beat grid danced (form.py)

    def initial_state(self, seed: int | None = None, needed_beats: float = np.inf) -> StreamState:
        """Fresh state. Without a seed the first segment may start at any clip's first beat
        (InitS, as in the paper); a seed picks one of the starts that can dance
        ``needed_beats`` beats, so different seeds give different dances."""
        start = self.graph.init_nodes
        if seed is not None:
            able = start[self.graph.capacity[start] >= needed_beats]
            if len(able):
                start = np.array([np.random.default_rng(seed).choice(able)])
        return StreamState(start_nodes=start)

    def step(self, state: StreamState, segment: MusicSegment) -> tuple[StreamState, SegmentFrames]:
        """Synthesise and render one music segment."""
        beats = np.asarray(segment.beat_times_s, dtype=np.float64)
        inten = np.asarray(segment.intensity_db, dtype=np.float64)
        k = len(inten) - segment.ahead  # intervals danced now; the rest is only looked at
        n, mean, m2 = state.n_heard, state.mean_db, state.m2_db
        for x in inten[:k]:  # Welford: the statistics of all music heard so far
            n += 1
            d = x - mean
            mean += d / n
            m2 += d * (x - mean)
        std = np.sqrt(m2 / n) if n else 0.0
        if state.node is None:
            start = self.graph.init_nodes if state.start_nodes is None else state.start_nodes
        else:
            start = np.array([state.node])
        thc = np.inf if segment.remaining_beats is None else float(segment.remaining_beats - segment.ahead)
        seen = state.last_seen_s if state.last_seen_s is not None else np.full(self.graph.n_nodes, -np.inf)
        plan = segment.form if segment.form is not None else self.form
        targets, fresh, starts = self._form(state, len(beats), plan)
        penalty = None
        if self.config.repeat_penalty > 0:  # a new section remembers the whole dance
            window = np.inf if fresh else self.config.repeat_window_s
            penalty = self.config.repeat_penalty * (np.isfinite(seen) & (beats[0] - seen <= window))
        counts = state.motif_counts
        if self.signature is not None:
            counts = np.zeros(len(self.signature.template)) if counts is None else counts
            owed = self.signature.arrival_cost(counts)
            if owed is not None:
                penalty = owed if penalty is None else penalty + owed
        t0 = time.perf_counter()
        bars = segment.bar_position
        target = standardise(inten, mean, std) + bar_shape(None if bars is None else bars[:-1],
                                                            segment.beats_per_bar, self.config.bar_accent)
        target = target + self.config.section_accent * starts[:-1]

        def best(node_penalty):
            return search(self.graph, target, np.diff(beats), start_nodes=start,
                          prev_duration_s=state.prev_duration_s, thc=thc, node_penalty=node_penalty,
                          steps=self.steps, intensity_weight=self.config.intensity_weight,
                          shown_intensity=self.config.shown_intensity,
                          **self._beat_costs(bars, segment.music_beat), **self._targets(targets, state.beat, plan))

        path = best(penalty)
        # The memory knows the segments before this one; a path that comes back to its own beats (a loop
        # within the segment) is searched again with those beats charged too.
        for _ in range(self.config.repeat_retries if self.config.repeat_penalty > 0 else 0):
            visits = np.bincount(path.nodes[1:], minlength=self.graph.n_nodes)
            if visits.max() < 2:
                break
            penalty = penalty + self.config.repeat_penalty * (visits > 1)
            path = best(penalty)
        path = path.first(k)
        beats, bars = beats[:k + 1], None if bars is None else bars[:k + 1]
        count = None if segment.beat_count is None else segment.beat_count[:k + 1]
        seen = seen.copy()
        seen[path.nodes[1:]] = beats[1:]
        t1 = time.perf_counter()
        pieces = pieces_from_path(self.graph, path, beats, count,
                                  self.config.beat_ease(len(beats), bars, segment.beats_per_bar),
                                  self.config.ease_max_rate, self.speed_room)
        last = segment.end_s is not None
        stitch, frames = render(
            self.style, pieces, state.stitch, fps=self.fps, end_s=segment.end_s if last else float(beats[-1]),
            blend_s=self.config.blend_s, inclusive_end=last, roles=self.roles)
        t2 = time.perf_counter()
        local, feet = self._lock_feet(frames, state.feet)
        t3 = time.perf_counter()
        danced = np.r_[state.danced, path.nodes[1:]] if len(state.danced) else path.nodes.copy()
        new_state = replace(state, node=int(path.nodes[-1]), prev_duration_s=float(beats[-1] - beats[-2]),
                            n_heard=n, mean_db=mean, m2_db=m2, stitch=stitch, segments=state.segments + 1,
                            last_seen_s=seen, feet=feet, danced=danced,
                            motif_counts=None if counts is None else self.signature.count(counts, path.nodes[1:]))
        return new_state, SegmentFrames.of(frames, local, path, pieces, t1 - t0, time.perf_counter() - t1,
                                           self.signature, foot_lock_s=t3 - t2)

    def run_global(self, beat_times_s: np.ndarray, intensity_db: np.ndarray, end_s: float,
                   seed: int | None = None, bar_position: np.ndarray | None = None,
                   beats_per_bar: int | None = None, music_beat: np.ndarray | None = None,
                   beat_count: np.ndarray | None = None) -> SegmentFrames:
        """The global-DP baseline: one search over the whole song, then one render.

        ``bar_position``, ``beats_per_bar``, ``music_beat`` and ``beat_count`` as in ``MusicSegment``."""
        inten = np.asarray(intensity_db, dtype=np.float64)
        state = self.initial_state(seed, needed_beats=len(inten))
        t0 = time.perf_counter()
        # The same objective as streaming (jump cost included) but over the whole song.
        _, _, starts = self._form(state, len(beat_times_s), self.form)
        target = standardise(inten, inten.mean(), inten.std()) + bar_shape(
            None if bar_position is None else bar_position[:-1], beats_per_bar, self.config.bar_accent)
        target = target + self.config.section_accent * starts[:-1]

        def searched(targets, charged):
            return search(self.graph, target, np.diff(beat_times_s),
                          start_nodes=state.start_nodes, thc=0.0, steps=self.steps, beat_penalty=charged,
                          intensity_weight=self.config.intensity_weight,
                          shown_intensity=self.config.shown_intensity,
                          **self._beat_costs(bar_position, music_beat), **self._targets(targets, 0, self.form))

        def best(targets=None):
            # One DP remembers nothing it danced: alone it loops the song's best-matching cycle (four beats
            # of one take for 20 s). As streaming charges a beat danced in the last minute, the path is
            # searched again with each beat it comes back to charged on every beat but its first visit.
            # Charges move loops as well as end them, so the path that comes back least is kept.
            source = None if self.form is None else self.form.source
            path, charged = searched(targets, None), None
            looped, count = revisits(path.nodes, beat_times_s, self.config.repeat_window_s, source)
            kept = (count, path)
            for _ in range(self.config.global_retries if self.config.repeat_penalty > 0 else 0):
                if not looped:
                    break
                more = revisit_penalty(path.nodes, looped, self.config.repeat_penalty, source)
                charged = more if charged is None else tuple(np.r_[a, b] for a, b in zip(charged, more))
                path = searched(targets, charged)
                looped, count = revisits(path.nodes, beat_times_s, self.config.repeat_window_s, source)
                kept = min(kept, (count, path), key=lambda c: c[0])
            return kept[1]

        path = best()
        if self.form is not None and (self.form.source >= 0).any():
            # The form's pairs point back into the path itself: search again, rewarded for keeping the
            # first pass's nodes on the paired beats of both occurrences.
            path = best(self.form.held(path.nodes, self.mirror))
        t1 = time.perf_counter()
        pieces = pieces_from_path(self.graph, path, np.asarray(beat_times_s, dtype=np.float64), beat_count,
                                  self.config.beat_ease(len(beat_times_s), bar_position, beats_per_bar),
                                  self.config.ease_max_rate, self.speed_room)
        _, frames = render(self.style, pieces, state.stitch, fps=self.fps, end_s=end_s, blend_s=self.config.blend_s,
                           inclusive_end=True, roles=self.roles)
        t2 = time.perf_counter()
        local, _ = self._lock_feet(frames, state.feet)
        t3 = time.perf_counter()
        return SegmentFrames.of(frames, local, path, pieces, t1 - t0, t3 - t1, self.signature,
                                foot_lock_s=t3 - t2)

    def _form(self, state: StreamState, n: int, plan: FormPlan | None) -> tuple[np.ndarray, bool, np.ndarray]:
        """``plan``'s ask of the ``n`` beats from ``state.beat``: target nodes (-1: none), whether a new
        section begins or goes on in them, and which are a section's first beat."""
        if plan is None:
            return np.full(n, -1, dtype=np.int64), False, np.zeros(n)
        first = state.beat
        part = slice(first, first + n)
        starts = np.zeros(n)
        starts[:len(plan.section_start[part])] = plan.section_start[part]
        return (plan.targets(state.danced, first, n, self.mirror if plan.mirrored else None),
                bool(plan.fresh[part].any()), starts)

    def _targets(self, targets: np.ndarray | None, first: int, plan: FormPlan | None) -> dict:
        """``search``'s form terms for beats ``first ..`` with these target nodes."""
        if targets is None or plan is None or self.config.replay_reward <= 0 or not (targets >= 0).any():
            return {}
        entry = np.zeros(len(targets), bool)
        part = plan.entry[first:first + len(targets)]
        entry[:len(part)] = part
        return {"beat_target": targets, "target_reward": self.config.replay_reward, "entry": entry,
                "entry_cost": self.config.entry_cost}

    @cached_property
    def mirror(self) -> np.ndarray | None:
        """Each node's mirror-image node, for ``--repeat mirror`` (None: the style has no mirrored takes)."""
        return graph_mirror(self.style, self.graph)

    @cached_property
    def speed_room(self) -> SpeedRoom | None:
        """How fast the style's source moves, for the accent timing (None: not limited by it)."""
        return speed_room(self.style, self.config)

    @cached_property
    def roles(self) -> JointRoles:
        """The style's feet, knees and hips (found once: each segment's render and foot lock need them)."""
        return find_roles(self.style.skeleton)

    @cached_property
    def steps(self) -> StepCosts:
        """The graph's step costs under this configuration, shared by every search."""
        return StepCosts(self.graph, self.config.jump_cost, self.config.accent)

    def _beat_costs(self, bar_position: np.ndarray | None, music_beat: np.ndarray | None) -> dict:
        """``search``'s per-beat costs: a clear stop is worth more on a bar's first beat, and
        costs what an off-beat stop does on a grid beat that is no music beat."""
        strength = self.graph.node_accent
        if strength is None or self.config.accent is None or (bar_position is None and music_beat is None):
            return {}
        n = len(bar_position if bar_position is not None else music_beat)
        cls = np.full(n, -1)
        if bar_position is not None:
            cls[np.asarray(bar_position) == 0] = 0
        if music_beat is not None:
            cls[~np.asarray(music_beat, dtype=bool)] = 1
        cls[0] = -1  # the segment's first node was chosen by the previous segment
        return {"beat_class": cls, "class_cost": self._class_costs}

    @cached_property
    def _class_costs(self) -> np.ndarray:
        """(2, N): arriving at each node on a bar's first beat, and on a grid beat that is no music beat."""
        strength = self.graph.node_accent
        return np.stack([-self.config.downbeat_stop * np.minimum(strength, 3.0),
                         self.config.accent.beat_costs(strength, strength)[1]])

    def _lock_feet(self, frames: Rendered, feet: FootLockState):
        if not self.config.foot_lock:
            return frames.local_rot, feet
        return lock_feet(self.style.skeleton, self.roles, frames, feet, fps=self.fps)

"""The double buffer of Xu et al.'s Fig. 1: segment n is synthesised while segment n+1 is heard.

The main thread reads audio and feeds the streaming beat tracker; every
``segment_s`` of audio it cuts a ``MusicSegment`` (the first early, after ``first_segment_s``,
so that the dance starts within 2 s) and hands it to one worker thread, which runs the engine's pure
``step`` and passes the frames to a sink. Steps run in order on that one worker,
so the engine's state never needs a lock; reading never waits for synthesis.

A cut's beats are those the tracker is sure of (given for good, ``hindsight_s`` before what was
heard) and then its guess at those since, up to what was heard (``peek``: not given, so the
tracker stays anchored on sure beats; the next cut keeps the sure beats after the last one danced).
So a beat's move is ready at most a segment after the beat was heard, and a wrong guess at the edge
costs a few beats, never the tracker's phase.

A stalled source does not stop the dancer: in real-time mode, when no audio has
arrived for ``stall_s`` the runtime feeds silence at the wall clock's pace, the
tracker carries the beat on at the last tempo, and the dance goes on (within the
graph's synchronization capacity, which is infinite for a live stream: THC = inf).
"""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..engines.beatgrid import choose_style
from ..engines.form import check_repeat
from ..engines.graph.cache import load_graph
from ..engines.graph.engine import EngineConfig, GraphEngine, MusicSegment
from ..errors import InputError
from ..motion.database import MotionDatabase, open_database
from ..motion.motifs import chi2
from ..types import DEFAULT_FPS, FALLBACK_BPM, SEGMENT_S, MotionClip, check_fps, check_seed
from .beats import LATENCY_S, StreamingBeatTracker
from .form import LiveForm
from .sources import AudioSource, wait_for_audio


# The first segment: cut after this much audio, so that the first motion is ready within 2 s (its beats are
# all guessed at the edge, even without ``edge``); each later cut comes ``segment_s`` after the one before.
FIRST_SEGMENT_S = 1.8


@dataclass(frozen=True)
class LiveConfig:
    segment_s: float = SEGMENT_S
    style: str | None = None
    fps: float = DEFAULT_FPS
    seed: int | None = None
    database: object = None            # a MotionDatabase, a path, or None for the bundled one
    stall_s: float | None = None       # feed silence after this long without audio (default: one segment)
    first_audio_timeout_s: float = 20.0
    render: EngineConfig = field(default_factory=EngineConfig)
    follow_signature: bool = False     # keep the genre's motif signature (engines/graph/signature.py)
    repeat: str = "off"                # the song's form, as heard (live/form.py): same, mirror, vary or off
    vary: float = 0.5
    first_segment_s: float = FIRST_SEGMENT_S   # the first segment is cut this soon, on every beat heard so far
    hindsight_s: float = LATENCY_S     # a cut takes the beats up to this long before what was heard for sure,
    edge: bool = True                  # and dances the tracker's guess at those after, up to what was heard

    def __post_init__(self):
        check_repeat(self.repeat, self.vary)
        if not (np.isfinite(self.hindsight_s) and self.hindsight_s >= 0.0):
            raise InputError(f"the cuts' hindsight must be 0 s or more, got {self.hindsight_s!r}")
        if not (np.isfinite(self.first_segment_s) and self.first_segment_s >= 1.0):
            raise InputError(f"the first segment must be at least 1 s long, got {self.first_segment_s!r}")
        check_seed(self.seed)
        check_fps(self.fps)


@dataclass(frozen=True)
class SegmentReport:
    index: int
    audio_end_s: float        # how much audio had been heard when the segment was cut
    beats: int                # beat intervals in the segment
    motion_start_s: float     # stream time of its first and last frame
    motion_end_s: float
    process_s: float          # time in the engine's step (search + render + foot lock)
    segment_s: float
    ready_s: float            # wall time since the first audio arrived when its frames reached the sink
    silence_s: float          # silence fed for stalls so far
    beat_times_s: tuple = ()  # the music beats this segment dances to (stream time)
    tempo_bpm: float = 0.0    # the tracker's tempo when the segment was cut
    beat_in_bar: tuple = ()   # per beat of beat_times_s, its position in its bar (0 = downbeat)
    beats_per_bar: int = 4    # the metre the tracker counted those beats in

    @property
    def late(self) -> bool:
        return self.process_s > self.segment_s


class _Worker:
    """Owns the engine state; runs steps in order on one thread."""

    def __init__(self, engine: GraphEngine, seed, on_frames, on_report, t0: float, fps: float):
        self.engine = engine
        self.state = engine.initial_state(seed)
        self.on_frames, self.on_report = on_frames, on_report
        self.t0, self.fps = t0, fps
        self.frames = 0
        self.reports: list[SegmentReport] = []

    def run(self, index: int, segment: MusicSegment, audio_end_s: float, segment_s: float, silence_s: float,
            beats: tuple, tempo: float, bars: tuple = (), beats_per_bar: int = 4):
        t = time.perf_counter()
        self.state, out = self.engine.step(self.state, segment)
        process_s = time.perf_counter() - t
        clip = MotionClip(self.engine.style.skeleton, self.fps, out.root_pos, out.local_rot, contacts=out.contacts)
        start = self.frames / self.fps
        self.frames += clip.n_frames
        self.on_frames(clip)
        report = SegmentReport(index, audio_end_s, len(segment.intensity_db), start, self.frames / self.fps,
                               process_s, segment_s, time.perf_counter() - self.t0, silence_s, beats, tempo,
                               bars, beats_per_bar)
        self.reports.append(report)
        if self.on_report is not None:
            self.on_report(report)


def run_live(source: AudioSource, on_frames: Callable[[MotionClip], None], *, config: LiveConfig = LiveConfig(),
             on_report: Callable[[SegmentReport], None] | None = None, realtime: bool = True,
             stop: threading.Event | None = None) -> dict:
    """Dance to ``source`` until it ends (or ``stop`` is set); frames go to ``on_frames`` segment by segment.

    Returns a summary: style, tempo, segments, per-segment processing times,
    the wall time at which the first motion was ready, how much silence was
    fed for stalls.
    """
    if not config.segment_s > 0.5:
        raise InputError(f"segment length must be more than 0.5 s, got {config.segment_s!r}")
    db = config.database if isinstance(config.database, MotionDatabase) else open_database(config.database)
    if config.style:
        db.styles_of(config.style)  # an unknown style fails now, not after the first segment
    stall_s = config.stall_s if config.stall_s is not None else config.segment_s
    tracker = StreamingBeatTracker(source.sr)
    form = LiveForm(source.sr, config.repeat, config.vary)
    first = wait_for_audio(source, config.first_audio_timeout_s)
    t0 = time.perf_counter()  # latencies count from the first audio, as a listener hears it
    tracker.push(first.samples)
    form.push(first.samples)
    last_audio = t0
    silence_s = 0.0
    heard_s = first.samples.size / source.sr
    executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="dancesynth-step")
    worker: _Worker | None = None
    futures = []
    prev_beat: float | None = None
    prev_bar = 0
    next_cut = min(config.first_segment_s, config.segment_s)   # a short first segment, on unsure beats
    waiting = None   # the beats of a first cut too short to start on, kept for the next try
    index = 0
    ended = False
    stalled = False
    tempo = 0.0
    metre = 4
    try:
        while not ended:
            if stop is not None and stop.is_set():
                ended = True
            else:
                try:
                    chunk = source.read(timeout=0.05)
                except StopIteration:
                    ended = True
                    chunk = None
                now = time.perf_counter()
                if chunk is not None and chunk.samples.size:
                    tracker.push(chunk.samples)
                    form.push(chunk.samples)
                    heard_s += chunk.samples.size / source.sr
                    last_audio = now
                    stalled = False
                elif realtime and (stalled or now - last_audio > stall_s):
                    # Once stalled, silence goes in as the clock runs, so segments keep being cut on time.
                    stalled = True
                    gap = now - last_audio
                    tracker.push(np.zeros(int(gap * source.sr), dtype=np.float32))
                    form.push(np.zeros(int(gap * source.sr), dtype=np.float32))
                    heard_s += gap
                    silence_s += gap
                    last_audio = now
            while futures and futures[0].done():
                futures.pop(0).result()  # a failed step (a full disk) ends the dance now, not at the source's end
            if not ended and heard_s < next_cut:
                continue
            # The beats the tracker is sure of (given for good), then its guess at those since, up to what
            # was heard (peeked: the next cut gets them again, surer, and keeps those after the last danced).
            update = tracker.flush() if ended else tracker.update(until_s=heard_s - config.hindsight_s)
            sure = _beats_of(update)
            if waiting is not None:
                sure = tuple(np.concatenate((a, b)) for a, b in zip(waiting, sure))
                waiting = None
            peek = (config.edge or worker is None) and not ended   # the first cut always: it cannot wait
            edge = _beats_of(tracker.peek(heard_s) if peek else None)
            beats, inten, bars = (np.concatenate((a, b)) for a, b in zip(sure, edge))
            tempo, metre = update.tempo_bpm or tempo, update.beats_per_bar
            if worker is not None:   # the beats danced already, as guessed at the last cut
                keep = beats > prev_beat + 0.5 * (60.0 / tempo if tempo > 0 else 60.0 / FALLBACK_BPM)
                beats, inten, bars = beats[keep], inten[keep], bars[keep]
            # Each cut comes a segment of audio after the one before (the first, early): no beat waits longer.
            next_cut = heard_s + config.segment_s
            if worker is None:
                if beats.size < 2 and not ended:   # not enough beats yet to start: try again soon, with these
                    waiting, next_cut = sure, heard_s + 0.25
                    continue
                if beats.size == 0:
                    break
                style, _ = choose_style(db, tempo if tempo > 0 else FALLBACK_BPM, config.style)
                style = style.material
                graph, _ = load_graph(style)
                worker = _Worker(GraphEngine(style, graph, config.render, fps=config.fps,
                                             signature=_signature(config, db, style, graph)),
                                 config.seed, on_frames, on_report, t0, config.fps)
                covered, inten = _cover_start(beats, inten, tempo)
                # The beats made up before the first heard one count backwards in its bar.
                bars = np.concatenate(((bars[0] - np.arange(covered.size - beats.size, 0, -1)) % metre, bars))
                beats = covered
                prev_beat, prev_bar = float(beats[0]), int(bars[0])
                beats, inten, bars = beats[1:], inten, bars[1:]
            if beats.size == 0 and not ended:
                continue
            times = np.concatenate(([prev_beat], beats))
            positions = np.concatenate(([prev_bar], bars))
            end_s = None
            if ended:
                # The last segment renders to the end of what was heard: carry the beat on to it.
                end_s = max(heard_s, float(times[-1]))
                period = float(times[-1] - times[-2]) if times.size > 1 else (60.0 / tempo if tempo > 0 else 0.6)
                n_after = int(np.ceil((end_s - times[-1]) / period - 1e-9)) if times.size < 2 or end_s > times[-1] else 0
                n_after = max(n_after, 1 if times.size < 2 else 0)
                times = np.concatenate((times, times[-1] + period * np.arange(1, n_after + 1)))
                positions = np.concatenate((positions, (positions[-1] + np.arange(1, n_after + 1)) % metre))
                last = inten[-1] if inten.size else 0.0
                inten = np.concatenate((inten, np.full(n_after, last)))
            new_beats = tuple(float(t) for t in (times if index == 0 else times[1:]))
            new_bars = tuple(int(p) for p in (positions if index == 0 else positions[1:]))
            form.add_beats(new_beats, new_bars, metre)   # what the music repeats, as heard so far
            segment = MusicSegment(times, inten, remaining_beats=None, end_s=end_s, bar_position=positions,
                                   beats_per_bar=metre, form=form.plan if config.repeat != "off" else None)
            futures.append(executor.submit(worker.run, index, segment, heard_s, config.segment_s, silence_s,
                                           new_beats, tempo, new_bars, metre))
            prev_beat, prev_bar = float(times[-1]), int(positions[-1])
            index += 1
        for f in futures:
            f.result()  # re-raise a failure of the worker here
    finally:
        executor.shutdown(wait=True, cancel_futures=True)
    reports = worker.reports if worker else []
    steps = [r.process_s for r in reports]
    counts = worker.state.motif_counts if worker else None
    return {
        "motif_chi2": chi2(worker.engine.signature.template, counts) if counts is not None and counts.sum() else None,
        "style": worker.engine.style.name if worker else None,
        "tempo_bpm": tempo,
        "beats_per_bar": metre,
        "heard_s": heard_s,
        "silence_s": silence_s,
        "segments": len(reports),
        "frames": worker.frames if worker else 0,
        "fps": config.fps,
        "segment_s": config.segment_s,
        "step_s_median": float(np.median(steps)) if steps else 0.0,
        "step_s_max": float(np.max(steps)) if steps else 0.0,
        "late_segments": sum(r.late for r in reports),
        "first_motion_ready_s": reports[0].ready_s if reports else None,
        **beat_delays(reports),
        "first_audio_s": reports[0].audio_end_s if reports else None,
        "form": {**form.summary(), "bar_starts_s": form.bar_starts_s().tolist(),
                 **(form.plan.replayed(worker.state.danced) if worker else {}),
                 "beat_times_s": form.beat_times_s().tolist(),   # the beats danced, and the graph node of each
                 "danced": [] if worker is None else worker.state.danced.tolist()},
    }


def segment_lead_s(segment_s: float, first_segment_s: float = FIRST_SEGMENT_S) -> float:
    """How long after the first segment's frames the last of the next segment's can arrive, relative to their
    place in the dance: a segment later, less the first one's length."""
    return max(0.0, segment_s - min(first_segment_s, segment_s))


def beat_delays(reports: list[SegmentReport]) -> dict:
    """How long after a beat was heard its move was ready (the segment's ``ready_s`` less the beat's time), over
    the segments after the first (whose beats were taken early): median and largest, in seconds."""
    delays = [r.ready_s - t for r in reports[1:] for t in r.beat_times_s if t >= 0]
    return {"beat_delay_s_median": float(np.median(delays)) if delays else None,
            "beat_delay_s_max": float(np.max(delays)) if delays else None}


def _beats_of(update) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An update's beat times, intensities and bar positions (none for None)."""
    if update is None:
        return np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.int64)
    return (np.asarray(update.beat_times_s, dtype=np.float64), np.asarray(update.intensity_db, dtype=np.float64),
            np.asarray(update.beat_in_bar, dtype=np.int64))


def _signature(config: LiveConfig, db, style, graph):
    if not config.follow_signature:
        return None
    from ..engines.graph.signature import database_signature

    return database_signature(style, graph, db, config.render.signature_weight)


def _cover_start(beats: np.ndarray, inten: np.ndarray, tempo: float) -> tuple[np.ndarray, np.ndarray]:
    """Beats extended backwards at the first beat period so the first interval starts at or before 0 s."""
    period = float(beats[1] - beats[0]) if beats.size > 1 else (60.0 / tempo if tempo > 0 else 0.6)
    n_before = int(np.ceil(max(beats[0], 0.0) / period - 1e-9)) if period > 0 else 0
    first = inten[0] if inten.size else 0.0
    # The first beat's interval (from the stream start) is replaced by regular ones.
    head = beats[0] - period * np.arange(n_before, 0, -1)
    times = np.concatenate((head, beats))
    if n_before == 0:
        times = np.concatenate(([beats[0] - period], beats))
        n_before = 1
    return times, np.concatenate((np.full(n_before, first), inten[1:] if inten.size == beats.size else inten))

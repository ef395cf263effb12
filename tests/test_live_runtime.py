"""The double buffer of Xu et al.'s Fig. 1 under a clock the test drives: audio is read on while
a segment is synthesised, segments reach the sink in order and back to back, and a stall is
bridged with motion at the wall clock's pace. No real time passes: every read advances the clock
by the audio it returns (or, on a stall, by how long the reader waited)."""

from __future__ import annotations

import threading
import types

import numpy as np
import pytest

from conftest import BUNDLED_MUSIC
from dancesynth.engines.graph.engine import GraphEngine
from dancesynth.io.audio import load_audio
from dancesynth.live import runtime
from dancesynth.live.runtime import LiveConfig, run_live
from dancesynth.live.sources import SR, Chunk

SEGMENT_S = 2.0


class ScriptedSource:
    """A song in 0.1 s chunks as fast as they are asked for, with an optional stall: ``stall`` =
    (after_s, for_s). The clock moves with what the runtime reads and waits for."""

    def __init__(self, samples: np.ndarray, clock: dict, stall: tuple[float, float] | None = None):
        self.sr, self.spec, self.error = SR, "scripted", ""
        self.samples, self.clock, self.stall = samples, clock, stall
        self.pos = 0
        self.reads = 0

    @property
    def heard_s(self) -> float:
        return self.pos / self.sr

    def read(self, timeout: float):
        self.reads += 1
        if self.stall and self.stall[0] <= self.heard_s and self.clock["stalled"] < self.stall[1]:
            self.clock["now"] += timeout
            self.clock["stalled"] += timeout
            return None
        if self.pos >= len(self.samples):
            raise StopIteration
        n = int(0.1 * self.sr)
        chunk = Chunk(self.samples[self.pos:self.pos + n], self.pos / self.sr)
        self.pos += n
        self.clock["now"] += n / self.sr
        return chunk


@pytest.fixture(scope="module")
def song():
    y, _ = load_audio(BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg", sr=SR)
    return y[: 16 * SR]


@pytest.fixture
def clock(monkeypatch):
    clock = {"now": 0.0, "stalled": 0.0}
    monkeypatch.setattr(runtime, "time", types.SimpleNamespace(perf_counter=lambda: clock["now"]))
    return clock


def test_audio_is_read_on_while_a_segment_is_synthesised_and_segments_arrive_in_order(song, clock, bundled_db,
                                                                                     monkeypatch):
    source = ScriptedSource(song, clock)
    step, read_on = GraphEngine.step, []

    def slow_step(engine, state, segment):
        # The first step holds until the reader has gone on a whole segment: if reading waited for
        # synthesis, that would never happen (bounded: 10 s of real time).
        if not read_on:
            start = source.heard_s
            for _ in range(1000):
                if source.heard_s >= start + SEGMENT_S:
                    break
                threading.Event().wait(0.01)
            read_on.append(source.heard_s - start)
        return step(engine, state, segment)

    monkeypatch.setattr(GraphEngine, "step", slow_step)
    clips, reports = [], []
    summary = run_live(source, clips.append, config=LiveConfig(segment_s=SEGMENT_S, database=bundled_db),
                       on_report=reports.append, realtime=False)
    assert read_on[0] >= SEGMENT_S - 1e-6   # the reader went on during the first step
    assert [r.index for r in reports] == list(range(len(reports))) and len(reports) >= 6
    for a, b in zip(reports, reports[1:]):
        assert b.motion_start_s == pytest.approx(a.motion_end_s)   # back to back, in order
    for a, b in zip(reports, reports[1:-1]):                      # (the last one ends with the song)
        assert b.audio_end_s >= a.audio_end_s + SEGMENT_S - 0.11   # cut every segment of audio heard
    assert sum(c.n_frames for c in clips) == summary["frames"]
    assert summary["frames"] / summary["fps"] == pytest.approx(source.heard_s, abs=0.5)


def test_a_stall_is_danced_through_at_the_clocks_pace(song, clock, bundled_db):
    source = ScriptedSource(song, clock, stall=(6.0, 9.0))
    clips, reports = [], []
    summary = run_live(source, clips.append, config=LiveConfig(segment_s=SEGMENT_S, database=bundled_db),
                       on_report=reports.append, realtime=True)
    assert summary["silence_s"] == pytest.approx(9.0, abs=0.3)  # the whole stall, once it is one segment long
    # Motion for every second of the clock: segments keep being cut through the stall, one per
    # segment of time, and the dance lasts as long as the music plus the bridged stall.
    during = [r for r in reports if 6.0 <= r.audio_end_s <= 6.0 + 9.0 + SEGMENT_S]
    assert len(during) >= 4
    for a, b in zip(during, during[1:]):
        assert b.audio_end_s - a.audio_end_s == pytest.approx(SEGMENT_S, abs=0.15)
    total = summary["frames"] / summary["fps"]
    assert total == pytest.approx(16.0 + summary["silence_s"], abs=0.5)


@pytest.mark.parametrize("edge", [True, False])
def test_the_first_motion_comes_within_two_seconds_then_whole_segments(song, clock, bundled_db, edge):
    source = ScriptedSource(song, clock)
    clips, reports = [], []
    config = LiveConfig(segment_s=5.0, database=bundled_db, edge=edge)
    summary = run_live(source, clips.append, config=config,
                       on_report=reports.append, realtime=False)
    first = reports[0]
    # Counted in audio read (the scripted clock), not wall time: the cut comes after FIRST_SEGMENT_S of music.
    # How soon the motion is ready in wall time is benchmarks/live_bench.py's to measure.
    assert first.audio_end_s == pytest.approx(runtime.FIRST_SEGMENT_S, abs=0.11) and first.audio_end_s <= 2.0
    assert first.motion_end_s > 0.5 and len(first.beat_times_s) >= 2              # a short first dance, on beats
    for a, b in zip(reports, reports[1:-1]):                                     # then a segment each
        assert b.audio_end_s == pytest.approx(a.audio_end_s + 5.0, abs=0.11)
    for a, b in zip(reports, reports[1:]):
        assert b.motion_start_s == pytest.approx(a.motion_end_s)                   # back to back
    # Each later segment holds the beats heard up to its cut (by default; else those the tracker is sure of,
    # its hindsight before), so a beat's move is ready at most a segment after it was heard.
    for r in reports[1:-1]:
        last = r.audio_end_s - (0.0 if edge else config.hindsight_s)
        assert last - 0.7 <= r.beat_times_s[-1] <= last + 0.05
    assert summary["beat_delay_s_median"] is not None

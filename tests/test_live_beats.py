"""Streaming beat tracking: beats given once, in order, on time, through silence, in bounded memory."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

import signals
from dancesynth.errors import InputError
from dancesynth.eval.beat_metrics import beat_tracking_scores
from dancesynth.live.beats import LATENCY_S, BeatUpdate, StreamingBeatTracker
from dancesynth.music.intensity import beat_intensity_db
from dancesynth.music.onset import onset_envelope

SR = signals.SR


def run_stream(y: np.ndarray, chunks, *, every_s: float = 0.0, **options):
    """Push ``y`` in chunks of the given sizes (cycled); update every ``every_s`` of audio (0: every chunk).

    Checks on the way that no beat is ever revised: every update's beats increase
    and all come after every beat given before. Returns the tracker, the updates
    (the flush last) and the concatenated beats and flags.
    """
    tracker = StreamingBeatTracker(SR, **options)
    updates, last, start, k, next_update = [], -np.inf, 0, 0, every_s
    tracker.chunk_before_update = []    # the size of the chunk pushed just before each update
    while start < len(y):
        size = chunks[k % len(chunks)]
        tracker.push(y[start:start + size])
        start, k = start + size, k + 1
        if tracker.heard_s >= next_update:
            updates.append(tracker.update())
            tracker.chunk_before_update.append(size / SR)
            next_update += every_s
    updates.append(tracker.flush())
    for u in updates:
        assert isinstance(u, BeatUpdate)
        assert u.beat_times_s.shape == u.intensity_db.shape == u.extrapolated.shape
        if u.beat_times_s.size:
            assert np.all(np.diff(u.beat_times_s) > 0) and u.beat_times_s[0] > last
            last = u.beat_times_s[-1]
    beats = np.concatenate([u.beat_times_s for u in updates])
    extrapolated = np.concatenate([u.extrapolated for u in updates])
    return tracker, updates, beats, extrapolated


def nearest(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """For every value of ``a``, the distance to the nearest value of ``b``."""
    return np.abs(a[:, None] - b[None, :]).min(axis=1)


def test_click_track_in_odd_chunks_on_time_never_revised_and_within_the_latency():
    y, clicks = signals.click_track(120, 20.0)
    chunks = [37, 2205, 1, 4410, 999, 12345, 441]
    tracker, updates, beats, extrapolated = run_stream(y, chunks)
    assert not extrapolated.any()
    assert np.all(nearest(beats, clicks) < 0.020), beats[nearest(beats, clicks) >= 0.020]
    assert np.median(nearest(beats, clicks)) < 0.005     # the onset latency is corrected
    # Every click after the first second is a beat, and nothing after the last click.
    assert np.all(nearest(clicks[clicks > 1.0], beats) < 0.020)
    assert beats[-1] < clicks[-1] + 0.1
    # Latency: a beat comes with the first update that has heard it + latency.
    for u, chunk_s in zip(updates[:-1], tracker.chunk_before_update):
        assert np.all(u.heard_s - u.beat_times_s <= LATENCY_S + chunk_s + 1e-9), (u, chunk_s)
        assert u.latency_s == LATENCY_S
    assert abs(updates[-2].tempo_bpm - 120) < 3
    assert updates[-1].heard_s == pytest.approx(len(y) / SR)


def test_intensity_is_the_level_of_each_interval_closed_by_a_beat():
    y, _ = signals.drum_loop(100, 12.0)
    y[int(6 * SR):] *= 0.1      # 20 dB quieter in the second half
    _, updates, beats, _ = run_stream(y, [2205], every_s=5.0)
    intensity = np.concatenate([u.intensity_db for u in updates])
    expected = beat_intensity_db(y, SR, np.concatenate(([0.0], beats)))
    np.testing.assert_allclose(intensity, expected, atol=1e-6)
    assert intensity[beats < 5.5].mean() - intensity[beats > 6.7].mean() > 15


@pytest.mark.skipif(shutil.which("fluidsynth") is None, reason="fluidsynth not installed")
@pytest.mark.parametrize("tempo", [(90, 120), (140, 100)])
def test_a_tempo_step_in_a_generated_song_is_followed(tmp_path_factory, tempo):
    from dancesynth.bench.groundtruth import SongSpec, render_song
    from dancesynth.io.audio import load_audio

    spec = SongSpec(f"step{tempo[0]}-{tempo[1]}", tempo, kind="step", duration_s=24.0, seed=3)
    song = render_song(spec, tmp_path_factory.mktemp("groundtruth"))
    y, sr = load_audio(song.audio_path)
    assert sr == SR
    _, updates, beats, extrapolated = run_stream(y, [2205], every_s=5.0)
    assert beat_tracking_scores(song.beats_s, beats)["f_measure"] >= 0.9
    assert not extrapolated[beats > 1.0].any()
    assert abs(updates[-2].tempo_bpm - tempo[1]) < 5


@pytest.mark.skipif(shutil.which("fluidsynth") is None, reason="fluidsynth not installed")
def test_beats_given_early_on_the_wrong_phase_are_mended_by_a_rephase(tmp_path_factory):
    """At 60 bpm the first seconds look like 120 bpm with beats on the eighths; updated every
    chunk, the first beats are given on too little audio, and later ones must not follow them."""
    from dancesynth.bench.groundtruth import SongSpec, render_song
    from dancesynth.io.audio import load_audio

    spec = SongSpec("c60", (60,), duration_s=20.0, seed=60)
    song = render_song(spec, tmp_path_factory.mktemp("groundtruth"))
    y, _ = load_audio(song.audio_path)
    _, updates, beats, _ = run_stream(y, [2205])
    assert beat_tracking_scores(song.beats_s, beats)["f_measure"] >= 0.9
    assert abs(updates[-2].tempo_bpm - 60) < 3


def test_updated_every_chunk_a_real_song_keeps_a_steady_beat(bundled_song):
    """The anchored DP keeps the given phase: few beat intervals differ from the last by 15 %."""
    from dancesynth.io.audio import load_audio

    y, _ = load_audio(bundled_song)
    _, _, beats, _ = run_stream(y[:30 * SR], [2205])
    intervals = np.diff(beats[beats > 3.0])
    assert np.mean(np.abs(intervals[1:] / intervals[:-1] - 1) > 0.15) < 0.04
    assert 0.44 < np.median(intervals) < 0.48      # 130 bpm


def test_silence_in_the_middle_keeps_the_beat_and_resumes_on_the_music():
    first, clicks_1 = signals.click_track(120, 8.0, offset_s=0.25)
    second, clicks_2 = signals.click_track(100, 10.0, offset_s=0.13)
    gap_s = 6.0
    y = np.concatenate((first, np.zeros(int(gap_s * SR), np.float32), second))
    clicks_2 = clicks_2 + 8.0 + gap_s
    _, updates, beats, extrapolated = run_stream(y, [2205], every_s=1.0)
    # During the silence the beats go on at the last tempo, marked as extrapolated.
    silent = (beats > 8.3) & (beats < 8.0 + gap_s - 0.1)
    assert silent.sum() >= 9 and extrapolated[silent].all()
    np.testing.assert_allclose(np.diff(beats[silent]), 0.5, atol=0.005)
    # Beats never pause for longer than 1.5 periods, and never crowd below 0.5.
    intervals = np.diff(beats)
    assert intervals.max() < 1.5 * 0.6 + 0.01 and intervals.min() > 0.25
    # On the music again, on the clicks, at the new tempo.
    resumed = beats > clicks_2[0] + 1.5
    assert resumed.sum() >= 10 and not extrapolated[resumed].any()
    assert np.all(nearest(beats[resumed], clicks_2) < 0.020)
    assert abs(updates[-2].tempo_bpm - 100) < 3


def test_silence_before_any_music_gives_beats_at_the_fallback_tempo():
    tracker = StreamingBeatTracker(SR, fallback_bpm=90.0)
    tracker.push(np.zeros(5 * SR, np.float32))
    u = tracker.update()
    assert u.extrapolated.all() and u.beat_times_s.size >= 4
    np.testing.assert_allclose(np.diff(u.beat_times_s), 60 / 90, atol=1e-9)
    assert u.beat_times_s[-1] <= 5 - LATENCY_S + 1e-9
    assert np.all(u.intensity_db == -100.0)


def test_until_s_bounds_the_beats_given():
    y, clicks = signals.click_track(120, 12.0)
    tracker = StreamingBeatTracker(SR)
    tracker.push(y[:10 * SR])
    u = tracker.update(until_s=6.0)
    assert u.beat_times_s[-1] <= 6.0 and u.beat_times_s[-1] > 5.4
    assert tracker.update(until_s=5.0).beat_times_s.size == 0      # nothing before what was given
    rest = tracker.update(until_s=100.0)                            # at most what was heard
    assert rest.beat_times_s[0] > 6.0 and rest.beat_times_s[-1] <= 10.0


def test_streaming_sees_the_offline_envelope():
    y, _ = signals.drum_loop(110, 12.0)
    tracker = StreamingBeatTracker(SR, history_s=30.0)
    for start in range(0, len(y), 1000):
        tracker.push(y[start:start + 1000])
    tracker.flush()
    env, first = tracker.envelope()
    offline = onset_envelope(y, SR)
    assert first == 0 and env.shape == offline.shape
    np.testing.assert_allclose(env, offline, rtol=1e-3, atol=1e-3)


def test_memory_stays_bounded_over_an_hour_pushed_fast():
    block, _ = signals.click_track(120, 10.0, offset_s=0.0)  # 20 beats, loops seamlessly
    tracker = StreamingBeatTracker(SR)
    for _ in range(3):      # 30 s in small chunks, updated every 5 s
        for start in range(0, len(block), 2205):
            tracker.push(block[start:start + 2205])
            if start % (5 * SR) == 0:
                tracker.update()
    u = tracker.update()
    n_beats = int(np.searchsorted(np.arange(0, 30, 0.5), u.beat_times_s[-1], side="right"))
    sizes = {name: arr.shape for name, arr in vars(tracker).items() if isinstance(arr, np.ndarray)}
    rings = {name: ring.data.shape for name, ring in vars(tracker).items() if hasattr(ring, "data")}
    nbytes = tracker.memory_bytes()
    minute = np.tile(block, 6)
    for _ in range(59):     # then a minute at a time, longer than the history: the tracker bridges the gaps
        tracker.push(minute)
        u = tracker.update()
        n_beats += u.beat_times_s.size
        assert np.all(np.diff(u.beat_times_s) > 0.49) and np.all(np.diff(u.beat_times_s) < 0.51)
    tracker.push(minute[:len(minute) // 2])
    u = tracker.update()
    n_beats += u.beat_times_s.size
    assert tracker.heard_s == pytest.approx(3600.0)
    assert {name: arr.shape for name, arr in vars(tracker).items() if isinstance(arr, np.ndarray)} == sizes
    assert {name: ring.data.shape for name, ring in vars(tracker).items() if hasattr(ring, "data")} == rings
    assert tracker.memory_bytes() == nbytes < 20e6
    # One beat every 0.5 s from 0 s, none lost, none doubled, up to the latency.
    last = u.beat_times_s[-1]
    assert n_beats == np.searchsorted(np.arange(0, 3600, 0.5), last + 0.02) and last > 3600 - LATENCY_S - 0.5
    assert not u.extrapolated[-20:].any()     # the recent beats were heard, the bridge is marked


@pytest.mark.parametrize("bad", [
    np.array([0.0, np.nan, 0.1], np.float32),
    np.array([0.0, np.inf]),
    np.zeros((2, 100), np.float32),
    np.array(["a", "b"]),
    np.array([1 + 1j, 0j]),
    [object(), object()],
])
def test_bad_samples_are_refused(bad):
    tracker = StreamingBeatTracker(SR)
    with pytest.raises(InputError):
        tracker.push(bad)


def test_bad_settings_and_use_after_flush_are_refused():
    for kwargs in ({"sr": 44100}, {"history_s": 2.0}, {"fallback_bpm": 0.0}, {"latency_s": 6.0}):
        with pytest.raises(InputError):
            StreamingBeatTracker(**kwargs)
    tracker = StreamingBeatTracker(SR)
    tracker.push(np.zeros(100, np.float32))
    tracker.push([0.0, 0.1])                   # a list of floats is fine
    tracker.flush()
    with pytest.raises(InputError):
        tracker.push(np.zeros(100, np.float32))
    with pytest.raises(InputError):
        tracker.update(until_s=float("nan"))

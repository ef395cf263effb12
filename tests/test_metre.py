"""Metre and downbeats: generated songs with exact bars, accented click tracks, degenerate input, live, the CLI."""

from __future__ import annotations

import json
import shutil

import mir_eval
import numpy as np
import pytest

import signals
from dancesynth.errors import InputError
from dancesynth.bench import groundtruth as gt
from dancesynth.io.audio import load_audio
from dancesynth.live.beats import stream_updates
from dancesynth.music import analyze_music
from dancesynth.music import metre
from test_cli import run

SR = signals.SR
needs_fluidsynth = pytest.mark.skipif(shutil.which("fluidsynth") is None, reason="fluidsynth not installed")

# Both start with a pickup, so counting bars from the first beat is wrong; the 4/4 song
# holds each chord for two bars, so harmony marks only every other downbeat.
SPECS = [gt.SongSpec("waltz", (132,), beats_per_bar=3, drums=False, pickup_beats=2, duration_s=20.0, seed=21),
         gt.SongSpec("four", (104,), pickup_beats=3, bars_per_chord=2, duration_s=20.0, seed=22)]


@pytest.fixture(scope="module")
def songs(tmp_path_factory):
    return {s.name: s for s in gt.ground_truth_set(tmp_path_factory.mktemp("metre"), specs=SPECS)}


def downbeat_f(reference_s, estimated_s) -> float:
    return float(mir_eval.beat.f_measure(np.asarray(reference_s), np.asarray(estimated_s), f_measure_threshold=0.07))


def test_ground_truth_knows_the_bars(tmp_path):
    spec = gt.SongSpec("p", (120,), pickup_beats=3, duration_s=10.0)
    positions = gt.beat_positions(spec)
    assert list(positions[:6]) == [1, 2, 3, 0, 1, 2] and len(positions) == len(gt.beat_times(spec))
    assert (len(positions) - 3) % 4 == 0  # the pickup, then whole bars
    with pytest.raises(InputError, match="pickup_beats"):
        gt.beat_positions(gt.SongSpec("bad", (120,), beats_per_bar=3, pickup_beats=3))
    # The MIDI file's bar lines agree: a short first bar of the pickup's length.
    import mido

    gt.write_midi(spec, tmp_path / "p.mid")
    signatures = [(m.numerator, m.time) for m in mido.MidiFile(tmp_path / "p.mid").tracks[0]
                  if m.type == "time_signature"]
    assert signatures == [(3, 0), (4, 3 * gt.TICKS_PER_BEAT)]


@needs_fluidsynth
@pytest.mark.parametrize("name", ["waltz", "four"])
def test_generated_songs_get_their_metre_and_downbeats(songs, name):
    song = songs[name]
    assert song.beats_per_bar == {"waltz": 3, "four": 4}[name]
    cached = json.loads(song.audio_path.with_suffix(".beats.json").read_text())
    assert cached["beat_in_bar"] == song.beat_in_bar.tolist() and cached["beats_per_bar"] == song.beats_per_bar
    y, sr = load_audio(song.audio_path)
    music = analyze_music(y=y, sr=sr)
    assert music.beats_per_bar == song.beats_per_bar
    assert downbeat_f(song.downbeats_s, music.downbeat_times_s) >= 0.9
    assert music.meta["metre_confidence"] > 0.3
    # The test can tell: counting from the first beat misses the downbeats of these songs.
    from_first = music.beat_times_s[metre.default_positions(music.n_beats, song.beats_per_bar) == 0]
    assert downbeat_f(song.downbeats_s, from_first) < 0.5


@pytest.mark.parametrize("bpm, every", [(100, 3), (120, 4), (150, 3), (150, 4)])
def test_accented_clicks_mark_the_bars(bpm, every):
    y, clicks = signals.click_track(bpm, 16.0, offset_s=0.3, accent_every=every)
    # The recording starts just before the second click: the first bar heard is incomplete.
    cut = int(round((clicks[1] - 0.1) * SR))
    accented = clicks[::every][1:] - cut / SR
    music = analyze_music(y=y[cut:], sr=SR)
    assert music.beats_per_bar == every
    found = music.downbeat_times_s
    assert np.all(np.min(np.abs(found[:, None] - accented[None, :]), axis=1) < 0.03), (found, accented)
    assert found.size >= accented.size - 1
    assert music.meta["metre_confidence"] > 0.5


@pytest.mark.parametrize("bpm", [90, 120])
def test_no_evidence_gives_four_from_the_first_beat_with_no_confidence(bpm):
    # Clicks all alike: a steady pulse, no bars (at 90 bpm the 10 ms feature frames
    # fall the same way every third beat: that is no bar of 3 either).
    y, _ = signals.click_track(bpm, 12.0)
    music = analyze_music(y=y, sr=SR)
    assert not music.default_tempo and music.beats_per_bar == 4
    assert music.meta["metre_confidence"] < 0.1
    # Noise: the fallback grid, counted 4/4 from its first beat.
    noise = analyze_music(y=signals.colored_noise(8.0, exponent=1.0), sr=SR)
    assert noise.default_tempo and noise.beats_per_bar == 4 and noise.meta["metre_confidence"] == 0.0
    np.testing.assert_array_equal(noise.beat_in_bar, np.arange(noise.n_beats) % 4)
    np.testing.assert_array_equal(noise.downbeat_times_s, noise.beat_times_s[::4])


def test_degenerate_input_to_the_pure_functions():
    # Too few beats, nothing measured, a steady grid: 4/4 from the first beat, confidence 0.
    assert metre.estimate_metre(np.random.default_rng(0).normal(size=(7, metre.N_FEATURES)))[0::2] == (4, 0.0)
    bpb, positions, confidence = metre.estimate_metre(np.zeros((40, metre.N_FEATURES)))
    assert (bpb, confidence) == (4, 0.0) and list(positions[:5]) == [0, 1, 2, 3, 0]
    bpb, positions, confidence = metre.estimate_metre(np.full((40, metre.N_FEATURES), np.nan))
    assert (bpb, confidence) == (4, 0.0) and positions.shape == (40,)
    y, _ = signals.click_track(120, 6.0, accent_every=3)
    assert metre.track_metre(y, SR, beat_times_s=np.arange(0.0, 6.0, 0.5), steady_grid=True)[0::2] == (4, 0.0)
    assert metre.track_metre(y, SR, beat_times_s=[0.5, 1.0])[0] == 4
    assert metre.beat_features(y, SR, beat_times_s=[]).shape == (0, metre.N_FEATURES)
    path, score = metre.bar_positions(np.zeros(9), beats_per_bar=3)
    assert list(path) == [0, 1, 2] * 3 and score == 0.0
    # A beat the tracker dropped: the count jumps once and goes on.
    activation = np.where(np.r_[np.arange(40) % 4 == 0, np.arange(41) % 4 == 1], 2.0, -0.5)
    path, _ = metre.bar_positions(activation, beats_per_bar=4)
    assert list(path[:40:4]) == [0] * 10 and list(path[41::4]) == [0] * 10
    assert np.count_nonzero(np.diff(path) % 4 != 1) == 1
    for bad in ({"beat_times_s": [1.0, 0.5]}, {"beat_times_s": [[0.5, 1.0]]}):
        with pytest.raises(InputError, match="increasing"):
            metre.beat_features(y, SR, **bad)
    with pytest.raises(InputError, match="mono"):
        metre.beat_features(np.zeros((2, 100)), SR, beat_times_s=[0.1])
    with pytest.raises(InputError, match="features"):
        metre.estimate_metre()
    with pytest.raises(InputError, match="shape"):
        metre.bar_cues(np.zeros((10, 3)))


@needs_fluidsynth
def test_live_bar_positions_agree_with_offline(songs):
    song = songs["waltz"]
    y, sr = load_audio(song.audio_path)
    updates = stream_updates(y, sr, chunk_s=0.1, update_every_s=2.0)
    live = np.concatenate([u.beat_times_s for u in updates])
    positions = np.concatenate([u.beat_in_bar for u in updates])
    for u in updates:
        assert u.beat_in_bar.shape == u.beat_times_s.shape and u.beat_in_bar.dtype.kind == "i"
        assert np.all((0 <= u.beat_in_bar) & (u.beat_in_bar < u.beats_per_bar))
    assert updates[-1].beats_per_bar == 3 and updates[-1].metre_confidence > 0.3
    music = analyze_music(y=y, sr=sr)
    # After a few bars to settle, the live count is the offline one, and the truth.
    settled = live >= 8.0
    distance = np.abs(live[:, None] - music.beat_times_s[None, :])
    nearest, matched = distance.argmin(axis=1), settled & (distance.min(axis=1) < 0.07)
    assert matched.sum() >= 0.9 * settled.sum()
    assert np.mean(positions[matched] == music.beat_in_bar[nearest[matched]]) >= 0.95
    reference = song.downbeats_s[song.downbeats_s >= 8.0]
    assert downbeat_f(reference, live[settled & (positions == 0)]) >= 0.9


def test_live_runtime_reports_bar_positions_beside_the_beats(tmp_path):
    from dancesynth.live.runtime import LiveConfig, run_live
    from dancesynth.live.sources import AudioSource

    y, clicks = signals.click_track(120, 10.0, offset_s=0.3, accent_every=3)
    path = signals.write(tmp_path / "clicks.wav", y, SR)
    reports = []
    with AudioSource(str(path), realtime=False) as source:
        summary = run_live(source, lambda clip: None, config=LiveConfig(segment_s=2.0),
                           on_report=reports.append, realtime=False)
    assert summary["beats_per_bar"] == 3
    beats = np.concatenate([r.beat_times_s for r in reports])
    positions = np.concatenate([r.beat_in_bar for r in reports])
    assert positions.shape == beats.shape and np.all(np.diff(beats) > 0)
    last = reports[-1]
    assert last.beats_per_bar == 3
    # Once the metre is heard (the second half; the last segment alone may hold no downbeat: the cuts fall a
    # segment apart wherever the reads end) the count is in threes, the downbeats on the accented clicks.
    down = beats[(positions == 0) & (beats >= 5.0)]
    accented = np.arange(0.3, 20.0, 1.5)
    assert down.size and np.all(np.min(np.abs(down[:, None] - accented[None, :]), axis=1) < 0.03)


def test_beats_json_has_the_bars(tmp_path):
    y, clicks = signals.click_track(120, 12.0, offset_s=0.37, accent_every=3)
    song = signals.write(tmp_path / "waltz.wav", y, SR)
    proc = run("beats", song, "--json", tmp_path / "beats.json")
    assert proc.returncode == 0, proc.stderr
    assert "metre 3/4" in proc.stdout and "| " in proc.stdout
    data = json.loads((tmp_path / "beats.json").read_text())
    beats, positions, bars = np.asarray(data["beats"]), np.asarray(data["beat_in_bar"]), np.asarray(data["bar"])
    assert data["beats_per_bar"] == 3 and positions.shape == beats.shape == bars.shape
    downbeats = np.asarray(data["downbeats"])
    np.testing.assert_allclose(downbeats, beats[positions == 0])
    assert downbeats.size >= 7 and np.all(np.min(np.abs(downbeats[:, None] - clicks[None, ::3]), axis=1) < 0.02)
    assert bars[0] == 1 and np.all(np.diff(bars) == (positions[1:] == 0))
    assert 0.0 <= data["metre_confidence"] <= 1.0

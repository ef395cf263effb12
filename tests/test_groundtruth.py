"""Generated ground truth: MIDI songs with exactly known beats, and the default tracker measured on them."""

from __future__ import annotations

import shutil

import mir_eval
import mido
import numpy as np
import pytest

from dancesynth.errors import InputError
from dancesynth.bench import groundtruth as gt
from dancesynth.io.audio import load_audio
from dancesynth.music import track_beats

needs_fluidsynth = pytest.mark.skipif(shutil.which("fluidsynth") is None, reason="fluidsynth not installed")


def midi_beat_times(path) -> np.ndarray:
    """Beat times read back from a MIDI file by mido's own tempo-map arithmetic."""
    mid = mido.MidiFile(path)
    tempo_changes = []  # (tick, microseconds per beat)
    for track in mid.tracks:
        tick = 0
        for msg in track:
            tick += msg.time
            if msg.type == "set_tempo":
                tempo_changes.append((tick, msg.tempo))
    tempo_changes.sort()
    last_tick = max(sum(m.time for m in track) for track in mid.tracks)
    times, seconds, tempo, previous = [], 0.0, 500000, 0
    changes = iter(tempo_changes + [(10 ** 12, None)])
    next_tick, next_tempo = next(changes)
    for beat_tick in range(0, last_tick, mid.ticks_per_beat):
        while next_tick <= beat_tick:
            seconds += mido.tick2second(next_tick - previous, mid.ticks_per_beat, tempo)
            previous, tempo = next_tick, next_tempo
            next_tick, next_tempo = next(changes)
        times.append(seconds + mido.tick2second(beat_tick - previous, mid.ticks_per_beat, tempo))
    return np.asarray(times)


@pytest.mark.parametrize("spec", [gt.SongSpec("c", (120,), duration_s=10),
                                  gt.SongSpec("s", (90, 120), kind="step", beats_per_bar=3, duration_s=12),
                                  gt.SongSpec("r", (80, 130), kind="ramp", swing=True, drums=False, duration_s=12)],
                         ids=["constant", "step", "ramp"])
def test_midi_beats_are_what_a_midi_reader_computes(tmp_path, spec):
    beats = gt.write_midi(spec, tmp_path / "song.mid")
    read_back = midi_beat_times(tmp_path / "song.mid")
    assert len(read_back) >= len(beats) - 1
    np.testing.assert_allclose(read_back[:len(beats)], beats[:len(read_back)], atol=1e-6)
    assert beats[-1] >= spec.duration_s - 60.0 / min(spec.tempo)  # the song lasts as asked


def test_tempo_maps_step_and_ramp():
    step = gt.beat_tempi(gt.SongSpec("s", (90, 120), kind="step", duration_s=30))
    assert set(np.unique(step)) == {90, 120} and np.all(np.diff(step) >= 0)
    ramp = gt.beat_tempi(gt.SongSpec("r", (160, 110), kind="ramp", duration_s=30))
    assert ramp[0] == 160 and ramp[-1] == 110 and np.all(np.diff(ramp) <= 0)
    assert len(np.unique(ramp)) > 10  # a ramp, not a step
    bars = gt.beat_tempi(gt.SongSpec("w", (100,), beats_per_bar=3, duration_s=20))
    assert len(bars) % 3 == 0


@pytest.mark.parametrize("split", gt.SPLIT_NAMES)
def test_the_set_covers_what_the_benchmark_promises(split):
    specs = gt.song_specs(split=split)
    tempi = [t for s in specs for t in s.tempo]
    assert min(tempi) <= 60 and max(tempi) >= 180
    kinds = {(s.kind, s.beats_per_bar, s.drums, s.swing) for s in specs}
    assert {k[0] for k in kinds} == {"constant", "step", "ramp"}
    assert {k[1] for k in kinds} == {3, 4} and {k[2] for k in kinds} == {True, False} and any(k[3] for k in kinds)
    quick = gt.song_specs(quick=True, split=split)
    assert {s.kind for s in quick} == {"constant", "step", "ramp"} and len(quick) < len(specs)


def test_the_reported_songs_are_not_those_the_constants_were_chosen_on():
    """Issue 31 item 7: the bench reports the test split; the engines' constants were chosen on the tune split."""
    tune, test = gt.song_specs(split="tune"), gt.song_specs(split="test")
    assert len(tune) == len(test) == 25
    assert not {s.name for s in tune} & {s.name for s in test} and not {s.seed for s in tune} & {s.seed for s in test}
    assert not {t for s in tune for t in s.tempo} & {t for s in test for t in s.tempo}
    from dancesynth.bench.common import BenchConfig

    assert BenchConfig().groundtruth_split == BenchConfig.full().groundtruth_split == "test"
    with pytest.raises(InputError, match="split"):
        gt.song_specs(split="validation")


@pytest.mark.parametrize("bad", [gt.SongSpec("x", (120, 130)), gt.SongSpec("x", (10,)),
                                 gt.SongSpec("x", (120,), kind="wobble")])
def test_bad_specs_are_refused(bad):
    with pytest.raises(InputError):
        gt.beat_tempi(bad)


@needs_fluidsynth
def test_broken_midi_gets_a_clear_error(tmp_path):
    broken = tmp_path / "broken.mid"
    broken.write_bytes(b"MThd this is not midi")
    with pytest.raises(InputError, match="fluidsynth"):
        gt.render_midi(broken, tmp_path / "out.wav")
    assert not (tmp_path / "out.wav").exists() and not list(tmp_path.glob(".*part"))


@needs_fluidsynth
@pytest.mark.slow
def test_default_tracker_follows_steps_ramps_and_fast_tempi(tmp_path):
    # The cases one global tempo gets wrong: a step, a ramp, 180 bpm (halved by
    # the tempo prior), 60 bpm without drums. Rendered by fluidsynth, so these are
    # real instrument sounds, not clicks.
    specs = [gt.SongSpec("step", (140, 100), kind="step", seed=7),
             gt.SongSpec("ramp", (80, 130), kind="ramp", seed=10),
             gt.SongSpec("fast", (180,), seed=180),
             gt.SongSpec("slow", (60,), drums=False, seed=61)]
    songs = gt.ground_truth_set(tmp_path, specs=specs)
    scores = {}
    for song in songs:
        y, sr = load_audio(song.audio_path)
        beats, _, _ = track_beats(y, sr)
        global_beats, _, _ = track_beats(y, sr, tracker="dp")
        scores[song.name] = (mir_eval.beat.f_measure(mir_eval.beat.trim_beats(song.beats_s),
                                                     mir_eval.beat.trim_beats(beats)),
                             mir_eval.beat.f_measure(mir_eval.beat.trim_beats(song.beats_s),
                                                     mir_eval.beat.trim_beats(global_beats)))
    for name, (ours, one_tempo) in scores.items():
        assert ours >= 0.95, (name, scores)
    assert all(scores[n][1] < 0.9 for n in ("step", "ramp", "fast")), scores  # the test can tell them apart
    # Rendered again from the cache: nothing is re-rendered.
    before = {s.audio_path: s.audio_path.stat().st_mtime_ns for s in songs}
    again = gt.ground_truth_set(tmp_path, specs=specs)
    assert {s.audio_path: s.audio_path.stat().st_mtime_ns for s in again} == before

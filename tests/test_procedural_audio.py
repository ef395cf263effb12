"""The melody of a recording (pYIN + beat tracker + loudness), checked on a MIDI render with known notes."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from dancesynth.errors import InputError
from dancesynth.bench import groundtruth as gt
from dancesynth.music.melody import audio_notes, read_notes
from dancesynth.music.notes import DRUM_CHANNEL

pytestmark = pytest.mark.skipif(shutil.which("fluidsynth") is None, reason="needs fluidsynth to render MIDI")


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    d = tmp_path_factory.mktemp("render")
    rng = np.random.default_rng(7)
    pitches = 67 + np.cumsum(rng.choice([-3, -2, 2, 3, 4, -4], 40)) % 12
    lengths = rng.choice([1.0, 1.0, 0.5, 2.0], 40)
    starts = np.concatenate(([0.0], np.cumsum(lengths)[:-1]))
    melody = [(s, l * 0.9, int(p), 100) for s, l, p in zip(starts, lengths, pitches)]
    drums = [(b, 0.25, 36, 110) for b in range(int(starts[-1] + 2))]
    from dancesynth.music.notes import write_midi_parts

    write_midi_parts(d / "tune.mid", [("Melody", 0, melody), ("Drums", DRUM_CHANNEL, drums)], tempo_bpm=120)
    gt.render_midi(d / "tune.mid", d / "tune.wav")
    return d, starts * 0.5, pitches


def test_recorded_melody_matches_the_score(rendered):
    d, onsets, pitches = rendered
    notes = audio_notes(d / "tune.wav")
    heard = notes.onset_s
    # Most score notes are found within 80 ms with the right pitch.
    k = np.argmin(np.abs(heard[:, None] - onsets[None, :]), axis=0)
    found = (np.abs(heard[k] - onsets) < 0.08) & (notes.pitch[k] == pitches)
    assert found.mean() > 0.8
    assert notes.meta["kind"] == "audio" and abs(notes.tempo_bpm - 120) < 3
    # Beat notes are the ones starting on the kick drum's beats.
    on_beat = np.abs(onsets / 0.5 - np.round(onsets / 0.5)) < 1e-6
    assert np.mean(notes.is_beat[k[found]] == on_beat[found]) > 0.8
    # Durations in sixteenths: a quarter note (0.5 s at 120 bpm) is about 4.
    quarter = found & (np.diff(np.append(onsets, onsets[-1] + 1)) == 0.5)
    assert np.median(notes.duration_16[k[quarter]]) == pytest.approx(4.0, abs=0.5)


def test_a_recording_without_a_tune_is_refused(tmp_path):
    import soundfile as sf

    rng = np.random.default_rng(0)
    sr = 22050
    y = np.zeros(sr * 6, dtype=np.float32)
    for b in range(12):  # clicks only: a beat but no melody
        y[b * sr // 2: b * sr // 2 + 200] = rng.uniform(-0.8, 0.8, 200)
    sf.write(tmp_path / "clicks.wav", y, sr)
    with pytest.raises(InputError, match="no melody"):
        read_notes(tmp_path / "clicks.wav")

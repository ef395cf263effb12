"""Melodies as Loi & Li's note features: MIDI parts, tempo maps, time signatures, beat notes, bad files."""

from __future__ import annotations

import mido
import numpy as np
import pytest
from procedural_songs import HAT, KICK, chorale_midi, drum_beats, phrase_song

from dancesynth.errors import InputError
from dancesynth.bench import groundtruth as gt
from dancesynth.music.notes import DRUM_CHANNEL, midi_notes, read_midi, write_midi_parts


def test_generated_song_with_drums_picks_melody_and_drums(tmp_path):
    spec = gt.SongSpec("t", (120,), duration_s=16.0, seed=3)
    beats = gt.write_midi(spec, tmp_path / "song.mid")
    notes = midi_notes(tmp_path / "song.mid")
    song = read_midi(tmp_path / "song.mid")
    mel, rhy = song.parts[notes.meta["melody_part"]], song.parts[notes.meta["rhythm_part"]]
    assert mel.channel == 3 and rhy.channel == DRUM_CHANNEL   # write_midi's melody channel, GM drums
    # At 120 bpm a sixteenth is 0.125 s: durations are onset gaps in sixteenths.
    assert np.allclose(notes.duration_16[:-1], np.diff(notes.onset_s) / 0.125)
    # Kick or snare sound on every quarter beat; hi-hats on the eighths do not make beat notes.
    on_beat = np.min(np.abs(notes.onset_s[:, None] - beats[None, :]), axis=1) < 1e-6
    assert np.array_equal(notes.is_beat, on_beat)
    assert 0 < notes.is_beat.sum() < notes.n_notes
    assert notes.features.shape == (notes.n_notes, 4)
    assert np.allclose(notes.beat_times_s[:len(beats)], beats)


def test_tempo_map_is_honoured(tmp_path):
    spec = gt.SongSpec("ramp", (80, 130), kind="ramp", duration_s=20.0, seed=1)
    beats = gt.write_midi(spec, tmp_path / "ramp.mid")
    notes = midi_notes(tmp_path / "ramp.mid")
    # Every melody note that starts on a beat lands on the ramp's exact beat time (microsecond tempo map).
    err = np.min(np.abs(notes.onset_s[:, None] - beats[None, :]), axis=1)
    assert np.sum(err < 1e-6) >= 0.5 * notes.n_notes
    assert np.allclose(notes.beat_times_s[:len(beats)], beats, atol=1e-6)
    # Durations are in sixteenths whatever the tempo: a quarter note is 4 at 80 bpm and at 130 bpm.
    assert set(np.round(notes.duration_16[:-1], 6)) <= {2.0, 4.0, 8.0}


def test_time_signatures_set_the_beat_grid(tmp_path):
    three = gt.SongSpec("w", (90,), beats_per_bar=3, duration_s=12.0, drums=False, seed=2)
    beats = gt.write_midi(three, tmp_path / "waltz.mid")
    notes = midi_notes(tmp_path / "waltz.mid")
    assert np.allclose(notes.beat_times_s[:len(beats)], beats)
    # 6/8: the beat is a dotted quarter, two to the bar.
    melody = [(i * 0.5, 0.5, 60 + i % 5, 80) for i in range(24)]
    write_midi_parts(tmp_path / "jig.mid", [("m", 0, melody)], tempo_bpm=120, time_signature=(6, 8))
    jig = midi_notes(tmp_path / "jig.mid")
    assert np.allclose(np.diff(jig.beat_times_s), 0.75)
    # No rhythm part: beat notes are the ones on metric beats (every third eighth).
    assert np.array_equal(jig.is_beat, np.arange(24) % 3 == 0)


def test_chorale_from_music21_with_a_rhythm_track(tmp_path):
    pytest.importorskip("music21")
    path = chorale_midi(tmp_path / "chorale.mid")
    notes = midi_notes(path)
    song = read_midi(path)
    assert song.parts[notes.meta["melody_part"]].name == "Soprano"
    assert song.parts[notes.meta["rhythm_part"]].is_drums
    quarter_s = 60.0 / notes.tempo_bpm
    on_quarter = np.abs(notes.onset_s / quarter_s - np.round(notes.onset_s / quarter_s)) < 1e-3
    assert np.array_equal(notes.is_beat, on_quarter)
    # Without the drum track the bass line gives the rhythm.
    bass = midi_notes(path, rhythm_track=3)
    assert bass.meta["rhythm_part"] == 3 and bass.is_beat.sum() >= 0.8 * notes.is_beat.sum()


def test_overrides_and_their_errors(tmp_path):
    path = phrase_song(tmp_path / "p.mid")
    assert midi_notes(path, melody_track=0).meta["melody_part"] == 0
    with pytest.raises(InputError, match="no part 7"):
        midi_notes(path, melody_track=7)
    with pytest.raises(InputError, match="drum part"):
        midi_notes(path, melody_track=1)
    with pytest.raises(InputError, match="different parts"):
        midi_notes(path, melody_track=0, rhythm_track=0)


def test_long_staccato_and_rests(tmp_path):
    notes = midi_notes(phrase_song(tmp_path / "p.mid"))
    assert np.array_equal(notes.duration_16[:4], [8, 4, 2, 2])
    assert np.array_equal(notes.staccato[:4], [False, True, False, False])
    assert notes.rest_after[1] and not notes.rest_after[0] and notes.rest_after[-1]


def test_type0_file_splits_channels(tmp_path):
    mid = mido.MidiFile(type=0, ticks_per_beat=96)
    tr = mido.MidiTrack()
    mid.tracks.append(tr)
    for i in range(8):
        tr.append(mido.Message("note_on", channel=DRUM_CHANNEL, note=KICK, velocity=90, time=0 if i == 0 else 48))
        tr.append(mido.Message("note_on", channel=0, note=70 + i % 3, velocity=80, time=0))
        tr.append(mido.Message("note_off", channel=0, note=70 + i % 3, velocity=0, time=48))
        tr.append(mido.Message("note_off", channel=DRUM_CHANNEL, note=KICK, velocity=0, time=0))
    mid.save(tmp_path / "t0.mid")
    notes = midi_notes(tmp_path / "t0.mid")
    assert notes.n_notes == 8 and notes.is_beat.all()


def _empty_song(path):
    mid = mido.MidiFile(type=1)
    tr = mido.MidiTrack()
    tr.append(mido.MetaMessage("set_tempo", tempo=500000))
    mid.tracks.append(tr)
    mid.save(path)


@pytest.mark.parametrize("case, message", [
    ("empty", "not a readable MIDI file"),
    ("garbage", "not a readable MIDI file"),
    ("truncated", "not a readable MIDI file"),
    ("no_notes", "has no notes"),
    ("drums_only", "no melody found"),
    ("missing", "no such MIDI file"),
])
def test_bad_midi_files_get_clear_errors(tmp_path, case, message):
    path = tmp_path / f"{case}.mid"
    if case == "empty":
        path.write_bytes(b"")
    elif case == "garbage":
        path.write_bytes(b"MThd this is not a midi file at all" * 3)
    elif case == "truncated":
        phrase_song(tmp_path / "whole.mid")
        path.write_bytes((tmp_path / "whole.mid").read_bytes()[:60])
    elif case == "no_notes":
        _empty_song(path)
    elif case == "drums_only":
        write_midi_parts(path, [("Drums", DRUM_CHANNEL, drum_beats(16) + [(0.0, 1.0, HAT, 50)])])
    with pytest.raises(InputError, match=message) as info:
        midi_notes(path)
    assert "\n" not in str(info.value)


def _hostile_song(path, *, ticks_per_beat=96, gap=48, tempo=500000, signature=None):
    """A 4-note melody whose file states the given tempo, time signature and note gaps."""
    mid = mido.MidiFile(type=0, ticks_per_beat=ticks_per_beat)
    tr = mido.MidiTrack()
    tr.append(mido.MetaMessage("set_tempo", tempo=tempo))
    if signature:
        tr.append(mido.MetaMessage("time_signature", numerator=signature[0], denominator=signature[1]))
    for i in range(4):
        tr.append(mido.Message("note_on", note=70 + i, velocity=80, time=0 if i == 0 else gap))
        tr.append(mido.Message("note_off", note=70 + i, velocity=0, time=gap))
    mid.tracks.append(tr)
    mid.save(path)
    return path


@pytest.mark.parametrize("kind, message", [
    # 1 tick per beat and a 2^27-tick gap: 4 years of music, once a 14 GiB beat grid.
    ("huge delta", "beyond 15 minutes"),
    ("tempo 0", "outside 5-1000 bpm"),
    ("tempo 1 us", "outside 5-1000 bpm"),
    ("denominator 2^24", "not one music uses"),
    ("numerator 0", "not one music uses"),
    ("17 minutes", "over the limit of 15.0 min"),
])
def test_hostile_midi_headers_are_refused_before_anything_is_sized_by_them(tmp_path, kind, message):
    """Issue 13: tiny files that once asked for 14 GiB or danced at 503 million bpm."""
    path = tmp_path / "hostile.mid"
    if kind == "huge delta":
        _hostile_song(path, ticks_per_beat=1, gap=2 ** 27)
    elif kind == "tempo 0":
        _hostile_song(path, tempo=0)
    elif kind == "tempo 1 us":
        _hostile_song(path, tempo=1)
    elif kind == "denominator 2^24":
        _hostile_song(path, signature=(4, 4))
        # mido only writes powers of two it knows; the file stores the exponent, so patch it to 24.
        raw = bytearray(path.read_bytes())
        raw[raw.index(b"\xff\x58\x04") + 4] = 24
        path.write_bytes(bytes(raw))
    elif kind == "numerator 0":
        _hostile_song(path, signature=(0, 4))
    elif kind == "17 minutes":
        _hostile_song(path, ticks_per_beat=96, gap=96 * 300)  # 7 gaps of 300 beats at 120 bpm
    with pytest.raises(InputError, match=message) as info:
        midi_notes(path, max_duration_s=900.0)
    assert "\n" not in str(info.value)

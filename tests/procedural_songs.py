"""MIDI songs with known notes for the procedural dancer's tests (written with mido)."""

from __future__ import annotations

from pathlib import Path

from dancesynth.music.notes import DRUM_CHANNEL, write_midi_parts

KICK, HAT = 36, 42


def drum_beats(n_beats: int, every: float = 1.0, with_hats: bool = True):
    """A kick every ``every`` quarter notes (hi-hats on every eighth when asked)."""
    notes = [(b * every, 0.25, KICK, 100) for b in range(int(n_beats / every))]
    if with_hats:
        notes += [(b * 0.5, 0.2, HAT, 60) for b in range(2 * n_beats)]
    return notes


def chorale_midi(path: Path, name: str = "bach/bwv66.6") -> Path:
    """A Bach chorale from the music21 corpus written to MIDI, plus a drum track on every quarter."""
    import music21
    import mido

    score = music21.corpus.parse(name)
    score.write("midi", fp=str(path))
    mid = mido.MidiFile(str(path))
    quarters = mid.tracks and max(sum(m.time for m in t) for t in mid.tracks) / mid.ticks_per_beat
    tpb = mid.ticks_per_beat
    drums = mido.MidiTrack()
    drums.append(mido.MetaMessage("track_name", name="Drums"))
    for b in range(int(quarters)):
        drums.append(mido.Message("note_on", channel=DRUM_CHANNEL, note=KICK, velocity=100, time=0 if b == 0 else tpb // 2))
        drums.append(mido.Message("note_off", channel=DRUM_CHANNEL, note=KICK, velocity=0, time=tpb - tpb // 2))
    mid.tracks.append(drums)
    mid.save(str(path))
    return path


def phrase_song(path: Path, *, bpm: float = 120.0) -> Path:
    """Eight bars: long notes (half notes), staccato quarters, legato eighths off the beat; drums on quarters."""
    melody, t = [], 0.0
    pitches = [60, 64, 67, 72, 71, 67, 65, 62]
    for bar in range(8):
        p = pitches[bar]
        melody.append((t, 1.9, p, 90))                         # a long note (half note)
        melody.append((t + 2.0, 0.2, p + 2, 100))              # a staccato quarter
        melody.append((t + 3.0, 0.5, p + 4, 70))               # legato eighths
        melody.append((t + 3.5, 0.5, p + 5, 70))
        t += 4.0
    write_midi_parts(path, [("Melody", 0, melody), ("Drums", DRUM_CHANNEL, drum_beats(32, with_hats=False))],
                     tempo_bpm=bpm)
    return path

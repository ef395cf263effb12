"""MIDI notes (``dancesynth.music.notes.midi_notes``, what ``conduct`` reads from a MIDI file).

Mutates: standard MIDI files written byte by byte (so that any field can be
wrong), built by hypothesis: format 0/1/2/junk, declared track counts up to
65535, ticks per beat 0/1/SMPTE/65535, delta times up to 2^28 and over-long
variable-length numbers past 2^63, tempo 0 to 2^24-1, time-signature
denominators 2^0..2^255, running status with junk data bytes, sysex, missing
end-of-track, chunk lengths that lie; and byte mutations of well-formed songs.

Sane: at least 4 melody notes, finite strictly increasing onsets from 0 within
the 15-minute limit, finite positive durations, a tempo the stated limits allow
(5-1000 quarter notes per minute, beat units down to 1/64: 1-16000 bpm).
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from .harness import Case, Insane, Target, hypothesis_examples, mutate_bytes, rng_for

MAX_S = 900.0  # conduct's song limit (15 minutes)


def vlq(value: int) -> bytes:
    """A MIDI variable-length number (any size: over-long ones are what a hostile file has)."""
    out = [value & 0x7F]
    value >>= 7
    while value:
        out.append(0x80 | (value & 0x7F))
        value >>= 7
    return bytes(reversed(out))


def smf(tracks: list[bytes], *, fmt: int = 1, division: int = 480, declared: int | None = None) -> bytes:
    head = b"MThd" + struct.pack(">IHHH", 6, fmt & 0xFFFF, (len(tracks) if declared is None else declared) & 0xFFFF,
                                 division & 0xFFFF)
    return head + b"".join(b"MTrk" + struct.pack(">I", len(t)) + t for t in tracks)


def melody_track(notes, channel=0, tpb=480) -> bytes:
    """(start beats, length beats, pitch, velocity) rows as a track with its end-of-track."""
    events = []
    for start, length, pitch, vel in notes:
        events.append((int(start * tpb), bytes([0x90 | channel, pitch, vel])))
        events.append((int((start + length) * tpb), bytes([0x80 | channel, pitch, 0])))
    events.sort(key=lambda e: e[0])
    out, tick = b"", 0
    for at, msg in events:
        out += vlq(at - tick) + msg
        tick = at
    return out + b"\x00\xff\x2f\x00"


def _seed_songs() -> dict[str, bytes]:
    scale = [60, 62, 64, 65, 67, 69, 71, 72]
    tune = [(i * 0.5, 0.45, scale[i % 8], 90) for i in range(40)]
    bass = [(i * 1.0, 0.9, 36 + (i % 4), 70) for i in range(20)]
    drums = [(i * 1.0, 0.1, 36 if i % 2 == 0 else 38, 100) for i in range(20)]
    tempo = b"\x00\xff\x51\x03" + (500000).to_bytes(3, "big") + b"\x00\xff\x58\x04\x04\x02\x18\x08\x00\xff\x2f\x00"
    return {
        "type1.mid": smf([tempo, melody_track(tune), melody_track(bass, 1), melody_track(drums, 9)]),
        "type0.mid": smf([melody_track(tune)], fmt=0),
        "waltz.mid": smf([b"\x00\xff\x58\x04\x03\x02\x18\x08\x00\xff\x2f\x00", melody_track(tune)]),
    }


class MidiTarget(Target):
    name = "midi"
    suffix = ".mid"
    mutates = "hypothesis-built SMF bytes (headers, deltas, tempi, metres, running status) and byte mutations"
    sane = ">=4 notes, finite increasing onsets, <=15 min, 1-16000 bpm"

    def cases(self, n: int, seed: int, workdir: Path) -> list[Case]:
        songs = _seed_songs()
        names = sorted(songs)
        rng = rng_for(seed, "midi")
        n_built = n // 2
        out = []
        for i in range(n - n_built):
            data, how = mutate_bytes(rng, songs[names[i % len(names)]])
            out.append(Case(f"{names[i % len(names)]}:{how}", data))
        out += [Case("built:" + label, data) for label, data in hypothesis_examples(_midi_files(), n_built, seed)]
        return out

    def run(self, case: Case, workdir: Path) -> None:
        from dancesynth.music.notes import midi_notes

        path = workdir / "case.mid"
        path.write_bytes(case.data)
        notes = midi_notes(path, max_duration_s=MAX_S)
        onset = notes.onset_s
        arrays = [onset, notes.pitch, notes.duration_16, notes.intensity, notes.sounding_s, notes.beat_times_s]
        if notes.n_notes < 4 or not all(np.all(np.isfinite(a)) for a in arrays):
            raise Insane(f"{notes.n_notes} notes or non-finite values")
        if onset[0] < 0 or np.any(np.diff(onset) <= 0) or not 0 < notes.duration_s <= MAX_S + 1:
            raise Insane(f"onsets or duration out of order: {onset[:3]}, {notes.duration_s} s")
        if np.any(notes.sounding_s <= 0) or np.any(notes.duration_16 < 0):
            raise Insane("a note with no length")
        if not 1.0 <= notes.tempo_bpm <= 16000.0:
            raise Insane(f"tempo {notes.tempo_bpm:.4g} bpm")


def _midi_files():
    """A hypothesis strategy of (label, MIDI bytes) with every header and event field open to odd values."""
    from hypothesis import strategies as st

    # Branches of one_of are drawn about equally often: repeating the plain ones keeps most files playable.
    small = st.integers(0, 480)
    huge = st.sampled_from([2 ** 21, 2 ** 28 - 1, 2 ** 40, 2 ** 63 + 5, 2 ** 70])
    delta = st.one_of(small, small, small, small, huge)
    data = st.one_of(st.integers(0, 127), st.integers(0, 127), st.integers(0, 127), st.integers(128, 255))
    note = st.tuples(st.sampled_from([0x80, 0x90, 0x90, 0x90]), st.integers(0, 15), data,
                     data).map(lambda t: bytes([t[0] | t[1], t[2], t[3]]))
    tempo = st.one_of(st.integers(0, 2 ** 24 - 1), st.sampled_from([0, 1, 60000, 500000, 2 ** 24 - 1]))
    meta = st.one_of(
        tempo.map(lambda t: b"\xff\x51\x03" + t.to_bytes(3, "big")),
        st.tuples(st.integers(0, 255), st.integers(0, 255)).map(lambda s: b"\xff\x58\x04" + bytes(s) + b"\x18\x08"),
        st.sampled_from([b"\xff\x51\x00", b"\xff\x51\x02\x07", b"\xff\x58\x02\x04\x02", b"\xff\x58\x00",
                         b"\xff\x03\x05Piano", b"\xff\x03\x04\xff\xfe\x00\x80", b"\xff\x2f\x00",
                         b"\xf0\x05\x7e\x7f\x09\x01\xf7", b"\xff\x7f\x83\xff\xff\x7f", b"\xff\x01" + vlq(10 ** 6)]))
    running = st.binary(min_size=1, max_size=4)  # data bytes without a status byte: running status or junk
    event = st.tuples(delta, st.one_of(note, note, note, note, note, note, meta, meta, running))
    track = st.lists(event, max_size=40).map(lambda evs: b"".join(vlq(d) + m for d, m in evs))

    @st.composite
    def files(draw):
        fmt = draw(st.sampled_from([1, 1, 1, 1, 1, 1, 0, 0, 2, 3, 0xFFFF]))
        division = draw(st.sampled_from([480] * 10 + [96, 96, 0, 1, 0x7FFF, 0xE728, 0xFFFF]))
        tracks = draw(st.lists(track, min_size=0, max_size=4))
        # A well-formed melody in most files, so that the odd events meet a song that otherwise plays.
        if draw(st.sampled_from([True, True, True, True, False])):
            tune = [(i * 0.5, 0.4, 60 + (i * 5) % 12, 80) for i in range(draw(st.integers(0, 30)) + 3)]
            tracks.append(melody_track(tune, tpb=max(1, division if division < 0x8000 else 480)))
        tracks = [t + b"\x00\xff\x2f\x00" if draw(st.sampled_from([True, True, True, False])) else t for t in tracks]
        declared = draw(st.sampled_from([None] * 8 + [0, 1, 100, 65535]))
        data = smf(tracks, fmt=fmt, division=division, declared=declared)
        if draw(st.sampled_from([False] * 9 + [True])):  # a chunk length that lies
            at = data.find(b"MTrk")
            if at >= 0:
                data = data[:at + 4] + struct.pack(">I", draw(st.sampled_from([0, 1, 2 ** 31, 2 ** 32 - 1]))) + \
                    data[at + 8:]
        return f"format {fmt}, division {division}, {len(tracks)} tracks, declared {declared}", data

    return files()


TARGET = MidiTarget()

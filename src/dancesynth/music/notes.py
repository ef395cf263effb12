"""A melody as Loi & Li's note sequence, and reading it from a MIDI file (mido).

Loi & Li (§IV.A) describe each melody note by four features
``[pitch, duration, intensity, isBeat]``: pitch as a MIDI number, duration in
sixteenth notes (0..64), intensity as the note's velocity (0..127) and whether the
rhythm track sounds with it. ``NoteSequence`` keeps those four plus what the
procedural dancer also needs: onset times in seconds (tempo maps honoured), the
sounding length (for staccato), whether a rest follows, and the metric beat grid
(time signatures honoured).

MIDI files are split into *parts*, one per (track, channel) that plays notes. The
melody part is chosen as the highest mostly-monophonic non-drum part; the rhythm
part is the drum channel (GM channel 10) if there is one, else the lowest other
part (a bass line). Both can be overridden by part index (``midi_parts`` lists
them). Without a rhythm part a melody note is a beat note when it starts on a
metric beat.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError

DRUM_CHANNEL = 9                # GM percussion is MIDI channel 10 (9 counting from 0)
# Hi-hats, rides and crashes keep time on every subdivision; the drums that accent are the rest.
TIMEKEEPING_DRUMS = (42, 44, 46, 49, 51, 52, 53, 55, 57, 59)
MAX_DURATION_16 = 64.0          # the paper's duration range
REST_MIN_16 = 2.0               # a silence of an eighth or more after a note is a rest
STACCATO_FRACTION = 0.5         # sounding for at most half its time, and a quarter note or shorter
MIN_MELODY_NOTES = 4
# What a MIDI file may state, checked as it is read, before anything is sized by it: a 79-byte
# file with a huge delta time or a time signature of x/2^24 must not make a grid of billions of beats.
TEMPO_RANGE_BPM = (5.0, 1000.0)   # quarter notes per minute of a tempo event
MAX_DENOMINATOR = 64              # time signature denominators: 1, 2, 4, ... 64
LONGEST_S = 24 * 3600.0           # no MIDI song is read past a day, whatever limit the caller sets


@dataclass(eq=False)
class NoteSequence:
    """A monophonic melody with the paper's four features per note, plus timing.

    ``duration_16`` is the time from a note's onset to the next onset (the last
    note: to its end) in sixteenth notes, capped at 64; ``sounding_s`` how long it
    actually sounds. ``beat_times_s`` is the metric beat grid of the song.
    """

    onset_s: np.ndarray
    pitch: np.ndarray
    duration_16: np.ndarray
    intensity: np.ndarray
    is_beat: np.ndarray
    sounding_s: np.ndarray
    rest_after: np.ndarray
    beat_times_s: np.ndarray
    duration_s: float
    tempo_bpm: float
    source: str = ""
    meta: dict = field(default_factory=dict)

    def __post_init__(self):
        self.onset_s = np.asarray(self.onset_s, dtype=np.float64)
        n = len(self.onset_s)
        for name in ("pitch", "duration_16", "intensity", "sounding_s"):
            setattr(self, name, np.asarray(getattr(self, name), dtype=np.float64))
        for name in ("is_beat", "rest_after"):
            setattr(self, name, np.asarray(getattr(self, name), dtype=bool))
        self.beat_times_s = np.asarray(self.beat_times_s, dtype=np.float64)
        if any(getattr(self, k).shape != (n,) for k in ("pitch", "duration_16", "intensity", "is_beat",
                                                        "sounding_s", "rest_after")):
            raise InputError("every per-note array of a NoteSequence needs one value per note")
        if n and np.any(np.diff(self.onset_s) <= 0):
            raise InputError("note onsets must be strictly increasing (a melody is monophonic)")

    @property
    def n_notes(self) -> int:
        return len(self.onset_s)

    @property
    def features(self) -> np.ndarray:
        """(n, 4) ``[pitch, duration (sixteenths), intensity, isBeat]`` as in the paper."""
        return np.stack([self.pitch, self.duration_16, self.intensity, self.is_beat.astype(float)], axis=1)

    @property
    def offset_s(self) -> np.ndarray:
        """Onset of the next note (the last note: its end): when each note's time is over."""
        return np.append(self.onset_s[1:], max(self.duration_s, self.onset_s[-1] + self.sounding_s[-1])) \
            if self.n_notes else np.zeros(0)

    @property
    def staccato(self) -> np.ndarray:
        """Notes sounding for at most half their time, a quarter note or shorter."""
        ioi = self.offset_s - self.onset_s
        return (self.sounding_s <= STACCATO_FRACTION * ioi) & (self.duration_16 <= 4.0)


def note_sequence(onset_s, pitch, sounding_s, intensity, *, sixteenth_s, beat_times_s, duration_s, tempo_bpm,
                  is_beat, source: str = "", meta: dict | None = None) -> NoteSequence:
    """Build a ``NoteSequence`` from onsets; durations, rests follow from the timing.

    ``sixteenth_s`` is the length of a sixteenth note at each onset (tempo maps) or a scalar.
    """
    onset_s = np.asarray(onset_s, dtype=np.float64)
    sounding_s = np.asarray(sounding_s, dtype=np.float64)
    end = onset_s[-1] + sounding_s[-1]
    nxt = np.append(onset_s[1:], end)
    sixteenth_s = np.broadcast_to(np.asarray(sixteenth_s, dtype=np.float64), onset_s.shape)
    duration_16 = np.minimum((nxt - onset_s) / sixteenth_s, MAX_DURATION_16)
    gap_16 = (nxt - onset_s - sounding_s) / sixteenth_s
    rest_after = gap_16 >= REST_MIN_16 - 1e-6
    rest_after[-1] = True  # the song ends: the melody rests after its last note
    return NoteSequence(onset_s, pitch, duration_16, intensity, is_beat, np.minimum(sounding_s, nxt - onset_s),
                        rest_after, beat_times_s, float(duration_s), float(tempo_bpm), source, meta or {})


# --- MIDI ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class MidiPart:
    """The notes one (track, channel) plays, in ticks; ``index`` is what ``--melody-track`` takes."""

    index: int
    track: int
    channel: int
    name: str
    on: np.ndarray        # onset ticks
    off: np.ndarray       # release ticks
    pitch: np.ndarray
    velocity: np.ndarray

    @property
    def is_drums(self) -> bool:
        return self.channel == DRUM_CHANNEL

    def rhythm_onsets(self) -> np.ndarray:
        """Onset ticks that mark the rhythm: a drum part's accenting drums (not its hi-hats), if any."""
        if self.is_drums:
            accents = ~np.isin(self.pitch, TIMEKEEPING_DRUMS)
            if np.any(accents):
                return np.unique(self.on[accents])
        return np.unique(self.on)

    @property
    def mean_pitch(self) -> float:
        return float(np.mean(self.pitch))

    @property
    def polyphony(self) -> float:
        """Fraction of onsets shared with another note of the part (chords)."""
        _, counts = np.unique(self.on, return_counts=True)
        return float(np.sum(counts[counts > 1]) / len(self.on))

    def describe(self) -> str:
        kind = "drums" if self.is_drums else f"pitch {int(self.pitch.min())}-{int(self.pitch.max())}"
        name = f" '{self.name}'" if self.name else ""
        return f"part {self.index}: track {self.track}{name}, channel {self.channel + 1}, {len(self.on)} notes, {kind}"


@dataclass(frozen=True)
class MidiSong:
    """A parsed MIDI file: its parts, tempo map and time signatures, all in ticks."""

    parts: tuple[MidiPart, ...]
    ticks_per_beat: int
    tempo_ticks: np.ndarray      # ticks where a tempo starts (first is 0)
    tempo_us: np.ndarray         # microseconds per quarter note from there
    timesig_ticks: np.ndarray
    timesig: tuple[tuple[int, int], ...]
    end_tick: int
    source: str

    def seconds(self, ticks) -> np.ndarray:
        """Ticks to seconds through the tempo map."""
        ticks = np.asarray(ticks, dtype=np.float64)
        sec_per_tick = self.tempo_us / 1e6 / self.ticks_per_beat
        start_s = np.concatenate(([0.0], np.cumsum(np.diff(self.tempo_ticks) * sec_per_tick[:-1])))
        k = np.clip(np.searchsorted(self.tempo_ticks, ticks, side="right") - 1, 0, None)
        return start_s[k] + (ticks - self.tempo_ticks[k]) * sec_per_tick[k]

    def beat_ticks(self) -> np.ndarray:
        """The metric beats: the time signature's beat unit (a dotted quarter in 6/8, 9/8, 12/8)."""
        out = []
        bounds = list(self.timesig_ticks) + [self.end_tick]
        for (num, den), a, b in zip(self.timesig, bounds[:-1], bounds[1:]):
            unit = self.ticks_per_beat * 4.0 / den
            if den == 8 and num % 3 == 0 and num > 3:
                unit *= 3
            out.append(np.arange(a, max(b, a + 1), unit))
        return np.unique(np.concatenate(out))


def read_midi(path, max_duration_s: float | None = None) -> MidiSong:
    """Parse a MIDI file into parts; ``InputError`` when it cannot be read, has no notes, states a
    tempo or time signature outside ``TEMPO_RANGE_BPM`` / ``MAX_DENOMINATOR``, or lasts longer than
    ``max_duration_s`` (and ``LONGEST_S`` in any case), all checked before anything is sized by them."""
    import mido

    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path}: no such MIDI file; check the path")
    try:
        mid = mido.MidiFile(str(path), clip=True)
    except Exception as exc:  # mido raises OSError, EOFError, KeyError, ValueError on broken files
        raise InputError(f"{path}: not a readable MIDI file ({type(exc).__name__}: {exc}); "
                         "export it again as a standard MIDI file (.mid)") from None
    if mid.type == 2:
        raise InputError(f"{path}: MIDI type 2 (independent sequences) is not supported; save it as type 0 or 1")
    tpb = int(mid.ticks_per_beat)
    if tpb <= 0:
        raise InputError(f"{path}: the file uses SMPTE timing, not ticks per beat; save it with musical timing")
    limit = LONGEST_S if max_duration_s is None else min(float(max_duration_s), LONGEST_S)
    # Ticks past what the slowest allowed tempo plays within the limit are a corrupt or hostile file.
    max_tick = limit * TEMPO_RANGE_BPM[1] / 60.0 * tpb
    tempos, sigs, parts, end_tick = {0: 500000}, {0: (4, 4)}, [], 0
    for t, track in enumerate(mid.tracks):
        tick, name, pending, notes = 0, "", {}, {}
        for msg in track:
            tick += msg.time
            if tick > max_tick:
                raise InputError(f"{path}: an event at tick {tick} lies beyond {limit / 60:.0f} minutes at any "
                                 f"tempo the file may state: the file is corrupt or too long")
            if msg.type == "set_tempo":
                bpm = 60e6 / msg.tempo if msg.tempo > 0 else float("inf")
                if not TEMPO_RANGE_BPM[0] <= bpm <= TEMPO_RANGE_BPM[1]:
                    raise InputError(f"{path}: a tempo of {bpm:.4g} bpm at tick {tick} is outside "
                                     f"{TEMPO_RANGE_BPM[0]:g}-{TEMPO_RANGE_BPM[1]:g} bpm; fix the tempo map")
                tempos[tick] = msg.tempo
            elif msg.type == "time_signature":
                num, den = msg.numerator, msg.denominator
                if num < 1 or not 1 <= den <= MAX_DENOMINATOR or den & (den - 1):
                    raise InputError(f"{path}: the time signature {num}/{den} at tick {tick} is not one music "
                                     f"uses (a denominator of 1, 2, 4, ... {MAX_DENOMINATOR}); fix it")
                sigs[tick] = (num, den)
            elif msg.type == "track_name":
                name = msg.name.strip()
            elif msg.type == "note_on" and msg.velocity > 0:
                pending.setdefault((msg.channel, msg.note), []).append((tick, msg.velocity))
            elif msg.type in ("note_off", "note_on"):
                starts = pending.get((msg.channel, msg.note))
                if starts:
                    on, vel = starts.pop(0)
                    notes.setdefault(msg.channel, []).append((on, max(tick, on + 1), msg.note, vel))
        end_tick = max(end_tick, tick)
        for (ch, p), starts in pending.items():  # never released: they last to the end of the track
            for on, vel in starts:
                notes.setdefault(ch, []).append((on, max(tick, on + 1), p, vel))
        for ch in sorted(notes):
            a = np.array(sorted(notes[ch]), dtype=np.int64)
            parts.append(MidiPart(len(parts), t, ch, name, a[:, 0], a[:, 1], a[:, 2], a[:, 3]))
    if not parts:
        raise InputError(f"{path}: the MIDI file has no notes; give a file with a melody track")
    tt = np.array(sorted(tempos), dtype=np.int64)
    st = np.array(sorted(sigs), dtype=np.int64)
    song = MidiSong(tuple(parts), tpb, tt, np.array([tempos[k] for k in tt], dtype=np.float64), st,
                    tuple(sigs[k] for k in st), int(max(end_tick, max(int(p.off.max()) for p in parts))), str(path))
    duration_s = float(song.seconds(song.end_tick))
    if duration_s > limit:
        raise InputError(f"{path}: the song is {duration_s / 60:.1f} min long, over the limit of "
                         f"{limit / 60:.1f} min; cut it or raise the limit")
    return song


def choose_parts(song: MidiSong, melody: int | None = None, rhythm: int | None = None) -> tuple[MidiPart, MidiPart | None]:
    """The melody part and the rhythm part (``None`` when there is none), automatic unless given."""
    n = len(song.parts)
    listing = "; ".join(p.describe() for p in song.parts)
    for what, idx in (("melody", melody), ("rhythm", rhythm)):
        if idx is not None and not 0 <= idx < n:
            raise InputError(f"{song.source}: there is no part {idx} for the {what} (parts are 0..{n - 1}: {listing})")
    if melody is not None:
        mel = song.parts[melody]
        if mel.is_drums:
            raise InputError(f"{song.source}: part {melody} is a drum part and has no melody; parts: {listing}")
    else:
        tonal = [p for p in song.parts if not p.is_drums and len(p.on) >= MIN_MELODY_NOTES]
        if not tonal:
            raise InputError(f"{song.source}: no melody found, only drums or too few notes ({listing}); "
                             "give a MIDI file with a melody track")
        # The highest line that is mostly single notes: chords and accompaniment score lower.
        mel = max(tonal, key=lambda p: (p.mean_pitch - 24.0 * p.polyphony, len(p.on)))
    if rhythm is not None:
        rhy = song.parts[rhythm]
    else:
        others = [p for p in song.parts if p.index != mel.index]
        drums = [p for p in others if p.is_drums]
        bass = [p for p in others if not p.is_drums and len(p.on) >= MIN_MELODY_NOTES
                and p.mean_pitch < mel.mean_pitch]
        rhy = max(drums, key=lambda p: len(p.on)) if drums else (min(bass, key=lambda p: p.mean_pitch) if bass else None)
    if rhy is not None and rhy.index == mel.index:
        raise InputError(f"{song.source}: the melody and the rhythm must be different parts ({listing})")
    return mel, rhy


def _skyline(part: MidiPart) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The top voice: at every onset the highest note (on, off, pitch, velocity), overlaps cut."""
    order = np.lexsort((-part.pitch, part.on))
    on, off, pitch, vel = part.on[order], part.off[order], part.pitch[order], part.velocity[order]
    first = np.concatenate(([True], on[1:] != on[:-1]))
    on, off, pitch, vel = on[first], off[first], pitch[first], vel[first]
    return on, off, pitch, vel


def midi_notes(path, *, melody_track: int | None = None, rhythm_track: int | None = None,
               max_duration_s: float | None = None) -> NoteSequence:
    """The melody of a MIDI file as a ``NoteSequence`` (see the module docstring for the choices)."""
    song = read_midi(path, max_duration_s)
    mel, rhy = choose_parts(song, melody_track, rhythm_track)
    on, off, pitch, vel = _skyline(mel)
    if len(on) < MIN_MELODY_NOTES:
        raise InputError(f"{song.source}: the melody ({mel.describe()}) has only {len(on)} notes; "
                         f"at least {MIN_MELODY_NOTES} are needed")
    beats = song.beat_ticks()
    tol = song.ticks_per_beat / 8.0  # a 32nd note
    ref = rhy.rhythm_onsets() if rhy is not None else beats
    k = np.clip(np.searchsorted(ref, on), 1, len(ref) - 1) if len(ref) > 1 else np.zeros(len(on), int)
    near = np.minimum(np.abs(ref[k] - on), np.abs(ref[np.maximum(k - 1, 0)] - on))
    is_beat = near <= tol
    onset_s, off_s = song.seconds(on), song.seconds(off)
    # A sixteenth's length averaged over each note's time, so durations count ticks exactly across tempo changes.
    nxt = np.append(on[1:], off[-1])
    sixteenth_s = (song.seconds(nxt) - onset_s) / ((nxt - on) / (song.ticks_per_beat / 4.0))
    duration_s = float(song.seconds(song.end_tick))  # within the limit: read_midi checked it
    beat_s = song.seconds(beats)
    tempo = 60.0 / float(np.median(np.diff(beat_s))) if len(beat_s) > 1 else 60e6 / song.tempo_us[0]
    meta = {"melody_part": mel.index, "rhythm_part": None if rhy is None else rhy.index,
            "parts": [p.describe() for p in song.parts], "kind": "midi"}
    return note_sequence(onset_s, pitch, off_s - onset_s, vel, sixteenth_s=sixteenth_s, beat_times_s=beat_s,
                         duration_s=duration_s, tempo_bpm=tempo, is_beat=is_beat, source=song.source, meta=meta)


def write_midi_parts(path, parts, *, tempo_bpm=120.0, time_signature=(4, 4), ticks_per_beat: int = 480) -> None:
    """Write notes as a type-1 MIDI file (atomically), one track per part.

    ``parts``: a list of ``(name, channel, notes)`` with ``notes`` rows of
    ``(start, length, pitch, velocity)`` in quarter notes (channel 9 is GM drums).
    ``tempo_bpm`` is a number or a list of ``(start in quarter notes, bpm)`` changes.
    """
    import mido

    from ..io.files import atomic_output

    changes = [(0.0, float(tempo_bpm))] if np.isscalar(tempo_bpm) else [(float(a), float(b)) for a, b in tempo_bpm]
    mid = mido.MidiFile(type=1, ticks_per_beat=ticks_per_beat)
    conductor = mido.MidiTrack()
    events = [(0, mido.MetaMessage("time_signature", numerator=time_signature[0], denominator=time_signature[1]))]
    events += [(int(round(a * ticks_per_beat)), mido.MetaMessage("set_tempo", tempo=mido.bpm2tempo(bpm)))
               for a, bpm in changes]
    mid.tracks.append(conductor)
    tracks = [(conductor, events)]
    for name, channel, notes in parts:
        track = mido.MidiTrack()
        evs = [(0, mido.MetaMessage("track_name", name=name))]
        for start, length, pitch, velocity in notes:
            on = int(round(start * ticks_per_beat))
            off = max(on + 1, int(round((start + length) * ticks_per_beat)))
            evs.append((on, mido.Message("note_on", channel=channel, note=int(pitch), velocity=int(velocity))))
            evs.append((off, mido.Message("note_off", channel=channel, note=int(pitch), velocity=0)))
        mid.tracks.append(track)
        tracks.append((track, evs))
    for track, evs in tracks:
        tick = 0
        # Releases before onsets at the same tick, so that repeated notes retrigger.
        for at, msg in sorted(evs, key=lambda e: (e[0], e[1].type == "note_on")):
            track.append(msg.copy(time=at - tick))
            tick = at
    with atomic_output(Path(path), "wb") as fh:
        mid.save(file=fh)

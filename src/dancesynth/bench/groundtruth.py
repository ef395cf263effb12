"""Songs with exactly known beats: MIDI written here, rendered to audio by fluidsynth.

Beat trackers are measured against ground truth that nobody annotated by ear: each
song is generated as MIDI (``mido``) from a ``SongSpec`` -- a tempo map (constant,
a step, or a ramp), a meter (3/4 or 4/4), an optional pickup (the last beats of a
bar before the first full bar, as many songs begin), straight or swung eighths,
with or without a drum kit -- so its beat times and bar positions follow from the
spec alone. The MIDI is rendered with ``fluidsynth`` and a General MIDI soundfont
(Debian packages ``fluidsynth`` and ``timgm6mb-soundfont`` or ``fluid-soundfont-gm``).

Tempo changes happen only on beats (a ramp changes tempo at every beat), and each
beat's length is computed from the integer microseconds-per-beat stored in the MIDI
file, so the beat times are exact to the microsecond; ``write_midi`` returns them.

The music: bass on the beats, piano chords (a waltz "oom-pah-pah" in 3/4) that
follow I-V-vi-IV with a new chord on the bar line every ``bars_per_chord`` bars, a
seeded melody of quarter, eighth and half notes on a pentatonic scale, and, with
drums, kick and snare on the beats and hi-hat eighths. Velocities accent the
downbeat a little, as players do; nothing else marks the beat or the bar.

A song with a ``form`` (``structure_specs``) is made of sections, each a label and a
length in bars: every label has its own progression, melody, lead instrument, drum
part and loudness, and a section heard again replays its melody and chords with one
instrument more (the lead doubled an octave up), as arrangements do. Its truth adds
the sections' times and labels.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.files import atomic_output, atomic_path

TICKS_PER_BEAT = 480
RENDER_SR = 22050
# Where Debian's GM soundfont packages put their files, smallest first.
SOUNDFONTS = (
    "/usr/share/sounds/sf2/TimGM6mb.sf2",
    "/usr/share/sounds/sf2/default-GM.sf2",
    "/usr/share/sounds/sf2/FluidR3_GM.sf2",
)
# Bump when the music written for a spec changes, so cached renders are redone.
GENERATOR_VERSION = 2  # 2: pickups, chords held for bars_per_chord bars, bar positions

_KICK, _SNARE, _HAT = 36, 38, 42
_BASS_PROGRAM, _PIANO_PROGRAM = 33, 0
_MELODY_PROGRAMS = (73, 56, 65, 11)     # flute, trumpet, alto sax, vibraphone
_PENTATONIC = (0, 2, 4, 7, 9)
_PROGRESSION = (0, 7, 9, 5)             # I - V - vi - IV, as semitones above the key
_MINOR_DEGREE = {9}
_DOUBLE_PROGRAM = 40                    # violin: the instrument a repeated section adds
# A form's sections by label: progression, drum part, loudness (a chorus loud with full drums, a verse lighter,
# a bridge without drums, an intro or outro quiet); another label takes one of these by its first appearance.
_SECTION_SOUND = {"V": ((0, 7, 9, 5), "light", -8), "C": ((5, 0, 7, 9), "full", 8),
                  "B": ((9, 5, 7, 7), "", -16), "I": ((2, 7, 0, 0), "light", -18), "O": ((2, 7, 0, 0), "light", -18)}


@dataclass(frozen=True)
class _Texture:
    """How one bar is played: its section's progression (from ``first_bar``), drums ("full", "light":
    kick and hats, "": none), a velocity shift, its lead, whether the lead is doubled, and whether
    the bar starts its section (the melody restarts from ``seed``)."""

    progression: tuple[int, ...] = _PROGRESSION
    first_bar: int = 0
    drums: str = "full"
    loud: int = 0
    program: int = 0
    double: bool = False
    starts: bool = False
    seed: int = 0


_PLAIN = _Texture()


def _textures(spec: "SongSpec") -> list[_Texture]:
    """Per bar of a song with a ``form``: how its section plays it (empty without a form)."""
    order: list[str] = []
    seen: dict[str, int] = {}
    out = []
    for label, first_bar, bars in spec.sections:
        if label not in order:
            order.append(label)
        i = order.index(label)
        progression, drums, loud = _SECTION_SOUND.get(label, list(_SECTION_SOUND.values())[i % len(_SECTION_SOUND)])
        base = _Texture(progression, first_bar, drums, loud, _MELODY_PROGRAMS[(spec.seed + i) % len(_MELODY_PROGRAMS)],
                        seen.get(label, 0) > 0, seed=spec.seed * 100 + i)
        seen[label] = seen.get(label, 0) + 1
        out += [replace(base, starts=(k == 0)) for k in range(bars)]
    return out


@dataclass(frozen=True)
class SongSpec:
    """One generated song.

    ``tempo``: ``(bpm,)`` constant, ``(bpm_a, bpm_b)`` with ``kind="step"`` (the
    tempo jumps at the middle bar) or ``kind="ramp"`` (the tempo moves linearly from
    a to b between 25% and 75% of the song, beat by beat). ``pickup_beats``: the
    song starts with the last that many beats of a bar (an anacrusis), so its first
    downbeat is beat ``pickup_beats``. ``bars_per_chord``: how long each chord of
    the progression lasts.
    """

    name: str
    tempo: tuple[float, ...]
    kind: str = "constant"          # constant | step | ramp
    beats_per_bar: int = 4
    drums: bool = True
    swing: bool = False
    duration_s: float = 30.0
    seed: int = 0
    pickup_beats: int = 0
    bars_per_chord: int = 1
    form: tuple[tuple[str, int], ...] = ()   # sections (label, bars), in order; () = one texture throughout

    @property
    def sections(self) -> list[tuple[str, int, int]]:
        """``(label, first bar, bars)`` of each section of ``form`` (bars counted after the pickup)."""
        out, bar = [], 0
        for label, bars in self.form:
            out.append((label, bar, bars))
            bar += bars
        return out

    @property
    def tags(self) -> dict:
        return {"tempo": self.kind, "meter": f"{self.beats_per_bar}/4", "drums": self.drums, "swing": self.swing,
                "pickup": self.pickup_beats}


@dataclass(frozen=True)
class GroundTruthSong:
    """A rendered song and its truth: beat times, and each beat's position in its bar (0 = downbeat)."""

    name: str
    audio_path: Path
    midi_path: Path
    beats_s: np.ndarray
    duration_s: float
    tags: dict = field(default_factory=dict)
    beat_in_bar: np.ndarray | None = None
    beats_per_bar: int | None = None
    sections: tuple[tuple[float, float, str], ...] = ()   # (start s, end s, label) of a song with a form

    @property
    def downbeats_s(self) -> np.ndarray | None:
        return None if self.beat_in_bar is None else self.beats_s[self.beat_in_bar == 0]


#: The two sets of generated songs: the same kinds of song at other tempi and seeds. ``tune`` is where the
#: engines' constants (accent timing and costs, beat tracker) were chosen; ``test`` is what the bench reports,
#: and no choice looked at it. Per kind: tempi (one tuple of tempi per song), and the first seed.
SPLITS = {
    "tune": {"const_drums": ((60,), (80,), (100,), (120,), (140,), (160,), (180,)),
             "const_nodrums": ((70,), (110,), (150,)), "waltz_drums": ((90,), (135,)),
             "waltz_nodrums": ((100,), (160,)), "swing_drums": ((95,), (125,), (155,)), "swing_nodrums": ((115,),), "step": ((90, 120), (140, 100), (75, 110), (120, 150)),
             "ramp": ((80, 130), (160, 110), (100, 140)), "seed": 0},
    "test": {"const_drums": ((58,), (84,), (106,), (128,), (146,), (166,), (182,)),
             "const_nodrums": ((74,), (114,), (154,)), "waltz_drums": ((94,), (138,)),
             "waltz_nodrums": ((104,), (164,)), "swing_drums": ((98,), (128,), (158,)), "swing_nodrums": ((118,),),
             "step": ((86, 116), (144, 104), (78, 112), (124, 154)), "ramp": ((84, 134), (164, 114), (102, 142)),
             "seed": 1000},
}
SPLIT_NAMES = tuple(SPLITS)
QUICK = (0, 3, 6, 8, 11, 15, 18, 22)   # 8 songs covering every kind (the same places in either split)


def song_specs(*, quick: bool = False, split: str = "test") -> list[SongSpec]:
    """A split of the benchmark's song set (``SPLITS``): 60-180 bpm, steps, ramps, swing, 3/4 and 4/4,
    pickups, with and without drums; 25 songs. ``quick`` keeps 8 covering every kind."""
    if split not in SPLITS:
        raise InputError(f"generated-song split {split!r}: use one of {', '.join(SPLITS)}")
    t, seed = SPLITS[split], SPLITS[split]["seed"]

    def name(kind, tempi, metre, drums):
        return f"{kind}{'-'.join(map(str, tempi))}_{metre}-4_{'drums' if drums else 'nodrums'}"

    specs = [SongSpec(name("const", b, 4, True), b, seed=seed + b[0]) for b in t["const_drums"]]
    specs += [SongSpec(name("const", b, 4, False), b, drums=False, seed=seed + b[0] + 1) for b in t["const_nodrums"]]
    specs += [SongSpec(name("const", b, 3, True), b, beats_per_bar=3, seed=seed + b[0] + 2) for b in t["waltz_drums"]]
    specs += [SongSpec(name("const", b, 3, False), b, beats_per_bar=3, drums=False, seed=seed + b[0] + 3)
              for b in t["waltz_nodrums"]]
    specs += [SongSpec(name("swing", b, 4, True), b, swing=True, seed=seed + b[0] + 4) for b in t["swing_drums"]]
    specs += [SongSpec(name("swing", b, 4, False), b, swing=True, drums=False, seed=seed + 5)
              for b in t["swing_nodrums"]]
    steps = t["step"]
    specs += [SongSpec(name("step", steps[0], 4, True), steps[0], kind="step", seed=seed + 6),
              SongSpec(name("step", steps[1], 4, True), steps[1], kind="step", seed=seed + 7),
              SongSpec(name("step", steps[2], 4, False), steps[2], kind="step", drums=False, seed=seed + 8),
              SongSpec(name("step", steps[3], 3, True), steps[3], kind="step", beats_per_bar=3, seed=seed + 9)]
    ramps = t["ramp"]
    specs += [SongSpec(name("ramp", ramps[0], 4, True), ramps[0], kind="ramp", seed=seed + 10),
              SongSpec(name("ramp", ramps[1], 4, True), ramps[1], kind="ramp", seed=seed + 11),
              SongSpec(name("ramp", ramps[2], 4, False), ramps[2], kind="ramp", drums=False, seed=seed + 12)]
    # Songs start on any beat of the bar (only 8 of the 25 on a downbeat, so counting
    # bars from the first beat is wrong for most), and every third holds its chords two bars.
    specs = [replace(s, pickup_beats=i % s.beats_per_bar, bars_per_chord=2 if i % 3 == 2 else 1)
             for i, s in enumerate(specs)]
    return [specs[i] for i in QUICK] if quick else specs


def beat_tempi(spec: SongSpec) -> np.ndarray:
    """Tempo (bpm) of every beat of the song: the pickup, then whole bars covering ``spec.duration_s``."""
    if not (isinstance(spec.beats_per_bar, int) and 1 <= spec.beats_per_bar <= 16):
        raise InputError(f"{spec.name}: beats_per_bar must be a whole number from 1 to 16, got {spec.beats_per_bar!r}")
    if not (isinstance(spec.pickup_beats, int) and 0 <= spec.pickup_beats < spec.beats_per_bar):
        raise InputError(f"{spec.name}: pickup_beats must be a whole number from 0 to beats_per_bar - 1 "
                         f"({spec.beats_per_bar - 1}), got {spec.pickup_beats!r}")
    if not (isinstance(spec.bars_per_chord, int) and spec.bars_per_chord >= 1):
        raise InputError(f"{spec.name}: bars_per_chord must be a positive whole number, got {spec.bars_per_chord!r}")
    if spec.kind not in ("constant", "step", "ramp"):
        raise InputError(f"unknown tempo kind {spec.kind!r}; use constant, step or ramp")
    if spec.kind == "constant" and len(spec.tempo) != 1 or spec.kind != "constant" and len(spec.tempo) != 2:
        raise InputError(f"{spec.name}: a {spec.kind} tempo needs {1 if spec.kind == 'constant' else 2} values")
    if not all(20 <= b <= 400 for b in spec.tempo):
        raise InputError(f"{spec.name}: tempi must be between 20 and 400 bpm, got {spec.tempo}")
    a = spec.tempo[0]
    b = spec.tempo[-1]
    pickup = spec.pickup_beats
    if spec.form:
        if spec.kind != "constant" or any(not (isinstance(n, int) and n >= 1) for _, n in spec.form):
            raise InputError(f"{spec.name}: a form needs a constant tempo and sections of whole bars")
        return np.full(pickup + sum(n for _, n in spec.form) * spec.beats_per_bar, float(a))
    # Enough beats at the faster tempo, trimmed to whole bars below.
    n = int(np.ceil(spec.duration_s * max(a, b) / 60.0)) + spec.beats_per_bar + pickup
    if spec.kind == "constant":
        tempi = np.full(n, a)
    else:
        n_mean = int(np.ceil(spec.duration_s * (a + b) / 120.0)) + 2 * spec.beats_per_bar
        n = max(n, n_mean)
        idx = np.arange(n)
        if spec.kind == "step":
            half = pickup + _beats_until(a, spec.duration_s / 2, spec.beats_per_bar)
            tempi = np.where(idx < half, a, b).astype(float)
        else:
            start = pickup + _beats_until(a, spec.duration_s / 4, spec.beats_per_bar)
            # The ramp spans half the song at the mean tempo.
            length = max(int(round(spec.duration_s / 2 * (a + b) / 120.0)), 1)
            frac = np.clip((idx - start) / length, 0.0, 1.0)
            tempi = a + (b - a) * frac
    # Cut at the first bar line at or after the duration.
    us = microseconds_per_beat(tempi)
    ends = np.cumsum(us) / 1e6
    n_beats = int(np.searchsorted(ends, spec.duration_s)) + 1
    n_beats = pickup + int(np.ceil(max(n_beats - pickup, 0) / spec.beats_per_bar)) * spec.beats_per_bar
    return tempi[:n_beats]


def _beats_until(bpm: float, seconds: float, beats_per_bar: int) -> int:
    """Whole bars of beats at ``bpm`` that fit in ``seconds``."""
    return int(seconds * bpm / 60.0) // beats_per_bar * beats_per_bar


def microseconds_per_beat(tempi_bpm: np.ndarray) -> np.ndarray:
    """The integer tempo a MIDI file stores for each beat."""
    return np.round(60e6 / np.asarray(tempi_bpm, dtype=np.float64)).astype(np.int64)


def beat_positions(spec: SongSpec) -> np.ndarray:
    """Each beat's position in its bar, from 0 (the downbeat): the pickup's beats are the last of a bar."""
    n = len(beat_tempi(spec))
    return (np.arange(n) - spec.pickup_beats) % spec.beats_per_bar


def beat_times(spec: SongSpec) -> np.ndarray:
    """Exact beat onsets (s) of the song: the first at 0."""
    us = microseconds_per_beat(beat_tempi(spec))
    return np.concatenate(([0], np.cumsum(us)[:-1])) / 1e6


def write_midi(spec: SongSpec, path: Path) -> np.ndarray:
    """Write the song as a type-1 MIDI file; return its beat times (s)."""
    import mido  # only the ground-truth generator needs it

    rng = np.random.default_rng(spec.seed)
    tempi = beat_tempi(spec)
    us = microseconds_per_beat(tempi)
    n_beats = len(tempi)
    bpb = spec.beats_per_bar
    key = 45 + int(rng.integers(0, 7))  # A2..D#3 bass roots

    events: dict[str, list[tuple[float, mido.Message]]] = {"bass": [], "piano": [], "melody": [], "double": [],
                                                           "drums": []}

    def note(part: str, channel: int, pitch: int, start_beat: float, length_beats: float, velocity: int):
        if start_beat < 0:  # the part of the pickup's bar before the song starts
            return
        events[part].append((start_beat, mido.Message("note_on", channel=channel, note=pitch, velocity=velocity)))
        events[part].append((start_beat + length_beats * 0.95,
                             mido.Message("note_off", channel=channel, note=pitch, velocity=0)))

    offbeat = 2.0 / 3.0 if spec.swing else 0.5
    melody_pitch = 3  # index into the melody's scale
    scale = [key + 24 + 12 * octave + step for octave in range(3) for step in _PENTATONIC]
    pickup = spec.pickup_beats
    textures = _textures(spec)
    # Bar -1 is the pickup: only its last ``pickup`` beats sound.
    for bar in range(-1 if pickup else 0, (n_beats - pickup) // bpb):
        first = bar * bpb + pickup
        tex = textures[bar] if bar >= 0 and textures else _PLAIN
        if tex.starts:  # a section's own melody from its first note (a repeat replays it) and its lead
            rng, melody_pitch = np.random.default_rng(tex.seed), 3
            events["melody"].append((first, mido.Message("program_change", channel=3, program=tex.program)))
        loud = tex.loud
        degree = tex.progression[((bar - tex.first_bar) // spec.bars_per_chord) % len(tex.progression)]
        root = key + degree
        third = 3 if degree in _MINOR_DEGREE else 4
        chord = [root + 12, root + 12 + third, root + 19]
        for beat in range(bpb):
            accent = 12 if beat == 0 else 0
            note("bass", 1, root if beat % 2 == 0 else root + 7, first + beat, 0.9, 88 + accent + loud)
        if bpb == 3:  # oom-pah-pah: the bass is the oom
            for beat in (1, 2):
                for p in chord:
                    note("piano", 2, p, first + beat, 0.5, 62 + loud)
        else:
            for beat in (0, 2):
                for p in chord:
                    note("piano", 2, p, first + beat, 1.8, (70 if beat == 0 else 62) + loud)
        # Melody: a seeded rhythm of half, quarter and eighth notes filling the bar.
        position = 0.0
        while position < bpb - 1e-9:
            choices = [d for d in (2.0, 1.0, 1.0, 0.5, 0.5) if position + d <= bpb + 1e-9]
            length = float(rng.choice(choices))
            def lead(start, length_beats, velocity):
                note("melody", 3, scale[melody_pitch], start, length_beats, velocity + loud)
                if tex.double:
                    note("double", 4, scale[melody_pitch] + 12, start, length_beats, velocity - 10 + loud)

            if length == 0.5:
                # Eighths come in pairs; the second is swung.
                melody_pitch = int(np.clip(melody_pitch + rng.integers(-2, 3), 0, len(scale) - 1))
                lead(first + position, offbeat, 80)
                melody_pitch = int(np.clip(melody_pitch + rng.integers(-2, 3), 0, len(scale) - 1))
                lead(first + position + offbeat, 1.0 - offbeat, 72)
                length = 1.0
            else:
                melody_pitch = int(np.clip(melody_pitch + rng.integers(-2, 3), 0, len(scale) - 1))
                lead(first + position, length, 84)
            position += length
        if spec.drums and tex.drums:
            for beat in range(bpb):
                if beat == 0 or (bpb == 4 and beat == 2):
                    note("drums", 9, _KICK, first + beat, 0.25, 100 + loud)
                elif tex.drums == "full":
                    note("drums", 9, _SNARE, first + beat, 0.25, (90 if bpb == 4 else 70) + loud)
                note("drums", 9, _HAT, first + beat, 0.25, 70 + loud)
                note("drums", 9, _HAT, first + beat + offbeat, 0.25, 50 + loud)

    mid = mido.MidiFile(type=1, ticks_per_beat=TICKS_PER_BEAT)
    conductor = mido.MidiTrack()
    # A pickup is a short first bar (pickup/4), so MIDI readers put the bar lines where the music does.
    meta = [(0, mido.MetaMessage("time_signature", numerator=pickup or bpb, denominator=4))]
    if pickup:
        meta.append((pickup * TICKS_PER_BEAT, mido.MetaMessage("time_signature", numerator=bpb, denominator=4)))
    meta += [(i * TICKS_PER_BEAT, mido.MetaMessage("set_tempo", tempo=int(tempo)))
             for i, tempo in enumerate(us) if i == 0 or tempo != us[i - 1]]
    last_tick = 0
    for tick, msg in sorted(meta, key=lambda e: e[0]):
        conductor.append(msg.copy(time=tick - last_tick))
        last_tick = tick
    mid.tracks.append(conductor)
    programs = {"bass": (1, _BASS_PROGRAM), "piano": (2, _PIANO_PROGRAM),
                "melody": (3, _MELODY_PROGRAMS[spec.seed % len(_MELODY_PROGRAMS)]), "double": (4, _DOUBLE_PROGRAM)}
    for part, messages in events.items():
        if not messages:
            continue
        track = mido.MidiTrack()
        if part in programs:
            channel, program = programs[part]
            track.append(mido.Message("program_change", channel=channel, program=program, time=0))
        tick = 0
        # note_offs before note_ons at the same tick, so repeated notes retrigger
        for start, msg in sorted(messages, key=lambda e: (e[0], e[1].type == "note_on")):
            at = int(round(start * TICKS_PER_BEAT))
            track.append(msg.copy(time=at - tick))
            tick = at
        mid.tracks.append(track)
    with atomic_output(Path(path), "wb") as fh:
        mid.save(file=fh)
    return np.concatenate(([0], np.cumsum(us)[:-1])) / 1e6


def find_soundfont() -> Path:
    """A General MIDI soundfont from Debian's packages, or a clear error saying what to install."""
    for candidate in SOUNDFONTS:
        if Path(candidate).is_file():
            return Path(candidate)
    raise InputError("no General MIDI soundfont found; install one: apt-get install timgm6mb-soundfont")


def render_midi(midi_path: Path, wav_path: Path, *, soundfont: Path | None = None, sr: int = RENDER_SR) -> None:
    """Render a MIDI file to a wav with fluidsynth (no audio device, no reverb or chorus)."""
    exe = shutil.which("fluidsynth")
    if exe is None:
        raise InputError("fluidsynth is not installed; install it: apt-get install fluidsynth timgm6mb-soundfont")
    soundfont = soundfont or find_soundfont()
    with atomic_path(wav_path) as tmp:
        cmd = [exe, "-n", "-i", "-q", "-R", "0", "-C", "0", "-g", "0.6", "-r", str(sr), "-T", "wav",
               "-F", str(tmp), str(soundfont), str(midi_path)]
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        if done.returncode != 0 or tmp.stat().st_size < 1000:
            raise InputError(f"fluidsynth could not render {midi_path}: {done.stderr.strip()[-300:]}")


def render_song(spec: SongSpec, out_dir: Path, *, soundfont: Path | None = None) -> GroundTruthSong:
    """The song's MIDI, wav and truth (``NAME.beats.json``: beats, bar positions) in ``out_dir``, made when missing."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    midi_path = out_dir / f"{spec.name}.mid"
    wav_path = out_dir / f"{spec.name}.wav"
    beats_path = out_dir / f"{spec.name}.beats.json"
    beats, positions = beat_times(spec), beat_positions(spec)
    sections = section_times(spec)
    if not midi_path.is_file():
        write_midi(spec, midi_path)
    if not wav_path.is_file():
        render_midi(midi_path, wav_path, soundfont=soundfont)
    if not beats_path.is_file():
        with atomic_output(beats_path) as fh:
            fh.write(json.dumps({"beats": beats.tolist(), "beat_in_bar": positions.tolist(),
                                 "beats_per_bar": spec.beats_per_bar, "spec": asdict(spec),
                                 **({"sections": sections} if sections else {})}, indent=1))
    duration = sections[-1][1] if sections else spec.duration_s
    return GroundTruthSong(spec.name, wav_path, midi_path, beats, duration, spec.tags,
                           beat_in_bar=positions, beats_per_bar=spec.beats_per_bar, sections=tuple(sections))


def section_times(spec: SongSpec) -> list[tuple[float, float, str]]:
    """``(start s, end s, label)`` of each section of a song with a ``form`` (none without): each starts
    on its first downbeat, the first at 0 s (with the pickup), the last ends with its last bar."""
    if not spec.form:
        return []
    us = microseconds_per_beat(beat_tempi(spec))
    edges = np.concatenate(([0], np.cumsum(us))) / 1e6
    starts = [0.0 if k == 0 else float(edges[spec.pickup_beats + first * spec.beats_per_bar])
              for k, (_, first, _) in enumerate(spec.sections)]
    ends = starts[1:] + [float(edges[-1])]
    return [(a, b, label) for a, b, (label, _, _) in zip(starts, ends, spec.sections)]


#: Songs of known form for the music-structure benchmark, per split (tune: where the analysis's constants
#: were chosen; test: what the bench reports): (tempo, beats per bar, form). Sections are verse (V),
#: chorus (C), bridge (B), intro (I) and outro (O); 8 bars each but intros and outros of 4.
_FORMS = {
    "pop": (("I", 4), ("V", 8), ("C", 8), ("V", 8), ("C", 8), ("B", 8), ("C", 8)),
    "aaba": (("V", 8), ("V", 8), ("B", 8), ("V", 8)),
    "double-chorus": (("V", 8), ("C", 8), ("V", 8), ("C", 8), ("C", 8), ("O", 4)),
    "rondo": (("V", 8), ("C", 8), ("B", 8), ("C", 8), ("V", 8), ("C", 8)),
}
STRUCTURE_SPLITS = {
    "tune": ((96, 4, "pop"), (124, 4, "aaba"), (140, 4, "double-chorus"), (108, 3, "rondo"),
             (150, 4, "pop"), (88, 4, "rondo")),
    "test": ((100, 4, "pop"), (132, 4, "aaba"), (118, 4, "double-chorus"), (112, 3, "rondo"),
             (156, 4, "rondo"), (92, 3, "pop")),
}


def structure_specs(split: str = "test") -> list[SongSpec]:
    """The songs of known form of a split (``STRUCTURE_SPLITS``), with drums, half of them with a pickup."""
    if split not in STRUCTURE_SPLITS:
        raise InputError(f"generated-song split {split!r}: use one of {', '.join(STRUCTURE_SPLITS)}")
    seed = SPLITS[split]["seed"] + 500
    return [SongSpec(f"form-{form}{bpm}_{bpb}-4", (float(bpm),), beats_per_bar=bpb, seed=seed + i,
                     pickup_beats=(i % 2) * (bpb - 1), form=_FORMS[form])
            for i, (bpm, bpb, form) in enumerate(STRUCTURE_SPLITS[split])]


def ground_truth_set(cache_dir: Path, *, quick: bool = False, specs: list[SongSpec] | None = None,
                     progress=None, split: str = "test") -> list[GroundTruthSong]:
    """Render (once) and return the benchmark's ground-truth songs, cached under ``cache_dir``.

    The cache folder's name hashes the specs, the generator version and the
    soundfont, so a change to any of them renders afresh.
    """
    specs = song_specs(quick=quick, split=split) if specs is None else specs
    soundfont = find_soundfont()
    # A song without a form keys as it did before forms existed (its render is the same).
    key = hashlib.sha256(json.dumps([GENERATOR_VERSION, str(soundfont),
                                     [{k: v for k, v in asdict(s).items() if k != "form" or v} for s in specs]],
                                    sort_keys=True).encode()).hexdigest()[:12]
    out_dir = Path(cache_dir) / f"groundtruth-{key}"
    songs = []
    for i, spec in enumerate(specs):
        if progress is not None:
            progress(f"ground truth {i + 1}/{len(specs)}: {spec.name}")
        songs.append(render_song(spec, out_dir, soundfont=soundfont))
    return songs

"""A recording's melody as a ``NoteSequence`` (beyond Loi & Li, who start from MIDI).

The pitch track comes from librosa's pYIN (probabilistic YIN, with voicing); it is
rounded to semitones, smoothed, and cut into notes where the pitch changes, where
the voice stops, or where a new onset repeats the same pitch. Beats come from the
product's beat tracker (``analyze_music``); they play the rhythm track, so a note is
a beat note when it starts within ``BEAT_TOLERANCE_S`` of a beat. Intensity is the
note's RMS level mapped from 40 dB below the song's loudest note to it onto 0..127,
and durations in sixteenths use the local beat period.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..io.audio import DEFAULT_MAX_DURATION_S, load_audio
from .analysis import analyze_music
from .intensity import rms_db
from .notes import MIN_MELODY_NOTES, NoteSequence, note_sequence
from .onset import onset_envelope

PITCH_SR = 11025            # pYIN at a quarter of CD rate: melodies live below 1.4 kHz
PITCH_HOP = 256             # 23 ms frames
FMIN_HZ, FMAX_HZ = 65.0, 1400.0
MIN_NOTE_S = 0.06
MERGE_GAP_S = 0.16         # same pitch again after a shorter silence: still the same note
SNAP_S = 0.12              # how far back a note's start may move to an onset
BEAT_TOLERANCE_S = 0.07
DYNAMIC_RANGE_DB = 40.0
MIDI_SUFFIXES = (".mid", ".midi", ".kar", ".smf")


def _runs(labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and stop indices of the runs of equal values in ``labels``."""
    change = np.flatnonzero(np.diff(labels)) + 1
    starts = np.concatenate(([0], change))
    stops = np.concatenate((change, [len(labels)]))
    return starts, stops


def pitch_track(y: np.ndarray, sr: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame MIDI pitch (NaN where unvoiced) and frame times in seconds, by pYIN."""
    import librosa
    from scipy.ndimage import median_filter

    f0, voiced, _ = librosa.pyin(y, fmin=FMIN_HZ, fmax=FMAX_HZ, sr=sr, frame_length=1024, hop_length=PITCH_HOP,
                                 resolution=0.2, n_thresholds=50)
    midi = np.where(voiced & np.isfinite(f0), 69.0 + 12.0 * np.log2(np.where(np.isfinite(f0), f0, 440.0) / 440.0),
                    np.nan)
    # Semitones, with one-frame wobbles (vibrato, octave slips) removed.
    rounded = np.round(midi)
    filled = np.where(np.isnan(rounded), -1.0, rounded)
    smooth = median_filter(filled, size=5, mode="nearest")
    smooth = np.where(smooth < 0, np.nan, smooth)
    return smooth, np.arange(len(smooth)) * PITCH_HOP / sr


def segment_pitch_track(midi: np.ndarray, times_s: np.ndarray, onset_s: np.ndarray,
                        min_note_s: float = MIN_NOTE_S) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Notes (onset_s, sounding_s, pitch) from a semitone pitch track (NaN: unvoiced).

    A note is a run of one pitch; pYIN needs a few frames of steady pitch to call
    a frame voiced, so each note's start is moved back to an onset (``onset_s``,
    from the onset envelope) up to ``SNAP_S`` before it. Onsets do not split runs:
    drums make onsets in the middle of held notes.
    """
    label = np.where(np.isnan(midi), -1.0, midi)
    starts, stops = _runs(label)
    hop_s = times_s[1] - times_s[0] if len(times_s) > 1 else PITCH_HOP / PITCH_SR
    voiced = label[starts] >= 0
    starts, stops = starts[voiced], stops[voiced]
    # A held note broken by a short unvoiced gap (a drum hit masking it) is one note.
    join = np.flatnonzero((label[starts[1:]] == label[starts[:-1]]) & ((starts[1:] - stops[:-1]) * hop_s < MERGE_GAP_S))
    keep_start = np.ones(len(starts), dtype=bool)
    keep_start[join + 1] = False
    keep_stop = np.ones(len(stops), dtype=bool)
    keep_stop[join] = False
    starts, stops = starts[keep_start], stops[keep_stop]
    keep = (stops - starts) * hop_s >= min_note_s
    starts, stops = starts[keep], stops[keep]
    if len(starts) == 0:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    begin, end = times_s[starts], times_s[stops - 1] + hop_s
    if len(onset_s):
        k = np.clip(np.searchsorted(onset_s, begin + 0.02, side="right") - 1, 0, len(onset_s) - 1)
        cand = onset_s[k]
        prev_end = np.concatenate(([-np.inf], end[:-1]))
        snap = (cand <= begin + 0.02) & (cand >= begin - SNAP_S) & (cand > prev_end)
        begin = np.where(snap, cand, begin)
    # Runs that now start together (a pitch slip at the attack) keep the first.
    first = np.concatenate(([True], np.diff(begin) > 1e-9))
    return begin[first], (end - begin)[first], label[starts][first]


def audio_notes(path, *, max_duration_s: float | None = DEFAULT_MAX_DURATION_S) -> NoteSequence:
    """The melody of an audio file as a ``NoteSequence`` (see the module docstring)."""
    music = analyze_music(path=path, max_duration_s=max_duration_s)
    y, sr = load_audio(path, sr=PITCH_SR, mono=True, max_duration_s=max_duration_s)
    midi, times_s = pitch_track(y, sr)
    env = onset_envelope(y, sr, hop_length=PITCH_HOP)
    # Onset peaks well above the local level: where repeated notes restart.
    from scipy.signal import find_peaks

    peaks, _ = find_peaks(env, height=np.median(env) + np.std(env), distance=max(1, int(0.1 * sr / PITCH_HOP)))
    onset_s, sounding_s, pitch = segment_pitch_track(midi, times_s, peaks * PITCH_HOP / sr)
    if len(onset_s) < MIN_MELODY_NOTES:
        raise InputError(f"{path}: no melody could be heard ({len(onset_s)} pitched notes found); "
                         "give a recording with a clear tune, or its MIDI file")
    # Loudness of each note, relative to the loudest.
    # A note's samples, clipped to the signal: the pitch track's last frame may end past its last sample.
    a = np.clip(np.round(onset_s * sr).astype(np.int64), 0, len(y) - 1)
    b = np.clip(np.round((onset_s + sounding_s) * sr).astype(np.int64), a + 1, len(y))
    energy = np.concatenate(([0.0], np.cumsum(np.square(y, dtype=np.float64))))
    db = rms_db(np.sqrt(np.maximum(energy[b] - energy[a], 0.0) / (b - a)))
    intensity = 127.0 * np.clip((db - (db.max() - DYNAMIC_RANGE_DB)) / DYNAMIC_RANGE_DB, 0.0, 1.0)
    beats = music.beat_times_s
    k = np.clip(np.searchsorted(beats, onset_s), 1, len(beats) - 1)
    is_beat = np.minimum(np.abs(beats[k] - onset_s), np.abs(beats[k - 1] - onset_s)) <= BEAT_TOLERANCE_S
    period = np.diff(beats)[k - 1]  # the beat interval around each note
    meta = {"kind": "audio", "beat_confidence": music.beat_confidence, "default_tempo": music.default_tempo}
    return note_sequence(onset_s, pitch, sounding_s, intensity, sixteenth_s=period / 4.0, beat_times_s=beats,
                         duration_s=music.duration_s, tempo_bpm=music.tempo_bpm, is_beat=is_beat,
                         source=str(path), meta=meta)


def read_notes(path, *, melody_track: int | None = None, rhythm_track: int | None = None,
               max_duration_s: float | None = DEFAULT_MAX_DURATION_S) -> NoteSequence:
    """Notes of a song: MIDI files (.mid, .midi, .kar) are read as MIDI, anything else as audio."""
    from pathlib import Path

    from .notes import midi_notes

    if Path(path).suffix.lower() in MIDI_SUFFIXES:
        return midi_notes(path, melody_track=melody_track, rhythm_track=rhythm_track, max_duration_s=max_duration_s)
    if melody_track is not None or rhythm_track is not None:
        raise InputError("--melody-track and --rhythm-track choose MIDI parts; a recording has none")
    return audio_notes(path, max_duration_s=max_duration_s)

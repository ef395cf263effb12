"""From a song to ``MusicFeatures``: beats, tempo, beat confidence, per-beat intensity, metre and downbeats.

``analyze_music`` takes a file or samples (librosa style, keyword-only), checks
that there is something to dance to, tracks the beats, and falls back to a steady
grid at ``fallback_bpm`` when the audio has no clear pulse (noise, a drone, a
sustained chord): that is a valid song, not an error, and ``default_tempo`` says so.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.audio import DEFAULT_MAX_DURATION_S, DEFAULT_MIN_DURATION_S, load_audio
from ..io.resampling import resample
from ..types import FALLBACK_BPM, MusicFeatures
from .beats import (DEFAULT_TRACKER, MIN_BEATS, MIN_CONFIDENCE, TRACKERS, beat_onset_db, steady_beat_grid,
                    track_beats)
from .intensity import beat_intensity_db, rms_db
from .metre import track_metre
from .onset import ANALYSIS_SR, HOP_LENGTH, onset_envelope

# Below this peak level a file is "silent" (a 16-bit file's dither sits near -90 dBFS,
# a quiet but real recording peaks well above -40 dBFS).
SILENCE_PEAK_DB = -60.0


def analyze_music(*, path=None, y: np.ndarray | None = None, sr: int | None = None,
                  fallback_bpm: float = FALLBACK_BPM, tracker: str = DEFAULT_TRACKER,
                  min_confidence: float = MIN_CONFIDENCE, silence_db: float = SILENCE_PEAK_DB,
                  max_duration_s: float | None = DEFAULT_MAX_DURATION_S,
                  min_duration_s: float = DEFAULT_MIN_DURATION_S, structure: bool = False) -> MusicFeatures:
    """Analyse a song for dancing.

    Give either ``path`` (any format ``dancesynth.io.audio.load_audio`` reads) or the
    samples ``y`` (``(n,)`` or ``(channels, n)``) with their rate ``sr``. Audio is
    analysed mono at 22050 Hz with 20 ms feature frames.

    Beats come from ``tracker`` (see ``dancesynth.music.beats.TRACKERS``: the
    default ``"dp"`` needs numpy only, ``"librosa"`` costs seconds of numba
    compilation per process); the tempo is 60 / median beat interval. Beats are
    kept wherever the audio is not silent (quiet passages and fade-outs keep
    theirs). When fewer than 4 beats are found or their ``beat_confidence`` (pulse
    clarity, see ``dancesynth.music.beats.beat_confidence``) is below
    ``min_confidence``, the audio has no clear beat: the beats become a steady grid
    at ``fallback_bpm`` from 0 s to the end, with ``default_tempo=True``.
    ``intensity_db`` is the RMS level (dB re full scale, floored at -100 dB) of
    each beat interval. ``beats_per_bar`` (3 or 4) and ``beat_in_bar`` come from
    ``dancesynth.music.metre.track_metre`` (``meta["metre_confidence"]`` in [0, 1]
    says how sure it is); the fallback grid counts 4/4 from its first beat with
    confidence 0. With ``structure``, also the song's sections and phrases
    (``MusicFeatures.structure``, ``dancesynth.music.structure``) from the same samples.

    Raises ``InputError`` for unusable input: a bad file (see ``load_audio``),
    audio shorter than ``min_duration_s`` or longer than ``max_duration_s``, or
    silence (peak below ``silence_db`` dBFS).
    """
    if (path is None) == (y is None):
        raise InputError("analyze_music needs exactly one of path= (an audio file) or y= (samples, with sr=)")
    if path is not None and sr is not None:
        raise InputError(f"sr= describes samples given as y=; a file is always analysed at {ANALYSIS_SR} Hz")
    if tracker not in TRACKERS:
        raise InputError(f"unknown beat tracker {tracker!r}; choose one of {', '.join(sorted(TRACKERS))}")
    if not (np.isfinite(fallback_bpm) and 20.0 <= fallback_bpm <= 400.0):
        raise InputError(f"fallback tempo must be between 20 and 400 bpm, got {fallback_bpm!r}")
    if path is not None:
        name = str(Path(path))
        samples, rate = load_audio(path, sr=ANALYSIS_SR, mono=True,
                                   max_duration_s=max_duration_s, min_duration_s=min_duration_s)
    else:
        name = ""
        samples, rate = _prepare_samples(y, sr, max_duration_s, min_duration_s)

    duration_s = len(samples) / rate
    peak = peak_level(samples)
    peak_db = float(rms_db(peak))
    if peak_db < silence_db:
        where = f"{name}: " if path is not None else ""
        raise InputError(f"{where}the audio is silent: nothing to dance to (peak level {peak_db:.0f} dBFS); "
                         f"check that the right file or track was given")

    onset_env = onset_envelope(samples, rate, hop_length=HOP_LENGTH)
    tracked_s, tracked_bpm, confidence = track_beats(samples, rate, onset_env=onset_env, tracker=tracker,
                                                     hop_length=HOP_LENGTH)
    clear = len(tracked_s) >= MIN_BEATS and confidence >= min_confidence
    if clear:
        beat_times_s, tempo_bpm = tracked_s, tracked_bpm
    else:
        beat_times_s, tempo_bpm = steady_beat_grid(duration_s, fallback_bpm), float(fallback_bpm)
    beats_per_bar, beat_in_bar, metre_confidence = track_metre(samples, rate, beat_times_s=beat_times_s,
                                                               end_s=duration_s, steady_grid=not clear)

    form = None
    if structure:
        from .structure import song_structure

        form = song_structure(samples, rate, beat_times_s, beat_in_bar, beats_per_bar, duration_s)
    return MusicFeatures(
        duration_s=duration_s,
        beat_times_s=beat_times_s,
        intensity_db=beat_intensity_db(samples, rate, beat_times_s),
        tempo_bpm=tempo_bpm,
        beat_confidence=float(confidence),
        default_tempo=not clear,
        source=name,
        beats_per_bar=beats_per_bar,
        beat_in_bar=beat_in_bar,
        structure=form,
        meta={
            "tracker": tracker,
            "analysis_sr": rate,
            "hop_length": HOP_LENGTH,
            "feature_fps": rate / HOP_LENGTH,
            "tracked_tempo_bpm": tracked_bpm,
            "n_tracked_beats": int(len(tracked_s)),
            "beat_onset_db": beat_onset_db(onset_env, np.round(tracked_s * rate / HOP_LENGTH).astype(int)),
            "min_confidence": float(min_confidence),
            "peak_db": peak_db,
            "metre_confidence": metre_confidence,
        },
    )


def peak_level(y: np.ndarray, *, block: int = 1 << 18) -> float:
    """``max(|y|)`` (0 for no samples), a block at a time: no absolute-value copy of the song."""
    peak = 0.0
    for start in range(0, len(y), block):
        peak = max(peak, float(np.max(np.abs(y[start:start + block]))))
    return peak


def _prepare_samples(y, sr, max_duration_s, min_duration_s) -> tuple[np.ndarray, int]:
    """Validate caller-supplied samples and bring them to mono at the analysis rate."""
    if sr is None or not np.isfinite(sr) or sr <= 0 or int(sr) != sr:
        raise InputError(f"analyze_music(y=...) needs the sample rate sr= as a positive integer, got {sr!r}")
    sr = int(sr)
    y = np.asarray(y, dtype=np.float32)
    if y.ndim == 2:
        y = y.mean(axis=0)  # librosa's layout: (channels, n)
    if y.ndim != 1:
        raise InputError(f"samples must have shape (n,) or (channels, n), got {y.shape}")
    if not np.all(np.isfinite(y)):
        raise InputError("the audio samples contain NaN or infinite values; clean the signal first")
    duration_s = len(y) / sr
    if max_duration_s is not None and duration_s > max_duration_s:
        raise InputError(f"the audio samples are {duration_s / 60:.1f} min long, over the limit of "
                         f"{max_duration_s / 60:.1f} min; raise max_duration_s or cut the song")
    if duration_s < min_duration_s:
        raise InputError(f"the audio samples are only {duration_s:.1f} s long, too short to find a beat; "
                         f"they need at least {min_duration_s:g} s")
    return resample(y, sr, ANALYSIS_SR), ANALYSIS_SR

"""Beat tracking and beat confidence.

The tracker sits behind one function, ``track_beats(..., tracker="varying")``, so
that trackers can be measured and swapped without touching callers:

- ``"varying"`` (default): Ellis' dynamic programming following a local tempo
  curve, with a metrical-level check (``dancesynth.beat_tracking.dp_beat_track_varying``).
  On the generated ground truth (``dancesynth.bench.groundtruth``: tempo steps,
  ramps, swing, 3/4, 60-180 bpm) it scores mean F = 1.00 where one global tempo
  scores 0.93 (``dancesynth bench``).
- ``"dp"``: Ellis' dynamic programming at one global tempo (``dancesynth.beat_tracking.dp_beat_track``).
- ``"librosa"``: the same algorithm as librosa implements it, for comparison. Its
  tempo is rounded to whole frames; otherwise it gives the same beats.

Every tracker works on the same onset-strength envelope (``onset.onset_envelope``,
librosa's log-mel spectral flux computed in numpy) at ``FEATURE_FPS`` frames per
second and returns beat frames over the whole envelope; trimming to where the
audio sounds, sub-frame refinement, times, tempo and confidence are done here the
same way for all of them.

Why not librosa's own trimming (``beat_track(trim=True)``): it drops the leading
and trailing beats whose onset strength is below half the song's average, so a
song whose second half is 20 dB quieter lost its last 17 s of beats. Beats are
instead kept wherever the audio is not silent (``sounding_span``).

librosa is imported only by the ``"librosa"`` tracker: its first import compiles
numba kernels that it does not cache (about 4 s in every new process), and the
default path must stay at numpy speed.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from .. import timebase
from ..beat_tracking import dp_beat_track, dp_beat_track_varying
from ..errors import InputError
from .intensity import cumulative_energy
from .onset import ANALYSIS_SR, HOP_LENGTH, onset_envelope

# Chance level of the beat contrast (see ``beat_confidence``): on noise, where the
# tracker can only pick random peaks, the contrast stayed below
# CHANCE_FLOOR + CHANCE_SCALE / sqrt(n_beats) (white, pink and brown noise of 4 s
# to 15 min: largest 0.18 with 9 beats, 0.10 with 26, 0.057 with 131, 0.045 with 1982).
CHANCE_FLOOR = 0.04
CHANCE_SCALE = 0.42
# Onset strength (dB of spectral rise, averaged over mel bands, at the beats) below
# which the audio has no onsets worth dancing to, and from which it counts fully.
# A sustained chord measures 0.2-0.25 dB (the envelope only ripples with the
# analysis frames), the bundled songs 1.8-5.3 dB, their weakest 10 s excerpt 1.3 dB.
ONSET_FLOOR_DB = 0.3
ONSET_FULL_DB = 1.0
# A beat is "clear" at or above this confidence. The bundled songs score 0.15-0.42,
# noise and sustained chords at most about 0.01 (re-measured with the numpy
# envelope and the "dp" tracker: songs 0.153-0.421; white, pink and brown noise of
# 4.5 s to 15 min and organ chords at most 0.006).
MIN_CONFIDENCE = 0.05
# Fewer beats than this cannot show a pulse (a tempo needs several intervals).
MIN_BEATS = 4
# The onset envelope peaks this long after a click starts (measured on clicks at
# 120 bpm over 10 sub-frame phases: 9-22 ms, median 13 ms), so beats are moved
# earlier by it. Instruments with slower attacks (General MIDI renders) still peak
# about 10 ms later.
ONSET_LATENCY_S = 0.013
# Trailing beats weaker than this fraction of the median beat sit on a decaying
# tail (generated songs: 0.00-0.22 after the last note, 0.7-1.6 on the beats).
TRAILING_BEAT_FRACTION = 0.3
# Frames quieter than the song's loud frames (95th percentile) by more than this
# are silence: beats there are dropped. -50 dB keeps fade-outs and quiet passages.
SILENCE_BELOW_LOUD_DB = 50.0


def _track_dp(onset_env: np.ndarray, sr: int, hop_length: int) -> np.ndarray:
    """Ellis' dynamic-programming tracker in numpy (``dancesynth.beat_tracking.dp_beat_track``), untrimmed."""
    frames, _ = dp_beat_track(onset_env, sr / hop_length)
    return frames


def _track_varying(onset_env: np.ndarray, sr: int, hop_length: int) -> np.ndarray:
    """Ellis' DP following a local tempo curve (``dancesynth.beat_tracking.dp_beat_track_varying``), untrimmed."""
    frames, _ = dp_beat_track_varying(onset_env, sr / hop_length)
    return frames


def _track_librosa(onset_env: np.ndarray, sr: int, hop_length: int) -> np.ndarray:
    """Ellis' dynamic-programming tracker as librosa implements it, untrimmed."""
    import librosa.beat

    _, frames = librosa.beat.beat_track(onset_envelope=onset_env, sr=sr, hop_length=hop_length,
                                        units="frames", trim=False)
    return np.asarray(frames, dtype=np.int64)


# name -> tracker(onset_env, sr, hop_length) -> beat frames over the whole envelope.
TRACKERS: dict[str, Callable[[np.ndarray, int, int], np.ndarray]] = {
    "dp": _track_dp,
    "varying": _track_varying,
    "librosa": _track_librosa,
}
DEFAULT_TRACKER = "varying"


def track_beats(y: np.ndarray | None = None, sr: int = ANALYSIS_SR, *, onset_env: np.ndarray | None = None,
                tracker: str = DEFAULT_TRACKER, hop_length: int = HOP_LENGTH,
                ) -> tuple[np.ndarray, float, float]:
    """Find the beats of mono audio.

    Give the samples ``y``, and optionally their precomputed ``onset_env`` (from
    ``onset_envelope`` with the same ``sr`` and ``hop_length``). With ``onset_env``
    alone beats are not trimmed to the sounding part of the audio.

    Beat frames are refined to a fraction of a frame (``refine_beat_frames``), so
    the tempo is not quantised to whole 20 ms frames (at 128 bpm a beat lasts
    23.4 frames; whole frames would give 130.4 bpm).

    Returns
    -------
    beat_times_s : (B,) increasing beat instants in seconds
    tempo_bpm : 60 / median beat interval (0 when fewer than two beats)
    confidence : ``beat_confidence`` of these beats
    """
    if tracker not in TRACKERS:
        raise InputError(f"unknown beat tracker {tracker!r}; choose one of {', '.join(sorted(TRACKERS))}")
    if onset_env is None:
        if y is None:
            raise InputError("track_beats needs the samples y= or an onset envelope onset_env=")
        onset_env = onset_envelope(y, sr, hop_length=hop_length)
    frames = np.unique(TRACKERS[tracker](onset_env, sr, hop_length))
    frames = frames[(frames >= 0) & (frames < len(onset_env))]
    if y is not None:
        first, last = sounding_span(y, hop_length=hop_length)
        frames = frames[(frames >= first) & (frames <= last)]
    frames = drop_trailing_weak_beats(onset_env, frames)
    beat_times_s = timebase.frames_to_seconds(refine_beat_frames(onset_env, frames), sr / hop_length)
    beat_times_s = np.maximum(beat_times_s - ONSET_LATENCY_S, 0.0)
    tempo_bpm = timebase.bpm_from_intervals(np.diff(beat_times_s))
    return beat_times_s, tempo_bpm, beat_confidence(onset_env, frames)


def drop_trailing_weak_beats(onset_env: np.ndarray, beat_frames: np.ndarray, *,
                             fraction: float = TRAILING_BEAT_FRACTION) -> np.ndarray:
    """Beats without the run of last beats whose onset strength is below ``fraction`` of the median beat's.

    The tracker carries its pulse on through the final chord's decay; a dancer stops
    with the music. Onset strength is spectral rise in dB, so quiet endings and
    fade-outs keep their beats; only beats on no onset at all go.
    """
    frames = np.asarray(beat_frames, dtype=np.int64)
    if frames.size < MIN_BEATS:
        return frames
    strength = _peak_envelope(onset_env)[frames]
    weak = strength < fraction * np.median(strength)
    keep = frames.size
    while keep > 0 and weak[keep - 1]:
        keep -= 1
    return frames[:keep]


def sounding_span(y: np.ndarray, *, hop_length: int = HOP_LENGTH, frame_length: int = 2048,
                  below_loud_db: float = SILENCE_BELOW_LOUD_DB) -> tuple[int, int]:
    """First and last feature frame at which the audio is not silent.

    Frame ``i`` is the RMS of ``frame_length`` samples centred on sample
    ``i * hop_length`` (librosa's framing); it is silent when more than
    ``below_loud_db`` below the 95th percentile of all frames. ``(0, -1)`` if all
    frames are silent.
    """
    y = np.asarray(y)
    n_frames = 1 + len(y) // hop_length
    centres = np.arange(n_frames) * hop_length
    lo = np.clip(centres - frame_length // 2, 0, len(y))
    hi = np.clip(centres + frame_length // 2, 0, len(y))
    # Only the running energy at the frames' ends is kept (no float64 copy of the song).
    energy = cumulative_energy(y, np.stack([lo, hi]))
    mean_square = np.maximum(energy[1] - energy[0], 0.0) / frame_length
    with np.errstate(divide="ignore"):
        level = 10.0 * np.log10(mean_square)
    finite = level[np.isfinite(level)]
    if finite.size == 0:
        return 0, -1
    sounding = np.flatnonzero(level > np.percentile(finite, 95) - below_loud_db)
    return (int(sounding[0]), int(sounding[-1])) if sounding.size else (0, -1)


def refine_beat_frames(onset_env: np.ndarray, beat_frames) -> np.ndarray:
    """Beat frames moved to the vertex of a parabola through the onset peak they sit on.

    Only beats on a strict local maximum of the envelope move, by at most half a
    frame, so the order of beats is kept.
    """
    o = np.asarray(onset_env, dtype=np.float64)
    frames = np.asarray(beat_frames, dtype=np.int64)
    refined = frames.astype(np.float64)
    inner = (frames > 0) & (frames < len(o) - 1)
    f = frames[inner]
    left, mid, right = o[f - 1], o[f], o[f + 1]
    curvature = left - 2.0 * mid + right
    peak = (mid >= left) & (mid >= right) & (curvature < 0)
    shift = np.zeros(f.size)
    shift[peak] = 0.5 * (left[peak] - right[peak]) / curvature[peak]
    refined[inner] += np.clip(shift, -0.5, 0.5)
    return refined


def _peak_envelope(onset_env: np.ndarray) -> np.ndarray:
    """The onset envelope max-filtered over +-1 frame, so a beat a frame off its onset still counts."""
    padded = np.pad(np.asarray(onset_env, dtype=np.float64), 1, mode="edge")
    return np.maximum(np.maximum(padded[:-2], padded[1:-1]), padded[2:])


def beat_contrast(onset_env: np.ndarray, beat_frames) -> float:
    """How much the onset envelope at the beats stands above its value at other phases.

    With ``o_max`` the onset envelope max-filtered over +-1 frame (+-20 ms),
    ``m_beat`` the mean of ``o_max`` at the beat frames and ``m_all`` its mean over
    the same beats shifted by every phase ``0..P-1`` of the median beat period ``P``::

        contrast = (m_beat - m_all) / (m_beat + m_all)        in [-1, 1]

    1 means all onset energy sits on the beats (a click track), 0 that the beats
    fall no more on onsets than random instants do. It does not depend on the
    envelope's scale.
    """
    onset_env = np.asarray(onset_env, dtype=np.float64)
    frames = np.asarray(beat_frames, dtype=np.int64)
    frames = frames[(frames >= 0) & (frames < len(onset_env))]
    if frames.size < 2:
        return 0.0
    period = max(int(round(np.median(np.diff(frames)))), 1)
    o_max = _peak_envelope(onset_env)
    shifted = np.clip(frames[None, :] + np.arange(period)[:, None], 0, len(o_max) - 1)
    values = o_max[shifted]
    m_beat = values[0].mean()
    m_all = values.mean()
    if m_beat + m_all <= 0:
        return 0.0
    return float((m_beat - m_all) / (m_beat + m_all))


def beat_onset_db(onset_env: np.ndarray, beat_frames) -> float:
    """Median onset strength at the beats (dB of spectral rise averaged over mel bands)."""
    frames = np.asarray(beat_frames, dtype=np.int64)
    frames = frames[(frames >= 0) & (frames < len(onset_env))]
    return float(np.median(_peak_envelope(onset_env)[frames])) if frames.size else 0.0


def beat_confidence(onset_env: np.ndarray, beat_frames) -> float:
    """Pulse clarity: how much better than chance the beats sit on onsets that are heard.

    ::

        confidence = (beat_contrast - CHANCE_FLOOR - CHANCE_SCALE / sqrt(B)) * onset_weight

    ``beat_contrast`` (see there) is corrected by the contrast chance gives with
    ``B`` beats: a tracker always finds *some* peaks in noise, so the raw contrast
    of noise is positive, and larger for short excerpts (few beats, more freedom).
    On white, pink and brown noise of 4 s to 15 min it stayed below
    ``0.04 + 0.42 / sqrt(B)``, so noise scores 0 or below.

    The contrast ignores scale, so ``onset_weight`` brings it back: it rises from 0
    to 1 as the median onset strength at the beats (``beat_onset_db``) goes from
    ``ONSET_FLOOR_DB`` (0.3 dB) to ``ONSET_FULL_DB`` (1 dB). A sustained chord's
    envelope only ripples (0.2 dB) with the analysis frames, periodically enough to
    be tracked; its weight is 0. Music's onsets measure 1.3 dB and more.

    The bundled songs score 0.15 to 0.42, click tracks about 0.6; noise and chords
    -0.2 to 0.01 (``MIN_CONFIDENCE`` is 0.05). Fewer than two beats give 0.
    """
    frames = np.asarray(beat_frames)
    if frames.size < 2:
        return 0.0
    clarity = beat_contrast(onset_env, frames) - CHANCE_FLOOR - CHANCE_SCALE / np.sqrt(frames.size)
    onset_weight = np.clip((beat_onset_db(onset_env, frames) - ONSET_FLOOR_DB)
                           / (ONSET_FULL_DB - ONSET_FLOOR_DB), 0.0, 1.0)
    return float(clarity * onset_weight)


def steady_beat_grid(duration_s: float, bpm: float, *, start_s: float = 0.0) -> np.ndarray:
    """Beats at a constant tempo from ``start_s`` to the end of the song."""
    if not (np.isfinite(bpm) and bpm > 0):
        raise InputError(f"tempo must be a positive number of beats per minute, got {bpm!r}")
    period = 60.0 / bpm
    return start_s + period * np.arange(int(np.floor((duration_s - start_s) / period + 1e-9)) + 1)

"""Beat tracking on a stream: the default offline tracker's pieces on a sliding window of the recent past.

Audio comes in chunks (mono floats at 22050 Hz, any size); ``update()`` gives the
beats the tracker is now sure of and has not given before, with the level of the
intervals they close. Nothing given is ever revised.

1. Envelope: ``push`` turns each new 20 ms frame into its mel power spectrum
   (``music.onset``'s window, framing and filters), kept for ``history_s``;
   ``update`` takes ``power_to_db`` and the flux: ``onset_envelope``'s values (its
   80 dB floor relative to the window's loudest bin, not the song's).
2. Tempo and level: ``beat_tracking.tempo_curve`` and ``metrical_level`` on the window.
3. Beats: Ellis' DP with a period per frame (``beat_tracking._dp``), backtracked
   from the best frame of the last period heard. *Anchored* when the last beat
   given was heard on music and is in the window: the DP starts there, so the next
   beat comes one period later (lags in ``[P/2, 2P]``) and a phase error is mended
   gradually at the DP's interval cost. *Re-phased* when the window's free DP path
   beats the given beats over the same span by ``REPHASE_GAIN`` per beat (early
   off-beats, a new metrical level): the new beats follow the free path. *Free*
   otherwise (no beat yet, the last one extrapolated or out of the window). A new
   beat closer than ``0.5 P`` to the previous is skipped; a gap over ``1.5 P`` is
   filled with evenly spaced extrapolated beats.
4. Latency: beats are given once ``latency_s`` (``LATENCY_S``) in the past; the
   backtracked path is unstable near the right edge.
5. Silence (50 dB under the recent loud level, or -70 dBFS) has no beats of its own:
   through it, or a stretch without onsets, a grid goes on at the current tempo
   (``fallback_bpm`` before any), marked ``extrapolated``; a dancer never waits.
   ``flush`` drops the run of last beats on no onset (a final decay), as offline.
6. Times are refined to the onset peak and moved 13 ms earlier, as offline.
7. Bars: once a beat is given, the interval it closes gets ``music.metre.beat_features``
   from the audio buffer (an excerpt on the offline frame grid: the values a whole
   recording gets), and ``live.bars.BarCounter`` counts the new beats' bar positions.

Memory is bounded: audio and spectra of ``history_s`` in fixed buffers, a few short
arrays of recent beats; nothing grows with the stream.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from ..beat_tracking import _dp, beat_local_score, metrical_level, tempo_curve
from ..defaults import BEAT_LATENCY_S
from ..errors import InputError
from ..types import FALLBACK_BPM
from ..music.beats import ONSET_LATENCY_S, TRAILING_BEAT_FRACTION, _peak_envelope, refine_beat_frames
from ..music.intensity import rms_db
from ..music.metre import CHROMA_HOP, DEFAULT_BEATS_PER_BAR, FEATURE_SR, N_FEATURES, beat_features
from .bars import BarCounter
from .ring import Ring
from ..music.onset import ANALYSIS_SR, HOP_LENGTH, N_FFT, N_MELS, mel_filterbank, power_to_db

FPS = ANALYSIS_SR / HOP_LENGTH
# Beats are given once this far in the past (the latency). Mean F on the 25 generated songs:
# updated every 5 s, 0.999 at 0-0.5 s, 1.000 from 1 s; every 0.1 s, 0.94/0.95/0.97/0.98/1.00 at 0.5/1/1.5/2/3 s.
LATENCY_S = BEAT_LATENCY_S
TIGHTNESS = 100.0
MIN_WINDOW_S = 1.0      # less audio than this has no tempo to speak of (the first beats wait)
# Silence: SILENCE_BELOW_LOUD_DB under the recent loud level (95th percentile of the
# window's 2048-sample RMS levels, decaying DECAY_DB_PER_S), or under SILENCE_FLOOR_DB.
SILENCE_BELOW_LOUD_DB = 50.0
SILENCE_FLOOR_DB = -70.0
DECAY_DB_PER_S = 1.0
# Beat intervals stay within [MIN_GAP_PERIODS, MAX_GAP_PERIODS] periods.
MAX_GAP_PERIODS = 1.5
MIN_GAP_PERIODS = 0.5
# Re-phase when >= REPHASE_MIN_BEATS of the last 2 x that many given beats (since the
# last re-phase) are in the window and the free path over their span scores REPHASE_GAIN
# per beat more (DP objective). Measured per update: songs tracked right 0-0.4; early
# off-beats or a changed metrical level 7-47; the bundled songs' ambiguous phases < 3.
REPHASE_MIN_BEATS = 4
REPHASE_GAIN = 4.0
DUE_EARLY_PERIODS = 0.15   # an update runs the analysis again from this far before the next beat seen
# Audio kept around a beat interval for its features: the bass rise looks a quarter
# interval back, the chroma windows reach 85 ms beyond the interval, resampling needs a margin.
BAR_MARGIN_S = 0.25
_ANCHOR = 1e6            # local score of the anchor: every kept path starts there
_HALF = N_FFT // 2
_DELAY = 1 + N_FFT // (2 * HOP_LENGTH)   # onset_envelope's shift: frame i rises from db[i-3] to db[i-2]


@dataclass(frozen=True)
class BeatUpdate:
    """What ``update`` or ``flush`` learnt since the previous call.

    ``beat_times_s``: new beats (s from the stream's start), increasing, after every
    beat given before. ``intensity_db``: per new beat, the level (as
    ``music.intensity.beat_intensity_db``) of the interval from the previous beat
    (the stream's start for the first); audio that left the history before its
    beats were asked for counts at its mean level. ``tempo_bpm``: the current tempo
    (0 before any). ``heard_s``: audio pushed in total. ``extrapolated``: per new
    beat, True when it continues the tempo through silence, a stretch without
    onsets or a gap instead of sitting on heard music. ``latency_s``: how far
    behind ``heard_s`` beats are given by default. ``beat_in_bar``: per new beat,
    its position in its bar (0 = downbeat) in the metre of ``beats_per_bar`` (see
    the module's notes, step 7); ``metre_confidence``: the confidence of the bar
    count in force (0 until decided).
    """

    beat_times_s: np.ndarray
    intensity_db: np.ndarray
    tempo_bpm: float
    heard_s: float
    extrapolated: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    latency_s: float = LATENCY_S
    beat_in_bar: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    beats_per_bar: int = DEFAULT_BEATS_PER_BAR
    metre_confidence: float = 0.0


class StreamingBeatTracker:
    """Beats of streamed audio, given once sure, never revised (see the module's notes).

    ``sr`` must be 22050 (resample before pushing); ``history_s``: audio analysed
    per update; ``fallback_bpm``: tempo of extrapolated beats before any is known;
    ``latency_s``: how far behind the audio heard ``update()`` gives beats.
    """

    def __init__(self, sr: int = ANALYSIS_SR, *, history_s: float = 16.0, fallback_bpm: float = FALLBACK_BPM,
                 latency_s: float = LATENCY_S):
        if sr != ANALYSIS_SR:
            raise InputError(f"the streaming beat tracker analyses audio at {ANALYSIS_SR} Hz, got sr={sr!r}; "
                             "resample the stream first (dancesynth.io.resampling.resample)")
        if not (np.isfinite(fallback_bpm) and 20.0 <= fallback_bpm <= 400.0):
            raise InputError(f"fallback tempo must be between 20 and 400 bpm, got {fallback_bpm!r}")
        if not (np.isfinite(latency_s) and 0.0 <= latency_s <= 5.0):
            raise InputError(f"latency_s must be between 0 and 5 s, got {latency_s!r}")
        if not (np.isfinite(history_s) and max(6.0, latency_s + 4.0) <= history_s <= 600.0):
            raise InputError(f"history_s must be between {max(6.0, latency_s + 4.0):g} and 600 s, got {history_s!r}")
        self.sr, self.history_s, self.fallback_bpm, self.latency_s = int(sr), history_s, fallback_bpm, latency_s
        # Audio from global sample -_HALF on: the zeros before the stream's start frame the first windows.
        self._audio = Ring(int(round(history_s * sr)) + N_FFT + HOP_LENGTH, start=-_HALF)
        self._audio.append(np.zeros(_HALF, dtype=np.float32))
        # Per frame: the mel power spectrum, and last the sum of squares of its 2048 samples.
        self._mel = Ring(int(round(history_s * FPS)), (N_MELS + 1,))
        # The mel filters as (bin, weight) runs: each band is a few contiguous FFT bins, and
        # a sparse sum needs no BLAS call (whose threads cost more than the work for 5 frames).
        basis = mel_filterbank(sr, N_FFT, n_mels=N_MELS)
        runs = [np.flatnonzero(row) for row in basis]
        self._bins = np.concatenate(runs)
        self._weights = np.concatenate([row[r] for row, r in zip(basis, runs)]).astype(np.float32)
        self._band_starts = np.cumsum([0] + [r.size for r in runs[:-1]])
        self._window = (0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(N_FFT) / N_FFT)).astype(np.float32)
        self._heard, self._ended = 0, False     # samples pushed; flushed
        # The last beat given: time, DP frame (global), whether it was heard on music, its sample edge.
        self._last_s, self._last_real, self._last_edge = -np.inf, False, 0
        # Energy and count of the samples after _last_edge that fell out of the audio buffer.
        self._carry = [0.0, 0]
        self._recent = np.zeros(4)      # the last real beat intervals (s), newest last; 0: none yet
        self._strength = np.zeros(16)   # onset strength of the last real beats given
        self._given = np.full(64, -1, dtype=np.int64)  # DP frames of the last beats given, the last last
        self._gain, self._rephasing = 0.0, False    # the last re-phase comparison; did it re-phase
        self._tempo_bpm, self._loud_db, self._loud_at, self._next_due = 0.0, -np.inf, 0.0, -np.inf
        self._bars = BarCounter()

    @property
    def heard_s(self) -> float:
        return self._heard / self.sr

    def push(self, samples: np.ndarray) -> None:
        """Append mono samples (float, about [-1, 1]); memory stays bounded by ``history_s``."""
        if self._ended:
            raise InputError("the stream was flushed; start a new StreamingBeatTracker for a new stream")
        y = _as_samples(samples)
        for start in range(0, len(y), self._audio.keep - N_FFT):
            piece = y[start:start + self._audio.keep - N_FFT]
            self._audio.append(piece, on_drop=self._dropped)
            self._heard += len(piece)
        # Only now: audio that a long chunk pushed out of the history gets no frames.
        self._compute_frames((self._heard - _HALF) // HOP_LENGTH)

    def _dropped(self, rows: np.ndarray, start: int) -> None:
        """Samples leaving the audio buffer: keep the energy of those after the last beat given."""
        lo = max(self._last_edge - start, 0)
        if lo < len(rows):
            part = rows[lo:].astype(np.float64)
            self._carry[0] += float(np.dot(part, part))
            self._carry[1] += part.size

    def _compute_frames(self, last: int) -> None:
        """Mel power spectra of frames ``self._mel.end .. last`` (their samples are all in the buffer)."""
        first = max(self._mel.end, last - self._mel.keep + 1,
                    -(-(self._audio.start + _HALF) // HOP_LENGTH))
        if last < first:
            return
        if first > self._mel.end:   # a gap: the window starts afresh
            self._mel.size, self._mel.start = 0, first
        audio = self._audio.view()
        offset = first * HOP_LENGTH - _HALF - self._audio.start
        count = last - first + 1
        seg = audio[offset:offset + (count - 1) * HOP_LENGTH + N_FFT]
        frames = np.lib.stride_tricks.as_strided(seg, shape=(count, N_FFT),
                                                 strides=(seg.strides[0] * HOP_LENGTH, seg.strides[0]),
                                                 writeable=False)
        spectrum = np.fft.rfft(frames * self._window, axis=1)
        power = np.square(spectrum.real) + np.square(spectrum.imag)
        cumulative = np.concatenate(([0.0], np.cumsum(np.square(seg, dtype=np.float64))))
        starts = np.arange(count) * HOP_LENGTH
        self._mel.append(np.column_stack((np.add.reduceat(power[:, self._bins] * self._weights, self._band_starts,
                                                          axis=1), cumulative[starts + N_FFT] - cumulative[starts])))

    def envelope(self) -> tuple[np.ndarray, int]:
        """The window's onset envelope and the global index of its first frame.

        Frames equal ``music.onset.onset_envelope`` of the whole stream (up to its 80 dB
        floor, here relative to the window) but the window's first three, which are 0.
        """
        mel = self._mel.view()[:, :N_MELS]
        env = np.zeros(mel.shape[0] + _DELAY - 1, dtype=np.float32)
        if mel.shape[0] >= 2:
            db = power_to_db(mel)
            env[_DELAY:] = np.maximum(db[1:] - db[:-1], 0.0).mean(axis=1, dtype=np.float32)[:env.size - _DELAY]
        if self._ended:     # offline, the envelope ends with the last frame
            env = env[:mel.shape[0]]
        return env, self._mel.start

    def update(self, *, until_s: float | None = None) -> BeatUpdate:
        """The new beats up to ``until_s`` (default: ``heard_s - latency_s``; at most ``heard_s``)."""
        try:
            horizon = self.heard_s - self.latency_s if until_s is None else min(float(until_s), self.heard_s)
        except (TypeError, ValueError):
            horizon = np.nan
        if not np.isfinite(horizon):
            raise InputError(f"until_s must be a finite number of seconds, got {until_s!r}")
        return self._give(horizon)

    def peek(self, until_s: float) -> BeatUpdate:
        """What ``update(until_s=...)`` would give now, without giving it: the tracker stays anchored on the
        beats it was sure of, and a later update gives these (or surer ones) again."""
        probe = copy.copy(self)   # the buffers are only read; the state that giving changes in place is copied
        probe._given, probe._bars = self._given.copy(), copy.deepcopy(self._bars)
        return probe.update(until_s=until_s)

    def flush(self) -> BeatUpdate:
        """The stream ended: the remaining beats up to its end (none on its silent or decaying tail)."""
        if not self._ended:
            self._ended = True
            # The last frames see zeros after the end, as offline.
            self._audio.append(np.zeros(_HALF + HOP_LENGTH, dtype=np.float32), on_drop=self._dropped)
            self._compute_frames(self._heard // HOP_LENGTH)
        return self._give(self.heard_s, final=True)

    def _give(self, horizon: float, final: bool = False) -> BeatUpdate:
        beats, real = self._next_beats(horizon, final)
        keep = beats > self._last_s + 1e-6
        beats, real = beats[keep], real[keep]
        intensity = self._intensity(beats)
        positions = self._bar_positions(beats)
        if beats.size:
            intervals = np.diff(np.concatenate(([self._last_s], beats)))
            heard = real & np.concatenate(([self._last_real], real[:-1])) & np.isfinite(intervals)
            self._recent = np.concatenate((self._recent, intervals[heard]))[-self._recent.size:]
            self._last_s, self._last_real = float(beats[-1]), bool(real[-1])
            frames = np.round((beats + ONSET_LATENCY_S) * FPS).astype(np.int64)
            if self._rephasing:     # compare only the beats given from now on
                self._given[:] = -1
            self._given = np.concatenate((self._given, frames))[-self._given.size:]
        self._rephasing = False
        return BeatUpdate(beats, intensity, float(self._tempo_bpm), self.heard_s, ~real, self.latency_s,
                          positions, self._bars.metre, self._bars.confidence)

    def _bar_positions(self, beats: np.ndarray) -> np.ndarray:
        """Bar positions of the new beats; first the intervals they close join the bar history."""
        if beats.size == 0:
            return np.zeros(0, dtype=np.int64)
        known = np.concatenate(([self._last_s], beats)) if np.isfinite(self._last_s) else beats
        return self._bars.count(self._interval_features(known), beats.size)

    def _interval_features(self, known: np.ndarray) -> np.ndarray:
        """``beat_features`` of the intervals between consecutive ``known`` beats, from the audio buffer.

        The excerpt starts on the offline feature grid, so frames fall where a whole
        recording's would; intervals whose audio left the buffer get NaN.
        """
        rows = np.full((max(known.size - 1, 0), N_FEATURES), np.nan)
        if known.size < 2:
            return rows
        grid = int(round(self.sr * CHROMA_HOP / FEATURE_SR))
        first_s = known[0] - (known[1] - known[0]) / 4.0 - BAR_MARGIN_S
        lo = max(int(np.floor(first_s * self.sr / grid)) * grid, -(-self._audio.start // grid) * grid, 0)
        hi = min(int(np.ceil((known[-1] + BAR_MARGIN_S) * self.sr)), self._heard)
        inside = known[:-1] * self.sr >= lo
        if hi - lo < grid or not inside.any():
            return rows
        excerpt = self._audio.view()[lo - self._audio.start:hi - self._audio.start]
        start = int(np.argmax(inside))
        rows[start:] = beat_features(excerpt, self.sr, beat_times_s=known[start:-1] - lo / self.sr,
                                     end_s=known[-1] - lo / self.sr)
        return rows

    def _period_s(self) -> float:
        known = self._recent[self._recent > 0]
        return float(np.median(known)) if known.size else 60.0 / (self._tempo_bpm or self.fallback_bpm)

    def _next_beats(self, horizon: float, final: bool) -> tuple[np.ndarray, np.ndarray]:
        """New beat times (s, after latency correction) up to ``horizon`` and whether each was heard."""
        # Skip the analysis while no beat can be due: the DP's shortest interval is half a
        # period, and the last analysis saw the next beat later (less DUE_EARLY_PERIODS).
        soonest = min(self._period_s(), 60.0 / self._tempo_bpm if self._tempo_bpm else np.inf)
        if horizon <= max(self._last_s + MIN_GAP_PERIODS * 0.9 * soonest, -np.inf if final else self._next_due):
            return np.zeros(0), np.zeros(0, dtype=bool)
        env, f0 = self.envelope()
        sounding = self._sounding(env.size)
        dead, track = ~sounding, None
        if env.size >= MIN_WINDOW_S * FPS and np.any(env[sounding] > 0):
            track = self._track(env, f0)
        out, real, previous = [], [], self._last_s
        if track is not None:
            frames, period, bpm_now, window_typical = track
            self._tempo_bpm = bpm_now
            times = refine_beat_frames(env, frames) / FPS + f0 / FPS - ONSET_LATENCY_S
            peak = _peak_envelope(env)
            known = self._strength[self._strength > 0]
            typical = float(np.median(known)) if known.size >= 4 else window_typical
            dead |= peak < TRAILING_BEAT_FRACTION * typical
            ok = sounding[frames] & (times <= horizon)
            later = times[times > horizon]
            self._next_due = later[0] - DUE_EARLY_PERIODS * period[-1] if later.size else -np.inf
            strength = peak[frames]
            if final:   # drop the run of last beats on no onset (a final chord's decay), as offline
                weak = strength < TRAILING_BEAT_FRACTION * typical
                ok &= np.arange(weak.size) < weak.size - np.argmin(weak[::-1]) if not weak.all() else False
            times, period, strength = times[ok], period[frames[ok]], strength[ok]
            # Keep intervals within [0.5, 1.5] periods: skip a beat too close, fill a wide gap.
            for t, p, x in zip(times, period, strength):
                if np.isfinite(previous) and t - previous < MIN_GAP_PERIODS * p:
                    continue
                if np.isfinite(previous) and t - previous > MAX_GAP_PERIODS * p:
                    n = max(int(round((t - previous) / p)), 2)
                    out.extend(previous + (t - previous) * np.arange(1, n) / n)
                    real.extend([False] * (n - 1))
                out, real = out + [t], real + [True]
                previous = t
                self._strength = np.concatenate((self._strength[1:], [x]))
        elif env.size < MIN_WINDOW_S * FPS and np.any(sounding):
            return np.zeros(0), np.zeros(0, dtype=bool)     # music has begun, too little to know its tempo
        if not final:
            tail = self._extrapolate(previous, horizon, dead, f0, None if track is None else 60.0 / bpm_now)
            out, real = out + list(tail), real + [False] * len(tail)
        return np.asarray(out, dtype=np.float64), np.asarray(real, dtype=bool)

    def _extrapolate(self, previous: float, horizon: float, dead: np.ndarray, f0: int,
                     period: float | None) -> np.ndarray:
        """A grid after ``previous`` through the silence or onset-less stretch after it, up to ``horizon``.

        At ``period`` (the tempo curve's, which holds through a break), else the last
        intervals'; it stops half a period before the music that the DP will give beats to.
        """
        period = period or self._period_s()
        if not np.isfinite(previous):   # nothing given yet: the grid starts at the stream start
            previous = -period
        first = int(np.ceil((previous + MIN_GAP_PERIODS * period + ONSET_LATENCY_S) * FPS)) - f0
        live = np.flatnonzero(~dead[max(first, 0):])
        limit = horizon
        if live.size:
            limit = min(limit, (max(first, 0) + live[0] + f0) / FPS - ONSET_LATENCY_S - MIN_GAP_PERIODS * period)
        n = int(np.floor((limit - previous) / period + 1e-9))
        return previous + period * np.arange(1, n + 1) if n > 0 else np.zeros(0)

    def _sounding(self, n: int) -> np.ndarray:
        """Per envelope frame (``n``): is the audio around it (2048 samples) above the silence level?"""
        level = rms_db(np.sqrt(self._mel.view()[:n, N_MELS].astype(np.float64) / N_FFT))
        if level.size:
            decayed = self._loud_db - DECAY_DB_PER_S * (self.heard_s - self._loud_at)
            self._loud_db, self._loud_at = max(float(np.percentile(level, 95)), decayed), self.heard_s
        loud = level > max(self._loud_db - SILENCE_BELOW_LOUD_DB, SILENCE_FLOOR_DB)
        return np.pad(loud, (0, n - level.size))

    def _track(self, env: np.ndarray, f0: int):
        """DP beat frames (window indices) after the last given beat, the period (s) per frame, the tempo now."""
        env64 = env.astype(np.float64)
        bpm = tempo_curve(env64, FPS)
        period = np.maximum(60.0 * FPS / bpm, 2.0)
        local = beat_local_score(env64, float(np.median(period)))
        first = _path(local, period)
        factor = metrical_level(env64, first, bpm)
        if np.any(factor != 1.0):
            bpm = bpm * factor
            period = np.maximum(60.0 * FPS / bpm, 2.0)
            local = beat_local_score(env64, float(np.median(period)))
            first = _path(local, period)
        anchor = self._given[-1] - f0
        frames = free = first[first >= np.argmax(local > 0)]
        if self._last_real and 0 <= anchor < env.size - 1:
            frames = _path(local, period, anchor=anchor)
            given = self._given[self._given >= f0][-2 * REPHASE_MIN_BEATS:] - f0
            if given.size >= REPHASE_MIN_BEATS:
                span = free[(free >= given[0] - period[given[0]] / 2) & (free <= anchor + period[anchor] / 4)]
                gain = (_path_score(local, span, period) - _path_score(local, given, period)) / given.size
                self._gain, self._rephasing = gain, gain > REPHASE_GAIN
                frames = free if self._rephasing else frames
        typical = float(np.median(_peak_envelope(env64)[free])) if free.size else 0.0
        return frames, period / FPS, float(bpm[-1]), typical

    def _intensity(self, beats: np.ndarray) -> np.ndarray:
        """Level (dB) of the interval each new beat closes, as ``beat_intensity_db`` measures it."""
        out = np.zeros(beats.size)
        audio, base = self._audio.view(), self._audio.start
        for k, t in enumerate(beats):
            edge = int(np.clip(np.round(t * self.sr), 0, self._heard))
            part = audio[max(self._last_edge, base) - base:max(edge - base, 0)].astype(np.float64)
            energy, count = self._carry[0] + float(np.dot(part, part)), self._carry[1] + part.size
            if edge > base:
                self._carry = [0.0, 0]
            else:   # the whole interval left the buffer before it was asked for: the carried mean
                count = self._carry[1]
            out[k] = rms_db(np.sqrt(energy / max(count, 1)))
            self._last_edge = max(edge, self._last_edge)
        return out

    def memory_bytes(self) -> int:
        """Bytes held by the tracker's arrays (constant over the stream)."""
        arrays = [self._audio.data, self._mel.data, self._bars.rows] + [a for a in vars(self).values()
                                                                        if isinstance(a, np.ndarray)]
        return sum(a.nbytes for a in arrays)


def stream_updates(y: np.ndarray, sr: int = ANALYSIS_SR, *, chunk_s: float = 0.1, update_every_s: float = 5.0,
                   **options) -> list[BeatUpdate]:
    """A recording fed as a stream: pushed in ``chunk_s`` chunks, ``update()`` every ``update_every_s``, ``flush()``.

    Returns every update, the flush last. ``options`` go to ``StreamingBeatTracker``.
    """
    tracker = StreamingBeatTracker(sr, **options)
    y, chunk, due, updates = _as_samples(y), max(int(round(chunk_s * sr)), 1), update_every_s, []
    for start in range(0, len(y), chunk):
        tracker.push(y[start:start + chunk])
        if tracker.heard_s >= due - 1e-9:
            updates.append(tracker.update())
            due += update_every_s
    updates.append(tracker.flush())
    return updates


def stream_beats(y: np.ndarray, sr: int = ANALYSIS_SR, *, chunk_s: float = 0.1, update_every_s: float = 5.0,
                 **options) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What a live dancer would have got from ``stream_updates``, concatenated over the updates:
    ``(beat_times_s, intensity_db, extrapolated)``.
    """
    updates = stream_updates(y, sr, chunk_s=chunk_s, update_every_s=update_every_s, **options)
    return tuple(np.concatenate([getattr(u, name) for u in updates])
                 for name in ("beat_times_s", "intensity_db", "extrapolated"))


def _path(local: np.ndarray, period: np.ndarray, anchor: int | None = None) -> np.ndarray:
    """Ellis' DP beat frames, backtracked from the best frame of the last period; from ``anchor`` when given."""
    start = 0 if anchor is None else anchor
    sub = local[start:].copy()
    if anchor is not None:
        sub[0] = _ANCHOR
    back, cum = _dp(sub, period[start:], TIGHTNESS)
    reach = min(max(int(np.ceil(period[-1])), 1), sub.size)
    i = sub.size - reach + int(np.argmax(cum[-reach:]))
    beats = [i]
    while back[beats[-1]] >= 0:
        beats.append(back[beats[-1]])
    frames = np.asarray(beats[::-1], dtype=np.int64) + start
    if anchor is not None:
        return frames[1:]
    if frames.size > 1:
        # The path's first beat is the first frame whose smoothed onset is noticeable
        # (``_dp``'s start rule), often a frame or two before the onset: move it onto the peak.
        lo = max(frames[0] - 3, 0)
        frames[0] = min(lo + int(np.argmax(local[lo:frames[0] + 4])), frames[1] - 1)
    return frames


def _path_score(local: np.ndarray, frames: np.ndarray, period: np.ndarray) -> float:
    """The DP's objective for a given path: onset score at the beats minus the interval costs."""
    if frames.size == 0:
        return 0.0
    cost = TIGHTNESS * np.log(np.maximum(np.diff(frames), 1) / period[frames[1:]]) ** 2
    return float(local[frames].sum() - cost.sum())


def _as_samples(samples) -> np.ndarray:
    """Samples as a finite float32 1-D array, or ``InputError`` saying what is wrong."""
    a = np.asarray(samples)
    if a.dtype.kind not in "fiub":
        raise InputError(f"audio samples must be real numbers, got an array of dtype {a.dtype}; "
                         "decode the audio to float samples first")
    if a.ndim != 1:
        raise InputError(f"audio samples must be mono, shape (n,), got shape {a.shape}; average the channels first")
    a = a.astype(np.float32, copy=False)
    if not np.all(np.isfinite(a)):
        raise InputError("the audio samples contain NaN or infinite values; clean the signal first")
    return a

"""Metre and downbeats: how many beats make a bar (3 or 4), and which beat is the "1".

The beats come first (``dancesynth.music.beats``); this module only groups them.
Pure functions, arrays in, arrays out:

1. ``beat_features``: per beat, what players do at bar lines, measured on the
   interval from that beat to the next: its chroma (12 pitch classes from 60 Hz to
   1 kHz, log-compressed, from a 2048-point FFT at 12 kHz), the rise of the bass
   band (20-200 Hz: kick and bass notes) at the beat, and the loudness of the
   interval's first half. Each interval's values depend only on the audio around
   it, so a stream (``dancesynth.live.beats``) gets the same numbers as a file.
2. ``bar_cues``: per beat, the harmonic change at it (``harmonic_change``: cosine
   distance between the chroma of the two beats before and the two from it --
   chords change on bar lines), the bass rise and the loudness accent, the last two
   without their slow trend (a 12-beat moving average: 12 holds whole bars of 3
   and of 4), each z-scored over the song.
3. The metre: ``metre_periodicity`` -- how much of the cues' variance the position
   in a bar of 3, or of 4, explains (a waltz's oom-pah-pah repeats every 3 beats,
   a backbeat every 2 and 4). 4 wins unless 3 is clearly better: 2/4 counts as 4
   at the beat level, and 4/4 is the common case.
4. The phase: ``bar_positions``, a Viterbi path through the positions ``0..M-1``
   that counts up one per beat, gains the ``downbeat_activation`` (the weighted
   cues) at every "1" and pays ``SWITCH_COST`` to jump elsewhere (a beat the
   tracker dropped or inserted), so a song keeps one count unless the music
   insists. ``estimate_metre`` does 3 and 4 and says how sure it is.

Degenerate input (fewer than ``MIN_BEATS`` beats, no cues, the steady fallback
grid of ``analyze_music``) gives 4/4 from the first beat with confidence 0.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..io.resampling import resample_blocks
from .onset import ANALYSIS_SR

METRES = (3, 4)
DEFAULT_BEATS_PER_BAR = 4
# Features are measured at 12 kHz: chroma needs nothing above 1 kHz, and the
# 2048-point FFT there resolves 5.9 Hz (a semitone at 100 Hz) at a quarter of the
# cost of the same resolution at 22050 Hz.
FEATURE_SR = 12000
CHROMA_N_FFT, CHROMA_HOP = 2048, 480        # 171 ms windows every 40 ms
# 20 ms windows every 10 ms: onsets stay sharp. Their window is a sine, whose square
# (a Hann) sums to 1 at half overlap: every sample's energy counts alike, so a click
# weighs the same wherever it falls between frames (Hann windows would ripple 3 dB).
ACCENT_N_FFT, ACCENT_HOP = 240, 120
# Level windows start this long before the beat (tracked beats sit within +-10 ms of the attack).
ATTACK_GUARD_S = 0.02
# Bass and chords live below 1 kHz; melody and cymbals above it change with no regard to bar lines.
CHROMA_FMIN_HZ, CHROMA_FMAX_HZ = 60.0, 1000.0
BASS_FMIN_HZ, BASS_FMAX_HZ = 20.0, 200.0
# Levels are dB of 240-point FFT power (a full-scale 100 Hz sine: +39 dB in the bass
# band), floored here so that silence (before the music, between clicks) has no depth
# to rise from: the bundled songs' bass sits at 0 to +30 dB, their full band at -5 to +12 dB.
LEVEL_FLOOR_DB = -30.0
# Columns of ``beat_features``.
CHROMA = slice(0, 12)
BASS = 12
LOUDNESS = 13
N_FEATURES = 14
# Activation weights (z units). Harmonic change is the surest cue: on the generated
# songs its downbeats stand 0.6-1.8 above the other beats (span 2 beats; spans of 3
# or 4 blur the peak). The bass rise (0.0-1.3: high on beat 3 of 4/4 and of 3/4
# too) and the loudness (0.5-2.0) settle the phase where a chord lasts two bars.
HARMONY_SPAN_BEATS = 2
# Mean chroma length (log1p of FFT magnitudes) below which a beat has too little tone for
# its harmony to count: songs measure 3-12 per beat, the silence between clicks 0.07.
TONAL_LEVEL = 1.0
CUE_WEIGHTS = (1.0, 0.5, 0.5)       # harmony, bass, loudness
# Smallest spread (standard deviation) each cue is divided by (cosine distance, dB,
# dB). Songs measure 0.01-0.2, 5-20 dB and 0.7-8 dB; a click track's chroma and bass
# leakage wobble by less than these with the frame grid, and are no accents.
CUE_FLOORS = (0.01, 3.0, 1.0)
DETREND_BEATS = 12
# Viterbi cost of a jump in the bar count (z units of activation): a new phase must
# win about three bars of typical downbeat evidence first. On the generated songs
# 3-8 keep every phase and still follow a beat the tracker inserted at a tempo step
# (2 jumps needlessly; 10 or more stays on the wrong phase for the 12 s before it).
SWITCH_COST = 5.0
# 3 is chosen only when its periodicity beats 4's by this much.
THREE_MARGIN = 0.1
# Confidence reaches 1 at these margins over the runner-up metre (periodicity) and phase (z units).
METRE_MARGIN_FULL = 0.5
PHASE_MARGIN_FULL = 1.0
# Metre by periodicity: windows of 24 beats hold whole bars of 3 and of 4.
PERIODICITY_WINDOW_BEATS = 24
# Fewer beats than three bars of 4 show no metre.
MIN_BEATS = 12
# Samples of the song resampled and framed at a time by ``frame_features`` (3 s at 22050 Hz).
_STREAM_BLOCK = 1 << 16
# Chroma frames projected onto the pitch classes per matrix product, at least: OpenBLAS rounds
# small products (one row: a matrix-vector product) differently from the whole song's.
_MIN_BATCH = 256


def beat_features(y: np.ndarray, sr: int = ANALYSIS_SR, *, beat_times_s, end_s: float | None = None) -> np.ndarray:
    """Per beat interval, the cues of a bar line: ``(B, N_FEATURES)`` float64.

    ``y``: mono samples at ``sr``; ``beat_times_s``: ``(B,)`` increasing, seconds
    from the start of ``y``. Interval ``i`` runs from beat ``i`` to beat ``i + 1``
    (the last to ``end_s``, default one median beat interval later, within ``y``).

    Columns: ``CHROMA`` (12, the interval's mean chroma -- ``log1p`` of the FFT
    magnitude summed per pitch class -- C first; not normalised, so a quiet beat
    weighs little in ``harmonic_change``), ``BASS`` (dB: mean bass-band level in
    the first quarter of the interval minus that in the quarter-interval before the
    beat; NaN where the audio does not reach back that far) and ``LOUDNESS`` (dB:
    mean level of the interval's first half). Levels are of mean power, at least
    ``LEVEL_FLOOR_DB``; their windows start ``ATTACK_GUARD_S`` before the beat.
    """
    y = np.asarray(y, dtype=np.float32)
    if y.ndim != 1:
        raise InputError(f"beat_features needs mono samples of shape (n,), got {y.shape}")
    beats = np.asarray(beat_times_s, dtype=np.float64)
    if beats.ndim != 1 or np.any(np.diff(beats) <= 0):
        raise InputError("beat_times_s must be a one-dimensional, strictly increasing array of seconds")
    out = np.full((beats.size, N_FEATURES), np.nan)
    if beats.size == 0 or y.size == 0:
        return out
    duration_s = y.size / sr
    if end_s is None:
        step = float(np.median(np.diff(beats))) if beats.size > 1 else 0.5
        end_s = beats[-1] + step
    edges = np.minimum(np.append(beats, max(float(end_s), beats[-1])), duration_s)
    chroma, bass, loud = frame_features(y, sr)
    # Only windows wholly inside the interval: one that reaches over a beat would mix
    # in the previous chord, more or less depending on how the frame grid falls.
    half_window_s = CHROMA_N_FFT / 2 / FEATURE_SR
    inner_lo = np.minimum(edges[:-1] + half_window_s, (edges[:-1] + edges[1:]) / 2)
    inner_hi = np.maximum(edges[1:] - half_window_s, inner_lo)
    lo, hi = _frame_span(inner_lo, inner_hi, FEATURE_SR / CHROMA_HOP, len(chroma))
    sums = np.concatenate((np.zeros((1, 12)), np.cumsum(chroma, axis=0, dtype=np.float64)))
    out[:, CHROMA] = (sums[hi] - sums[lo]) / (hi - lo)[:, None]

    fps = FEATURE_SR / ACCENT_HOP
    quarter = (edges[1:] - edges[:-1]) / 4.0
    # The attack goes wholly into the window "after" the beat even when the beat is a
    # few ms late: a short click split by the boundary would make a pattern of its own.
    onset = beats - ATTACK_GUARD_S
    after = _level_db(bass, *_frame_span(onset, onset + quarter, fps, len(bass)))
    before = _level_db(bass, *_frame_span(onset - quarter, onset, fps, len(bass)))
    reaches_back = onset - quarter >= 0
    out[:, BASS] = np.where(reaches_back, after - before, np.nan)
    out[:, LOUDNESS] = _level_db(loud, *_frame_span(onset, onset + 2 * quarter, fps, len(loud)))
    return out


def frame_features(y: np.ndarray, sr: int = ANALYSIS_SR, *, block: int = _STREAM_BLOCK
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The frame-level cues ``beat_features`` sums over beats: ``(chroma, bass, loud)``.

    ``chroma``: ``(frames, 12)`` float32 every ``CHROMA_HOP`` samples at ``FEATURE_SR``
    (``log1p`` of the FFT magnitude summed per pitch class); ``bass`` and ``loud``:
    the bass-band sum and the mean of the power spectrum, every ``ACCENT_HOP``
    samples. ``y`` (mono at ``sr``) is resampled to ``FEATURE_SR`` and framed as it
    streams, ``block`` samples at a time (soxr's stream resampler gives the same
    samples as resampling the whole signal): memory is a block, not a copy of the song.
    """
    y = np.asarray(y)
    chroma_frames = _Framer(CHROMA_N_FFT, CHROMA_HOP)
    accent_frames = _Framer(ACCENT_N_FFT, ACCENT_HOP, sine=True)
    weights = _chroma_weights(FEATURE_SR, CHROMA_N_FFT)
    freqs = np.fft.rfftfreq(ACCENT_N_FFT, 1.0 / FEATURE_SR)
    band = (freqs >= BASS_FMIN_HZ) & (freqs <= BASS_FMAX_HZ)
    chroma, bass, loud = [], [], []
    pending = []     # magnitude spectra not yet projected onto the pitch classes

    def take(new_chroma, new_accent, last=False):
        pending.append(np.sqrt(new_chroma))
        rows = sum(len(m) for m in pending)
        # Projected in batches of at least _MIN_BATCH frames (or all of a short song at once):
        # BLAS rounds a one-row product differently, and every frame should get the numbers it
        # gets when the whole song is projected in one product.
        if rows >= 2 * _MIN_BATCH or (last and rows):
            mags = np.concatenate(pending)
            keep = 0 if last else _MIN_BATCH
            chroma.append(np.log1p(mags[:len(mags) - keep] @ weights))
            pending[:] = [mags[len(mags) - keep:]]
        if len(new_accent):
            bass.append(new_accent[:, band].sum(axis=1))
            loud.append(new_accent.mean(axis=1))

    pieces = (y[start:start + block] for start in range(0, len(y), block))
    for piece in resample_blocks(pieces, int(sr), FEATURE_SR):
        take(chroma_frames.push(piece), accent_frames.push(piece))
    take(chroma_frames.finish(), accent_frames.finish(), last=True)
    empty = np.zeros(0, dtype=np.float32)
    return (np.concatenate(chroma) if chroma else np.zeros((0, 12), dtype=np.float32),
            np.concatenate(bass) if bass else empty, np.concatenate(loud) if loud else empty)


class _Framer:
    """Power spectra of a signal that arrives in blocks: frames of ``n_fft`` samples centred on
    samples ``0, hop, 2 hop, ...`` (the signal zero-padded by ``n_fft // 2`` at both ends), as
    ``_power_spectrogram`` gives them for the whole signal, row for row."""

    def __init__(self, n_fft: int, hop: int, *, sine: bool = False):
        self.n_fft, self.hop, self.sine = n_fft, hop, sine
        self._buf = np.zeros(n_fft // 2, dtype=np.float32)   # the left padding
        self._start = 0        # position of _buf[0] in the padded signal
        self._next = 0         # the next frame to give
        self._n = 0            # samples pushed

    def push(self, samples: np.ndarray) -> np.ndarray:
        """The power spectra ``(frames, bins)`` of the frames ``samples`` completed."""
        self._n += len(samples)
        self._buf = np.concatenate((self._buf, np.asarray(samples, dtype=np.float32)))
        end = self._start + len(self._buf)
        count = max(0, (end - self.n_fft) // self.hop + 1 - self._next)
        return self._spectra(count)

    def finish(self) -> np.ndarray:
        """The spectra of the frames that reach into the right padding."""
        self._buf = np.concatenate((self._buf, np.zeros(self.n_fft // 2, dtype=np.float32)))
        return self._spectra(1 + self._n // self.hop - self._next)

    def _spectra(self, count: int) -> np.ndarray:
        first = self._next * self.hop - self._start
        if count <= 0:
            out = np.zeros((0, self.n_fft // 2 + 1), dtype=np.float32)
        else:
            out = _power_spectrogram(self._buf[first:first + (count - 1) * self.hop + self.n_fft], self.n_fft,
                                     self.hop, sine=self.sine, centred=False)
            self._next += count
            first += count * self.hop
        self._buf = self._buf[first:].copy()
        self._start += first
        return out


def bar_cues(features: np.ndarray) -> np.ndarray:
    """Per beat, the three cues of a bar line, ``(B, 3)``: harmonic change, bass rise, loudness.

    ``features``: ``(B, N_FEATURES)`` from ``beat_features``. The harmonic change at
    beat ``b`` is ``harmonic_change`` of the chroma (span ``HARMONY_SPAN_BEATS``); the
    bass rise and loudness have their ``DETREND_BEATS`` moving average removed (a
    crescendo is not an accent). Each cue is z-scored over the beats (see ``_zscore``;
    its spread is at least ``CUE_FLOORS``); missing values are 0.
    """
    features = np.asarray(features, dtype=np.float64)
    if features.ndim != 2 or features.shape[1] != N_FEATURES:
        raise InputError(f"features must have shape (beats, {N_FEATURES}) as beat_features returns, "
                         f"got {features.shape}")
    harmony = harmonic_change(features[:, CHROMA], span=HARMONY_SPAN_BEATS)
    bass = features[:, BASS] - _moving_mean(features[:, BASS], DETREND_BEATS)
    loudness = features[:, LOUDNESS] - _moving_mean(features[:, LOUDNESS], DETREND_BEATS)
    return np.column_stack([_zscore(harmony, CUE_FLOORS[0]), _zscore(bass, CUE_FLOORS[1]),
                            _zscore(loudness, CUE_FLOORS[2])])


def downbeat_activation(cues: np.ndarray) -> np.ndarray:
    """Per beat, evidence that it is a bar's first beat: ``cues @ CUE_WEIGHTS`` (z units, about mean 0).

    ``cues``: ``(B, 3)`` from ``bar_cues``.
    """
    return np.asarray(cues, dtype=np.float64) @ np.asarray(CUE_WEIGHTS)


def metre_periodicity(cues: np.ndarray, beats_per_bar: int, *, window_beats: int = PERIODICITY_WINDOW_BEATS
                      ) -> float:
    """How much of the cues' variance the position in a ``beats_per_bar`` bar explains, above chance.

    In windows of ``window_beats`` beats (hop half that), each cue's variance between
    the positions (the one-way analysis of variance with the positions as groups)
    minus what chance gives, ``(M - 1) / (n - 1)`` of its variance; averaged over
    windows, summed over cues. In the cues' z units (``bar_cues``), so a cue held
    small by its floor (a click track's 2 dB of bass leakage) counts little however
    regular. It does not depend on which position is the downbeat, only on the bar
    repeating, and the windows let a dropped beat spoil only its own. A 4/4 song
    scores for 4 (its kick-snare pattern repeats every 2 and 4 beats), not for 3; a
    waltz the other way round.
    """
    x = np.nan_to_num(np.asarray(cues, dtype=np.float64))
    if x.ndim == 1:
        x = x[:, None]
    m = int(beats_per_bar)
    n_beats = x.shape[0]
    win = min(int(window_beats), n_beats)
    if win < 2 * m:
        return 0.0
    scores = []
    for start in range(0, n_beats - win + 1, max(win // 2, 1)):
        w = x[start:start + win]
        w = w - w.mean(axis=0)
        total = np.sum(w * w, axis=0)
        pos = np.arange(win) % m
        means = np.stack([w[pos == p].mean(axis=0) for p in range(m)])
        counts = np.bincount(pos, minlength=m)[:, None]
        explained = np.sum(counts * means * means, axis=0)
        scores.append(np.sum(explained - total * (m - 1) / (win - 1)) / win)
    return float(np.mean(scores)) if scores else 0.0


def harmonic_change(chroma: np.ndarray, *, span: int = HARMONY_SPAN_BEATS,
                    tonal_level: float = TONAL_LEVEL) -> np.ndarray:
    """Cosine distance between the chroma of the ``span`` beats before each beat and the ``span`` from it.

    Near the ends fewer beats are summed; the first beat (nothing before it) is NaN.
    Where either side's mean chroma is shorter than ``tonal_level`` (``beat_features``
    units) the distance is scaled down in proportion: the chroma of near silence (a
    click track between its clicks) points anywhere.
    """
    c = np.nan_to_num(np.asarray(chroma, dtype=np.float64))
    n = len(c)
    sums = np.concatenate((np.zeros((1, c.shape[1])), np.cumsum(c, axis=0)))
    idx = np.arange(n)
    start, stop = np.maximum(idx - span, 0), np.minimum(idx + span, n)
    before, after = sums[idx] - sums[start], sums[stop] - sums[idx]
    norm_before, norm_after = np.linalg.norm(before, axis=1), np.linalg.norm(after, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        change = 1.0 - np.sum(before * after, axis=1) / (norm_before * norm_after)
        level = np.minimum(norm_before / (idx - start), norm_after / (stop - idx))
    change = change * np.clip(level / tonal_level, 0.0, 1.0)
    return np.where(norm_before * norm_after > 1e-12, change, np.nan)


def bar_positions(activation: np.ndarray, *, beats_per_bar: int,
                  switch_cost: float = SWITCH_COST) -> tuple[np.ndarray, float]:
    """Each beat's position in its bar (0 = downbeat) by a Viterbi path, and the path's score.

    The count goes up by one per beat (mod ``beats_per_bar``) for free; any other
    step costs ``switch_cost``. A beat at position 0 scores its ``activation``.
    Among equally good paths, the one that starts at 0 on the first beat (so no
    evidence at all counts from the first beat).
    """
    a = np.nan_to_num(np.asarray(activation, dtype=np.float64))
    m = int(beats_per_bar)
    if m < 1:
        raise InputError(f"beats_per_bar must be a positive whole number, got {beats_per_bar!r}")
    n = a.size
    if n == 0:
        return np.zeros(0, dtype=np.int64), 0.0
    gain = np.zeros((n, m))
    gain[:, 0] = a
    # transition[to, from]: 0 for from + 1 == to (mod m), else -switch_cost.
    transition = np.full((m, m), -float(switch_cost))
    transition[(np.arange(m) + 1) % m, np.arange(m)] = 0.0
    score = gain[0].copy()
    back = np.zeros((n, m), dtype=np.int64)
    for b in range(1, n):
        candidates = score[None, :] + transition
        back[b] = np.argmax(candidates, axis=1)
        score = candidates[np.arange(m), back[b]] + gain[b]
    path = np.empty(n, dtype=np.int64)
    # Among equal ends, the one whose count started at 0 on the first beat.
    ends = np.roll(np.arange(m), -((n - 1) % m))
    path[-1] = int(ends[np.argmax(score[ends])])
    best = float(score[path[-1]])
    for b in range(n - 1, 0, -1):
        path[b - 1] = back[b, path[b]]
    return path, best


def estimate_metre(features: np.ndarray | None = None, *, cues: np.ndarray | None = None,
                   switch_cost: float = SWITCH_COST, min_beats: int = MIN_BEATS) -> tuple[int, np.ndarray, float]:
    """Beats per bar (3 or 4), each beat's position in its bar, and a confidence in [0, 1].

    Give the ``features`` of ``beat_features`` or their ``cues`` (``bar_cues``).
    The metre is the one whose bar the cues repeat with (``metre_periodicity``): 3
    only when it beats 4 by ``THREE_MARGIN``. The positions are ``bar_positions`` of
    the ``downbeat_activation``. The confidence is the smaller of the metre's
    periodicity margin over the other metre (1 at ``METRE_MARGIN_FULL``) and the
    phase margin (1 at ``PHASE_MARGIN_FULL``): the downbeats' activation contrast
    (mean at the downbeats minus mean at the other beats, less ``switch_cost`` per
    jump spread over the downbeats) over that of the best other phase held throughout.
    Fewer than ``min_beats`` beats, or no cues at all: ``(4, positions from 0, 0.0)``.
    """
    if cues is None:
        if features is None:
            raise InputError("estimate_metre needs the beat features= or their cues=")
        cues = bar_cues(features)
    cues = np.nan_to_num(np.asarray(cues, dtype=np.float64))
    if cues.ndim != 2:
        raise InputError(f"cues must have shape (beats, cues), got {cues.shape}")
    n = cues.shape[0]
    if n < max(int(min_beats), 2 * max(METRES)) or not np.any(cues):
        return DEFAULT_BEATS_PER_BAR, default_positions(n), 0.0
    periodicity = {m: metre_periodicity(cues, m) for m in METRES}
    m = 3 if periodicity[3] > periodicity[4] + THREE_MARGIN else 4
    other = 4 if m == 3 else 3
    a = downbeat_activation(cues)
    path, _ = bar_positions(a, beats_per_bar=m, switch_cost=switch_cost)
    down = path == 0
    jumps = int(np.count_nonzero(np.diff(path) % m != 1))
    contrast = _contrast(a, down) - switch_cost * jumps / max(int(down.sum()), 1)
    # The runner-up: the best constant phase other than the one the path ends in.
    phase_end = int((path[-1] - (n - 1)) % m)
    others = [_contrast(a, (np.arange(n) + p) % m == 0) for p in range(m) if p != phase_end]
    metre_margin = (periodicity[m] - periodicity[other]) / METRE_MARGIN_FULL
    phase_margin = (contrast - max(others)) / PHASE_MARGIN_FULL
    return m, path, float(np.clip(min(metre_margin, phase_margin), 0.0, 1.0))


def track_metre(y: np.ndarray, sr: int = ANALYSIS_SR, *, beat_times_s, end_s: float | None = None,
                steady_grid: bool = False) -> tuple[int, np.ndarray, float]:
    """``estimate_metre`` of ``beat_features``: ``(beats_per_bar, beat_in_bar, confidence)``.

    ``steady_grid=True`` (the beats are ``analyze_music``'s fallback grid, heard on
    no pulse) skips the analysis: 4/4 from the first beat, confidence 0.
    """
    beats = np.asarray(beat_times_s, dtype=np.float64)
    if steady_grid or beats.size < MIN_BEATS:
        return DEFAULT_BEATS_PER_BAR, default_positions(beats.size), 0.0
    return estimate_metre(beat_features(y, sr, beat_times_s=beats, end_s=end_s))


def default_positions(n_beats: int, beats_per_bar: int = DEFAULT_BEATS_PER_BAR) -> np.ndarray:
    """Bar positions counted from the first beat: ``0, 1, ..., beats_per_bar - 1, 0, ...``."""
    return np.arange(int(n_beats), dtype=np.int64) % int(beats_per_bar)


def _contrast(a: np.ndarray, down: np.ndarray) -> float:
    """Mean of ``a`` where ``down`` minus its mean elsewhere (0 when either side is empty)."""
    if not down.any() or down.all():
        return 0.0
    return float(a[down].mean() - a[~down].mean())


def _zscore(x: np.ndarray, floor: float) -> np.ndarray:
    """``(x - mean) / max(std, floor)`` after clipping to the 5th-95th percentiles; NaN gives 0.

    The clipping keeps one odd beat (the silence after the last) from flattening the
    rest; the floor keeps variation too small to mean anything (a click track's
    chroma) from being blown up to the size of a real cue.
    """
    x = np.asarray(x, dtype=np.float64)
    ok = np.isfinite(x)
    if ok.sum() < 2:
        return np.zeros_like(x)
    lo, hi = np.percentile(x[ok], [5.0, 95.0])
    clipped = np.clip(np.where(ok, x, 0.0), lo, hi)
    return np.where(ok, (clipped - clipped[ok].mean()) / max(clipped[ok].std(), floor), 0.0)


def _moving_mean(x: np.ndarray, width: int) -> np.ndarray:
    """Centred moving mean over ``width`` values, ignoring NaN (shorter at the ends)."""
    x = np.asarray(x, dtype=np.float64)
    ok = np.isfinite(x)
    sums = np.concatenate(([0.0], np.cumsum(np.where(ok, x, 0.0))))
    counts = np.concatenate(([0], np.cumsum(ok)))
    idx = np.arange(x.size)
    lo, hi = np.maximum(idx - width // 2, 0), np.minimum(idx + width - width // 2, x.size)
    n = counts[hi] - counts[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, (sums[hi] - sums[lo]) / n, np.nan)


def _power_spectrogram(y: np.ndarray, n_fft: int, hop: int, *, sine: bool = False,
                       centred: bool = True) -> np.ndarray:
    """Power spectra of frames centred on samples ``0, hop, 2 hop, ...``, ``(frames, bins)``.

    Periodic Hann window, or with ``sine`` its square root (a sine arch). With
    ``centred=False`` the frames start at those samples instead (``y`` is padded already).
    """
    if centred:
        padded = np.pad(np.asarray(y, dtype=np.float32), n_fft // 2)
        n_frames = 1 + len(y) // hop
    else:
        padded = np.asarray(y, dtype=np.float32)
        n_frames = 1 + (len(y) - n_fft) // hop
    frames = np.lib.stride_tricks.sliding_window_view(padded, n_fft)[::hop][:n_frames]
    arch = np.sin(np.pi * np.arange(n_fft) / n_fft)
    window = (arch if sine else arch * arch).astype(np.float32)
    spectrum = np.fft.rfft(frames * window, axis=1)
    return (np.square(spectrum.real) + np.square(spectrum.imag)).astype(np.float32)


def _chroma_weights(sr: float, n_fft: int) -> np.ndarray:
    """``(bins, 12)``: each FFT bin in the chroma range to its pitch class, weighted by how near a semitone it is."""
    freqs = np.fft.rfftfreq(n_fft, 1.0 / sr)
    weights = np.zeros((freqs.size, 12), dtype=np.float32)
    used = np.flatnonzero((freqs >= CHROMA_FMIN_HZ) & (freqs <= CHROMA_FMAX_HZ))
    midi = 12.0 * np.log2(freqs[used] / 440.0) + 69.0
    nearest = np.round(midi)
    weights[used, nearest.astype(np.int64) % 12] = np.clip(1.0 - 2.0 * np.abs(midi - nearest), 0.0, 1.0)
    return weights


def _frame_span(start_s, stop_s, fps: float, n_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Frames whose centres fall in ``[start_s, stop_s)``, as ``lo, hi`` index arrays with at least one frame."""
    lo = np.clip(np.ceil(np.asarray(start_s) * fps - 1e-9).astype(np.int64), 0, n_frames - 1)
    hi = np.clip(np.ceil(np.asarray(stop_s) * fps - 1e-9).astype(np.int64), 0, n_frames)
    return lo, np.maximum(hi, lo + 1)


def _level_db(power: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """dB of the mean of ``power[lo:hi]`` for every pair, floored at ``LEVEL_FLOOR_DB`` (one cumulative sum)."""
    sums = np.concatenate(([0.0], np.cumsum(power, dtype=np.float64)))
    return 10.0 * np.log10(np.maximum((sums[hi] - sums[lo]) / (hi - lo), 10.0 ** (LEVEL_FLOOR_DB / 10.0)))

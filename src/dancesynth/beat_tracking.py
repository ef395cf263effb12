"""Beat tracking by dynamic programming in plain numpy: Ellis' (2007) tracker and a tempo-following variant.

``dp_beat_track(onset_env, fps)`` works on any onset-strength envelope at any
frame rate -- audio onsets at 50 fps (``dancesynth.music``) and motion onsets at
60 fps (``dancesynth.motion.beats``) -- so it sits below both layers:

1. ``estimate_tempo``: the global tempo is the lag that maximises the mean
   autocorrelation of 8 s windows of the envelope plus a log-normal prior on the
   tempo (centre ``start_bpm``, ``std_bpm`` octaves), refined between lags by a
   parabola through the peak.
2. A local score: the envelope (divided by its standard deviation) smoothed by a
   Gaussian of standard deviation ``period / 32``.
3. The dynamic program: ``score[t] = local[t] + max_tau (score[tau] - tightness *
   log((t - tau) / period)**2)`` over ``tau`` in ``[t - 2 period, t - period / 2]``,
   and backtracking from the last peak of ``score`` that reaches half the
   median of its peaks.

``dp_beat_track_varying`` (the product's default for music) lets the tempo change:

4. ``tempo_curve``: a tempogram of 8 s windows every 0.25 s, each tempo scored by
   the autocorrelation at 1, 2 and 3 of its beat periods, and a Viterbi path
   through it that pays per octave of tempo change -- so it follows steps and
   ramps but not syncopation.
5. The same DP with a period per frame, then ``metrical_level``: where the onsets
   half-way between beats are as strong as on them the tempo is doubled, where
   every other beat is much weaker it is halved, and the DP runs again.

``dp_beat_track`` follows librosa's ``beat_track`` step for step (same tempogram, prior, local
score, transition cost, first-beat and last-beat rules) but imports no numba: the
DP is vectorised over blocks of ``period / 2`` frames, which depend only on
earlier blocks, so a 3-minute song takes a few hundred small numpy operations.
The difference to librosa: the tempo (and so the DP period) is not rounded to
whole frames.
"""

from __future__ import annotations

import numpy as np
from .errors import InputError

# librosa's defaults: an 8 s autocorrelation window, tempi up to 320 bpm.
AC_WINDOW_S = 8.0
MAX_BPM = 320.0
# The tempogram's windows advance by this fraction of the window: their mean
# barely changes from a hop of one frame (librosa's) and costs 1/25 as much.
_TEMPOGRAM_HOP_FRACTION = 1.0 / 25
# Autocorrelation windows transformed at a time (memory: ~60 kB a window at 50 fps).
_ACF_ROWS = 128


def estimate_tempo(onset_env: np.ndarray, fps: float, *, start_bpm: float = 120.0, std_bpm: float = 1.0,
                   ac_window_s: float = AC_WINDOW_S, max_bpm: float = MAX_BPM) -> float:
    """Global tempo (bpm) of an onset envelope sampled at ``fps`` frames per second.

    The envelope is cut into Hann-windowed ``ac_window_s`` windows (centred on
    frames, the ends ramped to zero, as librosa's ``tempogram``); each window's
    autocorrelation is divided by its value at lag 0 and the windows are averaged.
    The tempo maximises ``log(mean autocorrelation) + log prior``, the prior
    ``-0.5 * (log2(bpm / start_bpm) / std_bpm)**2``, over lags whose tempo is below
    ``max_bpm``; the best lag is refined to a fraction of a frame by a parabola.
    Returns 0 for an envelope without onsets.
    """
    env = np.asarray(onset_env, dtype=np.float64)
    if env.size == 0 or not np.any(env > 0):
        return 0.0
    win = max(int(ac_window_s * fps), 4)
    acf = window_autocorrelation(env, win, max(1, int(round(win * _TEMPOGRAM_HOP_FRACTION))))[0].mean(axis=0)

    lags = np.arange(win, dtype=np.float64)
    with np.errstate(divide="ignore"):
        bpm = 60.0 * fps / lags
        score = np.log1p(1e6 * np.maximum(acf, 0.0)) - 0.5 * (np.log2(bpm / start_bpm) / std_bpm) ** 2
    score[bpm >= max_bpm] = -np.inf
    best = int(np.argmax(score))
    if not np.isfinite(score[best]) or best == 0:
        return 0.0
    lag = float(best)
    if 0 < best < win - 1 and np.all(np.isfinite(score[best - 1:best + 2])):
        left, mid, right = score[best - 1:best + 2]
        curvature = left - 2.0 * mid + right
        if curvature < 0:
            lag += float(np.clip(0.5 * (left - right) / curvature, -0.5, 0.5))
    return float(60.0 * fps / lag)


def window_autocorrelation(env: np.ndarray, win: int, hop: int) -> tuple[np.ndarray, np.ndarray]:
    """Autocorrelation of Hann windows of ``win`` frames every ``hop`` frames.

    Windows are centred on frames ``0, hop, 2 hop, ...``; the envelope is ramped to
    zero beyond its ends (as librosa's ``tempogram``). Returns the autocorrelation at
    lags ``0..win-1`` divided by its value at lag 0 (all 0 for a window without
    onsets), and that lag-0 value (the window's onset energy).
    """
    blocks = list(window_autocorrelation_blocks(env, win, hop))
    if len(blocks) == 1:
        return blocks[0][1:]
    return np.concatenate([b[1] for b in blocks]), np.concatenate([b[2] for b in blocks])


def window_autocorrelation_blocks(env: np.ndarray, win: int, hop: int, *, rows: int = _ACF_ROWS):
    """``window_autocorrelation`` a block of ``rows`` windows at a time: yields ``(first window,
    acf, lag-0 value)``, row for row the same numbers, in memory for one block (a 30-minute song
    has 7,200 windows: 140 MB of spectra at once)."""
    env = np.asarray(env, dtype=np.float64)
    n = env.size
    half = win // 2
    padded = np.concatenate((np.linspace(0.0, env[0], half, endpoint=False), env,
                             np.linspace(env[-1], 0.0, half + 1)[1:]))
    starts = np.arange(0, n, hop)
    window = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(win) / win)
    n_fft = 1 << int(np.ceil(np.log2(2 * win - 1)))
    for first in range(0, starts.size, rows):
        frames = padded[starts[first:first + rows, None] + np.arange(win)[None, :]] * window
        spectrum = np.fft.rfft(frames, n_fft, axis=1)
        acf = np.fft.irfft(spectrum.real ** 2 + spectrum.imag ** 2, n_fft, axis=1)[:, :win]
        norm = acf[:, :1]
        yield first, np.where(norm > 1e-20, acf / np.maximum(norm, 1e-20), 0.0), norm[:, 0]


def tempo_curve(onset_env: np.ndarray, fps: float, *, window_s: float = 8.0, hop_s: float = 0.25,
                min_bpm: float = 40.0, max_bpm: float = 240.0, bins_per_octave: int = 48,
                start_bpm: float = 120.0, std_bpm: float = 1.0, change_cost: float = 4.0,
                harmonics: int = 3, smooth_s: float = 1.0) -> np.ndarray:
    """Local tempo (bpm) at every frame of an onset envelope: a Viterbi path through a tempogram.

    Every ``hop_s`` a Hann window of ``window_s`` gives an autocorrelation; its
    value at the lag of each tempo of a log-spaced grid (``bins_per_octave``
    between ``min_bpm`` and ``max_bpm``), divided by the window's largest, scores
    that tempo. The path maximises the summed scores plus the log-normal tempo
    prior of ``estimate_tempo`` minus ``change_cost`` per octave of tempo change
    between windows, so the tempo may step or ramp but does not flicker between
    metrical levels. Windows with less onset energy than the song's median count
    less (in proportion), so a fade-out or a break holds the tempo instead of
    drifting to the prior's centre. The path is interpolated (in log tempo) to
    every frame.
    """
    env = np.asarray(onset_env, dtype=np.float64)
    n = env.size
    win = max(int(window_s * fps), 8)
    hop = max(1, int(round(hop_s * fps)))
    n_windows = len(range(0, n, hop))
    energy = np.empty(n_windows)
    n_bins = int(np.floor(bins_per_octave * np.log2(max_bpm / min_bpm))) + 1
    grid = min_bpm * 2.0 ** (np.arange(n_bins) / bins_per_octave)
    lags = 60.0 * fps / grid
    keep = harmonics * lags < win - 1
    grid, lags = grid[keep], lags[keep]
    # A tempo's evidence is the autocorrelation at 1..harmonics beat periods: a
    # syncopated figure repeats with the bar, not with its own odd intervals.
    obs = np.zeros((n_windows, grid.size))
    for first, acf, norm in window_autocorrelation_blocks(env, win, hop):
        acf = np.maximum(acf, 0.0)
        rows = slice(first, first + len(acf))
        energy[rows] = norm
        for k in range(1, harmonics + 1):
            lo = np.floor(k * lags).astype(np.int64)
            frac = k * lags - lo
            obs[rows] += acf[:, lo] * (1.0 - frac) + acf[:, lo + 1] * frac
    obs /= harmonics
    sounding = energy[energy > 1e-20]
    weight = np.clip(energy / np.median(sounding), 0.0, 1.0) if sounding.size else np.zeros_like(energy)
    # One scale for the whole song: a window whose periodicity is weak (a break, a
    # fill) has little say against the cost of changing tempo.
    peaks = obs.max(axis=1)
    obs /= max(float(np.median(peaks[peaks > 0])) if np.any(peaks > 0) else 1.0, 1e-12)
    prior = -0.5 * (np.log2(grid / start_bpm) / std_bpm) ** 2
    octaves = np.abs(np.subtract.outer(np.arange(grid.size), np.arange(grid.size))) / bins_per_octave
    transition = -change_cost * octaves
    gain = obs                                         # in place: weight * (obs + prior)
    gain += prior[None, :]
    gain *= weight[:, None]
    score = gain[0]
    back = np.zeros((len(obs), grid.size), dtype=np.int16 if grid.size < 2 ** 15 else np.int64)
    for w in range(1, len(obs)):
        candidates = score[None, :] + transition       # [to, from]
        back[w] = np.argmax(candidates, axis=1)
        score = candidates[np.arange(grid.size), back[w]] + gain[w]
    path = np.empty(len(obs), dtype=np.int64)
    path[-1] = int(np.argmax(score))
    for w in range(len(obs) - 1, 0, -1):
        path[w - 1] = back[w, path[w]]
    # A tempo between two grid steps makes the path flicker between them: average
    # the log tempo over ``smooth_s`` (ramps are unchanged, steps take that long).
    log_path = np.log2(grid[path])
    reach = int(round(smooth_s / hop_s / 2))
    if reach > 0 and log_path.size > 1:
        padded = np.pad(log_path, reach, mode="edge")
        log_path = np.convolve(padded, np.ones(2 * reach + 1) / (2 * reach + 1), mode="valid")
    centres = np.arange(len(obs)) * hop
    return 2.0 ** np.interp(np.arange(n), centres, log_path)


def beat_local_score(onset_env: np.ndarray, period: float) -> np.ndarray:
    """The envelope over its standard deviation, smoothed by a Gaussian of std ``period / 32`` frames."""
    env = np.asarray(onset_env, dtype=np.float64)
    norm = env.std(ddof=1) if env.size > 1 else 0.0
    env = env / (norm + np.finfo(np.float64).tiny)
    reach = int(np.ceil(period))
    kernel = np.exp(-0.5 * (np.arange(-reach, reach + 1) * 32.0 / period) ** 2)
    full = np.convolve(env, kernel)
    return full[reach:reach + env.size]


def dp_beat_track(onset_env: np.ndarray, fps: float, *, start_bpm: float = 120.0, tightness: float = 100.0,
                  std_bpm: float = 1.0, bpm: float | None = None) -> tuple[np.ndarray, float]:
    """Beats of an onset-strength envelope by Ellis' dynamic programming.

    Parameters
    ----------
    onset_env : (n,) non-negative onset strength, one value per frame
    fps : frames per second of ``onset_env``
    start_bpm, std_bpm : centre (bpm) and width (octaves) of the log-normal tempo prior
    tightness : how strongly beat intervals are held to the tempo (librosa's 100)
    bpm : use this tempo instead of estimating it

    Returns
    -------
    beat_frames : (B,) int64, increasing frame indices of the beats over the whole
        envelope (only beats before the first / after the last onset are dropped)
    tempo_bpm : the global tempo the beats were tracked at (0 when the envelope
        has no onsets; then there are no beats)
    """
    env = np.asarray(onset_env, dtype=np.float64)
    if env.ndim != 1:
        raise InputError(f"onset_env must be one-dimensional, got shape {env.shape}")
    if not (fps > 0 and tightness > 0 and start_bpm > 0 and std_bpm > 0):
        raise InputError("fps, tightness, start_bpm and std_bpm must be positive")
    if bpm is None:
        bpm = estimate_tempo(env, fps, start_bpm=start_bpm, std_bpm=std_bpm)
    if not (bpm > 0) or env.size < 2 or not np.any(env > 0):
        return np.zeros(0, dtype=np.int64), 0.0
    return _track_with_curve(env, fps, np.float64(bpm), tightness), float(bpm)


# Metrical-level check (``metrical_level``): on the generated ground-truth songs
# the onset strength half-way between true beats is 0.01-0.30 of that on the
# beats, and 0.8-1.1 when only every other beat is tracked; every other true beat
# has 0.78-1.0 of its neighbours' strength, and the off-beats of eighth notes
# 0.01-0.30. Loud hi-hat eighths raise the half-way strength to 0.76 (the test
# drum loop) and real songs measure 0.12-0.48 and 0.52-0.93, so doubling needs
# more than 0.9: when unsure, the slower level is kept.
DOUBLE_ABOVE = 0.9
HALVE_BELOW = 0.3
LEVEL_BPM_RANGE = (50.0, 200.0)
LEVEL_SPAN_BEATS = 16


def dp_beat_track_varying(onset_env: np.ndarray, fps: float, *, tightness: float = 100.0,
                          check_level: bool = True, **tempo_options) -> tuple[np.ndarray, np.ndarray]:
    """Beats of an onset envelope whose tempo may change: ``tempo_curve`` then Ellis' DP with a period per frame.

    With ``check_level`` the beats are tracked again at twice or half the tempo
    when ``metrical_level`` says the first pass counted every other beat or every
    off-beat. Returns ``(beat_frames, bpm_per_frame)``; no beats when the envelope
    has no onsets.
    """
    env = np.asarray(onset_env, dtype=np.float64)
    if env.ndim != 1:
        raise InputError(f"onset_env must be one-dimensional, got shape {env.shape}")
    if env.size < 2 or not np.any(env > 0):
        return np.zeros(0, dtype=np.int64), np.zeros(env.size)
    bpm = tempo_curve(env, fps, **tempo_options)
    frames = _track_with_curve(env, fps, bpm, tightness)
    if check_level:
        factor = metrical_level(env, frames, bpm)
        if np.any(factor != 1.0):
            bpm = bpm * factor
            frames = _track_with_curve(env, fps, bpm, tightness)
    return frames, bpm


def metrical_level(onset_env: np.ndarray, beat_frames: np.ndarray, bpm: np.ndarray, *,
                   span_beats: int = LEVEL_SPAN_BEATS) -> np.ndarray:
    """Per frame: 2 where the beats skip every other beat, 0.5 where they count off-beats too, else 1.

    Over a sliding span of ``span_beats`` beats it compares the onset strength
    (max over +-1 frame) half-way between beats with that on the beats (strong in
    between: the pulse is twice as fast), and that of every other beat with its
    neighbours' (much weaker: those are off-beats). The new tempo must stay within
    ``LEVEL_BPM_RANGE``. Deciding per span lets a song whose first section was
    tracked at double time keep its correct second section.
    """
    env = np.asarray(onset_env, dtype=np.float64)
    frames = np.asarray(beat_frames, dtype=np.int64)
    factor = np.ones(env.size)
    if frames.size < max(8, span_beats // 2):
        return factor
    peak = np.maximum(np.maximum(env, np.roll(env, 1)), np.roll(env, -1))
    on = peak[frames]
    mid = peak[(frames[1:] + frames[:-1]) // 2]
    beat_factor = np.ones(frames.size - 1)
    half = span_beats // 2
    for i in range(frames.size - 1):
        lo, hi = max(0, i - half), min(frames.size - 1, i + half)
        strength = on[lo:hi + 1].mean()
        if strength <= 0:
            continue
        between = mid[lo:hi].mean() / strength
        even, odd = on[lo:hi + 1:2].mean(), on[lo + 1:hi + 1:2].mean()
        alternate = min(even, odd) / max(even, odd, 1e-12)
        local_bpm = bpm[frames[i]]
        if between > DOUBLE_ABOVE and 2 * local_bpm <= LEVEL_BPM_RANGE[1]:
            beat_factor[i] = 2.0
        elif alternate < HALVE_BELOW and local_bpm / 2 >= LEVEL_BPM_RANGE[0]:
            beat_factor[i] = 0.5
    # Each frame takes the decision of the beat interval it falls in (the nearest one outside).
    index = np.clip(np.searchsorted(frames, np.arange(env.size), side="right") - 1, 0, frames.size - 2)
    return beat_factor[index]


def _track_with_curve(env: np.ndarray, fps: float, bpm, tightness: float) -> np.ndarray:
    """Ellis' DP with the period of ``bpm`` (one tempo, or one per frame), backtracked from the last beat.

    Beats before the first or after the last onset sit on nothing and are dropped
    (librosa's ``trim=False`` does the same).
    """
    period = np.maximum(60.0 * fps / bpm, 2.0)
    local = beat_local_score(env, float(np.median(period)))
    backlink, cumscore = _dp(local, period, tightness)
    beats = []
    i = _last_beat(cumscore)
    while i >= 0:
        beats.append(i)
        i = backlink[i]
    frames = np.asarray(beats[::-1], dtype=np.int64)
    scored = np.flatnonzero(local > 0)
    if scored.size:
        frames = frames[(frames >= scored[0]) & (frames <= scored[-1])]
    return frames


def _dp(local: np.ndarray, period, tightness: float) -> tuple[np.ndarray, np.ndarray]:
    """Best cumulative score and the best predecessor (-1: none) of a beat at every frame.

    ``period`` is one number or one per frame (a beat at frame t is expected one
    ``period[t]`` after the previous beat). All transitions span at least
    ``min_lag = round(min(period) / 2)`` frames, so a block of ``min_lag`` frames
    depends only on frames before it: each block is one vectorised
    gather-add-argmax over (block, candidate lags).
    """
    n = local.size
    period = np.broadcast_to(np.asarray(period, dtype=np.float64), (n,))
    min_lag = max(1, int(round(period.min() / 2)))
    max_lag = max(min_lag, int(round(2 * period.max())))
    lags = np.arange(min_lag, max_lag + 1)
    log_lags = np.log(lags)[None, :]
    log_period = np.log(period)
    cumscore = np.full(max_lag + n, -np.inf)  # frame i lives at max_lag + i; before it: no beat
    backlink = np.full(n, -1, dtype=np.int64)
    for start in range(0, n, min_lag):
        frames = np.arange(start, min(start + min_lag, n))
        sources = frames[:, None] - lags[None, :]
        ratio = log_lags - log_period[frames, None]
        # Only lags within [period / 2, 2 period] of this frame's period may link.
        transition = np.where(np.abs(ratio) <= np.log(2.0) + 1e-9, -tightness * ratio ** 2, -np.inf)
        candidates = cumscore[max_lag + sources] + transition
        best = np.argmax(candidates, axis=1)  # ties: the nearest predecessor, as in librosa
        rows = np.arange(frames.size)
        value = candidates[rows, best]
        has_source = np.isfinite(value)
        cumscore[max_lag + frames] = local[frames] + np.where(has_source, value, 0.0)
        backlink[frames] = np.where(has_source, sources[rows, best], -1)
    # The first beat is the first frame with a noticeable local score: nothing links before it.
    first = int(np.argmax(local >= 0.01 * local.max()))
    backlink[:first] = -1
    return backlink, cumscore[max_lag:]


def _last_beat(cumscore: np.ndarray) -> int:
    """The last local maximum of the cumulative score that reaches half the median of all its maxima."""
    left = np.concatenate((cumscore[:1], cumscore[:-1]))
    right = np.concatenate((cumscore[1:], cumscore[-1:]))
    peaks = np.flatnonzero((cumscore > left) & (cumscore >= right))
    if peaks.size == 0:
        return cumscore.size - 1
    good = peaks[cumscore[peaks] >= 0.5 * np.median(cumscore[peaks])]
    return int(good[-1]) if good.size else cumscore.size - 1

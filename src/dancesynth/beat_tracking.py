"""Ellis' (2007) dynamic-programming beat tracker in plain numpy.

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

It follows librosa's ``beat_track`` step for step (same tempogram, prior, local
score, transition cost, first-beat and last-beat rules) but imports no numba: the
DP is vectorised over blocks of ``period / 2`` frames, which depend only on
earlier blocks, so a 3-minute song takes a few hundred small numpy operations.
The difference to librosa: the tempo (and so the DP period) is not rounded to
whole frames.
"""

from __future__ import annotations

import numpy as np

# librosa's defaults: an 8 s autocorrelation window, tempi up to 320 bpm.
AC_WINDOW_S = 8.0
MAX_BPM = 320.0
# The tempogram's windows advance by this fraction of the window: their mean
# barely changes from a hop of one frame (librosa's) and costs 1/25 as much.
_TEMPOGRAM_HOP_FRACTION = 1.0 / 25


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
    win = max(int(ac_window_s * fps), 4)
    if env.size == 0 or not np.any(env > 0):
        return 0.0
    n = env.size
    half = win // 2
    padded = np.concatenate((np.linspace(0.0, env[0], half, endpoint=False), env,
                             np.linspace(env[-1], 0.0, half + 1)[1:]))
    hop = max(1, int(round(win * _TEMPOGRAM_HOP_FRACTION)))
    starts = np.arange(0, n, hop)
    window = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(win) / win)
    frames = padded[starts[:, None] + np.arange(win)[None, :]] * window
    n_fft = 1 << int(np.ceil(np.log2(2 * win - 1)))
    spectrum = np.fft.rfft(frames, n_fft, axis=1)
    acf = np.fft.irfft(spectrum.real ** 2 + spectrum.imag ** 2, n_fft, axis=1)[:, :win]
    norm = acf[:, :1]
    acf = np.where(norm > 1e-20, acf / np.maximum(norm, 1e-20), 0.0).mean(axis=0)

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
        raise ValueError(f"onset_env must be one-dimensional, got shape {env.shape}")
    if not (fps > 0 and tightness > 0 and start_bpm > 0 and std_bpm > 0):
        raise ValueError("fps, tightness, start_bpm and std_bpm must be positive")
    if bpm is None:
        bpm = estimate_tempo(env, fps, start_bpm=start_bpm, std_bpm=std_bpm)
    if not (bpm > 0) or env.size < 2 or not np.any(env > 0):
        return np.zeros(0, dtype=np.int64), 0.0
    period = max(60.0 * fps / bpm, 2.0)
    local = beat_local_score(env, period)
    backlink, cumscore = _dp(local, period, tightness)
    beats = []
    i = _last_beat(cumscore)
    while i >= 0:
        beats.append(i)
        i = backlink[i]
    frames = np.asarray(beats[::-1], dtype=np.int64)
    # Beats before the first or after the last onset sit on nothing (librosa's
    # trim=False does the same).
    scored = np.flatnonzero(local > 0)
    if scored.size:
        frames = frames[(frames >= scored[0]) & (frames <= scored[-1])]
    return frames, float(bpm)


def _dp(local: np.ndarray, period: float, tightness: float) -> tuple[np.ndarray, np.ndarray]:
    """Best cumulative score and the best predecessor (-1: none) of a beat at every frame.

    All transitions span at least ``min_lag = round(period / 2)`` frames, so a block
    of ``min_lag`` frames depends only on frames before it: each block is one
    vectorised gather-add-argmax over (block, candidate lags).
    """
    n = local.size
    min_lag = max(1, int(round(period / 2)))
    max_lag = max(min_lag, int(round(2 * period)))
    lags = np.arange(min_lag, max_lag + 1)
    transition = -tightness * np.log(lags / period) ** 2
    cumscore = np.full(max_lag + n, -np.inf)  # frame i lives at max_lag + i; before it: no beat
    backlink = np.full(n, -1, dtype=np.int64)
    for start in range(0, n, min_lag):
        frames = np.arange(start, min(start + min_lag, n))
        sources = frames[:, None] - lags[None, :]
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

"""Onset strength in plain numpy: the spectral flux of a log-mel spectrogram.

This is librosa's default ``onset_strength`` (2048-sample Hann frames centred on
every hop, 128 Slaney mel bands up to Nyquist, ``power_to_db`` with an 80 dB
floor, positive first difference averaged over bands, no detrending) rewritten
with ``numpy.fft`` so that analysing a song imports neither librosa (whose first
import compiles numba kernels for seconds in every new process) nor scipy
(``scipy.fft`` alone costs ~0.3 s of import, more than numpy's FFT needs for a
3-minute song). The output matches librosa's to float32 rounding, frame for frame.

Frame ``i`` of the envelope is the rise of the spectrum into the analysis window
centred at sample ``(i - 2) * hop``: like librosa, the flux is shifted by
``lag + n_fft // (2 * hop)`` frames so that an onset's peak lands on the frame of
the onset itself, not on the frame whose window first touches it.
"""

from __future__ import annotations

import numpy as np
from ..errors import InputError

ANALYSIS_SR = 22050
# 441 samples at 22050 Hz = 20 ms: 50 feature frames per second, an exact frame
# rate (512 would give 43.07 fps); beats are refined below one frame anyway.
HOP_LENGTH = 441
FEATURE_FPS = ANALYSIS_SR / HOP_LENGTH
N_FFT = 2048
N_MELS = 128
# Log power below the loudest bin by more than this is floored (librosa's top_db).
TOP_DB = 80.0
# Frames transformed per FFT call: big enough to amortise the call, small enough
# that a block's spectra (1024 x 1025 complex64 = 8 MB) stay in cache-friendly memory.
_BLOCK_FRAMES = 1024


def hz_to_mel(hz):
    """Slaney's mel scale (librosa's default, ``htk=False``): linear below 1 kHz, logarithmic above."""
    hz = np.asarray(hz, dtype=np.float64)
    f_sp = 200.0 / 3
    min_log_hz, min_log_mel, logstep = 1000.0, 1000.0 / f_sp, np.log(6.4) / 27.0
    lin = hz / f_sp
    with np.errstate(divide="ignore"):
        log = min_log_mel + np.log(np.maximum(hz, 1e-12) / min_log_hz) / logstep
    return np.where(hz >= min_log_hz, log, lin)


def mel_to_hz(mel):
    """Inverse of ``hz_to_mel``."""
    mel = np.asarray(mel, dtype=np.float64)
    f_sp = 200.0 / 3
    min_log_hz, min_log_mel, logstep = 1000.0, 1000.0 / f_sp, np.log(6.4) / 27.0
    return np.where(mel >= min_log_mel, min_log_hz * np.exp(logstep * (mel - min_log_mel)), f_sp * mel)


def mel_filterbank(sr: float, n_fft: int, *, n_mels: int = N_MELS, fmin: float = 0.0,
                   fmax: float | None = None) -> np.ndarray:
    """Triangular mel filters with Slaney's area normalisation, ``(n_mels, 1 + n_fft // 2)``.

    Band ``m`` rises linearly from mel point ``m`` to ``m + 1`` and falls to
    ``m + 2`` (``n_mels + 2`` points evenly spaced in mel between ``fmin`` and
    ``fmax``, default Nyquist), scaled by ``2 / (f[m+2] - f[m])`` so every band
    has the same area: the same matrix as ``librosa.filters.mel(sr=, n_fft=)``.
    """
    fmax = sr / 2.0 if fmax is None else float(fmax)
    fft_hz = np.linspace(0.0, sr / 2.0, 1 + n_fft // 2)
    mel_hz = mel_to_hz(np.linspace(hz_to_mel(fmin), hz_to_mel(fmax), n_mels + 2))
    widths = np.diff(mel_hz)
    ramps = mel_hz[:, None] - fft_hz[None, :]
    rising = -ramps[:-2] / widths[:-1, None]
    falling = ramps[2:] / widths[1:, None]
    weights = np.maximum(0.0, np.minimum(rising, falling))
    return weights * (2.0 / (mel_hz[2:] - mel_hz[:-2]))[:, None]


def power_to_db(power: np.ndarray, *, amin: float = 1e-10, top_db: float | None = TOP_DB) -> np.ndarray:
    """``10 log10(power)`` (re 1.0), floored at ``amin`` and at ``top_db`` below the maximum."""
    db = 10.0 * np.log10(np.maximum(power, amin))
    if top_db is not None and db.size:
        np.maximum(db, db.max() - top_db, out=db)
    return db


def mel_power_spectrogram(y: np.ndarray, sr: float, *, hop_length: int = HOP_LENGTH, n_fft: int = N_FFT,
                          n_mels: int = N_MELS) -> np.ndarray:
    """Mel power spectrogram ``(1 + len(y) // hop_length, n_mels)``, float32, frames first.

    Frame ``i`` is the periodic-Hann-windowed ``n_fft`` samples centred on sample
    ``i * hop_length``, the signal zero-padded by ``n_fft // 2`` at both ends
    (librosa's ``center=True, pad_mode="constant"``).
    """
    y = np.asarray(y, dtype=np.float32)
    if y.ndim != 1:
        raise InputError(f"expected mono samples of shape (n,), got {y.shape}")
    padded = np.pad(y, n_fft // 2)
    n_frames = 1 + len(y) // hop_length
    frames = np.lib.stride_tricks.as_strided(
        padded, shape=(n_frames, n_fft), strides=(padded.strides[0] * hop_length, padded.strides[0]),
        writeable=False)
    window = (0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n_fft) / n_fft)).astype(np.float32)
    basis_t = np.ascontiguousarray(mel_filterbank(sr, n_fft, n_mels=n_mels).T, dtype=np.float32)
    mel = np.empty((n_frames, n_mels), dtype=np.float32)
    for start in range(0, n_frames, _BLOCK_FRAMES):
        spectrum = np.fft.rfft(frames[start:start + _BLOCK_FRAMES] * window, axis=1)
        power = np.square(spectrum.real) + np.square(spectrum.imag)
        np.matmul(power, basis_t, out=mel[start:start + _BLOCK_FRAMES])
    return mel


def onset_envelope(y: np.ndarray, sr: int = ANALYSIS_SR, *, hop_length: int = HOP_LENGTH) -> np.ndarray:
    """Onset strength, one value per hop: how much the log-mel spectrum rises, in dB averaged over bands.

    ``y`` are mono samples at rate ``sr``. Returns ``(1 + len(y) // hop_length,)``
    float32, the same frames and values as ``librosa.onset.onset_strength(y=y,
    sr=sr, hop_length=hop_length)``: the positive first difference of the 128-band
    log-mel spectrogram (80 dB range), averaged over the bands and delayed by
    ``1 + 2048 // (2 * hop_length)`` frames (zeros at the start).
    """
    db = power_to_db(mel_power_spectrogram(y, sr, hop_length=hop_length))
    flux = np.maximum(db[1:] - db[:-1], 0.0).mean(axis=1, dtype=np.float32)
    env = np.zeros(len(db), dtype=np.float32)
    delay = 1 + N_FFT // (2 * hop_length)
    if len(db) > delay:
        env[delay:] = flux[:len(db) - delay]
    return env

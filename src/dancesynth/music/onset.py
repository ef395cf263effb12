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

import itertools

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
# Frames per FFT call within a block: numpy's real FFT needs several times its output in working
# memory (40 MB for 1024 frames).
_FFT_ROWS = 128
# Frames whose log-mel spectrum ``onset_envelope`` keeps between its passes (16 MB, 11 minutes).
KEPT_FRAMES = 32 * _BLOCK_FRAMES


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
    y = _mono_samples(y)
    mel = np.empty((1 + len(y) // hop_length, n_mels), dtype=np.float32)
    for start, block in mel_power_blocks(y, sr, hop_length=hop_length, n_fft=n_fft, n_mels=n_mels):
        mel[start:start + len(block)] = block
    return mel


def mel_power_blocks(y: np.ndarray, sr: float, *, hop_length: int = HOP_LENGTH, n_fft: int = N_FFT,
                     n_mels: int = N_MELS, start_frame: int = 0):
    """``mel_power_spectrogram`` in blocks of frames: yields ``(first frame, (frames, n_mels) float32)``.

    Each block is framed from its own stretch of ``y`` (zero-padded only at the signal's
    ends), so no padded copy of the whole signal is made; the values are the same.
    Blocks start at multiples of 1024 frames, from ``start_frame`` (rounded down to one).
    """
    y = _mono_samples(y)
    n = len(y)
    n_frames = 1 + n // hop_length
    half = n_fft // 2
    window = (0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n_fft) / n_fft)).astype(np.float32)
    basis_t = np.ascontiguousarray(mel_filterbank(sr, n_fft, n_mels=n_mels).T, dtype=np.float32)
    power = np.empty((min(_BLOCK_FRAMES, n_frames), 1 + n_fft // 2), dtype=np.float32)
    for start in range(int(start_frame) // _BLOCK_FRAMES * _BLOCK_FRAMES, n_frames, _BLOCK_FRAMES):
        stop = min(start + _BLOCK_FRAMES, n_frames)
        lo, hi = start * hop_length - half, (stop - 1) * hop_length - half + n_fft
        piece = np.asarray(y[max(lo, 0):min(hi, n)], dtype=np.float32)
        if lo < 0 or hi > n:
            piece = np.pad(piece, (max(0, -lo), max(0, hi - n)))
        frames = np.lib.stride_tricks.as_strided(
            piece, shape=(stop - start, n_fft), strides=(piece.strides[0] * hop_length, piece.strides[0]),
            writeable=False)
        # The FFT a few rows at a time (its working memory is several times its output); the
        # product with the filters over the whole block, as before.
        for a in range(0, stop - start, _FFT_ROWS):
            b = min(a + _FFT_ROWS, stop - start)
            spectrum = np.fft.rfft(frames[a:b] * window, axis=1)
            np.square(spectrum.real, out=power[a:b])
            power[a:b] += np.square(spectrum.imag)
        yield start, np.matmul(power[:stop - start], basis_t)


def onset_envelope(y: np.ndarray, sr: int = ANALYSIS_SR, *, hop_length: int = HOP_LENGTH,
                   kept_frames: int = KEPT_FRAMES) -> np.ndarray:
    """Onset strength, one value per hop: how much the log-mel spectrum rises, in dB averaged over bands.

    ``y`` are mono samples at rate ``sr``. Returns ``(1 + len(y) // hop_length,)``
    float32, the same frames and values as ``librosa.onset.onset_strength(y=y,
    sr=sr, hop_length=hop_length)``: the positive first difference of the 128-band
    log-mel spectrogram (80 dB range), averaged over the bands and delayed by
    ``1 + 2048 // (2 * hop_length)`` frames (zeros at the start).

    The 80 dB range hangs from the loudest value of the whole song, so the rises
    can only be taken once every frame has been seen. The log-mel spectrogram of
    the first ``kept_frames`` frames (512 bytes a frame: 16 MB, 11 minutes at 50
    frames a second) is kept for that; frames beyond are transformed a second time
    instead of kept, so memory stays bounded for a song of any length. Either way
    the values are the same.
    """
    y = _mono_samples(y)
    n = 1 + len(y) // hop_length
    # Whole blocks, so that the second pass transforms exactly the blocks the first did.
    keep = n if n <= kept_frames else max(0, int(kept_frames)) // _BLOCK_FRAMES * _BLOCK_FRAMES
    head = np.empty((keep, N_MELS), dtype=np.float32)
    top = None
    for start, mel in mel_power_blocks(y, sr, hop_length=hop_length):
        block = head[start:start + len(mel)] if start < keep else mel
        _to_db(mel, out=block)
        block_top = block.max()
        top = block_top if top is None else max(top, block_top)
    env = np.zeros(n, dtype=np.float32)
    if top is None:
        return env
    floor = top - TOP_DB                    # float32, as ``power_to_db`` computes it
    np.maximum(head, floor, out=head)
    blocks = (head[a:a + _BLOCK_FRAMES] for a in range(0, keep, _BLOCK_FRAMES))
    if keep < n:
        blocks = itertools.chain(blocks, (np.maximum(_to_db(mel, out=mel), floor, out=mel) for _, mel in
                                          mel_power_blocks(y, sr, hop_length=hop_length, start_frame=keep)))
    # env[delay + i] is the rise from frame i to frame i + 1.
    delay = 1 + N_FFT // (2 * hop_length)
    previous, done = None, 0      # the last frame of the block before; frames seen
    for block in blocks:
        rows = block if previous is None else np.concatenate((previous[None], block))
        first = done - (previous is not None)       # the frame rows[0] is
        pairs = min(len(rows) - 1, n - delay - first)
        if pairs > 0:
            rise = rows[1:pairs + 1] - rows[:pairs]
            np.maximum(rise, 0.0, out=rise)
            env[delay + first:delay + first + pairs] = rise.mean(axis=1, dtype=np.float32)
        previous = block[-1].copy()
        done += len(block)
    return env


def _to_db(power: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``power_to_db`` without its floor, into ``out`` (the same float32 operations)."""
    np.maximum(power, 1e-10, out=out)
    np.log10(out, out=out)
    out *= 10.0
    return out


def _mono_samples(y) -> np.ndarray:
    y = np.asarray(y)
    if y.ndim != 1:
        raise InputError(f"expected mono samples of shape (n,), got {y.shape}")
    return y

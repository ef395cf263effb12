"""Synthetic test audio whose ground truth is known exactly.

Everything here is plain numpy so that tests state their truth analytically (a click
every 0.5 s is 120 bpm) instead of trusting an opaque reference file. Signals are
float32 mono in [-1, 1]; ``write`` puts them on disk in a chosen container/subtype.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import soundfile as sf

SR = 22050


def beat_grid(bpm: float, duration_s: float, offset_s: float = 0.0) -> np.ndarray:
    """Beat instants of a steady tempo starting at ``offset_s``, within ``duration_s``."""
    period = 60.0 / bpm
    return np.arange(offset_s, duration_s - 1e-9, period)


def click_track(bpm: float, duration_s: float, *, sr: int = SR, offset_s: float = 0.25,
                freq_hz: float = 1000.0, amplitude: float = 0.8, accent_every: int = 0,
                ) -> tuple[np.ndarray, np.ndarray]:
    """A metronome: a short decaying tone burst on every beat.

    Returns ``(y, beat_times_s)``. ``accent_every=4`` makes every fourth click
    louder and higher, like a metronome marking bars.
    """
    n = int(round(duration_s * sr))
    y = np.zeros(n, dtype=np.float64)
    t = np.arange(int(0.06 * sr)) / sr
    # A 60 ms burst with a 10 ms decay has a sharp onset and no tail into the next beat.
    burst = np.sin(2 * np.pi * freq_hz * t) * np.exp(-t / 0.010)
    accent = np.sin(2 * np.pi * 1.5 * freq_hz * t) * np.exp(-t / 0.010)
    beats = beat_grid(bpm, duration_s, offset_s)
    for k, bt in enumerate(beats):
        i = int(round(bt * sr))
        b = accent if accent_every and k % accent_every == 0 else 0.6 * burst
        m = min(len(b), n - i)
        y[i:i + m] += b[:m]
    y *= amplitude / np.max(np.abs(y))
    return y.astype(np.float32), beats


def colored_noise(duration_s: float, *, sr: int = SR, exponent: float = 0.0, seed: int = 0,
                  rms_db: float = -20.0) -> np.ndarray:
    """Gaussian noise with power spectrum ~ 1/f**exponent (0 white, 1 pink, 2 brown)."""
    rng = np.random.default_rng(seed)
    n = int(round(duration_s * sr))
    spec = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, 1.0 / sr)
    f[0] = f[1]
    spec *= f ** (-exponent / 2.0)
    y = np.fft.irfft(spec, n)
    y *= 10 ** (rms_db / 20.0) / np.sqrt(np.mean(y ** 2))
    return np.clip(y, -1.0, 1.0).astype(np.float32)


def organ_chord(duration_s: float, *, sr: int = SR, root_hz: float = 130.81,
                amplitude: float = 0.5) -> np.ndarray:
    """A sustained C-major chord of organ-like tones with a slow swell: no onsets at all."""
    t = np.arange(int(round(duration_s * sr))) / sr
    y = np.zeros_like(t)
    for ratio in (1.0, 1.25, 1.5, 2.0):
        for h, a in ((1, 1.0), (2, 0.5), (3, 0.35), (4, 0.2), (6, 0.1)):
            y += a * np.sin(2 * np.pi * root_hz * ratio * h * t + ratio * h)
    # A 1.5 s swell in and out so neither end is an attack.
    env = np.minimum(1.0, np.minimum(t, t[-1] - t) / 1.5)
    y *= env
    return (amplitude * y / np.max(np.abs(y))).astype(np.float32)


def sine(freq_hz: float, duration_s: float, *, sr: int = SR, amplitude: float = 1.0) -> np.ndarray:
    t = np.arange(int(round(duration_s * sr))) / sr
    return (amplitude * np.sin(2 * np.pi * freq_hz * t)).astype(np.float32)


def write(path: Path, y: np.ndarray, sr: int, *, subtype: str | None = None,
          fmt: str | None = None, channels: int = 1) -> Path:
    """Write ``y`` (mono) to ``path``; ``channels=2`` duplicates it into stereo."""
    data = np.asarray(y, dtype=np.float32)
    if channels > 1:
        data = np.repeat(data[:, None], channels, axis=1)
    sf.write(str(path), data, sr, subtype=subtype, format=fmt)
    return Path(path)

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


def swing_track(bpm: float, duration_s: float, *, sr: int = SR, offset_s: float = 0.25, swing: float = 2.0 / 3.0,
                off_gain: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
    """Swung eighth notes: a click on every beat and a softer one ``swing`` of a beat later.

    ``swing=0.5`` is straight eighths, ``2/3`` the triplet swing of jazz. The
    truth is the beats only (the on-beat clicks). Returns ``(y, beat_times_s)``.
    """
    n = int(round(duration_s * sr))
    y = np.zeros(n, dtype=np.float64)
    beats = beat_grid(bpm, duration_s, offset_s)
    burst = _burst(sr, 1000.0, 0.010)
    for bt in beats:
        for at, gain in ((bt, 1.0), (bt + swing * 60.0 / bpm, off_gain)):
            _add(y, gain * burst, int(round(at * sr)))
    return (0.8 * y / np.max(np.abs(y))).astype(np.float32), beats


def drum_loop(bpm: float, duration_s: float, *, sr: int = SR, offset_s: float = 0.25, seed: int = 0,
              ) -> tuple[np.ndarray, np.ndarray]:
    """A song-like pattern: kick on beats 1 and 3, snare on 2 and 4, closed hi-hat on
    every eighth note, and a sustained two-chord pad underneath (changing every bar).

    The kick is a 150 -> 50 Hz sine sweep, the snare a noise burst over a 190 Hz
    tone, the hi-hat differentiated (high-passed) noise; the pad gives the
    spectrum a steady background as real music has. Returns ``(y, beat_times_s)``.
    """
    rng = np.random.default_rng(seed)
    n = int(round(duration_s * sr))
    y = np.zeros(n, dtype=np.float64)
    t = np.arange(int(0.3 * sr)) / sr
    kick = np.sin(2 * np.pi * (50.0 * t + 100.0 * 0.04 * (1 - np.exp(-t / 0.04)))) * np.exp(-t / 0.12)
    ts = t[: int(0.18 * sr)]
    snare = (0.6 * rng.standard_normal(ts.size) + 0.5 * np.sin(2 * np.pi * 190.0 * ts)) * np.exp(-ts / 0.05)
    th = t[: int(0.05 * sr)]
    hat = np.diff(rng.standard_normal(th.size + 1)) * np.exp(-th / 0.012)
    beats = beat_grid(bpm, duration_s, offset_s)
    period = 60.0 / bpm
    for k, bt in enumerate(beats):
        i = int(round(bt * sr))
        _add(y, 0.9 * kick if k % 2 == 0 else 0.7 * snare, i)
        _add(y, 0.15 * hat, i)
        _add(y, 0.1 * hat, int(round((bt + period / 2) * sr)))
    tt = np.arange(n) / sr
    bar = np.floor((tt - offset_s) / (4 * period)).astype(int) % 2
    pad = np.zeros(n)
    for root in (220.0, 277.18, 329.63):
        f = np.where(bar == 0, root, root * 2 ** (-2 / 12))
        pad += np.sin(2 * np.pi * np.cumsum(f) / sr)
    y += 0.05 * pad
    return (0.8 * y / np.max(np.abs(y))).astype(np.float32), beats


def _burst(sr: int, freq_hz: float, decay_s: float, length_s: float = 0.06) -> np.ndarray:
    t = np.arange(int(length_s * sr)) / sr
    return np.sin(2 * np.pi * freq_hz * t) * np.exp(-t / decay_s)


def _add(y: np.ndarray, sound: np.ndarray, at: int) -> None:
    """Mix ``sound`` into ``y`` starting at sample ``at`` (cut at the end of ``y``)."""
    if 0 <= at < len(y):
        m = min(len(sound), len(y) - at)
        y[at:at + m] += sound[:m]


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

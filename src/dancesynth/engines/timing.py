"""Accent timing: where within a beat piece its source motion is shown.

The paper plays each beat-to-beat piece at one rate (its source beat frames warped onto the music
beats). ``ease`` plays it slower on each beat and faster between, so the motion settles into every
beat; ``beat_ease`` says how hard each beat is hit (the bar's "1" hardest), ``ease_within``
keeps the easing from playing a piece much faster than captured and ``within_room`` any frame faster
than the style's own fast frames. ``stitch.render`` applies it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError


def ease(u, count0, count1, ease0, ease1):
    """Accent timing: where within a piece (``u`` = 0..1 of its music time) its source is shown.

    Played linearly, a piece moves as fast on the beat as between beats, and the beat
    goes by unseen wherever the mocap does not happen to stop there. Eased, the playback
    rate follows ``1 - a(c) cos(2 pi c)`` of the music's beat count ``c``, normalised so
    the piece keeps its length: slower on each beat, faster between. The motion settles
    into every beat and springs out of it -- the accent by speed that Loi & Li give the
    hands on each beat, what a dancer does when "hitting" the count. ``a`` runs linearly
    from ``ease0`` at the piece's start to ``ease1`` at its end, so a beat can be hit
    harder than its neighbours (the bar's "1"). Piece ends stay put: the source beat
    frames still land exactly on their beats. ``ease0 = ease1 = 0`` is linear.
    """
    shown, _ = _timing(u, count0, count1, ease0, ease1)
    return shown


def ease_rate(u, count0, count1, ease0, ease1):
    """d ease / d u: the playback rate at ``u`` relative to the piece's mean rate."""
    _, rate = _timing(u, count0, count1, ease0, ease1)
    return rate


def beat_ease(n: int, bar_position=None, beats_per_bar: int | None = None, *, amount: float,
              downbeat: float = 0.0) -> np.ndarray:
    """How hard ``ease`` hits each of ``n`` grid beats: ``amount``, plus ``downbeat`` on a bar's
    first beat, so the "1" is the bar's strongest accent. (Taking as much off the other beats, so
    that a bar kept its mean, cost them their stops: precision 0.62 against 0.69.) Beats of
    unknown position get ``amount``. Each must stay below 1: at 1 the motion halts on the beat,
    above it would run backwards."""
    if not (0.0 <= amount and 0.0 <= downbeat and amount + downbeat < 1.0):
        raise InputError(f"accent timing needs 0 <= ease_beats, 0 <= ease_downbeat and their sum < 1, got "
                         f"{amount} and {downbeat}")
    out = np.full(n, float(amount))
    if bar_position is None or not beats_per_bar or beats_per_bar < 2 or downbeat == 0:
        return out
    out[np.asarray(bar_position) == 0] += downbeat
    return out


def ease_within(ease, rates, max_rate: float | None, count=None) -> np.ndarray:
    """Per grid beat, ``ease`` (K+1,) scaled down where the accent timing would play a piece faster than
    ``max_rate`` times its captured speed. Between beats ``ease`` plays piece k at up to ``peak_k`` times
    its mean rate (``rates`` (K,), source seconds per music second: the warp that fits it to its beat;
    ``count`` (K+1,) the music's beat count at each grid beat, None: one beat each), and ``peak_k - 1``
    grows with the easing, so the easing of both ends of the piece is scaled by ``lambda_k`` to keep
    ``rate_k * (1 + lambda_k (peak_k - 1)) <= max_rate`` (``lambda_k`` = 0: a piece already warped past
    ``max_rate`` is played evenly), and each beat takes the smaller scale of the two pieces it joins
    (the rate stays continuous there). A bar's "1" keeps its extra weight against its neighbours. None:
    no limit. (``within_room`` then keeps each frame within the style's own speeds.)"""
    ease = np.asarray(ease, dtype=np.float64)
    if max_rate is None or ease.size < 2:
        return ease
    count = np.arange(ease.size, dtype=np.float64) if count is None else np.asarray(count, dtype=np.float64)
    u = np.linspace(0.0, 1.0, 41)[:, None]
    peak = ease_rate(u, count[:-1], count[1:], ease[:-1], ease[1:]).max(axis=0)
    rates = np.maximum(np.asarray(rates, dtype=np.float64), 1e-9)
    scale = np.clip((max_rate / rates - 1.0) / np.maximum(peak - 1.0, 1e-9), 0.0, 1.0)
    return ease * np.minimum(np.r_[scale[0], scale], np.r_[scale, scale[-1]])


@dataclass(frozen=True)
class SpeedRoom:
    """How fast a style's source moves, for ``within_room``: ``speed`` (F,) its fastest joint's speed per
    frame as captured (m/s, ``motion.accents.peak_speeds``) and ``limit``, the speed (m/s) the easing may
    not push a frame past: the style's own ``percentile`` of ``speed``."""

    speed: np.ndarray
    limit: float

    @classmethod
    def of(cls, speed: np.ndarray, percentile: float) -> "SpeedRoom":
        speed = np.asarray(speed, dtype=np.float64)
        return cls(speed, float(np.percentile(speed, percentile)) if speed.size else np.inf)

    def at(self, frames: np.ndarray) -> np.ndarray:
        return self.speed[np.clip(np.rint(frames).astype(np.int64), 0, len(self.speed) - 1)]


ROOM_SAMPLES = 65  # per piece: finer than a beat piece's source frames at 60 fps


def within_room(ease, count, f0, f1, rates, room: SpeedRoom) -> np.ndarray:
    """(K, ROOM_SAMPLES) the share of each piece's source shown at evenly spaced points of its music time:
    ``ease``'s timing (``ease`` and ``count`` (K+1,) per grid beat, as ``ease_within``'s) with the easing
    taking only the speed headroom each frame has. The eased rate ``r(u)`` would play a source frame of
    speed ``v`` at ``v * rate_k * r(u)``; where that passes ``room.limit`` the rate is held at the limit
    (never below the even rate or the eased one), and the source time it no longer shows is shown
    instead between the beats where the piece moves slowly: the rate there is ``kappa * r(u)``, ``kappa``
    >= 1 solved so the piece still spans its beat (``_fill``). The stop on each beat stays while the
    piece's fast moves are played no faster than the mocap's own fast moves; the cosine's amplitude
    scaled down instead (``ease_within``) costs the same speed a third of the accents. A piece that
    cannot fit at all is played evenly."""
    ease, count = np.asarray(ease, dtype=np.float64), np.asarray(count, dtype=np.float64)
    f0, f1 = np.asarray(f0, dtype=np.float64), np.asarray(f1, dtype=np.float64)
    rates = np.maximum(np.asarray(rates, dtype=np.float64), 1e-9)
    u = np.linspace(0.0, 1.0, ROOM_SAMPLES)[:, None]
    shown, wanted = _timing(u, count[:-1], count[1:], ease[:-1], ease[1:])   # (N, K)
    floor = np.minimum(wanted, 1.0)
    rate = wanted
    for _ in range(3):   # the frames shown move as the rate changes: look again
        speed = _spread(room.at(f0 + shown * (f1 - f0)), np.maximum, 2 * SMOOTH)
        rate, fits = _fill(wanted, np.maximum(room.limit / np.maximum(speed * rates, 1e-9), floor))
        held = wanted * _spread(rate / wanted, np.add, SMOOTH) / (2 * SMOOTH + 1)   # the hold smoothed, not
        rate = np.where(fits, held / _mean(held), 1.0)                             # the stops
        shown = _integrate(rate)
    return shown.T


SMOOTH = 2  # samples each side: the hold on the rate changes smoothly, so it adds no stops of its own


def _spread(x: np.ndarray, op, half: int) -> np.ndarray:
    """``op`` (np.maximum or np.add) of each sample of axis 0 with its ``half`` neighbours each side, the
    ends repeated. A fast frame caps the rate a little before and after it, so the smoothed rate still
    holds it."""
    padded = np.concatenate([np.repeat(x[:1], half, axis=0), x, np.repeat(x[-1:], half, axis=0)])
    out = padded[:len(x)].copy()
    for i in range(1, 2 * half + 1):
        out = op(out, padded[i:i + len(x)])
    return out


def _mean(x: np.ndarray) -> np.ndarray:
    """Trapezoid mean over the evenly spaced samples of axis 0."""
    return (x[1:] + x[:-1]).sum(axis=0) / (2.0 * (len(x) - 1))


def _fill(wanted: np.ndarray, cap: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``min(wanted, cap)``, the part between the beats (``wanted`` >= 1) scaled by ``kappa`` >= 1 per
    column so the mean is 1: the time the cap saves is shown between the beats, and the stops on them
    stay as eased. Where that part cannot take it, the whole column is scaled; where nothing up to
    ``kappa`` = 4 can, the column is even (1). Also returns whether it fit."""
    between = wanted >= 1.0
    rate, fits = _scaled(wanted, cap, between)
    if fits.all():   # as a rule: the whole-piece scaling is for pieces fast nearly throughout
        return rate, fits
    everywhere, fits_everywhere = _scaled(wanted, cap, np.ones_like(between))
    rate = np.where(fits, rate, np.where(fits_everywhere, everywhere, 1.0))
    return rate, fits | fits_everywhere


def _scaled(wanted, cap, scaled) -> tuple[np.ndarray, np.ndarray]:
    """``min(kappa * wanted, cap)`` where ``scaled``, ``min(wanted, cap)`` elsewhere, ``kappa`` in [1, 4]
    making each column's mean 1 (bisection); and whether it could."""
    def at(kappa):
        return np.minimum(np.where(scaled, kappa * wanted, wanted), cap)

    lo, hi = np.ones(wanted.shape[1]), np.full(wanted.shape[1], 4.0)
    fits = _mean(at(hi)) >= 1.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        short = _mean(at(mid)) < 1.0
        lo, hi = np.where(short, mid, lo), np.where(short, hi, mid)
    rate = at(hi)
    return rate / _mean(rate), fits


def _integrate(rate: np.ndarray) -> np.ndarray:
    """The share shown at each sample of a rate that means 1 (trapezoid), ending exactly at 1."""
    cum = np.r_[np.zeros((1, rate.shape[1])), np.cumsum(rate[1:] + rate[:-1], axis=0)]
    return cum / cum[-1]


def speed_room(style, config) -> SpeedRoom | None:
    """``style``'s ``SpeedRoom`` at ``config.ease_speed_percentile`` (an engine's or the mixer's; None:
    none), its speeds analysed once per style and kept on disk."""
    from ..motion.accents import cached_peak_speeds

    pct = config.ease_speed_percentile
    if pct is None or not (config.ease_beats or config.ease_downbeat):
        return None
    return SpeedRoom.of(cached_peak_speeds(style), pct)


def plain_timing(config):
    """``config`` (an engine's or the mixer's) with the accent timing off: each piece at one rate, as
    the papers play it. The path is the same; only where within each piece its frames are shown changes."""
    from dataclasses import replace

    return replace(config, ease_beats=0.0, ease_downbeat=0.0)


def _timing(u, count0, count1, ease0, ease1):
    """``(ease, ease_rate)`` at ``u``: ``F(u) / F(1)`` and ``span * (1 - a(c) cos 2 pi c) / F(1)``, with
    ``F(u)`` the integral of ``1 - a(c) cos(2 pi c) dc`` from the piece's start, in beats counted from
    the start's whole beat (the wave repeats every beat). Pieces of no span play linearly."""
    u = np.asarray(u, dtype=np.float64)
    c0 = np.asarray(count0, dtype=np.float64)
    span = np.asarray(count1, dtype=np.float64) - c0
    safe = np.where(span > 0, span, 1.0)
    start = c0 - np.floor(c0)
    slope = (np.asarray(ease1, dtype=np.float64) - ease0) / safe  # a(c) = base + slope * c, locally
    base = ease0 - slope * start

    def integral(x):  # x minus the integral of (base + slope c) cos(2 pi c) dc, from start to x
        return x - start - (_wave_integral(x, base, slope) - _wave_integral(start, base, slope))

    c = start + span * u
    total = np.where(span > 0, integral(start + span), 1.0)
    shown = np.where(span > 0, integral(c) / total, u)
    rate = np.where(span > 0, span * (1.0 - (base + slope * c) * np.cos(2 * np.pi * c)) / total, 1.0)
    return shown, rate


def _wave_integral(x, base, slope):
    """Integral of ``(base + slope c) cos(2 pi c) dc`` from 0 to ``x``."""
    w = 2 * np.pi * x
    return base * np.sin(w) / (2 * np.pi) + slope * (x * np.sin(w) / (2 * np.pi) + (np.cos(w) - 1) / (4 * np.pi ** 2))

"""From music beats to the beat grid an engine dances on, and the style that suits it.

The grid is the music's beats, extended with beats at the local beat period before
the first and after the last detected beat so that the whole song -- from 0 s to
its end -- is covered by beat intervals (the dancer never stands still waiting for
the first beat). When the song is much slower than every style, each interval can
be subdivided so the dancer moves at a natural pace; every music beat stays a grid
beat, so every music beat still gets a motion beat frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..motion.database import MotionDatabase, Style
from ..types import MusicFeatures


@dataclass(frozen=True)
class BeatGrid:
    times_s: np.ndarray         # (G,) increasing; times_s[0] <= 0 and times_s[-1] >= duration
    intensity_db: np.ndarray    # (G-1,) per interval
    is_music_beat: np.ndarray   # (G,) bool: this grid beat is a detected music beat
    subdivide: int = 1

    @property
    def n_intervals(self) -> int:
        return len(self.times_s) - 1


def beat_grid(music: MusicFeatures, *, subdivide: int = 1) -> BeatGrid:
    """The beat grid of ``music`` covering [0, duration], each interval split ``subdivide`` times."""
    beats = np.asarray(music.beat_times_s, dtype=np.float64)
    inten = np.asarray(music.intensity_db, dtype=np.float64)
    if beats.size < 2:
        raise ValueError("beat_grid needs at least two beats")
    first_period = float(beats[1] - beats[0])
    last_period = float(beats[-1] - beats[-2])
    n_before = int(np.ceil(max(beats[0], 0.0) / first_period - 1e-9))
    n_after = int(np.ceil(max(music.duration_s - beats[-1], 0.0) / last_period - 1e-9))
    times = np.concatenate([beats[0] - first_period * np.arange(n_before, 0, -1), beats,
                            beats[-1] + last_period * np.arange(1, n_after + 1)])
    intensity = np.concatenate([np.full(n_before, inten[0]), inten, np.full(n_after, inten[-1])])
    is_beat = np.zeros(len(times), dtype=bool)
    is_beat[n_before:n_before + beats.size] = True
    if subdivide > 1:
        frac = np.arange(subdivide) / subdivide
        sub = (times[:-1, None] + np.diff(times)[:, None] * frac[None, :]).ravel()
        times = np.r_[sub, times[-1]]
        intensity = np.repeat(intensity, subdivide)
        is_beat = np.r_[(is_beat[:-1, None] & (frac == 0)[None, :]).ravel(), is_beat[-1:]]
    return BeatGrid(times, intensity, is_beat, subdivide)


def choose_style(db: MotionDatabase, tempo_bpm: float, name: str | None = None) -> tuple[Style, int]:
    """The style (and subdivision) whose tempo range best covers ``tempo_bpm``.

    Candidates are the styles called ``name`` (or of genre ``name``), or all styles.
    A style's cost is how far (in log tempo) the song, possibly at double time, lies
    outside the style's tempo range; ties go to the larger style.
    """
    candidates = db.styles_of(name) if name else list(db.styles.values())
    best = None
    for st in candidates:
        lo, hi = st.tempo_range_bpm
        for sub in (1, 2):
            t = tempo_bpm * sub
            outside = max(np.log(lo / t), np.log(t / hi), 0.0) if t > 0 else 1.0
            cost = (outside + 0.05 * abs(np.log(t / st.natural_tempo_bpm)) + 0.15 * (sub - 1)
                    if t > 0 else 10.0, -st.n_frames)
            if best is None or cost < best[0]:
                best = (cost, st, sub)
    return best[1], best[2]

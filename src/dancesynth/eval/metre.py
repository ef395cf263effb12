"""The dance's metre: the period, in music beats, at which its energy per beat repeats."""

from __future__ import annotations

import numpy as np

from ..types import MotionClip, MusicFeatures
from .beat_metrics import dominant_beat_period
from .motion_metrics import beat_interval_energy

#: How much more the dance's energy must repeat at 3 beats than at 2 or 4 for a style to count as
#: dancing a waltz in three (autocorrelation): a tie is a coin flip that the next reading may lose.
IN_THREE_MARGIN = 0.05


def dance_period(clip: MotionClip, music: MusicFeatures) -> int | None:
    """The period (2, 3 or 4 beats) at which the dance's kinetic energy per music beat repeats most."""
    return period_strengths(clip, music)[0]


def period_strengths(clip: MotionClip, music: MusicFeatures) -> tuple[int | None, dict[int, float]]:
    """``dance_period`` and how strongly the energy repeats at each candidate period."""
    energy = beat_interval_energy(clip, music.beat_times_s)
    return dominant_beat_period(energy[np.isfinite(energy)])


def dances_in_three(clip: MotionClip, music: MusicFeatures) -> bool:
    """The dance clearly repeats in threes: its strongest period is 3, by ``IN_THREE_MARGIN``."""
    period, strength = period_strengths(clip, music)
    others = [r for lag, r in strength.items() if lag != 3]
    return period == 3 and (not others or strength[3] >= max(others) + IN_THREE_MARGIN)

"""The rest of the body, Loi & Li §V.G: left hand, head and torso, plus the legs' stance.

- Left hand: it waits low in front of the body; on a note longer than a quarter of
  a whole note (``long_note`` sixteenths) it reaches out to the side for the note's
  time; on a staccato note it drops quickly and stops dead, then recovers.
- Head: nods down onto beats. Torso: swings to one side, then the other, turning
  on beats. Both keep at least ``nod_turn`` / ``sway_turn`` seconds between two
  changes of direction, so fast music gives a nod every other beat instead of a
  rattle.
- Legs: an easy stance with slightly bent knees (the paper animates the upper body
  only), feet under the hips, flat on the ground.

Targets are in arm lengths from the shoulder, in the frame the arm hangs from
(x outwards for the left hand), like the right hand's keyframes.
"""

from __future__ import annotations

import numpy as np

from ...music.notes import NoteSequence
from .config import ProceduralConfig

LEFT_REST = np.array([0.2, -0.5, 0.35])      # outwards, up, forwards
LEFT_OUT = np.array([0.7, -0.15, 0.4])
RISE_S, FALL_S = 0.3, 0.4
DROP_S, RECOVER_S = 0.08, 0.25


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def extension_envelope(times_s: np.ndarray, notes: NoteSequence, cfg: ProceduralConfig) -> np.ndarray:
    """0..1 per frame: how far the left hand is out, for the long notes."""
    env = np.zeros(len(times_s))
    long = np.flatnonzero(notes.duration_16 > cfg.long_note)
    ends = notes.offset_s
    for i in long:
        t0, t1 = notes.onset_s[i], ends[i]
        rise = min(RISE_S, 0.4 * (t1 - t0))
        lo, hi = np.searchsorted(times_s, [t0, t1 + FALL_S])
        t = times_s[lo:hi]
        e = np.where(t <= t1, _smoothstep((t - t0) / rise), 1.0 - _smoothstep((t - t1) / FALL_S))
        env[lo:hi] = np.maximum(env[lo:hi], e)
    return env


def drop_envelope(times_s: np.ndarray, notes: NoteSequence) -> np.ndarray:
    """0..1 per frame: the staccato drops -- fast, accelerating, then a dead stop, then a slow recovery."""
    env = np.zeros(len(times_s))
    ends = notes.offset_s
    for i in np.flatnonzero(notes.staccato):
        t0, t1 = notes.onset_s[i], ends[i]
        fall = min(DROP_S, 0.5 * (t1 - t0))
        hold_end = t0 + max(fall, 0.8 * (t1 - t0))
        lo, hi = np.searchsorted(times_s, [t0, hold_end + RECOVER_S])
        t = times_s[lo:hi]
        d = np.where(t < t0 + fall, ((t - t0) / fall) ** 2,
                     np.where(t <= hold_end, 1.0, 1.0 - _smoothstep((t - hold_end) / RECOVER_S)))
        env[lo:hi] = np.maximum(env[lo:hi], d)
    return env


def left_hand_targets(times_s: np.ndarray, notes: NoteSequence, cfg: ProceduralConfig) -> np.ndarray:
    """(F, 3) left-hand targets (arm lengths; x outwards)."""
    ext = extension_envelope(times_s, notes, cfg)[:, None] * cfg.extend
    drop = drop_envelope(times_s, notes)[:, None] * cfg.staccato_drop
    return LEFT_REST + ext * (LEFT_OUT - LEFT_REST) - drop * np.array([0.0, 1.0, 0.0])


def turning_beats(beats_s: np.ndarray, min_gap_s: float) -> np.ndarray:
    """The beats where a motion may change direction: each at least ``min_gap_s`` after the last one kept."""
    kept, last = [], -np.inf
    for b in beats_s:
        if b - last >= min_gap_s - 1e-9:
            kept.append(b)
            last = b
    return np.asarray(kept)


def nod_angles(times_s: np.ndarray, beats_s: np.ndarray, cfg: ProceduralConfig) -> np.ndarray:
    """Head pitch (degrees, down positive): lowest on nod beats, up half-way between."""
    # A nod turns twice (down at the beat, up between), so nods are two turns apart.
    nods = turning_beats(beats_s, 2.0 * cfg.nod_turn)
    if len(nods) < 2:
        return np.zeros(len(times_s))
    k = np.clip(np.searchsorted(nods, times_s, side="right") - 1, 0, len(nods) - 2)
    phase = np.clip((times_s - nods[k]) / (nods[k + 1] - nods[k]), 0.0, 1.0)
    angle = cfg.nod * 0.5 * (1.0 + np.cos(2.0 * np.pi * phase))
    fade = np.clip(np.minimum(times_s - nods[0] + 0.5, nods[-1] + 0.5 - times_s) / 0.5, 0.0, 1.0)
    return angle * fade


def sway_angles(times_s: np.ndarray, beats_s: np.ndarray, cfg: ProceduralConfig) -> np.ndarray:
    """Torso swing (degrees about the forward axis): at one side on a turning beat, the other on the next."""
    turns = turning_beats(beats_s, cfg.sway_turn)
    if len(turns) < 2:
        return np.zeros(len(times_s))
    side = np.where(np.arange(len(turns)) % 2 == 0, 1.0, -1.0) * cfg.sway
    side[0] = 0.0  # start upright, end upright
    return _eased(times_s, np.append(turns, turns[-1] + cfg.sway_turn), np.append(side, 0.0))


def _eased(times_s: np.ndarray, knots_s: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Cosine-eased interpolation: the motion slows into every knot and turns there."""
    k = np.clip(np.searchsorted(knots_s, times_s, side="right") - 1, 0, len(knots_s) - 2)
    u = np.clip((times_s - knots_s[k]) / (knots_s[k + 1] - knots_s[k]), 0.0, 1.0)
    w = 0.5 - 0.5 * np.cos(np.pi * u)
    return values[k] * (1.0 - w) + values[k + 1] * w

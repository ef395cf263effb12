"""Inertialization decays (``stitch``): where the source changes, the pose and velocity difference
between the old and the new motion, per joint a rotation-vector offset and for the root a position
offset, decays to zero along a cubic Hermite curve, so pose and velocity stay continuous. How long
each decay lasts: long enough not to accelerate the joint faster than the mocap does
(``decay_time``), not to carry a violent velocity past a pose neither motion has
(``carried_speed``) and, where asked, not to move a limb's end faster than a speed (``unhurried``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


#: Fastest angular acceleration an inertialization decay may add (rad/s^2): about what
#: the mocap itself reaches in its roughest 1 % of frames, so a decay hides in the motion.
BLEND_ACCEL_RAD_S2 = 300.0
#: Same for the root's position (m/s^2), across the floor and up or down: the body may glide
#: over a planted foot for a while, but a height difference held long sinks the feet into the
#: floor or lifts them off it.
BLEND_ACCEL_M_S2 = np.array([6.0, 30.0, 6.0])
#: No decay lasts longer (s): past this the two motions are mixed for too long.
BLEND_MAX_S = 1.0
#: A decay kept slow (``render``'s ``limb_speed``) lasts no longer than this for it (s): longer, the
#: two words blur into one (up to 1 s, a re-created dance's motifs were found again in its motion on
#: 0.69 of beats, 0.82 without the limit).
BLEND_UNHURRIED_S = 0.4
#: How far a carried velocity difference may swing a joint past its offset before the
#: decay brings it back (rad): more of a violent difference is dropped instead, so it
#: cannot overshoot into a pose neither motion has.
BLEND_MAX_SWING_RAD = 0.6


@dataclass(frozen=True)
class Blend:
    """An inertialization offset starting at ``t0``: value and velocity, decaying to zero.

    Rotations decay per joint over ``duration`` (J,), the root position per axis over ``pos_duration`` (3,).
    """

    t0: float
    duration: np.ndarray  # (J,) seconds
    rot_x0: np.ndarray    # (J, 3) rotation-vector offsets
    rot_v0: np.ndarray
    pos_duration: np.ndarray  # (3,) seconds
    pos_x0: np.ndarray    # (3,) root position offset
    pos_v0: np.ndarray

    @property
    def end_s(self) -> float:
        return self.t0 + max(float(np.max(self.duration)), float(np.max(self.pos_duration)))

    def at(self, t: np.ndarray):
        """The offsets at times ``t`` (n,): rotation vectors (n, J, 3) and root positions (n, 3)."""
        return self.rot_at(t), self.pos_at(t)

    def rot_at(self, t: np.ndarray) -> np.ndarray:
        return _rot_offsets(np.asarray(t, float)[:, None] - self.t0, self.duration, self.rot_x0, self.rot_v0)

    def pos_at(self, t: np.ndarray) -> np.ndarray:
        return _pos_offsets(np.asarray(t, float)[:, None] - self.t0, self.pos_duration, self.pos_x0, self.pos_v0)


def _rot_offsets(dt, duration, x0, v0):
    """Rotation offsets ``dt`` (n, 1) after a blend's start: each joint's decay over its ``duration`` (J,)."""
    h00, h10 = decay_basis(np.clip(dt / duration, 0.0, 1.0))            # (n, J)
    return h00[..., None] * x0 + (h10 * duration)[..., None] * v0


def _pos_offsets(dt, duration, x0, v0):
    """Root offsets ``dt`` (n, 1) after a blend's start: each axis's decay over its ``duration`` (3,)."""
    p00, p10 = decay_basis(np.clip(dt / duration, 0.0, 1.0))            # (n, 3)
    return p00 * x0 + p10 * duration * v0


def blends_at(blends: list, counts, t: np.ndarray, positions: bool = True):
    """``Blend.at`` of several blends at once: blend ``i`` at the next ``counts[i]`` of the times ``t``
    (n,); ``positions=False``: the rotation offsets alone (``rot_at``)."""

    def each(values):
        return np.repeat(np.stack(values), counts, axis=0)

    dt = np.asarray(t, float)[:, None] - each([b.t0 for b in blends])[:, None]
    rx = _rot_offsets(dt, each([b.duration for b in blends]), each([b.rot_x0 for b in blends]),
                      each([b.rot_v0 for b in blends]))
    if not positions:
        return rx
    return rx, _pos_offsets(dt, each([b.pos_duration for b in blends]), each([b.pos_x0 for b in blends]),
                            each([b.pos_v0 for b in blends]))


def carried_speed(size, accel, swing):
    """Fastest velocity difference a decay of an offset of ``size`` carries.

    A Hermite decay over ``T`` that starts at speed ``v`` swings past its offset by
    up to ``4/27 v T``; with ``T = decay_time(size, v)`` that is ``swing`` at::

        v = 2 sqrt(accel) swing / sqrt(24 k^2 size + 16 k swing),  k = 4/27
    """
    k = 4.0 / 27.0
    return 2.0 * np.sqrt(accel) * swing / np.sqrt(24 * k * k * np.asarray(size, float) + 16 * k * swing)


def decay_time(size, speed, min_s: float, accel):
    """Shortest decay time (>= ``min_s``, <= ``BLEND_MAX_S``) whose Hermite curve from an offset
    of ``size`` moving at ``speed`` never accelerates faster than ``accel``.

    The curve's acceleration peaks at its start, ``(6 size + 4 T speed) / T^2``; solved for T.
    """
    size, speed = np.asarray(size, float), np.asarray(speed, float)
    t = (4 * speed + np.sqrt(16 * speed**2 + 24 * accel * size)) / (2 * accel)
    low = max(min_s, 1e-3)  # a zero blend time would divide by zero
    return np.clip(t, low, max(low, BLEND_MAX_S))


def decay_basis(s):
    """Cubic Hermite weights ``(h00, h10)`` at ``s`` in [0, 1] that take an offset (value x0,
    velocity v0) to rest: ``x(s) = h00 x0 + h10 duration v0``, with x and x' zero at s = 1."""
    s = np.asarray(s, dtype=np.float64)
    return 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s


def unhurried(duration, sweep_s):
    """``duration`` long enough that a decay whose offset would take ``sweep_s`` to cross at the speed
    allowed (its angle times the limb it turns, over that speed) never moves faster: a Hermite decay
    peaks at 1.5 times its mean speed. Lengthened no further than ``BLEND_UNHURRIED_S``."""
    return np.minimum(np.maximum(duration, 1.5 * np.asarray(sweep_s, float)),
                      np.maximum(duration, BLEND_UNHURRIED_S))


def limb_reach(skeleton) -> np.ndarray:
    """(J,) how far each joint's limb reaches beyond it (m): the longest chain of bones below it."""
    reach = np.zeros(skeleton.n_joints)
    for j, end in skeleton.end_sites.items():
        reach[j] = np.linalg.norm(end)
    for j in range(skeleton.n_joints - 1, 0, -1):
        p = skeleton.parents[j]
        reach[p] = max(reach[p], reach[j] + np.linalg.norm(skeleton.offsets[j]))
    return reach

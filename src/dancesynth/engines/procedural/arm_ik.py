"""Analytic arm IK (shoulder - elbow - wrist) with a natural elbow swivel and joint limits.

Loi & Li solve the arm with IKAN's analytic method; this is the same geometry:

1. The shoulder-wrist distance fixes the elbow's flexion (law of cosines); it is
   clamped to the elbow's limits, which also keeps the wrist within reach.
2. The elbow lies on a circle about the shoulder-wrist axis; we put it where a
   relaxed arm has it, below the axis and turned ``swivel`` degrees outwards.
3. Each bone's rotation maps its rest frame (bone direction, hinge axis) onto the
   posed one, so the elbow turns about one hinge axis only and the upper arm's
   twist follows the elbow smoothly (no shortest-arc flips).

Everything is in the frame of the upper-arm joint's parent (the collar), batched
over frames.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

FORWARD = np.array([0.0, 0.0, 1.0])
DOWN = np.array([0.0, -1.0, 0.0])


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _frame(direction, hinge):
    """Orthonormal frames (..., 3, 3) with columns ``direction``, ``hinge``, their cross product."""
    d = _unit(direction)
    h = _unit(hinge - np.sum(hinge * d, axis=-1, keepdims=True) * d)
    return np.stack([d, h, np.cross(d, h)], axis=-1)


def reach_limits(upper: float, fore: float, elbow_min_deg: float, elbow_max_deg: float) -> tuple[float, float]:
    """Shortest and longest shoulder-wrist distance the elbow limits allow."""
    def dist(flex):
        return np.sqrt(upper ** 2 + fore ** 2 + 2 * upper * fore * np.cos(np.radians(flex)))
    return float(dist(elbow_max_deg)), float(dist(elbow_min_deg))


def pose_chain(top_rest, mid_rest, top_dir, mid_dir, hinge, *, bends_forward: bool = True):
    """Local rotations (F, 4) of a two-bone chain's top and middle joints pointing its bones along
    ``top_dir`` and ``mid_dir`` with the bend about ``hinge`` (= top_dir x mid_dir); ``top_rest``
    and ``mid_rest`` are the rest offsets of the middle and end joints. The middle joint turns
    about the hinge only. A (nearly) straight rest chain is taken to bend forwards (an elbow)
    or backwards (a knee)."""
    rest_hinge = np.cross(top_rest, mid_rest)
    if np.linalg.norm(rest_hinge) < 0.03 * np.linalg.norm(top_rest) * np.linalg.norm(mid_rest):
        rest_hinge = np.cross(top_rest, FORWARD) * (1.0 if bends_forward else -1.0)
    R_top = _frame(top_dir, hinge) @ _frame(top_rest, rest_hinge).T
    R_mid = _frame(mid_dir, hinge) @ _frame(mid_rest, rest_hinge).T
    q_top = Rotation.from_matrix(R_top).as_quat()
    q_mid = Rotation.from_matrix(np.swapaxes(R_top, -1, -2) @ R_mid).as_quat()
    return q_top, q_mid


def solve_arm(shoulder: np.ndarray, upper_rest: np.ndarray, fore_rest: np.ndarray, target: np.ndarray, *,
              outward: np.ndarray, swivel_deg: float, elbow_min_deg: float, elbow_max_deg: float,
              max_reach: float | None = None):
    """Local rotations (upper arm, elbow) as (F, 4) quaternions putting the wrist at ``target`` (F, 3).

    ``shoulder``: the upper-arm joint's position in its parent's frame; ``upper_rest``
    and ``fore_rest``: the rest offsets of the elbow and the wrist; ``outward``: the
    side the arm is on (unit vector). Also returns the wrist positions reached (F, 3)
    and the elbow flexion in degrees (F,).
    """
    a, b = np.linalg.norm(upper_rest), np.linalg.norm(fore_rest)
    d_min, d_max = reach_limits(a, b, elbow_min_deg, elbow_max_deg)
    if max_reach is not None:
        d_max = min(d_max, max_reach)
    to = target - shoulder
    dist = np.clip(np.linalg.norm(to, axis=-1), d_min, d_max)
    axis = _unit(to)
    wrist = shoulder + axis * dist[:, None]
    cos_s = np.clip((a ** 2 + dist ** 2 - b ** 2) / (2 * a * dist), -1.0, 1.0)
    center = shoulder + axis * (a * cos_s)[:, None]
    radius = a * np.sqrt(1.0 - cos_s ** 2)
    sw = np.radians(swivel_deg)
    ref = np.cos(sw) * DOWN + np.sin(sw) * outward
    ref = ref - np.sum(ref * axis, axis=-1, keepdims=True) * axis
    bad = np.linalg.norm(ref, axis=-1) < 1e-6        # wrist straight below: point the elbow outwards
    ref[bad] = outward
    elbow = center + _unit(ref) * radius[:, None]
    du, df = elbow - shoulder, wrist - elbow
    hinge = np.cross(du, df)
    straight = np.linalg.norm(hinge, axis=-1) < 1e-9
    hinge[straight] = np.cross(_unit(ref[straight]), du[straight])
    q_upper, q_elbow = pose_chain(upper_rest, fore_rest, du, df, hinge)
    flex = np.degrees(np.arccos(np.clip(np.sum(_unit(du) * _unit(df), axis=-1), -1.0, 1.0)))
    return q_upper, q_elbow, wrist, flex

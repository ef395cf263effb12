"""Rendering finds the rotations of all of a call's blends at once (stitch._chain_rotations): the same
frames and state, to the bit, as one by one -- also where a blend still runs at the next jump."""

from __future__ import annotations

import functools
from dataclasses import fields

import numpy as np
import pytest

from dancesynth.engines import stitch
from dancesynth.engines.decay import Blend, blends_at
from dancesynth.engines.stitch import Pieces, StitchState, render


def _same(a, b) -> bool:
    if isinstance(a, Blend) or isinstance(b, Blend):
        return (a is None) == (b is None) and all(_same(getattr(a, f.name), getattr(b, f.name)) for f in fields(Blend))
    if a is None or b is None:
        return a is b
    a, b = np.atleast_1d(a), np.atleast_1d(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def _random_pieces(style, rng, start_s: float, k: int) -> Pieces:
    length = rng.uniform(0.15, 0.8, size=k)  # short pieces: jumps closer than a blend lasts
    t0 = start_s + np.r_[0.0, np.cumsum(length)[:-1]]
    f0 = rng.uniform(5, style.n_frames - 40, size=k)
    f1 = np.minimum(f0 + length * 30.0 * rng.uniform(0.7, 1.3, size=k), style.n_frames - 2)
    count = np.cumsum(rng.choice([0.5, 1.0, 2.0], size=k + 1))
    ease = rng.uniform(0, 0.6, size=k + 1)
    return Pieces(t0, t0 + length, f0, f1, rng.random(k) < 0.8, count[:-1], count[1:], ease[:-1], ease[1:])


@pytest.mark.parametrize("blend_s, limb_speed", [(0.3, None), (0.9, None), (0.3, 1.0)])
def test_jumps_placed_together_equal_jumps_placed_one_by_one(bundled_db, monkeypatch, blend_s, limb_speed):
    rng = np.random.default_rng(int(blend_s * 10))
    batched = stitch._chain_rotations
    for style in sorted(bundled_db.styles.values(), key=lambda s: s.name)[:3]:
        states = [StitchState(), StitchState()]
        start = 0.0
        for call in range(3):  # a blend in progress carries from call to call
            pieces = _random_pieces(style, rng, start, int(rng.integers(1, 10)))
            start = float(pieces.t1[-1])
            out = []
            for i, batch in enumerate((True, False)):
                monkeypatch.setattr(stitch, "_chain_rotations", functools.partial(batched, batch=batch))
                states[i], frames = render(style, pieces, states[i], fps=30.0, end_s=start, blend_s=blend_s,
                                           inclusive_end=call == 2, limb_speed=limb_speed)
                out.append(frames)
            assert all(_same(getattr(out[0], f.name), getattr(out[1], f.name)) for f in fields(out[0]))
            assert all(_same(getattr(states[0], f.name), getattr(states[1], f.name)) for f in fields(StitchState))


def test_several_blends_at_once_are_each_blend_at_its_times():
    rng = np.random.default_rng(0)
    blends = [Blend(float(t0), rng.uniform(0.3, 1.0, 5), rng.normal(size=(5, 3)), rng.normal(size=(5, 3)),
                    rng.uniform(0.3, 1.0, 3), rng.normal(size=3), rng.normal(size=3)) for t0 in (0.0, 0.4, 1.1)]
    counts = [4, 1, 6]
    t = rng.uniform(0, 2, size=sum(counts))
    rx, px = blends_at(blends, counts, t)
    which = np.repeat(np.arange(3), counts)
    for i in range(len(t)):
        one_rx, one_px = blends[which[i]].at(t[i:i + 1])
        assert _same(rx[i], one_rx[0]) and _same(px[i], one_px[0])
    assert _same(blends_at(blends, counts, t, positions=False), rx)


def test_feet_summed_from_the_root_are_forward_kinematics_to_the_bit(bundled_db):
    from dancesynth import rotations as rot
    from dancesynth.kinematics import fk
    from dancesynth.motion.roles import find_roles

    style = sorted(bundled_db.styles.values(), key=lambda s: s.name)[0]
    sk, ankles = style.skeleton, find_roles(style.skeleton).ankles
    rng = np.random.default_rng(0)
    m = 4
    old, new = (rot.exp(rng.normal(size=(m, sk.n_joints, 3))) for _ in range(2))
    roots = rng.normal(size=(2, m, 3))
    jumps = [stitch._Jump(float(i), 0.0, 0.0, np.array([True, True]), np.zeros(2), np.zeros(2), np.zeros(6))
             for i in range(m)]
    feet = stitch._feet_steps(style, ankles, jumps, old, new)
    _, want_old = fk(old, roots[0], sk.offsets, sk.parents, only=list(ankles))
    _, want_new = fk(new, roots[1], sk.offsets, sk.parents, only=list(ankles))
    for i in range(m):
        got = feet(i, roots[0, i], roots[1, i], [0, 1])
        assert _same(got[0], want_old[i, list(ankles)]) and _same(got[1], want_new[i, list(ankles)])


@pytest.mark.parametrize("limit", [1.0, None])
def test_a_stitch_between_far_poses_does_not_whip_the_limb_across(limit):
    """Issue 31 item 5: a stitch's decay over the 0.25 s blend moved the limb's end as fast as the offset
    asked (the choreography's stitches made 60-80 % of its fastest joint motion). A jump from arm down to
    arm raised 0.8 rad, both held still, now sweeps the hand over at most ``limb_speed`` (the decay
    lengthened for it, up to ``BLEND_UNHURRIED_S``); without the limit it whips over at 1.4 m/s (30 fps)."""
    from dancesynth import rotations as rot
    from dancesynth.eval.motion_metrics import joint_speeds
    from dancesynth.motion.database import Style
    from dancesynth.types import MotionClip
    from test_metrics import ARM, biped, standing, times

    t = times(60.0, 4.0)
    down = biped(standing(t))
    raised = down.local_rot.copy()
    raised[:, ARM] = rot.exp(np.array([0.0, 0.0, 0.8]))
    n = len(t)
    style = Style("held", "test", down.skeleton, 60.0, ("down", "up"), ("d.bvh", "u.bvh"), np.array([0, n, 2 * n]),
                  np.r_[down.local_rot, raised].astype(np.float32), np.r_[down.root_pos, down.root_pos].astype(np.float32),
                  np.zeros((2 * n, 2), bool), np.ones(2 * n, np.float32), np.array([30, 90, n + 30, n + 90]),
                  np.array([120.0, 120.0]), "")
    pieces = Pieces(np.array([0.0, 1.0]), np.array([1.0, 3.0]), np.array([30.0, n + 30.0]),
                    np.array([90.0, n + 150.0]), np.array([False, True]))
    _, frames = render(style, pieces, StitchState(), fps=30.0, end_s=3.0, blend_s=0.25, inclusive_end=True,
                       limb_speed=limit)
    hand = joint_speeds(MotionClip(style.skeleton, 30.0, frames.root_pos, frames.local_rot))[:, ARM + 1]
    if limit is not None:
        assert hand.max() <= limit * 1.1, hand.max()
    else:
        assert hand.max() > 1.3, hand.max()

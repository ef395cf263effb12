"""Hands kept out of the head (engines/handclear.py) on real mocap with a hand driven through the head."""

import numpy as np
import pytest

from dancesynth import rotations as rot
from dancesynth.engines.handclear import keep_hands_out_of_head
from dancesynth.eval.artefacts import hand_in_head_frames, joint_steps_deg
from dancesynth.kinematics import chain_local_rotations, fk, two_bone_ik
from dancesynth.motion.database import open_database
from dancesynth.motion.roles import find_roles, head_centre
from dancesynth.types import MotionClip


@pytest.fixture(scope="module")
def swept():
    """A salsa clip whose left hand sweeps through the head's centre, side to side, for a second."""
    style = open_database().styles["salsa-97-124bpm"]
    clip = style.clip(0)
    sk, fps = clip.skeleton, clip.fps
    roles = find_roles(sk)
    local, root = clip.local_rot[: int(4 * fps)].copy(), clip.root_pos[: int(4 * fps)].copy()
    g_rot, g_pos = fk(local, root, sk.offsets, sk.parents)
    centre, _ = head_centre(sk, roles.head, g_rot, g_pos)
    chain = (roles.shoulders[0], roles.elbows[0], roles.wrists[0])
    a, b = int(1.5 * fps), int(2.5 * fps)
    t = np.linspace(0.0, 1.0, b - a)
    side = rot.apply(g_rot[a:b, 0], np.array([1.0, 0.0, 0.0]))       # the body's left-right axis
    path = centre[a:b] + side * (0.15 * np.cos(np.pi * t))[:, None]    # 15 cm one side -> the centre -> the other
    ease = np.sin(np.pi * t) ** 2                                      # in from and back to the mocap's own arm
    target = g_pos[a:b, chain[2]] + ease[:, None] * (path - g_pos[a:b, chain[2]])
    rows, cols = np.arange(a, b)[:, None], np.array(chain)
    new = two_bone_ik(g_rot[rows, cols], g_pos[rows, cols], (0, 1, 2), target)
    local[rows, cols] = chain_local_rotations(g_rot[a:b, sk.parents[chain[0]]], new)
    return MotionClip(sk, fps, root, local), roles, (a, b)


def test_a_hand_swept_through_the_head_is_kept_out_without_a_jump(swept):
    clip, roles, (a, b) = swept
    assert hand_in_head_frames(clip) > 0.03                                # the hand is in the head, visibly
    fixed = MotionClip(clip.skeleton, clip.fps, clip.root_pos,
                       keep_hands_out_of_head(clip.skeleton, roles, clip.local_rot, clip.root_pos, clip.fps))
    assert hand_in_head_frames(fixed) == 0.0
    # No arm joint turns much faster than in the input: the push eases in and out and keeps one side.
    assert joint_steps_deg(fixed.local_rot).max() < joint_steps_deg(clip.local_rot).max() + 10.0
    margin = int(0.3 * clip.fps)                                           # the ease reaches 0.2 s out
    untouched = np.r_[0:a - margin, b + margin:clip.n_frames]
    assert np.array_equal(fixed.local_rot[untouched], clip.local_rot[untouched])


def test_a_dance_without_hands_near_the_head_is_unchanged():
    clip = open_database().styles["salsa-97-124bpm"].clip(0)
    roles = find_roles(clip.skeleton)
    g_rot, g_pos = fk(clip.local_rot, clip.root_pos, clip.skeleton.offsets, clip.skeleton.parents)
    centre, _ = head_centre(clip.skeleton, roles.head, g_rot, g_pos)
    far = np.linalg.norm(g_pos[:, list(roles.wrists)] - centre[:, None], axis=-1).min(axis=1) > 0.3
    clear = np.flatnonzero(far)[:200]
    out = keep_hands_out_of_head(clip.skeleton, roles, clip.local_rot[clear], clip.root_pos[clear], clip.fps)
    assert np.array_equal(out, clip.local_rot[clear])

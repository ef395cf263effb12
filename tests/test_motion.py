"""Motion analysis on synthetic motion whose answers are known, and on real fixtures."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import REPO
from dancesynth import rotations as rot
from dancesynth.io.bvh import read_bvh
from dancesynth.kinematics import clip_fk, fk, two_bone_ik
from dancesynth.motion import beats as mb
from dancesynth.motion.features import foot_contacts, interval_energy, kinetic_energy
from dancesynth.motion.roles import bone_masses, find_roles
from dancesynth.types import MotionClip, Skeleton

FIXTURES = sorted((REPO / "tests" / "data" / "mocap").rglob("*.bvh"))


def swinging_body(fps=60.0, seconds=20.0, period_s=1.0):
    """Root, a spine and an arm; the arm swings sinusoidally with ``period_s``.

    The arm turns back at every extreme of the swing: twice per period.
    """
    sk = Skeleton(("root", "spine", "arm", "hand"), np.array([-1, 0, 1, 2]),
                  np.array([[0, 0, 0], [0, 0.5, 0], [0.2, 0.3, 0], [0.6, 0, 0]]),
                  (("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"),
                   ("Zrotation", "Xrotation", "Yrotation"), ("Zrotation", "Xrotation", "Yrotation"),
                   ("Zrotation", "Xrotation", "Yrotation")))
    t = np.arange(int(seconds * fps)) / fps
    angle = 60.0 * np.sin(2 * np.pi * t / period_s)
    local = np.tile(rot.IDENTITY, (len(t), 4, 1))
    local[:, 2] = rot.from_euler(np.stack([angle, np.zeros_like(t), np.zeros_like(t)], -1), "ZXY")
    root = np.tile([0.0, 1.0, 0.0], (len(t), 1))
    clip = MotionClip(sk, fps, root, local)
    turns = np.round((np.arange(1, 2 * seconds / period_s) * period_s / 2 - period_s / 4) * fps).astype(int)
    return clip, turns[turns > 0]


def test_pca_beats_land_on_the_turns_of_a_swing():
    clip, turns = swinging_body(period_s=1.0)
    g_rot, g_pos = clip_fk(clip)
    beats = mb.pca_beats(g_pos, g_rot[:, 0], clip.fps)
    inner = beats[(beats > 60) & (beats < clip.n_frames - 60)]
    dist = np.abs(inner[:, None] - turns[None, :]).min(axis=1)
    assert np.all(dist <= 3), dist  # within 50 ms at 60 fps
    assert 60.0 / np.median(np.diff(beats) / clip.fps) == pytest.approx(120.0, rel=0.03)


def test_kinematic_beats_are_speed_minima():
    clip, turns = swinging_body(period_s=0.8)
    _, g_pos = clip_fk(clip)
    beats, smooth = mb.kinematic_beats(mb.summed_speed(g_pos, clip.fps), clip.fps)
    inner = beats[(beats > 30) & (beats < clip.n_frames - 30)]
    assert len(inner) >= len(turns) - 4
    assert np.abs(inner[:, None] - turns[None, :]).min(axis=1).max() <= 2
    assert smooth.shape == (clip.n_frames,)


def test_beats_snap_to_nearby_accents_only():
    beats = np.array([0, 30, 60, 90, 120])
    accents = np.array([4, 33, 47, 61, 62, 119])
    # 4 and 33 are within 0.2 * 30 = 6 frames; 47 is too far from 60's neighbours;
    # 60 takes 61; 90 has no accent near; 120 takes 119.
    np.testing.assert_array_equal(mb.snap_beats(beats, accents, fraction=0.2), [4, 33, 61, 90, 119])
    np.testing.assert_array_equal(mb.snap_beats(beats, accents, fraction=0.0), beats)
    # Two beats that would land on one accent both stay where they were.
    np.testing.assert_array_equal(mb.snap_beats(np.array([10, 14, 40]), np.array([12]), fraction=0.5), [10, 14, 40])
    assert mb.snap_beats(beats, np.zeros(0, dtype=int), fraction=0.2).tolist() == beats.tolist()


def test_kinetic_energy_of_a_gliding_body():
    clip, _ = swinging_body()
    clip.local_rot[:] = rot.IDENTITY
    clip.root_pos[:, 0] = np.arange(clip.n_frames) * (2.0 / clip.fps)  # 2 m/s
    _, g_pos = clip_fk(clip)
    masses = bone_masses(clip.skeleton, body_mass_kg=70.0)
    energy = kinetic_energy(g_pos, clip.fps, masses)
    assert energy == pytest.approx(np.full(clip.n_frames, 0.5 * 70.0 * 4.0))
    beats = np.array([0, 60, 180])
    assert interval_energy(energy, beats, clip.fps) == pytest.approx([140.0, 280.0])


def test_foot_contacts_follow_a_stepping_foot():
    fps, n = 60.0, 240
    feet = np.zeros((n, 2, 2, 3))
    lifted = (np.arange(n) // 30) % 2 == 1           # the left foot lifts every other half second
    feet[:, 0, :, 1] = np.where(lifted, 0.15, 0.02)[:, None]
    feet[:, 0, :, 0] = np.cumsum(np.where(lifted, 1.0 / fps, 0.0))[:, None]  # it moves only in the air
    feet[:, 1, :, 1] = 0.02                           # the right foot stays planted
    contacts = foot_contacts(feet, fps)
    assert contacts[:, 1].all()
    core = np.r_[0:25, 65:85, 125:145]  # away from the transitions
    assert contacts[core, 0].all()
    assert not contacts[35:55, 0].any() and not contacts[95:115, 0].any()


@pytest.mark.parametrize("path", FIXTURES, ids=lambda p: p.parent.name)
def test_roles_are_found_on_every_skeleton(path):
    clip = read_bvh(path)
    roles = find_roles(clip.skeleton)
    _, pos = clip_fk(clip)
    for side in (0, 1):
        assert clip.skeleton.parents[roles.ankles[side]] == roles.knees[side]
        assert clip.skeleton.parents[roles.knees[side]] == roles.hips[side]
    # The head is above the ankles, the left leg on the character's left (+X of the root's frame
    # for these Y-up, Z-forward skeletons at rest).
    assert np.all(pos[:, roles.head, 1] > pos[:, roles.ankles[0], 1])


def test_two_bone_ik_keeps_the_knee_in_front_when_the_input_leg_bends_backwards():
    # A blend can carry a leg straight and on past straight (bent backwards) while the foot
    # lock asks for a bent knee: the knee must stay in front, not swing back in one frame.
    sk = Skeleton(("root", "hip", "knee", "ankle"), np.array([-1, 0, 1, 2]),
                  np.array([[0, 0, 0], [0, 0, 0], [0, -0.45, 0], [0, -0.4, 0]]),
                  (("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"),)
                  + (("Zrotation", "Xrotation", "Yrotation"),) * 3)
    bend = np.radians(np.linspace(20.0, -10.0, 31))          # positive: the knee in front (+Z)
    local = np.tile(rot.IDENTITY, (31, 4, 1))
    local[:, 1] = rot.exp(np.stack([-bend / 2, 0 * bend, 0 * bend], -1))
    local[:, 2] = rot.exp(np.stack([bend, 0 * bend, 0 * bend], -1))
    g_rot, g_pos = fk(local, np.tile([0.0, 1.0, 0.0], (31, 1)), sk.offsets, sk.parents)
    hip, ankle = g_pos[:, 1], g_pos[:, 3]
    target = hip + 0.97 * 0.85 * (ankle - hip) / np.linalg.norm(ankle - hip, axis=-1, keepdims=True)
    forward = np.tile([0.0, 0.0, 1.0], (31, 1))
    new = two_bone_ik(g_rot, g_pos, (1, 2, 3), target, bend_toward=forward, pole_weight=0.3)
    knee = hip + rot.apply(new[:, 0], np.array([0.0, -0.45, 0.0]))
    assert np.all(knee[:, 2] - (hip[:, 2] + target[:, 2]) / 2 > 0.05)   # about 28 degrees of bend, in front
    knee_turn = np.degrees(rot.angle(new[1:, 1], new[:-1, 1]))
    assert knee_turn.max() < 5.0


def test_two_bone_ik_reaches_reachable_targets_and_keeps_bone_lengths():
    clip = read_bvh(FIXTURES[0])
    roles = find_roles(clip.skeleton)
    g_rot, g_pos = clip_fk(clip)
    chain = (roles.hips[0], roles.knees[0], roles.ankles[0])
    target = g_pos[:, chain[2]] + np.array([0.05, 0.03, -0.04])
    new = two_bone_ik(g_rot, g_pos, chain, target)
    local = clip.local_rot.copy()
    parent = clip.skeleton.parents[chain[0]]
    local[:, chain[0]] = rot.mul(rot.inv(g_rot[:, parent]), new[:, 0])
    local[:, chain[1]] = rot.mul(rot.inv(new[:, 0]), new[:, 1])
    local[:, chain[2]] = rot.mul(rot.inv(new[:, 1]), new[:, 2])
    g2_rot, g2_pos = fk(local, clip.root_pos, clip.skeleton.offsets, clip.skeleton.parents)
    assert np.abs(g2_pos[:, chain[2]] - target).max() < 1e-5
    # The foot keeps its orientation in the world.
    assert np.degrees(rot.angle(g2_rot[:, chain[2]], g_rot[:, chain[2]])).max() < 1e-6

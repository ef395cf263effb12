"""The metric functions on inputs whose answers are known analytically, and on bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dancesynth import rotations as rot
from dancesynth.errors import InputError
from dancesynth.eval import metrics as M
from dancesynth.types import MotionClip, Skeleton
from signals import beat_grid

R3 = ("Zrotation", "Xrotation", "Yrotation")
ARM = 10  # joint index of LeftArm in ``biped``


def biped_skeleton() -> Skeleton:
    """Hips at the root, two legs (hip 0.9 m above the toes), a spine, an arm and a hand.

    With the root at y = 0.9 and no rotation, ankles are at y = 0.05 and toe joints at 0.
    """
    names = ("Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "RightUpLeg", "RightLeg", "RightFoot",
             "RightToeBase", "Spine", "LeftArm", "LeftHand")
    parents = np.array([-1, 0, 1, 2, 3, 0, 5, 6, 7, 0, 9, 10])
    offsets = np.array([[0, 0, 0], [0.1, 0, 0], [0, -0.45, 0], [0, -0.4, 0], [0, -0.05, 0.12],
                        [-0.1, 0, 0], [0, -0.45, 0], [0, -0.4, 0], [0, -0.05, 0.12], [0, 0.3, 0], [0.2, 0.2, 0],
                        [0.3, 0, 0]])
    channels = (("Xposition", "Yposition", "Zposition") + R3,) + (R3,) * 11
    return Skeleton(names, parents, offsets, channels)


def biped(root_pos, local_rot=None, fps: float = 60.0) -> MotionClip:
    root_pos = np.asarray(root_pos, dtype=float)
    if local_rot is None:
        local_rot = np.tile(rot.IDENTITY, (len(root_pos), 12, 1))
    return MotionClip(biped_skeleton(), fps, root_pos, local_rot)


def times(fps: float, seconds: float) -> np.ndarray:
    return np.arange(int(round(seconds * fps))) / fps


def standing(t, x=None, y=0.9, z=None) -> np.ndarray:
    zero = np.zeros_like(t)
    return np.stack([zero if x is None else x, zero + y, zero if z is None else z], axis=-1)


# ---------------------------------------------------------------------------------------------
# Kinematic beats


def test_kinematic_beats_are_the_known_speed_minima():
    fps, period = 60.0, 0.77  # turning points fall between frames
    t = times(fps, 6.0)
    clip = biped(standing(t, x=0.2 * np.sin(2 * np.pi * t / period)))
    beats, speed, smooth = M.kinematic_beats(clip)
    assert speed.shape == smooth.shape == (clip.n_frames,)
    truth = period / 4 + period / 2 * np.arange(16)
    truth = truth[truth < t[-1] - 0.1]  # not in the last 0.1 s (half a smoothing window)
    assert np.abs(beats[:, None] - truth[None, :]).min(axis=1).max() <= 1.0 / fps  # no false beat
    assert np.abs(truth[:, None] - beats[None, :]).min(axis=1).max() <= 1.0 / fps  # none missed
    # Summed speed of 12 joints moving with the root: 12 * |x'(t)| (central differences).
    mid = slice(1, -1)
    expect = 12 * np.abs(np.gradient(0.2 * np.sin(2 * np.pi * t / period)) * fps)
    np.testing.assert_allclose(speed[mid], expect[mid], rtol=1e-9)


def test_kinematic_beats_ignore_the_dips_of_a_still_body():
    fps, period = 60.0, 0.8
    t = times(fps, 6.0)
    x = 0.2 * np.sin(2 * np.pi * np.minimum(t, 3.0) / period)  # dances 3 s, then stands still
    x = x + np.random.default_rng(0).normal(0.0, 2e-4, t.size) * (t > 3.0)  # sensor noise
    clip = biped(standing(t, x=x))
    beats, _, _ = M.kinematic_beats(clip)
    assert beats.size >= 6 and beats.max() < 3.1
    every, _, _ = M.kinematic_beats(clip, min_prominence_frac=0.0)
    assert np.sum(every > 3.3) >= 3


def test_kinematic_beats_of_a_clip_shorter_than_the_smoothing_window():
    clip = biped(standing(times(60.0, 0.1)))
    beats, speed, smooth = M.kinematic_beats(clip)
    assert beats.size == 0 and speed.size == smooth.size == 6


# ---------------------------------------------------------------------------------------------
# Beat alignment


def test_beat_align_score_exact_values():
    music = np.array([1.0, 2.0, 3.0])
    assert M.beat_align_score(music, music) == 1.0
    assert M.beat_align_score(music, music + 0.05) == pytest.approx(math.exp(-0.5), rel=1e-9)
    assert M.beat_align_score(music, music + 0.1, sigma_s=0.1, average_over="music") == pytest.approx(math.exp(-0.5))


def test_beat_align_score_directions_differ_with_extra_motion_beats():
    music = np.array([1.0, 2.0, 3.0])
    motion = np.array([1.0, 1.5, 2.0, 2.5, 3.0])  # every beat marked, plus two off-beat accents
    assert M.beat_align_score(music, motion, average_over="music") == 1.0
    expected = (3 + 2 * math.exp(-0.25 / (2 * 0.05**2))) / 5
    assert M.beat_align_score(music, motion, average_over="motion") == pytest.approx(expected)
    # ... and the other way round: the dance skips beats.
    assert M.beat_align_score(motion, music, average_over="motion") == 1.0


def test_beat_align_score_with_kinematic_beats_of_a_synthetic_dance():
    fps, period = 60.0, 0.8
    t = times(fps, 4.0)
    beats, _, _ = M.kinematic_beats(biped(standing(t, x=0.2 * np.sin(2 * np.pi * t / period))))
    music = period / 4 + period / 2 * np.arange(10)
    assert M.beat_align_score(music[music < 3.9], beats) >= math.exp(-((1 / fps) ** 2) / (2 * 0.05**2))


def test_hit_rate_and_aristidou_ratios():
    music = np.array([1.0, 2.0, 3.0, 4.0])
    motion = np.array([1.02, 2.05, 3.2])
    assert M.hit_rate(music, motion, window_s=0.05) == 0.5  # 50 ms exactly is a hit
    assert M.hit_rate(music, motion, window_s=0.3) == 0.75
    assert M.beat_count_ratio(music, motion) == 0.75
    assert M.aligned_beat_ratio(music, motion, window_s=1 / 60) == 0.0
    assert M.aligned_beat_ratio(music, [1.01, 2.05, 3.2], window_s=1 / 60) == pytest.approx(1 / 3)
    assert M.aligned_beat_ratio(music, [1.0, 2.0 + 1 / 60, 2.5], window_s=1 / 60) == pytest.approx(2 / 3)


def test_undefined_beat_metrics_have_their_stated_values():
    assert math.isnan(M.beat_align_score([1.0, 2.0], [], average_over="motion"))
    assert M.beat_align_score([1.0, 2.0], [], average_over="music") == 0.0
    assert M.beat_align_score([], [1.0], average_over="motion") == 0.0
    assert math.isnan(M.hit_rate([], [1.0]))
    assert M.hit_rate([1.0], []) == 0.0
    assert math.isnan(M.beat_count_ratio([], [1.0]))
    assert M.beat_count_ratio([1.0], []) == 0.0
    assert math.isnan(M.aligned_beat_ratio([1.0], [], window_s=0.01))
    assert M.aligned_beat_ratio([], [1.0], window_s=0.01) == 0.0


def test_beat_metrics_ignore_the_order_of_the_beats():
    assert M.beat_align_score([3.0, 1.0, 2.0], [2.0, 3.0, 1.05]) == M.beat_align_score([1, 2, 3], [1.05, 2, 3])


# ---------------------------------------------------------------------------------------------
# Beat tracking


def test_beat_tracking_scores_on_a_click_track_grid():
    ref = beat_grid(120.0, 30.0)
    exact = M.beat_tracking_scores(ref, ref)
    assert exact == dict.fromkeys(("f_measure", "cmlc", "cmlt", "amlc", "amlt", "p_score"), 1.0)
    assert M.beat_f_measure(ref, ref + 0.05) == 1.0
    assert M.beat_f_measure(ref, ref + 0.1) == 0.0
    assert M.beat_f_measure(ref, ref + 0.1, window_s=0.11) == 1.0
    half = M.beat_tracking_scores(ref, ref[::2])
    assert half["f_measure"] == pytest.approx(2 / 3)
    assert half["cmlt"] == 0.0 and half["amlt"] == 1.0
    offbeat = M.beat_tracking_scores(ref, ref + 0.25)
    assert offbeat["f_measure"] == 0.0 and offbeat["cmlt"] == 0.0 and offbeat["amlt"] > 0.9


def test_beat_tracking_skips_the_first_seconds():
    ref = beat_grid(120.0, 30.0)
    est = np.concatenate([[0.3, 1.1, 2.9, 4.2], ref[ref >= 5.0]])
    assert M.beat_f_measure(ref, est) == 1.0
    assert M.beat_f_measure(ref, est, skip_s=0.0) < 0.95


def test_beat_tracking_without_beats():
    scores = M.beat_tracking_scores([1.0, 2.0], [1.0, 2.0])  # all before skip_s
    assert all(math.isnan(v) for v in scores.values())
    assert M.beat_tracking_scores(beat_grid(120.0, 30.0), []) == dict.fromkeys(scores, 0.0)
    with pytest.raises(InputError, match="seconds"):
        M.beat_f_measure(np.arange(10.0) * 44100, np.arange(10.0) * 44100)


# ---------------------------------------------------------------------------------------------
# Intensity, signature, time warp


def test_intensity_correlation_is_spearman():
    loud = np.array([-30.0, -20.0, -12.0, -6.0, -3.0])
    energy = np.array([1.0, 2.0, 2.5, 90.0, 1000.0])
    assert M.intensity_correlation(loud, energy) == pytest.approx(1.0)
    assert M.intensity_correlation(loud, energy[::-1]) == pytest.approx(-1.0)
    assert M.intensity_correlation([1, 2, 3, 4, 5], [2, 1, 4, 3, 5]) == pytest.approx(0.8)  # 1 - 6*4/(5*24)
    assert M.intensity_correlation([1, 2, 2, 3], [1, 2, 3, 4]) == pytest.approx(0.9486832980505138)  # ties
    assert M.intensity_correlation([-np.inf, -10.0, -5.0], [0.0, 1.0, 2.0]) == pytest.approx(1.0)
    assert math.isnan(M.intensity_correlation([1.0, 2.0], [1.0, 2.0]))
    assert math.isnan(M.intensity_correlation([1.0, 1.0, 1.0], [1.0, 2.0, 3.0]))


def test_signature_chi2_on_hand_made_histograms():
    assert M.signature_chi2([1, 2, 3], [2, 4, 6]) == 0.0
    assert M.signature_chi2([1, 0], [0, 1]) == 1.0
    assert M.signature_chi2([1, 1, 2, 0], [1, 3, 0, 0]) == pytest.approx(0.375)  # ½(0 + .25/1 + .25/.5)
    assert M.signature_chi2([0.2, 0.8], [0.5, 0.5]) == M.signature_chi2([0.5, 0.5], [0.2, 0.8])


def test_time_warp_stats_on_known_rates():
    s = M.time_warp_stats([1.0, 2.0, 0.5, 1.05, 0.75, 1.2])
    assert s["median_abs_log2"] == pytest.approx((math.log2(1.2) + math.log2(4 / 3)) / 2)
    assert s["frac_over_10pct"] == pytest.approx(4 / 6)
    assert s["frac_over_25pct"] == pytest.approx(3 / 6)
    assert (s["min"], s["max"]) == (0.5, 2.0)
    assert all(math.isnan(v) for v in M.time_warp_stats([]).values())


def test_percentile_rank():
    assert M.percentile_rank(5.0, np.arange(10.0)) == 60.0
    assert M.percentile_rank(100.0, np.arange(10.0)) == 100.0
    assert math.isnan(M.percentile_rank(1.0, []))


# ---------------------------------------------------------------------------------------------
# Smoothness


def popping_arm(fps=60.0, seconds=2.0, pop_deg=10.0, pop_s=1.0):
    """The arm turns at 90 deg/s about Z and pops forward by ``pop_deg`` at ``pop_s``."""
    t = times(fps, seconds)
    angle = 90.0 * t + pop_deg * (t >= pop_s - 1e-9)
    local = np.tile(rot.IDENTITY, (t.size, 12, 1))
    local[:, ARM] = rot.from_euler(np.stack([angle, 0 * t, 0 * t], -1), "ZXY")
    return biped(standing(t), local, fps)


def test_angular_velocity_jump_of_a_pop():
    clip = popping_arm()
    jumps = M.angular_velocity_jumps(clip)
    # 1.5 deg/frame, then 11.5 deg in one frame (690 deg/s), then 1.5 again: |690 - 90| = 600.
    np.testing.assert_allclose(jumps[[59, 60]], 600.0, rtol=1e-6)
    assert np.delete(jumps, [59, 60]).max() < 1e-6
    assert M.transition_jump(clip, [1.0]) == pytest.approx(600.0, rel=1e-6)
    assert M.transition_jump(clip, [1.0 + 2 / 60]) == pytest.approx(600.0, rel=1e-6)  # within 2 frames
    assert M.transition_jump(clip, [1.0 + 4 / 60]) < 1e-6
    np.testing.assert_allclose(M.transition_jumps(clip, [1.5, 0.5, 1.0]), [0, 0, 600], atol=1e-6)
    assert math.isnan(M.transition_jump(clip, []))


def test_transition_times_in_frames_are_rejected():
    with pytest.raises(InputError, match="not frames"):
        M.transition_jump(popping_arm(), [60])


def test_mean_jerk_of_a_cubic_path():
    t = times(60.0, 2.0)
    assert M.mean_jerk(biped(standing(t, x=t**3))) == pytest.approx(6.0, rel=1e-6)
    assert M.mean_jerk(biped(standing(t, x=3 * t**2))) == pytest.approx(0.0, abs=1e-6)
    assert math.isnan(M.mean_jerk(biped(standing(t[:3]))))


# ---------------------------------------------------------------------------------------------
# Feet


def test_foot_skate_planted_and_sliding():
    t = times(60.0, 2.0)
    assert M.foot_skate(biped(standing(t))) == 0.0
    assert M.foot_skate(biped(standing(t, x=0.5 * t))) == pytest.approx(0.5)
    assert M.foot_skate(biped(standing(t, x=0.3 * t, z=0.4 * t))) == pytest.approx(0.5)
    lifted = biped(standing(t, x=0.5 * t, y=0.9 + 0.2 * (t > 1.0)))  # slides only while on the floor
    assert M.foot_skate(lifted, floor_m=0.0) == pytest.approx(0.5)
    assert math.isnan(M.foot_skate(biped(standing(t, y=1.5)), floor_m=0.0))  # never on the floor
    no_contact = np.zeros((t.size, 2), dtype=bool)
    assert math.isnan(M.foot_skate(biped(standing(t, x=0.5 * t)), contacts=no_contact))


def test_ground_penetration_known_depth():
    t = times(60.0, 2.0)
    sunk = biped(standing(t, y=0.87))  # toes 3 cm below y = 0
    assert M.ground_penetration(sunk, floor_m=0.0) == pytest.approx(0.03)
    assert M.ground_penetration(sunk, floor_m=0.0, statistic="max") == pytest.approx(0.03)
    assert M.ground_penetration(sunk) == 0.0  # estimated floor: where the feet stand
    dips = biped(standing(t, y=np.where(np.arange(t.size) % 10 == 0, 0.8, 0.9)))  # 10 % of frames 10 cm down
    assert M.floor_height(M.feet_of(dips)) == pytest.approx(0.0)
    assert M.ground_penetration(dips) == pytest.approx(0.01)
    assert M.ground_penetration(dips, statistic="max") == pytest.approx(0.1)


def edge_pfc(joints: np.ndarray) -> float:
    """EDGE's calc_physical_score for one clip at 30 fps, joints = (root, LA, LT, RA, RT), Y up."""
    dt = 1 / 30
    root_v = (joints[1:, 0] - joints[:-1, 0]) / dt
    root_a = (root_v[1:] - root_v[:-1]) / dt
    root_a[:, 1] = np.maximum(root_a[:, 1], 0)
    root_a = np.linalg.norm(root_a, axis=-1)
    root_a = root_a / root_a.max()
    feet = joints[:, 1:][..., [0, 2]]
    foot_v = np.linalg.norm(feet[2:] - feet[1:-1], axis=-1)
    left, right = np.minimum(foot_v[:, 0], foot_v[:, 1]), np.minimum(foot_v[:, 2], foot_v[:, 3])
    return float(np.mean(left * right * root_a) * 10000)


def kicking(fps):
    t = times(fps, 3.0)
    local = np.tile(rot.IDENTITY, (t.size, 12, 1))
    local[:, 1] = rot.from_euler(np.stack([0 * t, 25 * np.sin(3 * t), 0 * t], -1), "ZXY")
    local[:, 5] = rot.from_euler(np.stack([0 * t, 15 * np.sin(2 * t + 1), 0 * t], -1), "ZXY")
    return biped(standing(t, x=0.3 * t**2, y=0.9 + 0.02 * np.sin(5 * t), z=0.05 * t**3), local, fps)


def test_pfc_follows_edge():
    from dancesynth.kinematics import clip_fk

    clip = kicking(30.0)
    _, g_pos = clip_fk(clip)
    feet = M.feet_of(clip)
    joints = np.concatenate([g_pos[:, :1], feet.reshape(-1, 4, 3)], axis=1)
    assert M.pfc(clip) == pytest.approx(edge_pfc(joints), rel=1e-9)
    assert M.pfc(clip) > 1.0
    assert M.pfc(kicking(60.0)) == pytest.approx(M.pfc(clip), rel=0.05)  # per 1/30 s at any fps
    t = times(30.0, 2.0)
    assert M.pfc(biped(standing(t, y=0.9 + 0.1 * np.sin(4 * t)))) == 0.0  # feet never move sideways
    assert M.pfc(biped(standing(t, x=0.5 * t))) == 0.0                  # root never accelerates


def test_pfc_scores_five_second_clips_and_averages_them_as_edge_does():
    from dancesynth.kinematics import clip_fk

    t = times(30.0, 12.0)
    local = np.tile(rot.IDENTITY, (t.size, 12, 1))
    local[:, 1] = rot.from_euler(np.stack([0 * t, 25 * np.sin(3 * t), 0 * t], -1), "ZXY")
    local[:, 5] = rot.from_euler(np.stack([0 * t, 15 * np.sin(2 * t + 1), 0 * t], -1), "ZXY")
    root_x = 0.3 * np.sin(0.7 * t) + 0.02 * t**2
    clip = biped(standing(t, x=root_x, y=0.9 + 0.02 * np.sin(5 * t), z=0.1 * np.sin(0.5 * t)), local, 30.0)
    _, g_pos = clip_fk(clip)
    joints = np.concatenate([g_pos[:, :1], M.feet_of(clip).reshape(-1, 4, 3)], axis=1)
    # 360 frames: windows [0, 150) and [150, 360) (the 2 s tail joins the second).
    assert M.pfc(clip) == pytest.approx(np.mean([edge_pfc(joints[:150]), edge_pfc(joints[150:])]), rel=1e-9)
    assert M.pfc(clip, window_s=None) == pytest.approx(edge_pfc(joints), rel=1e-9)
    # A jolt in the last seconds no longer rescales the first window's accelerations.
    jolted = biped(standing(t, x=root_x + 0.2 * (t > 11.0), y=0.9 + 0.02 * np.sin(5 * t),
                            z=0.1 * np.sin(0.5 * t)), local, 30.0)
    _, j_pos = clip_fk(jolted)
    j_joints = np.concatenate([j_pos[:, :1], M.feet_of(jolted).reshape(-1, 4, 3)], axis=1)
    assert M.pfc(jolted) == pytest.approx(np.mean([edge_pfc(joints[:150]), edge_pfc(j_joints[150:])]), rel=1e-9)
    assert edge_pfc(j_joints[150:]) != pytest.approx(edge_pfc(joints[150:]), rel=0.01)


def test_beat_interval_energy_of_a_gliding_body():
    t = times(60.0, 2.0)
    clip = biped(standing(t, x=2.0 * t))
    energy = M.beat_interval_energy(clip, [-0.5, 0.0, 0.5, 1.0, 1.5, 2.5])
    # 70 kg at 2 m/s: 140 J, for 0.5 s per interval. The first and last intervals leave the clip.
    assert np.isnan(energy[[0, 4]]).all()
    np.testing.assert_allclose(energy[1:4], 70.0, rtol=1e-9)


# ---------------------------------------------------------------------------------------------
# Bad input


ARRAY_METRICS = [
    lambda a: M.beat_align_score(a, [1.0]),
    lambda a: M.beat_align_score([1.0], a, average_over="music"),
    lambda a: M.hit_rate(a, [1.0]),
    lambda a: M.beat_count_ratio([1.0], a),
    lambda a: M.aligned_beat_ratio(a, [1.0], window_s=0.02),
    lambda a: M.beat_tracking_scores(a, [6.0]),
    lambda a: M.beat_f_measure([6.0], a),
    lambda a: M.intensity_correlation(a, [1.0, 2.0, 3.0]),
    lambda a: M.intensity_correlation([1.0, 2.0, 3.0], a),
    lambda a: M.signature_chi2(a, [1.0, 2.0, 3.0]),
    lambda a: M.time_warp_stats(a),
    lambda a: M.percentile_rank(1.0, a),
    lambda a: M.transition_jump(popping_arm(), a),
]


@pytest.mark.parametrize("metric", ARRAY_METRICS)
@pytest.mark.parametrize("bad", [[1.0, np.nan, 3.0], [[1.0, 2.0], [3.0, 4.0]], "abc"])
def test_array_metrics_reject_nan_and_wrong_shapes(metric, bad):
    with pytest.raises(InputError, match="non-finite|NaN|1-D|list"):
        metric(bad)


@pytest.mark.parametrize("call, match", [
    (lambda: M.beat_align_score([1.0], [1.0], sigma_s=-0.05), "sigma_s must be a positive"),
    (lambda: M.beat_align_score([1.0], [1.0], sigma_s=0.0), "sigma_s"),
    (lambda: M.beat_align_score([1.0], [1.0], average_over="both"), "average_over"),
    (lambda: M.hit_rate([1.0], [1.0], window_s=-1), "window_s"),
    (lambda: M.hit_rate([1.0], [1.0], window_s=float("nan")), "window_s"),
    (lambda: M.aligned_beat_ratio([1.0], [1.0], window_s="1 frame"), "window_s"),
    (lambda: M.beat_tracking_scores([6.0], [6.0], skip_s=-1), "skip_s"),
    (lambda: M.intensity_correlation([1.0, 2.0, 3.0], [1.0, 2.0]), "one value per beat interval"),
    (lambda: M.signature_chi2([1.0, 2.0], [1.0, 2.0, 3.0]), "same motifs"),
    (lambda: M.signature_chi2([1.0, -2.0], [1.0, 2.0]), "negative"),
    (lambda: M.signature_chi2([0.0, 0.0], [1.0, 2.0]), "all zeros"),
    (lambda: M.time_warp_stats([1.0, 0.0]), "positive"),
    (lambda: M.time_warp_stats([1.0, -2.0]), "positive"),
    (lambda: M.kinematic_beats(popping_arm(), smooth_s=-0.1), "smooth_s"),
    (lambda: M.kinematic_beats(popping_arm(), polyorder=1.5), "polyorder"),
    (lambda: M.kinematic_beats(popping_arm(), global_pos=np.zeros((3, 12, 3))), "global_pos"),
    (lambda: M.transition_jump(popping_arm(), [1.0], radius_s=-0.01), "radius_s"),
    (lambda: M.ground_penetration(popping_arm(), statistic="median"), "statistic"),
    (lambda: M.ground_penetration(popping_arm(), floor_m="floor"), "floor_m"),
    (lambda: M.foot_skate(popping_arm(), contacts=np.zeros((3, 2))), "contacts"),
    (lambda: M.foot_skate(popping_arm(), height_tol_m=-0.1), "height_tol_m"),
    (lambda: M.beat_interval_energy(popping_arm(), [0.0, 1.0], masses=[1.0, 2.0]), "masses"),
])
def test_bad_parameters_are_explained(call, match):
    with pytest.raises(InputError, match=match):
        call()


MOTION_METRICS = [
    M.kinematic_beats, M.angular_velocity_jumps, M.mean_jerk, M.foot_skate, M.pfc, M.ground_penetration,
    M.feet_of, lambda m: M.transition_jump(m, [0.0]), lambda m: M.beat_interval_energy(m, [0.0, 1.0]),
]


@pytest.mark.parametrize("metric", MOTION_METRICS)
def test_motion_metrics_reject_empty_and_nan_motion(metric):
    with pytest.raises(InputError, match="no frames"):
        metric(biped(np.zeros((0, 3))))
    broken = popping_arm()
    broken.root_pos[7, 1] = np.nan
    with pytest.raises(InputError, match="root_pos has NaN .* frame 7"):
        metric(broken)
    with pytest.raises(InputError, match="MotionClip"):
        metric(np.zeros((10, 3)))


def test_short_motion_gives_nan_not_errors():
    one = biped(standing(times(60.0, 1 / 60)))
    assert math.isnan(M.foot_skate(one)) and math.isnan(M.pfc(one)) and math.isnan(M.mean_jerk(one))
    assert M.angular_velocity_jumps(one).tolist() == [0.0]
    assert M.ground_penetration(one) == 0.0

"""``evaluate()`` and ``format_table``: keys, applicability, a frozen regression on real mocap."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conftest import REPO
from dancesynth import rotations as rot
from dancesynth.errors import InputError
from dancesynth.eval.evaluate import METRICS, EvalParams, evaluate, format_table, mocap_reference
from dancesynth.eval.metrics import mean_jerk
from dancesynth.io.bvh import read_bvh
from dancesynth.types import MotionClip, Skeleton
from test_metrics import biped, popping_arm, standing, times

MOCAP = REPO / "tests" / "data" / "mocap"


def test_keys_are_the_metrics_in_order_and_json_ready():
    t = times(60.0, 3.0)
    res = evaluate(biped(standing(t, x=0.2 * np.sin(2 * np.pi * t / 0.8))))
    assert list(res) == list(METRICS)
    json.dumps(res, allow_nan=False)
    assert res["n_frames"] == 180 and isinstance(res["n_frames"], int)
    assert res["duration_s"] == pytest.approx(179 / 60)
    assert res["n_kinematic_beats"] >= 6
    for key in ("bas_motion", "bas_music", "hit_rate", "intensity_spearman", "n_music_beats", "n_transitions",
                "max_transition_jump_deg_s", "mocap_jump_p99_deg_s", "jerk_vs_mocap", "warp_rate_max"):
        assert res[key] is None, key  # no music, transitions, mocap or warp rates given
    for key in ("jump_p99_deg_s", "jerk_m_s3", "foot_skate_m_s", "pfc", "ground_penetration_m"):
        assert isinstance(res[key], float), key


def test_every_metric_has_display_info():
    groups = {"general", "beat alignment", "bars", "intensity", "smoothness", "contact", "time warp", "form"}
    for key, info in METRICS.items():
        assert info.group in groups and info.label and info.better, key


def test_beat_alignment_of_a_dance_on_its_beats():
    period = 0.8
    t = times(60.0, 6.0)
    clip = biped(standing(t, x=0.2 * np.sin(2 * np.pi * t / period)))
    music = period / 4 + period / 2 * np.arange(15)  # 0.2 ... 5.8 s: the turning points
    res = evaluate(clip, music_beats_s=np.concatenate([music, [7.0, 8.0]]))  # two beats after the motion
    assert res["n_music_beats"] == 15
    assert res["bas_motion"] > 0.94 and res["bas_music"] > 0.94 and res["hit_rate"] == 1.0
    assert res["aligned_beat_ratio"] == 1.0
    assert res["kinematic_beat_ratio"] == pytest.approx(res["n_kinematic_beats"] / 15)
    off = evaluate(clip, music_beats_s=music + period / 4)  # on the fastest moments instead
    assert off["hit_rate"] == 0.0 and off["bas_motion"] < 1e-3


def test_intensity_follows_loudness():
    t = times(60.0, 4.0)
    clip = biped(standing(t, x=0.5 * t**2))  # ever faster
    beats = np.arange(0.0, 4.5, 0.5)           # the last interval leaves the motion: ignored
    loud = np.linspace(-30.0, -5.0, beats.size - 1)
    assert evaluate(clip, music_beats_s=beats, music_loudness_db=loud)["intensity_spearman"] == pytest.approx(1.0)
    assert evaluate(clip, music_beats_s=beats, music_loudness_db=loud[::-1])["intensity_spearman"] == \
        pytest.approx(-1.0)


def test_transitions_and_mocap_reference():
    dance = popping_arm()  # a 600 deg/s pop at 1.0 s
    res = evaluate(dance, transitions_s=[0.5, 1.0], mocap=[popping_arm(pop_deg=0.0)])
    assert res["n_transitions"] == 2
    assert res["max_transition_jump_deg_s"] == pytest.approx(600.0, rel=1e-6)
    assert res["jump_max_deg_s"] == pytest.approx(600.0, rel=1e-6)
    assert res["transition_jump_pct_in_mocap"] == 100.0
    assert res["transition_frac_over_mocap_p99"] == 0.5
    assert res["mocap_jump_p99_deg_s"] < 1e-6
    none = evaluate(dance, transitions_s=[])
    assert none["n_transitions"] == 0 and none["max_transition_jump_deg_s"] is None


def test_mocap_clips_are_not_concatenated():
    """Two smooth clips in different poses: joined, their seam would be a huge jump."""
    a = popping_arm(seconds=0.4, pop_deg=0.0)
    b = popping_arm(seconds=0.4, pop_deg=0.0)
    b.local_rot[:, 10] = rot.mul(rot.from_euler([90.0, 0.0, 0.0], "ZXY"), b.local_rot[:, 10])
    b.root_pos[:, 0] += 1.0
    dance = popping_arm()
    res = evaluate(dance, mocap=[a, b])
    assert res["mocap_jump_p99_deg_s"] < 1e-6
    assert res["jerk_vs_mocap"] == pytest.approx(mean_jerk(dance) / mean_jerk(a), rel=1e-9)


def test_mocap_is_resampled_to_the_motion_frame_rate():
    dance = popping_arm(fps=30.0)
    same = evaluate(dance, mocap=[popping_arm(fps=30.0)])
    faster = evaluate(dance, mocap=[popping_arm(fps=120.0)])
    assert faster["mocap_jump_p99_deg_s"] == pytest.approx(same["mocap_jump_p99_deg_s"], rel=1e-3)


def test_a_precomputed_mocap_reference_gives_the_same_scores():
    dance, mocap = popping_arm(), [popping_arm(fps=120.0, pop_deg=3.0), popping_arm(seconds=1.0)]
    ref = mocap_reference(mocap, dance.fps)
    assert ref.n_clips == 2 and ref.jumps_deg_s.size == 118 + 58  # at 60 fps
    assert evaluate(dance, transitions_s=[1.0], mocap=ref) == evaluate(dance, transitions_s=[1.0], mocap=mocap)
    with pytest.raises(InputError, match="mocap_reference"):
        evaluate(popping_arm(fps=30.0), mocap=ref)


def test_warp_rates():
    res = evaluate(popping_arm(), warp_rates=[1.0, 2.0, 0.5, 1.05, 0.75, 1.2])
    assert res["warp_frac_over_25pct"] == 0.5 and res["warp_rate_min"] == 0.5 and res["warp_rate_max"] == 2.0


def test_skeleton_without_legs_has_no_contact_metrics():
    sk = Skeleton(("root", "spine"), np.array([-1, 0]), np.array([[0, 0, 0], [0, 0.5, 0]]),
                  (("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"),
                   ("Zrotation", "Xrotation", "Yrotation")))
    clip = MotionClip(sk, 60.0, np.zeros((30, 3)), np.tile(rot.IDENTITY, (30, 2, 1)))
    res = evaluate(clip)
    assert res["foot_skate_m_s"] is None and res["pfc"] is None and res["ground_penetration_m"] is None
    assert res["jerk_m_s3"] == 0.0


def test_a_two_frame_motion_gives_none_not_errors():
    res = evaluate(biped(standing(times(60.0, 2 / 60))), music_beats_s=[0.0, 0.5], transitions_s=[0.0])
    json.dumps(res, allow_nan=False)
    assert res["jerk_m_s3"] is None and res["jump_p99_deg_s"] is None and res["bas_motion"] is None
    assert res["hit_rate"] == 0.0 and res["max_transition_jump_deg_s"] == 0.0


@pytest.mark.parametrize("kwargs, match", [
    ({"music_beats_s": [0.5, 1.0, 1.5], "music_loudness_db": [-10.0]}, "one per beat interval"),
    ({"music_loudness_db": [-10.0, -12.0]}, "needs music_beats_s"),
    ({"music_beats_s": [1.0, 0.5, 1.5]}, "strictly increasing"),
    ({"music_beats_s": [0.5, np.nan]}, "non-finite"),
    ({"music_beats_s": [0.5, 1.0], "music_loudness_db": [np.nan]}, "NaN"),
    ({"transitions_s": [90]}, "not frames"),
    ({"warp_rates": [1.0, -1.0]}, "positive"),
    ({"mocap": [biped(np.zeros((0, 3)))]}, r"mocap\[0\] has no frames"),
])
def test_bad_input_to_evaluate(kwargs, match):
    with pytest.raises(InputError, match=match):
        evaluate(popping_arm(), **kwargs)


def test_evaluate_rejects_an_empty_or_broken_motion():
    with pytest.raises(InputError, match="no frames"):
        evaluate(biped(np.zeros((0, 3))))
    broken = popping_arm()
    broken.local_rot[3, 2] = np.nan
    with pytest.raises(InputError, match="local_rot has NaN"):
        evaluate(broken)


def test_format_table():
    a = {"duration_s": 12.5, "bas_motion": 0.25, "hit_rate": None, "n_frames": 750, "extra_thing": 3.0}
    b = {"duration_s": 10.0, "bas_motion": float("nan"), "hit_rate": 0.5, "n_frames": 600}
    text = format_table({"dance": a, "reference": b})
    lines = text.splitlines()
    assert lines[0].split() == ["metric", "unit", "better", "dance", "reference"]
    row = next(line for line in lines if METRICS["bas_motion"].label in line)
    assert row.split()[-2:] == ["0.25", "—"]
    row = next(line for line in lines if METRICS["hit_rate"].label in line)
    assert row.split()[-2:] == ["—", "0.5"]
    assert "beat alignment" in lines and "other" in lines and "  extra_thing" in text
    assert METRICS["pfc"].label not in text  # in no column: left out
    assert lines.index("general") < lines.index("beat alignment") < lines.index("other")


# ---------------------------------------------------------------------------------------------
# Frozen regression on real mocap: numbers written down from this code (update them, with a
# reason in the commit, when a metric's definition changes on purpose).

FROZEN = {
    "duration_s": 1.9833333333333334,
    "n_frames": 120,
    "n_music_beats": 5,
    "n_kinematic_beats": 5,
    "bas_motion": 0.4037860917123762,
    "bas_music": 0.4037694952101597,
    "hit_rate": 0.4,
    "kinematic_beat_ratio": 1.0,
    "aligned_beat_ratio": 0.2,
    "intensity_spearman": -0.8,
    "n_transitions": 2,
    "max_transition_jump_deg_s": 42.9581199382865,
    "transition_jump_pct_in_mocap": 42.241379310344826,
    "transition_jump_vs_mocap_p99": 0.023937836994075118,
    "transition_frac_over_mocap_p99": 0.0,
    "jump_p99_deg_s": 867.8437043241563,
    "jump_max_deg_s": 1085.3793379426306,
    "mocap_jump_p99_deg_s": 1794.5698247055118,
    "jump_p99_vs_mocap": 0.48359428113451597,
    "jerk_m_s3": 723.4638275650327,
    "jerk_vs_mocap": 1.7409307572579278,
    "foot_skate_m_s": 0.19906080542936339,
    "pfc": 0.3409854730294513,
    "ground_penetration_m": 0.0018459044290601231,
    "ground_penetration_max_m": 0.0343163566259554,
    "warp_median_abs_log2": 0.11874965686332825,
    "warp_frac_over_10pct": 0.5,
    "warp_frac_over_25pct": 0.0,
    "warp_rate_min": 0.8,
    "warp_rate_max": 1.12,
    "accent_precision": 0.4,
    "accent_precision_chance": 0.254945054945055,
    "accent_precision_x_chance": 1.5689655172413792,
    "accent_recall": 0.4,
    "accent_recall_chance": 0.254945054945055,
    "accent_recall_x_chance": 1.5689655172413792,
    "stop_depth_on_beats": 0.3311832014454647,
    "visible_accent_precision": 0.5,
    "visible_accent_precision_chance": 0.25274725274725274,
    "visible_accent_precision_x_chance": 1.9782608695652175,
    "visible_accent_recall": 0.2,
    "visible_accent_recall_chance": 0.10109890109890111,
    "visible_accent_recall_x_chance": 1.9782608695652173,
    "joint_speed_p99_m_s": 10.872904201203125,
    "joint_speed_p99_vs_mocap": 7.023910922097896,
    "root_travel_m_s": 0.12105428486572342,
    "root_travel_vs_mocap": 0.4403766328177453,
    "foot_skate_vs_mocap": 1.4944135362285578,
    "pfc_vs_mocap": 3.5455264940256095,
}


def test_frozen_regression_on_real_mocap():
    dance = read_bvh(MOCAP / "cmu_daz_salsa" / "60_01_scaled.bvh")  # 120 frames at 60 fps
    mocap = [read_bvh(MOCAP / "cmu_max_cgspeed" / "94_01.bvh"), read_bvh(MOCAP / "cmu_mb_fbx2bvh" / "55_01_cmu.bvh")]
    beats = np.arange(0.1, 2.0, 0.45)
    res = evaluate(dance, music_beats_s=beats, music_loudness_db=[-20.0, -12.0, -15.0, -9.0],
                   transitions_s=[0.55, 1.3], warp_rates=[1.0, 1.12, 0.8, 0.95], mocap=mocap,
                   params=EvalParams())
    assert set(FROZEN) == {k for k, v in res.items() if v is not None}
    for key, value in FROZEN.items():
        assert res[key] == pytest.approx(value, rel=1e-6, abs=1e-12), key

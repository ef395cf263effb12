"""Bench section 6's liveliness, artefact and plan numbers (issue 16), on one short song."""

from __future__ import annotations

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from dancesynth.bench import structure as bs
from dancesynth.bench.common import BenchConfig
from dancesynth.bench.run import targets

HUNGARIAN = "Hungarian_Dance_number_5_-_Allegro_in_F_sharp_minor_(string_orchestra).ogg"


def small_config() -> BenchConfig:
    return replace(BenchConfig.quick(), structure_songs=(HUNGARIAN,), structure_max_s=30.0, structure_seeds=1,
                   structure_engines=("streaming", "random_walk"), fig12_song=HUNGARIAN, fig12_seeds=1,
                   fig12_engines=(), recreate_song=HUNGARIAN, recreate_clips=0, mocap_max_clips=1)


@pytest.fixture(scope="module")
def section(bundled_db):
    return bs.structure(small_config(), bundled_db)


def test_every_dance_and_engine_has_the_liveliness_numbers(section):
    s = section
    assert s["engines"] == ["mocap", "streaming", "random_walk"]
    for d in s["dances"]:
        live = d["liveliness"]
        for k in bs.LIVE_KEYS + ("root_travel_vs_mocap", "joint_speed_p99_vs_mocap"):
            assert live[k] is not None and math.isfinite(live[k]), (d["engine"], k)
        assert 0 <= live["hand_in_head"] <= 1 and live["root_travel_m_per_min"] > 0 and live["joint_speed_p99"] > 0
        for k in ("accent_precision_x_chance", "accent_recall_x_chance"):
            assert d["scores"][k] is not None and d["scores"][k] > 0
    (stream,) = [d for d in s["dances"] if d["engine"] == "streaming"]
    (walk,) = [d for d in s["dances"] if d["engine"] == "random_walk"]
    assert 0 <= stream["liveliness"]["plan_followed"] <= 1  # it counts the motifs it dances
    assert walk["liveliness"]["plan_followed"] is None      # a random walk plans nothing
    live = s["liveliness"]
    for e in s["engines"]:
        for k in ("hand_in_head", "root_travel_m_per_min", "joint_speed_p99", "one_frame_steps",
                  "accent_precision_x_chance", "accent_recall_x_chance"):
            assert live[e][k] is not None and math.isfinite(live[e][k]), (e, k)
    ratio = live["streaming"]["root_travel_m_per_min"] / live["mocap"]["root_travel_m_per_min"]
    assert live["streaming"]["root_travel_vs_mocap"] == pytest.approx(ratio)


def test_the_mocap_row_is_the_clean_reference(section, bundled_db):
    live, clips = section["liveliness"]["mocap"], section["mocap_liveliness"]
    assert live["dances"] == len(clips) == sum(st.n_clips for st in bundled_db.styles_of("salsa"))
    assert live["hand_in_head"] < 0.02
    # The capture has a few glitches of its own (about one clip in three, one or two snaps): nearly none.
    assert live["one_frame_steps"] < 1 and sum(c["one_frame_steps"] == 0 for c in clips) > len(clips) / 2
    assert 10 < live["root_travel_m_per_min"] < 60 and 1 < live["joint_speed_p99"] < 5
    assert live["root_travel_vs_mocap"] == live["joint_speed_p99_vs_mocap"] == 1.0


def test_without_the_neural_engine_its_targets_are_not_measured(section):
    assert section["neural_realism"] == {"skipped": "the neural engine was not selected"}
    t = section["neural_targets"]
    assert [name for name, *_ in bs.NEURAL_TARGETS] == list(t)
    assert all(x["value"] is None and x["met"] is None for x in t.values())


def test_the_format_prints_liveliness_and_the_neural_targets(section):
    text = bs.format_structure(section)
    for title in ("Table I", "Liveliness and artefacts", "hand in head %", "plan followed %",
                  "Neural realism vs held-out mocap: skipped", "Neural generator targets", "FID_k / streaming's"):
        assert title in text
    assert "nan" not in text.lower()


def test_plan_followed_compares_the_planned_beats_only():
    clip = SimpleNamespace(provenance=SimpleNamespace(motifs={"motif_plan": np.array([1, 2, -1, 3, 4])}))
    assert bs.plan_followed(clip, np.array([1, 0, 5, 3])) == pytest.approx(2 / 3)
    chosen = SimpleNamespace(provenance=SimpleNamespace(motifs={"motif_ids": np.array([7, 7]), "motif_plan": [1]}))
    assert bs.plan_followed(chosen, np.array([7, 1])) == 0.5  # an engine that chose its motifs: those
    assert bs.plan_followed(SimpleNamespace(provenance=SimpleNamespace(motifs={})), np.array([1])) is None


def test_neural_targets_pass_and_fail_and_reach_the_bench_targets():
    neural = {"plan_followed": 0.6, "hand_in_head": 0.05, "root_travel_vs_mocap": 1.2,
              "joint_speed_p99_vs_mocap": 0.6, "one_frame_steps_total": 0, "accent_precision_x_chance": 2.5,
              "accent_recall_x_chance": 1.5}
    s = {"table_i": {"neural": {"chi2": 0.25}}, "liveliness": {"neural": neural},
         "neural_realism": {"fid_k_ratio": 1.2, "fid_g_ratio": 2.0}}
    s["neural_targets"] = bs.neural_targets(s)
    met = {k: v["met"] for k, v in s["neural_targets"].items()}
    assert met == {"chi2 to the salsa template": True, "beats whose motif follows the plan": True,
                   "frames with a hand in the head": False, "root travel / mocap's": True,
                   "p99 joint speed / mocap's": False, "one-frame joint steps > 30°, all dances": True,
                   "FID_k / streaming's (held-out mocap)": True, "FID_g / streaming's (held-out mocap)": False,
                   "accent precision / chance": True, "accent recall / chance": False}
    t = targets({"structure": s})
    assert t["chi2 to the template, neural generator"]["limit"] == 0.30
    assert t["neural: p99 joint speed / mocap's, distance from 1"]["value"] == pytest.approx(0.4)
    assert t["neural: p99 joint speed / mocap's, distance from 1"]["met"] is False
    assert t["neural: accent precision x chance"]["met"] is True
    assert t["neural: frames with a hand in the head"]["met"] is False


def test_neural_realism_scores_against_the_clips_the_model_never_saw(bundled_db, monkeypatch):
    from dancesynth.bench.common import load_song

    held = "60_09_scaled"
    seen = []

    def fake_dances(music, db, seed, engines, style=bs.GENRE):
        # Both "engines" dance a remaining salsa clip: the held-out one must be out of the database.
        names = [n for st in db.styles_of(bs.GENRE) for n in st.clip_names]
        seen.append(names)
        st = db.styles["salsa-133-150bpm"]
        return {e: bs.at_fps(st.clip(i), bs.MOCAP_FPS) for i, e in enumerate(engines)}

    monkeypatch.setattr(bs, "engine_dances", fake_dances)
    songs = [(HUNGARIAN, load_song(HUNGARIAN, 25.0))]
    r = bs.neural_realism(small_config(), bundled_db, {"held_out_clips": [held]}, songs, None)
    assert r["held_out"] == [held] and r["dances"] == 1 and r["reference_s"] > 10
    assert seen and all(held not in names and len(names) == 25 for names in seen)
    for e in ("neural", "streaming"):
        assert r["scores"][e]["fid_k"] >= 0 and r["scores"][e]["n_reference"] > 0
    assert r["fid_k_ratio"] == pytest.approx(r["scores"]["neural"]["fid_k"] / r["scores"]["streaming"]["fid_k"])
    assert bs.neural_realism(small_config(), bundled_db, {}, songs, None) == {
        "skipped": "the neural model names no held-out clips"}


def test_found_motifs_stay_aligned_with_the_plan_when_the_grid_starts_before_the_song(bundled_db):
    """A beat grid extended before 0 s (a slow song's subdivided grid) must not shift the found motifs.

    Cutting at the distinct frames merged the intervals before the song into one, and every
    later motif was compared with the plan of the next beat: 6-13 % of beats followed the plan
    at 60 bpm, 46-65 % once aligned.
    """
    from dancesynth.motion.motifs import load_motif_model

    model = load_motif_model(bundled_db)
    clip = bundled_db.styles["salsa-97-124bpm"].clip(0)
    beats = clip.meta["beat_frames"][:12] / clip.fps
    found = bs.found_motifs(clip, model, beats)
    extended = bs.found_motifs(clip, model, np.r_[-1.0, -0.5, beats])
    assert len(found) == len(beats) - 1 and len(extended) == len(beats) + 1   # one id per interval
    assert extended[0] == -1                                  # wholly before the song: nothing to cut
    assert (extended[2:] == found).all() and (found >= 0).all()
    plan = np.r_[7, extended[1:]]                             # a motif planned where the song has no motion
    danced = SimpleNamespace(provenance=SimpleNamespace(motifs={"motif_plan": plan}))
    assert bs.plan_followed(danced, extended) == 1.0          # ... is not counted against the dance

"""The benchmark library: every section on tiny settings, its JSON and its tables."""

from __future__ import annotations

import json
import re
import shutil
from dataclasses import replace

import numpy as np
import pytest

from dancesynth.errors import InputError
from dancesynth.bench.run import SECTIONS, BenchConfig, format_bench, run_bench

HUNGARIAN = "Hungarian_Dance_number_5_-_Allegro_in_F_sharp_minor_(string_orchestra).ogg"


def tiny_config(tmp_path) -> BenchConfig:
    from dancesynth.bench.groundtruth import SongSpec

    specs = (SongSpec("t120_4-4_drums", (120,), duration_s=12.0, seed=1),
             SongSpec("t90_3-4_nodrums", (90,), beats_per_bar=3, drums=False, duration_s=12.0, seed=2))
    return replace(BenchConfig.quick(), song_max_s=20.0, segments_s=(2.0, 5.0), repeats=1, scales=(1,),
                   pipeline_song_s=15.0, pipeline_runs=1, quality_songs=(HUNGARIAN,), quality_max_s=None,
                   mocap_max_clips=1, groundtruth_specs=specs, groundtruth_dir=tmp_path / "groundtruth",
                   trackers=("dp",), structure_songs=(HUNGARIAN,), structure_max_s=30.0,
                   structure_engines=("streaming", "signature", "choreography"), fig12_song=HUNGARIAN, fig12_seeds=1,
                   fig12_engines=("signature",), recreate_clips=1, vocabulary_long_songs=1, vocabulary_long_s=30.0,
                   form_engines=("streaming", "random_walk"), form_specs=(_shortest_form_song(),))


def _shortest_form_song():
    from dancesynth.bench.groundtruth import structure_specs

    return next(s for s in structure_specs("tune") if s.name.startswith("form-aaba"))   # V V B V, 58 s


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    messages = []
    result = run_bench(quick=True, out_dir=out, progress=messages.append, config=tiny_config(out))
    return result, out, messages


def test_every_section_ran_and_the_json_is_written(bench):
    result, out, messages = bench
    expect_skip = {"beat_tracking"} if shutil.which("fluidsynth") is None else set()
    for name in SECTIONS:
        assert ("skipped" in result[name]) == (name in expect_skip), (name, result[name].get("skipped"))
    assert json.loads((out / "bench.json").read_text()) == result
    assert result["mode"] == "quick" and result["dancesynth"]
    m = result["machine"]
    assert m["cpus"] >= 1 and m["python"].count(".") == 2 and m["numpy"] == np.__version__
    assert all(result["timings_s"][s] > 0 for s in SECTIONS) and result["timings_s"]["total"] > 0
    assert messages and all(isinstance(x, str) for x in messages)


def test_fig4_times_and_fit(bench):
    s = bench[0]["fig4"]
    assert s["N"] > 100 and s["D"] > 1
    assert [r["segment_s"] for r in s["rows"]] == [2.0, 5.0, "song"]
    for r in s["rows"]:
        for key in ("stream_search_ms", "stream_step_ms", "global_search_ms", "global_total_ms"):
            assert 0 < r[key]["median"] <= r[key]["max"] < 5000, (r["segment_s"], key)
        assert r["stream_step_ms"]["median"] >= r["stream_search_ms"]["median"]  # the step includes the search
        assert r["beats_mean"] >= 1 and r["segments"] >= 1
    beats = [r["beats_mean"] for r in s["rows"]]
    assert beats == sorted(beats)
    for fit in s["fit"].values():
        assert 0.0 <= fit["r2"] <= 1.0 and fit["slope_ns"] > 0 and fit["points"] >= 3
    assert s["paper_form"]["a_ns"] is not None


def test_scaling_measures_time_and_memory_in_a_fresh_process(bench):
    (row,) = bench[0]["scaling"]["rows"]
    assert row["times"] == 1 and row["nodes"] == bench[0]["fig4"]["N"]
    assert row["build_s"] > 0 and row["search_ms_median"] > 0 and row["global_search_s"] > 0
    for key in ("build_peak_mb", "stream_peak_mb", "global_peak_mb"):
        assert 30 < row[key] < 4096, key


def test_pipeline_builds_every_graph_and_writes_a_bvh(bench):
    s = bench[0]["pipeline"]
    assert len(s["graphs"]) >= 1 and all(g["reloaded"] and g["build_s"] > 0 for g in s["graphs"])
    assert s["frames"] == int(15.0 * 30) + 1 and s["wall_s_median"] > s["in_process_s_median"] > 0


def test_quality_table_has_every_metric_for_every_dance(bench):
    from dancesynth.eval.evaluate import METRICS

    s = bench[0]["quality"]
    assert s["rows"] == ["streaming", "global", "random_walk", "mocap"] and s["metrics"] == list(METRICS)
    for row in s["rows"]:
        assert list(s["mean"][row]) == list(METRICS)
    mean = s["mean"]
    assert mean["mocap"]["intensity_spearman"] is None  # no music with the mocap
    assert mean["mocap"]["n_transitions"] == 0 and mean["mocap"]["warp_median_abs_log2"] == 0
    for row in ("streaming", "global", "random_walk"):
        assert -1 <= mean[row]["intensity_spearman"] <= 1 and mean[row]["n_transitions"] > 0
    # (How often each jumps is not compared: the walk's rate is its own parameter, and the search trades jumps
    # against replaying a move of the last minute.)


def test_our_dance_follows_the_music_intensity_better_than_a_random_walk(bench):
    """The user-visible claim: the search, not the graph alone, makes the dance follow the loudness (on the
    Hungarian Dance measured 0.51 streaming, 0.49 global, 0.20 for this walk and 0.04-0.11 for walks of other
    seeds). Its loud passages are its fast ones, where the pieces matched as shown at the song's tempo are
    calmer ones played faster: 0.36 / 0.58 when the search matched each piece's rank among the style's
    (eq. 5's w1_z; over the five bundled songs 0.43 / 0.69 then, 0.45 / 0.72 now)."""
    mean = bench[0]["quality"]["mean"]
    for engine in ("streaming", "global"):
        assert mean[engine]["intensity_spearman"] > mean["random_walk"]["intensity_spearman"] + 0.2, engine


def test_the_random_walk_still_dances_on_the_beat(bench, bundled_db):
    """Same renderer: the walk's beat alignment is like our dance's, and far above the same walk off the beat."""
    from dancesynth.bench.common import load_song
    from dancesynth.bench.quality import walk_dance
    from dancesynth.eval.evaluate import evaluate

    mean = bench[0]["quality"]["mean"]
    assert mean["random_walk"]["bas_music"] > 0.75 * mean["streaming"]["bas_music"]
    music = load_song(HUNGARIAN)
    walk = walk_dance(bundled_db.styles[bench[0]["quality"]["songs"][0]["style"]], music, seed=0)
    on = evaluate(walk, music_beats_s=music.beat_times_s)
    assert on["bas_music"] == pytest.approx(mean["random_walk"]["bas_music"])  # the same seeded walk
    half = float(np.median(np.diff(music.beat_times_s))) / 2
    off = evaluate(walk, music_beats_s=music.beat_times_s + half)
    assert on["bas_music"] > 1.5 * off["bas_music"]


@pytest.mark.skipif(shutil.which("fluidsynth") is None, reason="fluidsynth not installed")
def test_beat_tracking_scores_each_tracker_by_tag(bench):
    s = bench[0]["beat_tracking"]
    assert s["trackers"] == ["dp"] and len(s["songs"]) == 2
    r = s["results"]["dp"]["mean"]
    for key in ("f_measure", "cmlt", "amlt", "p_score"):     # P-score: our scorer's, not a fallback's (issue 31)
        assert 0 <= r[key] <= 1
    assert s["scorer"].startswith("dancesynth.eval.beat_metrics.beat_tracking_scores")
    assert "fallback" not in format_bench(bench[0])
    assert r["f_measure"] > 0.5 and r["speed_x_realtime"] > 1
    assert r["f_3/4"] is not None and r["f_no drums"] is not None and r["f_step"] is None  # no step song here
    assert s["groups"]["constant"] == 2


def test_structure_measures_every_engine_against_the_genre_template(bench, bundled_db):
    result, out, _ = bench
    s = result["structure"]
    assert s["engines"] == ["mocap", "streaming", "signature", "choreography"] and s["genre"] == "salsa"
    t = s["table_i"]
    # A raw dance is closer to a template it is part of than to the template of the others.
    salsa_clips = sum(st.n_clips for st in bundled_db.styles_of("salsa"))
    assert t["mocap"]["dances"] == salsa_clips and 0 < t["mocap"]["chi2_danced"] < t["mocap"]["chi2"] < 1
    for engine in ("streaming", "signature", "choreography"):
        assert t[engine]["dances"] == 1 and 0 < t[engine]["chi2"] < 1 and t[engine]["chi2_danced"] is not None
    # eq. (5) plans towards the template; the mixer dances about 2 beats in 3 as planned (measured 0.09-0.12)
    assert t["choreography"]["chi2_danced"] < min(0.2, t["streaming"]["chi2_danced"])
    f = s["fig12"]
    (curve,) = f["curves"]["signature"]
    assert len(curve) == len(f["times_s"]) and f["times_s"][-1] <= 30.0 and (out / "fig12_chi2.png").is_file()
    (row,) = s["recreation"]["rows"]
    assert row["danced"] >= 0.8 and 0 < row["found_again"] <= 1
    for engine in s["engines"]:
        assert s["metrics"][engine]["hit_rate"] is not None


def test_tables_have_the_same_layout_whatever_the_numbers(bench):
    result = bench[0]
    text = format_bench(result)
    for title in ("Fig. 4", "Growth with the database", "Graphs of the bundled database", "Quality on the bundled",
                  "fit (streaming search)", "random walk", "mocap*"):
        assert title in text
    assert "skipped:" not in text or shutil.which("fluidsynth") is None

    def scramble(x):
        if isinstance(x, dict):
            return {k: scramble(v) for k, v in x.items()}
        if isinstance(x, list):
            return [scramble(v) for v in x]
        if isinstance(x, float):
            return x * 7.31 + 0.5
        return x

    def shape(t):
        return [re.sub(r"-?\d[\d.e+-]*", "#", line).split()[:1] + [len(line.split())] for line in t.splitlines()]

    other = format_bench(scramble(result))
    assert len(other.splitlines()) == len(text.splitlines())
    assert [ln.split("[")[0] for ln in other.splitlines() if ln.startswith("==")] == \
        [ln.split("[")[0] for ln in text.splitlines() if ln.startswith("==")]
    assert shape(other) == shape(text)


def test_a_section_that_cannot_run_is_recorded_and_the_others_run(tmp_path):
    from dancesynth.bench.groundtruth import SongSpec

    cfg = replace(tiny_config(tmp_path), sections=("beat_tracking",),
                  groundtruth_specs=(SongSpec("bad", (120,), kind="wobble", duration_s=8.0),))
    result = run_bench(quick=True, out_dir=tmp_path, config=cfg)
    assert "skipped" in result["beat_tracking"]
    assert all(result[s] == {"skipped": "not selected"} for s in SECTIONS if s != "beat_tracking")
    text = format_bench(result)
    assert text.count("skipped:") == len(SECTIONS)


def test_unknown_section_is_refused(tmp_path):
    with pytest.raises(InputError, match="unknown bench section"):
        run_bench(quick=True, out_dir=tmp_path, config=replace(BenchConfig.quick(), sections=("fig5",)))


def test_accents_score_every_engine_beside_chance_a_random_walk_and_the_mocap(bench):
    s = bench[0]["accents"]
    assert {x["set"] for x in s["songs"]} == {"bundled", "generated"}
    for subset in ("bundled", "generated"):
        table = s["summary"][subset]
        assert set(table) == set(s["engines"])
        for engine, row in table.items():
            assert 0 <= row["accent_recall_chance"] <= 1 and 0 <= row["accent_recall"] <= 1
            # Xu et al. as printed has nothing that puts stops on beats: it sits at chance (full bench:
            # 0.245 against 0.239 on the bundled songs), on either side of it on one short song.
            assert engine == "paper" or row["accent_recall_chance"] < row["accent_recall"], (engine, row)
            assert row["warp_in_range"] is not None and row["one_frame_steps"] >= 0
    # The generated 3/4 song is scored in bars of three, the 4/4 one in fours.
    assert sorted(x["beats_per_bar"] for x in s["songs"] if x["set"] == "generated") == [3, 4]
    assert s["summary"]["generated"]["streaming"]["waltz_period_3"] in (0.0, 1.0)
    assert s["summary"]["mocap"]["accent_recall"] is not None
    # The speed guard, song by song, each dance beside its style's own range over as long a stretch.
    for engine, g in s["speed_guard"].items():
        assert g["dances"] == sum(engine in x["scores"] for x in s["songs"])
        assert 0 <= g["outside_mocap_range"] <= g["outside"] <= g["dances"]
    for x in s["songs"]:
        for lo, hi in x["speed_range"].values():
            assert 0 < lo <= hi
    assert "p99 joint speed outside ±25 %" in format_bench(bench[0])


def test_the_mocaps_own_speed_range_narrows_as_its_stretches_lengthen(bundled_db):
    """A stretch of mocap strays from the whole capture's p99 joint speed the more the shorter it is: 5 s of
    salsa-97-124bpm span 0.61-1.51x (measured), 90 s stay within the guard's +-25 %."""
    from dancesynth.bench.accents import mocap_speed_range, mocap_speeds
    from dancesynth.bench.quality import at_fps
    from dancesynth.eval.evaluate import mocap_reference

    style = bundled_db.styles["salsa-97-124bpm"]
    clips = [at_fps(style.clip(c), 30.0) for c in range(style.n_clips)]
    whole = mocap_reference(clips, 30.0).joint_speed_p99_m_s
    speeds = mocap_speeds(clips)
    short, long_ = (mocap_speed_range(speeds, 30.0, whole, d) for d in (5.0, 90.0))
    assert short[0] < 0.75 and short[1] > 1.25
    assert short[0] < long_[0] <= 1.0 <= long_[1] < short[1] and 0.75 < long_[0] and long_[1] < 1.25
    assert mocap_speed_range(speeds, 30.0, whole, 1e5) == [1.0, 1.0]   # longer than the capture: no stretch to compare


def test_form_scores_each_engine_with_and_without_the_song_form(bench):
    result, _, _ = bench
    if "skipped" in result["form"]:
        pytest.skip(result["form"]["skipped"])
    form = result["form"]
    assert set(form["summary"]) == {"streaming/off", "streaming/same", "random_walk/off", "random_walk/same"}
    same, off = form["summary"]["streaming/same"], form["summary"]["streaming/off"]
    assert same["replayed_share"] >= 0.8 and off["replayed_share"] is None
    assert same["form_score"] > same["form_chance"] + 0.2 and same["form_score"] > off["form_score"] + 0.2
    walk, replayed = form["summary"]["random_walk/off"], form["summary"]["random_walk/same"]
    assert replayed["form_score"] > walk["form_score"] + 0.2   # exact replays of the walk follow the form
    song = form["songs"][0]
    assert song["sections_true"] == "VVBV" and 0 <= song["boundary_f"] <= 1
    assert song["live"]["live_replayed_share"] is not None
    targets = result["targets"]
    assert targets["live: paired beats danced as their pair, --repeat same"]["met"] is not None
    assert "10. The song's form" in format_bench(result)

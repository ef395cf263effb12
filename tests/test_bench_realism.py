"""The bench's realism section (bench.realism) on a tiny setting: one short song, one split, two engines."""

from __future__ import annotations

from dataclasses import replace

import pytest

from dancesynth.errors import InputError
from dancesynth.bench.run import TARGETS, targets
from dancesynth.bench.common import BenchConfig
from dancesynth.bench.realism import format_realism, realism_section


HUNGARIAN = "Hungarian_Dance_number_5_-_Allegro_in_F_sharp_minor_(string_orchestra).ogg"  # 46 s


def tiny_config() -> BenchConfig:
    return replace(BenchConfig.quick(), sections=("realism",), realism_songs=(HUNGARIAN,), realism_seeds=1,
                   realism_engines=("streaming", "random_walk"))


@pytest.fixture(scope="module")
def section(bundled_db):
    messages = []
    return realism_section(tiny_config(), bundled_db, messages.append), messages


def test_rows_and_scores(section):
    s, messages = section
    assert s["rows"] == ["mocap", "frozen", "streaming", "random_walk"]
    assert s["style"] == "salsa-97-124bpm" and s["dim_g"] == 32 and s["dim_k"] == 3 * len(s["smpl_joints"])
    (split,) = s["seeds"]
    assert split["seed"] == 0 and split["held_out"] and split["remaining_clips"] + len(split["held_out"]) == s["clips"]
    assert [x["song"] for x in s["songs"]] == [HUNGARIAN] and 40 < s["songs"][0]["duration_s"] < 50
    for row in s["rows"]:
        assert set(s["mean"][row]) == {"fid_k", "fid_g", "div_k", "div_g", "n_generated"}
        assert s["mean"][row] == pytest.approx({k: split["scores"][row][k] for k in s["mean"][row]})
    # A dance and a frozen pose of the song's length give as many 5 s windows; the remaining mocap many more.
    assert s["mean"]["streaming"]["n_generated"] == s["mean"]["frozen"]["n_generated"] > 0
    assert s["mean"]["mocap"]["n_generated"] > 50 and s["reference"]["n_reference"] >= 10
    assert messages and all(m.startswith("realism:") for m in messages)


def test_a_frozen_pose_scores_far_worse_than_the_mocap_and_the_dance(section):
    mean = section[0]["mean"]
    assert mean["frozen"]["fid_k"] > 3 * mean["mocap"]["fid_k"]
    assert mean["frozen"]["fid_k"] > 3 * mean["streaming"]["fid_k"]
    assert mean["frozen"]["fid_g"] > 3 * mean["mocap"]["fid_g"]
    assert mean["frozen"]["div_k"] == mean["frozen"]["div_g"] == 0.0
    assert mean["streaming"]["div_k"] > 0.3 * section[0]["reference"]["div_k_ref"]


def test_format_and_target(section):
    s = section[0]
    text = format_realism(s)
    for title in ("remaining mocap (floor)", "frozen pose", "streaming (Xu)", "random walk",
                  "held-out mocap (reference)", "FID_k", "Div_g", "not comparable with AIST++ tables"):
        assert title in text
    assert "global DP" not in text and "seed 0: held out" not in text
    assert "seed 0: held out" in format_realism(s, per_seed=True)
    t = targets({"realism": s})["FID_k, streaming vs held-out mocap"]
    assert t["value"] == s["mean"]["streaming"]["fid_k"] and t["limit"] == TARGETS[
        "FID_k, streaming vs held-out mocap"][2]


def test_unknown_engines_are_refused(bundled_db):
    with pytest.raises(InputError, match="mocap engines only"):
        realism_section(replace(tiny_config(), realism_engines=("streaming", "neural")), bundled_db)

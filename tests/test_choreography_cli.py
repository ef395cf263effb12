"""``dancesynth dance --engine choreography / --motif-at / --recreate`` as a user runs them."""

from __future__ import annotations

import json

import pytest

from conftest import BUNDLED_MUSIC
from test_cli import assert_clean_failure, cli, run

SONG = BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg"


def test_choreography_dance_then_eval(tmp_path):
    out, report = tmp_path / "dance.bvh", tmp_path / "dance.json"
    proc = run("dance", SONG, "-o", out, "--engine", "choreography", "--seed", "2", "--report", report)
    assert proc.returncode == 0, proc.stderr
    assert "engine    choreography" in proc.stdout and "chi2 to the salsa template" in proc.stdout
    planned = json.loads(report.read_text())["summary"]["plan_followed"]
    assert f"{planned:.0%} of beats as planned" in proc.stdout
    from dancesynth.io.bvh import read_bvh

    clip = read_bvh(out)
    assert clip.n_frames == json.loads(report.read_text())["summary"]["frames"]
    proc = run("eval", out, SONG, "--report", report, "--json", tmp_path / "eval.json")
    assert proc.returncode == 0, proc.stderr
    scores = json.loads((tmp_path / "eval.json").read_text())
    assert scores["mocap_style"] == "salsa-133-150bpm"
    assert scores["dance"]["n_transitions"] == len(json.loads(report.read_text())["transition_times_s"]) > 20
    assert scores["dance"]["hit_rate"] > 0.4                      # measured 0.52 on this song


def test_motif_at_implies_the_choreography_engine(tmp_path):
    out = tmp_path / "dance.bvh"
    proc = run("dance", SONG, "-o", out, "--motif-at", "12.0=M20", "--motif-at", "30.5=M4")
    assert proc.returncode == 0, proc.stderr
    assert "engine    choreography" in proc.stdout and "2 constraint(s)" in proc.stdout


@pytest.mark.parametrize("args, words", [
    (("--motif-at", "12=M999"), ("unknown motif", "M0 .. M47")),
    (("--motif-at", "500=M3"), ("outside the song",)),
    (("--motif-at", "twelve"), ("TIME=MOTIF",)),
    (("--engine", "streaming", "--motif-at", "12=M3"), ("choreography engine",)),
    (("--recreate", "no-such-dance.bvh"), ("no-such-dance.bvh",)),
])
def test_bad_choreography_input(tmp_path, args, words):
    out = tmp_path / "dance.bvh"
    assert_clean_failure(cli("dance", SONG, "-o", out, *args), out, *words)


def test_recreate_from_a_dance_on_another_skeleton(tmp_path, bundled_db):
    from dancesynth.io.bvh import write_bvh

    ref, out = tmp_path / "mj.bvh", tmp_path / "dance.bvh"
    write_bvh(ref, bundled_db.styles["mj"].clip(0))
    assert_clean_failure(cli("dance", SONG, "-o", out, "--style", "salsa", "--recreate", ref), out,
                         "skeleton of 31 joints", "no style uses")


@pytest.mark.parametrize("how", [("--engine", "choreography"), ("--motif-at", "1.0=M3")])
def test_paper_is_refused_for_the_choreography_engine(tmp_path, how):
    """Issue 31: --paper with the choreography engine ran silently with none of the paper's settings."""
    out = tmp_path / "d.bvh"
    assert_clean_failure(cli("dance", SONG, *how, "--paper", "-o", out), out, "--paper", "choreography")


def test_paper_help_says_what_stays_on():
    text = " ".join(run("dance", "--help").stdout.split())
    for stays in ("dead-end closing", "snapped", "loudness standardised", "foot lock", "beat warp", "choreography"):
        assert stays in text, stays

"""`dancesynth beats` and `dancesynth eval` as a user meets them: real processes, real files."""

from __future__ import annotations

import json

import numpy as np
import pytest

import signals
from conftest import BUNDLED_MUSIC, SHARED_MOCAP, requires_shared
from test_cli import assert_clean_failure, cli, run

TRUMPET = BUNDLED_MUSIC / "sorohanro_-_solo-trumpet-06.ogg"
VIBE_ACE = BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg"


def test_beats_prints_and_writes_the_beats_of_a_click_track(tmp_path):
    y, truth = signals.click_track(120, 12.0, offset_s=0.37, accent_every=4)
    song = tmp_path / "clicks.wav"
    signals.write(song, y, signals.SR)
    proc = run("beats", song, "--json", tmp_path / "beats.json")
    assert proc.returncode == 0, proc.stderr
    assert "120.0 bpm" in proc.stdout
    data = json.loads((tmp_path / "beats.json").read_text())
    assert data["tempo"] == pytest.approx(120, abs=0.5)
    beats = np.asarray(data["beats"])
    assert len(beats) == len(truth)
    assert np.max(np.abs(beats - truth)) < 0.02  # within one analysis frame of every click
    assert data["tracker"] == "varying" and not data["default_tempo"]
    assert len(data["intensity_db"]) == len(beats) - 1


def test_beats_bad_input(tmp_path):
    text = tmp_path / "notes.mp3"
    text.write_text("not audio")
    assert_clean_failure(cli("beats", text, "--json", tmp_path / "b.json"), tmp_path / "b.json", "notes.mp3")
    y, _ = signals.click_track(120, 6.0)
    song = tmp_path / "clicks.wav"
    signals.write(song, y, signals.SR)
    assert_clean_failure(cli("beats", song, "--json", tmp_path / "nowhere" / "b.json"),
                         tmp_path / "nowhere" / "b.json", "does not exist")
    assert_clean_failure(cli("beats", song, "--tracker", "magic"), tmp_path / "none", "unknown tracker")


@pytest.fixture(scope="module")
def trumpet_dance(tmp_path_factory):
    folder = tmp_path_factory.mktemp("dance")
    proc = run("dance", TRUMPET, "-o", folder / "dance.bvh", "--report", folder / "dance.json", "-q")
    assert proc.returncode == 0, proc.stderr
    return folder


def test_eval_prints_every_metric_and_writes_json_and_plot(trumpet_dance, tmp_path):
    out_json, out_png = tmp_path / "eval.json", tmp_path / "beats.png"
    proc = run("eval", trumpet_dance / "dance.bvh", TRUMPET, "--report", trumpet_dance / "dance.json",
               "--json", out_json, "--plot", out_png)
    assert proc.returncode == 0, proc.stderr
    for words in ("Beat Align Score", "Spearman", "transition", "Foot Contact", "time-warp"):
        assert words in proc.stdout
    result = json.loads(out_json.read_text())
    dance = result["dance"]
    assert dance["n_music_beats"] == result["song"]["beats"]
    assert 0.0 <= dance["bas_motion"] <= 1.0 and 0.0 <= dance["hit_rate"] <= 1.0
    assert dance["n_transitions"] is not None and dance["warp_rate_min"] > 0.5  # from the report
    assert result["mocap_style"] is not None and dance["jump_p99_vs_mocap"] is not None
    assert out_png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out_png.stat().st_size > 10_000
    assert "--plot-from" in proc.stdout  # the plot says which seconds it shows and how to choose others


def test_eval_plot_window_is_chosen_and_checked(trumpet_dance, tmp_path):
    """Issue 13: --plot silently showed the first 20 s only."""
    dance = trumpet_dance / "dance.bvh"
    proc = run("eval", dance, TRUMPET, "--plot", tmp_path / "late.png", "--plot-from", "2", "--plot-length", "2")
    assert proc.returncode == 0, proc.stderr
    assert "2.0-4.0 s of" in proc.stdout and (tmp_path / "late.png").stat().st_size > 10_000
    assert_clean_failure(cli("eval", dance, TRUMPET, "--plot", tmp_path / "x.png", "--plot-from", "99"),
                         tmp_path / "x.png", "past the song's end")


def test_eval_without_a_report_still_measures_what_a_bvh_holds(trumpet_dance):
    proc = run("eval", trumpet_dance / "dance.bvh", TRUMPET)
    assert proc.returncode == 0, proc.stderr
    row = next(line for line in proc.stdout.splitlines() if "largest angular-velocity jump at a transition" in line)
    assert "—" in row  # no transition times without the report
    assert "Beat Align Score" in proc.stdout


@requires_shared
def test_eval_reference_adds_a_column_computed_by_the_same_code(trumpet_dance, tmp_path):
    from dancesynth.io.bvh import read_bvh, write_bvh
    from dancesynth.types import MotionClip

    # A reference as long as the song: the start of a real salsa capture.
    mocap = read_bvh(SHARED_MOCAP / "cmu_daz_salsa" / "61_11_scaled.bvh")
    dance = read_bvh(trumpet_dance / "dance.bvh")
    n = int(round(dance.duration_s * mocap.fps)) + 1
    write_bvh(tmp_path / "ref.bvh", MotionClip(mocap.skeleton, mocap.fps, mocap.root_pos[:n], mocap.local_rot[:n]))
    out_json = tmp_path / "eval.json"
    proc = run("eval", trumpet_dance / "dance.bvh", TRUMPET, "--reference", tmp_path / "ref.bvh", "--json", out_json)
    assert proc.returncode == 0, proc.stderr
    assert "reference" in proc.stdout.splitlines()[2]  # the table's header
    result = json.loads(out_json.read_text())
    assert set(result["reference"]) == set(result["dance"])
    assert result["reference"]["n_frames"] == n


def test_eval_bad_input(trumpet_dance, tmp_path):
    dance = trumpet_dance / "dance.bvh"
    out = tmp_path / "eval.json"
    # A dance of another song: the lengths give it away.
    assert_clean_failure(cli("eval", dance, VIBE_ACE, "--json", out), out, "lasts")
    not_bvh = tmp_path / "dance.bvh"
    not_bvh.write_text("MOTION\nFrames: 0\n")
    assert_clean_failure(cli("eval", not_bvh, TRUMPET, "--json", out), out, "dance.bvh")
    garbage = tmp_path / "report.json"
    garbage.write_text("{not json")
    assert_clean_failure(cli("eval", dance, TRUMPET, "--report", garbage, "--json", out), out, "report")
    assert_clean_failure(cli("eval", dance, TRUMPET, "--style", "tango", "--json", out), out, "unknown style")
    assert_clean_failure(cli("eval", dance, tmp_path / "missing.ogg", "--json", out), out, "missing.ogg")
    assert_clean_failure(cli("eval", dance, TRUMPET, "--plot", tmp_path / "plot.xyz"), tmp_path / "plot.xyz",
                         "plot")


def test_bench_refuses_a_file_as_its_output_folder(tmp_path):
    taken = tmp_path / "results"
    taken.write_text("not a folder")
    proc = run("bench", "--quick", "--out", taken)
    assert proc.returncode == 2 and "is a file" in proc.stderr and "Traceback" not in proc.stderr
    assert taken.read_text() == "not a folder"

"""`dancesynth motifs` as a user meets it: real processes, real BVH files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from test_cli import assert_clean_failure, cli, run

SALSA_EXCERPT = Path(__file__).resolve().parent / "data" / "mocap" / "cmu_daz_salsa" / "60_01_scaled.bvh"  # 2 s


@pytest.fixture(scope="module")
def dances(tmp_path_factory, bundled_db):
    """Whole dances of the bundled database written back as BVH files, as a user would have them."""
    from dancesynth.io.bvh import write_bvh

    folder = tmp_path_factory.mktemp("dances")
    for genre in ("pop", "salsa"):
        clip = bundled_db.styles_of(genre)[0].clip(0)
        write_bvh(folder / f"{genre}.bvh", clip.frames(0, min(clip.n_frames, int(40 * clip.fps))))
    return folder


def test_motifs_prints_the_sequence_and_writes_json_and_plot(dances, tmp_path):
    out_json, out_png = tmp_path / "m.json", tmp_path / "m.png"
    proc = run("motifs", dances / "pop.bvh", "--json", out_json, "--plot", out_png)
    assert proc.returncode == 0, proc.stderr
    data = json.loads(out_json.read_text())
    assert data["genre"] == "pop" and data["genre_guessed"]          # its own genre, found from the motifs
    assert len(data["words"]) >= 10
    starts = [w["start_s"] for w in data["words"]]
    assert starts == sorted(starts) and all(w["motif"].startswith("M") for w in data["words"])
    assert f"{starts[3]:.2f}  {data['words'][3]['motif']}" in proc.stdout
    assert sum(data["signature"]) == pytest.approx(1.0, abs=1e-3)
    assert len(data["signature"]) == len(data["template"]) == data["k"]
    assert 0.0 <= data["chi2"] == min(data["chi2_by_genre"].values()) < 1.0
    assert f"chi2 to the pop template: {data['chi2']:.3f}" in proc.stdout
    assert out_png.stat().st_size > 10_000 and out_png.read_bytes()[:4] == b"\x89PNG"


def test_motifs_against_a_chosen_genre(dances, tmp_path):
    out_json = tmp_path / "m.json"
    proc = run("motifs", dances / "salsa.bvh", "--json", out_json)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(out_json.read_text())["genre"] == "salsa"
    proc = run("motifs", dances / "salsa.bvh", "--genre", "pop", "--json", out_json)
    assert proc.returncode == 0, proc.stderr
    data = json.loads(out_json.read_text())
    assert data["genre"] == "pop" and not data["genre_guessed"]
    assert "nearest template" not in proc.stdout
    # a salsa dance is further from the pop template than from the salsa one, each against what the genre's
    # own takes score (read on the robot's rig a salsa take lands near pop's broad template: 0.24 against 0.34)
    assert data["chi2"] == data["chi2_by_genre"]["pop"]
    assert data["chi2_over_own_takes"]["pop"] > 1.5 * data["chi2_over_own_takes"]["salsa"]
    np.testing.assert_allclose(sum(data["template"]), 1.0, atol=1e-3)


def test_motifs_bad_input(tmp_path):
    out = tmp_path / "m.json"
    text = tmp_path / "notes.bvh"
    text.write_text("this is not motion capture")
    assert_clean_failure(cli("motifs", text, "--json", out), out, "notes.bvh")
    assert_clean_failure(cli("motifs", tmp_path / "absent.bvh", "--json", out), out, "absent.bvh")
    assert_clean_failure(cli("motifs", SALSA_EXCERPT, "--genre", "polka", "--json", out), out, "unknown genre", "salsa")
    assert_clean_failure(cli("motifs", SALSA_EXCERPT, "--json", tmp_path / "nowhere" / "m.json"),
                         tmp_path / "nowhere" / "m.json", "does not exist")


def test_motifs_refuses_a_skeleton_without_legs_and_a_dance_too_short(tmp_path):
    from bvh_samples import TWO_JOINTS

    out = tmp_path / "m.json"
    legless = tmp_path / "legless.bvh"
    legless.write_text(TWO_JOINTS)
    assert_clean_failure(cli("motifs", legless, "--json", out), out, "legs")
    lines = SALSA_EXCERPT.read_text().splitlines()
    header = lines.index("MOTION")
    short = tmp_path / "short.bvh"
    body = lines[header + 3: header + 3 + 12]
    short.write_text("\n".join(lines[:header + 1] + [f"Frames: {len(body)}", lines[header + 2]] + body) + "\n")
    assert_clean_failure(cli("motifs", short, "--json", out), out, "no motion word", "longer dance")


def test_motifs_and_eval_read_a_dance_alike_on_every_rig(tmp_path):
    """Issue 31: the same dance scored chi2 0.043 to the salsa template written on its source rig and 0.68 on
    the mannequin (where motifs took it for 'mj'); every analysis now reads a dance on the rig of the mocap it
    is compared with."""
    from test_choreography_cli import SONG

    results = {}
    for rig in ("source", "mannequin", "mixamo"):
        dance = tmp_path / f"{rig}.bvh"
        assert cli("dance", SONG, "--style", "salsa", "--character", rig, "-o", dance, "-q").returncode == 0
        assert cli("motifs", dance, "--json", tmp_path / f"{rig}.json").returncode == 0
        assert cli("eval", dance, SONG, "--json", tmp_path / f"{rig}.eval.json").returncode == 0
        results[rig] = (json.loads((tmp_path / f"{rig}.json").read_text()),
                        json.loads((tmp_path / f"{rig}.eval.json").read_text()))
    source_motifs, source_eval = results["source"]
    for rig in ("mannequin", "mixamo"):
        motifs, evaluated = results[rig]
        assert motifs["genre"] == source_motifs["genre"] == "salsa"
        assert abs(motifs["chi2"] - source_motifs["chi2"]) <= 0.05, (rig, motifs["chi2"], source_motifs["chi2"])
        assert evaluated["mocap_style"] == source_eval["mocap_style"]
        for key in ("hit_rate", "accent_precision", "accent_recall", "joint_speed_p99_vs_mocap", "foot_skate_m_s"):
            a, b = source_eval["dance"][key], evaluated["dance"][key]
            assert abs(a - b) <= 0.05 * max(abs(a), 0.05), (rig, key, a, b)

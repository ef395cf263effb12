"""The page as a dance studio (issue 34), each behaviour in headless Chromium against the real server:
only the dance on stage gets its video, the menus offer only what works, a dance the server let go of
says so, a failed dance does not pass for the one on stage."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from serve_support import CLIENTS, VIDEO_SIZE
from servers import uvicorn_server
from test_serve_page import needs_browser

SHOTS = Path("/tmp/web_shots")


@pytest.fixture(scope="module")
def studio():
    """A server that keeps two dances (so a test can make it let one go) and renders small videos."""
    from dancesynth.web.server import create_app

    with uvicorn_server(create_app(max_stored_dances=2, video_size=VIDEO_SIZE)) as address:
        yield address


def run_studio(server, tmp_path, scenario) -> dict:
    chromium = "/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else shutil.which("chromium")
    proc = subprocess.run(["node", str(CLIENTS / "studio_check.mjs"), f"http://{server[0]}:{server[1]}/",
                           str(tmp_path), scenario, chromium], capture_output=True, text=True, timeout=300,
                          cwd=CLIENTS)
    shutil.copytree(tmp_path, SHOTS / tmp_path.name, dirs_exist_ok=True)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report["ok"] and not report["errors"] and not report["console"], report
    return report


@needs_browser
def test_only_the_dance_on_stage_gets_its_video(studio, tmp_path):
    """An MP4 asked for, then another song danced and its MP4 asked for: the file saved is the new song's,
    and the first render was cancelled (it does not hold the queue for a video nobody wants)."""
    report = run_studio(studio, tmp_path, "stale-video")
    assert report["saved"].startswith("sorohanro_-_solo-trumpet"), report
    assert report["first_render"]["state"] == "cancelled", report["first_render"]
    assert report["video"]["state"] == "done" and report["video"]["dance_id"] == report["second_id"]


@needs_browser
def test_the_menus_offer_only_what_the_engines_can_dance(studio, tmp_path):
    report = run_studio(studio, tmp_path, "neural-styles")
    with_neural = {s["value"]: s["disabled"] for s in report["with_neural"]["styles"] if s["value"]}
    assert not any(d for v, d in with_neural.items() if v.startswith("salsa")), with_neural
    assert all(d for v, d in with_neural.items() if not v.startswith("salsa")), with_neural
    engines = {e["value"]: e["disabled"] for e in report["with_other_style"]["engines"]}
    assert engines["neural"] and not engines["streaming"], engines
    # The API refuses the combination with a reason a page user can act on (400, not 500).
    assert report["api"]["status"] == 400, report["api"]
    assert "learned only salsa" in report["api"]["body"]["error"] and "dancesynth train" not in \
        report["api"]["body"]["error"]


@needs_browser
def test_a_dance_the_server_let_go_of_says_so(studio, tmp_path):
    report = run_studio(studio, tmp_path, "gone")
    assert "let this one go" in report["after_bvh"] and "press Dance" in report["after_bvh"], report
    assert report["links"] == ["true", "true", "true", "true"] and report["mp4_disabled"], report
    assert report["saved"] is None, "an empty or error file was saved"


@needs_browser
def test_a_failed_dance_does_not_pass_for_the_one_on_stage(studio, tmp_path):
    report = run_studio(studio, tmp_path, "error-keeps-label")
    assert "Could not dance" in report["status"] and "seed" in report["status"], report
    assert report["info_after"].startswith("Still on stage, the previous dance: "), report
    assert report["info_after"].endswith(report["info_before"])


@needs_browser
def test_a_user_dances_their_own_character_and_downloads_it(studio, tmp_path):
    """"Your own file" in the Character menu: a GLB dances on stage as itself and downloads as GLB (the user's
    model with the dance) and VRMA; a .gltf reaching outside its folder is refused with the loader's words,
    the dance on stage labelled as the previous one; a VRM dropped on the page dances."""
    import pygltflib

    from fuzz.character_target import make_seeds

    seeds = tmp_path / "seeds"
    seeds.mkdir()
    make_seeds(seeds)
    doc = json.loads((seeds / "model.gltf").read_text())
    doc["buffers"][0]["uri"] = "../../../etc/passwd"
    (tmp_path / "evil.gltf").write_text(json.dumps(doc))
    shutil.copy(seeds / "avatar1.vrm", tmp_path / "avatar.vrm")
    report = run_studio(studio, tmp_path, "own-character")
    assert report["hidden_before"] and not report["hidden_after"]
    assert "Choose your character file" in report["no_file"], report["no_file"]
    own = report["own"]
    assert own["state"] == "ready" and own["character"] == "My_Avatar" and own["view"] == "character", own
    assert report["saved_glb"] == "sorohanro_-_solo-trumpet-06-My_Avatar.glb", report
    model = pygltflib.GLTF2().load(str(tmp_path / "own-glb.glb"))
    assert model.meshes and [a.name for a in model.animations][0] == "dance"
    assert report["saved_vrma"].endswith(".vrma") and (tmp_path / "own-vrma.vrma").read_bytes()[:4] == b"glTF"
    assert report["saved_fbx"] == "sorohanro_-_solo-trumpet-06-My_Avatar.fbx"
    assert (tmp_path / "own-fbx.fbx").read_bytes().startswith(b"Kaydara FBX Binary")
    evil = report["evil"]
    assert evil["state"] == "error" and "outside the model's folder" in evil["status"], evil
    assert "/tmp" not in evil["status"] and evil["info"].startswith("Still on stage, the previous dance: "), evil
    assert report["dropped"]["state"] == "ready" and report["dropped"]["view"] == "character", report["dropped"]


@needs_browser
def test_a_span_is_re_danced_in_the_page_and_undone(studio, tmp_path):
    """Shift+drag on the timeline selects a span on beats; "4 bars from here" selects the bars from the one
    playing; Re-dance span gives a new dance whose frames differ from the old one's only within the span
    (the music plays on); Undo brings the old one back; a motif that does not exist is refused in words."""
    report = run_studio(studio, tmp_path, "edit")
    assert report["panel_folded"], "the edit panel waits folded until a span is chosen"
    assert report["dragged"]["open"], "choosing a span opens the edit panel"
    dragged = report["dragged"]["span"]
    assert dragged and 16 < dragged["start"] < 21 and 22 < dragged["end"] < 27, report["dragged"]
    assert report["dragged"]["time"] == 0, "a Shift+drag selects, it does not seek"
    span = report["selected"]
    assert 18 < span["start"] <= 20.01 and 6.5 < span["end"] - span["start"] < 8.0, span   # 4 bars at 130 bpm
    after = report["after"]
    assert after["state"] == "ready" and len(after["edits"]) == 1 and after["undo"], after
    assert after["edits"][0]["seed"] == 5 and abs(after["edits"][0]["start_s"] - span["start"]) < 0.01
    assert "/api/songs/" in after["src"] and after["time"] < span["start"], after
    assert report["info_after"].endswith("1 span re-danced"), report["info_after"]
    changed = report["changed"]
    assert changed["same_length"] and changed["count"] > 0, changed
    assert span["start"] - 0.05 <= changed["first"] / 30 and changed["last"] / 30 <= span["end"] + 0.05, (changed, span)
    undone = report["undone"]
    assert undone["id"] != after["id"] and not undone["undo"] and report["info_undone"] == report["info_before"]
    assert "Could not re-dance the span" in report["bad_motif"]["status"], report["bad_motif"]
    assert "M9999" in report["bad_motif"]["status"] and report["bad_motif"]["id"] == undone["id"]
    opened, closed = report["bracket_open"], report["bracket_close"]
    assert opened["start"] == pytest.approx(30, abs=0.3) and 31 < opened["end"] < 32.5, opened   # a bar on
    assert closed["start"] == opened["start"] and closed["end"] == pytest.approx(40, abs=0.3), closed


@needs_browser
def test_the_page_fits_a_phone_and_a_desktop(studio, tmp_path):
    """At 390x844 nothing scrolls sideways and the stage has most of the screen (the live controls folded
    away); at 1280x800 likewise, before and after a dance."""
    report = run_studio(studio, tmp_path, "layout")
    for size, states in report["sizes"].items():
        height = int(size.split("x")[1])
        for name, m in states.items():
            assert m["scroll_width"] <= m["window_width"], (size, name, m)
            assert m["stage"]["height"] >= 0.55 * height, (size, name, m)


@needs_browser
def test_limits_drop_live_engine_and_names(studio, tmp_path):
    """The limits are on the page before an upload; a dropped song is danced, one over the limit is refused
    before it is sent; the engine menu is off while live is on (live is always the streaming engine); no two
    controls share an accessible name."""
    report = run_studio(studio, tmp_path, "small-things")
    assert "50 MB" in report["limits"] and "15 min" in report["limits"], report["limits"]
    assert "takes files up to 50 MB" in report["too_large"]["status"] and report["too_large"]["uploads"] == 0
    assert report["dropped"]["state"] == "ready" and report["dropped"]["file"] == "my song.ogg", report["dropped"]
    assert "/api/uploads/" in report["dropped"]["audio"]
    assert report["engine_disabled_live"] and not report["engine_disabled_after"]
    names = [n for n in report["names"] if n]
    assert len(names) == len(set(names)), sorted(names)


@needs_browser
def test_the_dancer_fills_the_stage_while_playing_and_right_after_seeks(studio, tmp_path):
    """At a phone's and a desktop's size, at 10 moments of play and 10 right after seeks: the dancer's box
    (her bones on screen) is at least 40 % of the stage's height and inside it (the camera aims where she
    is around each moment, so a seek does not leave her at the edge)."""
    report = run_studio(studio, tmp_path, "framing")
    for size, boxes in report["sizes"].items():
        assert len(boxes) == 20
        for box in boxes:
            assert box["height"] >= 0.40, (size, box)
            assert box["left"] > 0.0 and box["right"] < 1.0 and box["top"] > 0.0 and box["bottom"] < 1.0, (size, box)
    # The follow view (the default): the camera stands where the server's yaw (the MP4 camera's) says.
    assert report["default_view"] == "follow"
    camera = report["camera"]
    assert camera["rate_hz"] > 0 and len(camera["yaw"]) > 50
    turned = np.unwrap([box["view_yaw"] for box in report["follow"]])
    for box, yaw in zip(report["follow"], turned):
        want = np.interp(box["t"] * camera["rate_hz"], np.arange(len(camera["yaw"])), camera["yaw"])
        assert abs((yaw - want + np.pi) % (2 * np.pi) - np.pi) < 0.05, (box, want)
        assert box["height"] >= 0.40 and 0 < box["left"] and box["right"] < 1, box
    assert np.ptp(turned) > 0.3, "the follow view should turn with her over a minute of salsa"


@needs_browser
def test_the_timeline_seeks_and_the_keys_move_by_beats_bars_and_seconds(studio, tmp_path):
    report = run_studio(studio, tmp_path, "timeline")
    beats, downbeats = report["marks"]["beats"], report["marks"]["downbeats"]
    assert report["marks"]["timeline"]["beats"] == len(beats) > 100 and 0 < len(downbeats) < len(beats) / 2
    steps = {s["action"] + f"#{i}": s for i, s in enumerate(report["steps"])}
    s = report["steps"]
    assert s[0]["t"] == pytest.approx(report["duration"] / 2, abs=0.02 * report["duration"])   # the middle
    assert s[1]["t"] == pytest.approx(s[0]["t"] + 10, abs=0.05)                              # L: 10 s on
    assert s[2]["t"] == pytest.approx(s[0]["t"], abs=0.05)                                   # J: 10 s back
    after = [b for b in beats if b > s[2]["t"] + 1e-3]
    assert s[3]["t"] == pytest.approx(after[0], abs=0.01) and s[4]["t"] == pytest.approx(after[1], abs=0.01)
    assert s[5]["t"] == pytest.approx(after[0], abs=0.01)                                    # back a beat
    bar = [b for b in downbeats if b > s[5]["t"] + 1e-3][0]
    assert s[6]["t"] == pytest.approx(bar, abs=0.01)                                         # on to the next bar
    assert not s[7]["paused"] and s[8]["paused"]                                             # space plays, pauses
    assert "Paused at" in s[8]["status"] and "beat" in s[8]["status"], s[8]
    assert steps


@needs_browser
def test_axe_finds_no_serious_or_critical_violations(studio, tmp_path):
    report = run_studio(studio, tmp_path, "axe")
    assert set(report["states"]) == {"idle", "dancing", "editing", "live", "error", "light_dancing"}
    assert report["light_background"] == "rgb(244, 245, 247)"   # the light theme when the system asks for it
    assert all(not found for found in report["states"].values()), report["states"]

"""`dancesynth serve`: the web API over real HTTP (the page in Chromium: test_serve_page.py; live dances over
WebSocket: test_serve_live.py; a user's character and re-danced spans: test_serve_studio_api.py)."""

from __future__ import annotations

import json
import shutil
import sys
import threading
import time

import numpy as np
import pytest
import soundfile as sf

from conftest import BUNDLED_MUSIC, REPO
from serve_support import (MAX_UPLOAD_MB, TRUMPET, VIDEO_SIZE, assert_video_with_song,  # noqa: F401 (fixtures)
                           glb_json, kept_dance, multipart, post_dance, request, server, wait_for_video)
from servers import uvicorn_server

sys.path.insert(0, str(REPO / "benchmarks"))  # serve_load's client, which retries a busy answer as the page does


def test_styles_and_songs_are_listed_and_a_song_is_served(server):
    status, _, data = request(server, "GET", "/api/styles")
    assert status == 200
    names = [s["name"] for s in json.loads(data)["styles"]]
    assert any("salsa" in n for n in names)
    status, _, data = request(server, "GET", "/api/songs")
    assert status == 200
    songs = {s["name"]: s for s in json.loads(data)["songs"]}
    assert TRUMPET.name in songs
    assert all(not n.endswith(".txt") for n in songs)
    status, headers, audio = request(server, "GET", songs[TRUMPET.name]["url"])
    assert status == 200 and audio == TRUMPET.read_bytes()
    assert headers["content-type"].startswith("audio/ogg")


def test_the_page_and_its_vendored_three_js_are_served(server):
    status, _, page = request(server, "GET", "/")
    assert status == 200 and b'type="importmap"' in page and b"/static/app.js" in page
    for path in ("/static/app.js", "/static/vendor/three.module.js", "/static/vendor/three.core.js",
                 "/static/vendor/BVHLoader.js", "/static/vendor/OrbitControls.js",
                 "/static/vendor/loaders/GLTFLoader.js", "/static/vendor/utils/BufferGeometryUtils.js",
                 "/static/vendor/utils/SkeletonUtils.js", "/static/vendor/LICENSE-three.txt"):
        status, _, _ = request(server, "GET", path)
        assert status == 200, path


def test_a_dance_of_a_bundled_song_returns_a_bvh_as_long_as_the_song(server):
    from dancesynth.io.bvh import parse_bvh

    status, result = post_dance(server, {"song": TRUMPET.name, "style": "", "seed": "3"})
    assert status == 200, result
    clip = parse_bvh(result["bvh"])
    duration = sf.info(TRUMPET).duration
    assert clip.fps == pytest.approx(30.0) == result["fps"]
    assert clip.n_frames == int(duration * 30) + 1 == result["frames"]
    assert result["duration_s"] == pytest.approx(duration, abs=0.05)
    beats = np.asarray(result["beats"])
    assert len(beats) >= 3 and np.all(np.diff(beats) > 0) and 0 <= beats[0] and beats[-1] <= duration
    assert result["tempo_bpm"] > 0 and result["style"]
    assert result["audio_url"] == f"/api/songs/{TRUMPET.name}"


def test_engines_and_characters_are_listed(server):
    from dancesynth.api import ENGINES
    from dancesynth.retarget.rigs import LAYOUTS

    status, _, data = request(server, "GET", "/api/engines")
    engines = json.loads(data)
    assert status == 200 and [e["name"] for e in engines["engines"]] == list(ENGINES)
    assert engines["default"] == "streaming"
    # What each engine can dance: the neural one only the genres it has a model of, the others any.
    assert {e["name"]: e["genres"] for e in engines["engines"]} == {
        "streaming": None, "global": None, "choreography": None, "neural": ["salsa"]}
    status, _, data = request(server, "GET", "/api/limits")
    assert status == 200 and json.loads(data) == {"max_upload_mb": MAX_UPLOAD_MB, "max_song_minutes": 15.0}
    status, _, data = request(server, "GET", "/api/characters")
    characters = json.loads(data)
    assert status == 200 and [c["name"] for c in characters["characters"]] == list(LAYOUTS)
    assert characters["default"] == "mannequin"
    assert {c["name"] for c in characters["characters"] if c["mesh"]} == {"mannequin"}  # the others are rigs


@pytest.mark.parametrize("engine, character", [
    ("streaming", "mannequin"), ("global", "mixamo"), ("choreography", "smpl"), ("neural", "cmu"), ("", "vrm")])
def test_the_chosen_engine_dances_on_the_chosen_character(server, engine, character):
    from dancesynth.io.bvh import parse_bvh
    from dancesynth.retarget.rigs import rig_skeleton

    status, result = post_dance(server, {"song": TRUMPET.name, "engine": engine, "character": character})
    assert status == 200, result
    assert result["engine"] == (engine or "streaming")  # the engine's own record of the dance
    assert result["character"] == character and result["mesh"] == (character == "mannequin")
    clip = parse_bvh(result["bvh"])  # the stick figure: the dance on the character's rig
    assert rig_skeleton(character)[0].names == tuple(result["joints"])
    assert sorted(clip.skeleton.names) == sorted(result["joints"])  # a BVH lists joints depth first
    assert clip.n_frames == int(sf.info(TRUMPET).duration * 30) + 1 == result["frames"]
    assert (result["glb_url"] is not None) == result["mesh"]
    assert result["sections"] and result["sections"][0]["start_s"] == 0.0


def test_downloads_are_valid_bvh_glb_vrma_and_fbx_files(server, tmp_path):
    from dancesynth.io.bvh import read_bvh

    result = kept_dance(server)
    files = {}
    for kind, url in result["downloads"].items():
        status, headers, files[kind] = request(server, "GET", url)
        assert status == 200, (kind, files[kind][:200])
        assert headers["content-disposition"] == f'attachment; filename="sorohanro_-_solo-trumpet-06-mannequin.{kind}"'
    (tmp_path / "dance.bvh").write_bytes(files["bvh"])
    clip = read_bvh(tmp_path / "dance.bvh", drop_tpose=False)
    assert clip.n_frames == result["frames"] and sorted(clip.skeleton.names) == sorted(result["joints"])
    gltf = glb_json(files["glb"])  # the mannequin: a skinned mesh and the dance
    assert gltf["meshes"] and gltf["skins"] and gltf["animations"]
    status, _, shown = request(server, "GET", result["glb_url"])  # what the page shows is what is downloaded
    assert status == 200 and shown == files["glb"]
    vrma = glb_json(files["vrma"])
    assert "VRMC_vrm_animation" in vrma["extensionsUsed"] and "VRMC_vrm_animation" in vrma["extensions"]
    assert vrma["animations"]
    assert files["fbx"].startswith(b"Kaydara FBX Binary"), files["fbx"][:40]   # Blender's, for game engines


def test_a_rig_without_a_mesh_downloads_its_skeleton_and_dance(server):
    result = kept_dance(server, "cmu")
    assert result["glb_url"] is None
    status, _, data = request(server, "GET", result["downloads"]["glb"])
    gltf = glb_json(data)
    assert status == 200 and gltf["animations"] and not gltf.get("meshes")
    assert "LHipJoint" in [n.get("name") for n in gltf["nodes"]]


def test_a_character_in_its_rest_pose_is_served_as_glb_for_the_live_page(server):
    """``/api/characters/{name}.glb``: the built-in standing in its rest pose, its joints named as in the
    live hierarchy (the mannequin with its skinned mesh, a rig without); anything else is a 404."""
    from dancesynth.retarget.character import load_character

    status, headers, data = request(server, "GET", "/api/characters/mannequin.glb")
    assert status == 200 and headers["content-type"] == "model/gltf-binary"
    gltf = glb_json(data)
    assert gltf["meshes"] and gltf["skins"]
    names = [gltf["nodes"][j]["name"] for j in gltf["skins"][0]["joints"]]
    mannequin = load_character("mannequin")
    assert names == list(mannequin.skeleton.names)
    assert gltf["nodes"][0]["translation"] == pytest.approx(list(mannequin.rest_root))
    status, _, data = request(server, "GET", "/api/characters/cmu.glb")
    gltf = glb_json(data)
    assert status == 200 and not gltf.get("meshes") and "LHipJoint" in [n.get("name") for n in gltf["nodes"]]
    for path in ("/api/characters/robot.glb", "/api/characters/..%2F..%2Fetc%2Fpasswd.glb"):
        status, _, data = request(server, "GET", path)
        assert status == 404, data[:200]
    assert "no character named 'robot'" in json.loads(request(server, "GET", "/api/characters/robot.glb")[2])["error"]


def test_an_mp4_is_rendered_on_the_server_with_the_song(server, tmp_path):
    result = kept_dance(server)
    video = result["video_url"] + "?figure=character"
    status, _, data = request(server, "GET", video)
    assert status == 404 and "POST" in json.loads(data)["error"], "nothing is rendered before it is asked for"
    status, _, data = request(server, "POST", video)
    job = json.loads(data)
    assert status == 202 and job["state"] in ("queued", "rendering"), job
    job, states = wait_for_video(server, video)
    assert job["state"] == "done" and job["progress"] == 1.0, job
    status, _, again = request(server, "POST", video)  # asked again: the same video, not a second render
    assert status == 200 and json.loads(again)["url"] == job["url"]
    status, headers, mp4 = request(server, "GET", job["url"])
    assert status == 200 and headers["content-type"] == "video/mp4"
    assert 'filename="sorohanro_-_solo-trumpet-06-mannequin.mp4"' in headers["content-disposition"]
    (tmp_path / "dance.mp4").write_bytes(mp4)
    assert_video_with_song(tmp_path / "dance.mp4")


def test_a_render_can_be_cancelled_and_started_again(server):
    """DELETE cancels a video (the page does when another dance takes the stage); a later POST starts afresh.
    While it renders, the status estimates the seconds left."""
    result = kept_dance(server)
    video = result["video_url"] + "?figure=stick"
    status, _, data = request(server, "POST", video)
    assert status == 202
    status, _, data = request(server, "DELETE", video)
    assert status == 200 and json.loads(data)["state"] == "cancelled", data
    status, _, data = request(server, "POST", video)
    assert status == 202 and json.loads(data)["state"] in ("queued", "rendering")
    seen_eta = []
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        job = json.loads(request(server, "GET", video)[2])
        if job["state"] == "rendering" and job["eta_s"] is not None:
            seen_eta.append(job["eta_s"])
        if job["state"] not in ("queued", "rendering"):
            break
        time.sleep(0.1)
    assert job["state"] == "done", job
    assert seen_eta and min(seen_eta) >= 0, "no estimate of the time left was given while it rendered"


def test_library_advice_for_the_command_line_is_reworded_for_the_page():
    from pathlib import Path

    from dancesynth.errors import InputError
    from dancesynth.io.audio import _check_duration
    from dancesynth.web.server import _for_the_page

    with pytest.raises(InputError) as exc:
        _check_duration(Path("long.ogg"), 20 * 60.0, 15 * 60.0, 0.1)
    worded = _for_the_page(str(exc.value))
    assert "--max-minutes" not in worded and "max_duration_s" not in worded and "cut the song" in worded


@pytest.mark.parametrize("path, method, code, words", [
    ("/api/dances/0123456789abcdef0123456789abcdef/dance.glb", "GET", 404, "no such dance"),
    ("/api/dances/0123456789abcdef0123456789abcdef/video", "POST", 404, "no such dance"),
    ("/api/dances/{id}/dance.obj", "GET", 404, "formats"),
    ("/api/dances/{id}/dance.mp4", "GET", 404, "not rendered"),
    ("/api/dances/{id}/video?figure=ghost", "POST", 400, "figure"),
    ("/api/dances/{id}/dance.bvh", "POST", 405, ""),
])
def test_bad_dance_urls_get_a_clear_error(server, path, method, code, words):
    path = path.format(id=kept_dance(server)["dance_id"]) if "{id}" in path else path
    status, _, data = request(server, method, path)
    assert status == code, data[:200]
    assert words in json.loads(data)["error"]


def test_only_the_last_dances_are_kept_and_renders_are_bounded():
    """The server forgets all but the last max_stored_dances dances; one render at a time, none waiting:
    a second video asked for meanwhile is refused with 503 and a Retry-After, like a busy dance."""
    from dancesynth.web.server import create_app

    app = create_app(max_stored_dances=2, max_renders=1, max_waiting_renders=0, video_size=VIDEO_SIZE)
    with uvicorn_server(app) as address:
        first, second, third = (kept_dance(address, c) for c in ("mannequin", "mixamo", "mannequin"))
        status, _, _ = request(address, "GET", first["downloads"]["bvh"])
        assert status == 404, "the oldest dance is forgotten"
        for kept in (second, third):
            assert request(address, "GET", kept["downloads"]["bvh"])[0] == 200
        status, _, _ = request(address, "POST", third["video_url"])
        assert status == 202
        status, headers, data = request(address, "POST", third["video_url"] + "?figure=stick")
        assert status == 503 and "busy" in json.loads(data)["error"] and int(headers["retry-after"]) >= 1
        job, _ = wait_for_video(address, third["video_url"])
        assert job["state"] == "done"
        status, _, _ = request(address, "POST", third["video_url"] + "?figure=stick")
        assert status == 202, "the queue is free again"
        wait_for_video(address, third["video_url"] + "?figure=stick")


def test_an_uploaded_song_is_kept_while_its_video_renders(server, tmp_path):
    status, result = post_dance(server, {"character": "smpl"}, {"audio": ("my song.ogg", TRUMPET.read_bytes())})
    assert status == 200, result
    status, _, _ = request(server, "POST", result["video_url"])  # a rig: its stick figure, with the song
    assert status == 202
    job, _ = wait_for_video(server, result["video_url"])
    assert job["state"] == "done", job
    status, headers, mp4 = request(server, "GET", job["url"])
    assert status == 200 and 'filename="my_song-smpl.mp4"' in headers["content-disposition"]
    (tmp_path / "dance.mp4").write_bytes(mp4)
    assert_video_with_song(tmp_path / "dance.mp4")


def test_an_upload_held_for_a_video_is_not_removed_to_make_room():
    from dancesynth.web.uploads import UploadStore

    store = UploadStore(max_files=1)
    try:
        key, path = store.new_path("a.ogg")
        path.write_bytes(b"song")
        store.done(key)
        store.served(key)
        assert store.hold(key) == path
        assert store.new_path("b.ogg") is None and path.is_file(), "busy: the only place holds a song being rendered"
        store.release(key)
        assert store.new_path("b.ogg") is not None and not path.exists()
        assert store.hold(key) is None, "gone: a video of it cannot be made any more"
    finally:
        store.close()


def test_an_uploaded_song_is_danced_and_kept_for_playback(server):
    status, result = post_dance(server, {"style": "salsa"}, {"audio": ("my song.ogg", TRUMPET.read_bytes())})
    assert status == 200, result
    assert result["style"].startswith("salsa")
    assert result["audio_url"].startswith("/api/uploads/") and result["audio_url"].endswith(".ogg")
    status, _, audio = request(server, "GET", result["audio_url"])
    assert status == 200 and audio == TRUMPET.read_bytes()


@pytest.mark.parametrize("path", [
    "/static/../server.py", "/static/..%2Fserver.py", "/static/%2e%2e/server.py", "/static/vendor/../../server.py",
    "/api/songs/..%2F..%2Fpyproject.toml", "/api/songs/..%2F..%2F..%2F..%2Fpyproject.toml",
    "/api/songs/sorohanro_-_solo-trumpet-06.txt", "/api/uploads/..%2F..%2Fetc%2Fpasswd", "/api/uploads/nothing",
])
def test_paths_outside_the_served_files_are_not_found(server, path):
    status, _, data = request(server, "GET", path)
    assert status == 404, (path, data[:200])
    assert b"import" not in data and b"[project]" not in data and b"root:" not in data


def test_an_oversized_upload_is_refused_with_413(server):
    big = b"\0" * int((MAX_UPLOAD_MB + 0.5) * 2**20)
    body, headers = multipart({"style": ""}, {"audio": ("big.ogg", big)})
    status, _, data = request(server, "POST", "/api/dance", body, headers)
    assert status == 413 and "limit" in json.loads(data)["error"]
    # Without a Content-Length (chunked), the server stops reading at the limit.
    status, _, data = request(server, "POST", "/api/dance", iter([body[i:i + 65536]
                                                                    for i in range(0, len(body), 65536)]), headers)
    assert status == 413 and "limit" in json.loads(data)["error"]


@pytest.mark.parametrize("fields, files, words", [
    ({}, {"audio": ("notes.ogg", b"this is not audio, just a text file\n" * 50)}, ["notes"]),
    ({"song": "no_such_song.ogg"}, None, ["no bundled song"]),
    ({}, None, ["audio file"]),
    ({"song": TRUMPET.name, "seed": "abc"}, None, ["seed"]),
    ({"song": TRUMPET.name, "seed": "--5"}, None, ["seed"]),  # issue 13: was HTTP 500
    ({"song": TRUMPET.name, "seed": "-1"}, None, ["seed"]),
    ({"song": TRUMPET.name, "style": "polka-on-ice"}, None, ["style"]),
    # Issue 13, every parameter validated: these were ignored, or the upload silently won.
    ({"song": TRUMPET.name, "seeds": "5"}, None, ["unknown field 'seeds'"]),
    ({"song": TRUMPET.name}, {"style": ("salsa.txt", b"salsa")}, ["'style' must be text"]),
    ({"audio": "song.ogg"}, None, ["'audio' must be a file"]),
    ({"song": TRUMPET.name}, {"audio": ("my song.ogg", TRUMPET.read_bytes())}, ["not both"]),
    ({"song": TRUMPET.name, "engine": "waltzomatic"}, None, ["unknown engine 'waltzomatic'", "streaming"]),
    ({"song": TRUMPET.name, "character": "robot"}, None, ["unknown character 'robot'", "mannequin"]),
    # Built-ins only: a path would have the server read a file of its own disk as a character.
    ({"song": TRUMPET.name, "character": "/etc/passwd"}, None, ["unknown character"]),
    ({"song": TRUMPET.name, "character": str(BUNDLED_MUSIC.parents[1] / "retarget" / "x.bvh")}, None,
     ["unknown character"]),
    # A user's character file: the CLI's checks, in the page's words.
    ({"song": TRUMPET.name}, {"character_file": ("me.txt", b"hello")}, ["must be .glb, .gltf, .vrm, .bvh", "me.txt"]),
    ({"song": TRUMPET.name}, {"character_file": ("me.glb", b"glTF" + bytes(40))}, ["me.glb"]),
    ({"song": TRUMPET.name}, {"character_file": ("me.bvh", b"HIERARCHY\nROOT")}, ["me.bvh"]),
    ({"song": TRUMPET.name}, {"bone_map": ("bones.toml", b"[bones]\n")}, ["a bone map goes with a character file"]),
    ({"song": TRUMPET.name, "character": "mannequin"}, {"character_file": ("me.gltf", b'{"asset": {"version": "2.0"}, '
     b'"buffers": [{"uri": "../../../etc/passwd", "byteLength": 4}]}')}, ["me.gltf"]),
])
def test_bad_requests_get_400_with_a_message_and_no_traceback(server, fields, files, words):
    status, result = post_dance(server, fields, files)
    assert status == 400, result
    for w in words:
        assert w.lower() in result["error"].lower()
    assert "Traceback" not in result["error"] and "dancesynth-uploads" not in result["error"]


def test_a_malformed_body_is_a_clean_error_and_the_server_keeps_serving(server):
    status, _, data = request(server, "POST", "/api/dance", b"garbage", {"Content-Type": "multipart/form-data"})
    assert 400 <= status < 500 and b"Traceback" not in data
    status, _, _ = request(server, "GET", "/api/songs")
    assert status == 200


def test_serve_refuses_a_busy_port_with_a_clear_error(server):
    from dancesynth.errors import InputError
    from dancesynth.web.server import serve

    with pytest.raises(InputError, match="cannot listen"):
        serve(host=server[0], port=server[1])


def test_bundled_songs_are_regular_files_only(tmp_path, monkeypatch):
    """Issue 13: a symlink placed in the bundled music folder was listed and served, wherever it led."""
    from dancesynth.web import server as web

    shutil.copy(TRUMPET, tmp_path / TRUMPET.name)
    (tmp_path / "secret.ogg").symlink_to("/etc/passwd")
    monkeypatch.setattr(web, "MUSIC_DIR", tmp_path)
    assert [s["name"] for s in web.bundled_songs()] == [TRUMPET.name]


def test_concurrent_uploads_are_all_danced_through_busy_answers_and_the_folder_stays_bounded():
    """Issue 13: of 30 concurrent uploads 11 got 400 'file not found' and 11 of the 19 dances came back
    with an audio_url already deleted, while the folder grew to 60 files against a bound of 8: uploads
    waiting for a dance slot were pruned. Now each is danced (its audio still there) or refused with
    503 before it is stored, with a Retry-After (it had none, so no client knew when to come back):
    a client that waits that long and asks again, as the page does, gets its dance."""
    from concurrent.futures import ThreadPoolExecutor

    from serve_load import upload_and_dance

    from dancesynth.web.server import create_app

    app = create_app(max_upload_mb=MAX_UPLOAD_MB, max_concurrent_dances=2, max_stored_uploads=4)
    with uvicorn_server(app) as address:
        store_dir = app.state.uploads.dir
        peak, stop = [0], threading.Event()

        def watch_folder():
            while not stop.is_set():
                peak[0] = max(peak[0], len(list(store_dir.iterdir())))
                time.sleep(0.01)

        watcher = threading.Thread(target=watch_folder, daemon=True)
        watcher.start()
        deadline = time.monotonic() + 120
        with ThreadPoolExecutor(12) as pool:
            outcomes = list(pool.map(lambda _: upload_and_dance(address, TRUMPET, deadline), range(12)))
        stop.set()
        watcher.join(5)
    # Danced: the BVH parses, and the audio_url served the upload when the page asked for it.
    assert all(o["status"] == 200 and o["correct"] for o in outcomes), outcomes
    assert sum(o["tries"] > 1 for o in outcomes) > 0, "nobody was told to wait: the test did not load the server"
    assert peak[0] <= 4


def test_a_busy_server_says_so_with_retry_after_and_holds_a_bounded_queue():
    """Issue 13: dances of bundled songs queued without bound (each request held until its turn).
    Now at most max_concurrent_dances + max_waiting_dances are held; the others get 503 and a Retry-After."""
    from concurrent.futures import ThreadPoolExecutor

    from dancesynth.web.server import create_app

    app = create_app(max_concurrent_dances=1, max_waiting_dances=1)
    with uvicorn_server(app) as address, ThreadPoolExecutor(6) as pool:
        body, headers = multipart({"song": TRUMPET.name})
        answers = list(pool.map(lambda _: request(address, "POST", "/api/dance", body, headers), range(6)))
    busy = [(h, json.loads(data)["error"]) for status, h, data in answers if status == 503]
    assert sorted({status for status, _, _ in answers}) == [200, 503], [a[0] for a in answers]
    assert all(1 <= int(h["retry-after"]) <= 60 and "busy" in msg for h, msg in busy), busy


def test_an_upload_being_sent_is_not_removed_to_make_room():
    """The audio_url answered 404 or 500 when the upload was pruned between looking it up and sending it:
    it counted as served (free to go) before it was sent. Now it is served once the response is done."""
    from dancesynth.web.uploads import UploadStore

    store = UploadStore(max_files=2)
    try:
        keys = [store.new_path("a.ogg")[0] for _ in range(2)]
        for key in keys:
            (store.dir / key).write_bytes(b"song")
            store.done(key)
        path = store.path(keys[0])  # the server is about to send it ...
        assert store.new_path("b.ogg") is None, "busy: both places hold songs not yet played"
        assert path.is_file()  # ... and it is still there to send
        store.served(keys[0])
        assert store.new_path("b.ogg") is not None and not path.exists(), "played, it makes room"
    finally:
        store.close()

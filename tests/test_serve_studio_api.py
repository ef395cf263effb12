"""`dancesynth serve`'s studio over HTTP (issue 34): a user's own character file danced, downloaded and
rendered, and a span of a dance re-danced (the page itself: test_serve_studio.py)."""

from __future__ import annotations

import json

import pytest

from serve_support import (MAX_UPLOAD_MB, TRUMPET, VIDEO_SIZE, assert_video_with_song, glb_json,  # noqa: F401
                           kept_dance, multipart, post_dance, request, server, wait_for_video)
from servers import uvicorn_server


def test_a_users_character_file_dances_downloads_and_renders_and_is_not_kept(tmp_path):
    """A GLB sent as ``character_file`` dances as itself (its name, its mesh), downloads as the user's model with
    the dance, and renders to MP4; once answered, the server keeps none of its files. A .gltf reaching for a
    file beside the server's folder is refused in the loader's words, without the server's paths."""
    from dancesynth.web.server import create_app

    app = create_app(max_upload_mb=MAX_UPLOAD_MB, video_size=VIDEO_SIZE)
    with uvicorn_server(app) as srv:
        _, _, glb = request(srv, "GET", "/api/characters/mannequin.glb")
        status, result = post_dance(srv, {"song": TRUMPET.name}, {"character_file": ("My Avatar.glb", glb)})
        assert status == 200 and result["character"] == "My_Avatar" and result["mesh"], result
        assert not list(app.state.characters_dir.iterdir()), "the user's file outlived the request"
        status, headers, data = request(srv, "GET", result["downloads"]["glb"])
        gltf = glb_json(data)
        assert status == 200 and gltf["meshes"] and gltf["animations"][0]["name"] == "dance"
        assert 'filename="sorohanro_-_solo-trumpet-06-My_Avatar.glb"' in headers["content-disposition"]
        status, _, fbx = request(srv, "GET", result["downloads"]["fbx"], timeout=180)   # made from the GLB kept
        assert status == 200 and fbx.startswith(b"Kaydara FBX Binary"), fbx[:200]
        video = result["video_url"] + "?figure=character"
        request(srv, "POST", video)
        job, _ = wait_for_video(srv, video)
        assert job["state"] == "done", job
        (tmp_path / "own.mp4").write_bytes(request(srv, "GET", job["url"])[2])
        assert_video_with_song(tmp_path / "own.mp4")
        doc = {"asset": {"version": "2.0"}, "buffers": [{"uri": "../secret.bin", "byteLength": 60}]}
        status, answer = post_dance(srv, {"song": TRUMPET.name},
                                    {"character_file": ("evil.gltf", json.dumps(doc).encode())})
        assert status == 400 and "outside the model's folder" in answer["error"], answer
        assert str(app.state.characters_dir) not in answer["error"] and "/tmp" not in answer["error"]
        assert not list(app.state.characters_dir.iterdir())


def redance(server, url, fields):
    body, headers = multipart(fields)
    status, _, data = request(server, "POST", url, body, headers)
    return status, json.loads(data)


def test_a_span_re_danced_is_a_new_dance_on_the_same_character_and_song(server):
    """``POST /api/dances/{id}/redance``: a new dance (its own id and files), the same song, length, beats and
    character, its edit listed; the old dance is still there (the page's undo); bad spans and fields get
    400 with what to send, a dance the server let go of 404."""
    result = kept_dance(server, "cmu", song="Kevin_MacLeod_-_Vibe_Ace.ogg")
    status, edited = redance(server, result["redance_url"], {"start_s": "20", "end_s": "27.5", "seed": "4"})
    assert status == 200, edited
    assert edited["dance_id"] != result["dance_id"] and edited["audio_url"] == result["audio_url"]
    assert (edited["frames"], edited["beats"], edited["character"]) == (result["frames"], result["beats"], "cmu")
    assert edited["edits"] == [{"start_s": pytest.approx(20, abs=0.3), "end_s": pytest.approx(27.5, abs=0.3),
                                "seed": 4, "style": result["style"], "engine": "streaming", "motif": None}]
    assert edited["bvh"] != result["bvh"] and edited["bvh"].split("MOTION")[0] == result["bvh"].split("MOTION")[0]
    assert request(server, "GET", result["downloads"]["bvh"])[0] == 200, "the old dance is kept for undo"
    for fields, words in [({"start_s": "20", "end_s": "20.1"}, "fewer than two beats"),
                          ({"start_s": "abc", "end_s": "3"}, "numbers of seconds"),
                          ({"start_s": "20", "end_s": "27", "seed": "-3"}, "seed"),
                          ({"start_s": "20", "end_s": "27", "motif": "../../x"}, "motif's name"),
                          ({"start_s": "20", "end_s": "27", "motif": "M9999"}, "M0 .. M"),
                          ({"start_s": "20", "end_s": "27", "style": "polka"}, "unknown style"),
                          ({"start_s": "20", "end_s": "27", "speed": "2"}, "unknown field 'speed'")]:
        status, answer = redance(server, result["redance_url"], fields)
        assert status == 400 and words in answer["error"], (fields, answer)
    status, answer = redance(server, "/api/dances/" + "0" * 32 + "/redance", {"start_s": "1", "end_s": "3"})
    assert status == 404 and "dance it again" in answer["error"]

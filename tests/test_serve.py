"""`dancesynth serve`: the web API over real HTTP, and the page in headless Chromium."""

from __future__ import annotations

import http.client
import json
import shutil
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from conftest import BUNDLED_MUSIC, REPO
from servers import http_folder, uvicorn_server

TRUMPET = BUNDLED_MUSIC / "sorohanro_-_solo-trumpet-06.ogg"
CLIENTS = REPO / "tests" / "clients"
sys.path.insert(0, str(REPO / "benchmarks"))  # serve_load's client, which retries a busy answer as the page does
MAX_UPLOAD_MB = 1.0  # the trumpet song (67 kB) fits; the oversized test sends more


@pytest.fixture(scope="module")
def server():
    """The app under uvicorn in a thread on a free 127.0.0.1 port; yields (host, port)."""
    from dancesynth.web.server import create_app

    with uvicorn_server(create_app(max_upload_mb=MAX_UPLOAD_MB)) as address:
        yield address


@pytest.fixture(scope="module")
def music_http():
    """The bundled songs over plain HTTP on 127.0.0.1 (a stand-in for an Internet radio); yields the base URL."""
    with http_folder(BUNDLED_MUSIC) as url:
        yield url


def request(server, method, path, body=None, headers=None, timeout=60):
    """One raw HTTP request (the path is sent exactly as given); returns (status, headers, bytes)."""
    conn = http.client.HTTPConnection(*server, timeout=timeout)
    try:
        chunked = body is not None and not isinstance(body, (bytes, str))
        conn.request(method, path, body=body, headers=headers or {}, encode_chunked=chunked)
        resp = conn.getresponse()
        return resp.status, dict(resp.getheaders()), resp.read()
    finally:
        conn.close()


def multipart(fields: dict, files: dict | None = None) -> tuple[bytes, dict]:
    boundary = uuid.uuid4().hex
    parts = []
    for name, value in fields.items():
        parts.append(f'--{boundary}\r\nContent-Disposition: form-data; name="{name}"\r\n\r\n{value}\r\n'.encode())
    for name, (filename, data) in (files or {}).items():
        parts.append(f'--{boundary}\r\nContent-Disposition: form-data; name="{name}"; filename="{filename}"\r\n'
                     f'Content-Type: application/octet-stream\r\n\r\n'.encode() + data + b"\r\n")
    body = b"".join(parts) + f"--{boundary}--\r\n".encode()
    return body, {"Content-Type": f"multipart/form-data; boundary={boundary}"}


def post_dance(server, fields, files=None):
    body, headers = multipart(fields, files)
    status, _, data = request(server, "POST", "/api/dance", body, headers)
    return status, json.loads(data)


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
                 "/static/vendor/LICENSE-three.txt"):
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


def live_messages(server, query: str, timeout_s: float = 40.0):
    """Every message of one /ws/live session: (JSON messages, audio bytes received)."""
    from websockets.sync.client import connect

    messages, audio = [], 0
    deadline = time.monotonic() + timeout_s
    with connect(f"ws://{server[0]}:{server[1]}/ws/live?{query}", open_timeout=10, max_size=None) as ws:
        while time.monotonic() < deadline:
            try:
                m = ws.recv(timeout=max(0.1, deadline - time.monotonic()))
            except TimeoutError:
                break
            except Exception:  # the server closed the connection
                break
            if isinstance(m, bytes):
                audio += len(m)
                continue
            messages.append(json.loads(m))
            if messages[-1]["type"] in ("end", "error"):
                break
    return messages, audio


def test_live_streams_audio_hierarchy_frames_and_beats(server, music_http):
    from urllib.parse import urlencode

    from dancesynth.io.bvh import parse_bvh

    url = f"{music_http}/{TRUMPET.name}"
    t0 = time.monotonic()
    messages, audio = live_messages(server, urlencode({"url": url, "segment_s": 2}))
    kinds = [m["type"] for m in messages]
    assert kinds[0] == "start" and kinds[-1] == "end", messages[-1]
    assert kinds.count("hierarchy") == 1 and kinds.index("hierarchy") < kinds.index("frames")
    duration = sf.info(TRUMPET).duration
    assert time.monotonic() - t0 > 0.8 * duration, "a stream plays at its own pace"
    assert audio == pytest.approx(duration * 22050 * 2, rel=0.02)
    frames = [m for m in messages if m["type"] == "frames"]
    assert len(frames) >= 2
    assert [f["start_frame"] for f in frames] == list(np.cumsum([0] + [len(f["rows"]) for f in frames[:-1]]))
    hierarchy = next(m for m in messages if m["type"] == "hierarchy")
    rows = [r for f in frames for r in f["rows"]]
    text = "\n".join([hierarchy["bvh"], "MOTION", f"Frames: {len(rows)}", "Frame Time: 0.03333333", *rows])
    clip = parse_bvh(text)
    assert clip.n_frames == len(rows) == messages[-1]["summary"]["frames"]
    assert abs(clip.n_frames / 30 - duration) < 0.5
    beats = [t for m in messages if m["type"] == "beats" for t in m["beats"]]
    assert len(beats) >= 3 and np.all(np.diff(beats) > 0)


def test_a_client_that_leaves_mid_stream_stops_the_live_dance(server, music_http):
    from urllib.parse import urlencode

    from websockets.sync.client import connect

    query = urlencode({"url": f"{music_http}/Kevin_MacLeod_-_Vibe_Ace.ogg", "segment_s": 2})
    with connect(f"ws://{server[0]}:{server[1]}/ws/live?{query}", open_timeout=10, max_size=None) as ws:
        assert json.loads(ws.recv(timeout=10))["type"] == "start"
        for _ in range(5):
            ws.recv(timeout=10)  # some audio
    deadline = time.monotonic() + 20
    while any(t.name == "dancesynth-live" for t in threading.enumerate()) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(t.name == "dancesynth-live" for t in threading.enumerate()), "the live thread kept running"
    status, _, _ = request(server, "GET", "/api/songs")
    assert status == 200


@pytest.mark.parametrize("query, words", [
    ("url=/etc/passwd", "http"), ("url=-", "http"), ("", "http"),
    ("url=http://127.0.0.1:9/x.ogg&segment_s=abc", "segment_s"),
    ("url=http://127.0.0.1:9/nothing.ogg", "no audio"),
])
def test_live_refuses_bad_streams_with_a_message(server, query, words):
    messages, _ = live_messages(server, query, timeout_s=30)
    assert messages[-1]["type"] == "error", messages
    assert words in messages[-1]["error"]


def _browser_missing() -> str | None:
    if not shutil.which("node"):
        return "node is not installed"
    if not Path("/usr/bin/chromium").exists() and not shutil.which("chromium"):
        return "chromium is not installed"
    if not (CLIENTS / "node_modules" / "playwright-core").is_dir():
        return "playwright-core is not installed (cd tests/clients && npm ci)"
    return None


def run_viewer(server, tmp_path, mode, value):
    chromium = "/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else shutil.which("chromium")
    url = f"http://{server[0]}:{server[1]}/"
    proc = subprocess.run(["node", str(CLIENTS / "viewer_check.mjs"), url, str(tmp_path), mode, value, chromium],
                          capture_output=True, text=True, timeout=150, cwd=CLIENTS)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report["ok"], report
    assert not report["errors"], report["errors"]
    assert not report["console"], report["console"]
    assert report["times"][1] - report["times"][0] > 0.3, "the music clock did not run"
    assert_dancing(tmp_path)
    return report


def assert_dancing(folder: Path):
    """The two screenshots show the (orange) character near the centre, in two different poses."""
    from PIL import Image

    a, b = (np.asarray(Image.open(folder / f"{n}.png").convert("RGB")).astype(int) for n in "ab")
    assert a.shape == b.shape
    h, w, _ = a.shape

    def figure(img):  # the character is orange; the background, grid and ring are not
        r, g, bl = img[..., 0], img[..., 1], img[..., 2]
        return (r > 150) & (r - bl > 90) & (g > 50)

    fa, fb = figure(a), figure(b)
    centre = (slice(h // 5, 4 * h // 5), slice(w // 4, 3 * w // 4))
    assert fa[centre].sum() > 500 and fb[centre].sum() > 500, "the character is not drawn near the centre"
    region = fa | fb
    changed = (np.abs(a - b).sum(axis=2) > 60) & region
    assert changed.sum() > 0.05 * region.sum(), "the character did not move between the screenshots"


def test_serve_refuses_a_busy_port_with_a_clear_error(server):
    from dancesynth.errors import InputError
    from dancesynth.web.server import serve

    with pytest.raises(InputError, match="cannot listen"):
        serve(host=server[0], port=server[1])


@pytest.mark.skipif(_browser_missing() is not None, reason=str(_browser_missing()))
def test_the_page_dances_to_a_bundled_song_in_headless_chromium(server, tmp_path):
    report = run_viewer(server, tmp_path, "song", "trumpet")
    assert report["page"]["frames"] == int(sf.info(TRUMPET).duration * 30) + 1


@pytest.mark.skipif(_browser_missing() is not None, reason=str(_browser_missing()))
def test_the_page_dances_live_to_a_stream_in_headless_chromium(server, music_http, tmp_path):
    report = run_viewer(server, tmp_path, "live", f"{music_http}/{TRUMPET.name}")
    live = report["page"]["live"]
    assert live["frames"] > 45 and live["beats"] >= 2
    # The delay the server asks for is enough: the motion of every moment heard had arrived.
    assert live["delay_s"] == pytest.approx(2 + 1.5 + 1.0)
    assert live["playing_s"] > 0.5 and live["starved_s"] < 0.1, live


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
    from dancesynth.web.server import UploadStore

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

"""What the `dancesynth serve` tests share: the app under uvicorn, the bundled songs over HTTP, raw
requests, multipart forms, a kept dance, a GLB's JSON, waiting for a video, and what a rendered video must be."""

from __future__ import annotations

import http.client
import json
import subprocess
import threading
import time
import uuid
from pathlib import Path

import pytest
import soundfile as sf

from conftest import BUNDLED_MUSIC, REPO
from servers import http_folder, uvicorn_server

TRUMPET = BUNDLED_MUSIC / "sorohanro_-_solo-trumpet-06.ogg"
CLIENTS = REPO / "tests" / "clients"
MAX_UPLOAD_MB = 1.0  # the trumpet song (67 kB) fits; the oversized test sends more
VIDEO_SIZE = (480, 270)  # a quarter of the server's default: the same code, rendered faster

@pytest.fixture(scope="module")
def server():
    """The app under uvicorn in a thread on a free 127.0.0.1 port; yields (host, port)."""
    from dancesynth.web.server import create_app

    with uvicorn_server(create_app(max_upload_mb=MAX_UPLOAD_MB, video_size=VIDEO_SIZE)) as address:
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

def ffprobe(path: Path) -> dict:
    out = subprocess.run(["ffprobe", "-v", "error", "-show_streams", "-show_format", "-of", "json", str(path)],
                         capture_output=True, text=True, timeout=30, check=True).stdout
    return json.loads(out)


def assert_video_with_song(path: Path):
    probe = ffprobe(path)
    kinds = sorted(s["codec_type"] for s in probe["streams"])
    assert kinds == ["audio", "video"], probe["streams"]
    assert float(probe["format"]["duration"]) == pytest.approx(sf.info(TRUMPET).duration, abs=0.3)
    video = next(s for s in probe["streams"] if s["codec_type"] == "video")
    assert (video["width"], video["height"]) == VIDEO_SIZE


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


def capture_session(server, query: str, pcm: bytes, rate: int, *, pace: float = 1.0, piece_s: float = 0.1,
                    end: bool = True, until=None, timeout_s: float = 60.0):
    """A page's capture over /ws/live?source=...: ``pcm`` (16-bit mono at ``rate``) sent in pieces of ``piece_s``
    at ``pace`` x real time (then {"type": "end"} if ``end``), while the messages are read until the end, an
    error, ``until(messages)`` or ``timeout_s``. Returns (JSON messages, audio bytes received back)."""
    from websockets.sync.client import connect

    messages, audio = [], 0
    t0 = time.monotonic()
    with connect(f"ws://{server[0]}:{server[1]}/ws/live?{query}", open_timeout=10, max_size=None) as ws:
        def send():
            size = 2 * int(piece_s * rate)
            try:
                for i, k in enumerate(range(0, len(pcm), size)):
                    time.sleep(max(0.0, t0 + i * piece_s / pace - time.monotonic()))
                    ws.send(pcm[k:k + size])
                if end:
                    ws.send(json.dumps({"type": "end"}))
            except Exception:  # the server closed the socket: a test reads why from the messages
                pass

        sender = threading.Thread(target=send, daemon=True)
        sender.start()
        while time.monotonic() - t0 < timeout_s:
            try:
                m = ws.recv(timeout=max(0.1, t0 + timeout_s - time.monotonic()))
            except Exception:  # a timeout, or the server closed the connection
                break
            if isinstance(m, bytes):
                audio += len(m)
                continue
            messages.append(json.loads(m))
            if messages[-1]["type"] in ("end", "error") or (until is not None and until(messages)):
                break
    return messages, audio


def song_pcm(path: Path, rate: int, seconds: float) -> bytes:
    """The first ``seconds`` of a song as 16-bit mono PCM at ``rate`` (what a page's capture sends)."""
    import numpy as np
    import soxr

    y, sr = sf.read(path, dtype="float32", frames=int(seconds * sf.info(path).samplerate))
    y = soxr.resample(y.mean(axis=1) if y.ndim > 1 else y, sr, rate)
    return (np.clip(y, -1, 1) * 32767).astype("<i2").tobytes()


def kept_dance(server, character="mannequin", song=TRUMPET.name):
    status, result = post_dance(server, {"song": song, "character": character, "seed": "2"})
    assert status == 200, result
    return result


def glb_json(data: bytes) -> dict:
    """The JSON chunk of a GLB (after the 12-byte header and the chunk's own 8)."""
    assert data[:4] == b"glTF"
    length = int.from_bytes(data[12:16], "little")
    assert data[16:20] == b"JSON"
    return json.loads(data[20:20 + length])


def wait_for_video(server, url: str, timeout_s: float = 90.0) -> tuple[dict, list[str]]:
    """Poll a video's status until it is over; (the last answer, every state seen)."""
    deadline = time.monotonic() + timeout_s
    states = []
    while time.monotonic() < deadline:
        status, _, data = request(server, "GET", url)
        job = json.loads(data)
        assert status in (200, 202), job
        states.append(job["state"])
        if job["state"] not in ("queued", "rendering"):
            return job, states
        time.sleep(0.2)
    raise AssertionError(f"the video was not done within {timeout_s} s: {states[-5:]}")

"""What the `dancesynth serve` tests share: the app under uvicorn, the bundled songs over HTTP, raw
requests, multipart forms, and what a rendered video must be."""

from __future__ import annotations

import http.client
import json
import subprocess
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

"""The web server's routes and parameters (``create_app``), through starlette's ``TestClient``.

Mutates: song and upload names (``..``, encoded slashes, absolute paths, NUL,
long names, the package's own files), static paths, the form of ``POST
/api/dance`` (style, seed, song, an uploaded 5 s song or junk, extra fields, a
body that is not multipart, a lying Content-Length), the query of ``/ws/live``
(url, segment_s, style, seed) and methods a route does not take.

Sane: 200 with the expected body (a bundled song's exact bytes, a dance whose BVH
reads back, JSON), or a 4xx/503 with a one-line JSON ``error``; never a 5xx; no
file outside the bundled music (and the page's static folder) is ever served.
"""

from __future__ import annotations

import json
import random
from pathlib import Path
from urllib.parse import quote

from .harness import Case, Failed, Insane, Target, rng_for

REPO = Path(__file__).resolve().parents[2]
PACKAGE = REPO / "src" / "dancesynth"
NAMES = ["..", "../database/database.json", "..%2f..%2fcli.py", "%2e%2e%2fserver.py", "/etc/passwd",
         "..\\..\\cli.py", "a" * 5000, "x\x00.ogg", "%00", "", " ", "Kevin_MacLeod_-_Vibe_Ace.txt",
         "Kevin_MacLeod_-_Vibe_Ace.ogg", "Kevin_MacLeod_-_Vibe_Ace.ogg/..", "./Kevin_MacLeod_-_Vibe_Ace.ogg",
         "../../web/server.py", "%252e%252e%252f", "ñ.ogg", "LICENSES", "CON"]
VALUES = ["", "-1", "--5", "0", "7", "1.5", "nan", "inf", "1e308", "9" * 40, "abc", "salsa", "jpop",
          "../../etc/passwd", "a" * 3000, "\x00", "٣"]


class WebTarget(Target):
    name = "web"
    mutates = "names, paths, form fields, uploads, bodies, WebSocket queries and methods of every route"
    sane = "200 with the right body, or 4xx/503 with one JSON error line; never 5xx; nothing outside the package"

    def __init__(self):
        self._client = None

    def prepare(self, workdir: Path) -> None:
        from .cli_target import CliTarget

        CliTarget().prepare(workdir)  # the 5 s song

    def _app(self):
        if self._client is None:
            from starlette.testclient import TestClient

            from dancesynth.web.server import create_app

            self._client = TestClient(create_app(live_realtime=False), raise_server_exceptions=False)
            self._client.__enter__()
        return self._client

    def cases(self, n: int, seed: int, workdir: Path) -> list[Case]:
        rng = rng_for(seed, "web")
        out = []
        for _ in range(n):
            kind = rng.choices(["song", "upload", "static", "get", "dance", "live", "method"],
                               [3, 2, 2, 1, 4, 2, 1])[0]
            case = {"song": lambda: ("GET", "/api/songs/" + _name(rng)),
                    "upload": lambda: ("GET", "/api/uploads/" + _name(rng)),
                    "static": lambda: ("GET", "/static/" + _name(rng)),
                    "get": lambda: ("GET", rng.choice(["/", "/api/songs", "/api/live", "/api/styles", "/nope"])),
                    "dance": lambda: _dance_request(rng),
                    "live": lambda: ("WS", "/ws/live?" + "&".join(
                        f"{k}={quote(rng.choice(VALUES + ['http://127.0.0.1:1/x', 'file:///etc/passwd']))}"
                        for k in rng.sample(["url", "segment_s", "style", "seed"], rng.randrange(5)))),
                    "method": lambda: (rng.choice(["PUT", "DELETE", "PATCH", "POST"]),
                                       rng.choice(["/", "/api/songs", "/api/songs/x", "/api/live"])),
                    }[kind]()
            out.append(Case(f"{kind}: {str(case)[:120]}", case))
        return out

    def run(self, case: Case, workdir: Path) -> None:
        client = self._app()
        method, url, *body = case.data
        if method == "WS":
            with client.websocket_connect(url) as ws:
                message = json.loads(ws.receive_text())
            if message.get("type") == "error":
                _one_line(message.get("error"), url)
            return
        if method == "POST" and url == "/api/dance":
            fields, upload, raw, headers = body
            if raw is not None:
                r = client.post(url, content=raw, headers=headers)
            else:
                files = {"audio": (upload[0], _upload_bytes(upload[1], workdir))} if upload else None
                r = client.post(url, data=fields, files=files, headers=headers)
        else:
            r = client.request(method, url)
        check_response(r, url)


def check_response(r, url: str) -> None:
    if r.status_code >= 500 and r.status_code != 503:
        raise Failed(f"HTTP {r.status_code} from {url.split('?')[0].rsplit('/', 1)[0] or '/'}", r.text[:200])
    if r.status_code != 200:
        try:
            error = r.json().get("error")
        except ValueError:
            raise Failed(f"HTTP {r.status_code} without a JSON reason", r.text[:200]) from None
        return _one_line(error, url)
    path = r.url.path  # as the server saw it (the client resolves "a/..")
    if path.startswith(("/api/songs/", "/api/uploads/", "/static/")):
        allowed = [p for p in (PACKAGE / "data" / "music").iterdir() if p.is_file()]
        allowed += [p for p in (PACKAGE / "web" / "static").rglob("*") if p.is_file()]
        if path.startswith("/api/uploads/"):
            return  # an upload made by an earlier case: its bytes came from the client
        if not any(r.content == p.read_bytes() for p in allowed):
            raise Insane(f"served something that is no bundled song or static file: {path[:80]}")
    elif path == "/api/dance":
        from dancesynth.io.bvh import parse_bvh

        from .bvh_target import check_clip

        check_clip(parse_bvh(r.json()["bvh"]))


def _one_line(error, url: str) -> None:
    from dancesynth.errors import InputError

    if not isinstance(error, str) or not error.strip() or "\n" in error.strip():
        raise Failed("an error without a one-line reason", f"{url[:80]}: {error!r}"[:200])
    raise InputError(error)


def _name(rng: random.Random) -> str:
    name = rng.choice(NAMES)
    return quote(name, safe="/%") if rng.random() < 0.5 else name.replace("\x00", "%00")


def _dance_request(rng: random.Random):
    fields = {k: rng.choice(VALUES) for k in rng.sample(["style", "seed", "song", "extra"], rng.randrange(4))}
    if "song" in fields and rng.random() < 0.5:
        fields["song"] = rng.choice(NAMES)
    upload = None
    if "song" not in fields or rng.random() < 0.3:
        upload = (rng.choice(["song.wav", "../../x.wav", "", "a" * 300 + ".ogg", "x.exe"]),
                  rng.choice(["song", "song", "junk", "empty"]))
    raw, headers = None, {}
    r = rng.random()
    if r < 0.1:
        raw = rng.choice([b"", b"garbage", b"--x\r\nContent-Disposition: form-data\r\n\r\n",
                          b"seed=1&style=x"])
        headers = {"content-type": rng.choice(["multipart/form-data; boundary=x", "application/json",
                                               "application/x-www-form-urlencoded", "text/plain"])}
    elif r < 0.15:
        headers = {"content-length": rng.choice(["99999999999", "-1", "abc"])}
    return ("POST", "/api/dance", fields, upload, raw, headers)


def _upload_bytes(kind: str, workdir: Path) -> bytes:
    if kind == "song":
        return (workdir / "cli_files" / "song.wav").read_bytes()
    return b"" if kind == "empty" else bytes(range(256)) * 8


TARGET = WebTarget()

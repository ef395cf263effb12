"""A small web server that lets a browser watch the character dance to a song.

``create_app`` builds a Starlette app: the page and its static files (three.js is
vendored, so it works offline), the bundled songs, and ``POST /api/dance``, which
runs ``dancesynth.dance`` in a worker thread and answers the BVH text, the music's
beats and a URL the page plays the song from. The page drives the animation from
the audio element's clock, so motion and music stay in sync through seeks and pauses.

The server is thin: it parses, calls one library function and reports. Errors a
user causes come back as JSON ``{"error": message}`` with a 4xx status; nothing
else (no traceback) ever reaches the client.
"""

from __future__ import annotations

import asyncio
import contextlib
import re
import shutil
import tempfile
import threading
import time
import uuid
from pathlib import Path

import numpy as np

from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.datastructures import UploadFile
from starlette.exceptions import HTTPException
from starlette.middleware import Middleware
from starlette.middleware.gzip import GZipMiddleware
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, Response
from starlette.routing import Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles
from starlette.websockets import WebSocket, WebSocketDisconnect

from ..errors import DanceSynthError, InputError

STATIC_DIR = Path(__file__).resolve().parent / "static"
MUSIC_DIR = Path(__file__).resolve().parents[1] / "data" / "music"
AUDIO_SUFFIXES = {".ogg", ".wav", ".flac", ".mp3", ".m4a", ".opus", ".aac", ".oga", ".webm"}
_MEDIA_TYPES = {".ogg": "audio/ogg", ".oga": "audio/ogg", ".opus": "audio/ogg", ".wav": "audio/wav",
                ".flac": "audio/flac", ".mp3": "audio/mpeg", ".m4a": "audio/mp4", ".aac": "audio/aac",
                ".webm": "audio/webm"}
_UPLOAD_ID = re.compile(r"^[0-9a-f]{32}(\.[a-z0-9]{1,5})?$")
MAX_SEED = 2**31 - 1


def bundled_songs() -> list[dict]:
    """The songs shipped with the package: file name, a readable title, the licence note if any."""
    songs = []
    for path in sorted(MUSIC_DIR.iterdir()) if MUSIC_DIR.is_dir() else []:
        if path.is_file() and path.suffix.lower() in AUDIO_SUFFIXES:
            songs.append({"name": path.name, "title": path.stem.replace("_", " "),
                          "url": f"/api/songs/{path.name}"})
    return songs


class UploadStore:
    """A bounded folder of uploaded songs, kept so the page can play them.

    At most ``max_files`` files and ``max_age_s`` seconds each; the oldest go first.
    """

    def __init__(self, *, max_files: int = 8, max_age_s: float = 3600.0):
        self.dir = Path(tempfile.mkdtemp(prefix="dancesynth-uploads-"))
        self.max_files = max_files
        self.max_age_s = max_age_s
        self._lock = threading.Lock()
        self._files: dict[str, float] = {}  # upload id -> time stored

    def new_path(self, filename: str | None) -> tuple[str, Path]:
        suffix = Path(filename or "").suffix.lower()
        suffix = suffix if re.fullmatch(r"\.[a-z0-9]{1,5}", suffix) else ""
        key = uuid.uuid4().hex + suffix
        with self._lock:
            self._prune(keep=self.max_files - 1)
            self._files[key] = time.time()
        return key, self.dir / key

    def discard(self, key: str) -> None:
        with self._lock:
            self._files.pop(key, None)
            (self.dir / key).unlink(missing_ok=True)

    def path(self, key: str) -> Path | None:
        if not _UPLOAD_ID.match(key):
            return None
        with self._lock:
            self._prune(keep=self.max_files)
            if key not in self._files:
                return None
        p = self.dir / key
        return p if p.is_file() else None

    def _prune(self, keep: int) -> None:
        now = time.time()
        for key, t in sorted(self._files.items(), key=lambda kv: kv[1]):
            if len(self._files) > keep or now - t > self.max_age_s:
                self._files.pop(key)
                (self.dir / key).unlink(missing_ok=True)

    def close(self) -> None:
        shutil.rmtree(self.dir, ignore_errors=True)


class _TooLarge(Exception):
    pass


def _error(status: int, message: str) -> JSONResponse:
    return JSONResponse({"error": message}, status_code=status)


def _limited(request: Request, max_bytes: int) -> Request:
    """The same request whose body raises ``_TooLarge`` once more than ``max_bytes`` arrive."""
    seen = 0
    receive = request.receive

    async def counting_receive():
        nonlocal seen
        message = await receive()
        if message["type"] == "http.request":
            seen += len(message.get("body", b""))
            if seen > max_bytes:
                raise _TooLarge()
        return message

    return Request(request.scope, counting_receive)


def create_app(*, database=None, max_upload_mb: float = 50, max_concurrent_dances: int = 2,
               max_stored_uploads: int = 8, max_live_streams: int = 2) -> Starlette:
    """The web app: the page, the bundled songs, and ``POST /api/dance``.

    ``database`` is passed to ``dancesynth.dance`` (a folder, a ``MotionDatabase`` or
    None for the bundled one); uploads larger than ``max_upload_mb`` are refused with 413.
    """
    from ..api import list_styles
    from ..motion.database import MotionDatabase, open_database

    if database is not None and not isinstance(database, MotionDatabase):
        database = open_database(database)  # a bad folder is an error now, not at the first dance
    max_bytes = int(max_upload_mb * 1024 * 1024)
    store = UploadStore(max_files=max_stored_uploads)
    songs = {s["name"]: s for s in bundled_songs()}
    slots = asyncio.Semaphore(max_concurrent_dances)
    live_slots = asyncio.Semaphore(max_live_streams)
    styles_cache: list = []

    async def index(request: Request) -> Response:
        return FileResponse(STATIC_DIR / "index.html", media_type="text/html")

    async def api_styles(request: Request) -> Response:
        if not styles_cache:
            styles_cache.extend(await run_in_threadpool(list_styles, database))
        return JSONResponse({"styles": styles_cache})

    async def api_songs(request: Request) -> Response:
        return JSONResponse({"songs": list(songs.values())})

    async def api_song(request: Request) -> Response:
        name = request.path_params["name"]
        if name not in songs:
            return _error(404, f"no bundled song named {name!r}; see /api/songs")
        path = MUSIC_DIR / name
        return FileResponse(path, media_type=_MEDIA_TYPES.get(path.suffix.lower(), "application/octet-stream"))

    async def api_upload(request: Request) -> Response:
        key = request.path_params["key"]
        path = store.path(key)
        if path is None:
            return _error(404, "no such upload (uploads are kept for a while only; dance it again)")
        return FileResponse(path, media_type=_MEDIA_TYPES.get(path.suffix.lower(), "application/octet-stream"))

    async def api_dance(request: Request) -> Response:
        length = request.headers.get("content-length")
        if length is not None and length.isdigit() and int(length) > max_bytes:
            return _error(413, f"the upload is {int(length) / 2**20:.1f} MB; the limit is {max_upload_mb:g} MB")
        try:
            form = await _limited(request, max_bytes).form(max_files=1, max_fields=10)
        except _TooLarge:
            return _error(413, f"the upload is larger than the limit of {max_upload_mb:g} MB")
        except Exception as exc:  # malformed multipart
            return _error(400, f"could not read the form: {exc}; send multipart/form-data with "
                               "'audio' (a file) or 'song' (a bundled song name)")
        upload_key, song_path, shown = None, None, ""
        try:
            style = _text(form, "style") or None
            seed_text = _text(form, "seed")
            if seed_text and not (seed_text.lstrip("-").isdigit() and abs(int(seed_text)) <= MAX_SEED):
                return _error(400, f"seed {seed_text!r} must be a whole number (e.g. 7) or empty")
            seed = int(seed_text) if seed_text else None
            audio = form.get("audio")
            song_name = _text(form, "song")
            if isinstance(audio, UploadFile) and (audio.filename or audio.size):
                upload_key, song_path = store.new_path(audio.filename)
                shown = Path(audio.filename or "upload").name
                await run_in_threadpool(_save_upload, audio, song_path)
                audio_url = f"/api/uploads/{upload_key}"
            elif song_name:
                if song_name not in songs:
                    return _error(400, f"no bundled song named {song_name!r}; pick one of /api/songs")
                song_path, audio_url, shown = MUSIC_DIR / song_name, songs[song_name]["url"], song_name
            else:
                return _error(400, "send an audio file ('audio') or the name of a bundled song ('song')")
            async with slots:
                result = await run_in_threadpool(_dance_json, song_path, style, seed, database)
        except DanceSynthError as exc:
            if upload_key:
                store.discard(upload_key)
            # Name the song as the user knows it, not by where the server keeps it.
            message = str(exc).replace(str(song_path), shown) if song_path else str(exc)
            return _error(400 if isinstance(exc, InputError) else 500, message)
        finally:
            await form.close()
        result["audio_url"] = audio_url
        return JSONResponse(result)

    async def ws_live(ws: WebSocket) -> None:
        await ws.accept()
        if live_slots.locked():
            await ws.send_json({"type": "error", "error": f"the server already streams {max_live_streams} "
                                                           "dances; try again later"})
            await ws.close()
            return
        async with live_slots:
            await _live_session(ws, database)

    async def on_error(request: Request, exc: Exception) -> Response:
        return _error(500, f"internal error: {type(exc).__name__} (see the server's log)")

    async def on_http_error(request: Request, exc: HTTPException) -> Response:
        return _error(exc.status_code, exc.detail or "error")

    routes = [
        Route("/", index),
        Route("/api/styles", api_styles),
        Route("/api/songs", api_songs),
        Route("/api/songs/{name}", api_song),
        Route("/api/uploads/{key}", api_upload),
        Route("/api/dance", api_dance, methods=["POST"]),
        WebSocketRoute("/ws/live", ws_live),
        Mount("/static", app=StaticFiles(directory=STATIC_DIR), name="static"),
    ]
    @contextlib.asynccontextmanager
    async def lifespan(app):
        try:
            yield
        finally:
            store.close()

    app = Starlette(routes=routes, middleware=[Middleware(GZipMiddleware, minimum_size=1024)],
                    exception_handlers={Exception: on_error, HTTPException: on_http_error}, lifespan=lifespan)
    app.state.uploads = store
    return app


class _TeeSource:
    """An ``AudioSource`` whose chunks are also relayed (as 16-bit PCM) and beat-tracked for the page."""

    def __init__(self, source, send, segment_s: float):
        from ..live.beats import StreamingBeatTracker

        self._source, self._send = source, send
        self.sr, self.spec = source.sr, source.spec
        self._tracker = StreamingBeatTracker(source.sr)
        self._segment_s, self._next = segment_s, segment_s

    @property
    def error(self) -> str:
        return self._source.error

    def read(self, timeout: float):
        try:
            chunk = self._source.read(timeout)
        except StopIteration:
            self._send("beats", self._tracker.flush())
            raise
        if chunk is not None and chunk.samples.size:
            pcm = (np.clip(chunk.samples, -1.0, 1.0) * 32767.0).astype("<i2")
            self._send("audio", pcm.tobytes())
            self._tracker.push(chunk.samples)
            if self._tracker.heard_s >= self._next:
                self._next += self._segment_s
                self._send("beats", self._tracker.update())
        return chunk


async def _live_session(ws: WebSocket, database) -> None:
    """Dance to ``?url=`` (an http(s) stream) with ``run_live`` in a thread; relay audio, motion and beats.

    Messages: ``start`` (sample rate, fps, the playback delay the double buffer
    needs), binary 16-bit mono PCM from stream time 0 on, ``hierarchy`` once, ``frames``
    (BVH rows from ``start_frame``) per segment, ``beats`` per segment, then
    ``end`` or ``error``. A client that stops reading for 10 s ends the session.
    """
    from ..live.runtime import LiveConfig, run_live
    from ..live.sources import AudioSource
    from ..io.bvh_writer import bvh_parts

    q = ws.query_params
    url = q.get("url", "").strip()
    try:
        segment_s = float(q.get("segment_s") or 5.0)
        seed = int(q["seed"]) if q.get("seed") else None
    except ValueError:
        segment_s = seed = None
    if not url.startswith(("http://", "https://")):
        await ws.send_json({"type": "error", "error": "give the stream as ?url=http(s)://..."})
        return await ws.close()
    if segment_s is None or not 1.0 <= segment_s <= 30.0:
        await ws.send_json({"type": "error", "error": "segment_s must be a number from 1 to 30 and seed a "
                                                      "whole number"})
        return await ws.close()
    loop = asyncio.get_running_loop()
    queue: asyncio.Queue = asyncio.Queue(maxsize=64)
    stop = threading.Event()
    frames_sent = 0

    def send(kind, payload) -> None:  # called from the live thread; waits (bounded) for a slow client
        if stop.is_set():
            return
        try:
            asyncio.run_coroutine_threadsafe(queue.put((kind, payload)), loop).result(timeout=10)
        except Exception:
            stop.set()

    def live() -> None:
        try:
            source = AudioSource(url, realtime=True)
        except DanceSynthError as exc:
            return send("error", str(exc))
        try:
            config = LiveConfig(segment_s=segment_s, style=q.get("style") or None, seed=seed, database=database)
            summary = run_live(_TeeSource(source, send, segment_s), lambda clip: send("frames", clip),
                               config=config, stop=stop)
            send("end", {k: v for k, v in summary.items() if isinstance(v, (int, float, str, type(None)))})
        except DanceSynthError as exc:
            send("error", str(exc))
        except Exception as exc:
            send("error", f"internal error: {type(exc).__name__}")
        finally:
            source.close()

    thread = threading.Thread(target=live, daemon=True, name="dancesynth-live")
    await ws.send_json({"type": "start", "sr": 22050, "delay_s": 2 * segment_s + 1.0, "segment_s": segment_s})
    thread.start()
    try:
        while True:
            kind, payload = await queue.get()
            if kind == "audio":
                await ws.send_bytes(payload)
            elif kind == "frames":
                hierarchy, rows = bvh_parts(payload)
                if frames_sent == 0:
                    await ws.send_json({"type": "hierarchy", "bvh": hierarchy, "fps": payload.fps})
                await ws.send_json({"type": "frames", "start_frame": frames_sent, "rows": rows})
                frames_sent += len(rows)
            elif kind == "beats":
                await ws.send_json({"type": "beats", "beats": [round(float(t), 4) for t in payload.beat_times_s],
                                    "tempo_bpm": float(payload.tempo_bpm)})
            else:
                await ws.send_json({"type": kind, ("error" if kind == "error" else "summary"): payload})
                break
        await ws.close()
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        stop.set()
        while not queue.empty():  # unblock a waiting sender
            queue.get_nowait()
        await asyncio.to_thread(thread.join, 15)


def _text(form, key: str) -> str:
    value = form.get(key)
    return value.strip() if isinstance(value, str) else ""


def _save_upload(upload: UploadFile, path: Path) -> None:
    upload.file.seek(0)
    with open(path, "wb") as fh:
        shutil.copyfileobj(upload.file, fh, 1 << 20)


def _dance_json(song_path: Path, style: str | None, seed: int | None, database) -> dict:
    from ..api import dance
    from ..io.bvh_writer import format_bvh

    clip = dance(song_path, style=style, seed=seed, database=database)
    s = clip.meta["summary"]
    return {"bvh": format_bvh(clip), "fps": clip.fps, "frames": clip.n_frames,
            "duration_s": float(s["duration_s"]), "tempo_bpm": float(s["tempo_bpm"]),
            "beats": [round(float(t), 4) for t in clip.meta["music_beat_times_s"]],
            "style": s["style"], "default_tempo": bool(s["default_tempo"])}


def serve(host: str = "127.0.0.1", port: int = 8000, *, log_level: str = "info", **app_options) -> None:
    """Run the web app with uvicorn until interrupted (Ctrl-C); 127.0.0.1 (this machine only) by default."""
    import socket

    import uvicorn

    try:  # a clear error for a busy port or a wrong address, before uvicorn starts
        with socket.create_server((host, port)):
            pass
    except OSError as exc:
        raise InputError(f"cannot listen on {host}:{port}: {exc.strerror or exc}; pick another --port "
                         "or --host") from None
    uvicorn.run(create_app(**app_options), host=host, port=port, log_level=log_level)

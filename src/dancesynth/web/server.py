"""A small web server that lets a browser watch the character dance to a song.

``create_app`` builds a Starlette app: the page and its static files (three.js is
vendored, so it works offline), the bundled songs, and ``POST /api/dance``, which
runs ``dancesynth.dance`` with the chosen engine in a worker thread, moves the dance onto
the chosen character (``retarget``) and answers the BVH text (the stick figure on the
character's rig), the music's beats and sections, a URL the page plays the song from and
the dance's own URLs (``/api/dances/{id}/...``: GLB with the skinned mesh, for the page to
show, and downloads as BVH, GLB, VRMA and an MP4 rendered with the song; ``web/dances.py``
keeps the last few dances, ``web/uploads.py`` the uploaded songs). ``/ws/live?url=&character=`` dances to a stream on a built-in
character, shared by everyone who watches it (``web/live.py``), and ``/ws/live?source=tab|mic&rate=``
to the sound the page captures and sends on the same socket; ``/api/live`` lists those
streams; ``/api/characters/{name}.glb`` is a character in its rest pose, which the page poses
from the live frames. The page drives the animation from
the audio element's clock, so motion and music stay in sync through seeks and pauses.

The server is thin: it parses, calls one library function and reports. Errors a
user causes come back as JSON ``{"error": message}`` with a 4xx status; nothing
else (no traceback) ever reaches the client.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import math
import re
import shutil
import tempfile
import time
from pathlib import Path


from starlette.applications import Starlette
from starlette.background import BackgroundTask
from starlette.concurrency import run_in_threadpool
from starlette.datastructures import UploadFile
from starlette.exceptions import HTTPException
from starlette.middleware import Middleware
from starlette.middleware.gzip import GZipMiddleware
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, Response
from starlette.routing import Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles
from starlette.websockets import WebSocket

from ..errors import DanceSynthError, InputError
from ..defaults import MAX_SONG_S
from ..types import MAX_SEED
from .dances import DOWNLOADS, FIGURES, RENDER_RETRY_S, VIDEO_SIZE, DanceStore, StoredDance
from .live import MAX_CAPTURE_S, LiveHub, parse_seed, watch
from .making import builtin_character, make_dance, redance, rest_glb
from .uploads import UploadStore

STATIC_DIR = Path(__file__).resolve().parent / "static"
MUSIC_DIR = Path(__file__).resolve().parents[1] / "data" / "music"
AUDIO_SUFFIXES = {".ogg", ".wav", ".flac", ".mp3", ".m4a", ".opus", ".aac", ".oga", ".webm"}
_MEDIA_TYPES = {".ogg": "audio/ogg", ".oga": "audio/ogg", ".opus": "audio/ogg", ".wav": "audio/wav",
                ".flac": "audio/flac", ".mp3": "audio/mpeg", ".m4a": "audio/mp4", ".aac": "audio/aac",
                ".webm": "audio/webm"}
# What the engine menu says about each of api.ENGINES (cli.py's --engine help, shorter).
ENGINE_NOTES = {"streaming": "motion graph, segment by segment as the music arrives",
                "global": "motion graph, the whole song at once",
                "choreography": "motifs danced with captured moves",
                "neural": "a learned pose generator"}


def bundled_songs() -> list[dict]:
    """The songs shipped with the package: file name, a readable title, the licence note if any.

    Only regular files inside the folder: a symlink placed there could point anywhere."""
    songs = []
    for path in sorted(MUSIC_DIR.iterdir()) if MUSIC_DIR.is_dir() else []:
        if not path.is_symlink() and path.is_file() and path.suffix.lower() in AUDIO_SUFFIXES:
            songs.append({"name": path.name, "title": path.stem.replace("_", " "),
                          "url": f"/api/songs/{path.name}"})
    return songs


class DanceQueue:
    """At most ``workers`` dances at once and ``max_waiting`` more waiting for a turn, each in a worker thread.

    Beyond that the server is busy: it says so, with how long to wait (``retry_after_s``), instead of
    holding ever more requests. The running mean of a dance's duration makes that estimate.
    """

    def __init__(self, workers: int, max_waiting: int):
        self.workers, self.max_waiting = workers, max_waiting
        self.queued = 0      # dances waiting or running
        self.mean_s = 2.0    # a first guess, replaced as dances finish
        self._turns = asyncio.Semaphore(workers)

    def full(self) -> bool:
        return self.queued >= self.workers + self.max_waiting

    def retry_after_s(self) -> int:
        """Whole seconds until the dances queued now are done, from 1 to 60."""
        return min(60, max(1, math.ceil(self.queued * self.mean_s / self.workers)))

    async def run(self, fn, *args):
        self.queued += 1
        try:
            async with self._turns:
                t0 = time.monotonic()
                result = await run_in_threadpool(fn, *args)
                self.mean_s = 0.8 * self.mean_s + 0.2 * (time.monotonic() - t0)
                return result
        finally:
            self.queued -= 1


class _TooLarge(Exception):
    pass


def _error(status: int, message: str, headers: dict | None = None) -> JSONResponse:
    return JSONResponse({"error": message}, status_code=status, headers=headers)


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


MAX_VIEWER_LAG_S = 20.0  # a live viewer further behind the stream than this is let go of
SHUTDOWN_S = 5.0     # on Ctrl-C / SIGTERM, wait this long for open connections (uvicorn's default: forever)


def create_app(*, database=None, max_upload_mb: float = 50, max_concurrent_dances: int = 2,
               max_waiting_dances: int = 16, max_stored_uploads: int = 8, max_live_streams: int = 2,
               max_viewer_lag_s: float = MAX_VIEWER_LAG_S, live_realtime: bool = True,
               max_stored_dances: int = 8, max_renders: int = 1, max_waiting_renders: int = 2,
               video_size: tuple[int, int] = VIDEO_SIZE, max_capture_s: float = MAX_CAPTURE_S) -> Starlette:
    """The web app: the page, the bundled songs, and ``POST /api/dance``.

    ``database`` is passed to ``dancesynth.dance`` (a folder, a ``MotionDatabase`` or
    None for the bundled one); uploads larger than ``max_upload_mb`` are refused with 413.
    ``max_concurrent_dances`` dance at once and ``max_waiting_dances`` more wait; beyond
    that, or with ``max_stored_uploads`` uploads kept, a dance is refused with 503 and a
    Retry-After (the page waits that long and asks again). The last ``max_stored_dances``
    dances can be downloaded; ``max_renders`` videos render at once and
    ``max_waiting_renders`` more wait, beyond that a video is refused with 503 too; videos are
    ``video_size`` (width, height) pixels. A page's tab or microphone capture lasts at most ``max_capture_s``.
    """
    from ..api import ENGINES, DanceConfig, list_styles
    from ..engines.neural.store import shipped_genres
    from ..motion.database import MotionDatabase, open_database
    from ..retarget.character import DEFAULT_CHARACTER
    from ..retarget.rigs import DESCRIPTIONS, LAYOUTS

    if database is not None and not isinstance(database, MotionDatabase):
        database = open_database(database)  # a bad folder is an error now, not at the first dance
    max_bytes = int(max_upload_mb * 1024 * 1024)
    store = UploadStore(max_files=max_stored_uploads)
    characters_dir = tempfile.mkdtemp(prefix="dancesynth-characters-")   # users' character files, while loaded
    songs = {s["name"]: s for s in bundled_songs()}
    dances = DanceQueue(max_concurrent_dances, max_waiting_dances)
    hub = LiveHub(database, max_streams=max_live_streams, max_lag_s=max_viewer_lag_s, realtime=live_realtime,
                  load_character=builtin_character, max_capture_s=max_capture_s)
    kept = DanceStore(max_dances=max_stored_dances, max_renders=max_renders, max_waiting_renders=max_waiting_renders,
                      video_size=video_size)
    default_engine = DanceConfig().engine
    engine_genres = {"neural": shipped_genres()}   # the neural engine dances the genres it has a model of
    styles_cache: list = []
    characters_cache: list = []

    async def index(request: Request) -> Response:
        return FileResponse(STATIC_DIR / "index.html", media_type="text/html")

    async def styles() -> list:
        """The database's styles, listed once."""
        if not styles_cache:
            styles_cache.extend(await run_in_threadpool(list_styles, database))
        return styles_cache

    async def api_styles(request: Request) -> Response:
        return JSONResponse({"styles": await styles()})

    async def api_limits(request: Request) -> Response:
        """What the page tells the user before an upload: the largest file and the longest song."""
        return JSONResponse({"max_upload_mb": max_upload_mb, "max_song_minutes": MAX_SONG_S / 60})

    async def api_engines(request: Request) -> Response:
        """The engines; ``genres``: the only genres an engine can dance here (null: any)."""
        engines = [{"name": e, "description": ENGINE_NOTES.get(e, ""), "genres": engine_genres.get(e)} for e in ENGINES]
        return JSONResponse({"engines": engines, "default": default_engine})

    async def beyond(engine: str, style: str | None) -> list[str] | None:
        """The only genres ``engine`` can dance here, when ``style`` is not of them; else None."""
        genres = engine_genres.get(engine)
        if not style or genres is None:
            return None
        return None if next((s["genre"] for s in await styles() if s["name"] == style), None) in genres else genres

    async def api_characters(request: Request) -> Response:
        if not characters_cache:
            loaded = await run_in_threadpool(lambda: [builtin_character(n) for n in LAYOUTS])
            characters_cache.extend({"name": c.name, "description": DESCRIPTIONS.get(c.name, ""),
                                     "mesh": c.mesh is not None, "joints": c.skeleton.n_joints} for c in loaded)
        return JSONResponse({"characters": characters_cache, "default": DEFAULT_CHARACTER})

    async def api_character_glb(request: Request) -> Response:
        """A built-in character in its rest pose as GLB (the skinned mesh, if it has one): the page poses
        it from the frames of a live dance, whose joints are named as its nodes."""
        name = request.path_params["name"]
        if name not in LAYOUTS:
            return _error(404, f"no character named {name[:40]!r}; pick one of {', '.join(LAYOUTS)} (/api/characters)")
        data = await run_in_threadpool(rest_glb, name)
        return Response(data, media_type="model/gltf-binary", headers={"Cache-Control": "max-age=3600"})

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
        return FileResponse(path, media_type=_MEDIA_TYPES.get(path.suffix.lower(), "application/octet-stream"),
                            background=BackgroundTask(store.served, key))

    def busy(what: str) -> Response:
        wait = dances.retry_after_s()
        return _error(503, f"the server is busy with {what}; try again in {wait} s",
                      headers={"Retry-After": str(wait)})

    async def api_dance(request: Request) -> Response:
        length = request.headers.get("content-length")
        if length is not None and length.isdigit() and int(length) > max_bytes:
            return _error(413, f"the upload is {int(length) / 2**20:.1f} MB; the limit is {max_upload_mb:g} MB")
        try:
            form = await _limited(request, max_bytes).form(max_files=3, max_fields=12)
        except _TooLarge:
            return _error(413, f"the upload is larger than the limit of {max_upload_mb:g} MB")
        except Exception as exc:  # malformed multipart
            return _error(400, f"could not read the form: {exc}; send multipart/form-data with "
                               "'audio' (a file) or 'song' (a bundled song name)")
        upload_key, song_path, shown = None, None, ""
        folder, bone_map, shown_character = None, None, ("", "")
        try:
            problem = _form_problem(form)
            if problem:
                return _error(400, problem)
            style = _text(form, "style") or None
            seed = parse_seed(_text(form, "seed"))
            if seed is False:
                return _error(400, _bad_seed(_text(form, "seed")))
            engine = _text(form, "engine") or default_engine
            if engine not in ENGINES:
                return _error(400, f"unknown engine {engine[:40]!r}; pick one of {', '.join(ENGINES)} (/api/engines)")
            genres = await beyond(engine, style)
            if genres:
                return _error(400, f"the {engine} engine has learned only {' and '.join(genres)} here; pick a "
                                   f"{' or '.join(genres)} style (or the best match for the tempo), or another engine")
            character = _text(form, "character") or DEFAULT_CHARACTER
            own, bone_map = _upload(form, "character_file"), _upload(form, "bone_map")
            if own is not None:
                suffix = Path(own.filename or "").suffix.lower()
                if suffix not in CHARACTER_SUFFIXES:
                    return _error(400, f"a character file must be {', '.join(CHARACTER_SUFFIXES)}; "
                                       f"got {Path(own.filename or 'a file without a name').name[:60]!r}")
                # A folder of its own: a .gltf may read only files beside it, and nothing else is there.
                folder = Path(tempfile.mkdtemp(prefix="character-", dir=characters_dir))
                stem = re.sub(r"[^A-Za-z0-9._-]+", "_", Path(own.filename).stem).strip("._")[:60] or "character"
                character = folder / (stem + suffix)
                await run_in_threadpool(_save_upload, own, character)
                if bone_map is not None:
                    await run_in_threadpool(_save_upload, bone_map, folder / "bone_map.toml")
                shown_character = (str(folder) + "/", "")
            elif bone_map is not None:
                return _error(400, "a bone map goes with a character file (character_file)")
            elif character not in LAYOUTS:  # built-ins only: a path would load a file from the server's disk
                return _error(400, f"unknown character {character[:40]!r}; pick one of {', '.join(LAYOUTS)} "
                                   "(/api/characters), or send your own as character_file")
            audio, song_name = _upload(form), _text(form, "song")
            if audio is None and not song_name:
                return _error(400, "send an audio file ('audio') or the name of a bundled song ('song')")
            if audio is None and song_name not in songs:
                return _error(400, f"no bundled song named {song_name!r}; pick one of /api/songs")
            if dances.full():
                return busy(f"{dances.queued} dances")
            if audio is not None:
                stored = store.new_path(audio.filename)
                if stored is None:  # every place holds a song waiting for its dance or to be played
                    return busy(f"{store.max_files} uploaded songs")
                upload_key, song_path = stored
                shown = Path(audio.filename or "upload").name
                await run_in_threadpool(_save_upload, audio, song_path)
                audio_url = f"/api/uploads/{upload_key}"
            else:
                song_path, audio_url, shown = MUSIC_DIR / song_name, songs[song_name]["url"], song_name
            result, made = await dances.run(make_dance, song_path, style, seed, engine, character, database,
                                            folder / "bone_map.toml" if bone_map is not None else None)
        except DanceSynthError as exc:
            if upload_key:
                store.discard(upload_key)
            # Name the song and the character as the user knows them, not by where the server keeps them.
            message = str(exc).replace(str(song_path), shown) if song_path else str(exc)
            message = message.replace(*shown_character)
            return _error(400 if isinstance(exc, InputError) else 500, _for_the_page(message))
        except BaseException:
            if upload_key:  # an internal error or a dropped request: the song will never be danced
                store.discard(upload_key)
            raise
        finally:
            await form.close()
            if folder is not None:   # the character is loaded (or refused): its files are not needed
                shutil.rmtree(folder, ignore_errors=True)
        if upload_key:
            store.done(upload_key)
        made.title, made.upload_key, made.audio_url = shown, upload_key, audio_url
        return answer(made, result)

    def answer(made: StoredDance, result: dict) -> Response:
        """Keep ``made`` and answer with ``result`` and where its files are."""
        key = kept.add(made)
        base = f"/api/dances/{key}"
        result.update(audio_url=made.audio_url, dance_id=key, downloads={k: f"{base}/dance.{k}" for k in DOWNLOADS},
                      glb_url=f"{base}/dance.glb" if made.has_mesh else None, video_url=f"{base}/video",
                      redance_url=f"{base}/redance")
        return JSONResponse(result)

    async def api_redance(request: Request) -> Response:
        """Re-dance a span of a kept dance (``start_s``, ``end_s``; ``seed``, ``style`` or ``motif``), keeping
        the rest (``dancesynth.edit``): a new dance, the old one kept for undo."""
        dance = kept_dance(request)
        if isinstance(dance, Response):
            return dance
        try:
            form = await _limited(request, 64 * 1024).form(max_files=0, max_fields=8)
        except Exception:  # too large or malformed
            return _error(400, "send the span as a small form: start_s, end_s and seed, style or motif")
        try:
            fields = {k: _text(form, k) for k in form.keys()}
            unknown = set(fields) - set(_EDIT_FIELDS)
            if unknown:
                return _error(400, f"unknown field {sorted(unknown)[0][:40]!r}; the form takes {', '.join(_EDIT_FIELDS)}")
            try:
                start_s, end_s = float(fields.get("start_s", "")), float(fields.get("end_s", ""))
            except ValueError:
                return _error(400, "start_s and end_s must be numbers of seconds (the span to dance again)")
            seed = parse_seed(fields.get("seed"))
            if seed is False:
                return _error(400, _bad_seed(fields["seed"]))
            style, motif = fields.get("style") or None, fields.get("motif") or None
            if motif is not None and not re.fullmatch(r"M\d{1,4}", motif):
                return _error(400, f"motif {motif[:20]!r} must be a motif's name, e.g. M17")
            genres = None if motif else await beyond(dance.provenance.engine, style)
            if genres:
                return _error(400, f"the {dance.provenance.engine} engine has learned only {' and '.join(genres)} "
                                   "here; pick one of its styles, or a motif (danced by the choreography engine)")
            if dances.full():
                return busy(f"{dances.queued} dances")
            result, made = await dances.run(redance, dance, start_s, end_s, seed, style, motif, database)
        except DanceSynthError as exc:
            return _error(400 if isinstance(exc, InputError) else 500, _for_the_page(str(exc)))
        finally:
            await form.close()
        return answer(made, result)

    def kept_dance(request: Request) -> StoredDance | Response:
        dance = kept.get(request.path_params["key"])
        if dance is None:
            return _error(404, f"no such dance (the server keeps the last {kept.max_dances} dances; dance it again)")
        return dance

    async def api_dance_file(request: Request) -> Response:
        """``dance.bvh|glb|vrma`` made on first request; ``dance.mp4?figure=`` once rendered (``api_video``)."""
        kind = request.path_params["kind"]
        if kind not in DOWNLOADS and kind != "mp4":
            return _error(404, f"no such download; the formats are {', '.join(DOWNLOADS)} and mp4")
        dance = kept_dance(request)
        if isinstance(dance, Response):
            return dance
        if kind == "mp4":
            figure = _video_figure(request, dance)
            render = dance.renders.get(figure)
            if render is None or render.state != "done" or not render.path.is_file():
                return _error(404, "this video is not rendered (yet): POST to the dance's video_url first")
            return FileResponse(render.path, media_type="video/mp4", filename=dance.file_name("mp4", figure))
        try:
            data = await run_in_threadpool(dance.encoded, kind)
        except DanceSynthError as exc:
            return _error(400 if isinstance(exc, InputError) else 500, f"cannot make the {kind.upper()}: {exc}")
        return Response(data, media_type=DOWNLOADS[kind],
                        headers={"Content-Disposition": f'attachment; filename="{dance.file_name(kind)}"'})

    async def api_video(request: Request) -> Response:
        """POST starts rendering the dance's MP4 with its song (or joins the render under way); DELETE
        cancels it; each answers how far it has got (``eta_s``: an estimate of the seconds left), with the
        file's URL once it is done."""
        dance = kept_dance(request)
        if isinstance(dance, Response):
            return dance
        figure = _video_figure(request, dance)
        if figure is None:
            return _error(400, f"figure must be one of {', '.join(FIGURES)}")
        render = dance.renders.get(figure)
        if request.method == "DELETE" and render is not None:
            render.cancel()
        if request.method == "POST" and (render is None or render.state in ("error", "cancelled")):
            song, release = dance.song_path, lambda: None
            if dance.upload_key:  # an upload is kept while its video renders
                song = store.hold(dance.upload_key)
                if song is None:
                    return _error(410, "the uploaded song is no longer kept on the server; dance it again "
                                       "to make a video")
                release = functools.partial(store.release, dance.upload_key)
            render = kept.start_render(request.path_params["key"], dance, figure, song, release)
            if render is None:
                return _error(503, f"the server is busy rendering other videos; try again in {RENDER_RETRY_S} s",
                              headers={"Retry-After": str(RENDER_RETRY_S)})
        if render is None:
            return _error(404, "no video of this dance is being made: POST here to start one")
        answer = render.status()
        if render.state == "done":
            answer["url"] = f"/api/dances/{request.path_params['key']}/dance.mp4?figure={figure}"
        return JSONResponse(answer, status_code=202 if render.state in ("queued", "rendering") else 200)

    async def ws_live(ws: WebSocket) -> None:
        await ws.accept()
        await watch(ws, hub)

    async def api_live(request: Request) -> Response:
        return JSONResponse(hub.status())

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
        Route("/api/engines", api_engines),
        Route("/api/limits", api_limits),
        Route("/api/characters", api_characters),
        Route("/api/characters/{name}.glb", api_character_glb),
        Route("/api/dances/{key}/dance.{kind}", api_dance_file),
        Route("/api/dances/{key}/video", api_video, methods=["GET", "POST", "DELETE"]),
        Route("/api/dances/{key}/redance", api_redance, methods=["POST"]),
        Route("/api/live", api_live),
        WebSocketRoute("/ws/live", ws_live),
        Mount("/static", app=StaticFiles(directory=STATIC_DIR), name="static"),
    ]
    @contextlib.asynccontextmanager
    async def lifespan(app):
        try:
            yield
        finally:
            hub.close()
            kept.close()
            store.close()
            shutil.rmtree(characters_dir, ignore_errors=True)

    app = Starlette(routes=routes, middleware=[Middleware(GZipMiddleware, minimum_size=1024)],
                    exception_handlers={Exception: on_error, HTTPException: on_http_error}, lifespan=lifespan)
    app.state.uploads = store
    app.state.dances = kept
    app.state.characters_dir = Path(characters_dir)
    return app


_FIELDS = {"audio": "a file", "song": "text", "style": "text", "seed": "text", "engine": "text", "character": "text",
           "character_file": "a file", "bone_map": "a file"}
CHARACTER_SUFFIXES = (".glb", ".gltf", ".vrm", ".bvh")
_EDIT_FIELDS = ("start_s", "end_s", "seed", "style", "motif")


# The library's advice names command-line options; a page user gets what they can do in the page.
_PAGE_WORDING = (
    ("raise the limit (--max-minutes, or max_duration_s=) or cut the song", "cut the song (the limit is the server's)"),
    ("(e.g. `ffmpeg -i IN out.wav`)", "(an audio converter or editor can)"),
    ("down-mix the file first (`ffmpeg -i IN -ac 2 out.wav`)", "mix it down to stereo first (an audio editor can)"),
    ("file given with --bone-map", "file chosen as the bone map"),
    ("keep the files a .gltf names next to it", "the page takes one file: export the model as .glb (glTF "
                                                "binary), which holds them all"),
)


def _bad_seed(text: str) -> str:
    return f"seed {text!r} must be a whole number from 0 to {MAX_SEED} (e.g. 7) or empty"


def _for_the_page(message: str) -> str:
    for cli, page in _PAGE_WORDING:
        message = message.replace(cli, page)
    return message


def _form_problem(form) -> str:
    """What is wrong with the form's fields (unknown, repeated, a file for text or text for a file), or ''."""
    for key in dict.fromkeys(form.keys()):
        values = form.getlist(key)
        if key not in _FIELDS:
            return f"unknown field {key[:40]!r}; the form takes {', '.join(_FIELDS)}"
        if len(values) > 1:
            return f"the field {key!r} is given {len(values)} times; give it once"
        if isinstance(values[0], UploadFile) != (_FIELDS[key] == "a file"):
            return f"the field {key!r} must be {_FIELDS[key]}"
    if _upload(form) is not None and _text(form, "song"):
        return "send an audio file ('audio') or the name of a bundled song ('song'), not both"
    return ""


def _upload(form, key: str = "audio") -> UploadFile | None:
    """The uploaded file of ``key`` (the song by default), if one was chosen (a form's empty file field sends
    no name and no bytes)."""
    upload = form.get(key)
    return upload if isinstance(upload, UploadFile) and (upload.filename or upload.size) else None


def _text(form, key: str) -> str:
    value = form.get(key)
    return value.strip() if isinstance(value, str) else ""


def _save_upload(upload: UploadFile, path: Path) -> None:
    upload.file.seek(0)
    with open(path, "wb") as fh:
        shutil.copyfileobj(upload.file, fh, 1 << 20)


def _video_figure(request: Request, dance: StoredDance) -> str | None:
    """The figure a video draws (``?figure=``, default the character); a rig without a mesh is drawn as
    the stick figure whatever is asked, so both names share one render. None when it is no figure."""
    figure = request.query_params.get("figure") or "character"
    if figure not in FIGURES:
        return None
    return figure if dance.has_mesh else "stick"


def serve(host: str = "127.0.0.1", port: int = 8000, *, log_level: str = "info", **app_options) -> None:
    """Run the web app with uvicorn until interrupted (Ctrl-C, SIGTERM); 127.0.0.1 (this machine only) by default.

    A live viewer that stops reading is dropped with a message once a send has been blocked for
    ``max_viewer_lag_s``; on a real-time stream the kernel's socket buffers hold minutes of it before
    a send blocks, so uvicorn's WebSocket keepalive (a ping every 20 s, answered within 20 s) lets
    it go first. (A ping every 5 s dropped every viewer under load in benchmarks/serve_load.py.)
    Shutting down waits for open connections at most ``SHUTDOWN_S``."""
    import socket

    import uvicorn

    try:  # a clear error for a busy port or a wrong address, before uvicorn starts
        with socket.create_server((host, port)):
            pass
    except OSError as exc:
        raise InputError(f"cannot listen on {host}:{port}: {exc.strerror or exc}; pick another --port "
                         "or --host") from None
    uvicorn.run(create_app(**app_options), host=host, port=port, log_level=log_level,
                timeout_graceful_shutdown=SHUTDOWN_S)

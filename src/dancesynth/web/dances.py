"""The dances the server has made, kept a while so the page can show and download them.

Each ``StoredDance`` holds one dance already retargeted onto the character it was asked
for, the song it was danced to and the files made from it: BVH, GLB and VRMA on first
request (then kept), an MP4 rendered in the background with the song. ``DanceStore``
keeps the last ``max_dances``; an older one is forgotten (its video removed) and its
URLs answer 404, so memory and disk stay bounded however many dances are made.

Videos take a while, so they are jobs: at most ``max_renders`` render at once and
``max_waiting_renders`` more wait; the page starts one, polls its progress and fetches
the file when it is done.
"""

from __future__ import annotations

import re
import shutil
import tempfile
import threading
import time
import uuid
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import DanceSynthError

# What each download is, and how it is sent.
DOWNLOADS = {"bvh": "text/plain; charset=utf-8", "glb": "model/gltf-binary", "vrma": "model/gltf-binary",
             "fbx": "application/octet-stream"}
FIGURES = ("character", "stick")   # what a video draws: the character's mesh or the stick figure on its rig
VIDEO_SIZE = (960, 540)
_BLENDER = threading.BoundedSemaphore(1)   # one Blender at a time for the FBX downloads (a whole Blender each)
RENDER_RETRY_S = 10   # a busy render queue asks the page to come back after this long


@dataclass(eq=False)
class Render:
    """One MP4 being made: ``state`` goes queued -> rendering -> done (``path``), error (``error``) or
    cancelled (``cancel``: the page moved on to another dance, or the user asked)."""

    figure: str
    state: str = "queued"
    done: int = 0
    total: int = 0
    error: str = ""
    path: Path | None = None
    started: float | None = None   # time.monotonic() when it began rendering

    def status(self) -> dict:
        progress = self.done / self.total if self.total else 0.0
        eta = None
        if self.state == "rendering" and self.done and self.started is not None:
            eta = round((time.monotonic() - self.started) / self.done * (self.total - self.done), 1)
        return {"state": self.state, "figure": self.figure, "frames_done": self.done, "frames": self.total,
                "progress": round(1.0 if self.state == "done" else progress, 3), "eta_s": eta,
                "error": self.error or None}

    def cancel(self) -> None:
        """Stop it: a queued render never starts, a rendering one stops at its next frame (its file removed)."""
        if self.state in ("queued", "rendering"):
            self.state = "cancelled"


@dataclass(eq=False)
class StoredDance:
    clip: object               # the dance on the character's skeleton (a MotionClip)
    character: object          # the retarget.character.Character it was moved onto
    song_path: Path
    title: str                 # the song as the user knows it (an upload's file name), for file names
    upload_key: str | None = None
    music: object = None       # the song's MusicFeatures, for re-dancing a span
    provenance: object = None  # the dance's Provenance (the clip is a retargeted copy)
    source: tuple = ((), None)  # the skeleton it was danced on (joint names) and its floor, for the same retarget
    audio_url: str = ""
    files: dict[str, bytes] = field(default_factory=dict)
    _encoding: threading.RLock = field(default_factory=threading.RLock, repr=False)
    renders: dict[str, Render] = field(default_factory=dict)
    forgotten: bool = False

    @property
    def has_mesh(self) -> bool:
        return self.character.mesh is not None

    def file_name(self, suffix: str, figure: str = "character") -> str:
        """``song-character.suffix`` (``-stick`` added for a video of the stick figure of a character with a
        mesh), in plain ASCII so every browser keeps it."""
        stem = re.sub(r"[^A-Za-z0-9._-]+", "_", Path(self.title).stem).strip("._")[:60] or "dance"
        stick = "-stick" if figure == "stick" and self.has_mesh else ""
        return f"{stem}-{self.character.name}{stick}.{suffix}"

    def encoded(self, kind: str) -> bytes:
        """The dance as a ``kind`` file (bvh, glb, vrma, fbx), made once. Runs in a worker thread."""
        with self._encoding:   # one Blender for an FBX asked for twice at once (re-entrant: the FBX needs the GLB)
            if kind not in self.files:
                if kind == "fbx":   # Blender converts our GLB (a user's model file is gone by now)
                    from ..export.fbx import fbx_bytes

                    glb = self.encoded("glb")
                    with _BLENDER:
                        self.files[kind] = fbx_bytes(glb, fps=self.clip.fps, name="dance")
                else:
                    from ..export.formats import encode_dance

                    self.files[kind] = encode_dance("." + kind, self.clip, self.character)
            return self.files[kind]


class DanceStore:
    """The last ``max_dances`` dances by id, and their video renders."""

    def __init__(self, *, max_dances: int = 8, max_renders: int = 1, max_waiting_renders: int = 2,
                 video_size: tuple[int, int] = VIDEO_SIZE):
        self.video_size = video_size
        self.dir = Path(tempfile.mkdtemp(prefix="dancesynth-dances-"))
        self.max_dances = max_dances
        self.max_renders, self.max_waiting_renders = max_renders, max_waiting_renders
        self._dances: OrderedDict[str, StoredDance] = OrderedDict()
        self._lock = threading.Lock()
        self._renders = 0   # queued or rendering
        self._closing = threading.Event()
        self._pool = ThreadPoolExecutor(max_renders, thread_name_prefix="dancesynth-render")

    def add(self, dance: StoredDance) -> str:
        key = uuid.uuid4().hex
        with self._lock:
            self._dances[key] = dance
            while len(self._dances) > self.max_dances:
                _, old = self._dances.popitem(last=False)
                self._forget(old)
        return key

    def get(self, key: str) -> StoredDance | None:
        with self._lock:
            return self._dances.get(key)

    def _forget(self, dance: StoredDance) -> None:
        dance.forgotten = True   # a render still running removes its own file when it ends
        for render in dance.renders.values():
            if render.path is not None:
                render.path.unlink(missing_ok=True)

    # -- videos ------------------------------------------------------------------------
    def start_render(self, key: str, dance: StoredDance, figure: str, song_path: Path, on_end) -> Render | None:
        """A new render of ``dance`` with ``figure``, queued; None when the queue is full. ``on_end()``
        is called once it is over (or at once when refused), in whichever thread that happens."""
        with self._lock:
            free = self._renders < self.max_renders + self.max_waiting_renders
            if free:
                self._renders += 1
        if not free:
            on_end()
            return None
        render = dance.renders[figure] = Render(figure)
        self._pool.submit(self._render, dance, render, song_path, self.dir / f"{key}-{figure}.mp4", on_end)
        return render

    def _render(self, dance: StoredDance, render: Render, song_path: Path, out: Path, on_end) -> None:
        from ..export.video import render_video

        def progress(done: int, total: int) -> None:
            if self._closing.is_set() or dance.forgotten or render.state == "cancelled":
                raise _Stopped()  # render_video stops ffmpeg and removes its partial file
            render.done, render.total = done, total

        try:
            if dance.forgotten or render.state == "cancelled":
                raise _Stopped()
            render.state, render.started = "rendering", time.monotonic()
            width, height = self.video_size
            render_video(dance.clip, song_path, out, width=width, height=height, character=dance.character,
                         figure=render.figure if dance.has_mesh else "stick", progress=progress)
            render.path = out
            render.state = "done"
            if dance.forgotten:  # forgotten while it rendered: nobody can fetch it
                out.unlink(missing_ok=True)
        except _Stopped:
            if render.state != "cancelled":
                render.state, render.error = "error", "the dance was forgotten or the server is stopping"
        except DanceSynthError as exc:
            # Name the song as the user knows it, not by where the server keeps it.
            render.state, render.error = "error", str(exc).replace(str(song_path), dance.title)
        except Exception as exc:  # noqa: BLE001 - the page gets a message, the log nothing secret
            render.state, render.error = "error", f"internal error: {type(exc).__name__}"
        finally:
            with self._lock:
                self._renders -= 1
            on_end()

    def close(self) -> None:
        self._closing.set()
        self._pool.shutdown(wait=False, cancel_futures=True)
        shutil.rmtree(self.dir, ignore_errors=True)


class _Stopped(Exception):
    pass

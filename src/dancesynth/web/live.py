"""Live dances shared by every viewer of the same stream.

One ``Broadcast`` per stream (URL, segment length, style, seed, character) runs ``run_live``
in a thread, moves each segment onto the character (one ``SegmentRetargeter``, so every viewer
sees the same rig on the same floor) and fans its messages out to the viewers' own queues.
Viewers of one URL who chose different characters watch different broadcasts: the motion is
retargeted once per broadcast, never per viewer, so 50 viewers cost one dance. Publishing never
waits: a viewer that falls more than ``max_lag_s`` of audio behind is dropped with a
message, so a slow connection never slows the dance or the other viewers. A bounded
backlog (the last ``delay_s`` of audio, the frames and beats from there on) lets a
viewer join late and still see motion and music in sync, at everyone's delay.

A page may also send its own sound (a tab's or the microphone's, captured in the browser): then the
socket carries PCM both ways, the broadcast dances to a ``PushedAudio`` the socket fills (``_receive``,
within the bounds of CAPTURE_*), and nobody else can watch it; one per computer.

Messages, in order: ``start`` (sample rate, fps, ``start_s`` the stream time of the
first audio sample this viewer gets, ``delay_s`` how long to buffer before playing, the
``character``), binary 16-bit mono PCM, ``hierarchy`` once (the character's skeleton as a
BVH header: its joints are named as the nodes of ``/api/characters/{name}.glb``), ``frames``
(BVH rows from ``start_frame``), ``beats`` (stream times, and ``late_s``: how much later than the
delay allows the segment's motion was ready), then ``end`` (a summary) or ``error``.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import threading
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ..errors import DanceSynthError
from ..types import MAX_SEED, SEGMENT_S
from ..live.sources import SR, PushedAudio

# Motion for stream time t is ready at most one segment after t arrives (live/runtime.py), plus the step; the margin covers the step and network jitter.
DELAY_MARGIN_S = 1.0
MIN_JOIN_DELAY_S = 0.3
# Audio goes to the viewers in pieces of at least this much: the source's own reads are ~20 ms, and
# 50 viewers x 50 sends a second kept the event loop so busy that, beside 100 dances, every viewer fell
# behind (benchmarks/serve_load.py). A stall or the end sends what is held at once.
RELAY_S = 0.1
# A page's capture (``?source=tab|mic&rate=HZ``): 16-bit mono PCM at the page's own rate, in binary messages of
# at most MAX_CAPTURE_PIECE_S, never more than CAPTURE_BURST_S ahead of the time it has been sending (a page
# sends as it hears), for at most ``LiveHub.max_capture_s``; the text message {"type": "end"} ends it.
CAPTURE_SOURCES = {"tab": "the shared tab", "mic": "the microphone"}
CAPTURE_RATES = (8000, 192000)
MAX_CAPTURE_PIECE_S = 1.0
CAPTURE_BURST_S = 2.0
MAX_CAPTURE_S = 4 * 3600.0


def playback_delay_s(segment_s: float) -> float:
    """How long a viewer buffers audio so the motion of each moment is there before it is heard."""
    return segment_s + DELAY_MARGIN_S


@dataclass(eq=False)
class Viewer:
    queue: asyncio.Queue = field(default_factory=asyncio.Queue)
    lag_s: float = 0.0          # audio queued for this viewer and not yet sent
    dropped: str = ""           # why the broadcast let go of this viewer
    sender: asyncio.Task | None = None
    backlog_s: float = 0.0      # audio handed over at once when it joined (not a lag)

    def offer(self, message, audio_s: float, max_lag_s: float) -> bool:
        if self.dropped:
            return False
        if self.lag_s + audio_s > max_lag_s + self.backlog_s:
            self.drop(max_lag_s)
            return False
        self.lag_s += audio_s
        self.queue.put_nowait((message, audio_s))
        return True

    def drop(self, max_lag_s: float) -> None:
        self.dropped = f"your connection fell {max_lag_s:g} s behind the stream; reconnect to watch from now"
        if self.sender is not None:
            self.sender.cancel()  # it may be stuck writing to a full socket


class Broadcast:
    """One stream danced once and watched by many; lives on the event loop, its dance in a thread."""

    def __init__(self, url: str, config, *, loop: asyncio.AbstractEventLoop, max_lag_s: float, on_over,
                 realtime: bool = True, stats: dict | None = None, character: str = "mannequin",
                 load_character=None, source=None):
        self.url, self.config, self.loop = url, config, loop
        self._source = source   # a ``PushedAudio`` the page fills (a capture), else the stream at ``url``
        self.character = character
        self._load_character = load_character or _load_character
        self.max_lag_s, self.realtime = max_lag_s, realtime
        self.stats = stats if stats is not None else {"dropped_viewers": 0, "viewers": 0}
        self.delay_s = playback_delay_s(config.segment_s)
        self.viewers: set[Viewer] = set()
        self.dropped = 0
        self._on_over = on_over
        self._audio: deque = deque()      # (start sample, bytes) for the last delay_s
        self._samples = 0
        self._hierarchy: str | None = None
        self._frames: deque = deque()     # (start frame, text of the frames message)
        self._n_frames = 0
        self._beats: deque = deque()      # (time s, text of the beats message)
        self.final: str | None = None     # the end or error message once the dance is over
        self.stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="dancesynth-live")
        self._thread.start()

    # -- the dance thread ------------------------------------------------------------------
    def _run(self) -> None:
        from ..io.bvh_writer import bvh_parts
        from ..live.runtime import run_live
        from ..live.sources import AudioSource, broke_off
        from ..retarget import SegmentRetargeter

        def post(fn, *args):
            if not self.stop.is_set():
                self.loop.call_soon_threadsafe(fn, *args)

        on_character = None

        def on_frames(clip):
            hierarchy, rows = bvh_parts(on_character(clip))
            post(self._publish_frames, hierarchy, clip.fps, rows)

        def on_report(report):
            # late_s: how much later than the delay allows this segment's motion was ready (a slow or busy
            # machine); a viewer may be starved that long, and no longer.
            late_s = max(0.0, report.ready_s - report.audio_end_s - DELAY_MARGIN_S)
            text = json.dumps({"type": "beats", "beats": [round(t, 4) for t in report.beat_times_s],
                               "tempo_bpm": round(float(report.tempo_bpm), 2), "late_s": round(late_s, 4)})
            post(self._publish_beats, report.beat_times_s, text)

        source = relay = None
        try:
            # Loaded here, not on the event loop: the mannequin's mesh takes a second the first time.
            on_character = SegmentRetargeter(self._load_character(self.character))
            source = self._source or AudioSource(self.url, realtime=self.realtime)
            relay = _RelaySource(source, lambda pcm: post(self._publish_audio, pcm), int(RELAY_S * source.sr))
            summary = run_live(relay, on_frames, config=self.config, on_report=on_report, realtime=self.realtime,
                               stop=self.stop)
            plain = {k: v for k, v in summary.items() if isinstance(v, (int, float, str, type(None)))}
            died = broke_off(source)
            # A source that died is an error for every viewer, not an end they could take for the song's.
            final = {"type": "error", "error": f"{died}; the dance stopped there"} if died else \
                {"type": "end", "summary": plain}
        except DanceSynthError as exc:
            final = {"type": "error", "error": str(exc)}
        except Exception as exc:  # noqa: BLE001 - a viewer gets a message, never a traceback
            final = {"type": "error", "error": f"internal error: {type(exc).__name__}"}
        finally:
            if relay is not None:
                relay.flush()  # the last of the music, before the end
            if source is not None:
                source.close()
        try:
            self.loop.call_soon_threadsafe(self._finish, json.dumps(final))
        except RuntimeError:  # the server has shut down
            pass

    # -- the event loop --------------------------------------------------------------------
    def _send_all(self, message, audio_s: float = 0.0) -> None:
        for viewer in list(self.viewers):
            # Unpaced, audio outruns every viewer: only a blocked send (in _pump) counts as too slow.
            if not viewer.offer(message, audio_s, self.max_lag_s if self.realtime else float("inf")):
                self.leave(viewer)

    def _publish_audio(self, pcm: bytes) -> None:
        self._audio.append((self._samples, pcm))
        self._samples += len(pcm) // 2
        while self._audio and self._samples - self._audio[0][0] - len(self._audio[0][1]) // 2 > self.delay_s * SR:
            self._audio.popleft()
        self._send_all(pcm, len(pcm) / 2 / SR)

    def _publish_frames(self, hierarchy: str, fps: float, rows: list[str]) -> None:
        if self._hierarchy is None:
            self._hierarchy = json.dumps({"type": "hierarchy", "bvh": hierarchy, "fps": fps})
            self._send_all(self._hierarchy)
        text = json.dumps({"type": "frames", "start_frame": self._n_frames, "rows": rows})
        self._frames.append((self._n_frames, len(rows), text))
        self._n_frames += len(rows)
        oldest_s = self._backlog_start_s()
        while len(self._frames) > 1 and (self._frames[0][0] + self._frames[0][1]) / fps < oldest_s:
            self._frames.popleft()
        self._send_all(text)

    def _publish_beats(self, beats, text: str) -> None:
        self._beats.append((max(beats) if beats else -np.inf, text))
        while self._beats and self._beats[0][0] < self._backlog_start_s() - 2.0:
            self._beats.popleft()
        self._send_all(text)

    def _backlog_start_s(self) -> float:
        return self._audio[0][0] / SR if self._audio else self._samples / SR

    def _finish(self, final: str) -> None:
        self.final = final
        self._send_all(final)
        self._on_over(self)

    def join(self) -> Viewer:
        """A new viewer, handed the backlog so it plays in sync from the oldest audio kept."""
        viewer = Viewer()
        self.stats["viewers"] += 1
        start_s = self._backlog_start_s()
        backlog_s = self._samples / SR - start_s
        start = {"type": "start", "sr": SR, "fps": self.config.fps, "segment_s": self.config.segment_s,
                 "start_s": round(start_s, 6), "delay_s": max(self.delay_s - backlog_s, MIN_JOIN_DELAY_S),
                 "character": self.character}
        messages = [json.dumps(start)]
        messages += [self._hierarchy] if self._hierarchy else []
        messages += [text for *_, text in self._frames] + [text for _, text in self._beats]
        for message in messages:
            viewer.queue.put_nowait((message, 0.0))
        viewer.backlog_s = backlog_s
        for _, pcm in self._audio:
            viewer.offer(pcm, len(pcm) / 2 / SR, float("inf"))
        if self.final is not None:
            viewer.queue.put_nowait((self.final, 0.0))
        else:
            self.viewers.add(viewer)
        return viewer

    def leave(self, viewer: Viewer) -> None:
        if viewer in self.viewers and viewer.dropped:
            self.dropped += 1
            self.stats["dropped_viewers"] += 1
        self.viewers.discard(viewer)
        if not self.viewers and self.final is None:
            self.close()

    def close(self) -> None:
        """Stop dancing (nobody is watching); the thread ends within a read timeout."""
        self.stop.set()
        self._on_over(self)

    def status(self) -> dict:
        return {"url": self.url, "segment_s": self.config.segment_s, "character": self.character,
                "viewers": len(self.viewers),
                "dropped_viewers": self.dropped,
                "max_viewer_lag_s": round(max((v.lag_s for v in self.viewers), default=0.0), 2), "heard_s": round(self._samples / SR, 2),
                "frames": self._n_frames, "delay_s": self.delay_s, "over": self.final is not None}


class _RelaySource:
    """An ``AudioSource`` whose chunks are also handed on as 16-bit PCM, in pieces of at least
    ``min_samples`` (a read that finds nothing, or the end, hands on what is held)."""

    def __init__(self, source, relay, min_samples: int = 1):
        self._source, self._relay, self._min = source, relay, min_samples
        self.sr, self.spec = source.sr, source.spec
        self._held: list[np.ndarray] = []
        self._n_held = 0

    def __getattr__(self, name):   # the rest (error, device, pushed) is the source's
        return getattr(self._source, name)

    def read(self, timeout: float):
        try:
            chunk = self._source.read(timeout)
        except StopIteration:
            self.flush()
            raise
        if chunk is not None and chunk.samples.size:
            self._held.append((np.clip(chunk.samples, -1.0, 1.0) * 32767.0).astype("<i2"))
            self._n_held += chunk.samples.size
            if self._n_held >= self._min:
                self.flush()
        else:
            self.flush()  # a stall: nothing is kept waiting for more
        return chunk

    def flush(self) -> None:
        if self._n_held:
            pcm = np.concatenate(self._held).tobytes()
            self._held, self._n_held = [], 0
            self._relay(pcm)


class LiveHub:
    """The server's broadcasts, at most ``max_streams`` at once, keyed by what makes two dances the same.

    ``realtime=False`` relays a recorded file served over http as fast as it decodes
    (no pacing, no stall bridging), for tests and benchmarks.
    """

    def __init__(self, database, *, max_streams: int = 2, max_lag_s: float = 20.0, realtime: bool = True,
                 load_character=None, max_capture_s: float = MAX_CAPTURE_S):
        self.database, self.max_streams, self.max_lag_s = database, max_streams, max_lag_s
        self.max_capture_s = max_capture_s
        self.realtime = realtime
        self.load_character = load_character   # a built-in's name -> Character (the server caches them)
        self.broadcasts: dict[tuple, Broadcast] = {}
        self.stats = {"viewers": 0, "dropped_viewers": 0}   # since the server started

    def join(self, url: str, segment_s: float, style: str | None, seed: int | None,
             character: str = "mannequin") -> tuple[Broadcast, Viewer]:
        key = (url, segment_s, style, seed, character)
        broadcast = self.broadcasts.get(key) or self._start(
            key, url, segment_s, style, seed, character,
            busy="watch one of them (the same URL, settings and character) or try again later")
        return broadcast, broadcast.join()

    def capture(self, client: str, kind: str, rate: int, segment_s: float, style: str | None, seed: int | None,
                character: str = "mannequin") -> tuple[Broadcast, Viewer, PushedAudio]:
        """A dance of its own to what ``client``'s page captures (``kind``: tab or mic) and sends at ``rate``:
        one at a time per client, and it counts among the server's ``max_streams``."""
        key = ("capture", client)
        if key in self.broadcasts:
            raise _Busy("this computer already sends the server a live source; stop that one first")
        source = PushedAudio(CAPTURE_SOURCES[kind], rate)
        broadcast = self._start(key, f"{kind} capture from {client}", segment_s, style, seed, character,
                                busy="try again later", source=source)
        return broadcast, broadcast.join(), source

    def _start(self, key: tuple, url: str, segment_s: float, style: str | None, seed: int | None,
               character: str, *, busy: str, source: PushedAudio | None = None) -> Broadcast:
        from ..live.runtime import LiveConfig

        if len(self.broadcasts) >= self.max_streams:
            raise _Busy(f"the server already dances to {self.max_streams} streams; {busy}")
        config = LiveConfig(segment_s=segment_s, style=style, seed=seed, database=self.database)
        # A capture is live whatever the hub's pace: its stalls are bridged, a slow viewer let go.
        broadcast = Broadcast(url, config, loop=asyncio.get_running_loop(), max_lag_s=self.max_lag_s,
                              on_over=self._forget, realtime=self.realtime or source is not None, stats=self.stats,
                              character=character, load_character=self.load_character, source=source)
        self.broadcasts[key] = broadcast
        return broadcast

    def _forget(self, broadcast: Broadcast) -> None:
        self.broadcasts = {k: b for k, b in self.broadcasts.items() if b is not broadcast}

    def status(self) -> dict:
        return {"streams": [b.status() for b in self.broadcasts.values()], **self.stats}

    def close(self) -> None:
        for b in list(self.broadcasts.values()):
            b.close()


class _Busy(DanceSynthError):
    pass


def _load_character(name: str):
    from ..retarget.character import load_character

    return load_character(name)


def parse_seed(text: str | None) -> int | None | bool:
    """A seed sent by the page: None when empty, the number, or False when it is no whole number
    from 0 to ``MAX_SEED`` ("-1", "--5", "abc")."""
    if not text:
        return None
    return int(text) if text.isascii() and text.isdigit() and int(text) <= MAX_SEED else False


async def watch(ws, hub: LiveHub) -> None:
    """Serve one viewer of ``/ws/live?url=...&segment_s=...&style=...&seed=...&character=...`` until the dance
    or the viewer ends; with ``source=tab|mic&rate=HZ`` instead of ``url``, a dance to what the page itself
    captures and sends on this socket (see CAPTURE_SOURCES). ``character`` is a built-in
    (``retarget.rigs.LAYOUTS``; default the mannequin): a path would load a file from the server's disk."""
    from ..retarget.character import DEFAULT_CHARACTER
    from ..retarget.rigs import LAYOUTS

    q = ws.query_params
    url = q.get("url", "").strip()
    kind = q.get("source", "").strip()
    try:
        segment_s = float(q.get("segment_s") or SEGMENT_S)
    except ValueError:
        segment_s = None
    seed = parse_seed(q.get("seed"))
    character = q.get("character", "").strip() or DEFAULT_CHARACTER
    rate = q.get("rate", "")
    if kind and kind not in CAPTURE_SOURCES:
        return await _refuse(ws, f"source must be {' or '.join(CAPTURE_SOURCES)} (what the page captures)")
    if kind and (not rate.isdigit() or not CAPTURE_RATES[0] <= int(rate) <= CAPTURE_RATES[1]):
        return await _refuse(ws, "rate must be the capture's sample rate in Hz, a whole number from "
                                 f"{CAPTURE_RATES[0]} to {CAPTURE_RATES[1]}")
    if not kind and not url.startswith(("http://", "https://")):
        return await _refuse(ws, "give the stream as ?url=http(s)://...")
    if segment_s is None or not 1.0 <= segment_s <= 30.0 or seed is False:
        return await _refuse(ws, "segment_s must be a number from 1 to 30 and seed a whole number")
    if character not in LAYOUTS:
        return await _refuse(ws, f"unknown character {character[:40]!r}; pick one of {', '.join(LAYOUTS)} "
                                 "(/api/characters)")
    receiver = None
    try:
        if kind:
            client = ws.client.host if ws.client else "unknown"
            broadcast, viewer, source = hub.capture(client, kind, int(rate), segment_s, q.get("style") or None,
                                                    seed, character)
            receiver = asyncio.create_task(_receive(ws, source, int(rate), hub.max_capture_s))
        else:
            broadcast, viewer = hub.join(url, segment_s, q.get("style") or None, seed, character)
    except _Busy as exc:
        return await _refuse(ws, str(exc))
    viewer.sender = asyncio.create_task(_pump(ws, viewer, broadcast))
    try:
        if receiver is not None:
            await asyncio.wait({viewer.sender, receiver}, return_when=asyncio.FIRST_COMPLETED)
            if receiver.done() and receiver.result() == "gone":
                return   # the page went away: nobody to send the rest to
        await viewer.sender
        await asyncio.wait_for(ws.close(), 2.0)
    except asyncio.CancelledError:
        if not viewer.dropped:
            raise  # the server is shutting down
        with contextlib.suppress(Exception):  # best effort: the socket may be full
            await asyncio.wait_for(ws.send_text(json.dumps({"type": "error", "error": viewer.dropped})), 1.0)
    except Exception:  # the viewer went away
        pass
    finally:
        for task in (viewer.sender, receiver):
            if task is not None:
                task.cancel()
        broadcast.leave(viewer)


async def _receive(ws, source: PushedAudio, rate: int, max_s: float) -> str:
    """The page's capture into ``source``, within its bounds, until it ends: 'gone' if the page went away,
    else 'ended' (it said so, or broke a bound: the dance ends with why)."""
    started, samples = None, 0
    max_bytes = 2 * int(MAX_CAPTURE_PIECE_S * rate)
    while True:
        message = await ws.receive()
        if message["type"] == "websocket.disconnect":
            source.end()
            return "gone"
        data = message.get("bytes")
        if data is None:   # text: the page's capture ended (the user stopped sharing)
            source.end()
            return "ended"
        now = time.monotonic()
        started = now if started is None else started
        samples += len(data) // 2
        why = ""
        if len(data) % 2 or len(data) > max_bytes:
            why = (f"the page sent {len(data)} bytes at once; audio comes as whole 16-bit samples, "
                   f"at most {MAX_CAPTURE_PIECE_S:g} s a message")
        elif samples / rate > now - started + CAPTURE_BURST_S:
            why = "the page sent audio faster than real time"
        elif samples / rate > max_s:
            why = f"a capture lasts at most {max_s / 60:g} min; start it again to go on"
        if why:
            source.end(why)
            return "ended"
        source.push(data)


async def _pump(ws, viewer: Viewer, broadcast: Broadcast) -> None:
    """Send the viewer's queue in order; a send blocked for ``max_lag_s`` (nothing read) drops the viewer."""
    while True:
        message, audio_s = await viewer.queue.get()
        send = ws.send_bytes(message) if isinstance(message, bytes) else ws.send_text(message)
        try:
            await asyncio.wait_for(send, broadcast.max_lag_s)
        except asyncio.TimeoutError:
            viewer.drop(broadcast.max_lag_s)
            raise asyncio.CancelledError from None
        viewer.lag_s -= audio_s
        if message is broadcast.final:
            return


async def _refuse(ws, message: str) -> None:
    await ws.send_text(json.dumps({"type": "error", "error": message}))
    await ws.close()

"""The web server under load: many concurrent uploads, many live viewers, one that never reads.

    .venv/bin/python benchmarks/serve_load.py [--uploads 100] [--viewers 50] [--stream-s 60] [--out benchmarks/results]

A real ``serve`` (uvicorn) in a subprocess on a free 127.0.0.1 port, a real local HTTP
"radio" relaying a stream excerpt, and at once:

- ``--uploads`` clients, each uploading a short song cut with ffmpeg from the bundled music
  (4.5-6 s, four formats, varied excerpts), asking for its dance, checking the BVH parses
  and fetching the returned ``audio_url``. A client told the server is busy (503/429 with
  Retry-After) waits as long and tries again, as the page does, for at most ``RETRY_FOR_S``;
- ``--viewers`` WebSocket viewers of one live stream, plus one that never reads;
- a prober asking ``GET /api/styles`` every 0.25 s.

It samples the upload folder's file count and the server's resident memory (its process
and any children, from /proc) every 0.05 s, prints a table and writes ``serve_load.json``.
Everything runs on 127.0.0.1; every loop is bounded in count and in time.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import random
import socket
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path
from urllib.parse import urlencode

import numpy as np

REPO = Path(__file__).resolve().parents[1]
MUSIC = REPO / "src" / "dancesynth" / "data" / "music"
sys.path.insert(0, str(REPO / "tests"))
from servers import free_port, http_folder  # noqa: E402  (the tests' real servers, on 127.0.0.1)
from test_serve import multipart, request  # noqa: E402

# The server as ``dancesynth serve`` runs it, with the options given as JSON.
LAUNCH = ("import json, sys; from dancesynth.web.server import serve; "
          "serve(port=int(sys.argv[1]), log_level='warning', **json.loads(sys.argv[2]))")
# A short lag bound: the viewer that never reads is dropped once its kernel buffers are full too
# (some 36 s of audio on Linux loopback), within a 60 s stream.
SERVER_OPTIONS = {"max_live_streams": 1, "max_viewer_lag_s": 3.0}
UPLOAD_BOUND = 8          # create_app's default max_stored_uploads
RETRY_FOR_S = 300.0       # how long a busy answer is retried (the page does the same)
MAX_TRIES = 200
RADIO_SONG = MUSIC / "Karissa_Hobbs_-_Lets_Go_Fishin.ogg"  # 133 s
FORMATS = (".ogg", ".mp3", ".flac", ".wav")


# -- the songs and the radio --------------------------------------------------------------
def cut(source: Path, out: Path, start_s: float, seconds: float) -> Path:
    subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-ss", str(start_s), "-t", str(seconds), "-i",
                    str(source), str(out)], check=True, timeout=60)
    return out


def make_songs(folder: Path, n: int) -> list[Path]:
    """``n`` different short songs: bundled songs at different places, lengths and formats."""
    long_songs = [p for p in sorted(MUSIC.glob("*.ogg")) if p.stat().st_size > 200_000]
    return [cut(long_songs[i % len(long_songs)], folder / f"song{i:02d}{FORMATS[i % len(FORMATS)]}",
                5.0 + 3.0 * (i // len(long_songs)), 4.5 + 0.5 * (i % 4)) for i in range(n)]


# -- the server -----------------------------------------------------------------------------
def tree_rss_mb(pid: int) -> float:
    """Resident memory of a process and its children (a dance worker pool counts), in MB."""
    total, todo, seen = 0, [pid], set()
    while todo and len(seen) < 256:
        p = todo.pop()
        seen.add(p)
        try:
            status = Path(f"/proc/{p}/status").read_text()
            total += int(next(line.split()[1] for line in status.splitlines() if line.startswith("VmRSS:")))
            for task in Path(f"/proc/{p}/task").iterdir():
                todo += [int(c) for c in (task / "children").read_text().split() if int(c) not in seen]
        except (OSError, StopIteration, ValueError):
            continue  # a child that just ended
    return total / 1024


@contextmanager
def server_process(workdir: Path, options: dict):
    """``serve`` in a subprocess; yields (address, pid, the folder where its upload folder appears)."""
    tmp = workdir / "server-tmp"
    tmp.mkdir()
    port = free_port()
    env = {**os.environ, "TMPDIR": str(tmp), "NUMBA_CACHE_DIR": os.environ.get("NUMBA_CACHE_DIR",
                                                                                str(REPO / ".cache" / "numba"))}
    log = open(workdir / "server.log", "w")
    proc = subprocess.Popen([sys.executable, "-c", LAUNCH, str(port), json.dumps(options)], env=env,
                            stdout=log, stderr=subprocess.STDOUT)
    address = ("127.0.0.1", port)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                if request(address, "GET", "/api/styles", timeout=30)[0] == 200:
                    break
            except OSError:
                time.sleep(0.2)
        else:
            raise RuntimeError(f"the server did not start: {(workdir / 'server.log').read_text()[-2000:]}")
        yield address, proc.pid, tmp
    finally:
        proc.terminate()
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)
        log.close()


# -- the clients ----------------------------------------------------------------------------
def upload_and_dance(address, song: Path, deadline: float) -> dict:
    """One user: upload, wait for the dance (retrying a busy answer after Retry-After), play the audio."""
    from dancesynth.io.bvh import parse_bvh

    data = song.read_bytes()
    body, headers = multipart({"style": "", "seed": ""}, {"audio": (song.name, data)})
    t0, statuses, answer = time.monotonic(), [], b""
    for _ in range(MAX_TRIES):
        try:
            status, answer_headers, answer = request(address, "POST", "/api/dance", body, headers,
                                                     timeout=max(1.0, deadline - time.monotonic()))
        except OSError as exc:
            statuses.append(f"{type(exc).__name__}")
            break
        statuses.append(status)
        retry = answer_headers.get("retry-after") or answer_headers.get("Retry-After")
        if status not in (429, 503) or retry is None:
            break
        wait = float(retry) * (1 + 0.25 * random.random())  # a little jitter, as the page has
        if time.monotonic() + wait > deadline:
            break
        time.sleep(wait)
    out = {"song": song.name, "status": statuses[-1], "tries": len(statuses),
           "latency_s": time.monotonic() - t0, "correct": False, "error": ""}
    try:
        result = json.loads(answer)
    except ValueError:
        out["error"] = "no JSON answer"
        return out
    if out["status"] != 200:
        out["error"] = str(result.get("error"))[:200]
        return out
    clip = parse_bvh(result["bvh"])
    got, _, audio = request(address, "GET", result["audio_url"], timeout=30)
    out["audio_status"] = got
    out["correct"] = bool(clip.n_frames > 0 and clip.n_frames == result["frames"] and got == 200 and audio == data)
    return out


async def watch_live(address, query: str, deadline: float) -> dict:
    """Read everything one viewer gets, noting the longest wait between messages."""
    from websockets.asyncio.client import connect

    got = {"messages": [], "audio_bytes": 0, "max_gap_s": 0.0, "first_audio_s": None}
    async with connect(f"ws://{address[0]}:{address[1]}/ws/live?{query}", max_size=None, open_timeout=30) as ws:
        last = time.monotonic()
        while time.monotonic() < deadline:
            try:
                m = await asyncio.wait_for(ws.recv(), max(0.1, deadline - time.monotonic()))
            except Exception:  # the deadline, or the server closed the connection
                break
            now = time.monotonic()
            if got["first_audio_s"] is not None:
                got["max_gap_s"] = max(got["max_gap_s"], now - last)
            last = now
            if isinstance(m, bytes):
                got["audio_bytes"] += len(m)
                got["first_audio_s"] = got["first_audio_s"] or now
                continue
            got["messages"].append(json.loads(m))
            if got["messages"][-1]["type"] in ("end", "error"):
                break
    return got


def non_reader(address, query: str) -> socket.socket:
    """A viewer that opens the WebSocket and never reads: a tiny receive window fills at once."""
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    s.connect(address)
    s.sendall((f"GET /ws/live?{query} HTTP/1.1\r\nHost: {address[0]}:{address[1]}\r\nUpgrade: websocket\r\n"
               "Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n"
               "Sec-WebSocket-Version: 13\r\n\r\n").encode())
    s.settimeout(10)
    assert b" 101 " in s.recv(4096).split(b"\r\n")[0], "the server refused the WebSocket"
    return s


def read_to_end(s: socket.socket, seconds: float) -> bytes:
    """What a socket still holds, up to the server closing it (or ``seconds``)."""
    data, deadline = bytearray(), time.monotonic() + seconds
    s.settimeout(5)
    while time.monotonic() < deadline and len(data) < 1 << 27:
        try:
            chunk = s.recv(1 << 16)
        except OSError:
            break
        if not chunk:
            break
        data += chunk
    return bytes(data)


def close_reason(data: bytes) -> str:
    """The code and reason of the WebSocket close frame that ends ``data``, or '' if it does not end with one."""
    for i in range(max(0, len(data) - 130), len(data) - 3):
        if data[i] == 0x88 and data[i + 1] == len(data) - i - 2:  # FIN + close, a short unmasked payload
            return f"{int.from_bytes(data[i + 2:i + 4], 'big')} {data[i + 4:].decode(errors='replace')}"
    return ""


class Sampler:
    """In the background: the upload folder and the server's memory every 0.05 s, a probe GET every 0.25 s."""

    def __init__(self, address, pid: int, tmp: Path, seconds: float):
        self.address, self.pid, self.tmp, self.deadline = address, pid, tmp, time.monotonic() + seconds
        self.folder_counts, self.rss_mb, self.probes = [], [], []   # probes: (status or error, seconds)
        self.stop = threading.Event()
        self.threads = [threading.Thread(target=f, daemon=True) for f in (self._sample, self._probe)]

    def __enter__(self):
        for t in self.threads:
            t.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        for t in self.threads:
            t.join(15)

    def _running(self) -> bool:
        return not self.stop.is_set() and time.monotonic() < self.deadline

    def _sample(self):
        while self._running():
            folders = list(self.tmp.glob("dancesynth-uploads-*"))
            self.folder_counts.append(sum(len(os.listdir(f)) for f in folders if f.is_dir()))
            self.rss_mb.append(tree_rss_mb(self.pid))
            self.stop.wait(0.05)

    def _probe(self):
        while self._running():
            t = time.monotonic()
            try:
                status = request(self.address, "GET", "/api/styles", timeout=10)[0]
            except OSError as exc:
                status = type(exc).__name__
            self.probes.append((status, time.monotonic() - t))
            self.stop.wait(max(0.0, 0.25 - (time.monotonic() - t)))


# -- the run ----------------------------------------------------------------------------------
def run(uploads: int = 100, viewers: int = 50, stream_s: float = 60.0, variants: int = 20,
        options: dict | None = None, limit_s: float = 600.0) -> dict:
    """The whole load test; returns the measurements (see ``print_table``)."""
    options = {**SERVER_OPTIONS, **(options or {})}
    bound = options.get("max_stored_uploads", UPLOAD_BOUND)
    with tempfile.TemporaryDirectory(prefix="serve-load-") as work:
        work = Path(work)
        (work / "songs").mkdir()
        (work / "radio").mkdir()
        songs = make_songs(work / "songs", min(variants, uploads))
        cut(RADIO_SONG, work / "radio" / "live.ogg", 0.0, stream_s)
        with http_folder(work / "radio") as radio, server_process(work, options) as (address, pid, tmp):
            query = urlencode({"url": f"{radio}/live.ogg", "segment_s": 2})
            slow = non_reader(address, query)  # it starts the broadcast; the others join it
            t0 = time.monotonic()
            deadline = t0 + limit_s
            try:
                with Sampler(address, pid, tmp, limit_s + 60) as sampler:
                    watched = {}
                    # A viewer waits for the stream's end, and a minute more: a dropped one may be left hanging.
                    watch_until = min(deadline, t0 + stream_s + 60)
                    watchers = threading.Thread(target=lambda: watched.update(enumerate(asyncio.run(_all_viewers(
                        address, query, viewers, watch_until)))), daemon=True)
                    watchers.start()
                    with ThreadPoolExecutor(max(1, uploads)) as pool:
                        danced = list(pool.map(lambda i: upload_and_dance(address, songs[i % len(songs)], deadline),
                                               range(uploads)))
                    watchers.join(max(1.0, deadline - time.monotonic()))
                    live = _wait_for_drop(address, deadline=time.monotonic() + 10)
                    slow_bytes = read_to_end(slow, 30)
            finally:
                slow.close()
            wall = time.monotonic() - t0
    return _summary(danced, list(watched.values()), viewers, slow_bytes, live, sampler, bound, wall,
                    {"uploads": uploads, "viewers": viewers, "stream_s": stream_s, "variants": len(songs),
                     "server_options": options})


async def _all_viewers(address, query, n, deadline):
    return await asyncio.gather(*[watch_live(address, query, deadline) for _ in range(n)])


def _wait_for_drop(address, deadline: float) -> dict:
    """The server's live statistics once it has let the non-reader go (or at the deadline)."""
    while True:
        stats = json.loads(request(address, "GET", "/api/live", timeout=10)[2])
        if stats["dropped_viewers"] or time.monotonic() > deadline:
            return stats
        time.sleep(0.2)


def _pct(values, q) -> float:
    return round(float(np.percentile(values, q)), 3) if len(values) else float("nan")


def _summary(danced, watched, viewers, slow_bytes, live, sampler, bound, wall, setup) -> dict:
    by_status: dict[str, int] = {}
    for d in danced:
        by_status[str(d["status"])] = by_status.get(str(d["status"]), 0) + 1
    latencies = [d["latency_s"] for d in danced if d["status"] == 200]
    kinds = [[m["type"] for m in w["messages"]] for w in watched]
    probe_s = [s for _, s in sampler.probes]
    return {
        **setup,
        "uploads_200": by_status.get("200", 0),
        "uploads_other": {k: v for k, v in by_status.items() if k != "200"},
        "uploads_correct": sum(d["correct"] for d in danced),
        "upload_busy_retries": sum(d["tries"] - 1 for d in danced),
        "upload_errors": sorted({d["error"] for d in danced if d["error"]})[:5],
        "upload_latency_max_s": round(max(latencies, default=float("nan")), 3),
        "upload_latency_p95_s": _pct(latencies, 95),
        "viewers_start": sum(bool(k) and k[0] == "start" for k in kinds),
        "viewers_frames": sum("frames" in k for k in kinds),
        "viewers_end": sum(bool(k) and k[-1] == "end" for k in kinds),
        "viewers_missing": viewers - len(watched),
        "viewer_max_gap_s": round(max((w["max_gap_s"] for w in watched), default=float("nan")), 3),
        "viewer_heard_min_s": round(min((w["audio_bytes"] / 2 / 22050 for w in watched), default=float("nan")), 2),
        "non_reader_bytes": len(slow_bytes),
        "server_dropped_viewers": live["dropped_viewers"],  # the non-reader and any viewer too slow
        # Server frames are unmasked and uncompressed (the non-reader offered no extension).
        "non_reader_got_message": b'"type": "error"' in slow_bytes and b"behind" in slow_bytes,
        "non_reader_close": close_reason(slow_bytes),
        "folder_max_files": max(sampler.folder_counts, default=0),
        "folder_bound": bound,
        "folder_samples": len(sampler.folder_counts),
        "rss_start_mb": round(sampler.rss_mb[0], 1) if sampler.rss_mb else float("nan"),
        "rss_peak_mb": round(max(sampler.rss_mb, default=float("nan")), 1),
        "probes": len(sampler.probes),
        "probes_failed": sum(status != 200 for status, _ in sampler.probes),
        "probe_max_s": round(max(probe_s, default=float("nan")), 3),
        "probe_p95_s": _pct(probe_s, 95),
        "wall_s": round(wall, 1),
    }


def print_table(r: dict) -> None:
    rows = [
        ("uploads answered 200 / other", f"{r['uploads_200']} / {r['uploads_other'] or 0}"),
        ("dances correct (BVH + audio_url)", f"{r['uploads_correct']} of {r['uploads']}"),
        ("busy answers retried", r["upload_busy_retries"]),
        ("upload latency max / p95 (s)", f"{r['upload_latency_max_s']} / {r['upload_latency_p95_s']}"),
        ("viewers start / frames / end", f"{r['viewers_start']} / {r['viewers_frames']} / {r['viewers_end']}"
                                          f" of {r['viewers']}"),
        ("viewer longest wait (s)", r["viewer_max_gap_s"]),
        ("viewers dropped by the server", r["server_dropped_viewers"]),
        ("non-reader got a message", r["non_reader_got_message"]),
        ("non-reader's close frame", r["non_reader_close"] or "none"),
        ("upload folder max files / bound", f"{r['folder_max_files']} / {r['folder_bound']}"),
        ("server RSS start / peak (MB)", f"{r['rss_start_mb']} / {r['rss_peak_mb']}"),
        ("probe GETs (failed)", f"{r['probes']} ({r['probes_failed']})"),
        ("probe latency max / p95 (s)", f"{r['probe_max_s']} / {r['probe_p95_s']}"),
        ("wall time (s)", r["wall_s"]),
    ]
    print(f"serve load: {r['uploads']} uploads + {r['viewers']} viewers + 1 non-reader, {r['stream_s']:g} s stream")
    for name, value in rows:
        print(f"  {name:<34} {value}")
    for e in r["upload_errors"]:
        print(f"  error: {e}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--uploads", type=int, default=100)
    parser.add_argument("--viewers", type=int, default=50)
    parser.add_argument("--stream-s", type=float, default=60.0)
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    args = parser.parse_args(argv)
    result = run(args.uploads, args.viewers, args.stream_s)
    print_table(result)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "serve_load.json").write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out / 'serve_load.json'}")


if __name__ == "__main__":
    main()

"""Live faults, measured: ``dancesynth stream`` against sources that stall, die, lie or fill the disk.

    .venv/bin/python benchmarks/live_faults.py [--quick] [--only NAME] [--out benchmarks/results]

Each scenario runs the real CLI against a real source (a local HTTP radio on
127.0.0.1 from ``tests/servers.py``, a file, standard input) with 2 s segments,
and watches the growing BVH every 0.1 s. Per scenario: exit code, the error line,
for a stall the wall seconds it lasted, the seconds of motion that reached the BVH
meanwhile and the longest wait between two arrivals of motion, and whether the BVH
on disk is a complete, readable BVH and how long its dance is. ``--quick`` shortens
the 20 s stall to 8 s. Prints the table and writes ``live_faults.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))  # the test servers: one radio for tests and benchmark

from servers import http_folder, radio, range_ignoring, silent  # noqa: E402

SONG = REPO / "src" / "dancesynth" / "data" / "music" / "Kevin_MacLeod_-_Vibe_Ace.ogg"
DANCESYNTH = [sys.executable, "-m", "dancesynth.cli"]
SEGMENT_S = 2.0
MP3_RATE = 8000  # bytes/s of a 64 kbit/s MP3
FRAMES = re.compile(rb"Frames:\s*(\d+)")


def _encode(tmp: Path, name: str, seconds: float, *args: str) -> Path:
    out = tmp / name
    subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-t", str(seconds), "-i", str(SONG), "-vn", *args,
                    str(out)], check=True)
    return out


def _frames_on_disk(path: Path) -> int:
    try:
        with open(path, "rb") as fh:
            m = FRAMES.search(fh.read(1 << 16))
    except OSError:
        return 0
    return int(m.group(1)) if m else 0


def _watch(cmd, out: Path, *, stdin_feed=None, timeout_s: float = 120.0, preexec=None) -> dict:
    """Run ``cmd``; sample the BVH's frame count every 0.1 s (monotonic time, frames)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(REPO / ".cache" / "numba")}
    proc = subprocess.Popen(cmd, stdin=subprocess.PIPE if stdin_feed else subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=False, env=env, cwd=REPO,
                            preexec_fn=preexec)
    if stdin_feed:
        threading.Thread(target=stdin_feed, args=(proc.stdin,), daemon=True).start()
    texts = {}
    readers = [threading.Thread(target=lambda k, f: texts.__setitem__(k, f.read().decode("utf-8", "replace")),
                                args=(k, f), daemon=True) for k, f in (("stdout", proc.stdout), ("stderr", proc.stderr))]
    for r in readers:
        r.start()
    samples = []
    deadline = time.monotonic() + timeout_s
    while proc.poll() is None and time.monotonic() < deadline:
        samples.append((time.monotonic(), _frames_on_disk(out)))
        time.sleep(0.1)
    if proc.poll() is None:
        proc.kill()
    proc.wait()
    for r in readers:
        r.join(timeout=10)
    return {"rc": proc.returncode, "samples": samples, **texts}


def _feed(chunks):
    """A writer for standard input: (bytes, pause after) pairs, then close."""
    def feed(pipe):
        try:
            for data, pause in chunks:
                pipe.write(data)
                pipe.flush()
                time.sleep(pause)
        except OSError:
            pass
        finally:
            try:
                pipe.close()
            except OSError:
                pass
    return feed


def _summarise(name: str, run: dict, out: Path, stall: tuple[float, float] | None = None) -> dict:
    from dancesynth.errors import DanceSynthError
    from dancesynth.io.bvh import read_bvh

    errors = [ln for ln in run["stderr"].splitlines() if ln.startswith(("error:", "internal error", "Traceback"))]
    message = errors[-1].replace(str(out.parent) + "/", "") if errors else ""
    row = {"scenario": name, "exit": run["rc"], "message": message,
           "stall_wall_s": None, "stall_motion_s": None, "max_gap_s": None}
    if not out.exists():
        row.update(bvh_ok=None, bvh_s=0.0)  # nothing written (an error before the first segment)
    else:
        try:
            clip = read_bvh(out)
            row.update(bvh_ok=True, bvh_s=round(clip.duration_s, 2))
        except (DanceSynthError, OSError) as exc:
            row.update(bvh_ok=False, bvh_s=0.0, bvh_error=str(exc)[:120])
    samples = run["samples"]
    arrivals = [t for (t, n), (_, prev) in zip(samples[1:], samples[:-1]) if n > prev]
    if stall is not None and arrivals:
        a, b = stall
        during = [(t, n) for t, n in samples if a <= t <= b]
        motion = (during[-1][1] - during[0][1]) / 30.0 if len(during) > 1 else 0.0
        # The longest wait for new motion from the stall's start to its end (or the end of the run).
        marks = [a] + [t for t in arrivals if a < t < b] + [min(b, samples[-1][0])]
        row.update(stall_wall_s=round(b - a, 1), stall_motion_s=round(motion, 1),
                   max_gap_s=round(max(y - x for x, y in zip(marks[:-1], marks[1:])), 1))
    return row


def scenario_radio_stall(tmp: Path, stall_s: float, resume: bool, name: str) -> dict:
    """An MP3 radio: 6 s of music, silent for ``stall_s`` s on an open connection, then 6 s more or off air."""
    mp3 = _encode(tmp, "radio.mp3", 12.0, "-b:a", "64k").read_bytes()
    handler = radio(mp3, MP3_RATE, stall_at=len(mp3) // 2, stall_s=stall_s, resume=resume)
    out = tmp / f"{name}.bvh"
    with http_folder(tmp, handler=handler) as url:
        run = _watch([*DANCESYNTH, "stream", f"{url}/radio", "-o", str(out), "--segment-seconds", str(SEGMENT_S)],
                     out, timeout_s=stall_s + 90)
    start = handler.stall_until - stall_s if handler.stall_until else run["samples"][-1][0]
    end = start + stall_s if resume else run["samples"][-1][0]
    return _summarise(name, run, out, stall=(start, end))


def scenario_silent_url(tmp: Path) -> dict:
    out = tmp / "silent.bvh"
    with http_folder(tmp, handler=silent(60.0)) as url:
        run = _watch([*DANCESYNTH, "stream", f"{url}/radio", "-o", str(out)], out, timeout_s=90)
    return _summarise("URL that never sends audio", run, out)


def scenario_range_ignoring(tmp: Path) -> dict:
    _encode(tmp, "song.mp3", 12.0, "-b:a", "64k")
    out = tmp / "norange.bvh"
    handler = range_ignoring(0.4)
    with http_folder(tmp, handler=handler) as url:
        run = _watch([*DANCESYNTH, "stream", f"{url}/song.mp3", "-o", str(out), "--segment-seconds",
                      str(SEGMENT_S), "--fast"], out, timeout_s=60)
    row = _summarise("URL drops, server ignores Range (12 s song)", run, out)
    row["requests"] = handler.requests
    return row


def scenario_truncated(tmp: Path, fmt: str, stdin: bool) -> dict:
    song = _encode(tmp, f"song.{fmt}", 12.0, *(["-ac", "1"] if fmt == "wav" else []))
    data = song.read_bytes()[: song.stat().st_size // 2]
    out = tmp / f"trunc_{fmt}_{stdin}.bvh"
    name = f"{fmt.upper()} cut in half, {'stdin' if stdin else 'file'}"
    if stdin:
        run = _watch([*DANCESYNTH, "stream", "-", "-o", str(out), "--segment-seconds", str(SEGMENT_S)], out,
                     stdin_feed=_feed([(data, 0.0)]), timeout_s=60)
    else:
        cut = tmp / f"cut.{fmt}"
        cut.write_bytes(data)
        run = _watch([*DANCESYNTH, "stream", str(cut), "-o", str(out), "--segment-seconds", str(SEGMENT_S),
                      "--fast"], out, timeout_s=60)
    return _summarise(name, run, out)


def scenario_junk(tmp: Path, fmt: str) -> dict:
    song = _encode(tmp, f"junk_song.{fmt}", 8.0, *(["-b:a", "64k"] if fmt == "mp3" else []))
    import numpy as np

    data = np.random.default_rng(0).bytes(4096) + song.read_bytes()
    out = tmp / f"junk_{fmt}.bvh"
    run = _watch([*DANCESYNTH, "stream", "-", "-o", str(out), "--segment-seconds", str(SEGMENT_S), "--fast"], out,
                 stdin_feed=_feed([(data, 0.0)]), timeout_s=60)
    return _summarise(f"4 KB junk + {fmt.upper()} on stdin (8 s)", run, out)


def _limit_file_size(limit: int):
    def preexec():
        # A full disk for real: writes past ``limit`` bytes fail with EFBIG (SIGXFSZ ignored).
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return preexec


def scenario_full_disk(tmp: Path) -> dict:
    song = _encode(tmp, "disk.ogg", 20.0)
    out = tmp / "full.bvh"
    run = _watch([*DANCESYNTH, "stream", str(song), "-o", str(out), "--segment-seconds", str(SEGMENT_S), "--fast"],
                 out, timeout_s=90, preexec=_limit_file_size(150_000))
    return _summarise("disk full after 150 kB (20 s song)", run, out)


def format_table(rows: list[dict]) -> str:
    head = (f"{'scenario':44}  {'exit':>4}  {'stall s':>7}  {'motion s':>8}  {'max gap':>7}  {'BVH ok':>6}  "
            f"{'BVH s':>6}  message")
    lines = [head, "-" * len(head)]
    f = lambda v: "-" if v is None else f"{v:g}"  # noqa: E731
    for r in rows:
        msg = r["message"].removeprefix("error: ")
        lines.append(f"{r['scenario'][:44]:44}  {r['exit']:>4}  {f(r['stall_wall_s']):>7}  {f(r['stall_motion_s']):>8}  "
                     f"{f(r['max_gap_s']):>7}  { {True: 'yes', False: 'NO', None: 'none'}[r['bvh_ok']]:>6}  {r['bvh_s']:6.1f}  "
                     f"{msg[:110]}")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="an 8 s stall instead of 20 s")
    parser.add_argument("--only", action="append", help="run only scenarios whose key contains this")
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    args = parser.parse_args()
    stall_s = 8.0 if args.quick else 20.0
    scenarios = {
        "stall_resume": lambda t: scenario_radio_stall(t, stall_s, True, f"radio stalls {stall_s:g} s, resumes"),
        "stall_dies": lambda t: scenario_radio_stall(t, stall_s, False, f"radio stalls {stall_s:g} s, off air"),
        "drop": lambda t: scenario_radio_stall(t, 0.0, False, "radio drops, reconnects refused"),
        "silent": scenario_silent_url,
        "norange": scenario_range_ignoring,
        "trunc_ogg_file": lambda t: scenario_truncated(t, "ogg", False),
        "trunc_ogg_stdin": lambda t: scenario_truncated(t, "ogg", True),
        "trunc_wav_stdin": lambda t: scenario_truncated(t, "wav", True),
        "junk_ogg": lambda t: scenario_junk(t, "ogg"),
        "junk_mp3": lambda t: scenario_junk(t, "mp3"),
        "full_disk": scenario_full_disk,
    }
    rows = []
    for key, scenario in scenarios.items():
        if args.only and not any(o in key for o in args.only):
            continue
        with tempfile.TemporaryDirectory() as tmp:
            t = time.perf_counter()
            row = scenario(Path(tmp))
            row["key"], row["run_s"] = key, round(time.perf_counter() - t, 1)
        rows.append(row)
        print(format_table([row]).splitlines()[-1], flush=True)
    print()
    print(format_table(rows))
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / ("live_faults_quick.json" if args.quick else "live_faults.json")
    path.write_text(json.dumps({"stall_s": stall_s, "segment_s": SEGMENT_S, "rows": rows}, indent=1) + "\n")
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()

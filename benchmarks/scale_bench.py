"""Benchmark of dancing a music library: songs per minute and CPU per song, every way a user could.

    .venv/bin/python benchmarks/scale_bench.py [--copies 4] [--no-ray] [--out benchmarks/results]

The library: each bundled song ``--copies`` times under another name (4 copies: 20 songs, 24 min
of music), danced onto the default character as BVH. Side by side, each in a fresh process:

- shell loop: ``dancesynth dance SONG -o OUT -q`` once per song;
- Python loop: ``dancesynth.dance()`` and a write per song in one process (the README's loop);
- hand-written: ``multiprocessing.Pool`` of 2 forked processes, each with its own database and
  torch/BLAS at one thread, ``imap_unordered`` over the songs (the best a user could write);
- ``dancesynth batch`` with 1 and 2 workers, and on a local Ray cluster (``ray start --head``
  with 2 CPUs, started before the timer) with 2 actors.

Also: the per-song overhead inside a batch worker (time not spent analysing, synthesising or
writing that song), the peak memory per worker, Ray's scheduling overhead per task, the start-up
of ``--help`` and ``styles``, the neural engine's speed at its default threads, and a written
projection to N machines and to 100,000 songs. Prints a table and writes ``scale_bench.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
MUSIC = REPO / "src" / "dancesynth" / "data" / "music"
BIN = Path(sys.executable).parent
DANCESYNTH = BIN / "dancesynth"
ISSUE = {"shell loop": 32.5, "hand-written (issue)": 102.0}   # songs/min measured when issue 15 was filed

LOOP = r"""
import sys, time
from pathlib import Path
import dancesynth
from dancesynth.export.formats import write_dance
from dancesynth.retarget import on_character

def one(args):
    song, out = args
    clip = dancesynth.dance(song)
    moved, character = on_character(clip, "mannequin")
    write_dance(Path(out), moved, character)
    return song

jobs = [(s, str(Path(sys.argv[2]) / (Path(s).stem + ".bvh"))) for s in Path(sys.argv[1]).read_text().split("\n") if s]
if sys.argv[3] == "loop":
    for job in jobs:
        one(job)
else:
    import multiprocessing
    from dancesynth.threads import limit_threads
    with multiprocessing.get_context("fork").Pool(2, initializer=limit_threads, initargs=(1,)) as pool:
        for _ in pool.imap_unordered(one, jobs):
            pass
"""


def children_cpu() -> float:
    use = resource.getrusage(resource.RUSAGE_CHILDREN)
    return use.ru_utime + use.ru_stime


def timed(cmd: list, env=None) -> tuple[float, float]:
    """(wall s, CPU s of the process and its children)."""
    cpu, t = children_cpu(), time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, env=env)
    return time.perf_counter() - t, children_cpu() - cpu


def make_library(root: Path, copies: int) -> tuple[list[Path], float]:
    import soundfile as sf

    songs, seconds = [], 0.0
    for c in range(copies):
        for song in sorted(MUSIC.glob("*.ogg")):
            dst = root / f"{song.stem[:24]}-{c}.ogg"
            shutil.copy(song, dst)
            songs.append(dst)
            seconds += sf.info(str(song)).duration
    return songs, seconds


def manifest(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / "manifest.jsonl").read_text().splitlines() if line.strip()]


def row(name: str, wall: float, cpu: float, n: int, extra=None) -> dict:
    return {"way": name, "wall_s": wall, "songs_per_min": 60.0 * n / wall, "cpu_per_song_s": cpu / n, **(extra or {})}


def batch_row(name: str, songs: list[Path], out: Path, args: list[str]) -> dict:
    wall, cpu = timed([str(DANCESYNTH), "batch", *map(str, songs), "-o", str(out), "-q", *args])
    recs = manifest(out)
    if len(recs) != len(songs) or any(r["status"] != "done" for r in recs):
        raise SystemExit(f"{name}: not every song was danced: {[r.get('error') for r in recs]}")
    worker_cpu = sum(r["cpu_seconds"] for r in recs)
    overhead = [r["seconds"] - r["timings_s"]["music_s"] - r["timings_s"]["synthesis_s"] - r["timings_s"]["write_s"]
                for r in recs]
    return row(name, wall, cpu if "--ray" not in args else worker_cpu, len(songs), {
        "worker_cpu_per_song_s": worker_cpu / len(songs),
        "overhead_per_song_s": statistics.median(overhead),
        "database_and_graph_per_song_s": statistics.median(r["timings_s"]["database_s"] + r["timings_s"]["prepare_s"]
                                                           for r in recs),
        "peak_rss_mb_per_worker": max(r["peak_rss_mb"] for r in recs),
        "workers": len({r["worker"] for r in recs})})


def start_ray(port: int, temp: Path) -> subprocess.Popen:
    head = subprocess.Popen([str(BIN / "ray"), "start", "--head", "--block", f"--port={port}", "--num-cpus=2",
                             "--include-dashboard=false", "--disable-usage-stats", f"--temp-dir={temp}"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    for _ in range(180):
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            time.sleep(2.0)   # the raylet comes up after the GCS port
            return head
        except OSError:
            time.sleep(0.5)
    raise SystemExit("the local Ray head node did not start")


def ray_task_overhead(address: str, calls: int = 300) -> float:
    """Seconds of Ray's own cost per task: a round trip to an actor method that does nothing."""
    code = f"""
import time, ray
ray.init(address={address!r}, logging_level="error", log_to_driver=False)
@ray.remote(num_cpus=1)
class A:
    def f(self, x):
        return x
actors = [A.remote() for _ in range(2)]
ray.get([a.f.remote(0) for a in actors])
t = time.perf_counter()
refs = [actors[i % 2].f.remote(i) for i in range({calls})]
ray.get(refs)
one = time.perf_counter()
for i in range({calls // 3}):
    ray.get(actors[0].f.remote(i))
print((time.perf_counter() - one) / {calls // 3})
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    return float(out.strip().splitlines()[-1])


def manifest_append_rate(tmp: Path, n: int = 500) -> float:
    """Records per second the batch's driver can append to its manifest (each flushed and synced)."""
    sys.path.insert(0, str(REPO / "src"))
    from dancesynth.batching.manifest import Manifest

    m = Manifest(tmp)
    rec = {"name": "x.bvh", "status": "done", "summary": {"beats": 130, "style": "salsa"}, "seconds": 1.0}
    t = time.perf_counter()
    for _ in range(n):
        m.append(rec)
    m.close()
    return n / (time.perf_counter() - t)


def startup() -> dict:
    out = {}
    for name, args in (("help", ["--help"]), ("styles", ["styles"])):
        out[f"{name}_s"] = min(timed([str(DANCESYNTH), *args])[0] for _ in range(5))
    return out


def neural_speed(song: Path, tmp: Path) -> dict:
    report = tmp / "neural.json"
    subprocess.run([str(DANCESYNTH), "dance", str(song), "--engine", "neural", "-o", str(tmp / "n.bvh"), "-q",
                    "--report", str(report)], check=True)
    s = json.loads(report.read_text())["summary"]
    return {"song_s": s["duration_s"], "synthesis_s": s["timings_s"]["synthesis_s"],
            "realtime_factor": s["duration_s"] / s["timings_s"]["synthesis_s"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--copies", type=int, default=4, help="copies of each bundled song (default %(default)s: 20 songs)")
    ap.add_argument("--no-ray", action="store_true", help="leave out the Ray rows")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    args = ap.parse_args()
    env = {**os.environ, "NUMBA_CACHE_DIR": os.environ.get("NUMBA_CACHE_DIR", str(REPO / ".cache" / "numba"))}
    os.environ.update(env)
    with tempfile.TemporaryDirectory(prefix="scale_bench_") as tmp_s:
        tmp = Path(tmp_s)
        songs, music_s = make_library(tmp, args.copies)
        listing = tmp / "songs.txt"
        listing.write_text("\n".join(map(str, songs)))
        subprocess.run([str(DANCESYNTH), "dance", str(songs[0]), "-o", str(tmp / "warm.bvh"), "-q"], check=True)
        rows = []

        def out(name):
            (tmp / name).mkdir()
            return tmp / name

        o = out("shell")
        cpu, t = children_cpu(), time.perf_counter()
        for s in songs:
            subprocess.run([str(DANCESYNTH), "dance", str(s), "-o", str(o / (s.stem + ".bvh")), "-q"], check=True,
                           stderr=subprocess.DEVNULL)  # the style-fit warnings, once per song
        rows.append(row("shell loop of `dancesynth dance`", time.perf_counter() - t, children_cpu() - cpu, len(songs)))
        for name, mode in (("Python loop, dancesynth.dance() x N", "loop"),
                           ("hand-written: Pool(2), one database each, BLAS 1 thread", "pool")):
            rows.append(row(name, *timed([sys.executable, "-c", LOOP, str(listing), str(out(mode)), mode]), len(songs)))
        rows.append(batch_row("dancesynth batch --workers 1", songs, tmp / "b1", ["--workers", "1"]))
        rows.append(batch_row("dancesynth batch --workers 2", songs, tmp / "b2", ["--workers", "2"]))
        # The same batch again: every song is done, so the manifest alone answers (best of 3 runs).
        rerun_s = min(timed([str(DANCESYNTH), "batch", *map(str, songs), "-o", str(tmp / "b2"), "-q",
                             "--workers", "2"])[0] for _ in range(3))
        ray = {}
        if not args.no_ray:
            with socket.socket() as s:
                s.bind(("127.0.0.1", 0))
                port = s.getsockname()[1]
            temp = Path("/tmp") / f"dsbench{port}"
            head = start_ray(port, temp)
            try:
                address = f"127.0.0.1:{port}"
                rows.append(batch_row("dancesynth batch --ray (local, 2 CPUs)", songs, tmp / "ray",
                                      ["--ray", address, "--workers", "2"]))
                ray["task_overhead_s"] = ray_task_overhead(address)
            finally:
                os.killpg(head.pid, signal.SIGKILL)
                head.wait()
                shutil.rmtree(temp, ignore_errors=True)
        append_rate = manifest_append_rate(tmp)
        extra = {"rerun_nothing_to_do_s": rerun_s, "startup": startup(),
                 "neural": neural_speed(MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg", tmp)}
    result = {"songs": len(songs), "music_minutes": music_s / 60.0, "rows": rows, "ray": ray,
              "manifest_appends_per_s": append_rate, **extra,
              "machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                          "load_avg_after": os.getloadavg()}}
    result["projection"] = projection(result)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "scale_bench.json").write_text(json.dumps(result, indent=1) + "\n")
    print(format_table(result))


def projection(r: dict) -> dict:
    """What N machines like this one would do, from the 2-worker batch and Ray's measured overheads."""
    by = {x["way"]: x for x in r["rows"]}
    local = by["dancesynth batch --workers 2"]
    song_s = local["worker_cpu_per_song_s"]
    overhead = r["ray"].get("task_overhead_s", 0.0)
    efficiency = song_s / (song_s + overhead)
    per_machine = local["songs_per_min"] * efficiency
    driver_limit = 60.0 * r["manifest_appends_per_s"]   # songs/min the one driver can record
    out = {"assumes": ("machines like this one (2 cores), each running the 2-worker batch's songs/min; Ray adds its "
                       "measured per-task round trip to each song; the songs and the output folder on a shared file "
                       "system fast enough not to matter; one driver appending every record to the manifest"),
           "per_machine_songs_per_min": per_machine, "ray_efficiency": efficiency,
           "driver_songs_per_min_limit": driver_limit, "machines": {}}
    for n in (1, 10, 100, 1000):
        rate = min(per_machine * n, driver_limit)
        out["machines"][str(n)] = {"songs_per_min": rate, "hours_for_100k": 100_000 / rate / 60.0}
    out["hours_for_100k_here"] = {k: 100_000 / x["songs_per_min"] / 60.0 for k, x in by.items()}
    return out


def format_table(r: dict) -> str:
    rows = r["rows"]
    shell = rows[0]["songs_per_min"]
    hand = next(x for x in rows if x["way"].startswith("hand-written"))["songs_per_min"]
    lines = [f"{r['songs']} songs, {r['music_minutes']:.1f} min of music, on {r['machine']['cpus']} cores "
             f"(load average after: {r['machine']['load_avg_after'][0]:.2f})", "",
             "| way | songs/min | × shell loop | × hand-written | CPU per song | per-song overhead in a worker | "
             "peak RSS per worker |", "|---|---|---|---|---|---|---|"]
    for x in rows:
        ov = f"{x['overhead_per_song_s']:.3f} s" if "overhead_per_song_s" in x else ""
        rss = f"{x['peak_rss_mb_per_worker']:.0f} MB" if "peak_rss_mb_per_worker" in x else ""
        lines.append(f"| {x['way']} | {x['songs_per_min']:.1f} | {x['songs_per_min'] / shell:.2f} | "
                     f"{x['songs_per_min'] / hand:.2f} | {x['cpu_per_song_s']:.2f} s | {ov} | {rss} |")
    by = {x["way"]: x for x in rows}
    b2 = by["dancesynth batch --workers 2"]
    lines += ["", f"batch (2 workers) vs the issue's measurements: {b2['songs_per_min'] / ISSUE['shell loop']:.2f}× "
                  f"its shell loop ({ISSUE['shell loop']} songs/min), "
                  f"{b2['songs_per_min'] / ISSUE['hand-written (issue)']:.2f}× its hand-written best "
                  f"({ISSUE['hand-written (issue)']} songs/min)"]
    if "dancesynth batch --ray (local, 2 CPUs)" in by:
        ray = by["dancesynth batch --ray (local, 2 CPUs)"]
        lines.append(f"Ray local / process pool: {ray['songs_per_min'] / b2['songs_per_min']:.3f} "
                     f"(Ray's round trip per task: {r['ray']['task_overhead_s'] * 1e3:.2f} ms)")
    s, n = r["startup"], r["neural"]
    lines.append(f"batch re-run with every song done: {r['rerun_nothing_to_do_s']:.2f} s for {r['songs']} songs")
    lines.append(f"start-up: --help {s['help_s']:.3f} s, styles {s['styles_s']:.3f} s; neural engine at its default "
                 f"threads: {n['realtime_factor']:.1f}× real time ({n['song_s']:.0f} s song)")
    p = r["projection"]
    lines += ["", f"Projection ({p['assumes']}):",
              f"  per machine {p['per_machine_songs_per_min']:.1f} songs/min (Ray efficiency "
              f"{p['ray_efficiency']:.4f}); one driver records at most {p['driver_songs_per_min_limit']:.0f} songs/min"]
    for n_machines, v in p["machines"].items():
        lines.append(f"  {n_machines:>5} machines: {v['songs_per_min']:.0f} songs/min, 100,000 songs in "
                     f"{v['hours_for_100k']:.2f} h")
    lines.append("  100,000 songs on this machine: " + ", ".join(f"{k}: {h:.1f} h"
                                                                for k, h in p["hours_for_100k_here"].items()))
    return "\n".join(lines)


if __name__ == "__main__":
    main()

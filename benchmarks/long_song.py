"""Long songs in bounded memory (issue 15): ``dancesynth dance`` on songs of 3, 10 and 30 minutes.

    .venv/bin/python benchmarks/long_song.py [--minutes 3 10 30] [--songs-dir DIR] [--repeat N]
                                             [--stages] [--src SRC] [--out benchmarks/results]

The songs are made from the real music the project bundles (``src/dancesynth/data/music``) and
shares (``/work/shared/data/music``, where present; files with the same content count once):
all of it joined end to end, looped to the length and encoded as Ogg Vorbis (44.1 kHz stereo),
in a temporary folder (``--songs-dir`` keeps them for the next run). Nothing large is written
into the repository.

Per song, in a fresh process each:

- ``dancesynth dance SONG -o out.bvh --max-minutes M+1 -q`` (streaming engine, the default
  character): the process's peak RSS (``wait4``'s ``ru_maxrss``), wall and CPU seconds;
- the analysis, stage by stage (CPU seconds, best of ``--repeat``): decoding at 22050 Hz
  (``load_audio``) against one plain read of the file (``soundfile.read``, no down-mix or
  resampling), and the beat tracker (``track_beats``: trimming, tracking, refinement) per
  minute of music.

``--stages`` adds the peak RSS of each stage of a dance (decode, onset, beats, metre, intensity,
database, synthesis, retarget, BVH text) in one more process per song, from Linux's VmHWM reset
before each stage. ``--src`` runs another checkout's ``src`` (e.g. ``git archive HEAD src | tar -x -C /tmp/head``) and
``--baseline`` prints an earlier run's JSON beside this one: a before/after comparison. Prints a
table and writes ``long_song.json`` (``--name``).
Targets: peak RSS <= 300 MB at 30 minutes; decoding ~ one read; beat tracking s/min about
constant from 3 to 30 minutes.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
MUSIC_DIRS = [REPO / "src" / "dancesynth" / "data" / "music", Path("/work/shared/data/music")]
TARGET_RSS_MB = 300.0

# Run in a fresh process: the analysis, stage by stage, CPU seconds (best of N).
ANALYSIS_CODE = r"""
import json, sys, time
import numpy as np
import soundfile as sf
from dancesynth.io.audio import load_audio
from dancesynth.music.beats import track_beats
from dancesynth.music.onset import onset_envelope
path, repeat = sys.argv[1], int(sys.argv[2])
def best(fn):
    out, times = None, []
    for _ in range(repeat):
        t = time.process_time(); out = fn(); times.append(time.process_time() - t)
    return min(times), out
read_s, _ = best(lambda: sf.read(path, dtype="float32")[0].shape)
decode_s, (y, sr) = best(lambda: load_audio(path, sr=22050, max_duration_s=None))
onset_s, env = best(lambda: onset_envelope(y, sr))
beats_s, _ = best(lambda: track_beats(y, sr, onset_env=env))
print(json.dumps({"one_read_s": read_s, "decode_s": decode_s, "onset_s": onset_s, "beat_tracking_s": beats_s,
                  "duration_s": len(y) / sr}))
"""

# Run in a fresh process: peak RSS of each stage of a dance (VmHWM is reset before each).
STAGES_CODE = r"""
import gc, json, sys
path = sys.argv[1]
def status():
    out = {}
    for line in open("/proc/self/status"):
        if line.startswith(("VmRSS", "VmHWM")):
            key, value = line.split(":"); out[key] = int(value.split()[0]) / 1024
    return out
rows = []
def stage(name, fn):
    gc.collect()
    with open("/proc/self/clear_refs", "w") as fh:
        fh.write("5")
    before = status()["VmRSS"]
    out = fn()
    after = status()
    rows.append({"stage": name, "rss_before_mb": before, "peak_mb": after["VmHWM"], "rss_after_mb": after["VmRSS"]})
    return out
from dancesynth.api import dance
from dancesynth.export.formats import encode_dance
from dancesynth.io.audio import load_audio
from dancesynth.motion.database import open_database
from dancesynth.music import analyze_music
from dancesynth.music.beats import track_beats
from dancesynth.music.intensity import beat_intensity_db
from dancesynth.music.metre import track_metre
from dancesynth.music.onset import onset_envelope
from dancesynth.retarget import on_character
from dancesynth.retarget.character import load_character
rows.append({"stage": "imports", "rss_before_mb": 0.0, "peak_mb": status()["VmHWM"], "rss_after_mb": status()["VmRSS"]})
y, sr = stage("decode", lambda: load_audio(path, sr=22050, max_duration_s=None))
env = stage("onset", lambda: onset_envelope(y, sr))
beats = stage("beats", lambda: track_beats(y, sr, onset_env=env))[0]
stage("metre", lambda: track_metre(y, sr, beat_times_s=beats, end_s=len(y) / sr))
stage("intensity", lambda: beat_intensity_db(y, sr, beats))
del y, env
music = stage("analyze_music (all)", lambda: analyze_music(path=path, max_duration_s=None))
db = stage("open database", lambda: open_database(None))
clip = stage("dance (synthesis)", lambda: dance(music, database=db, max_duration_s=music.duration_s + 60))
character = load_character("mannequin")
moved = stage("retarget", lambda: on_character(clip, character)[0])
stage("BVH bytes", lambda: len(encode_dance(".bvh", moved, character)))
print(json.dumps(rows))
"""


def music_files() -> list[Path]:
    """The bundled and shared songs, each content once, in name order."""
    seen, files = set(), []
    for folder in MUSIC_DIRS:
        for path in sorted(folder.glob("*.ogg")) if folder.is_dir() else []:
            digest = hashlib.sha1(path.read_bytes()).hexdigest()
            if digest not in seen:
                seen.add(digest)
                files.append(path)
    if not files:
        raise SystemExit("no music found in " + ", ".join(map(str, MUSIC_DIRS)))
    return files


def make_songs(folder: Path, minutes: list[float]) -> dict[float, Path]:
    """``song_<M>min.ogg`` for every length, made once (kept in ``folder``)."""
    folder.mkdir(parents=True, exist_ok=True)
    joined = folder / "joined.wav"
    songs = {m: folder / f"song_{m:g}min.ogg" for m in minutes}
    if all(p.exists() for p in songs.values()):
        return songs
    if not joined.exists():
        files = music_files()
        inputs = [arg for f in files for arg in ("-i", str(f))]
        chain = "".join(f"[{i}:a]aresample=44100,aformat=channel_layouts=stereo[a{i}];" for i in range(len(files)))
        chain += "".join(f"[a{i}]" for i in range(len(files))) + f"concat=n={len(files)}:v=0:a=1[out]"
        subprocess.run(["ffmpeg", "-nostdin", "-v", "error", "-y", *inputs, "-filter_complex", chain,
                        "-map", "[out]", str(joined)], check=True)
    for m, path in songs.items():
        if not path.exists():
            tmp = path.with_suffix(".part.ogg")
            subprocess.run(["ffmpeg", "-nostdin", "-v", "error", "-y", "-stream_loop", "-1", "-i", str(joined),
                            "-t", f"{m * 60:.3f}", "-c:a", "libvorbis", "-q:a", "4", str(tmp)], check=True)
            tmp.rename(path)
    return songs


def child_env(src: Path | None) -> dict:
    env = dict(os.environ)
    if src is not None:
        env["PYTHONPATH"] = str(src) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def run_measured(cmd: list[str], env: dict) -> dict:
    """Run ``cmd``; its peak RSS (this child's alone, from ``wait4``), wall and CPU seconds."""
    t = time.perf_counter()
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    stderr = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - t
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}): {stderr.decode(errors='replace')[-2000:]}")
    return {"peak_rss_mb": usage.ru_maxrss / 1024.0, "wall_s": wall, "cpu_s": usage.ru_utime + usage.ru_stime}


def run_json(code: str, args: list[str], env: dict):
    out = subprocess.run([sys.executable, "-c", code, *args], env=env, capture_output=True, check=False)
    if out.returncode != 0:
        raise SystemExit(f"measurement failed: {out.stderr.decode(errors='replace')[-2000:]}")
    return json.loads(out.stdout.decode().strip().splitlines()[-1])


def print_comparison(before: list[dict], after: list[dict]) -> None:
    """Before -> after, per length both runs measured."""
    print("\nbefore -> after")
    print(f"{'minutes':>7} {'peak RSS MB':>15} {'wall s':>13} {'decode/read':>13} {'beats s/min':>17}")
    earlier = {r["minutes"]: r for r in before}
    for r in after:
        b = earlier.get(r["minutes"])
        if b is None:
            continue
        print(f"{r['minutes']:>7g} {b['peak_rss_mb']:>6.0f} -> {r['peak_rss_mb']:<5.0f} "
              f"{b['wall_s']:>5.1f} -> {r['wall_s']:<5.1f} "
              f"{b['decode_per_read']:>5.2f} -> {r['decode_per_read']:<5.2f} "
              f"{b['beat_tracking_s_per_min']:>7.4f} -> {r['beat_tracking_s_per_min']:<7.4f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, nargs="+", default=[3, 10, 30])
    ap.add_argument("--songs-dir", type=Path, help="make (or reuse) the songs here instead of a temporary folder")
    ap.add_argument("--repeat", type=int, default=3, help="best of N for the analysis timings (default 3)")
    ap.add_argument("--dance-repeat", type=int, default=1, help="runs of `dancesynth dance` per song (best wall, "
                                                                 "highest RSS)")
    ap.add_argument("--stages", action="store_true", help="also the peak RSS of each stage (Linux)")
    ap.add_argument("--src", type=Path, help="run this checkout's src/ instead of the installed package")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    ap.add_argument("--name", default="long_song", help="result file name (default long_song -> long_song.json)")
    ap.add_argument("--baseline", type=Path, help="an earlier run's JSON (e.g. with --src of HEAD): print both")
    args = ap.parse_args(argv)

    env = child_env(args.src.resolve() if args.src else None)
    temp = None if args.songs_dir else tempfile.TemporaryDirectory(prefix="long_song_")
    folder = args.songs_dir or Path(temp.name)
    try:
        t = time.perf_counter()
        songs = make_songs(folder, args.minutes)
        print(f"songs ready in {time.perf_counter() - t:.0f} s ({folder})", file=sys.stderr)
        rows = []
        for minutes, song in songs.items():
            out_bvh = folder / f"out_{minutes:g}.bvh"
            cmd = [sys.executable, "-c", "import sys; from dancesynth.entry import main; sys.exit(main())",
                   "dance", str(song), "-o", str(out_bvh), "--max-minutes", f"{minutes + 1:g}", "-q"]
            runs = [run_measured(cmd, env) for _ in range(max(1, args.dance_repeat))]
            out_bvh.unlink(missing_ok=True)
            analysis = run_json(ANALYSIS_CODE, [str(song), str(max(1, args.repeat))], env)
            music_min = analysis["duration_s"] / 60.0
            row = {"minutes": minutes,
                   "peak_rss_mb": max(r["peak_rss_mb"] for r in runs),
                   "wall_s": min(r["wall_s"] for r in runs),
                   "cpu_s": min(r["cpu_s"] for r in runs),
                   "decode_s": analysis["decode_s"],
                   "one_read_s": analysis["one_read_s"],
                   "decode_per_read": analysis["decode_s"] / max(analysis["one_read_s"], 1e-9),
                   "onset_s_per_min": analysis["onset_s"] / music_min,
                   "beat_tracking_s_per_min": analysis["beat_tracking_s"] / music_min}
            if args.stages:
                row["stages"] = run_json(STAGES_CODE, [str(song)], env)
            rows.append(row)
            print(f"{minutes:g} min done", file=sys.stderr)
    finally:
        if temp is not None:
            temp.cleanup()

    print(f"{'minutes':>7} {'peak RSS MB':>11} {'wall s':>7} {'CPU s':>6} {'decode s':>8} {'1 read s':>8} "
          f"{'dec/read':>8} {'beats s/min':>11}")
    for r in rows:
        print(f"{r['minutes']:>7g} {r['peak_rss_mb']:>11.0f} {r['wall_s']:>7.1f} {r['cpu_s']:>6.1f} "
              f"{r['decode_s']:>8.2f} {r['one_read_s']:>8.2f} {r['decode_per_read']:>8.2f} "
              f"{r['beat_tracking_s_per_min']:>11.4f}")
    for r in rows:
        if "stages" in r:
            print(f"\nstages, {r['minutes']:g} min: peak RSS MB (RSS before -> after)")
            for s in r["stages"]:
                print(f"  {s['stage']:<20} {s['peak_mb']:>7.0f}   "
                      f"({s['rss_before_mb']:.0f} -> {s['rss_after_mb']:.0f})")
    baseline = json.loads(args.baseline.read_text()) if args.baseline else None
    if baseline:
        print_comparison(baseline["rows"], rows)
    at_30 = [r for r in rows if r["minutes"] == 30]
    verdict = {"target_rss_mb": TARGET_RSS_MB,
               "peak_rss_mb_at_30min": at_30[0]["peak_rss_mb"] if at_30 else None,
               "rss_ok_at_30min": at_30[0]["peak_rss_mb"] <= TARGET_RSS_MB if at_30 else None}
    result = {"benchmark": "long_song", "command": " ".join([Path(sys.argv[0]).name, *(argv or sys.argv[1:])]),
              "src": str(args.src) if args.src else None, "machine": platform.platform(),
              "cpus": os.cpu_count(), "songs_from": [str(p.name) for p in music_files()],
              "rows": rows, "verdict": verdict}
    if baseline:
        result["baseline"] = {"src": baseline.get("src"), "command": baseline.get("command"), "rows": baseline["rows"]}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{args.name}.json").write_text(json.dumps(result, indent=2) + "\n")
    print(f"\nwrote {args.out / (args.name + '.json')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

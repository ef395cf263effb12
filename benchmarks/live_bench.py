"""Live streaming, measured: beat alignment against the offline dance, memory over an hour, latency.

    .venv/bin/python benchmarks/live_bench.py [--quick] [--only PART] [--segment 5] [--hindsight S] [--no-edge]
                                              [--out benchmarks/results]

- alignment: every bundled song streamed (as fast as it decodes, the same runtime and
  streaming beat tracker as a live stream) and danced offline; both dances measured
  against the same offline-tracked music beats (hit rate, Beat Align Score, Spearman).
- memory: an hour of music (the bundled songs, looped) piped into ``dancesynth stream -``
  faster than real time; its resident memory sampled every second. ``--quick``: 10 minutes.
- latency: a 20 s excerpt over a local HTTP server at real-time pace: when the first
  motion is ready, how long after each beat its move, and the per-segment processing time.
Prints the tables and writes ``live_bench.json``.
"""

from __future__ import annotations

import argparse
import functools
import http.server
import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
MUSIC = REPO / "src" / "dancesynth" / "data" / "music"
SONGS = sorted(MUSIC.glob("*.ogg"))
DANCESYNTH = [sys.executable, "-m", "dancesynth.cli"]
KEYS = ("hit_rate", "bas_music", "bas_motion", "intensity_spearman", "visible_accent_precision_x_chance")


HINDSIGHT = {}   # LiveConfig's hindsight_s and edge, when --hindsight and --no-edge set them


def _dance_both(song: Path, seed: int, segment_s: float):
    """The live dance (streamed as fast as it decodes, live tracker) and the offline one, with the live beats."""
    from dancesynth.api import dance
    from dancesynth.live.runtime import LiveConfig, run_live
    from dancesynth.live.sources import AudioSource
    from dancesynth.types import MotionClip

    clips, reports = [], []
    with AudioSource(str(song), realtime=False) as source:
        summary = run_live(source, clips.append, config=LiveConfig(segment_s=segment_s, seed=seed, **HINDSIGHT), realtime=False,
                           on_report=reports.append)
    live = MotionClip(clips[0].skeleton, clips[0].fps, np.concatenate([c.root_pos for c in clips]),
                      np.concatenate([c.local_rot for c in clips]))
    live.meta["style"] = summary["style"]
    heard = np.concatenate([r.beat_times_s for r in reports])
    return live, dance(song, segment_s=segment_s, seed=seed), heard[heard >= 0]


@functools.lru_cache(maxsize=None)
def _mocap(style: str):
    """The mocap reference of a style (its clips at 30 fps): how deep its accents are, for visible accents."""
    from dancesynth.bench.quality import at_fps
    from dancesynth.eval.evaluate import mocap_reference
    from dancesynth.motion.database import open_database

    s = open_database().styles[style]
    return mocap_reference([at_fps(s.clip(c), 30.0) for c in range(s.n_clips)], 30.0)


def alignment(songs, seeds=range(5), segment_s: float = 5.0, truth: dict | None = None) -> list[dict]:
    """Mean metrics over ``seeds`` (a dance's hit rate depends much on which clips its path uses).

    Both dances are measured against the same beats: ``truth[song]`` (exact beats of a
    generated song) if given, else the offline tracker's; loudness per interval of those
    beats. ``live_own_hit_rate``: the live dance against the beats the live tracker gave it.
    """
    from dancesynth.eval.evaluate import evaluate
    from dancesynth.io.audio import load_audio
    from dancesynth.music import analyze_music, beat_intensity_db

    rows = []
    for song in songs:
        music = analyze_music(path=song)
        beats = music.beat_times_s if truth is None else np.asarray(truth[song])
        loud = music.intensity_db if truth is None else beat_intensity_db(*load_audio(song), beats)
        scores = {"live": [], "offline": [], "own": []}
        for seed in seeds:
            live, offline, heard = _dance_both(song, seed, segment_s)
            for name, motion in (("live", live), ("offline", offline)):
                style = motion.meta.get("style") or motion.provenance.style
                m = evaluate(motion, music_beats_s=beats, music_loudness_db=loud, mocap=_mocap(style))
                scores[name].append([m[k] for k in KEYS])
            scores["own"].append(evaluate(live, music_beats_s=heard)["hit_rate"])
        row = {"song": song.stem[:28], "duration_s": round(music.duration_s, 1), "seeds": len(seeds),
               "live_own_hit_rate": float(np.mean(scores.pop("own")))}
        for name, values in scores.items():
            row.update({f"{name}_{k}": float(v) for k, v in zip(KEYS, np.mean(values, axis=0))})
        rows.append(row)
    return rows


def truth_alignment(quick: bool, seeds, segment_s: float = 5.0) -> list[dict]:
    """``alignment`` on the generated songs with exactly known beats (bench.groundtruth), against those beats."""
    from dancesynth.bench.groundtruth import ground_truth_set
    from dancesynth.motion.database import cache_dir

    songs = ground_truth_set(cache_dir() / "groundtruth", quick=quick)
    return alignment([s.audio_path for s in songs], seeds=seeds, segment_s=segment_s,
                     truth={s.audio_path: s.beats_s for s in songs})


def _rss_mb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


def memory(minutes: float) -> dict:
    """``dancesynth stream -`` fed ``minutes`` of looped music by ffmpeg as fast as it can; RSS every second."""
    concat = "".join(f"file '{s}'\n" for s in SONGS)
    with tempfile.TemporaryDirectory() as tmp:
        listing = Path(tmp) / "songs.txt"
        listing.write_text(concat)
        feed = subprocess.Popen(["ffmpeg", "-loglevel", "fatal", "-nostdin", "-stream_loop", "-1", "-f", "concat",
                                 "-safe", "0", "-i", str(listing), "-t", str(minutes * 60), "-ac", "1",
                                 "-ar", "22050", "-f", "wav", "pipe:1"], stdout=subprocess.PIPE)
        out = Path(tmp) / "live.bvh"
        t0 = time.perf_counter()
        proc = subprocess.Popen([*DANCESYNTH, "stream", "-", "-o", str(out), "--fast", "-q"], stdin=feed.stdout,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO)
        feed.stdout.close()
        samples = []
        while proc.poll() is None:
            rss = _rss_mb(proc.pid)
            if rss is not None:
                samples.append((time.perf_counter() - t0, rss))
            time.sleep(1.0)
        stdout, stderr = proc.communicate()
        feed.wait()
        wall = time.perf_counter() - t0
        size_mb = out.stat().st_size / 2**20 if out.exists() else 0.0
    if proc.returncode != 0:
        raise RuntimeError(f"stream failed: {stderr.strip()[-500:]}")
    t, rss = np.array(samples).T
    half = t >= t[-1] / 2
    slope = np.polyfit(t[half], rss[half], 1)[0] if half.sum() > 2 else 0.0  # MB per wall second
    wrote = re.search(r"\((\d+) frames at ([0-9.]+) fps\)", stdout)
    danced_s = int(wrote.group(1)) / float(wrote.group(2)) if wrote else 0.0
    return {"stream_minutes": minutes, "wall_s": round(wall, 1), "x_real_time": round(minutes * 60 / wall, 1),
            "rss_mb_at_10pct": round(float(np.interp(0.1 * t[-1], t, rss)), 1),
            "rss_mb_at_50pct": round(float(np.interp(0.5 * t[-1], t, rss)), 1),
            "rss_mb_at_end": round(float(rss[-1]), 1), "rss_mb_peak": round(float(rss.max()), 1),
            "rss_growth_mb_per_stream_hour_second_half": round(float(slope * wall / (minutes / 60)), 1),
            "bvh_mb": round(size_mb, 1), "danced_s": round(danced_s, 1), "summary": stdout.strip().splitlines()[-6:]}


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


def latency(seconds: float = 20.0, segment_s: float = 5.0) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        excerpt = Path(tmp) / "excerpt.ogg"
        subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-t", str(seconds), "-i",
                        str(MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg"), str(excerpt)], check=True)
        httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(_Quiet, directory=tmp))
        threading.Thread(target=httpd.serve_forever, daemon=True).start()
        try:
            proc = subprocess.run([*DANCESYNTH, "stream", f"http://127.0.0.1:{httpd.server_address[1]}/excerpt.ogg",
                                   "-o", str(Path(tmp) / "live.bvh"), "--segment-seconds", str(segment_s)],
                                  capture_output=True, text=True, cwd=REPO, timeout=seconds * 3 + 60)
        finally:
            httpd.shutdown()
            httpd.server_close()
    if proc.returncode != 0:
        raise RuntimeError(f"stream failed: {proc.stderr.strip()[-500:]}")
    steps = [float(m) for m in re.findall(r"step\s+([0-9.]+) ms", proc.stdout)]
    ready = float(re.search(r"first motion ready ([0-9.]+) s", proc.stdout).group(1))
    delay = re.search(r"move ready ([0-9.]+) s after the beat \(median\), at most ([0-9.]+) s", proc.stdout)
    return {"excerpt_s": seconds, "segment_s": segment_s, "first_motion_ready_s": ready,
            "target_s": 2.0, "beat_delay_s_median": float(delay.group(1)) if delay else None,
            "beat_delay_s_max": float(delay.group(2)) if delay else None,
            "beat_delay_target_s": segment_s, "step_ms_median": float(np.median(steps)),
            "step_ms_max": max(steps), "segments": len(steps), "late_segments": proc.stdout.count("LATE")}


def _alignment_table(title: str, rows: list[dict]) -> list[str]:
    lines = [title, ""]
    head = f"{'song':28}  {'s':>5}  " + "  ".join(f"{k[:10]:>10} live/off" for k in KEYS) + "  live/own beats"
    lines += [head, "-" * len(head)]
    cols = [f"{w}_{k}" for w in ("live", "offline") for k in KEYS] + ["live_own_hit_rate"]
    mean = {"song": "mean", "duration_s": float("nan"), **{c: float(np.mean([x[c] for x in rows])) for c in cols}}
    for r in rows + ([mean] if rows else []):
        lines.append(f"{r['song']:28}  {r['duration_s']:5.1f}  " + "  ".join(
            f"{r[f'live_{k}']:9.3f} /{r[f'offline_{k}']:6.3f}" for k in KEYS) + f"  {r['live_own_hit_rate']:14.3f}")
    return lines


def format_tables(result: dict) -> str:
    lines = []
    if result.get("alignment"):
        lines += _alignment_table("Beat alignment, bundled songs: streamed (live tracker) vs offline, against the "
                                  "offline tracker's beats", result["alignment"])
    if result.get("truth_alignment"):
        lines += [""] + _alignment_table("Beat alignment, generated songs: streamed vs offline, against the exact "
                                         "beats", result["truth_alignment"])
    if "memory" in result:
        m = result["memory"]
        lines += ["", f"Memory over a {m['stream_minutes']:g}-minute stream fed {m['x_real_time']}x faster than "
                      f"real time ({m['wall_s']} s)",
                  f"  RSS at 10% {m['rss_mb_at_10pct']} MB, 50% {m['rss_mb_at_50pct']} MB, end {m['rss_mb_at_end']} MB,"
                  f" peak {m['rss_mb_peak']} MB; growth over the second half "
                  f"{m['rss_growth_mb_per_stream_hour_second_half']} MB per stream hour; danced "
                  f"{m['danced_s'] / 60:.1f} min, BVH {m['bvh_mb']} MB"]
    if "latency" in result:
        a = result["latency"]
        lines += ["", f"Latency, {a['excerpt_s']:g} s over HTTP at real-time pace, {a['segment_s']:g} s segments",
                  f"  first motion ready {a['first_motion_ready_s']:.2f} s after the first audio "
                  f"(target {a['target_s']:.1f} s); a beat's move ready {a['beat_delay_s_median'] or 0:.2f} s after "
                  f"the beat (median), at most {a['beat_delay_s_max'] or 0:.2f} s (target: a segment, "
                  f"{a['beat_delay_target_s']:.1f} s); step median {a['step_ms_median']:.0f} ms, "
                  f"max {a['step_ms_max']:.0f} ms; late segments {a['late_segments']}"]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="two songs, a 10-minute stream")
    parser.add_argument("--only", choices=["alignment", "truth_alignment", "memory", "latency"], action="append")
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    parser.add_argument("--hindsight", type=float, help="how far back the live cuts take the beats the tracker is "
                        "sure of, s (default its latency)")
    parser.add_argument("--no-edge", action="store_true", help="dance only those, not its guess at the beats since "
                        "(moves then come up to the hindsight later)")
    parser.add_argument("--segment", type=float, default=5.0, help="segment length of the alignment runs, s")
    args = parser.parse_args()
    if args.hindsight is not None:
        HINDSIGHT["hindsight_s"] = args.hindsight
    if args.no_edge:
        HINDSIGHT["edge"] = False
    os.environ.setdefault("NUMBA_CACHE_DIR", str(REPO / ".cache" / "numba"))
    only = set(args.only or ["alignment", "truth_alignment", "memory", "latency"])
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / ("live_bench_quick.json" if args.quick else "live_bench.json")
    # With --only, the other parts of an earlier run are kept.
    result: dict = json.loads(path.read_text()) if args.only and path.is_file() else {}
    seeds = range(2 if args.quick else 5)
    parts = {"alignment": lambda: alignment(SONGS[:2] if args.quick else SONGS, seeds=seeds, segment_s=args.segment),
             "truth_alignment": lambda: truth_alignment(args.quick, range(2), args.segment),
             "memory": lambda: memory(10.0 if args.quick else 60.0), "latency": lambda: latency(segment_s=args.segment)}
    for name, part in parts.items():
        if name in only:
            result[name] = part()
            path.write_text(json.dumps(result, indent=1, default=float) + "\n")  # a later failure keeps this part
    print(format_tables(result))
    print(f"\nwrote {path}")


if __name__ == "__main__":
    main()

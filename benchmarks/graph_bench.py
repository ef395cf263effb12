"""Benchmark of the meta-motion-graph engine (Xu et al. Fig. 4 and beyond).

    python benchmarks/graph_bench.py [--quick] [--out benchmarks/results]

Prints one table per measurement and writes ``graph_bench.json``:
- graph size (N, bi-directional edges, mean in-degree D), build time and cache reload time per style;
- per-segment search time for segment lengths 2, 3, 4, 5, 10, 30 s and for the global DP, on the
  largest style with the beats and loudness of the bundled songs, and the fit t = a * D*N*K + b
  (K = beats in the segment = P*L of the paper);
- growth with the database replicated 1x, 2x, 5x, 10x: build time, N, D, search time per 5 s
  segment, peak memory (each scale in its own process);
- a 3-minute song to BVH through the command line, warm cache.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
MUSIC = REPO / "src" / "dancesynth" / "data" / "music"
SONGS = ["Kevin_MacLeod_-_Vibe_Ace.ogg", "Karissa_Hobbs_-_Lets_Go_Fishin.ogg",
         "Hungarian_Dance_number_5_-_Allegro_in_F_sharp_minor_(string_orchestra).ogg"]
SEGMENTS_S = [2, 3, 4, 5, 10, 30]


def replicate(style, times: int):
    """The style's clips repeated ``times`` times (a bigger database with the same content)."""
    if times == 1:
        return style
    n = style.n_frames
    return replace(
        style, name=f"{style.name}-x{times}", clip_names=style.clip_names * times,
        clip_sources=style.clip_sources * times,
        clip_starts=np.r_[np.concatenate([style.clip_starts[:-1] + i * n for i in range(times)]), n * times],
        local_rot=np.tile(style.local_rot, (times, 1, 1)), root_pos=np.tile(style.root_pos, (times, 1)),
        contacts=np.tile(style.contacts, (times, 1)), energy=np.tile(style.energy, times),
        beat_frames=np.concatenate([style.beat_frames + i * n for i in range(times)]),
        clip_tempo_bpm=np.tile(style.clip_tempo_bpm, times), fingerprint=f"{style.fingerprint}-x{times}")


def largest_style(db):
    return max(db.styles.values(), key=lambda s: len(s.beat_frames))


def song_features():
    from dancesynth.music import analyze_music

    return [analyze_music(path=MUSIC / s) for s in SONGS]


def segment_timings(engine, music_list, segment_s: float):
    """Search and render times of every segment when streaming each song."""
    from dancesynth.api import DanceConfig, synthesise
    from dancesynth.engines.beatgrid import beat_grid

    rows = []
    for m in music_list:
        grid = beat_grid(m)
        cfg = DanceConfig(segment_s=segment_s)
        segs, _ = synthesise(engine, grid, m.duration_s, cfg)
        rows += [(s.search_s, s.render_s, len(s.pieces)) for s in segs]
    return np.array(rows)


def global_timings(engine, music_list, excerpt_s: float | None):
    from dancesynth.engines.beatgrid import beat_grid

    rows = []
    for m in music_list:
        grid = beat_grid(m)
        times, inten = grid.times_s, grid.intensity_db
        if excerpt_s:
            k = int(np.searchsorted(times, excerpt_s))
            times, inten = times[:k + 1], inten[:k]
        end = min(excerpt_s or m.duration_s, times[-1])
        seg = engine.run_global(times, inten, end)
        rows.append((seg.search_s, seg.render_s, len(seg.pieces)))
    return np.array(rows)


def scale_worker(times: int) -> dict:
    """Run in a fresh process: build and use the graph of the largest style replicated ``times``x."""
    from dancesynth.engines.graph.engine import GraphEngine
    from dancesynth.engines.graph.meta_graph import build_graph
    from dancesynth.motion.database import open_database

    style = replicate(largest_style(open_database()), times)
    t = time.perf_counter()
    graph = build_graph(style)
    build_s = time.perf_counter() - t
    music = song_features()[:1]
    seg = segment_timings(GraphEngine(style, graph), music, 5.0)
    return {"times": times, "nodes": graph.n_nodes, "bi_edges": graph.n_bi_edges, "D": graph.mean_in_degree,
            "build_s": build_s, "search_ms_median": float(np.median(seg[:, 0]) * 1e3),
            "search_ms_max": float(seg[:, 0].max() * 1e3),
            "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0}


def three_minute_song(tmp: Path) -> Path:
    import soundfile as sf

    parts, sr = [], 44100
    for s in SONGS[:2]:
        y, sr = sf.read(MUSIC / s, dtype="float32")
        parts.append(y)
    y = np.concatenate(parts)[: 180 * sr]
    path = tmp / "three_minutes.wav"
    sf.write(path, y, sr)
    return path


def cli_wall_time(song: Path, out: Path, runs: int) -> list[float]:
    cmd = [sys.executable, "-m", "dancesynth.cli", "dance", str(song), "-o", str(out), "-q"]
    subprocess.run(cmd, check=True)  # warm the graph and numba caches
    walls = []
    for _ in range(runs):
        t = time.perf_counter()
        subprocess.run(cmd, check=True)
        walls.append(time.perf_counter() - t)
    return walls


def table(title: str, header: list[str], rows: list[list]) -> str:
    widths = [max(len(str(h)), *(len(str(r[i])) for r in rows)) for i, h in enumerate(header)]
    line = lambda cells: "  ".join(str(c).rjust(w) for c, w in zip(cells, widths))  # noqa: E731
    return "\n".join([f"\n{title}", line(header), line(["-" * w for w in widths])] + [line(r) for r in rows])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer songs and scales, one CLI run")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    ap.add_argument("--scale-worker", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.scale_worker:
        print(json.dumps(scale_worker(args.scale_worker)))
        return 0

    from dancesynth.engines.graph.cache import load_graph
    from dancesynth.engines.graph.engine import GraphEngine
    from dancesynth.engines.graph.meta_graph import build_graph
    from dancesynth.motion.database import open_database

    result = {"machine": {"cpus": os.cpu_count(), "python": platform.python_version(),
                          "processor": platform.processor() or platform.machine()}}
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["DANCESYNTH_CACHE"] = str(Path(tmp) / "cache")
        db = open_database()

        rows, graphs = [], {}
        for style in sorted(db.styles.values(), key=lambda s: s.name):
            t = time.perf_counter()
            graphs[style.name] = g = build_graph(style)
            build_s = time.perf_counter() - t
            load_graph(style)  # writes the cache
            t = time.perf_counter()
            _, cached = load_graph(style)
            reload_s = time.perf_counter() - t
            assert cached
            rows.append({"style": style.name, "nodes": g.n_nodes, "bi_edges": g.n_bi_edges,
                         "D": round(g.mean_in_degree, 2), "build_s": round(build_s, 3),
                         "reload_ms": round(reload_s * 1e3, 1)})
        result["graphs"] = rows
        result["graph_build_total_s"] = sum(r["build_s"] for r in rows)
        print(table("Graphs of the bundled database (THS=3.0, THR=1.5)", list(rows[0]),
                    [list(r.values()) for r in rows]))

        style = largest_style(db)
        graph = graphs[style.name]
        engine = GraphEngine(style, graph)
        music = song_features()[: 1 if args.quick else 3]
        fig4, fit_x, fit_y = [], [], []
        runs = [(seg_s, segment_timings(engine, music, seg_s)) for seg_s in SEGMENTS_S]
        runs += [(label, global_timings(engine, music, excerpt))
                 for label, excerpt in (("global 30 s", 30.0), ("global song", None))]
        for label, t in runs:
            fig4.append({"segment_s": label, "segments": len(t), "beats_mean": round(float(t[:, 2].mean()), 1),
                         "search_ms_median": round(float(np.median(t[:, 0]) * 1e3), 3),
                         "search_ms_max": round(float(t[:, 0].max() * 1e3), 3),
                         "render_ms_median": round(float(np.median(t[:, 1]) * 1e3), 2)})
            fit_x += list(graph.mean_in_degree * graph.n_nodes * t[:, 2])
            fit_y += list(t[:, 0])
        x, y = np.array(fit_x), np.array(fit_y)
        a, b = np.linalg.lstsq(np.c_[x, np.ones_like(x)], y, rcond=None)[0]
        r2 = 1 - np.sum((y - (a * x + b)) ** 2) / np.sum((y - y.mean()) ** 2)
        result["fig4"] = {"style": style.name, "nodes": graph.n_nodes, "D": graph.mean_in_degree,
                          "songs": SONGS[: len(music)], "rows": fig4,
                          "fit": {"a_ns_per_DNK": a * 1e9, "b_ms": b * 1e3, "r2": r2}}
        print(table(f"Search time per segment on '{style.name}' (N={graph.n_nodes}, D={graph.mean_in_degree:.2f})",
                    list(fig4[0]), [list(r.values()) for r in fig4]))
        print(f"fit: t = {a * 1e9:.2f} ns * D*N*K + {b * 1e3:.3f} ms   (R^2 = {r2:.3f})")

        scales = []
        for times in ([1, 10] if args.quick else [1, 2, 5, 10]):
            proc = subprocess.run([sys.executable, __file__, "--scale-worker", str(times)], capture_output=True,
                                  text=True, check=True, env=os.environ)
            scales.append(json.loads(proc.stdout.strip().splitlines()[-1]))
        result["scaling"] = scales
        print(table(f"Growth with the database ('{style.name}' replicated)", list(scales[0]),
                    [[round(v, 2) if isinstance(v, float) else v for v in r.values()] for r in scales]))

        song = three_minute_song(Path(tmp))
        walls = cli_wall_time(song, Path(tmp) / "out.bvh", 1 if args.quick else 3)
        result["three_minute_song_wall_s"] = {"runs": walls, "median": float(np.median(walls))}
        print(f"\n3-minute song to BVH (dancesynth dance, warm cache): median {np.median(walls):.2f} s over "
              f"{len(walls)} run(s)")

    targets = {
        "segment_5s_search_ms_median<=2": next(r for r in fig4 if r["segment_s"] == 5)["search_ms_median"] <= 2.0,
        "segment_5s_search_ms_median_10x<=20": scales[-1]["search_ms_median"] <= 20.0,
        "graph_build_default_s<=10": result["graph_build_total_s"] <= 10.0,
        "graph_reload_s<=0.5": max(r["reload_ms"] for r in rows) <= 500.0,
        "three_minute_song_s<=5": result["three_minute_song_wall_s"]["median"] <= 5.0,
        "peak_memory_default_mb<=1024": scales[0]["peak_rss_mb"] <= 1024.0,
    }
    result["targets_met"] = targets
    print("\ntargets: " + ", ".join(f"{k}: {'yes' if v else 'NO'}" for k, v in targets.items()))
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "graph_bench.json").write_text(json.dumps(result, indent=1, default=float))
    print(f"wrote {args.out / 'graph_bench.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

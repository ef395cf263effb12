"""Speed benchmarks: Xu et al.'s Fig. 4, growth with the database, the pipeline end to end.

- ``fig4``: synthesis time per segment for segment lengths L, streaming (one
  ``GraphEngine.step``: the per-segment DP of eq. 7-9, then rendering) against the
  global DP over the same length of music, on the largest bundled style and the
  bundled song; and the regression of the search time on D*N*P*L as in the paper
  (D = mean in-degree, N = nodes, P = tempo in beats/s, L = segment length in s, so
  P*L = K, the beat intervals of the segment).
- ``scaling``: build time, search time and peak memory with the largest style
  replicated 1x..10x, each size in a fresh process.
- ``pipeline``: every bundled graph built and reloaded from the cache, and a
  3-minute song to BVH (analysis, synthesis, writing) in a fresh process.
- ``segment_costs`` and ``replicated_search`` (``benchmarks/segment_speed.py``): one streaming
  segment split into search, stitching, foot lock and BVH text, and the search on the largest
  style replicated 10x.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from .common import BenchConfig, MUSIC_DIR, Progress, largest_style, linear_fit, table

# ---------------------------------------------------------------------------------------------
# 1. Fig. 4


def fig4(cfg: BenchConfig, db, music, progress: Progress | None = None) -> dict:
    from ..api import DanceConfig, segment_bounds, synthesise
    from ..engines.beatgrid import beat_grid
    from ..engines.graph.cache import load_graph
    from ..engines.graph.engine import GraphEngine

    style = largest_style(db).material  # what the product dances: mirrored takes too
    graph, _ = load_graph(style)
    engine = GraphEngine(style, graph)
    grid = beat_grid(music)
    d, n = graph.mean_in_degree, graph.n_nodes
    lengths = [float(s) for s in cfg.segments_s]
    span = float(grid.times_s[-1] - grid.times_s[0])
    if cfg.whole_song_row:
        lengths.append(span)
    labels = ["song" if cfg.whole_song_row and i == len(lengths) - 1 else x for i, x in enumerate(lengths)]
    bounds = [segment_bounds(grid.times_s, x) for x in lengths]
    full = [list(range(len(b) - 1)) if len(b) > 1 else [0] for b in bounds]  # the short last one is left out
    # times[row][measure] is (repeats, segments). Repeats go round all lengths in turn, so a
    # burst of load from another process spreads over the rows instead of spoiling one.
    keys = ("search", "step", "g_search", "g_total")
    times = [{key: np.zeros((cfg.repeats, len(f))) for key in keys} for f in full]
    for r in range(cfg.repeats):
        if progress:
            progress(f"fig4: repeat {r + 1}/{cfg.repeats} over {len(lengths)} segment lengths")
        for i, length in enumerate(lengths):
            segs, stats = synthesise(engine, grid, music.duration_s, DanceConfig(segment_s=length))
            times[i]["search"][r] = [segs[j].search_s for j in full[i]]
            times[i]["step"][r] = [stats["step_s"][j] for j in full[i]]
            for c, j in enumerate(full[i]):
                b, e = bounds[i][j]
                window = grid.times_s[b:e + 1] - grid.times_s[b]  # the window as a song of its own
                t = time.perf_counter()
                out = engine.run_global(window, grid.intensity_db[b:e], float(window[-1]))
                times[i]["g_total"][r, c] = time.perf_counter() - t
                times[i]["g_search"][r, c] = out.search_s
    rows, points = [], {"streaming": ([], [], []), "global": ([], [], [])}  # D*N*P*L, t, D*N*P
    for i, label in enumerate(labels):
        k = np.array([bounds[i][j][1] - bounds[i][j][0] for j in full[i]], dtype=float)
        dur = np.array([grid.times_s[bounds[i][j][1]] - grid.times_s[bounds[i][j][0]] for j in full[i]])
        for name, key in (("streaming", "search"), ("global", "g_search")):
            points[name][0].extend(d * n * k)          # D*N*P*L with P*L = K
            points[name][1].extend(np.median(times[i][key], axis=0))
            points[name][2].extend(d * n * k / dur)    # D*N*P
        rows.append({
            "segment_s": label, "segments": len(full[i]), "beats_mean": float(k.mean()),
            "length_s_mean": float(dur.mean()),
            "stream_search_ms": _ms(times[i]["search"]), "stream_step_ms": _ms(times[i]["step"]),
            "global_search_ms": _ms(times[i]["g_search"]), "global_total_ms": _ms(times[i]["g_total"]),
            "step_fraction_of_segment": float(np.median(times[i]["step"]) / dur.mean()),
        })
    fits = {name: _scaled_fit(*points[name][:2]) for name in points}
    return {
        "style": style.name, "song": music.source and Path(music.source).name, "song_s": music.duration_s,
        "tempo_bpm": music.tempo_bpm, "N": n, "D": d, "repeats": cfg.repeats, "rows": rows, "fit": fits,
        "paper_form": _paper_form(*(np.asarray(v, float) for v in points["streaming"])),
        "definitions": "D = mean in-degree (steps into a node: a mono edge, or a jump plus its mono edge), "
                       "N = nodes (beat frames), P = tempo (beats/s), L = segment length (s); P*L = K, the "
                       "beat intervals of a segment; time = the DP search alone (eq. 7-9), median over repeats",
    }


def _ms(samples: np.ndarray) -> dict:
    """Median over repeats per segment, then median and max over segments, in ms."""
    per_segment = np.median(samples, axis=0) * 1e3
    return {"median": float(np.median(per_segment)), "max": float(per_segment.max())}


def _scaled_fit(x, y) -> dict:
    """t = slope * D*N*P*L + intercept, reported in ns per unit and ms."""
    f = linear_fit(x, y)
    if f["slope"] is not None:
        f = {**f, "slope_ns": f.pop("slope") * 1e9, "intercept_ms": f.pop("intercept") * 1e3}
    else:
        f = {**f, "slope_ns": None, "intercept_ms": None}
        f.pop("slope")
        f.pop("intercept")
    return f


def _paper_form(x: np.ndarray, y: np.ndarray, dnp: np.ndarray) -> dict:
    """The paper's t = D*N*P*(a*L + b), i.e. t = a*D*N*P*L + b*D*N*P (no intercept); R^2 about the mean."""
    if len(x) < 2 or np.linalg.matrix_rank(np.c_[x, dnp]) < 2:
        return {"a_ns": None, "b_ns": None, "r2": None}
    a, b = np.linalg.lstsq(np.c_[x, dnp], y, rcond=None)[0]
    ss_tot = float(np.sum((y - y.mean()) ** 2))
    r2 = 1.0 - float(np.sum((y - a * x - b * dnp) ** 2)) / ss_tot if ss_tot > 0 else 1.0
    return {"a_ns": float(a * 1e9), "b_ns": float(b * 1e9), "r2": float(r2)}


def format_fig4(s: dict) -> str:
    rows = [[r["segment_s"], r["segments"], r["beats_mean"], r["stream_search_ms"]["median"],
             r["stream_search_ms"]["max"], r["stream_step_ms"]["median"], 100 * r["step_fraction_of_segment"],
             r["global_search_ms"]["median"], r["global_total_ms"]["median"]] for r in s["rows"]]
    lines = [table(
        f"Synthesis time per segment (Xu et al. Fig. 4): style {s['style']} (N = {s['N']}, D = {s['D']:.2f}), "
        f"song {s['song']} ({s['song_s']:.1f} s, {s['tempo_bpm']:.0f} bpm), median of {s['repeats']} repeats",
        ["L (s)", "segments", "K beats", "stream search ms", "max ms", "stream step ms", "% of L",
         "global search ms", "global total ms"], rows, [1, 0, 1, 3, 3, 2, 2, 3, 2],
        notes=["stream step = one GraphEngine.step (DP search + rendering + foot locking); global = the "
               "whole-song DP over a window of the same length, searched and rendered",
               "'song' = the whole song as one segment; the short last segment of each length is left out"])]
    for name in ("streaming", "global"):
        f = s["fit"][name]
        if f["slope_ns"] is None:
            lines.append(f"fit ({name} search): not enough distinct segment lengths")
            continue
        lines.append(f"fit ({name} search): t = {f['slope_ns']:.2f} ns * D*N*P*L + {f['intercept_ms']:.3f} ms   "
                     f"R^2 = {f['r2']:.3f}  ({f['points']} segments)")
    p = s["paper_form"]
    if p["a_ns"] is not None:
        lines.append(f"paper's form (streaming): t = D*N*P*({p['a_ns']:.2f} ns * L {'-' if p['b_ns'] < 0 else '+'} "
                     f"{abs(p['b_ns']):.2f} ns)   "
                     f"R^2 = {p['r2']:.3f}   (paper, 2.83 GHz Core 2: t = D*N*P*(0.0030 L - 0.0003))")
    lines.append(f"  {s['definitions']}")
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------
# 2. Scaling


def replicate(style, times: int):
    """The style's clips repeated ``times`` times: a bigger database with the same content."""
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
        clip_tempo_bpm=np.tile(style.clip_tempo_bpm, times), fingerprint=f"{style.fingerprint}-x{times}",
        clip_licences=style.clip_licences * times, mirror=False, n_mirrored=0)


def _reset_peak() -> bool:
    """Reset this process's peak resident set (Linux >= 4.0); False where it cannot be."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def _peak_mb() -> float:
    """Peak resident set since the last reset (or since the process started), MB."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def scale_worker(times: int, beat_times_s: list, intensity_db: list, duration_s: float, segment_s: float) -> dict:
    """In a fresh process: build the largest style replicated ``times`` x and dance the given beats on it."""
    from ..api import DanceConfig, synthesise
    from ..engines.beatgrid import beat_grid
    from ..engines.graph.engine import GraphEngine
    from ..engines.graph.meta_graph import build_graph
    from ..motion.database import open_database
    from ..types import MusicFeatures

    music = MusicFeatures(duration_s, np.array(beat_times_s), np.array(intensity_db), 0.0)
    style = replicate(largest_style(open_database()).material, times)
    out = {"times": times, "base_mb": _peak_mb()}
    exact = _reset_peak()
    t = time.perf_counter()
    graph = build_graph(style)
    out.update(build_s=time.perf_counter() - t, build_peak_mb=_peak_mb(), nodes=graph.n_nodes,
               bi_edges=graph.n_bi_edges, D=graph.mean_in_degree)
    engine = GraphEngine(style, graph)
    grid = beat_grid(music)
    exact &= _reset_peak()
    t = time.perf_counter()
    segs, stats = synthesise(engine, grid, duration_s, DanceConfig(segment_s=segment_s))
    stream_s = time.perf_counter() - t
    search = np.array([s.search_s for s in segs]) * 1e3
    out.update(stream_peak_mb=_peak_mb(), stream_song_s=stream_s, search_ms_median=float(np.median(search)),
               search_ms_max=float(search.max()), step_ms_median=float(np.median(stats["step_s"]) * 1e3),
               segments=len(segs))
    exact &= _reset_peak()
    t = time.perf_counter()
    whole = engine.run_global(grid.times_s, grid.intensity_db, duration_s)
    out.update(global_song_s=time.perf_counter() - t, global_search_s=whole.search_s, global_peak_mb=_peak_mb(),
               peak_per_phase=bool(exact))
    return out


def _worker_main() -> None:
    """Entry point of a scaling subprocess: JSON arguments on stdin, JSON result on stdout."""
    kwargs = json.loads(sys.stdin.read())
    sys.stdout.write(json.dumps(scale_worker(**kwargs)) + "\n")


def subprocess_env() -> dict:
    """The environment for benchmark subprocesses: this dancesynth first on the path."""
    env = dict(os.environ)
    src = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = os.pathsep.join([src] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    return env


def scaling(cfg: BenchConfig, db, music, progress: Progress | None = None) -> dict:
    style = largest_style(db)
    rows = []
    args = {"beat_times_s": music.beat_times_s.tolist(), "intensity_db": music.intensity_db.tolist(),
            "duration_s": music.duration_s, "segment_s": cfg.scale_segment_s}
    for times in cfg.scales:
        if progress:
            progress(f"scaling: database x{times} in a fresh process")
        cmd = [sys.executable, "-c", "from dancesynth.bench.speed import _worker_main; _worker_main()"]
        done = subprocess.run(cmd, input=json.dumps({"times": times, **args}), capture_output=True, text=True,
                              env=subprocess_env(), timeout=cfg.scale_timeout_s)
        if done.returncode != 0:
            raise RuntimeError(f"scaling worker x{times} failed: {done.stderr.strip()[-500:]}")
        rows.append(json.loads(done.stdout.strip().splitlines()[-1]))
    return {"style": style.name, "song": Path(music.source).name if music.source else "",
            "song_s": music.duration_s, "segment_s": cfg.scale_segment_s, "rows": rows,
            "peak_method": "VmHWM reset per phase" if all(r["peak_per_phase"] for r in rows)
            else "process peak (ru_maxrss)"}


def format_scaling(s: dict) -> str:
    rows = [[f"{r['times']}x", r["nodes"], r["D"], r["build_s"], r["build_peak_mb"], r["search_ms_median"],
             r["search_ms_max"], r["step_ms_median"], r["stream_song_s"], r["stream_peak_mb"], r["global_search_s"],
             r["global_song_s"], r["global_peak_mb"]] for r in s["rows"]]
    return table(
        f"Growth with the database: style {s['style']} replicated, song {s['song']} ({s['song_s']:.1f} s), "
        f"{s['segment_s']:g} s segments",
        ["size", "N", "D", "build s", "build MB", "search ms", "max ms", "step ms", "stream song s", "stream MB",
         "global search s", "global song s", "global MB"], rows, [0, 0, 2, 2, 0, 3, 3, 2, 2, 0, 3, 2, 0],
        notes=[f"each size in a fresh process; MB = peak resident memory of the phase ({s['peak_method']}), "
               "the database and graph included",
               "search/step ms = per streaming segment (median, max); stream song s = all segments; global = "
               "one DP over the whole song, search alone and with rendering"])


# ---------------------------------------------------------------------------------------------
# Per-segment cost, phase by phase (benchmarks/segment_speed.py)

SEGMENT_PHASES = ("search", "stitch", "foot_lock", "step", "bvh_text", "total")


def segment_costs(style, graph, music, *, segment_s: float = 5.0, repeats: int = 7,
                  progress: Progress | None = None) -> dict:
    """What one streaming segment costs, phase by phase: the path search, stitching and foot lock
    (with the step's own bookkeeping, one ``GraphEngine.step``), and the BVH text of the segment's
    frames (``format_bvh``).

    Each repeat dances the whole song with a fresh engine, so nothing one repeat computed helps
    the next (a new song's beat lengths are new too). Per segment the fastest repeat counts (the
    one least disturbed by other processes); the result gives the median and max over segments, in
    ms, and the CPU time per segment of the fastest whole repeat.
    """
    from ..api import DanceConfig, synthesise
    from ..engines.beatgrid import beat_grid
    from ..engines.graph.engine import GraphEngine
    from ..io.bvh_writer import format_bvh
    from ..types import MotionClip

    grid = beat_grid(music)
    per_repeat, cpu = [], []
    for r in range(repeats):
        if progress:
            progress(f"segment costs: repeat {r + 1}/{repeats} ({style.name})")
        engine = GraphEngine(style, graph)
        engine.steps  # the graph's step costs are built once per engine, not per segment
        c = time.process_time()
        segs, stats = synthesise(engine, grid, music.duration_s, DanceConfig(segment_s=segment_s))
        text_s = []
        for seg in segs:
            t = time.perf_counter()
            format_bvh(MotionClip(style.skeleton, engine.fps, seg.root_pos, seg.local_rot))
            text_s.append(time.perf_counter() - t)
        cpu.append((time.process_time() - c) / len(segs))
        search = np.array([x.search_s for x in segs])
        lock = np.array([x.foot_lock_s for x in segs])
        stitch = np.array([x.render_s for x in segs]) - lock
        per_repeat.append({"search": search, "stitch": stitch, "foot_lock": lock, "step": np.array(stats["step_s"]),
                           "bvh_text": np.array(text_s)})
    phases = {}
    for name in SEGMENT_PHASES:
        t = (np.stack([r["step"] + r["bvh_text"] for r in per_repeat]) if name == "total"
             else np.stack([r[name] for r in per_repeat]))
        best = t.min(axis=0) * 1e3
        phases[name] = {"median": float(np.median(best)), "max": float(best.max())}
    return {"style": style.name, "N": graph.n_nodes, "D": graph.mean_in_degree, "segment_s": segment_s,
            "segments": len(per_repeat[0]["search"]), "repeats": repeats, "phases_ms": phases,
            "cpu_ms_per_segment": float(min(cpu) * 1e3)}


def replicated_search(db, music, *, times: int = 10, segment_s: float = 5.0, repeats: int = 3,
                      progress: Progress | None = None) -> dict:
    """Search time per streaming segment on the largest style replicated ``times`` x (as in ``scaling``,
    but in this process with the graph from the cache, and a fresh engine per repeat)."""
    from ..api import DanceConfig, synthesise
    from ..engines.beatgrid import beat_grid
    from ..engines.graph.cache import load_graph
    from ..engines.graph.engine import GraphEngine

    style = replicate(largest_style(db).material, times)
    if progress:
        progress(f"replicated search: graph of {style.name} (built once, then from the cache)")
    graph, _ = load_graph(style)
    grid = beat_grid(music)
    runs = []
    for r in range(repeats):
        if progress:
            progress(f"replicated search: repeat {r + 1}/{repeats}")
        engine = GraphEngine(style, graph)
        engine.steps  # built once per engine, not per segment
        segs, _ = synthesise(engine, grid, music.duration_s, DanceConfig(segment_s=segment_s))
        runs.append([x.search_s for x in segs])
    best = np.min(runs, axis=0) * 1e3
    return {"style": style.name, "times": times, "N": graph.n_nodes, "D": graph.mean_in_degree,
            "segment_s": segment_s, "segments": len(best), "repeats": repeats,
            "search_ms": {"median": float(np.median(best)), "max": float(best.max())}}


# ---------------------------------------------------------------------------------------------
# Pipeline: graphs of the bundled database, a long song end to end


_END_TO_END = """
import sys, time
t = time.perf_counter()
import dancesynth
clip = dancesynth.dance(sys.argv[1])
dancesynth.write_bvh(sys.argv[2], clip)
print(time.perf_counter() - t, clip.n_frames)
"""


def pipeline(cfg: BenchConfig, db, progress: Progress | None = None) -> dict:
    from ..engines.graph.cache import load_graph
    from ..engines.graph.meta_graph import build_graph

    graphs = []
    with tempfile.TemporaryDirectory(prefix="dancesynth-bench-") as tmp:
        old = os.environ.get("DANCESYNTH_CACHE")
        os.environ["DANCESYNTH_CACHE"] = str(Path(tmp) / "cache")  # a cold cache of its own
        try:
            for style in sorted((s.material for s in db.styles.values()), key=lambda s: s.name):
                if progress:
                    progress(f"pipeline: graph of {style.name}")
                t = time.perf_counter()
                g = build_graph(style)
                build_s = time.perf_counter() - t
                load_graph(style)  # writes the cache entry
                t = time.perf_counter()
                _, cached = load_graph(style)
                graphs.append({"style": style.name, "nodes": g.n_nodes, "bi_edges": g.n_bi_edges,
                               "D": g.mean_in_degree, "build_s": build_s,
                               "reload_ms": (time.perf_counter() - t) * 1e3, "reloaded": cached})
        finally:
            if old is None:
                os.environ.pop("DANCESYNTH_CACHE", None)
            else:
                os.environ["DANCESYNTH_CACHE"] = old
        song = _long_song(Path(tmp), cfg.pipeline_song_s)
        if progress:
            progress(f"pipeline: a {cfg.pipeline_song_s:.0f} s song to BVH ({cfg.pipeline_runs} run(s) + warm-up)")
        cmd = [sys.executable, "-c", _END_TO_END, str(song), str(Path(tmp) / "dance.bvh")]
        walls, inner, frames = [], [], 0
        for i in range(cfg.pipeline_runs + 1):  # the first run warms the graph cache
            t = time.perf_counter()
            done = subprocess.run(cmd, capture_output=True, text=True, env=subprocess_env(), timeout=600)
            wall = time.perf_counter() - t
            if done.returncode != 0:
                raise RuntimeError(f"song to BVH failed: {done.stderr.strip()[-500:]}")
            if i:
                walls.append(wall)
                inner_s, frames = done.stdout.split()[-2:]
                inner.append(float(inner_s))
    return {"graphs": graphs, "graph_build_total_s": float(sum(g["build_s"] for g in graphs)),
            "song_s": cfg.pipeline_song_s, "frames": int(frames), "wall_s": walls,
            "wall_s_median": float(np.median(walls)), "in_process_s_median": float(np.median(inner))}


def _long_song(folder: Path, seconds: float) -> Path:
    """The bundled songs back to back, cut to ``seconds``, as a wav."""
    import soundfile as sf

    from ..io.audio import load_audio

    parts, total, sr = [], 0, 22050
    for path in sorted(MUSIC_DIR.glob("*.ogg"), key=lambda p: p.name):
        y, sr = load_audio(path, sr=sr)
        parts.append(y)
        total += len(y)
        if total >= seconds * sr:
            break
    y = np.concatenate(parts)[: int(seconds * sr)]
    path = folder / "long_song.wav"
    sf.write(path, y, sr)
    return path


def format_pipeline(s: dict) -> str:
    g = s["graphs"]
    rows = [[r["style"], r["nodes"], r["bi_edges"], r["D"], r["build_s"], r["reload_ms"]] for r in g]
    rows.append(["all", sum(r["nodes"] for r in g), sum(r["bi_edges"] for r in g), None,
                 s["graph_build_total_s"], None])
    return "\n".join([
        table("Graphs of the bundled database (THS = 3.0, THR = 1.5): build, and reload from the cache",
              ["style", "N", "bi edges", "D", "build s", "reload ms"], rows, [0, 0, 0, 2, 3, 1]),
        f"a {s['song_s']:.0f} s song to BVH in a fresh process (import, analysis, synthesis, write; warm cache): "
        f"median {s['wall_s_median']:.2f} s wall over {len(s['wall_s'])} run(s), "
        f"{s['in_process_s_median']:.2f} s after import, {s['frames']} frames"])

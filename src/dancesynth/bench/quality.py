"""Quality table: our dance against the global-DP baseline, a random walk and the raw mocap.

For every bundled song (or the ones configured) four rows are evaluated with
``dancesynth.eval.evaluate.evaluate``:

- ``streaming``: ``dancesynth.dance`` with the product defaults (the style it picks);
- ``global``: the same with ``engine="global"`` (the paper's offline baseline);
- ``random_walk``: a seeded uniform random walk on the same style's graph, rendered
  by the same renderer (so it lands on the beats too): what the search adds;
- ``mocap``: the style's source clips themselves, evaluated one by one and averaged.
  The mocap has no music: its beat reference is the database's own motion beats
  (``Style.beat_frames`` in seconds), it has no loudness (intensity metrics are
  ``None``), no transitions and no time warp.

Every metric of ``evaluate`` is a column; the table shows the mean over songs.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .common import MUSIC_DIR, BenchConfig, Progress, load_song, table
from ..provenance import EngineRun, make_provenance
from ..types import MotionClip, MusicFeatures

ROWS = ("streaming", "global", "random_walk", "mocap")
TITLES = {"streaming": "streaming", "global": "global DP", "random_walk": "random walk", "mocap": "mocap*"}
LABELS = {"streaming": "our dance (streaming engine, product defaults)",
          "global": "the global-DP baseline (--engine global)",
          "random_walk": "a seeded uniform random walk on the same graph, same renderer",
          "mocap": "the raw mocap of the same style"}
MOCAP_NOTE = ("* mocap: the style's source clips, each evaluated alone at the dances' frame rate (against "
              "the style's other clips for the *mocap* ratios) and averaged; no music is paired with them, so "
              "their beat reference is the database's own motion beats (Style.beat_frames in seconds); no "
              "loudness, so intensity correlation does not apply; no transitions, no time warp (rate 1)")
TRANSITION_NOTE = ("transitions before 0 s (a jump on the beat the grid adds before the first frame) are left "
                   "out: evaluate() takes transitions inside the motion only")


def walk_dance(style, music: MusicFeatures, *, subdivide: int = 1, seed: int = 0, fps: float = 30.0,
               segment_s: float = 5.0, accent_timing: bool = True) -> MotionClip:
    """A random walk on ``style``'s graph danced to ``music``, rendered like ``dancesynth.dance``
    (``accent_timing`` as ``DanceConfig``'s)."""
    from ..api import DanceConfig, synthesise
    from ..engines.beatgrid import beat_grid
    from ..engines.graph.cache import load_graph
    from ..engines.graph.engine import EngineConfig
    from ..engines.graph.random_walk import OutSteps, RandomWalkEngine
    from ..engines.timing import plain_timing

    style = style.material  # the graph the product's engines walk
    graph, _ = load_graph(style)
    grid = beat_grid(music, subdivide=subdivide)
    render = EngineConfig() if accent_timing else plain_timing(EngineConfig())
    engine = RandomWalkEngine(style, graph, render, fps=fps)
    config = DanceConfig(segment_s=segment_s, fps=fps, seed=seed, accent_timing=accent_timing)
    segments, stats = synthesise(engine, grid, music.duration_s, config)
    dead_end = OutSteps.of(graph).count == 0  # where the walk restarted
    run = EngineRun(style=style.name, genre=style.genre, style_fingerprint=style.fingerprint, subdivide=subdivide,
                    grid_times_s=grid.times_s,
                    transition_times_s=np.concatenate([s.pieces.t0[s.pieces.jump] for s in segments]),
                    warp_rates=np.concatenate([s.warp_rates(style.fps) for s in segments]),
                    segment_times_s=stats["boundaries_s"], step_s=tuple(stats["step_s"]),
                    source_frames=np.concatenate([s.source_pos for s in segments]),
                    extra={"restarts": int(sum(np.sum(dead_end[s.path.nodes[:-1]]) for s in segments))})
    clip = MotionClip(style.skeleton, fps, np.concatenate([s.root_pos for s in segments]),
                      np.concatenate([s.local_rot for s in segments]),
                      contacts=np.concatenate([s.contacts for s in segments]))
    clip.provenance = make_provenance("random_walk", music.source, config, run, fps=fps, frames=clip.n_frames,
                                      timings={}, music=music, segment_s=segment_s)
    return clip


def _scores(evaluate, clip: MotionClip, music: MusicFeatures, mocap) -> dict:
    jumps = np.asarray(clip.provenance.transition_times_s, dtype=float)
    jumps = jumps[(jumps >= 0) & (jumps <= clip.duration_s)]
    return evaluate(clip, music_beats_s=music.beat_times_s, music_loudness_db=music.intensity_db,
                    transitions_s=jumps, warp_rates=clip.provenance.warp_rates, mocap=mocap)


def at_fps(clip: MotionClip, fps: float) -> MotionClip:
    """A mocap clip at the dances' frame rate (jumps and jerk depend on it); its beats stay in seconds."""
    from ..motion.resample import resample_clip_arrays

    if abs(clip.fps - fps) < 1e-6 * fps:
        return clip
    local_rot, root_pos, contacts = resample_clip_arrays(clip.local_rot, clip.root_pos, clip.contacts, clip.fps, fps)
    meta = {**clip.meta, "beat_times_s": np.asarray(clip.meta["beat_frames"], dtype=float) / clip.fps}
    return MotionClip(clip.skeleton, fps, root_pos, local_rot, contacts=contacts, meta=meta)


def mocap_scores(evaluate, clips: list, max_clips: int | None = None) -> dict:
    """Each of ``clips`` (a style's) against its own motion beats; the mean over clips, and each clip's scores."""
    per_clip = []
    chosen = range(len(clips))
    if max_clips and max_clips < len(clips):  # evenly spread over the style
        chosen = np.unique(np.linspace(0, len(clips) - 1, max_clips).round().astype(int))
    for i in chosen:
        clip = clips[i]
        beats_s = clip.meta.get("beat_times_s")
        if beats_s is None:
            beats_s = np.asarray(clip.meta["beat_frames"], dtype=float) / clip.fps
        others = [c for j, c in enumerate(clips) if j != i] or None  # judged against the rest of the style
        per_clip.append(evaluate(clip, music_beats_s=beats_s, music_loudness_db=None,
                                 transitions_s=np.zeros(0), warp_rates=np.ones(max(len(beats_s) - 1, 0)),
                                 mocap=others))
    return {"mean": mean_scores(per_clip), "clips": len(per_clip), "of": len(clips),
            "clip_names": [clips[i].meta.get("name", str(i)) for i in chosen], "per_clip": per_clip}


def mean_scores(rows: list[dict]) -> dict:
    """Metric by metric, the mean of the values that are not ``None``."""
    keys = list(dict.fromkeys(k for r in rows for k in r))
    out = {}
    for k in keys:
        vals = [float(r[k]) for r in rows if r.get(k) is not None and np.isfinite(float(r[k]))]
        out[k] = float(np.mean(vals)) if vals else None
    return out


def quality(cfg: BenchConfig, db, progress: Progress | None = None) -> dict:
    from ..api import dance
    from ..eval.evaluate import METRICS, evaluate

    songs = cfg.quality_songs or tuple(sorted(p.name for p in MUSIC_DIR.glob("*.ogg")))
    per_song, mocap_by_style, clips_by_style = [], {}, {}
    for i, song in enumerate(songs):
        if progress:
            progress(f"quality: song {i + 1}/{len(songs)}: {Path(song).name}")
        music = load_song(song, cfg.quality_max_s)
        timings = {}
        t = time.perf_counter()
        stream = dance(music, database=db)
        timings["streaming_s"] = time.perf_counter() - t
        t = time.perf_counter()
        whole = dance(music, database=db, engine="global")
        timings["global_s"] = time.perf_counter() - t
        style = db.styles[stream.provenance.style]
        t = time.perf_counter()
        walk = walk_dance(style, music, subdivide=stream.provenance.summary["subdivide"], seed=cfg.seed,
                          fps=stream.fps, segment_s=stream.provenance.summary["segment_s"])
        timings["random_walk_s"] = time.perf_counter() - t
        if (style.name, stream.fps) not in clips_by_style:
            clips_by_style[(style.name, stream.fps)] = [at_fps(style.clip(c), stream.fps)
                                                        for c in range(style.n_clips)]
        clips = clips_by_style[(style.name, stream.fps)]
        t = time.perf_counter()
        scores = {name: _scores(evaluate, clip, music, clips)
                  for name, clip in (("streaming", stream), ("global", whole), ("random_walk", walk))}
        if style.name not in mocap_by_style:
            if progress:
                progress(f"quality: raw mocap of {style.name} ({style.n_clips} clips)")
            mocap_by_style[style.name] = mocap_scores(evaluate, clips, cfg.mocap_max_clips)
        scores["mocap"] = mocap_by_style[style.name]["mean"]
        timings["evaluate_s"] = time.perf_counter() - t
        per_song.append({"song": Path(song).name, "duration_s": music.duration_s, "tempo_bpm": music.tempo_bpm,
                         "style": style.name, "transitions": {n: int(len(c.provenance.transition_times_s))
                                                               for n, c in (("streaming", stream),
                                                                            ("global", whole),
                                                                            ("random_walk", walk))},
                         "random_walk_restarts": walk.provenance.summary["restarts"],
                         "scores": scores, "timings_s": timings})
    metrics = list(METRICS)
    mean = {row: mean_scores([s["scores"][row] for s in per_song]) for row in ROWS}
    mean = {row: {m: mean[row].get(m) for m in metrics} for row in ROWS}
    return {"metrics": metrics, "rows": list(ROWS), "labels": dict(LABELS), "songs": per_song, "mean": mean,
            "mocap": {name: {k: v[k] for k in ("clips", "of", "clip_names", "mean")}
                      for name, v in mocap_by_style.items()},
            "notes": [MOCAP_NOTE, TRANSITION_NOTE]}


def format_quality(s: dict) -> str:
    """The metrics (rows, grouped as ``evaluate.METRICS``) of the four dances (columns), mean over songs."""
    columns = {TITLES[r]: s["mean"][r] for r in s["rows"]}
    try:
        from ..eval.evaluate import format_table
    except ImportError:  # formatting a result made elsewhere: a plain layout
        body = table("", ["metric"] + list(columns),
                     [[m] + [c.get(m) for c in columns.values()] for m in s["metrics"]], [0] + [3] * len(columns))
    else:
        body = format_table(columns)
    songs = "; ".join(f"{x['song']} ({x['duration_s']:.0f} s, style {x['style']}, walk restarts "
                      f"{x['random_walk_restarts']})" for x in s["songs"])
    mocap = ", ".join(f"{name}: {v['clips']} of {v['of']} clips" for name, v in s["mocap"].items())
    notes = [f"mean over {len(s['songs'])} song(s): {songs}",
             f"columns: {'; '.join(f'{TITLES[r]} = {LABELS[r]}' for r in s['rows'])}",
             f"raw mocap evaluated: {mocap}"] + list(s["notes"])
    return "\n".join(["Quality on the bundled music", body] + [f"  {n}" for n in notes])

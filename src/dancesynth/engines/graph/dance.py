"""The meta-motion-graph engines' entry under the engine protocol: choose a style and level, cut
the beat grid into segments (or take it whole for the global DP), search and render each.

``config`` is the ``api.DanceConfig`` (``engines.protocol``); its ``render`` is this engine's
``EngineConfig`` and its ``graph`` the ``GraphConfig``.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from ...eval.metre import dances_in_three
from ...motion.database import MotionDatabase
from ...provenance import EngineRun
from ...types import MotionClip, MusicFeatures
from ..beatgrid import METRE_SHARE, BeatGrid, StyleFit, beat_grid, fit_styles, fit_summary, genre_preference
from ..form import form_plan
from ..protocol import Progress
from ..timing import plain_timing
from .cache import load_graph
from .engine import GraphEngine, MusicSegment, SegmentFrames


def dance(music: MusicFeatures, db: MotionDatabase, config, timings: dict,
          progress: Progress | None = None) -> tuple[MotionClip, EngineRun]:
    """The meta-motion-graph engines (streaming, its signature variant, global) under the engine
    protocol (``engines.protocol``).

    The style and metrical level are those that warp the beat pieces least (engines/beatgrid.py).
    A song in three is danced in three where the database allows it: when the first style's
    dance does not clearly repeat in threes (``dances_in_three``), the next style that fits the
    tempo as well is tried (some styles' moves bend to a waltz's bars, others keep their fours),
    then styles that still play
    ``METRE_SHARE`` of the pieces within the natural rates, and the first dance is kept when none
    dances in three."""
    waltz = music.beats_per_bar == 3 and music.n_beats >= 4
    tag, prefer = (None, ()) if config.style else song_genres(db, music)
    t = time.perf_counter()
    fits = fit_styles(db, music, config.style, min_share=METRE_SHARE if waltz else None, prefer=prefer)
    timings["prepare_s"] = time.perf_counter() - t
    clip, run = in_style(fits[0], music, db, config, timings, progress)
    tried = [fits[0].style.name]
    if waltz and not dances_in_three(clip, music):
        for fit in fits[1:]:
            other_timings = dict(timings)
            other, other_run = in_style(fit, music, db, config, other_timings, progress)
            tried.append(fit.style.name)
            if dances_in_three(other, music):
                clip, run = other, other_run
                timings.update(other_timings)
                break
    if len(tried) > 1:
        run = replace(run, extra={**run.extra, "styles_tried_for_metre": tried})
    run = replace(run, extra={**run.extra, "genre_tag": tag,
                              "style_reason": style_reason(config.style, tag, prefer, run.genre)})
    return clip, run


def song_genres(db: MotionDatabase, music: MusicFeatures) -> tuple[str | None, tuple[str, ...]]:
    """The song file's genre tag (ID3, Vorbis comment, MP4 atom) and the database's genres it suggests."""
    from ...music.tags import read_genre_tag

    tag = read_genre_tag(music.source) if music.source and Path(music.source).is_file() else None
    return tag, genre_preference(db, tag)


def style_reason(asked: str | None, tag: str | None, prefer: tuple, genre: str) -> str:
    """Why the summary's style was danced: named, the song's genre tag, or the tempo and material."""
    if asked:
        return f"named with --style {asked}"
    if genre in prefer:
        return f"the song's genre tag '{tag}' suggests {', '.join(prefer)}, and '{genre}' fits its tempo"
    why = "it fits the song's tempo best, with the most material"
    if tag and prefer:
        return why + f" (the genre tag '{tag}' suggests {', '.join(prefer)}, which fit the tempo less well)"
    return why + (f" (the genre tag '{tag}' names no genre of the database)" if tag else "")


def in_style(fit: StyleFit, music: MusicFeatures, db: MotionDatabase, config, timings: dict,
             progress: Progress | None) -> tuple[MotionClip, EngineRun]:
    """``dance`` in one chosen style and metrical level (its ``material``: mirrored takes too)."""
    style, subdivide = fit.style.material, fit.subdivide
    t = time.perf_counter()
    graph, cached = load_graph(style, config.graph)
    timings["prepare_s"] = timings.get("prepare_s", 0.0) + time.perf_counter() - t

    t = time.perf_counter()
    grid = beat_grid(music, subdivide=subdivide)
    signature = None
    if config.follow_signature:
        from .signature import database_signature

        signature = database_signature(style, graph, db, config.render.signature_weight)
    render = config.render if config.accent_timing else plain_timing(config.render)
    form = form_plan(music, grid.times_s, config.repeat, config.vary)
    engine = GraphEngine(style, graph, render, fps=config.fps, signature=signature, form=form)
    segments, stats = synthesise(engine, grid, music.duration_s, config, progress)
    timings["synthesis_s"] = time.perf_counter() - t

    local = np.concatenate([s.local_rot for s in segments])
    root = np.concatenate([s.root_pos for s in segments])
    contacts = np.concatenate([s.contacts for s in segments])
    jumps = np.concatenate([s.pieces.t0[s.pieces.jump] for s in segments])
    # The beat grid starts before 0 s so that a piece covers the first frame; a jump
    # before the first frame is never seen.
    jumps = jumps[(jumps >= 0.0) & (jumps < music.duration_s)]
    warp_rates = np.concatenate([s.warp_rates(style.fps) for s in segments])
    extra = {"prepare_stage": "graph", "lookahead_s": config.lookahead_s, "graph_nodes": graph.n_nodes,
             "graph_mean_in_degree": graph.mean_in_degree, "graph_cached": cached,
             "form": form.summary(np.concatenate([segments[0].path.nodes[:1]] + [s.path.nodes[1:] for s in segments]),
                                  engine.mirror if form.mirrored else None)}
    motifs = {}
    if signature is not None:
        from ...motion.motifs import chi2

        ids = np.concatenate([s.motifs for s in segments])
        danced = ids[ids >= 0]
        extra.update(genre=signature.genre, motifs=len(signature.template), constraints=0, recreate=None,
                     motif_chi2=chi2(signature.template, np.bincount(danced, minlength=len(signature.template)))
                     if danced.size else None)
        motifs = {"motif_ids": ids}
    run = EngineRun(style=style.name, genre=style.genre, style_fingerprint=style.fingerprint, subdivide=subdivide,
                    grid_times_s=grid.times_s, transition_times_s=jumps, warp_rates=warp_rates,
                    segment_times_s=stats["boundaries_s"], step_s=tuple(stats["step_s"]),
                    source_frames=np.concatenate([s.source_pos for s in segments]), motifs=motifs,
                    fit=fit_summary(fit, music, warp_rates), extra=extra, form=form)
    return MotionClip(style.skeleton, config.fps, root, local, contacts=contacts), run


def segment_bounds(times_s: np.ndarray, segment_s: float) -> list[tuple[int, int]]:
    """Cut a beat grid into segments of at most ``segment_s`` (at least one interval each)."""
    bounds, b, last = [], 0, len(times_s) - 1
    while b < last:
        e = min(max(last_beat_within(times_s, b, segment_s), b + 1), last)
        bounds.append((b, e))
        b = e
    return bounds


def last_beat_within(times_s: np.ndarray, b: int, seconds: float) -> int:
    """Index of the last beat at most ``seconds`` after beat ``b``."""
    return int(np.searchsorted(times_s, times_s[b] + seconds + 1e-9, side="right") - 1)


def synthesise(engine: GraphEngine, grid: BeatGrid, duration_s: float, config,
               progress: Progress | None = None) -> tuple[list[SegmentFrames], dict]:
    """Run the chosen engine over a beat grid; returns the rendered segments and step timings.

    The grid's metre (``bar_position``), where known, goes to the engine with each segment."""
    bars, beats_per_bar = grid.bar_position, grid.beats_per_bar
    if config.engine == "global":
        t = time.perf_counter()
        out = [engine.run_global(grid.times_s, grid.intensity_db, duration_s, seed=config.seed,
                                 bar_position=bars, beats_per_bar=beats_per_bar, music_beat=grid.is_music_beat,
                                 beat_count=grid.count)]
        return out, {"segments": 1, "step_s": [time.perf_counter() - t], "boundaries_s": np.zeros(0)}
    state = engine.initial_state(config.seed)
    bounds = segment_bounds(grid.times_s, config.segment_s)
    out, step_s = [], []
    for i, (b, e) in enumerate(bounds):
        last = i == len(bounds) - 1
        # A file's music is all known: each segment is searched with what follows it in view
        # (a receding horizon) and only its own beats are danced.
        a = max(e, min(last_beat_within(grid.times_s, e, config.lookahead_s), grid.n_intervals))
        seg = MusicSegment(grid.times_s[b:a + 1], grid.intensity_db[b:a],
                           remaining_beats=grid.n_intervals - e, end_s=duration_s if last else None,
                           bar_position=bars[b:a + 1], beats_per_bar=beats_per_bar,
                           music_beat=grid.is_music_beat[b:a + 1],
                           beat_count=None if grid.count is None else grid.count[b:a + 1], ahead=a - e)
        t = time.perf_counter()
        state, frames = engine.step(state, seg)
        step_s.append(time.perf_counter() - t)
        out.append(frames)
        if progress:
            progress("synthesis", i + 1, len(bounds))
    return out, {"segments": len(bounds), "step_s": step_s,
                 "boundaries_s": grid.times_s[[e for _, e in bounds[:-1]]]}

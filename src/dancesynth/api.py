"""The library's front door: one call from a song to a dance."""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

from .engines.beatgrid import METRE_SHARE, BeatGrid, StyleFit, beat_grid, fit_styles, fit_summary
from .engines.form import check_repeat, form_plan
from .engines.graph.cache import load_graph
from .engines.graph.engine import EngineConfig, GraphEngine, MusicSegment, SegmentFrames
from .engines.graph.meta_graph import GraphConfig
from .engines.timing import plain_timing
from .errors import InputError
from .motion.catalog import list_styles  # noqa: F401  (part of this module's API)
from .motion.database import MotionDatabase, open_database
from .provenance import EngineRun, make_provenance
from .types import (DEFAULT_FPS, FALLBACK_BPM, MAX_SONG_S, SEGMENT_S, MotionClip, MusicFeatures, check_fps,
                    check_seed)

ENGINES = ("streaming", "global", "neural", "choreography")


@dataclass(frozen=True)
class DanceConfig:
    """Everything ``dance`` can be told, with the defaults in one place."""

    style: str | None = None
    engine: str | None = None   # None: "choreography" when motif_at or recreate is given, else "streaming"
    segment_s: float = SEGMENT_S
    lookahead_s: float = 0.0            # streaming: each segment's search also sees this much of the music after
                                        # it (a file's music is known): closer to its loudness, feet slide more
    fps: float = DEFAULT_FPS
    seed: int | None = None
    max_duration_s: float = MAX_SONG_S
    graph: GraphConfig = field(default_factory=GraphConfig)
    render: EngineConfig = field(default_factory=EngineConfig)
    motif_at: tuple = ()                # choreography: ("12.0=M17", ...) or ((12.0, 17), ...); see docs/choreography.md
    recreate: str | Path | None = None  # choreography: a reference BVH whose motif sequence to re-create
    follow_signature: bool = False      # streaming: also keep the genre's motif signature (engines/graph/signature.py)
    model: str | None = None            # neural: the weights to dance with (a .pt of 'dancesynth train'); None:
                                        # the shipped model of the style's genre
    accent_timing: bool = True          # streaming, global, choreography: ease into each beat (engines/timing.py);
                                        # False: each piece at one rate, on the same path (the bench compares)
    restore_spread: bool = True         # neural: widen the network's damped motion toward the mocap's spread
                                        # (engines/neural/data.restore_spread); False: the network alone
    repeat: str = "off"                 # the song's form (engines/form.py): a returning section replays its
                                        # moves ("same"), their mirror image ("mirror"), partly ("vary"), or
                                        # is danced afresh ("off": the default while the form costs guards,
                                        # docs/form.md)
    vary: float = 0.5                   # --repeat vary: the share of each repeat's bars danced anew

    def __post_init__(self):
        # Choreography constraints: one "12.0=M17" string or a sequence of them / of (seconds, motif) pairs.
        object.__setattr__(self, "motif_at", (self.motif_at,) if isinstance(self.motif_at, str)
                           else tuple(self.motif_at))
        constrained = bool(self.motif_at) or self.recreate is not None
        if self.model is not None:
            object.__setattr__(self, "model", str(self.model))
        if self.engine is None:
            object.__setattr__(self, "engine", "choreography" if constrained else
                               "neural" if self.model is not None else "streaming")
        if self.model is not None and self.engine != "neural":
            raise InputError(f"--model names weights of the neural engine, not of '{self.engine}': leave out "
                             "--engine (--model implies --engine neural)")
        if constrained and self.engine != "choreography":
            raise InputError(f"--motif-at and --recreate need the choreography engine, not '{self.engine}': "
                             "leave out --engine (they imply --engine choreography)")
        if self.engine not in ENGINES:
            raise InputError(f"unknown engine '{self.engine}': use one of {', '.join(ENGINES)}")
        if self.follow_signature and self.engine != "streaming":
            raise InputError(f"--follow-signature is for the streaming engine, not '{self.engine}' (the choreography "
                             "and neural engines follow the signature already; the global DP has no notion of "
                             "what has been danced so far)")
        if not 0.5 <= self.segment_s <= 600:
            raise InputError(f"segment length {self.segment_s} s is out of range: use 0.5 to 600 seconds")
        if not 0 <= self.lookahead_s <= 600:
            raise InputError(f"look-ahead {self.lookahead_s} s is out of range: use 0 to 600 seconds")
        if self.lookahead_s > 0 and self.engine != "streaming":
            raise InputError(f"--lookahead is for the streaming engine, not '{self.engine}' (the global DP sees the "
                             "whole song already)")
        check_repeat(self.repeat, self.vary)
        check_fps(self.fps)
        check_seed(self.seed)
        if not self.max_duration_s > 0:  # NaN too: it would switch the limit off
            raise InputError(f"the song length limit must be a positive number of seconds, got {self.max_duration_s}")


Progress = Callable[[str, int, int], None]


def config_from_report(report: dict) -> DanceConfig:
    """The ``DanceConfig`` a dance was made with, from its ``--report`` (``Provenance.report``):
    with the same song and database, ``dance(song, config=config_from_report(report))`` makes
    the same dance again."""
    from .motion.accents import AccentCosts

    try:
        c = dict(report["config"])
        render = dict(c.pop("render"))
        accent = render.pop("accent")
        graph = GraphConfig(**c.pop("graph"))
        render = EngineConfig(**render, accent=None if accent is None else AccentCosts(**accent))
        motif_at = tuple(m if isinstance(m, str) else tuple(m) for m in c.pop("motif_at", ()))
        return DanceConfig(**c, graph=graph, render=render, motif_at=motif_at)
    except (KeyError, TypeError, AttributeError) as exc:
        raise InputError(f"not a report of 'dancesynth dance --report' with its configuration ({exc})") from None


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


def synthesise(engine: GraphEngine, grid: BeatGrid, duration_s: float, config: DanceConfig,
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


def analyse(song, max_duration_s: float = MAX_SONG_S, structure: bool = True) -> MusicFeatures:
    """``song``'s beats, metre and loudness, and with ``structure`` its form (``music.structure``)."""
    from .music import analyze_music  # librosa is heavy: import on first use

    return analyze_music(path=song, fallback_bpm=FALLBACK_BPM, max_duration_s=max_duration_s, structure=structure)


def dance(song, *, config: DanceConfig | None = None, database: MotionDatabase | str | Path | None = None,
          progress: Progress | None = None, **overrides) -> MotionClip:
    """Make a dance for ``song`` (a path to an audio file, or ``MusicFeatures``).

    Keyword overrides are ``DanceConfig`` fields, e.g. ``dance("song.ogg", style="salsa")``.
    Returns a ``MotionClip`` on the chosen style's skeleton; ``clip.provenance`` records
    how it was made (``.summary``: tempo, beats, style, segments, time per stage).
    """
    if config is None:
        config = DanceConfig(**overrides)
    elif overrides:
        config = replace(config, **overrides)
    timings = {}
    t = time.perf_counter()
    music = song if isinstance(song, MusicFeatures) else analyse(song, config.max_duration_s,
                                                                 structure=config.repeat != "off")
    timings["music_s"] = time.perf_counter() - t

    t = time.perf_counter()
    db = database if isinstance(database, MotionDatabase) else open_database(database)
    name = music.source if isinstance(song, MusicFeatures) else str(song)
    if config.engine == "neural":  # the learned pose generator (Aristidou et al. §4); torch loads lazily
        from .engines.neural.engine import neural_dance

        timings["database_s"] = time.perf_counter() - t
        clip, run = neural_dance(music, db, config, timings=timings)
    elif config.engine == "choreography":  # motifs by eq. (5), danced with mocap words (Aristidou et al. §5.2)
        from .engines.choreography import choreography_dance
        from .motion.motifs import load_motif_model

        reference = None
        if config.recreate is not None:
            from .io.bvh import read_bvh

            reference = read_bvh(config.recreate)
        model = load_motif_model(db)
        timings["database_s"] = time.perf_counter() - t
        clip, run = choreography_dance(music, db, config, timings=timings, motif_model=model, reference=reference)
    else:
        clip, run, timings = _graph_dance(music, db, config, timings, t, progress)
    segment_s = config.segment_s if config.engine in ("streaming", "global") else None
    prov = make_provenance(config.engine, name, config, run, fps=config.fps, frames=clip.n_frames, timings=timings,
                           music=music, segment_s=segment_s)
    prov = prov.with_summary(**metre_summary(clip, music, run.style, prov.summary.get("warnings", [])))
    clip.provenance = with_repetition(prov, db, music, config.fps)
    return clip


def with_repetition(prov, db: MotionDatabase, music: MusicFeatures, fps: float):
    """``prov`` with the clip and frame danced on every music beat, and the summary's account of how
    much of the dance replays material danced in the previous minute (``eval.repetition``), the
    replays the song's form asked for (the engine's ``EngineRun.form``) aside."""
    from .eval.repetition import beat_sources, repetition

    style = db.styles.get(prov.style)
    if style is None or prov.source_frames is None or not len(prov.source_frames):
        return prov
    sources = beat_sources(prov.source_frames, fps, music.beat_times_s, style.material)
    asked = None
    if prov.run.form is not None and len(prov.run.grid_times_s) > 1:
        asked = prov.run.form.asked_at(prov.run.grid_times_s, music.beat_times_s)
        sources = [{**s, "form_replay": bool(a)} for s, a in zip(sources, asked)]
    stats = repetition([(s["clip"], s["source_position"]) for s in sources], music.beat_times_s, asked=asked)
    stats["material_minutes"] = style.captured_s / 60.0
    stats["mirrored_minutes"] = style.mirrored_s / 60.0
    return replace(prov, beat_sources=tuple(sources)).with_summary(repetition=stats)


def metre_summary(clip: MotionClip, music: MusicFeatures, style: str, warnings: list) -> dict:
    """What the dance made of the metre: the period (in beats) at which its energy per beat repeats,
    and a warning where a song in three is not danced in three (the style's moves repeat in twos and
    fours)."""
    if not music.beats_per_bar or music.n_beats < 4:
        return {}
    period = dance_period(clip, music)
    out = {"beats_per_bar": int(music.beats_per_bar), "dance_period_beats": period}
    if music.beats_per_bar == 3 and period is not None and period != 3:
        out["warnings"] = list(warnings) + [
            f"the song is in 3/4, but the dance's energy repeats every {period} beats, not in three: the "
            f"'{style}' moves found for it do not follow a waltz's bars, nor did "
            f"those of any other style that fits this tempo as well"]
    return out


def dance_period(clip: MotionClip, music: MusicFeatures) -> int | None:
    """The period (2, 3 or 4 beats) at which the dance's kinetic energy per music beat repeats most."""
    return _period_strengths(clip, music)[0]


def _period_strengths(clip: MotionClip, music: MusicFeatures) -> tuple[int | None, dict[int, float]]:
    from .eval.beat_metrics import dominant_beat_period
    from .eval.motion_metrics import beat_interval_energy

    energy = beat_interval_energy(clip, music.beat_times_s)
    return dominant_beat_period(energy[np.isfinite(energy)])


#: How much more the dance's energy must repeat at 3 beats than at 2 or 4 for a style to count as
#: dancing a waltz in three (autocorrelation): a tie is a coin flip that the next reading may lose.
IN_THREE_MARGIN = 0.05


def dances_in_three(clip: MotionClip, music: MusicFeatures) -> bool:
    period, strength = _period_strengths(clip, music)
    others = [r for lag, r in strength.items() if lag != 3]
    return period == 3 and (not others or strength[3] >= max(others) + IN_THREE_MARGIN)


def _graph_dance(music: MusicFeatures, db: MotionDatabase, config: DanceConfig, timings: dict,
                 t: float, progress: Progress | None) -> tuple[MotionClip, EngineRun, dict]:
    """``dance`` for the meta-motion-graph engines (streaming, its signature variant, global).

    The style and metrical level are those that warp the beat pieces least (engines/beatgrid.py).
    A song in three is danced in three where the database allows it: when the first style's
    dance does not clearly repeat in threes (``dances_in_three``), the next style that fits the
    tempo as well is tried (some styles' moves bend to a waltz's bars, others keep their fours),
    then styles that still play
    ``METRE_SHARE`` of the pieces within the natural rates, and the first dance is kept when none
    dances in three."""
    waltz = music.beats_per_bar == 3 and music.n_beats >= 4
    tag, prefer = (None, ()) if config.style else song_genres(db, music)
    fits = fit_styles(db, music, config.style, min_share=METRE_SHARE if waltz else None, prefer=prefer)
    timings["database_s"] = time.perf_counter() - t
    clip, run = _graph_dance_fit(fits[0], music, db, config, timings, progress)
    tried = [fits[0].style.name]
    if waltz and not dances_in_three(clip, music):
        for fit in fits[1:]:
            other_timings = dict(timings)
            other, other_run = _graph_dance_fit(fit, music, db, config, other_timings, progress)
            tried.append(fit.style.name)
            if dances_in_three(other, music):
                clip, run, timings = other, other_run, other_timings
                break
    if len(tried) > 1:
        run = replace(run, extra={**run.extra, "styles_tried_for_metre": tried})
    run = replace(run, extra={**run.extra, "genre_tag": tag,
                              "style_reason": style_reason(config.style, tag, prefer, run.genre)})
    return clip, run, timings


def song_genres(db: MotionDatabase, music: MusicFeatures) -> tuple[str | None, tuple[str, ...]]:
    """The song file's genre tag (ID3, Vorbis comment, MP4 atom) and the database's genres it suggests."""
    from .engines.beatgrid import genre_preference
    from .music.tags import read_genre_tag

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


def _graph_dance_fit(fit: StyleFit, music: MusicFeatures, db: MotionDatabase, config: DanceConfig,
                     timings: dict, progress: Progress | None) -> tuple[MotionClip, EngineRun]:
    """``_graph_dance`` in one chosen style and metrical level (its ``material``: mirrored takes too)."""
    style, subdivide = fit.style.material, fit.subdivide
    t = time.perf_counter()
    graph, cached = load_graph(style, config.graph)
    timings["graph_s"] = time.perf_counter() - t

    t = time.perf_counter()
    grid = beat_grid(music, subdivide=subdivide)
    signature = None
    if config.follow_signature:
        from .engines.graph.signature import database_signature

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
    extra = {"lookahead_s": config.lookahead_s, "graph_nodes": graph.n_nodes,
             "graph_mean_in_degree": graph.mean_in_degree, "graph_cached": cached,
             "form": form.summary(np.concatenate([segments[0].path.nodes[:1]] + [s.path.nodes[1:] for s in segments]),
                                  engine.mirror if form.mirrored else None)}
    motifs = {}
    if signature is not None:
        from .motion.motifs import chi2

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


def conduct(song, *, config=None, melody_track: int | None = None, rhythm_track: int | None = None,
            skeleton=None, database: MotionDatabase | str | Path | None = None,
            max_duration_s: float = MAX_SONG_S) -> MotionClip:
    """Upper-body motion interpreting ``song``'s melody (Loi & Li): a MIDI file, an audio file or a
    ``NoteSequence``. ``config`` is a ``ProceduralConfig`` (default look when ``None``).

    Returns a ``MotionClip`` on ``skeleton``, else the database's ``mj`` style's (the bundled
    database by default); ``clip.provenance`` says what was done.
    """
    from .engines.procedural import ProceduralConfig, conduct_notes, default_skeleton
    from .music.melody import read_notes
    from .music.notes import NoteSequence

    config = config or ProceduralConfig()
    t = time.perf_counter()
    notes = song if isinstance(song, NoteSequence) else read_notes(
        song, melody_track=melody_track, rhythm_track=rhythm_track, max_duration_s=max_duration_s)
    timings = {"notes_s": time.perf_counter() - t}
    if skeleton is None:
        skeleton = default_skeleton(database if isinstance(database, MotionDatabase) else open_database(database))
    clip = conduct_notes(notes, config, skeleton=skeleton)
    stats = dict(clip.meta["stats"])
    timings.update(stats.pop("timings_s"))
    run = EngineRun(style="", segment_times_s=clip.meta["segment_times_s"],
                    extra={**stats, "input": notes.meta.get("kind", "notes")})
    clip.provenance = make_provenance("procedural", notes.source, config, run, fps=config.fps, frames=clip.n_frames,
                                      timings=timings, duration_s=notes.duration_s, tempo_bpm=notes.tempo_bpm)
    return clip

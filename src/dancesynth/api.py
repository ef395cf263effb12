"""The library's front door: one call from a song to a dance."""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path

from .engines.form import check_repeat
from .engines.graph.dance import segment_bounds, synthesise  # noqa: F401  (part of this module's API)
from .engines.graph.engine import EngineConfig
from .engines.graph.meta_graph import GraphConfig
from .engines.protocol import ENGINES as ENGINE_MODULES
from .engines.protocol import Progress, engine
from .errors import InputError
from .eval.metre import dance_period
from .motion.catalog import list_styles  # noqa: F401  (part of this module's API)
from .motion.database import MotionDatabase, open_database
from .provenance import EngineRun, make_provenance
from .types import (DEFAULT_FPS, FALLBACK_BPM, MAX_SONG_S, SEGMENT_S, MotionClip, MusicFeatures, check_fps,
                    check_seed)

ENGINES = tuple(ENGINE_MODULES)


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
    timings["database_s"] = time.perf_counter() - t
    clip, run = engine(config.engine)(music, db, config, timings, progress)
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

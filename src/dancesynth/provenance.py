"""Where a dance came from: one frozen record per dance, built here and nowhere else.

Every engine says what it did in an ``EngineRun`` (the style and metrical level it
chose, the beat grid, the transitions and time warps it played, its own numbers);
``make_provenance`` joins that with the song's analysis, the configuration and the
timings into a ``Provenance``. ``dance --report`` writes it (``Provenance.report``),
the CLI prints its ``summary``, the evaluation reads its transitions and warps, and
the configuration in it (with the seed and the database fingerprint) is enough to
make the same dance again.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .io.files import jsonable
from .types import MusicFeatures



def _empty() -> np.ndarray:
    return np.zeros(0)


@dataclass(frozen=True)
class EngineRun:
    """What an engine reports about the dance it made (beyond the motion itself)."""

    style: str                                 # the style danced ("" for a procedural dance)
    genre: str = ""
    style_fingerprint: str = ""                # the style's content hash: same data, same dance
    subdivide: int = 1                         # metrical level: music beats per danced beat
    grid_times_s: np.ndarray = field(default_factory=_empty)          # the danced beats
    transition_times_s: np.ndarray = field(default_factory=_empty)    # where the dance jumps between captures
    warp_rates: np.ndarray = field(default_factory=_empty)            # playback speed of each beat piece (or frame)
    segment_times_s: np.ndarray = field(default_factory=_empty)       # where streaming segments meet
    step_s: tuple = ()                         # time of each synthesis step
    source_frames: np.ndarray | None = None    # the source frame each output frame shows
    motifs: dict = field(default_factory=dict)  # motif ids, plan and constraints (Aristidou et al.)
    fit: dict = field(default_factory=dict)     # engines.beatgrid.fit_summary: level, warp, warnings
    extra: dict = field(default_factory=dict)   # the engine's own numbers (graph size, model, ...)
    form: object = None                         # the engines.form.FormPlan it followed, on grid_times_s


@dataclass(frozen=True)
class Provenance:
    """A dance's record: what was asked, what was chosen, what was played, how long it took."""

    engine: str
    song: str
    config: dict               # the full configuration as plain data (seed, graph and render configs)
    summary: dict              # what the CLI prints: song, tempo, style, level, timings, warnings, ...
    run: EngineRun
    music_beat_times_s: np.ndarray = field(default_factory=_empty)
    music_beat_in_bar: np.ndarray = field(default_factory=_empty)   # each beat's place in its bar (0: a downbeat)
    version: str = ""
    beat_sources: tuple = ()   # per music beat: the clip and frame danced on it (eval.repetition.beat_sources)

    @property
    def style(self) -> str:
        return self.run.style

    @property
    def transition_times_s(self) -> np.ndarray:
        return self.run.transition_times_s

    @property
    def warp_rates(self) -> np.ndarray:
        return self.run.warp_rates

    @property
    def grid_times_s(self) -> np.ndarray:
        return self.run.grid_times_s

    @property
    def source_frames(self) -> np.ndarray | None:
        return self.run.source_frames

    @property
    def motifs(self) -> dict:
        return self.run.motifs

    def with_summary(self, **items) -> "Provenance":
        """The same record with ``items`` added to (or replacing) the summary's."""
        return replace(self, summary={**self.summary, **items})

    def report(self) -> dict:
        """JSON-ready: what ``dance --report`` writes and ``eval --report`` reads."""
        run = self.run
        return jsonable({
            "version": self.version, "engine": self.engine, "song": self.song, "style": run.style,
            "style_fingerprint": run.style_fingerprint, "config": self.config, "summary": self.summary,
            "music_beat_times_s": self.music_beat_times_s, "grid_times_s": run.grid_times_s,
            "transition_times_s": run.transition_times_s, "segment_times_s": run.segment_times_s,
            "warp_rates": run.warp_rates,
            "motifs": {k: v for k, v in run.motifs.items()},
            **({"music_beat_sources": list(self.beat_sources)} if self.beat_sources else {}),
        })


def make_provenance(engine: str, song: str, config, run: EngineRun, *, fps: float, frames: int,
                    timings: dict, music: MusicFeatures | None = None, segment_s: float | None = None,
                    duration_s: float | None = None, tempo_bpm: float | None = None) -> Provenance:
    """The one place a dance's record is built. ``config``: a dataclass (or dict) of everything the
    dance was asked with; ``music`` the analysis it danced to (a procedural dance has notes instead:
    give ``duration_s`` and ``tempo_bpm``)."""
    from . import __version__

    step_s = np.asarray(run.step_s, dtype=float)
    transitions = np.asarray(run.transition_times_s, dtype=float)
    summary = {"song": song, "engine": engine, "style": run.style}
    if run.genre:
        summary["genre"] = run.genre
    if music is not None:
        summary.update(duration_s=music.duration_s, tempo_bpm=music.tempo_bpm, beats=music.n_beats,
                       beat_confidence=music.beat_confidence, default_tempo=music.default_tempo)
    else:
        summary.update(duration_s=duration_s, tempo_bpm=tempo_bpm)
    summary.update(subdivide=run.subdivide, segments=max(len(run.segment_times_s) + 1, len(step_s), 1),
                   segment_s=segment_s if segment_s is not None else summary["duration_s"],
                   transitions=int(len(transitions)), frames=int(frames), fps=float(fps), timings_s=dict(timings))
    if step_s.size:
        summary.update(step_s_median=float(np.median(step_s)), step_s_max=float(np.max(step_s)))
    summary.update(run.extra)
    summary.update(run.fit)
    return Provenance(engine=engine, song=song, config=jsonable(config or {}), summary=summary, run=run,
                      music_beat_times_s=np.zeros(0) if music is None else np.asarray(music.beat_times_s),
                      music_beat_in_bar=np.zeros(0) if music is None or music.beat_in_bar is None
                      else np.asarray(music.beat_in_bar), version=__version__)

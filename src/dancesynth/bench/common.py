"""What the benchmark sections share: their settings, the bundled data, table layout, fits."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

from ..types import MusicFeatures

MUSIC_DIR = Path(__file__).resolve().parents[1] / "data" / "music"
DEFAULT_SONG = "Kevin_MacLeod_-_Vibe_Ace.ogg"  # the README's demo song
SECTIONS = ("fig4", "scaling", "pipeline", "quality", "beat_tracking", "structure", "accents", "realism",
            "vocabulary", "form")

Progress = Callable[[str], None]


@dataclass(frozen=True)
class BenchConfig:
    """How much the benchmark measures; ``full()`` and ``quick()`` are the two product settings.

    Tests shrink a ``quick()`` further with ``dataclasses.replace``.
    """

    sections: tuple[str, ...] = SECTIONS
    # 1. Xu Fig. 4: per-segment synthesis time on the largest style and the bundled song.
    song: str = DEFAULT_SONG
    song_max_s: float | None = None     # cut the song (fig4 and scaling) to its first seconds
    segments_s: tuple[float, ...] = (2.0, 5.0, 10.0, 15.0, 20.0, 30.0)
    whole_song_row: bool = True         # one more row: the whole song as one segment
    repeats: int = 7
    # 2. Scaling: the largest style replicated, each size in its own process.
    scales: tuple[int, ...] = (1, 2, 5, 10)
    scale_segment_s: float = 5.0
    scale_timeout_s: float = 600.0
    # Pipeline: bundled graphs built and reloaded, a long song to BVH end to end.
    pipeline_song_s: float = 180.0
    pipeline_runs: int = 3
    # 3. Quality: bundled songs (None: all), optionally cut short.
    quality_songs: tuple[str, ...] | None = None
    quality_max_s: float | None = None
    mocap_max_clips: int | None = None  # evaluate at most this many clips per style (None: all)
    seed: int = 0                       # the random walk's seed
    # 4. Beat tracking on generated ground truth.
    groundtruth_quick: bool = False
    groundtruth_split: str = "test"         # generated songs: "test" (reported) or "tune" (where constants were chosen)
    groundtruth_specs: tuple | None = None  # SongSpecs overriding the standard set (tests)
    groundtruth_dir: Path | None = None     # cache of rendered songs (None: the dancesynth cache)
    trackers: tuple[str, ...] | None = None  # None: every tracker in TRACKERS
    # 6. Global structure (bench.structure): Table I, Fig. 12, metrics per engine, re-creation.
    structure_songs: tuple[str, ...] | None = None   # None: every bundled song ...
    structure_min_s: float = 20.0                     # ... long enough for a signature (not the 5 s trumpet)
    structure_max_s: float | None = None
    structure_seeds: int = 3
    structure_engines: tuple[str, ...] = ("streaming", "signature", "global", "random_walk", "choreography",
                                          "neural")
    fig12_song: str | None = None          # None: the longest bundled song
    fig12_seeds: int = 5
    fig12_step_s: float = 5.0
    fig12_engines: tuple[str, ...] = ("streaming", "signature", "choreography", "neural")
    recreate_style: str = "salsa-133-150bpm"
    recreate_song: str = DEFAULT_SONG
    recreate_clips: int | None = None      # None: every clip of the style in turn
    # 7. Visible accents on the beats (bench.accents): every mocap engine on bundled and generated songs.
    accent_songs: tuple[str, ...] | None = None  # bundled songs (None: all)
    accent_generated: bool = True                # also the generated set (groundtruth_quick / _specs apply)
    accent_engines: tuple[str, ...] = ("streaming", "lookahead", "signature", "global", "choreography", "random_walk",
                                       "paper")
    # 8. Realism (bench.realism): FID_k/FID_g/Div_k/Div_g of every mocap engine against mocap held out of a style.
    realism_style: str | None = "salsa-97-124bpm"  # the salsa style with the most takes (None: the largest)
    realism_songs: tuple[str, ...] | None = None  # bundled songs (None: every one ...)
    realism_min_s: float = 20.0                   # ... at least this long
    realism_max_s: float | None = None
    realism_seeds: int = 3                        # held-out splits 0..n-1, each also the dances' seed
    realism_fraction: float = 0.2                 # share of the style's clips held out
    realism_window_s: float = 5.0
    realism_engines: tuple[str, ...] = ("streaming", "signature", "global", "choreography", "random_walk")
    # 9. Vocabulary (bench.vocabulary): minutes per genre, the tempo map, repetition on long songs, guards per style.
    vocabulary_split: str = "test"        # the long songs reported ("tune": those the constants were chosen on)
    vocabulary_long_songs: int = 10       # 3-minute generated songs, 4/4 and 3/4
    vocabulary_long_s: float = 180.0
    # 10. The song's form (bench.form): sections found, and every engine with --repeat off and same.
    form_engines: tuple[str, ...] = ("streaming", "global", "choreography", "neural", "random_walk")
    form_specs: tuple | None = None      # SongSpecs of known form (None: groundtruth.structure_specs of the split)
    form_seeds: tuple = (None, 1, 2)     # each song danced with each seed (None: the default dance)

    @classmethod
    def full(cls) -> "BenchConfig":
        return cls()

    @classmethod
    def quick(cls) -> "BenchConfig":
        """Under two minutes on a 2-core CPU."""
        return replace(cls(), segments_s=(2.0, 5.0, 10.0, 30.0), repeats=5, scales=(1, 2), pipeline_runs=1,
                       quality_songs=(DEFAULT_SONG,), quality_max_s=60.0, mocap_max_clips=6,
                       groundtruth_quick=True, structure_songs=(DEFAULT_SONG,), structure_seeds=1, fig12_seeds=2,
                       fig12_song=DEFAULT_SONG, recreate_clips=4, accent_songs=(DEFAULT_SONG,),
                       realism_songs=(DEFAULT_SONG,), realism_seeds=1, vocabulary_long_songs=4,
                       form_specs=tuple(_quick_form_specs()), form_seeds=(None,))


def _quick_form_specs():
    from .groundtruth import structure_specs

    return structure_specs("test")[:2]


def load_song(name: str, max_s: float | None = None) -> MusicFeatures:
    """Analyse a bundled song (by file name, or any path), optionally keeping its first ``max_s`` seconds."""
    from ..music import analyze_music

    path = Path(name) if Path(name).is_file() else MUSIC_DIR / name
    music = analyze_music(path=path)
    return truncate_music(music, max_s) if max_s else music


def truncate_music(music: MusicFeatures, max_s: float) -> MusicFeatures:
    """The first ``max_s`` seconds of analysed music: the beats before it and their intervals' loudness
    (not its form, which was found in the whole song)."""
    if music.duration_s <= max_s:
        return music
    keep = int(np.searchsorted(music.beat_times_s, max_s, side="right"))
    keep = max(keep, 2)
    return replace(music, duration_s=float(max(max_s, music.beat_times_s[keep - 1])),
                   beat_times_s=music.beat_times_s[:keep], intensity_db=music.intensity_db[:keep - 1],
                   beat_in_bar=None if music.beat_in_bar is None else music.beat_in_bar[:keep], structure=None)


def largest_style(db):
    """The style with the most beats (the paper's Fig. 4 uses one dance's whole graph)."""
    return max(db.styles.values(), key=lambda s: (len(s.beat_frames), s.name))


def linear_fit(x, y) -> dict:
    """Least squares ``y = slope * x + intercept`` with its coefficient of determination."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    if len(x) < 2 or np.ptp(x) == 0:
        return {"slope": None, "intercept": None, "r2": None, "points": int(len(x))}
    slope, intercept = np.polyfit(x, y, 1)
    ss_tot = float(np.sum((y - y.mean()) ** 2))
    r2 = 1.0 - float(np.sum((y - (slope * x + intercept)) ** 2)) / ss_tot if ss_tot > 0 else 1.0
    return {"slope": float(slope), "intercept": float(intercept), "r2": float(min(max(r2, 0.0), 1.0)),
            "points": int(len(x))}


# ---------------------------------------------------------------------------------------------
# Tables: right-aligned columns, a rule under the header; a value is a number, text or None.


def cell(value, digits: int = 2) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return f"{value:.{digits}f}"
    return str(value)


def split_name(cfg: BenchConfig) -> str:
    """Which generated songs a section scored: a split of ``groundtruth.SPLITS``, or the caller's own."""
    return "custom" if cfg.groundtruth_specs is not None else cfg.groundtruth_split


def table(title: str, header: list[str], rows: list[list], digits: list[int] | None = None,
          notes: list[str] = ()) -> str:
    """A plain-text table; ``digits[i]`` decimals for floats in column ``i``."""
    digits = digits or [2] * len(header)
    text = [[cell(v, d) for v, d in zip(r, digits)] for r in rows]
    widths = [max([len(h)] + [len(r[i]) for r in text]) for i, h in enumerate(header)]

    def line(cells):
        return "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths))).rstrip()

    out = [title, line(header), line(["-" * w for w in widths])] + [line(r) for r in text]
    return "\n".join(out + [f"  {n}" for n in notes])


def skipped(section: dict) -> str | None:
    return section.get("skipped") if isinstance(section, dict) else "missing"

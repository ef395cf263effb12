"""The data types that flow through dancesynth, defined once.

Conventions (see DESIGN.md):
- Y is up, lengths are metres, times are seconds (``_s``), frame counts ``_frames``.
- Rotations are unit quaternions in SciPy's order (x, y, z, w); Euler angles exist
  only at file boundaries.
- Arrays are structure-of-arrays with frames as the leading axis.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import InputError

ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
MAX_SEED = 2**63 - 1

from .defaults import DEFAULT_FPS, FALLBACK_BPM, MAX_SONG_S, SEGMENT_S  # noqa: F401  (read from here too)


def check_seed(seed) -> None:
    """A dance's seed is None or a whole number 0 .. 2^63 - 1 (numpy's generators take no negatives)."""
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer))
                             or not 0 <= int(seed) <= MAX_SEED):
        raise InputError(f"seed {seed!r} must be a whole number from 0 to {MAX_SEED} (or left out)")


DANCE_FPS_RANGE = (1.0, 240.0)     # frame rates a dance can be made at


def check_fps(fps) -> None:
    """A dance's frame rate is a number within ``DANCE_FPS_RANGE`` (NaN and infinity are not)."""
    lo, hi = DANCE_FPS_RANGE
    if isinstance(fps, bool) or not isinstance(fps, (int, float, np.integer, np.floating)) or not lo <= fps <= hi:
        raise InputError(f"frame rate {fps} is out of range: use {lo:g} to {hi:g} fps")


POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A joint hierarchy as a BVH file describes it.

    ``parents[j] < j`` for every joint but the root (``parents[0] == -1``).
    ``channels[j]`` keeps the channel names in file order, so a skeleton read from a
    BVH file is written back with the same layout. ``end_sites`` maps a joint index
    to the offset of its End Site.
    """

    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    end_sites: dict[int, np.ndarray] = field(default_factory=dict)

    def __post_init__(self):
        parents = np.asarray(self.parents, dtype=np.int64)
        offsets = np.asarray(self.offsets, dtype=np.float64).reshape(-1, 3)
        object.__setattr__(self, "parents", parents)
        object.__setattr__(self, "offsets", offsets)
        n = len(self.names)
        if parents.shape != (n,) or offsets.shape != (n, 3) or len(self.channels) != n:
            raise InputError("Skeleton arrays disagree on the number of joints")
        if n == 0 or parents[0] != -1 or np.any(parents[1:] < 0) or np.any(parents[1:] >= np.arange(1, n)):
            raise InputError("Skeleton parents must be topologically ordered with the root first")

    @property
    def n_joints(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        return self.names.index(name)

    def rotation_order(self, joint: int) -> str:
        """Intrinsic Euler order of a joint's rotation channels, e.g. ``"ZXY"``."""
        order = "".join(c[0] for c in self.channels[joint] if c in ROTATION_CHANNELS)
        return order or "ZXY"

    def children(self, joint: int) -> np.ndarray:
        return np.flatnonzero(self.parents == joint)

    def scaled(self, factor: float) -> "Skeleton":
        """The same skeleton with every length multiplied by ``factor``."""
        return Skeleton(self.names, self.parents, self.offsets * factor, self.channels,
                        {j: o * factor for j, o in self.end_sites.items()})


@dataclass(eq=False)
class MotionClip:
    """Motion of one skeleton sampled at a fixed frame rate.

    ``local_pos`` is only present when joints other than the root carry animated
    position channels; otherwise each joint sits at its skeleton offset.
    ``contacts`` marks frames where the (left, right) foot is planted.
    ``meta`` carries what the source says about the clip (a capture's name, source file and
    beat frames; a procedural dance's plan); a dance's ``provenance`` records how it was made
    (``dancesynth.provenance``).
    """

    skeleton: Skeleton
    fps: float
    root_pos: np.ndarray
    local_rot: np.ndarray
    local_pos: np.ndarray | None = None
    contacts: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    provenance: object = None   # a dancesynth.provenance.Provenance for a dance dancesynth made

    def __post_init__(self):
        self.root_pos = np.asarray(self.root_pos, dtype=np.float64)
        self.local_rot = np.asarray(self.local_rot, dtype=np.float64)
        f, j = self.local_rot.shape[:2]
        if self.local_rot.shape != (f, j, 4) or j != self.skeleton.n_joints:
            raise InputError(f"local_rot must be (frames, {self.skeleton.n_joints}, 4), got {self.local_rot.shape}")
        if self.root_pos.shape != (f, 3):
            raise InputError(f"root_pos must be ({f}, 3), got {self.root_pos.shape}")
        if self.local_pos is not None and np.shape(self.local_pos) != (f, j, 3):
            raise InputError("local_pos must be (frames, joints, 3)")
        if self.contacts is not None and np.shape(self.contacts) != (f, 2):
            raise InputError("contacts must be (frames, 2)")
        if not self.fps > 0:
            raise InputError("fps must be positive")

    @property
    def n_frames(self) -> int:
        return self.local_rot.shape[0]

    def scaled(self, factor: float) -> "MotionClip":
        """The same motion with every length (offsets, root and joint positions) multiplied by ``factor``."""
        if factor == 1.0:
            return self
        return MotionClip(self.skeleton.scaled(factor), self.fps, self.root_pos * factor, self.local_rot,
                          None if self.local_pos is None else self.local_pos * factor, self.contacts,
                          dict(self.meta), self.provenance)

    @property
    def duration_s(self) -> float:
        """Time from the first to the last frame."""
        return max(self.n_frames - 1, 0) / self.fps

    def frames(self, start: int, stop: int) -> "MotionClip":
        """Frames ``start:stop`` as a new clip (metadata is not sliced)."""
        sl = slice(start, stop)
        return MotionClip(
            self.skeleton, self.fps, self.root_pos[sl], self.local_rot[sl],
            None if self.local_pos is None else self.local_pos[sl],
            None if self.contacts is None else self.contacts[sl], dict(self.meta))


@dataclass(frozen=True)
class Section:
    """A part of a song's form (``music.structure``): from ``start_s`` (a downbeat; 0 for the first) to
    ``end_s``, bars ``first_bar`` .. ``first_bar + n_bars``; sections with the same ``label`` ("A", "B",
    ...) play the same music; ``name`` is verse, chorus, bridge, intro or outro."""

    start_s: float
    end_s: float
    label: str
    name: str
    first_bar: int
    n_bars: int


@dataclass(frozen=True)
class Phrase:
    """``n_bars`` bars from ``start_s`` (bar ``first_bar``), a group of ``size`` (4 or 8) counted from its
    section's first bar (shorter at a section's end)."""

    start_s: float
    first_bar: int
    n_bars: int
    size: int


@dataclass(frozen=True)
class SongStructure:
    """A song's sections in order and its phrases of each size."""

    sections: tuple[Section, ...]
    phrases: tuple[Phrase, ...] = ()
    bar_starts_s: tuple[float, ...] = ()    # where each bar starts (the first at its downbeat)
    similarity: np.ndarray | None = field(default=None, compare=False)  # (bars, bars) how alike each two
                                            # bars sound (notes in order and timbre; the structure score's)

    def report(self, first_bar: int = 1) -> dict:
        """JSON-ready: what ``beats --json`` writes, bars numbered from ``first_bar`` (the first downbeat's)."""
        return {"sections": [{"start_s": round(s.start_s, 3), "end_s": round(s.end_s, 3), "label": s.label,
                              "name": s.name, "first_bar": s.first_bar + first_bar, "bars": s.n_bars}
                             for s in self.sections],
                "phrases": {str(size): [{"start_s": round(p.start_s, 3), "first_bar": p.first_bar + first_bar,
                                         "bars": p.n_bars} for p in self.phrases if p.size == size]
                            for size in sorted({p.size for p in self.phrases})}}


@dataclass(eq=False)
class MusicFeatures:
    """What the synthesis engines know about a piece of music.

    ``beat_times_s`` are the music's beats; ``intensity_db`` is the sound pressure
    level of each beat interval (``len(beat_times_s) - 1`` values), the music
    intensity of Xu et al. ``beat_confidence`` says how clearly the audio pulses
    (see ``dancesynth.music``); ``default_tempo`` is set when no clear beat was found
    and the beats are a steady grid at a stated tempo instead.

    Metre: ``beats_per_bar`` (3 for a waltz, 4 for most pop) and ``beat_in_bar``
    ``(B,)``, each beat's position in its bar counted from 0 (0 = a downbeat, the
    bar's "1"); ``None`` when the metre is unknown.
    """

    duration_s: float
    beat_times_s: np.ndarray
    intensity_db: np.ndarray
    tempo_bpm: float
    beat_confidence: float = 1.0
    default_tempo: bool = False
    source: str = ""
    meta: dict = field(default_factory=dict)
    beats_per_bar: int | None = None
    beat_in_bar: np.ndarray | None = None
    structure: SongStructure | None = None   # sections and phrases (``music.structure``); None: not analysed

    def __post_init__(self):
        self.beat_times_s = np.asarray(self.beat_times_s, dtype=np.float64)
        self.intensity_db = np.asarray(self.intensity_db, dtype=np.float64)
        if self.beat_times_s.ndim != 1 or np.any(np.diff(self.beat_times_s) <= 0):
            raise InputError("beat_times_s must be strictly increasing")
        if self.intensity_db.shape != (max(len(self.beat_times_s) - 1, 0),):
            raise InputError("intensity_db needs one value per beat interval")
        if self.beat_in_bar is not None:
            self.beat_in_bar = np.asarray(self.beat_in_bar, dtype=np.int64)
            if (self.beats_per_bar is None or self.beat_in_bar.shape != self.beat_times_s.shape
                    or np.any(self.beat_in_bar < 0) or np.any(self.beat_in_bar >= self.beats_per_bar)):
                raise InputError("beat_in_bar needs one position in [0, beats_per_bar) per beat")

    @property
    def n_beats(self) -> int:
        return len(self.beat_times_s)

    @property
    def downbeat_times_s(self) -> np.ndarray | None:
        """The bars' first beats (seconds), or ``None`` when the metre is unknown."""
        return None if self.beat_in_bar is None else self.beat_times_s[self.beat_in_bar == 0]

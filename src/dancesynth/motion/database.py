"""The motion database: mocap clips grouped into styles, analysed once, stored compactly.

A *style* is what Xu et al. §3.2 call a sub-group: clips of one dance genre (from the
database's annotation) whose motion tempo falls in one fixed-width tempo range, on
one skeleton. Each style (``motion.style``) keeps its clips as flat arrays plus clip ranges
(Holden's motion-matching layout), with the motion beats, per-frame kinetic energy and foot
contacts computed here at build time.

On disk a database is a folder: ``database.json`` (styles, skeletons, clip names and
sources) and one compressed ``<style>.npz`` per style. Rotations of animated joints
are stored as int16 quaternions (error < 0.01 degrees); joints that never move are
stored once.
"""

from __future__ import annotations

import hashlib
import json
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from ..errors import InputError, ModelError
from ..io.files import atomic_folder, cache_dir  # noqa: F401  (cache_dir: also imported from here)
from ..kinematics import fk
from ..timebase import bpm_from_intervals
from ..types import MotionClip, Skeleton
from . import beats as motion_beats
from .catalog import BUNDLED_DATABASE, FORMAT_VERSION  # noqa: F401  (also imported from here)
from .features import foot_contacts, foot_points, kinetic_energy
from .mirror import mirror_pairs, symmetry_error
from .resample import resample_clip_arrays
from .roles import bone_masses, find_roles
from .sources import MANIFEST_NAME, Rig, collect_sources, manifest_options, read_clip
from .style import MotionDatabase, Style  # noqa: F401  (also imported from here)

MIN_CLIP_S = 0.5  # a clip shorter than this has no 3 beats to find (and may have too few frames to differentiate)


@dataclass(frozen=True)
class AnalysisConfig:
    """How clips are analysed and grouped when a database is built."""

    beat_method: str = "pca"        # "pca" (Xu's short-term PCA) or "kinematic" (speed minima)
    snap_beats: float = 0.15        # PCA beats move to a speed minimum within this fraction of a beat (0: off)
    max_fps: float = 60.0           # faster captures are decimated to this rate
    tempo_bin_bpm: float = 40.0     # width of the tempo ranges that split a genre (§3.2)
    min_style_minutes: float = 1.0  # a tempo range with less motion joins its nearest neighbour
    min_beats_per_clip: int = 3     # clips with fewer motion beats carry no usable edge


# ---------------------------------------------------------------------------------------------
# Analysis of one clip


@dataclass
class ClipAnalysis:
    beat_frames: np.ndarray
    energy: np.ndarray
    contacts: np.ndarray
    tempo_bpm: float


def analyse_clip(clip: MotionClip, config: AnalysisConfig = AnalysisConfig(), *,
                 tempo_prior: tuple[float, float] = (110.0, 1.0)) -> ClipAnalysis:
    """Motion beats, kinetic energy per frame and foot contacts of one clip.

    ``tempo_prior`` is (centre bpm, width in octaves) for inducing regular beats.
    """
    sk = clip.skeleton
    g_rot, g_pos = fk(clip.local_rot, clip.root_pos, sk.offsets, sk.parents, clip.local_pos)
    accents, _ = motion_beats.kinematic_beats(motion_beats.summed_speed(g_pos, clip.fps), clip.fps)
    if config.beat_method == "pca":
        regular = motion_beats.pca_beats(g_pos, g_rot[:, 0], clip.fps, start_bpm=tempo_prior[0],
                                         std_bpm=tempo_prior[1])
        tempo_bpm = bpm_from_intervals(np.diff(regular) / clip.fps)  # the pulse, before snapping
        beats = motion_beats.snap_beats(regular, accents, fraction=config.snap_beats)
    elif config.beat_method == "kinematic":
        beats = accents
        tempo_bpm = bpm_from_intervals(np.diff(beats) / clip.fps)
    else:
        raise InputError(f"unknown beat method '{config.beat_method}' (use 'pca' or 'kinematic')")
    energy = kinetic_energy(g_pos, clip.fps, bone_masses(sk))
    contacts = foot_contacts(foot_points(clip, find_roles(sk), g_rot, g_pos), clip.fps)
    return ClipAnalysis(beats, energy, contacts, tempo_bpm)


# ---------------------------------------------------------------------------------------------
# Building


def _leg_length(skeleton: Skeleton) -> float:
    roles = find_roles(skeleton)
    return float(sum(np.linalg.norm(skeleton.offsets[j]) for j in (roles.knees[0], roles.ankles[0])))


def build_database(sources: Iterable[tuple[str, Path]], config: AnalysisConfig = AnalysisConfig(),
                   *, progress: Callable[[str], None] | None = None, rigs: dict[Path, Rig] | None = None,
                   licences: dict[Path, tuple[str, str]] | None = None,
                   tempo_bins: dict[str, float] | None = None, mirror: Iterable[str] = ()) -> MotionDatabase:
    """Read, analyse and group BVH clips into styles (``rigs``: how to read some of them, ``collect_rigs``;
    ``licences``: each file's licence, ``collect_licences``; ``tempo_bins``: a genre's own tempo-range
    width, ``collect_tempo_bins``; ``mirror``: the genres danced with mirrored takes too,
    ``collect_mirrored``)."""
    mirror = set(mirror)
    groups: dict[tuple, list] = {}
    for genre, path in sources:
        if progress:
            progress(str(path))
        clip = read_clip(path, (rigs or {}).get(Path(path)))
        fps = clip.fps / max(1, round(clip.fps / config.max_fps)) if clip.fps > config.max_fps * 1.01 else clip.fps
        key = (genre, clip.skeleton.names, tuple(clip.skeleton.parents))
        groups.setdefault(key, []).append((Path(path), clip, fps))
    if not groups:
        raise InputError("no motion clips to build a database from")
    topologies_per_genre: dict[str, int] = {}
    for genre, *_ in groups:
        topologies_per_genre[genre] = topologies_per_genre.get(genre, 0) + 1

    styles: dict[str, Style] = {}
    for (genre, names, _), members in groups.items():
        canon = members[0][1].skeleton
        fps = min(m[2] for m in members)
        analysed = []
        for path, clip, _ in members:
            if clip.duration_s < MIN_CLIP_S:  # too short for a beat: nothing to analyse or dance
                continue
            rot_, pos_, _ = resample_clip_arrays(clip.local_rot, clip.root_pos, None, clip.fps, fps)
            pos_ = pos_ * (_leg_length(canon) / _leg_length(clip.skeleton))
            c = MotionClip(canon, fps, pos_, rot_, meta={"name": path.stem, "source": str(path),
                                                         "licence": (licences or {}).get(path, ("",))[0]})
            a = analyse_clip(c, config)
            if len(a.beat_frames) >= config.min_beats_per_clip:
                analysed.append((c, a))
        analysed = _consistent_metre(analysed, config)
        if not analysed:
            continue
        base = genre if topologies_per_genre[genre] == 1 else f"{genre}-{len(names)}j"
        width = (tempo_bins or {}).get(genre, config.tempo_bin_bpm)
        for name, part in _split_by_tempo(base, analysed, width, config.min_style_minutes).items():
            styles[name] = _style_from(name, genre, canon, fps, part)
            if genre in mirror:
                styles[name].mirror = _check_mirrorable(styles[name])
    if not styles:
        raise InputError(f"no clip had at least {config.min_beats_per_clip} motion beats: the database "
                         "needs dance clips several seconds long")
    return MotionDatabase(styles)


#: A skeleton whose paired bones differ by more than this share of its leg length is too lopsided to
#: mirror (the mirrored take's feet would not meet the floor where the original's did).
MIRROR_TOLERANCE = 0.05


def _check_mirrorable(style: Style) -> bool:
    """True where the style's skeleton has left/right pairs and is near symmetric, else an ``InputError``."""
    sk = style.skeleton
    if np.all(mirror_pairs(sk) == np.arange(sk.n_joints)):
        raise InputError(f"style '{style.name}' cannot be mirrored: its joint names have no left/right pairs; "
                         "leave its genre out of the manifest's [mirror] table")
    err, leg = symmetry_error(sk), _leg_length(sk)
    if err > MIRROR_TOLERANCE * leg:
        raise InputError(f"style '{style.name}' cannot be mirrored: its left and right bones differ by up to "
                         f"{err:.3g} (leg length {leg:.3g}); leave its genre out of the manifest's [mirror] table")
    return True


def _consistent_metre(analysed: list, config: AnalysisConfig) -> list:
    """Re-count clips whose beat is far from the genre's at the genre's metrical level.

    A beat tracker may count one take in quarter notes and the next in dotted or half
    notes; jumps between such clips would not land on the same kind of beat. Clips
    more than 25 % away from the genre's (duration-weighted) median tempo are tracked
    again with a narrow prior around it, and keep the new beats if they moved closer.
    """
    if config.beat_method != "pca" or len(analysed) < 2:
        return analysed
    tempi = np.array([a.tempo_bpm for _, a in analysed])
    weights = np.array([c.n_frames for c, _ in analysed], dtype=float)
    order = np.argsort(tempi)
    median = float(tempi[order][np.searchsorted(np.cumsum(weights[order]), weights.sum() / 2)])
    out = []
    for c, a in analysed:
        if abs(np.log(a.tempo_bpm / median)) > np.log(1.25):
            again = analyse_clip(c, config, tempo_prior=(median, 0.25))
            if (len(again.beat_frames) >= config.min_beats_per_clip
                    and abs(np.log(again.tempo_bpm / median)) < abs(np.log(a.tempo_bpm / median))):
                a = again
        out.append((c, a))
    return out


def _split_by_tempo(base: str, analysed: list, width: float, min_minutes: float) -> dict[str, list]:
    """Split a genre into tempo ranges of fixed width (§3.2), merging ranges too small to dance on.

    The ranges' edges sit in the widest gaps between the clips' tempi (``_range_origin``): an edge
    through a cluster of takes at one tempo (seven G1 routines at 100-103 bpm, on an edge at 100)
    would part takes that dance alike and leave both halves short of material at that tempo."""
    tempi = np.array([a.tempo_bpm for _, a in analysed])
    minutes = np.array([c.n_frames / c.fps / 60.0 for c, _ in analysed])
    bins = np.floor((tempi - _range_origin(tempi, width)) / width).astype(int)
    while len(set(bins)) > 1:
        labels = sorted(set(bins))
        size = {b: minutes[bins == b].sum() for b in labels}
        small = min(labels, key=lambda b: size[b])
        if size[small] >= min_minutes:
            break
        centre = {b: np.median(tempi[bins == b]) for b in labels}
        target = min((b for b in labels if b != small), key=lambda b: abs(np.log(centre[b] / centre[small])))
        bins[bins == small] = target
    groups = {b: [x for x, bb in zip(analysed, bins) if bb == b] for b in sorted(set(bins))}
    if len(groups) == 1:
        return {base: analysed}
    return {f"{base}-{tempi[bins == b].min():.0f}-{tempi[bins == b].max():.0f}bpm": g for b, g in groups.items()}


def _range_origin(tempi: np.ndarray, width: float) -> float:
    """Where the tempo ranges start (mod ``width``): the origin, in 0.5 bpm steps, whose range edges are
    farthest from every clip's tempo, the fewest ranges first, then the lowest origin (0 on ties, the
    plain multiples of the width)."""
    origins = np.arange(0.0, width, 0.5)
    edge_gap = np.array([np.min(np.abs((tempi - o + width / 2) % width - width / 2)) for o in origins])
    count = np.array([len(np.unique(np.floor((tempi - o) / width))) for o in origins])
    return float(origins[np.lexsort((origins, -edge_gap, count))[0]])


def _style_from(name, genre, skeleton, fps, analysed) -> Style:
    starts = np.cumsum([0] + [c.n_frames for c, _ in analysed])
    return Style(
        name=name, genre=genre, skeleton=skeleton, fps=float(fps),
        clip_names=tuple(c.meta["name"] for c, _ in analysed),
        clip_sources=tuple(c.meta["source"] for c, _ in analysed),
        clip_starts=starts,
        local_rot=np.concatenate([c.local_rot for c, _ in analysed]).astype(np.float32),
        root_pos=np.concatenate([c.root_pos for c, _ in analysed]).astype(np.float32),
        contacts=np.concatenate([a.contacts for _, a in analysed]),
        energy=np.concatenate([a.energy for _, a in analysed]).astype(np.float32),
        beat_frames=np.concatenate([a.beat_frames + s for (_, a), s in zip(analysed, starts)]).astype(np.int64),
        clip_tempo_bpm=np.array([a.tempo_bpm for _, a in analysed]),
        clip_licences=tuple(c.meta["licence"] for c, _ in analysed),
        fingerprint=_fingerprint(*(c.local_rot for c, _ in analysed), *(a.beat_frames for _, a in analysed)),
    )


def _fingerprint(*arrays) -> str:
    h = hashlib.blake2b(digest_size=16)
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


# ---------------------------------------------------------------------------------------------
# Storage


def _skeleton_to_json(sk: Skeleton) -> dict:
    return {"names": list(sk.names), "parents": sk.parents.tolist(), "offsets": sk.offsets.tolist(),
            "channels": [list(c) for c in sk.channels],
            "end_sites": {str(j): o.tolist() for j, o in sk.end_sites.items()}}


def _skeleton_from_json(d: dict) -> Skeleton:
    return Skeleton(tuple(d["names"]), np.array(d["parents"]), np.array(d["offsets"]),
                    tuple(tuple(c) for c in d["channels"]),
                    {int(j): np.array(o) for j, o in d["end_sites"].items()})


def _style_from_stored(name: str, meta: dict, arr: dict, fingerprint: str) -> Style:
    """A ``Style`` from its database.json entry and .npz arrays, every shape and range checked
    (a damaged or hand-edited database must be an error, not NaN motion or an IndexError later)."""
    sk = _skeleton_from_json(meta["skeleton"])
    n_j = len(sk.names)
    parents = np.asarray(sk.parents)
    if (parents.shape != (n_j,) or n_j == 0 or parents[0] != -1 or np.any(parents[1:] < 0)
            or np.any(parents[1:] >= np.arange(1, n_j)) or sk.offsets.shape != (n_j, 3)
            or not np.all(np.isfinite(sk.offsets)) or len(sk.channels) != n_j or len(set(sk.names)) != n_j):
        raise ValueError("the skeleton's names, parents, offsets or channels disagree")
    fps = float(meta["fps"])
    if not 1.0 <= fps <= 1000.0:
        raise ValueError(f"frame rate {fps}")
    root_pos, moving, static = arr["root_pos"], arr["moving"], arr["static_rot"]
    n_f = len(root_pos)
    clips, sources = tuple(meta["clips"]), tuple(meta["sources"])
    starts, beats = arr["clip_starts"], arr["beat_frames"]
    shapes_ok = (root_pos.shape == (n_f, 3) and moving.shape == (n_j,) and moving.dtype == bool
                 and static.shape == (n_j, 4) and arr["rot_q"].shape == (n_f, int(moving.sum()), 4)
                 and arr["contacts"].shape == (n_f, 2) and arr["energy"].shape == (n_f,)
                 and starts.shape == (len(clips) + 1,) and len(sources) == len(clips)
                 and arr["clip_tempo_bpm"].shape == (len(clips),) and beats.ndim == 1)
    if not shapes_ok or not clips:
        raise ValueError("array shapes disagree with each other or with the clip list")
    if starts.dtype.kind not in "iu" or beats.dtype.kind not in "iu" or arr["rot_q"].dtype != np.int16:
        raise ValueError("frame indices or rotations of the wrong type")
    if starts[0] != 0 or starts[-1] != n_f or np.any(np.diff(starts) <= 0) or np.any((beats < 0) | (beats >= n_f)):
        raise ValueError("clip ranges or beats outside the frames")
    rot = np.repeat(static[None].astype(np.float32), n_f, axis=0)
    rot[:, moving] = arr["rot_q"].astype(np.float32) / 32767.0
    with np.errstate(invalid="ignore", divide="ignore"):
        rot /= np.linalg.norm(rot, axis=-1, keepdims=True)
    for what, a in (("rotations", rot), ("root positions", root_pos), ("energies", arr["energy"]),
                    ("clip tempi", arr["clip_tempo_bpm"])):
        if a.dtype.kind != "f" or not np.all(np.isfinite(a)):
            raise ValueError(f"{what} are not finite numbers")
    return Style(name=name, genre=str(meta["genre"]), skeleton=sk, fps=fps, clip_names=clips, clip_sources=sources,
                 clip_starts=starts, local_rot=rot, root_pos=root_pos, contacts=arr["contacts"].astype(bool),
                 energy=arr["energy"], beat_frames=beats, clip_tempo_bpm=arr["clip_tempo_bpm"],
                 fingerprint=fingerprint, clip_licences=_licences(meta, len(clips)), mirror=_flag(meta, "mirror"))


def _flag(meta: dict, key: str) -> bool:
    value = meta.get(key, False)
    if not isinstance(value, bool):
        raise ValueError(f"'{key}' must be true or false")
    return value


def _licences(meta: dict, n_clips: int) -> tuple[str, ...]:
    """A stored style's per-clip licences (none recorded: empty strings)."""
    got = meta.get("licences") or [""] * n_clips
    if not isinstance(got, list) or len(got) != n_clips or not all(isinstance(x, str) for x in got):
        raise ValueError("the clip licences disagree with the clip list")
    return tuple(got)


def save_database(db: MotionDatabase, folder: Path) -> None:
    """Write ``db`` to ``folder`` (created if needed) in the compact on-disk form: all its files or,
    when one cannot be written (a full disk), none."""
    with atomic_folder(folder) as tmp:
        _save_database(db, tmp)


def _save_database(db: MotionDatabase, folder: Path) -> None:
    index = {"format": FORMAT_VERSION, "source": db.source, "notes": db.notes, "styles": {}}
    for name, st in db.styles.items():
        q = st.local_rot.astype(np.float64)
        q = q * np.where(q[..., 3:4] < 0, -1.0, 1.0)  # one hemisphere, so quantisation is stable
        moving = np.any(np.abs(q - q[:1]) > 1e-5, axis=(0, 2))
        moving[0] = True
        with open(folder / f"{name}.npz", "wb") as fh:
            np.savez_compressed(
                fh, rot_q=np.round(q[:, moving] * 32767).astype(np.int16), moving=moving,
                static_rot=q[0].astype(np.float32), root_pos=st.root_pos, contacts=st.contacts,
                energy=st.energy, beat_frames=st.beat_frames, clip_starts=st.clip_starts,
                clip_tempo_bpm=st.clip_tempo_bpm)
        index["styles"][name] = {
            "genre": st.genre, "fps": st.fps, "skeleton": _skeleton_to_json(st.skeleton),
            "clips": list(st.clip_names), "sources": list(st.clip_sources), "licences": list(st.clip_licences),
            **({"mirror": True} if st.mirror else {})}
    with open(folder / "database.json", "w") as fh:
        json.dump(index, fh, indent=1)


#: Databases already loaded in this process, by folder and its files' sizes and times: a batch, a
#: server or a loop of ``dance()`` calls loads each database once (0.2 s and ~100 MB each time).
_LOADED: dict[tuple, MotionDatabase] = {}
_MAX_LOADED = 4


def load_database(folder: Path) -> MotionDatabase:
    """Load a database folder written by ``save_database`` (once per process while its files are
    unchanged: the arrays are read-only, shared by every caller)."""
    folder = Path(folder)
    try:
        key = (str(folder.resolve()),) + tuple(sorted((p.name, p.stat().st_size, p.stat().st_mtime_ns)
                                                      for p in folder.iterdir() if p.is_file()))
    except OSError:
        key = None  # an unreadable folder: the loader below says what is wrong
    if key in _LOADED:
        return _LOADED[key]
    db = _load_database(folder)
    for style in db.styles.values():
        for a in (style.local_rot, style.root_pos, style.contacts, style.energy, style.beat_frames,
                  style.clip_starts, style.clip_tempo_bpm):
            a.setflags(write=False)
    if key is not None:
        while len(_LOADED) >= _MAX_LOADED:
            _LOADED.pop(next(iter(_LOADED)))
        _LOADED[key] = db
    return db


def _load_database(folder: Path) -> MotionDatabase:
    try:
        index = json.loads((folder / "database.json").read_text())
    except FileNotFoundError:
        raise InputError(f"{folder} is not a dancesynth database (no database.json)") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ModelError(f"{folder / 'database.json'} is corrupt ({exc}); rebuild the database") from None
    if not isinstance(index, dict) or index.get("format") != FORMAT_VERSION:
        raise ModelError(f"{folder} was written by another dancesynth version; rebuild it with 'dancesynth build-db'")
    if not isinstance(index.get("styles"), dict) or not index["styles"]:
        raise ModelError(f"{folder / 'database.json'} lists no styles; rebuild the database")
    styles = {}
    for name, meta in index["styles"].items():
        # The name becomes a file name: "../x" must not read beside the folder.
        if not name or name in (".", "..") or any(c in name for c in "/\\\x00"):
            raise ModelError(f"{folder / 'database.json'}: style name {name[:40]!r} is not a file name; "
                             "rebuild the database")
        path = folder / f"{name}.npz"
        try:
            raw = path.read_bytes()
            with np.load(path) as z:
                arr = {k: z[k] for k in z.files}
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
            raise ModelError(f"{path} is missing or corrupt ({exc}); rebuild the database") from None
        try:
            styles[name] = _style_from_stored(name, meta, arr, hashlib.blake2b(raw, digest_size=16).hexdigest())
        except (KeyError, TypeError, ValueError, AttributeError, IndexError, InputError) as exc:
            why = f"{type(exc).__name__}: {exc}".splitlines()[0][:200]
            raise ModelError(f"{path} or its entry in database.json is corrupt ({why}); rebuild the database") from None
    return MotionDatabase(styles, source=str(folder), notes=index.get("notes", {}))


# ---------------------------------------------------------------------------------------------
# Finding a database


def open_database(path: Path | None = None, config: AnalysisConfig = AnalysisConfig(), *,
                  progress: Callable[[str], None] | None = None) -> MotionDatabase:
    """The bundled database (``path=None``), a saved database folder, or a folder of BVH files.

    A folder of BVH files is analysed once and the result cached; editing, adding or
    removing a file, or changing ``config``, rebuilds it.
    """
    if path is None:
        return load_database(BUNDLED_DATABASE)
    path = Path(path)
    if not path.is_dir():
        raise InputError(f"database folder {path} does not exist")
    if (path / "database.json").is_file():
        return load_database(path)
    sources = collect_sources(path)
    options = manifest_options(path)
    h = hashlib.blake2b(repr((FORMAT_VERSION, config)).encode(), digest_size=16)
    for rig in {id(r): r for r in options["rigs"].values()}.values():
        h.update(rig.source.encode())
    if (path / MANIFEST_NAME).is_file():
        h.update((path / MANIFEST_NAME).read_bytes())
    # The analysis code is part of the key, so improving it re-analyses cached folders.
    package = Path(__file__).resolve().parents[1]
    for code in sorted([*package.joinpath("motion").glob("*.py"), package / "beat_tracking.py",
                        *package.joinpath("io").glob("*.py")]):
        h.update(code.read_bytes())
    for genre, p in sources:
        st = p.stat()
        h.update(f"{genre}|{p.resolve()}|{st.st_size}|{st.st_mtime_ns}".encode())
    cached = cache_dir() / "databases" / h.hexdigest()
    if (cached / "database.json").is_file():
        try:
            return load_database(cached)
        except ModelError:
            pass  # a damaged cache entry is rebuilt below
    db = build_database(sources, config, progress=progress, **options)
    db.source = str(path)
    save_database(db, cached)
    return load_database(cached)

"""The sources of a database folder: which motion files, of which genre, read how, under which licence.

A folder has one sub-folder per genre, or a ``genres.toml`` manifest (``MANIFEST_NAME``) that maps
file patterns to genres and may add tables: ``[rigs.NAME]`` (a chain map that reads a non-humanoid
skeleton as a humanoid, and whether to mend its one-frame snaps), ``[tempo_bins]`` (a genre's own
tempo-range width), ``[mirror]`` (the genres danced with mirrored takes too) and ``[licences]``.
``motion.database.build_database`` reads what these functions collect.
"""

from __future__ import annotations

import fnmatch
import tomllib
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError
from ..types import MotionClip

MANIFEST_NAME = "genres.toml"
# The suffixes io.motion_files reads (BVH, AIST++, CMU ASF/AMC), named here too: importing its readers
# costs 60 ms, which only building a database needs (tests/test_database.py checks the two agree).
MOTION_SUFFIXES = (".bvh", ".pkl", ".amc")


def _genre_of(path: Path, folder: Path) -> str:
    """A file's genre without a manifest: the genre its public set's naming states (AIST++ and Motorica
    ``gXX`` codes, LaFAN1, Bandai Namco; a CMU trial number only for files not sorted into a sub-folder),
    else its sub-folder's name (the folder's own name for files at the top)."""
    from ..io.asf_amc import cmu_subject_trial
    from ..io.motion_files import genre_from_name

    named = genre_from_name(path)
    if named and (path.parent == folder or cmu_subject_trial(path.stem) is None):
        return named
    return path.parent.name if path.parent != folder else folder.name


def collect_sources(folder: Path, manifest: Path | None = None) -> list[tuple[str, Path]]:
    """(genre, bvh path) pairs of a folder: from a genres manifest or its sub-folder names.

    The manifest (``genres.toml`` in the folder unless given) maps each genre to glob
    patterns relative to the folder::

        [genres]
        salsa = ["cmu_daz_salsa/*.bvh"]
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"database folder {folder} does not exist")
    manifest = Path(manifest) if manifest else folder / MANIFEST_NAME
    try:
        files = sorted(p for p in folder.rglob("*") if p.suffix.lower() in MOTION_SUFFIXES and p.is_file())
    except OSError as exc:  # a folder that changes or cannot be listed while we walk it (/proc, a lost mount)
        raise InputError(f"cannot list the files of {folder} ({exc.strerror or exc}); give a folder of BVH "
                         "files or a saved database") from None
    if manifest.is_file() or manifest != folder / MANIFEST_NAME:
        try:
            genres = tomllib.loads(manifest.read_text())["genres"]
        except (OSError, tomllib.TOMLDecodeError, KeyError, UnicodeDecodeError) as exc:
            raise InputError(f"{manifest}: not a valid genres manifest ({exc}); "
                             "it needs a [genres] table of genre = [glob patterns]") from None
        if not isinstance(genres, dict) or not all(
                isinstance(p, str) or (isinstance(p, list) and all(isinstance(x, str) for x in p))
                for p in genres.values()):
            raise InputError(f"{manifest}: 'genres' must be a table of genre = \"pattern\" or [\"pattern\", ...] "
                             f"(glob patterns as strings), e.g. salsa = [\"cmu_daz_salsa/*.bvh\"]")
        out = []
        for genre, patterns in genres.items():
            for pat in [patterns] if isinstance(patterns, str) else patterns:
                out += [(genre, p) for p in files if fnmatch.fnmatch(p.relative_to(folder).as_posix(), pat)]
    else:
        out = [(_genre_of(p, folder), p) for p in files]
    if not out:
        raise InputError(f"no motion files found in {folder}: a database folder needs BVH (or AIST++ .pkl, "
                         "CMU .amc) motion files "
                         f"(one sub-folder per genre, or a {MANIFEST_NAME})")
    return out


@dataclass(frozen=True)
class Rig:
    """How to read a manifest's robot-style clips: a chain map (``motion.chains``) and whether to
    mend their one-frame snaps (``motion.cleanup``)."""

    chains: dict
    mend_snaps: bool = False
    source: str = ""      # the chain map file, for messages and the cache key


def _manifest_table(manifest: Path, key: str) -> dict:
    """The manifest's ``[KEY]`` table ({} without a manifest or such a table)."""
    if not manifest.is_file():
        return {}
    try:
        return tomllib.loads(manifest.read_text()).get(key, {})
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{manifest}: not a valid genres manifest ({exc})") from None


def manifest_options(folder: Path, manifest: Path | None = None) -> dict:
    """What a manifest says beyond the genres, as ``build_database``'s keyword arguments."""
    return {"rigs": collect_rigs(folder, manifest), "licences": collect_licences(folder, manifest),
            "tempo_bins": collect_tempo_bins(folder, manifest), "mirror": collect_mirrored(folder, manifest)}


def _manifest_tables(folder: Path, manifest: Path | None, key: str) -> tuple[Path, list[tuple[str, dict, list[Path]]]]:
    """The manifest's ``[KEY.NAME]`` tables, each with the motion files its ``files`` patterns match."""
    folder = Path(folder)
    manifest = Path(manifest) if manifest else folder / MANIFEST_NAME
    tables = _manifest_table(manifest, key)
    if not tables:
        return manifest, []
    if not isinstance(tables, dict) or not all(isinstance(t, dict) for t in tables.values()):
        raise InputError(f"{manifest}: '{key}' must be tables such as [{key}.name] files = [\"glob\", ...]")
    files = sorted(p for p in folder.rglob("*") if p.suffix.lower() in MOTION_SUFFIXES and p.is_file())
    out = []
    for name, spec in tables.items():
        patterns = spec.get("files")
        if not isinstance(patterns, list) or not all(isinstance(x, str) for x in patterns):
            raise InputError(f"{manifest}: [{key}.{name}] needs files = [\"glob pattern\", ...]")
        out.append((name, spec, [p for p in files if any(fnmatch.fnmatch(p.relative_to(folder).as_posix(), pat)
                                                          for pat in patterns)]))
    return manifest, out


def collect_rigs(folder: Path, manifest: Path | None = None) -> dict[Path, Rig]:
    """The manifest's ``[rigs.NAME]`` tables: BVH file -> ``Rig``, for clips on skeletons the humanoid
    finders cannot read by name::

        [rigs.g1]
        files = ["g1_moves_ccby/*.bvh"]
        chains = "g1_chains.toml"      # relative to the manifest
        mend_snaps = true
    """
    from .chains import read_chain_map

    manifest, tables = _manifest_tables(folder, manifest, "rigs")
    out = {}
    for name, spec, files in tables:
        chains = spec.get("chains")
        if not isinstance(chains, str) or not isinstance(spec.get("mend_snaps", False), bool):
            raise InputError(f"{manifest}: [rigs.{name}] needs chains = \"map.toml\" (and optionally mend_snaps = true)")
        path = manifest.parent / chains
        rig = Rig(read_chain_map(path), spec.get("mend_snaps", False), path.read_text())
        out.update({p: rig for p in files})
    return out


def collect_tempo_bins(folder: Path, manifest: Path | None = None) -> dict[str, float]:
    """The manifest's ``[tempo_bin_bpm]`` table: genre -> the width of its tempo ranges, where a genre
    spans a wide range of tempi and one style for all would warp most beat pieces (``pop = 20``)."""
    manifest = Path(manifest) if manifest else Path(folder) / MANIFEST_NAME
    table = _manifest_table(manifest, "tempo_bin_bpm")
    if not isinstance(table, dict) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                              and 5 <= v <= 200 for v in table.values()):
        raise InputError(f"{manifest}: [tempo_bin_bpm] must map genres to widths of 5-200 bpm, e.g. pop = 20")
    return {str(k): float(v) for k, v in table.items()}


def collect_mirrored(folder: Path, manifest: Path | None = None) -> tuple[str, ...]:
    """The manifest's ``[mirror]`` table: the genres danced with mirrored takes too (``Style.material``)::

        [mirror]
        genres = ["salsa", "pop"]
    """
    manifest = Path(manifest) if manifest else Path(folder) / MANIFEST_NAME
    table = _manifest_table(manifest, "mirror")
    genres = table.get("genres", []) if isinstance(table, dict) else None
    if not isinstance(genres, list) or not all(isinstance(g, str) for g in genres):
        raise InputError(f"{manifest}: [mirror] needs genres = [\"genre\", ...]")
    return tuple(genres)


def collect_licences(folder: Path, manifest: Path | None = None) -> dict[Path, tuple[str, str]]:
    """The manifest's ``[licences.NAME]`` tables: BVH file -> (licence, credit line)::

        [licences.g1_moves]
        files = ["g1_moves_ccby/*.bvh"]
        licence = "CC BY 4.0"
        credit = "G1 Moves dance motion by ..."
    """
    manifest, tables = _manifest_tables(folder, manifest, "licences")
    out = {}
    for name, spec, files in tables:
        licence, credit = spec.get("licence"), spec.get("credit", "")
        if not isinstance(licence, str) or not isinstance(credit, str):
            raise InputError(f"{manifest}: [licences.{name}] needs licence = \"...\" (and credit = \"...\")")
        out.update({p: (licence, credit) for p in files})
    return out


def read_clip(path: Path, rig: Rig | None = None) -> MotionClip:
    """A clip of the database's sources (any format ``io.motion_files`` reads), on a humanoid skeleton
    when a ``rig`` says how."""
    from ..io.motion_files import read_motion  # the readers are only needed when building

    clip = read_motion(path)
    if rig is None:
        return clip
    from .chains import collapse
    from .cleanup import remove_snaps

    clip = collapse(clip, rig.chains, what=str(path))
    if rig.mend_snaps:
        clip, mended = remove_snaps(clip)
        clip.meta["snaps_mended"] = mended
    return clip

"""Which songs a batch dances, and where each dance goes.

Songs come as paths, a list file (one path per line) or a music folder searched recursively.
Each song's dance is ``OUT_DIR/<name><suffix>``: a folder's songs keep their sub-folders (two
albums may both have ``01.mp3``); songs named one by one keep their file name, and where two
share a name, a short hash of their full path tells them apart.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

from ..defaults import AUDIO_SUFFIXES
from ..errors import InputError


@dataclass(frozen=True)
class Job:
    """One song to dance: its file, and its output's path relative to the output folder."""

    song: Path
    name: str      # the output's path under OUT_DIR, e.g. "album/01.bvh"; the manifest's key


def collect_songs(songs=(), *, list_file: Path | None = None, folder: Path | None = None) -> list[tuple[Path, str]]:
    """``(song, output name without suffix)`` for every song given, in order, each once."""
    found: list[tuple[Path, str]] = []
    loose = [Path(s) for s in songs]
    if list_file is not None:
        loose += _read_list(Path(list_file))
    if folder is not None:
        found += _folder_songs(Path(folder))
    found += [(p, p.stem) for p in loose]
    if not found:
        raise InputError("no songs to dance: give song files, --list SONGS.txt or --folder MUSIC_DIR")
    seen, unique = set(), []
    for song, name in found:
        key = os.path.realpath(song)
        if key not in seen:
            seen.add(key)
            unique.append((song, name))
    return _unique_names(unique)


def plan_jobs(songs: list[tuple[Path, str]], suffix: str) -> list[Job]:
    """One job per song, its path made absolute (a worker, a Ray actor above all, may run elsewhere)."""
    return [Job(Path(os.path.abspath(song)), name + suffix) for song, name in songs]


def _read_list(path: Path) -> list[Path]:
    """The paths in a list file, one per line; blank lines and lines starting with # are skipped.
    Relative paths are relative to the list file's folder."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(f"song list {path} does not exist") from None
    except (OSError, UnicodeDecodeError) as exc:
        why = exc.strerror if isinstance(exc, OSError) else "it is not UTF-8 text"
        raise InputError(f"cannot read song list {path}: {why}") from None
    out = []
    for line in text.splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            p = Path(line).expanduser()
            out.append(p if p.is_absolute() else path.parent / p)
    if not out:
        raise InputError(f"song list {path} names no songs (one path per line)")
    return out


def _folder_songs(folder: Path) -> list[tuple[Path, str]]:
    if not folder.is_dir():
        raise InputError(f"music folder {folder} does not exist" if not folder.exists()
                         else f"{folder} is a file, not a music folder")
    out = []
    for root, dirs, files in os.walk(folder, onerror=None):
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        for f in sorted(files):
            p = Path(root) / f
            if p.suffix.lower() in AUDIO_SUFFIXES and not f.startswith("."):
                out.append((p, str(p.relative_to(folder).with_suffix(""))))
    if not out:
        raise InputError(f"music folder {folder} has no audio files ({', '.join(sorted(AUDIO_SUFFIXES))})")
    return out


def _unique_names(songs: list[tuple[Path, str]]) -> list[tuple[Path, str]]:
    """Names that two songs share get a short hash of each song's full path."""
    count: dict[str, int] = {}
    for _, name in songs:
        count[name] = count.get(name, 0) + 1
    return [(p, name if count[name] == 1 else
             f"{name}-{hashlib.blake2b(os.path.realpath(p).encode(), digest_size=3).hexdigest()}")
            for p, name in songs]

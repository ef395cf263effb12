"""What a database holds, read without loading its motion: ``dancesynth styles`` in a blink.

A stored database lists its styles in ``database.json``; the few numbers a listing shows
(tempi, clip and beat counts) are small arrays in each style's ``.npz``, read one by one
without decompressing the rotations. A folder of BVH files has to be analysed first
(``open_database``)."""

from __future__ import annotations

import json
import zipfile
import zlib
from pathlib import Path

from ..errors import InputError, ModelError

FORMAT_VERSION = 1
BUNDLED_DATABASE = Path(__file__).resolve().parents[1] / "data" / "database"


def list_styles(database=None) -> list[dict]:
    """The styles of a database (a ``MotionDatabase``, a folder, or ``None`` for the bundled one):
    name, genre, tempo range, clips, minutes, beats, joints, frame rate; sorted by name."""
    if database is None or not hasattr(database, "styles"):
        folder = BUNDLED_DATABASE if database is None else Path(database)
        if (folder / "database.json").is_file():
            return _stored_rows(folder)
        from .database import open_database

        database = open_database(folder)
    return sorted((_row(s.name, s.genre, s.clip_tempo_bpm, s.n_clips, s.n_frames, s.fps, len(s.beat_frames),
                        s.skeleton.n_joints, s.licences, s.mirror) for s in database.styles.values()),
                  key=lambda r: r["name"])


def _row(name, genre, tempi, clips, frames, fps, beats, joints, licences, mirror) -> dict:
    """A listing row. ``minutes`` is captured motion; ``mirrored_minutes`` the mirrored takes the style is
    also danced with (``Style.material``), counted apart."""
    minutes = frames / fps / 60.0
    return {"name": name, "genre": genre, "tempo_min_bpm": float(min(tempi)), "tempo_max_bpm": float(max(tempi)),
            "clips": int(clips), "minutes": minutes, "mirrored_minutes": minutes if mirror else 0.0,
            "beats": int(beats), "joints": int(joints), "fps": float(fps), "licence": ", ".join(licences)}


def _stored_rows(folder: Path) -> list[dict]:
    import numpy as np

    index_path = folder / "database.json"
    try:
        index = json.loads(index_path.read_text())
        if index.get("format") != FORMAT_VERSION:
            raise ModelError(f"{folder} was written by another dancesynth version; rebuild it with "
                             "'dancesynth build-db'")
        rows = []
        for name, meta in index["styles"].items():
            if not name or name in (".", "..") or any(c in name for c in "/\\\x00"):
                raise ValueError(f"style name {name[:40]!r} is not a file name")
            with np.load(folder / f"{name}.npz") as z:  # members load lazily: the rotations stay on disk
                tempi, starts, beats = z["clip_tempo_bpm"], z["clip_starts"], z["beat_frames"]
            if len(tempi) == 0 or len(starts) != len(tempi) + 1:
                raise ValueError(f"style {name}: no clips, or clip ranges that disagree with its tempi")
            licences = meta.get("licences") or [""] * len(tempi)
            rows.append(_row(name, str(meta["genre"]), tempi, len(tempi), int(starts[-1]), float(meta["fps"]),
                             len(beats), len(meta["skeleton"]["names"]),
                             tuple(dict.fromkeys(str(x) or "unrecorded" for x in licences)), meta.get("mirror") is True))
    except FileNotFoundError as exc:
        raise InputError(f"{folder}: {exc.filename} is missing; rebuild the database") from None
    except (OSError, ValueError, KeyError, TypeError, AttributeError, EOFError, zipfile.BadZipFile,
            zlib.error) as exc:
        why = f"{type(exc).__name__}: {exc}".splitlines()[0][:200]
        raise ModelError(f"{folder} is not a readable dancesynth database ({why}); rebuild it") from None
    if not rows:
        raise ModelError(f"{index_path} lists no styles; rebuild the database")
    return sorted(rows, key=lambda r: r["name"])

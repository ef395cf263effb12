"""The batch's record: ``OUT_DIR/manifest.jsonl``, one JSON line per song danced or failed.

Lines are appended as songs finish, so an interrupted batch keeps what it did; the last line
for a song is its state. A re-run skips a song whose last line says ``done`` with the same
settings, the song file unchanged and the dance still in place, and dances the rest.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

from ..errors import InputError
from ..io.files import jsonable

MANIFEST_NAME = "manifest.jsonl"


def settings_key(settings: dict) -> str:
    """A short stable hash of what a dance depends on besides the song (config, database, character)."""
    return hashlib.blake2b(json.dumps(jsonable(settings), sort_keys=True).encode(), digest_size=8).hexdigest()


def song_stamp(song: Path) -> dict:
    """What tells whether a song file changed since it was danced."""
    st = song.stat()
    return {"song_bytes": st.st_size, "song_mtime_ns": st.st_mtime_ns}


class Manifest:
    """The manifest of one output folder."""

    def __init__(self, out_dir: Path):
        self.path = Path(out_dir) / MANIFEST_NAME
        self._fh = None

    def last_records(self) -> dict[str, dict]:
        """The last record per output name. A torn last line (a crash mid-write) is ignored."""
        out: dict[str, dict] = {}
        try:
            with open(self.path, encoding="utf-8") as fh:
                for line in fh:
                    try:
                        rec = json.loads(line)
                    except json.JSONDecodeError:
                        continue
                    if isinstance(rec, dict) and isinstance(rec.get("name"), str):
                        out[rec["name"]] = rec
        except FileNotFoundError:
            pass
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"cannot read the batch manifest {self.path}: {exc}") from None
        return out

    def is_done(self, record: dict | None, song: Path, settings: str, out_dir: Path) -> bool:
        if not record or record.get("status") != "done" or record.get("settings") != settings:
            return False
        try:
            stamp = song_stamp(song)
        except OSError:
            return False
        return all(record.get(k) == v for k, v in stamp.items()) and (Path(out_dir) / record["name"]).is_file()

    def append(self, record: dict) -> None:
        """Add one line, flushed and synced: the record survives the batch being killed next."""
        if self._fh is None:
            torn = False
            if self.path.is_file() and self.path.stat().st_size > 0:
                with open(self.path, "rb") as fh:
                    fh.seek(-1, os.SEEK_END)
                    torn = fh.read(1) != b"\n"
            self._fh = open(self.path, "a", encoding="utf-8")
            if torn:
                self._fh.write("\n")  # the torn line of a killed run must not swallow ours
        self._fh.write(json.dumps(jsonable(record), allow_nan=False) + "\n")
        self._fh.flush()
        os.fsync(self._fh.fileno())

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

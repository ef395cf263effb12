"""Uploaded songs the server keeps while their dances are made and played: a bounded folder (``UploadStore``)."""

from __future__ import annotations

import re
import shutil
import tempfile
import threading
import time
import uuid
from pathlib import Path

_UPLOAD_ID = re.compile(r"^[0-9a-f]{32}(\.[a-z0-9]{1,5})?$")


class UploadStore:
    """A bounded folder of uploaded songs, kept so the page can play them.

    At most ``max_files`` files at any time. An upload is *pending* from ``new_path`` until
    ``done`` (its dance is finished) and is never removed meanwhile: a song waiting for a dance
    slot must still be there when its turn comes. A finished upload may go, oldest first, once
    it has been served (the page fetched it to play along) or ``grace_s`` after its dance was
    done, and in any case ``max_age_s`` after. When every place is taken by uploads that may
    not go yet, ``new_path`` returns None: the server is busy, and says so, rather than
    delete a song someone is waiting for or let the folder grow. A song being rendered into
    a video is ``hold``-ed and stays until it is ``release``-d.
    """

    def __init__(self, *, max_files: int = 8, max_age_s: float = 3600.0, grace_s: float = 60.0):
        self.dir = Path(tempfile.mkdtemp(prefix="dancesynth-uploads-"))
        self.max_files = max_files
        self.max_age_s = max_age_s
        self.grace_s = grace_s
        self._lock = threading.Lock()
        # upload id -> {"t": stored, "done": time or None, "served": bool, "holds": videos being rendered}
        self._files: dict[str, dict] = {}

    def new_path(self, filename: str | None) -> tuple[str, Path] | None:
        suffix = Path(filename or "").suffix.lower()
        suffix = suffix if re.fullmatch(r"\.[a-z0-9]{1,5}", suffix) else ""
        key = uuid.uuid4().hex + suffix
        with self._lock:
            self._prune(keep=self.max_files - 1)
            if len(self._files) >= self.max_files:
                return None
            self._files[key] = {"t": time.time(), "done": None, "served": False, "holds": 0}
        return key, self.dir / key

    def done(self, key: str) -> None:
        """The upload's dance is finished: it may be served now, and go later."""
        with self._lock:
            if key in self._files:
                self._files[key]["done"] = time.time()

    def discard(self, key: str) -> None:
        with self._lock:
            self._files.pop(key, None)
            (self.dir / key).unlink(missing_ok=True)

    def path(self, key: str) -> Path | None:
        """Where a danced upload is, to be sent; ``served`` once it has been (not before: it could go meanwhile)."""
        if not _UPLOAD_ID.match(key):
            return None
        with self._lock:
            entry = self._files.get(key)
            if entry is None or entry["done"] is None:
                return None
        p = self.dir / key
        return p if p.is_file() else None

    def served(self, key: str) -> None:
        with self._lock:
            if key in self._files:
                self._files[key]["served"] = True

    def hold(self, key: str) -> Path | None:
        """A danced upload's path, kept until ``release``; None if it is gone already."""
        with self._lock:
            entry = self._files.get(key)
            if entry is None or entry["done"] is None or not (self.dir / key).is_file():
                return None
            entry["holds"] += 1
        return self.dir / key

    def release(self, key: str) -> None:
        with self._lock:
            if key in self._files:
                self._files[key]["holds"] -= 1

    def _prune(self, keep: int) -> None:
        now = time.time()
        for key, e in sorted(self._files.items(), key=lambda kv: kv[1]["t"]):
            if e["holds"]:
                continue
            expired = now - e["t"] > self.max_age_s
            finished = e["done"] is not None and (e["served"] or now - e["done"] > self.grace_s)
            if expired or (len(self._files) > keep and finished):
                self._files.pop(key)
                (self.dir / key).unlink(missing_ok=True)

    def close(self) -> None:
        shutil.rmtree(self.dir, ignore_errors=True)

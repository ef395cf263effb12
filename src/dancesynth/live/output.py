"""The growing BVH of a live dance, complete on disk after every segment whatever happens."""

from __future__ import annotations

import contextlib
import os

from ..errors import InputError
from ..io.bvh_writer import BVHStreamWriter


class CompleteBVHWriter(BVHStreamWriter):
    """A growing BVH that stays complete when a write fails (a full disk): the file is cut back to its
    last complete segment (removed if there was none) and the failure is a one-line error."""

    def __init__(self, path):
        super().__init__(path)
        self._complete_bytes = 0
        self._failed: InputError | None = None

    def append(self, clip) -> None:
        if self._failed is not None:  # a segment queued behind the failed one: the file stays as it was cut
            raise self._failed
        try:
            super().append(clip)
            self._complete_bytes = os.fstat(self._fh.fileno()).st_size if self._fh else 0
        except OSError as exc:
            if self._fh is not None:  # (None: the file could not even be opened)
                with contextlib.suppress(OSError):
                    self._fh.close()  # its buffer cannot be written either; the cut below drops any part of it
            self._fh = None
            if self._complete_bytes:
                os.truncate(self.path, self._complete_bytes)
                kept = f"it holds the dance up to {self.frames / clip.fps:.1f} s"
            else:
                self.path.unlink(missing_ok=True)
                kept = "nothing was written"
            self._failed = InputError(f"cannot write {self.path}: {exc.strerror or exc}; {kept}")
            raise self._failed from None

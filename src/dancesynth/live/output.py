"""Where a live dance goes: the growing BVH, complete on disk after every segment whatever happens, and
the VMC sender (``live.vmc``) that plays it to an avatar app."""

from __future__ import annotations

import contextlib
import os
import time

from ..errors import InputError
from ..io.bvh_writer import BVHStreamWriter


class CompleteBVHWriter(BVHStreamWriter):
    """A growing BVH that stays complete when a write fails (a full disk): the file is cut back to its
    last complete segment (removed if there was none) and the failure is a one-line error."""

    def __init__(self, path):
        super().__init__(path)
        self._complete_bytes = 0
        self._failed: InputError | None = None

    def on_report(self, report) -> None:
        """After a segment's frames (``runtime.SegmentReport``): keep the VMC clock a whole number of bars behind the
        music heard (``VmcSender.align``), at the tempo and metre heard so far."""
        if self.vmc is not None and report.tempo_bpm > 0:
            self.vmc.align(time.perf_counter() - report.ready_s, 60.0 / report.tempo_bpm * report.beats_per_bar)

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


class LiveSinks:
    """Each segment's clip to the BVH at ``output`` (None: no file) and to a VMC receiver at ``address``
    ((host, port); None: none), on ``on_character`` (a ``SegmentRetargeter``; None: the dance's own rig)."""

    def __init__(self, output, address, on_character, fps: float, segment_s: float):
        self.on_character = on_character
        self.writer = CompleteBVHWriter(output) if output is not None else None
        self.vmc = None
        if address is not None:
            from .runtime import segment_lead_s
            from .vmc import MARGIN_S, VmcSender

            if on_character is None:
                raise InputError("VMC sends a humanoid avatar's bones: dance on a character, not the source rig")

            # The VMC clock starts when the next segment will be there before its first frame is due: the
            # first segment (cut early) is followed a segment of audio later by the next.
            self.vmc = VmcSender(*address, fps, margin_s=MARGIN_S + segment_lead_s(segment_s))

    def on_report(self, report) -> None:
        """After a segment's frames (``runtime.SegmentReport``): keep the VMC clock a whole number of bars behind the
        music heard (``VmcSender.align``), at the tempo and metre heard so far."""
        if self.vmc is not None and report.tempo_bpm > 0:
            self.vmc.align(time.perf_counter() - report.ready_s, 60.0 / report.tempo_bpm * report.beats_per_bar)

    def append(self, clip) -> None:
        dressed = clip if self.on_character is None else self.on_character(clip)
        if self.vmc is not None:   # first: the avatar must not wait for the disk
            from .vmc import VmcFrames

            self.vmc.push(VmcFrames.of(dressed, self.on_character.character.bones))
        if self.writer is not None:
            self.writer.append(dressed if self.on_character is None else
                               self.on_character.character.in_own_units(dressed))

    def __enter__(self):
        if self.writer is not None:
            self.writer.__enter__()
        return self

    def __exit__(self, *exc):
        try:
            if self.vmc is not None:
                self.vmc.close(drain=exc[0] is None)
        finally:
            if self.writer is not None:
                self.writer.__exit__(*exc)

"""Audio that arrives over time: a file at real-time pace, standard input, an http(s) stream.

Every source is decoded by one ffmpeg process into mono 16-bit samples at the
analysis rate; a reader thread turns its output into chunks on a bounded queue, so
the consumer can wait with a timeout and notice a stall without blocking. ffmpeg
does what it is good at: formats, resampling, http with reconnection, pacing a
file at its native rate (``-re``).
"""

from __future__ import annotations

import queue
import shutil
import subprocess
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError

SR = 22050
CHUNK_S = 0.1
# An http stream that sends nothing for this long is treated as ended (ffmpeg's own
# reconnection has had its chance by then).
HTTP_TIMEOUT_S = 15.0


@dataclass(frozen=True)
class Chunk:
    samples: np.ndarray      # (n,) float32 mono at ``SR``
    start_s: float           # stream time of the first sample


class AudioSource:
    """Mono float32 chunks from ffmpeg; ``read(timeout)`` returns a ``Chunk``, ``None`` on a stall, or raises StopIteration at the end."""

    def __init__(self, spec: str, *, realtime: bool = True, sr: int = SR, chunk_s: float = CHUNK_S):
        self.spec = spec
        self.sr = sr
        self._chunk_bytes = 2 * max(1, int(round(chunk_s * sr)))
        self._queue: queue.Queue = queue.Queue(maxsize=256)
        self._samples = 0
        self._done = False
        self.error = ""
        exe = shutil.which("ffmpeg")
        if exe is None:
            raise InputError("ffmpeg is not installed; install it: apt-get install ffmpeg")
        cmd = [exe, "-hide_banner", "-loglevel", "error", "-nostdin"]
        stdin = subprocess.DEVNULL
        # Live inputs start decoding after 0.5 s of audio, not after ffmpeg's default 5 s of probing.
        quick_probe = ["-probesize", "65536", "-analyzeduration", "500000"]
        self.network = spec.startswith(("http://", "https://"))
        if spec == "-":
            cmd = [exe, "-hide_banner", "-loglevel", "error", *quick_probe, "-i", "pipe:0"]
            stdin = None  # ffmpeg reads our standard input
        elif self.network:
            # -re: a whole file served over http plays at its pace too; a live stream sets its own.
            cmd += (["-re"] if realtime else []) + [
                "-reconnect", "1", "-reconnect_streamed", "1", "-reconnect_delay_max", "4",
                "-rw_timeout", str(int(HTTP_TIMEOUT_S * 1e6)), *quick_probe, "-i", spec]
        else:
            path = Path(spec)
            if not path.is_file():
                raise InputError(f"{spec}: no such file (give an audio file, '-' for standard input, or an http(s) URL)")
            cmd += (["-re"] if realtime else []) + ["-i", str(path)]
        cmd += ["-vn", "-ac", "1", "-ar", str(sr), "-f", "s16le", "pipe:1"]
        self._proc = subprocess.Popen(cmd, stdin=stdin, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        self._reader = threading.Thread(target=self._read_loop, daemon=True)
        self._reader.start()

    def _read_loop(self) -> None:
        out = self._proc.stdout
        pending = b""
        try:
            while True:
                data = out.read1(self._chunk_bytes) if hasattr(out, "read1") else out.read(self._chunk_bytes)
                if not data:
                    break
                pending += data
                usable = len(pending) // 2 * 2
                if usable:
                    self._queue.put(pending[:usable])
                    pending = pending[usable:]
        finally:
            self._proc.wait()
            err = self._proc.stderr.read().decode("utf-8", "replace").strip() if self._proc.stderr else ""
            # A network source that gives up after its reconnects still exits 0; its last word is then
            # "URL: Input/output error" (a reconnect that succeeds leaves only "[http @ ...]" notes).
            last = err.splitlines()[-1] if err else ""
            if last and (self._proc.returncode not in (0, None) or (self.network and last.startswith(self.spec))):
                self.error = last[:300]
            self._queue.put(None)

    def read(self, timeout: float) -> Chunk | None:
        """The next chunk; ``None`` if nothing arrived within ``timeout`` s; StopIteration when the stream ended."""
        if self._done:
            raise StopIteration
        try:
            data = self._queue.get(timeout=timeout)
        except queue.Empty:
            return None
        if data is None:
            self._done = True
            raise StopIteration
        samples = np.frombuffer(data, dtype="<i2").astype(np.float32) / 32768.0
        chunk = Chunk(samples, self._samples / self.sr)
        self._samples += samples.size
        return chunk

    @property
    def heard_s(self) -> float:
        return self._samples / self.sr

    def close(self) -> None:
        if self._proc.poll() is None:
            self._proc.terminate()
            try:
                self._proc.wait(timeout=2.0)
            except subprocess.TimeoutExpired:
                self._proc.kill()
        self._reader.join(timeout=2.0)

    def __enter__(self) -> "AudioSource":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def wait_for_audio(source: AudioSource, timeout_s: float) -> Chunk:
    """The first chunk of a source, or a clear error if it cannot be decoded or sends nothing."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            chunk = source.read(timeout=max(0.05, deadline - time.monotonic()))
        except StopIteration:
            why = f" ({source.error})" if source.error else ""
            raise InputError(f"{source.spec}: no audio could be decoded{why}; check that it plays "
                             "(e.g. ffplay), or convert it with ffmpeg") from None
        if chunk is not None and chunk.samples.size:
            return chunk
        if time.monotonic() >= deadline:
            raise InputError(f"{source.spec}: no audio arrived within {timeout_s:g} s")

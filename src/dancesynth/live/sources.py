"""Audio that arrives over time: a file at real-time pace, standard input, an http(s) stream, or
the computer's own sound (``system``: what it plays; ``mic``: its default input).

Every source is decoded by one ffmpeg process into mono 16-bit samples at the
analysis rate; a reader thread turns its output into chunks on a bounded queue, so
the consumer can wait with a timeout and notice a stall without blocking. ffmpeg
does what it is good at: formats, resampling, pacing a file at its native rate
(``-re``). An http(s) stream's bytes are fetched here (urllib) and fed to ffmpeg's
standard input, so that its end can be judged by the container's own end mark (an Ogg
stream's last page, a WAV's length) or the announced length: ffmpeg reports any http
stream that closes without a length as an error, a finished one too. A connection that
breaks is resumed with an HTTP Range request where the server accepts them. The computer's sound
comes through ffmpeg's device inputs (``device_input``): on Linux the PulseAudio (or PipeWire's
pulse) server's monitor of the default output and its default input; ``pulse:NAME`` and
``alsa:NAME`` name a source or device. ``PushedAudio`` is PCM handed over as it arrives (the web
page's capture), read the same way.
"""

from __future__ import annotations

import contextlib
import http.client
import queue
import shutil
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError

SR = 22050
CHUNK_S = 0.1
# An http stream that sends nothing for this long is treated as ended. A radio that stalls
# for 20 s on an open connection and then resumes must survive it (the dancer bridges the stall).
HTTP_TIMEOUT_S = 30.0
# Standard input: junk before the container (a player's log line, a cut-off first page) is skipped
# up to the first of these signatures, searched in the first SYNC_SEARCH_BYTES.
CONTAINER_MAGICS = (b"OggS", b"RIFF", b"fLaC", b"ID3")
SYNC_SEARCH_BYTES = 1 << 16
# An Ogg page is at most 65,307 bytes: the last one is always in a tail this long.
TAIL_BYTES = 1 << 17
# A broken http connection is resumed (HTTP Range) at most this often in a row, waiting up to this long.
HTTP_RESUMES = 5
HTTP_RESUME_WAIT_S = 4.0


DEVICES = ("system", "mic")
DEVICE_KINDS = ("pulse", "alsa")


def device_input(spec: str) -> list[str] | None:
    """ffmpeg's input arguments for a sound device: ``system`` (what the computer plays), ``mic`` (its
    default input), ``pulse:NAME`` or ``alsa:NAME``; None for any other source. macOS reads a microphone
    with AVFoundation and what it plays through a loopback device (BlackHole); Windows has no default
    loopback that ffmpeg can name, so it gets the recipe of piping ffmpeg's dshow capture in."""
    kind, _, name = spec.partition(":")
    if kind in DEVICE_KINDS and name:
        return ["-f", kind, "-i", name]
    if spec not in DEVICES:
        return None
    if sys.platform == "darwin":
        return ["-f", "avfoundation", "-i", ":default" if spec == "mic" else ":BlackHole 2ch"]
    if sys.platform == "win32":
        raise InputError(f"'{spec}' is not available on Windows: pipe a capture in, e.g. "
                         "ffmpeg -f dshow -i audio=\"Stereo Mix (Realtek(R) Audio)\" -f wav - | dancesynth stream -")
    return ["-f", "pulse", "-i", "@DEFAULT_MONITOR@" if spec == "system" else "default"]


@dataclass(frozen=True)
class Chunk:
    samples: np.ndarray      # (n,) float32 mono at ``SR``
    start_s: float           # stream time of the first sample


def _pcm16(data: bytes) -> np.ndarray:
    """16-bit little-endian PCM as float32 samples in [-1, 1)."""
    return np.frombuffer(data, dtype="<i2").astype(np.float32) / 32768.0


class _Stamped:
    """A source's clock: the stream time of each chunk, counted in the samples read so far."""

    sr: int
    _samples: int

    def _stamped(self, samples: np.ndarray) -> Chunk:
        chunk = Chunk(samples, self._samples / self.sr)
        self._samples += samples.size
        return chunk

    @property
    def heard_s(self) -> float:
        return self._samples / self.sr


class AudioSource(_Stamped):
    """Mono float32 chunks from ffmpeg; ``read(timeout)`` returns a ``Chunk``, ``None`` on a stall, or raises StopIteration at the end.

    After the end, ``error`` is empty if the source ended as it should, else why it broke off:
    ffmpeg's last error, a network stream whose reconnects failed, or a file or standard
    input whose container ends mid-way (an Ogg stream without its last page, a WAV shorter
    than its header says; an MP3 has no end mark, so a cut MP3 cannot be told from a short one).
    """

    pushed = False   # read from a file, a stream or a device (not handed over: ``PushedAudio``)

    def __init__(self, spec: str, *, realtime: bool = True, sr: int = SR, chunk_s: float = CHUNK_S):
        self.spec = spec
        self.sr = sr
        self._chunk_bytes = 2 * max(1, int(round(chunk_s * sr)))
        self._queue: queue.Queue = queue.Queue(maxsize=256)
        self._samples = 0
        self._done = False
        self._closing = False
        self._stderr: deque = deque(maxlen=20)  # ffmpeg's last lines; drained as it goes so it never blocks
        self._ends: tuple[bytes, bytes, int] | None = None  # head, tail and size of the bytes fed (stdin, http)
        self._net_error = ""          # why an http stream broke off ('' : it ended, or has not yet)
        self._net_complete = False    # it ended with every byte its length announced
        self.error = ""
        exe = shutil.which("ffmpeg")
        if exe is None:
            raise InputError("ffmpeg is not installed; install it: apt-get install ffmpeg")
        cmd = [exe, "-hide_banner", "-loglevel", "error", "-nostdin"]
        stdin = subprocess.DEVNULL
        # Live inputs start decoding after 0.5 s of audio, not after ffmpeg's default 5 s of probing.
        quick_probe = ["-probesize", "65536", "-analyzeduration", "500000"]
        self.network = spec.startswith(("http://", "https://"))
        self.path: Path | None = None
        self.device = device_input(spec)
        if self.device is not None:
            # A device is live: no pacing; a small probe, so the first audio comes at once.
            cmd += quick_probe + (["-fragment_size", "4096"] if self.device[1] == "pulse" else []) + self.device
        elif spec == "-":
            cmd = [exe, "-hide_banner", "-loglevel", "error", *quick_probe, "-i", "pipe:0"]
            stdin = subprocess.PIPE  # fed by _pump, which skips junk before the container
        elif self.network:
            # -re: a whole file served over http plays at its pace too; a live stream sets its own.
            cmd += (["-re"] if realtime else []) + [*quick_probe, "-i", "pipe:0"]
            stdin = subprocess.PIPE  # fed by _pump from _http_chunks
        else:
            self.path = Path(spec)
            if not self.path.is_file():
                raise InputError(f"{spec}: no such file (give an audio file, '-' for standard input, or an http(s) URL)")
            cmd += (["-re"] if realtime else []) + ["-i", str(self.path)]
        cmd += ["-vn", "-ac", "1", "-ar", str(sr), "-f", "s16le", "pipe:1"]
        # Its own process group: a Ctrl-C at the terminal is ours to handle (the dance ends cleanly), not ffmpeg's
        # to die of; it still ends with us (its pipes close).
        self._proc = subprocess.Popen(cmd, stdin=stdin, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                      process_group=0)
        self._stderr_reader = threading.Thread(target=self._drain_stderr, daemon=True)
        self._stderr_reader.start()
        if spec == "-":
            threading.Thread(target=self._pump, args=(self._stdin_chunks(), True), daemon=True).start()
        elif self.network:
            threading.Thread(target=self._pump, args=(self._http_chunks(), False), daemon=True).start()
        self._reader = threading.Thread(target=self._read_loop, daemon=True)
        self._reader.start()

    def _drain_stderr(self) -> None:
        for line in self._proc.stderr:
            self._stderr.append(line.decode("utf-8", "replace").strip())

    @staticmethod
    def _stdin_chunks():
        src = sys.stdin.buffer
        while data := (src.read1(1 << 16) if hasattr(src, "read1") else src.read(1 << 16)):
            yield data

    def _pump(self, chunks, skip_junk: bool) -> None:
        """``chunks`` (bytes) into ffmpeg's standard input (with ``skip_junk``, from the first container
        signature on); keeps the first and last bytes to check the container's end."""
        dst = self._proc.stdin
        head, tail, size = b"", b"", 0
        try:
            chunks = iter(chunks)
            for data in chunks:
                head += data
                if not skip_junk or len(head) >= SYNC_SEARCH_BYTES or len(head) >= 4 and (
                        _is_container(head) or _mp3_sync(head) or _first_sync(head) > 0):
                    break
            head = head[_first_sync(head):] if skip_junk else head
            dst.write(head)
            tail, size = head[-TAIL_BYTES:], len(head)
            for data in chunks:
                dst.write(data)
                tail, size = (tail + data)[-TAIL_BYTES:], size + len(data)
            self._ends = (head[:12], tail, size)
        except (OSError, ValueError, AttributeError):  # ffmpeg stopped reading; or we have no standard input
            pass
        finally:
            with contextlib.suppress(OSError):
                dst.close()

    def _http_chunks(self):
        """The bytes of the http(s) stream. A connection that breaks (an error, or fewer bytes than its
        length) is resumed with a Range request where the server said it accepts them, up to
        ``HTTP_RESUMES`` times in a row; else, or when the server cannot resume, ``_net_error`` says why
        it broke off. A server that ignores Range would send the file from its start again: that is
        never played as new music."""
        got, length, ranges, resumes = 0, None, False, 0
        while not self._closing:
            try:
                request = urllib.request.Request(self.spec, headers={
                    "User-Agent": "dancesynth", **({"Range": f"bytes={got}-"} if got else {})})
                response = urllib.request.urlopen(request, timeout=HTTP_TIMEOUT_S)
            except urllib.error.HTTPError as exc:
                self._net_error = f"the server answered {exc.code} {exc.reason}"
                return
            except (urllib.error.URLError, OSError, ValueError, http.client.HTTPException) as exc:
                self._net_error = str(getattr(exc, "reason", exc)) or type(exc).__name__
                return
            broke = ""
            with response:
                if got and not (response.status == 206 and
                                response.headers.get("Content-Range", "").startswith(f"bytes {got}-")):
                    self._net_error = f"the connection broke after {got} bytes and the server cannot resume it"
                    return
                if not got:
                    length = response.headers.get("Content-Length")
                    length = int(length) if length and length.isdigit() else None
                    ranges = response.headers.get("Accept-Ranges", "").lower() == "bytes"
                try:
                    while data := response.read1(1 << 16):
                        got += len(data)
                        resumes = 0
                        yield data
                except (OSError, http.client.HTTPException) as exc:  # a reset, a timeout, a short chunk
                    broke = str(exc) or type(exc).__name__
            if length is None and not broke:
                return      # the connection closed: the container's end says whether the stream is whole
            if length is not None and got >= length:
                self._net_complete = True
                return
            why = broke or f"the connection closed after {got} of {length} bytes"
            if not ranges or resumes >= HTTP_RESUMES:
                self._net_error = why
                return
            resumes += 1
            time.sleep(min(0.5 * 2 ** resumes, HTTP_RESUME_WAIT_S))

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
            if not self._closing:
                self.error = self._why_it_ended()
            self._queue.put(None)

    def _why_it_ended(self) -> str:
        """Empty when the source ended as it should, else why not (see the class)."""
        self._stderr_reader.join(timeout=2.0)  # ffmpeg has exited: its last line is on the way
        last = self._stderr[-1] if self._stderr else ""
        if last and self._proc.returncode != 0:
            return last[:300]
        if self.network:
            if self._net_error or self._net_complete:
                return self._net_error
            if not self._ends:
                return ""
            cut = _cut_off(*self._ends)
            if cut or _has_end_mark(self._ends[0]):
                return cut
            return ("the connection closed, and the stream states neither its length nor its end "
                    "(an MP3 or AAC radio has no end mark)")
        if self.path is not None:
            try:
                with open(self.path, "rb") as fh:
                    head = fh.read(12)
                    size = fh.seek(0, 2)
                    fh.seek(max(0, size - TAIL_BYTES))
                    return _cut_off(head, fh.read(), size)
            except OSError:  # the file went away meanwhile
                return ""
        return _cut_off(*self._ends) if self._ends else ""

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
        return self._stamped(_pcm16(data))

    def close(self) -> None:
        self._closing = True  # ffmpeg stopped by us has not failed
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


class PushedAudio(_Stamped):
    """Audio handed over by the caller as it arrives (the page's tab or microphone capture, sent over a
    WebSocket): 16-bit mono PCM at ``rate``, resampled to ``sr`` (soxr, one stream, so chunk edges leave
    no trace). Read like an ``AudioSource``; ``push`` and ``end`` may come from another thread. The
    caller bounds how fast and how much is pushed (``web/live.py``); a source that gets nothing for
    ``stall_end_s`` ends, as an http stream that stops sending does."""

    device = None
    path = None
    pushed = True

    def __init__(self, spec: str, rate: int, *, sr: int = SR, stall_end_s: float = HTTP_TIMEOUT_S):
        import soxr

        self.spec, self.rate, self.sr = spec, rate, sr
        self._resampler = soxr.ResampleStream(rate, sr, 1, dtype="float32")
        self._queue: queue.Queue = queue.Queue()
        self._samples = 0
        self._done = False
        self._stall_end_s = stall_end_s
        self._last = time.monotonic()
        self.error = ""

    def push(self, pcm: bytes) -> None:
        self._queue.put(pcm)

    def end(self, error: str = "") -> None:
        """No more audio; ``error`` says why it broke off ('' : it ended as it should)."""
        self._queue.put(("end", error))

    def read(self, timeout: float) -> Chunk | None:
        if self._done:
            raise StopIteration
        try:
            data = self._queue.get(timeout=timeout)
        except queue.Empty:
            if time.monotonic() - self._last <= self._stall_end_s:
                return None
            data = ("end", f"no audio came for {self._stall_end_s:g} s")
        self._last = time.monotonic()
        last = isinstance(data, tuple)
        pcm = np.zeros(0, np.float32) if last else _pcm16(data)
        samples = self._resampler.resample_chunk(pcm, last=last)
        if last:
            self._done, self.error = True, data[1]
            if not samples.size:
                raise StopIteration
        return self._stamped(samples)

    def close(self) -> None:
        self.end()


def broke_off(source: AudioSource) -> str:
    """After the end: '' if the source ended as it should, else a one-line account of how it broke off."""
    if not source.error:
        return ""
    name = "standard input" if source.spec == "-" else source.spec
    why = source.error.removeprefix(f"{source.spec}: ")
    return f"{name}: the stream broke off after {source.heard_s:.1f} s of audio ({why})"


def wait_for_audio(source: AudioSource, timeout_s: float) -> Chunk:
    """The first chunk of a source, or a clear error if it cannot be decoded or sends nothing."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            chunk = source.read(timeout=max(0.05, deadline - time.monotonic()))
        except StopIteration:
            why = f" ({source.error})" if source.error else ""
            if source.pushed:
                raise InputError(f"{source.spec}: {source.error or 'it ended before any audio came'}") from None
            if source.device is not None:
                raise InputError(f"{source.spec}: cannot capture from the sound device{why}; " + _device_help(source)) \
                    from None
            raise InputError(f"{source.spec}: no audio could be decoded{why}; check that it plays "
                             "(e.g. ffplay), or convert it with ffmpeg") from None
        if chunk is not None and chunk.samples.size:
            return chunk
        if time.monotonic() >= deadline:
            raise InputError(f"{source.spec}: no audio arrived within {timeout_s:g} s")


def _device_help(source: AudioSource) -> str:
    kind = source.device[1]
    if kind == "pulse":
        return ("dancesynth records through PulseAudio (or PipeWire's pulse server): is one running for this user "
                "(pactl info)? Name another source with pulse:NAME (pactl list short sources), or an ALSA device "
                "with alsa:NAME (arecord -L)")
    if kind == "alsa":
        return "name an ALSA capture device that exists (arecord -L)"
    return ("on macOS, allow the terminal to use the microphone; for what the Mac plays, install a loopback "
            "device named 'BlackHole 2ch' and send the output to it")


def _is_container(head: bytes) -> bool:
    return head.startswith(CONTAINER_MAGICS)


def _mp3_sync(data: bytes) -> bool:
    """An MPEG audio frame header (11 sync bits, a layer, a bitrate and a rate that exist) at the start."""
    return (len(data) >= 3 and data[0] == 0xFF and data[1] & 0xE0 == 0xE0 and data[1] & 0x06 != 0
            and data[2] & 0xF0 != 0xF0 and data[2] & 0x0C != 0x0C)


def _first_sync(head: bytes) -> int:
    """Where the stream starts: 0 if it starts with a container signature or an MP3 frame, else the
    first container signature in ``head`` (0 if none: ffmpeg's own probing has its chance)."""
    if _is_container(head[:4]) or _mp3_sync(head):
        return 0
    found = [i for i in (head.find(m) for m in CONTAINER_MAGICS) if i > 0]
    return min(found, default=0)


def _has_end_mark(head: bytes) -> bool:
    """Whether the container starting with ``head`` marks its own end (``_cut_off`` can tell a whole one)."""
    return head.startswith(b"OggS") or head.startswith(b"RIFF") and head[8:12] == b"WAVE"


def _cut_off(head: bytes, tail: bytes, size: int) -> str:
    """Why a container whose first bytes are ``head`` and last ``tail`` (of ``size``) ends mid-way, or ''."""
    if head.startswith(b"OggS"):
        at = tail.rfind(b"OggS")
        if at < 0 or len(tail) < at + 27:
            return "the Ogg stream is cut off mid-page"
        n = tail[at + 26]
        end = at + 27 + n + sum(tail[at + 27:at + 27 + n])
        if len(tail) < at + 27 + n or end != len(tail) or not tail[at + 5] & 0x04:
            return "the Ogg stream is cut off (its last page is missing)"
    elif head.startswith(b"RIFF") and head[8:12] == b"WAVE":
        declared = int.from_bytes(head[4:8], "little")
        # 0 and 0xFFFFFFFF: a WAV written to a pipe, whose writer could not go back to fill in the size.
        if declared not in (0, 0xFFFFFFFF) and size < declared + 8:
            return f"the WAV stream is cut off ({size} of the {declared + 8} bytes its header announces)"
    return ""

"""Decoding audio files into float32 samples, with errors a user can act on.

``load_audio`` reads what libsndfile reads (wav, flac, ogg/vorbis, ogg/opus, mp3,
aiff, ...) through ``soundfile`` and falls back to the ``ffmpeg`` program for
everything else (m4a/aac, opus in webm, mp4/mkv audio tracks, wma...). Samples are
down-mixed to mono by averaging channels and resampled with soxr, so the same
content gives the same samples whatever container it came in.

Checks happen before the expensive part: the duration comes from the file header
(``soundfile.info`` or ``ffprobe``) so that an hour-long file is refused at once,
and truncation is detected both from the container (an Ogg stream that lacks its
end-of-stream page, a WAV whose data chunk is shorter than its header says) and by
comparing the decoded length with the length the header declares. A user gets a
"truncated or corrupt" error rather than a silently shortened song.
"""

from __future__ import annotations

import json
import shutil
import struct
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import soundfile as sf

from ..errors import InputError
from ..types import MAX_SONG_S
from .resampling import Sink

DEFAULT_SR = 22050
DEFAULT_MAX_DURATION_S = MAX_SONG_S
_NOISY_FORMATS = {"MP3", "MPEG"}
DEFAULT_MIN_DURATION_S = 4.0
#: More channels than this is a corrupt header, not music (studio multitracks stop well short): refused before
#: decoding, since the down-mix names every channel (65,535 made ffmpeg's argument list too long).
MAX_CHANNELS = 256

# Formats a user can always convert to; named in every "cannot decode" message.
_CONVERT_HINT = "convert it to wav, flac, ogg or mp3 (e.g. `ffmpeg -i IN out.wav`)"
# A decoded stream may fall this much short of its header's length without being
# called truncated: encoders disagree by a frame or two of priming/padding samples.
_SHORTFALL_TOLERANCE_S = 0.25
_SHORTFALL_TOLERANCE_FRACTION = 0.005
# Decode in blocks so a long stereo file is down-mixed and resampled as it is read (small
# enough to stay in cache: 2**18-frame blocks cost twice the read itself).
_BLOCK_FRAMES = 1 << 16
# ffmpeg/ffprobe must never hang the caller; a 15-minute song decodes in seconds.
_FFPROBE_TIMEOUT_S = 30.0
_FFMPEG_TIMEOUT_S = 300.0


@dataclass(frozen=True)
class AudioInfo:
    """What a file's header says, read without decoding the audio.

    ``frames`` is 0 where the header does not say how long the stream is
    (then ``duration_s`` is ``nan`` and the length is checked while decoding).
    ``backend`` is ``"soundfile"`` or ``"ffmpeg"``: which decoder will read it.
    """

    path: Path
    samplerate: int
    channels: int
    frames: int
    duration_s: float
    format: str
    backend: str


def audio_duration_s(path) -> float:
    """Duration of an audio file in seconds from its header, without decoding it.

    Raises ``InputError`` for a missing, empty, unreadable or truncated file, or one
    whose header does not state its length.
    """
    info = probe_audio(path)
    if not np.isfinite(info.duration_s):
        raise InputError(f"{info.path}: the file does not state its duration; {_CONVERT_HINT}")
    return info.duration_s


def probe_audio(path) -> AudioInfo:
    """Read the header of an audio file (and check its container is complete)."""
    path = _check_path(path)
    try:
        info = sf.info(str(path))
    except (sf.LibsndfileError, RuntimeError, ValueError):
        # libsndfile does not know the format (its message then misleadingly says
        # "file does not exist"); ffmpeg knows far more containers and codecs.
        info = None
    # MP3 goes to ffmpeg: libsndfile's mpg123 prints its notes on a damaged frame ("Trying to resync...")
    # straight to the process's stderr, where ffmpeg's are ours to keep.
    if info is not None and info.samplerate > 0 and info.channels > 0 and info.format not in _NOISY_FORMATS:
        result = AudioInfo(path, int(info.samplerate), int(info.channels), int(info.frames),
                           float(info.frames) / info.samplerate, str(info.format), "soundfile")
    else:
        result = _ffprobe(path)
    if result.channels > MAX_CHANNELS:
        raise InputError(f"{path}: the header says {result.channels} channels, and dancesynth reads at most "
                         f"{MAX_CHANNELS}: the header is corrupt, or down-mix the file first "
                         "(`ffmpeg -i IN -ac 2 out.wav`)")
    _check_container_complete(result)
    return result


def load_audio(path, *, sr: int | None = DEFAULT_SR, mono: bool = True,
               max_duration_s: float | None = DEFAULT_MAX_DURATION_S,
               min_duration_s: float = DEFAULT_MIN_DURATION_S) -> tuple[np.ndarray, int]:
    """Decode an audio file to float32 samples.

    Parameters
    ----------
    path : str or Path
        wav/flac/ogg/mp3 (read by libsndfile) or anything ffmpeg decodes.
    sr : int or None
        Output sample rate; ``None`` keeps the file's own rate.
    mono : bool
        Average the channels into one (shape ``(n,)``); otherwise the result has
        shape ``(channels, n)`` as in librosa.
    max_duration_s, min_duration_s : float
        Refuse files longer / shorter than this (``max_duration_s=None``: no limit).

    Returns
    -------
    (y, sr) : the samples and their sample rate.

    The file is decoded, down-mixed and resampled block by block (soxr's stream
    resampler gives the same samples as resampling the whole signal at once) into
    one array of the output's length: the memory is that of the result, however
    long the song, and the time about one read of the file.

    Raises ``InputError`` (one line, naming the file) when the file is missing, a
    folder, empty, not audio, truncated or corrupt, too long or too short.
    """
    if sr is not None and (int(sr) != sr or sr <= 0):
        raise InputError(f"sample rate must be a positive integer, got {sr!r}")
    info = probe_audio(path)
    _check_duration(info.path, info.duration_s, max_duration_s, min_duration_s)
    out_sr = info.samplerate if sr is None else int(sr)
    sink = Sink(info.samplerate, out_sr, 1 if mono else info.channels, info.frames)
    if info.backend == "soundfile":
        _decode_soundfile(info, mono, sink)
    else:
        _decode_ffmpeg(info, mono, max_duration_s, sink)
    y = sink.finish()
    n = sink.frames_in
    _check_not_truncated(info, n)
    # Again on what was decoded: a header may not state the length, or understate it.
    _check_duration(info.path, n / info.samplerate, max_duration_s, min_duration_s)
    # Checked on the resampled blocks: float samples near 3e38 are finite in the file but overflow the resampler.
    if not sink.finite:
        raise InputError(f"{info.path}: the audio contains NaN, infinite or absurdly large samples, so the file is "
                         f"corrupt; re-export or {_CONVERT_HINT}")
    return (y[0] if mono else y), out_sr


# --------------------------------------------------------------------------- checks

def _check_path(path) -> Path:
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: file not found; check the path and the spelling")
    if path.is_dir():
        raise InputError(f"{path}: is a folder, not an audio file; give the path of a song file inside it")
    if not path.is_file():
        # A pipe or a device would block the reads below, or never end.
        raise InputError(f"{path}: is not a regular file; save the audio to a file first")
    try:
        size = path.stat().st_size
        with open(path, "rb"):
            pass
    except OSError as exc:
        raise InputError(f"{path}: cannot be read ({exc.strerror}); check its permissions") from None
    if size == 0:
        raise InputError(f"{path}: the file is empty (0 bytes); the download or copy probably failed, fetch it again")
    return path


def _check_duration(path: Path, duration_s: float, max_duration_s, min_duration_s) -> None:
    if not np.isfinite(duration_s):
        return
    if duration_s <= 0:
        raise InputError(f"{path}: the file contains no audio samples; {_CONVERT_HINT}")
    if max_duration_s is not None and duration_s > max_duration_s:
        raise InputError(
            f"{path}: the audio is {duration_s / 60:.1f} min long, over the limit of "
            f"{max_duration_s / 60:.1f} min; raise the limit (--max-minutes, or max_duration_s=) or cut the song")
    if duration_s < min_duration_s:
        raise InputError(
            f"{path}: the audio is only {duration_s:.1f} s long, too short to find a beat; "
            f"it needs at least {min_duration_s:g} s")


def _truncated(path: Path, detail: str) -> InputError:
    return InputError(f"{path}: the file is truncated or corrupt ({detail}); download or export it again")


def _check_not_truncated(info: AudioInfo, decoded_frames: int) -> None:
    """Compare the decoded length with the length the header declared."""
    if info.frames <= 0:
        return
    tolerance = max(_SHORTFALL_TOLERANCE_S * info.samplerate, _SHORTFALL_TOLERANCE_FRACTION * info.frames)
    if decoded_frames < info.frames - tolerance:
        raise _truncated(info.path, f"its header declares {info.duration_s:.1f} s but only "
                                    f"{decoded_frames / info.samplerate:.1f} s could be decoded")


def _check_container_complete(info: AudioInfo) -> None:
    """Container-level truncation checks that need no decoding.

    libsndfile (and ffprobe) report the length of what is *there* for Ogg and WAV,
    so a file cut short looks like a short song. The containers themselves tell:
    an Ogg stream ends with a page flagged end-of-stream, and a RIFF/WAV header
    states the size of its data chunk.
    """
    with open(info.path, "rb") as fh:
        head = fh.read(4096)
    if head.startswith(b"OggS"):
        problem = _ogg_tail_problem(info.path)
        if problem:
            raise _truncated(info.path, problem)
    elif head.startswith(b"RIFF") and head[8:12] == b"WAVE":
        problem = _wav_data_problem(info.path)
        if problem:
            raise _truncated(info.path, problem)


def _ogg_tail_problem(path: Path) -> str | None:
    """None if the last Ogg page is complete and flagged end-of-stream, else why not."""
    size = path.stat().st_size
    # An Ogg page is at most 27 + 255 + 255 * 255 bytes long.
    tail_len = min(size, 27 + 255 + 255 * 255 + 4096)
    with open(path, "rb") as fh:
        fh.seek(size - tail_len)
        tail = fh.read()
    pos = tail.rfind(b"OggS")
    while pos >= 0:
        # Walk back from the last capture pattern to the last page that ends exactly
        # at the end of the file (a later "OggS" may be payload or a cut-off page).
        if pos + 27 <= len(tail):
            n_segments = tail[pos + 26]
            if pos + 27 + n_segments <= len(tail):
                body = sum(tail[pos + 27:pos + 27 + n_segments])
                if pos + 27 + n_segments + body == len(tail):
                    if tail[pos + 5] & 0x04:
                        return None
                    return "the Ogg stream stops without its end-of-stream page"
        pos = tail.rfind(b"OggS", 0, pos)
    return "the last Ogg page is cut off"


def _wav_data_problem(path: Path) -> str | None:
    """None if the WAV data chunk holds as many bytes as its header declares."""
    size = path.stat().st_size
    with open(path, "rb") as fh:
        fh.seek(12)
        byte_rate = 0
        while True:
            chunk = fh.read(8)
            if len(chunk) < 8:
                return None  # no data chunk found: libsndfile has already judged it
            cid, csize = chunk[:4], struct.unpack("<I", chunk[4:])[0]
            if cid == b"fmt ":
                fmt = fh.read(min(csize, 16))
                if len(fmt) >= 12:
                    byte_rate = struct.unpack("<I", fmt[8:12])[0]
                fh.seek(csize - len(fmt) + (csize & 1), 1)
                continue
            if cid == b"data":
                available = size - fh.tell()
                # Writers that stream (or exceed 4 GiB) leave 0 or 0xFFFFFFFF here.
                if csize in (0, 0xFFFFFFFF) or csize <= available:
                    return None
                if byte_rate:
                    return (f"its header declares {csize / byte_rate:.1f} s of samples but the file "
                            f"holds {available / byte_rate:.1f} s")
                return f"its header declares {csize} bytes of samples but the file holds {available}"
            fh.seek(csize + (csize & 1), 1)


# ------------------------------------------------------------------------ decoders

def _decode_soundfile(info: AudioInfo, mono: bool, sink: Sink) -> None:
    buf = np.empty((_BLOCK_FRAMES, info.channels), dtype=np.float32)
    weights = np.full(info.channels, 1.0 / info.channels, np.float32)
    try:
        with sf.SoundFile(str(info.path)) as fh:
            while True:
                block = fh.read(_BLOCK_FRAMES, dtype="float32", always_2d=True, out=buf)
                if len(block) == 0:
                    break
                sink.add(_mono(block, weights) if mono else block)
    except (sf.LibsndfileError, RuntimeError) as exc:
        raise _truncated(info.path, f"the decoder stopped: {_one_line(str(exc))}") from None


def _mono(block: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The mean of a ``(frames, channels)`` block's channels, ``(frames,)`` float32."""
    if block.shape[1] == 1:
        return block[:, 0].copy()
    if block.shape[1] == 2:
        # Exactly what the matrix product below gives for two channels (halving is exact; adding
        # +0 turns -0 into +0 as BLAS's sum from zero does), without BLAS threads.
        out = np.add(block[:, 0], block[:, 1])
        out *= np.float32(0.5)
        out += np.float32(0.0)
        return out
    # A matrix product is ~8x faster than mean(axis=1) on interleaved frames.
    return block @ weights


def _tool(name: str, path: Path) -> str:
    exe = shutil.which(name)
    if exe is None:
        raise InputError(f"{path}: libsndfile cannot read this format and `{name}` is not installed; "
                         f"install ffmpeg or {_CONVERT_HINT}")
    return exe


def _ffmpeg_input(path: Path) -> str:
    # "file:" stops ffmpeg from reading a protocol ("concat:", "http:") or an
    # option out of a file name.
    return "file:" + str(path.resolve())


def _ffprobe(path: Path) -> AudioInfo:
    cmd = [_tool("ffprobe", path), "-v", "error", "-select_streams", "a:0",
           "-show_entries", "stream=codec_name,sample_rate,channels,duration:format=format_name,duration",
           "-of", "json", _ffmpeg_input(path)]
    try:
        proc = subprocess.run(cmd, capture_output=True, timeout=_FFPROBE_TIMEOUT_S, check=False)
    except subprocess.TimeoutExpired:
        raise InputError(f"{path}: reading the file's header took too long; {_CONVERT_HINT}") from None
    try:
        meta = json.loads(proc.stdout.decode("utf-8", "replace") or "{}")
    except json.JSONDecodeError:
        meta = {}
    streams = meta.get("streams") or []
    stream = streams[0] if streams else {}
    samplerate = int(float(stream.get("sample_rate") or 0))
    channels = int(stream.get("channels") or 0)
    if proc.returncode != 0 or samplerate <= 0 or channels <= 0:
        if proc.returncode:
            why = "ffmpeg: " + _one_line(proc.stderr.decode("utf-8", "replace")).replace(_ffmpeg_input(path) + ": ", "")
        else:
            why = "no audio stream found"
        raise InputError(f"{path}: cannot decode it: not an audio file, or truncated or corrupt ({why}); "
                         f"check that it plays, then {_CONVERT_HINT}")
    duration = _float_or_nan(stream.get("duration"))
    if not np.isfinite(duration):
        duration = _float_or_nan((meta.get("format") or {}).get("duration"))
    frames = int(round(duration * samplerate)) if np.isfinite(duration) else 0
    fmt = f"{(meta.get('format') or {}).get('format_name', '?')}/{stream.get('codec_name', '?')}"
    return AudioInfo(path, samplerate, channels, frames, duration, fmt, "ffmpeg")


def _decode_ffmpeg(info: AudioInfo, mono: bool, max_duration_s, sink: Sink) -> None:
    import tempfile
    import threading

    cmd = [_tool("ffmpeg", info.path), "-nostdin", "-hide_banner", "-loglevel", "error",
           "-i", _ffmpeg_input(info.path), "-map", "0:a:0", "-vn", "-sn", "-dn"]
    if max_duration_s is not None:
        # Bounds the work even when the header did not state the duration.
        cmd += ["-t", f"{max_duration_s + 1.0:.3f}"]
    channels = 1 if mono else info.channels
    if mono and info.channels > 1:
        # ffmpeg's own "-ac 1" weights channels unequally; a plain mean matches the
        # soundfile path exactly.
        gain = 1.0 / info.channels
        cmd += ["-af", "pan=mono|c0=" + "+".join(f"{gain!r}*c{i}" for i in range(info.channels))]
    else:
        cmd += ["-ac", str(channels)]
    cmd += ["-ar", str(info.samplerate), "-f", "f32le", "-acodec", "pcm_f32le", "pipe:1"]
    frame_bytes = 4 * channels
    block_bytes = _BLOCK_FRAMES * frame_bytes
    # The samples are read from the pipe as ffmpeg writes them (never the whole song as bytes);
    # its messages go to a file, so that neither pipe can fill up and stall the other.
    with tempfile.TemporaryFile() as err:
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=err)
        timed_out = threading.Event()

        def stop():
            timed_out.set()
            proc.kill()

        timer = threading.Timer(_FFMPEG_TIMEOUT_S, stop)
        timer.daemon = True
        timer.start()
        try:
            pending = b""
            while True:
                chunk = proc.stdout.read(block_bytes)
                if not chunk:
                    break
                chunk = pending + chunk
                whole = len(chunk) - len(chunk) % frame_bytes
                pending = chunk[whole:]
                if whole:
                    data = np.frombuffer(chunk, dtype="<f4", count=whole // 4)
                    sink.add(data if channels == 1 else data.reshape(-1, channels))
            returncode = proc.wait()
        finally:
            timer.cancel()
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            proc.stdout.close()
        if timed_out.is_set():
            raise InputError(f"{info.path}: decoding took longer than {_FFMPEG_TIMEOUT_S:.0f} s; "
                             f"{_CONVERT_HINT}") from None
        if returncode != 0:
            err.seek(0)
            why = _one_line(err.read().decode("utf-8", "replace")).replace(_ffmpeg_input(info.path) + ": ", "")
            raise _truncated(info.path, f"ffmpeg failed: {why}")


def _float_or_nan(value) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return float("nan")


def _one_line(text: str) -> str:
    lines = [ln.strip() for ln in text.strip().splitlines() if ln.strip()]
    return lines[-1] if lines else "no details"

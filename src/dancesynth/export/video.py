"""MP4 export: render a dance with the software renderer and mux it with its song.

The dancer is drawn as a character's skinned mesh (``figure="character"``, the default,
when a character with a mesh is given) or as a stick figure (``figure="stick"``).
Frames are drawn one at a time (``render.FrameRenderer``), already as the Y'CbCr planes
H.264 takes (``yuv420p``, BT.601 limited range, tagged so in the stream), and piped into an
``ffmpeg`` process that only encodes them (``libx264``) and the AAC audio, on the other core;
no frame is kept after it is written, so memory stays flat however long the dance.
Video and audio both start at t = 0; the song is cut to the video's length, so the
two stay in sync frame for frame. The file appears only when ffmpeg has finished:
until then it is a hidden ``.NAME.*.part`` file next to the output, removed on any
failure (an ffmpeg error, bad input, Ctrl-C).
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import subprocess
import tempfile
import time
from fractions import Fraction
from pathlib import Path

import numpy as np

from ..errors import DanceSynthError, InputError
from ..io.files import atomic_path
from ..types import MotionClip, Skeleton

MAX_LONG_SIDE = 3840          # 4K UHD: 3840x2160, either orientation
MAX_SHORT_SIDE = 2160
MIN_SIDE = 16
MAX_FPS = 240.0
# Dance and song may differ by this much (fraction of the song, plus seconds).
DURATION_TOLERANCE = (0.10, 1.0)
# x264 "veryfast" with the cheapest motion search (diamond, subpixel refinement 1): 0.65x the CPU
# of plain "veryfast" (18 vs 27 ms a frame at 1920x1080 on this 2-core machine), ~10 % more bytes,
# the same quality at this CRF (PSNR within 0.4 dB). "superfast" is a little cheaper still but drops
# the macroblock tree and doubles the size; with the tree back on it loses a little more quality.
X264_PRESET = "veryfast"
X264_PARAMS = "me=dia:subme=1"
X264_CRF = 20
AAC_BITRATE = "160k"
AAC_CODER = "fast"            # ffmpeg's default, "twoloop", takes 2.5x the CPU (~1 ms per video frame at 30 fps)
_AAC_RATES = {7350, 8000, 11025, 12000, 16000, 22050, 24000, 32000, 44100, 48000, 64000, 88200, 96000}
_FINISH_TIMEOUT_S = 600.0     # ffmpeg flushing the encoder and moving the index to the front
_PIPE_BYTES = 1 << 20         # Linux's default ceiling for an unprivileged pipe
FIGURES = ("character", "stick")


def render_video(dance: MotionClip, song_path: Path | None, out_path: Path, *, width: int = 960,
                 height: int = 540, fps: float | None = None, character=None, figure: str = "character",
                 progress=None) -> dict:
    """Render ``dance`` to an MP4 at ``out_path`` with ``song_path`` as its sound track.

    ``song_path`` ``None`` makes a silent video. ``fps`` resamples the dance by
    nearest frame (default: the dance's own frame rate). ``character`` (a
    ``retarget.character.Character`` whose skeleton the dance is on) is drawn as its
    skinned mesh with ``figure="character"``; ``figure="stick"``, or a character
    without a mesh, or none, draws a stick figure. ``progress(done, total)`` is called
    as frames are encoded. Returns ``{"frames", "duration_s", "seconds" (wall time),
    "fps", "width", "height", "audio", "figure" (what was drawn), "path"}``.

    Raises ``InputError`` for an output not ending in ``.mp4`` or in a missing folder,
    a size that is not even, positive and at most 3840x2160, an empty or non-finite
    dance, an unknown ``figure``, a character on another skeleton than the dance's or
    with a broken mesh, a song that cannot be decoded or whose duration differs from
    the dance's by more than 10 % + 1 s, or a missing ``ffmpeg``; ``DanceSynthError``
    when ffmpeg fails. No partial output is left behind.
    """
    t0 = time.perf_counter()
    out_path = check_output_path(out_path)
    width, height = _check_size(width, height)
    _check_dance(dance)
    if figure not in FIGURES:
        raise InputError(f"unknown figure {figure!r}: use one of {', '.join(FIGURES)}")
    mesh = None
    if character is not None:
        dance = on_skeleton_of(dance, character)
        if figure == "character" and character.mesh is not None:
            from .skinned import SkinnedMesh

            mesh = SkinnedMesh.from_character(character)
    fps_out = _check_fps(dance.fps if fps is None else fps)
    ffmpeg = _find_tool("ffmpeg")
    song = None
    if song_path is not None:
        song = _probe_song(song_path, out_path)
        check_durations(dance.duration_s, song.duration_s, song.path)
    source = source_frames(dance.n_frames, dance.fps, fps_out)
    n = len(source)
    from .render import FrameRenderer  # PIL and the scene only when a video is made

    renderer = FrameRenderer(dance, width, height, mesh=mesh, pix_fmt="yuv420p")
    with atomic_path(out_path) as tmp:
        cmd = ffmpeg_command(ffmpeg, tmp, width=width, height=height, fps=fps_out, n_frames=n, song=song)
        _encode(cmd, renderer.frames(source), n, progress, out_path)
    return {"frames": n, "duration_s": n / fps_out, "seconds": time.perf_counter() - t0, "fps": fps_out,
            "width": width, "height": height, "audio": song is not None,
            "figure": "stick" if mesh is None else "character", "path": str(out_path)}


def render_video_files(dance_path: Path, song_path: Path | None, out_path: Path, *, dress=None, **kwargs) -> dict:
    """Read the BVH at ``dance_path`` and ``render_video`` it with the song at ``song_path``
    (``kwargs``: ``render_video``'s, e.g. ``figure=``). ``dress(clip) -> (clip, character)``, when
    given, puts the dance on the character to draw (``retarget.on_character``)."""
    from ..io.bvh import read_bvh

    out_path = check_output_path(out_path)
    dance_path = Path(dance_path)
    if _same_file(dance_path, out_path):
        raise InputError(f"output {out_path} is the dance file itself; choose another output name")
    # Every frame as written: dropping a T-pose frame here would shift the dance off the music.
    dance = read_bvh(dance_path, drop_tpose=False)
    if dress is not None:
        dance, kwargs["character"] = dress(dance)
    return render_video(dance, song_path, out_path, **kwargs)


# --------------------------------------------------------------------------- checks

def check_output_path(out_path) -> Path:
    """An ``.mp4`` path whose folder exists (``InputError`` otherwise)."""
    out_path = Path(out_path)
    if out_path.suffix.lower() != ".mp4":
        raise InputError(f"output {out_path} must end in .mp4 (e.g. -o dance.mp4)")
    parent = out_path.parent if str(out_path.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"cannot write {out_path}: folder {parent} does not exist (create it first)")
    if out_path.is_dir():
        raise InputError(f"cannot write {out_path}: it is a folder; give a file name ending in .mp4")
    return out_path


def _check_size(width, height) -> tuple[int, int]:
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
            raise InputError(f"video {name} must be a whole number of pixels, got {v!r}")
        if v < MIN_SIDE:
            raise InputError(f"video {name} must be at least {MIN_SIDE} pixels, got {v}")
        if v % 2:
            raise InputError(f"video {name} must be even for H.264 (yuv420p), got {v}: use {v - 1} or {v + 1}")
    if max(width, height) > MAX_LONG_SIDE or min(width, height) > MAX_SHORT_SIDE:
        raise InputError(f"video size {width}x{height} is too large: at most {MAX_LONG_SIDE}x{MAX_SHORT_SIDE} "
                         f"(or {MAX_SHORT_SIDE}x{MAX_LONG_SIDE}); e.g. --width 1920 --height 1080")
    return int(width), int(height)


def _check_fps(fps) -> float:
    try:
        fps = float(fps)
    except (TypeError, ValueError):
        raise InputError(f"frame rate must be a number, got {fps!r}") from None
    if not np.isfinite(fps) or fps <= 0 or fps > MAX_FPS:
        raise InputError(f"frame rate must be above 0 and at most {MAX_FPS:g} fps, got {fps:g}")
    return fps


def _check_dance(dance: MotionClip) -> None:
    if not isinstance(dance, MotionClip):
        raise InputError(f"expected a MotionClip to render, got {type(dance).__name__}")
    if dance.n_frames == 0:
        raise InputError("the dance has no frames; nothing to render")
    arrays = [dance.root_pos, dance.local_rot] + ([] if dance.local_pos is None else [dance.local_pos])
    if not all(np.isfinite(a).all() for a in arrays):
        raise InputError("the dance contains NaN or infinite values; re-create or re-export it")


def on_skeleton_of(dance: MotionClip, character) -> MotionClip:
    """``dance`` with its joints in the order of ``character.skeleton`` (a BVH file lists them depth first,
    which may not be the character's order); ``InputError`` if the two skeletons are not the same tree."""
    from ..retarget.character import Character

    if not isinstance(character, Character):
        raise InputError(f"expected a Character to draw the dance as, got {type(character).__name__}")
    have, want = dance.skeleton, character.skeleton
    if have.names == want.names and np.array_equal(have.parents, want.parents):
        return dance
    where = {n: j for j, n in enumerate(have.names)}

    def parent(sk, j):
        return sk.names[sk.parents[j]] if sk.parents[j] >= 0 else None

    why = next((f"the dance has no joint {n!r}" if n not in where else
                f"joint {n!r} hangs from {parent(have, where[n])!r} in the dance, from {parent(want, j)!r} in the "
                "character" for j, n in enumerate(want.names)
                if n not in where or parent(have, where[n]) != parent(want, j)), None)
    if why is None and have.n_joints != want.n_joints:
        why = f"the character has no joint {next(n for n in have.names if n not in want.names)!r}"
    if why is not None:
        raise InputError(f"the dance's skeleton is not character {character.name!r}'s ({why}): retarget the dance "
                         "onto the character first")
    order = np.array([where[n] for n in want.names])
    new_index = {int(old): new for new, old in enumerate(order)}
    sk = Skeleton(want.names, want.parents, have.offsets[order], tuple(have.channels[j] for j in order),
                  {new_index[j]: off for j, off in have.end_sites.items()})
    local_pos = None if dance.local_pos is None else dance.local_pos[:, order]
    return MotionClip(sk, dance.fps, dance.root_pos, dance.local_rot[:, order], local_pos, dance.contacts,
                      dict(dance.meta), dance.provenance)


def check_durations(dance_s: float, song_s: float, song_name) -> None:
    """Refuse a dance and a song whose lengths differ by more than 10 % of the song + 1 s."""
    frac, slack = DURATION_TOLERANCE
    if abs(dance_s - song_s) > frac * song_s + slack:
        raise InputError(
            f"the dance lasts {dance_s:.1f} s but the song {song_name} lasts {song_s:.1f} s: they do not belong "
            f"together; render the dance with the song it was made for, or make a dance for this song with "
            f"`dancesynth dance {song_name} -o DANCE.bvh`")


def _probe_song(song_path, out_path: Path):
    from ..io.audio import load_audio, probe_audio

    song_path = Path(song_path)
    if _same_file(song_path, out_path):
        raise InputError(f"output {out_path} is the song itself and would overwrite it; choose another output name")
    info = probe_audio(song_path)
    if not np.isfinite(info.duration_s) or info.duration_s <= 0:
        # The header does not say how long it is: decode (cheaply) to find out.
        y, sr = load_audio(song_path, sr=8000, max_duration_s=None, min_duration_s=0.0)
        if len(y) == 0:
            raise InputError(f"{song_path}: the file contains no audio samples; convert it to wav, flac or ogg")
        info = type(info)(info.path, info.samplerate, info.channels, int(round(len(y) / sr * info.samplerate)),
                          len(y) / sr, info.format, info.backend)
    return info


def _same_file(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
        return a.resolve() == b.resolve()
    except OSError:
        return False


def _find_tool(name: str) -> str:
    exe = shutil.which(name)
    if exe is None:
        raise InputError(f"`{name}` is not installed (or not on PATH); it is needed to write MP4 video: "
                         "install it, e.g. `sudo apt install ffmpeg`")
    return exe


# --------------------------------------------------------------------------- encoding

def source_frames(n_frames: int, clip_fps: float, fps: float) -> np.ndarray:
    """Clip frame shown at each output frame, by nearest frame; spans the clip's duration."""
    duration_s = max(n_frames - 1, 0) / clip_fps
    n = int(np.floor(duration_s * fps + 1e-6)) + 1
    if abs(fps - clip_fps) < 1e-9:
        return np.arange(n_frames)
    return np.clip(np.rint(np.arange(n) * (clip_fps / fps)), 0, n_frames - 1).astype(np.int64)


def _rate(fps: float) -> str:
    r = Fraction(fps).limit_denominator(1001)
    return f"{r.numerator}/{r.denominator}"


def ffmpeg_command(ffmpeg: str, out: Path, *, width: int, height: int, fps: float, n_frames: int,
                   song=None) -> list[str]:
    """The ffmpeg argument list: raw yuv420p frames on stdin (+ the song) -> H.264/AAC MP4 at ``out``."""
    rate = _rate(fps)
    cmd = [ffmpeg, "-nostdin", "-hide_banner", "-loglevel", "error", "-y",
           "-f", "rawvideo", "-pix_fmt", "yuv420p", "-s", f"{width}x{height}", "-framerate", rate,
           "-colorspace", "smpte170m", "-color_range", "tv", "-i", "pipe:0"]
    if song is not None:
        # Read only as much of the song as the video lasts; both start at t = 0.
        cmd += ["-t", f"{n_frames / fps:.6f}", "-i", "file:" + str(Path(song.path).resolve())]
    cmd += ["-map", "0:v:0", "-c:v", "libx264", "-preset", X264_PRESET, "-x264-params", X264_PARAMS,
            "-crf", str(X264_CRF), "-pix_fmt", "yuv420p", "-r", rate]
    if song is not None:
        rate_hz = song.samplerate if song.samplerate in _AAC_RATES else 48000
        cmd += ["-map", "1:a:0", "-c:a", "aac", "-aac_coder", AAC_CODER, "-b:a", AAC_BITRATE,
                "-ac", str(min(max(song.channels, 1), 2)), "-ar", str(rate_hz)]
    cmd += ["-movflags", "+faststart", "-f", "mp4", "file:" + str(Path(out).resolve())]
    return cmd


def _encode(cmd: list[str], frames, total: int, progress, out_path: Path) -> None:
    """Pipe ``frames`` (bytes-like) into ffmpeg; raise ``InputError`` naming ``out_path`` with ffmpeg's message if
    it fails (a full disk, a song it cannot read), ``DanceSynthError`` if this ffmpeg cannot encode at all."""
    every = max(1, total // 200)
    if progress is not None:
        progress(0, total)
    with tempfile.TemporaryFile() as err:
        # Buffered stdin: its write() retries partial writes, so no frame is ever cut short.
        # ffmpeg gets its own process group, so a Ctrl-C is Python's alone to handle (the finally below
        # stops ffmpeg); otherwise ffmpeg might die of it first and the interrupt read as a failed write.
        proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=err, process_group=0)
        _grow_pipe(proc.stdin)
        broken = False
        try:
            try:
                for done, frame in enumerate(frames, 1):
                    proc.stdin.write(frame)
                    if progress is not None and (done % every == 0 or done == total):
                        progress(done, total)
            except BrokenPipeError:
                broken = True  # ffmpeg stopped early; its message says why
            with contextlib.suppress(BrokenPipeError):
                proc.stdin.close()
            try:
                rc = proc.wait(timeout=_FINISH_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                raise DanceSynthError(f"ffmpeg did not finish within {_FINISH_TIMEOUT_S:.0f} s of the last "
                                      "frame; try again, or a smaller --width/--height") from None
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            with contextlib.suppress(OSError):
                proc.stdin.close()
        if rc != 0 or broken:
            err.seek(0)
            raise _ffmpeg_failure(err.read().decode("utf-8", "replace"), rc, out_path)


def _grow_pipe(pipe) -> None:
    """Let the pipe hold most of a frame, so drawing the next frame overlaps ffmpeg reading this one."""
    with contextlib.suppress(AttributeError, OSError):
        import fcntl

        fcntl.fcntl(pipe.fileno(), fcntl.F_SETPIPE_SZ, _PIPE_BYTES)


def _ffmpeg_failure(stderr: str, rc: int, out_path: Path) -> DanceSynthError:
    # The first line names the cause; later ones say what could not be done about it.
    lines = [re.sub(r"^\[[^]]* @ 0x[0-9a-f]+\] ", "", ln.strip()) for ln in stderr.strip().splitlines() if ln.strip()]
    if lines:
        why = lines[0][:300]
    elif rc == -signal.SIGXFSZ:  # killed for a file over the system's size limit: to a user, a full disk
        why = "File too large"
    elif rc < 0:
        why = f"ffmpeg was stopped by signal {-rc}"
    else:
        why = f"ffmpeg exit status {rc}"
    if "Unknown encoder 'libx264'" in stderr or "Encoder not found" in stderr:
        return DanceSynthError(f"this ffmpeg lacks the libx264 encoder ({why}): install a full build "
                               "(e.g. `sudo apt install ffmpeg`)")
    return InputError(f"cannot write {out_path}: {why}; check the free disk space and that the song plays")

"""Live streaming as a user meets it: a growing BVH, real ffmpeg sources, a local HTTP server, stalls, garbage."""

from __future__ import annotations

import io
import os
import re
import resource
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

import signals
from conftest import BUNDLED_MUSIC, REPO
from servers import QuietHandler, http_folder, radio, range_ignoring
from dancesynth.errors import InputError
from dancesynth.io.bvh import read_bvh
from dancesynth.io.bvh_writer import BVHStreamWriter
from dancesynth.live.sources import AudioSource, wait_for_audio
from test_cli import assert_clean_failure, run

VIBE_ACE = BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg"
TRUMPET = BUNDLED_MUSIC / "sorohanro_-_solo-trumpet-06.ogg"


def test_stream_writer_keeps_a_complete_bvh_after_every_segment(tmp_path):
    from dancesynth import dance

    clip = dance(TRUMPET)
    path = tmp_path / "live.bvh"
    cuts = [0, 40, 41, 100, clip.n_frames]
    with BVHStreamWriter(path) as writer:
        for a, b in zip(cuts[:-1], cuts[1:]):
            part = type(clip)(clip.skeleton, clip.fps, clip.root_pos[a:b], clip.local_rot[a:b])
            writer.append(part)
            so_far = read_bvh(path)
            assert so_far.n_frames == b
            np.testing.assert_allclose(so_far.root_pos, clip.root_pos[:b], atol=1e-5)
    final = read_bvh(path)
    np.testing.assert_allclose(final.root_pos, clip.root_pos, atol=1e-5)


def test_file_source_decodes_everything(tmp_path):
    with AudioSource(str(TRUMPET), realtime=False) as src:
        total = 0
        while True:
            try:
                chunk = src.read(timeout=5.0)
            except StopIteration:
                break
            if chunk is not None:
                total += chunk.samples.size
                assert chunk.samples.dtype == np.float32 and np.abs(chunk.samples).max() <= 1.0
    assert total / src.sr == pytest.approx(sf.info(TRUMPET).duration, abs=0.05)


def test_pushed_audio_is_resampled_whole_and_ends_with_why():
    """PCM pushed in odd-sized pieces at 48 kHz reads back as one clean 22.05 kHz stream (what soxr makes of
    it at once); an end with a reason is the source's error; nothing pushed for stall_end_s ends it too."""
    import soxr

    from dancesynth.live.sources import SR, PushedAudio

    y, sr = sf.read(BUNDLED_MUSIC / "sorohanro_-_solo-trumpet-06.ogg", dtype="float32")
    y48 = soxr.resample(y if y.ndim == 1 else y.mean(axis=1), sr, 48000)
    pcm = (np.clip(y48, -1, 1) * 32767).astype("<i2").tobytes()
    source = PushedAudio("the microphone", 48000)
    cuts = [0, 2 * 1000, 2 * 4801, 2 * 30000, len(pcm)]
    for a, b in zip(cuts, cuts[1:]):
        source.push(pcm[a:b])
    source.end("the page stopped")
    got = []
    with pytest.raises(StopIteration):
        while True:
            chunk = source.read(0.05)
            assert chunk is not None
            got.append(chunk.samples)
    got = np.concatenate(got)
    whole = soxr.resample(np.frombuffer(pcm, "<i2").astype(np.float32) / 32768, 48000, SR)
    assert got.size == whole.size and np.abs(got - whole).max() < 1e-3
    assert source.error == "the page stopped" and source.heard_s == pytest.approx(y48.size / 48000, abs=1e-3)
    quiet = PushedAudio("the shared tab", 44100, stall_end_s=0.2)
    assert quiet.read(0.05) is None            # a stall, not yet an end
    with pytest.raises(InputError, match="the shared tab: no audio came for 0.2 s"):
        wait_for_audio(quiet, 5.0)


def test_sources_refuse_what_they_cannot_play(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        AudioSource(str(tmp_path / "missing.ogg"))
    garbage = tmp_path / "noise.mp3"
    garbage.write_bytes(np.random.default_rng(0).bytes(50_000))
    with AudioSource(str(garbage), realtime=False) as src, pytest.raises(InputError, match="no audio"):
        wait_for_audio(src, 10.0)


def _beats_line_up(bvh_path, song, fps=30.0):
    """Hit rate of the dance's kinematic beats on the song's offline beats, and the dance length."""
    from dancesynth.eval.evaluate import evaluate
    from dancesynth.music import analyze_music

    clip = read_bvh(bvh_path)
    music = analyze_music(path=song)
    return evaluate(clip, music_beats_s=music.beat_times_s)["hit_rate"], clip.duration_s


def test_stream_a_file_fast_gives_the_whole_dance(tmp_path):
    out = tmp_path / "live.bvh"
    proc = run("stream", TRUMPET, "--fast", "-o", out, "--segment-seconds", "2", timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "segment   1" in proc.stdout and "wrote" in proc.stdout
    clip = read_bvh(out)
    assert clip.duration_s == pytest.approx(sf.info(TRUMPET).duration, abs=0.2)


@pytest.fixture
def http_server(tmp_path):
    with http_folder(tmp_path) as url:
        yield url


@pytest.mark.slow
def test_stream_over_http_at_real_time_pace(tmp_path, http_server):
    excerpt = tmp_path / "excerpt.ogg"
    subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-t", "14", "-i", str(VIBE_ACE), str(excerpt)], check=True)
    out = tmp_path / "live.bvh"
    t = time.perf_counter()
    proc = run("stream", f"{http_server}/excerpt.ogg", "-o", out, "--segment-seconds", "3", timeout=120)
    wall = time.perf_counter() - t
    assert proc.returncode == 0, proc.stderr
    assert wall >= 13.0  # it really went at the music's pace
    ready = float(re.search(r"first motion ready ([0-9.]+) s", proc.stdout).group(1))
    assert ready <= 3.0 + 0.2 + 0.5  # a segment, our 0.2 s, and ffmpeg's chunking slack
    steps = [float(m) for m in re.findall(r"step\s+([0-9.]+) ms", proc.stdout)]
    assert len(steps) >= 4 and max(steps) < 3000 and "LATE" not in proc.stdout
    hit, duration = _beats_line_up(out, excerpt)
    assert duration == pytest.approx(14.0, abs=0.3)
    offline = tmp_path / "offline.bvh"
    assert run("dance", excerpt, "-o", offline, "-q").returncode == 0
    offline_hit, _ = _beats_line_up(offline, excerpt)
    # Live, the beats are heard as they come: on four 14 s excerpts (streamed fast, 3 and 5 s segments) the
    # live hit rate averages 0.71 against 0.81 offline (0.69 and 0.83 before issue 30); on this excerpt at real
    # time 0.84 against 0.97 (offline 0.90 before).
    assert hit >= offline_hit - 0.15, (hit, offline_hit)


def test_stream_from_stdin_survives_a_stall(tmp_path):
    # 4 s of music, the source goes quiet for 5 s (2.5 segments), then 4 s more.
    y, _ = signals.drum_loop(120, 8.0)
    buf = io.BytesIO()
    sf.write(buf, y, signals.SR, format="WAV", subtype="PCM_16")
    data = buf.getvalue()
    half = 44 + (len(data) - 44) // 2 // 2 * 2
    out = tmp_path / "live.bvh"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(REPO / ".cache" / "numba")}
    proc = subprocess.Popen([sys.executable, "-m", "dancesynth.cli", "stream", "-", "-o", str(out),
                             "--segment-seconds", "2"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=env)
    proc.stdin.write(data[:half])
    proc.stdin.flush()
    time.sleep(5.0)
    stdout, stderr = proc.communicate(input=data[half:], timeout=60)
    assert proc.returncode == 0, stderr.decode()
    text = stdout.decode()
    assert "stalls bridged" in text
    clip = read_bvh(out)
    assert clip.duration_s >= 8.0 + 2.0  # the dancer kept dancing through the stall


def test_stream_bad_input(tmp_path):
    out = tmp_path / "live.bvh"
    garbage = tmp_path / "song.mp3"
    garbage.write_bytes(np.random.default_rng(1).bytes(30_000))
    assert_clean_failure(run("stream", garbage, "--fast", "-o", out), out, "no audio")
    assert_clean_failure(run("stream", tmp_path / "missing.ogg", "-o", out), out, "missing.ogg")
    assert_clean_failure(run("stream", TRUMPET, "-o", tmp_path / "live.txt"), tmp_path / "live.txt", ".bvh")
    assert_clean_failure(run("stream", TRUMPET, "--fast", "--style", "tango", "-o", out), out, "unknown style")


class _Radio(QuietHandler):
    """Serves ``payload`` at ``rate`` bytes/s with no length, like an Internet radio that then goes off air."""

    payload, rate, served = b"", 1.0, 0

    def do_GET(self):
        type(self).served += 1
        if type(self).served > 1:  # off air: ffmpeg's reconnection finds nothing to play
            self.send_error(503)
            return
        self.send_response(200)
        self.send_header("Content-Type", "audio/mpeg")
        self.end_headers()
        step = max(int(self.rate / 10), 1)
        for i in range(0, len(self.payload), step):
            self.wfile.write(self.payload[i:i + step])
            time.sleep(0.1)


class _DroppingServer(QuietHandler):
    """Serves files with ranges, but cuts the first connection off after ``cut`` of the file."""

    cut, requests = 0.4, []

    def do_GET(self):
        data = (Path(self.directory) / self.path.lstrip("/")).read_bytes()
        rng = self.headers.get("Range")
        type(self).requests.append(rng)
        if rng:
            start = int(re.match(r"bytes=(\d+)-", rng).group(1))
            self.send_response(206)
            self.send_header("Content-Range", f"bytes {start}-{len(data) - 1}/{len(data)}")
        else:
            start = 0
            self.send_response(200)
        self.send_header("Accept-Ranges", "bytes")
        self.send_header("Content-Length", str(len(data) - start))
        self.end_headers()
        if len(type(self).requests) == 1:  # the connection drops mid-file
            self.wfile.write(data[:int(len(data) * self.cut)])
            self.wfile.flush()
            self.connection.shutdown(socket.SHUT_RDWR)
            return
        self.wfile.write(data[start:])


def _mp3(tmp_path, seconds: float) -> bytes:
    out = tmp_path / "radio.mp3"
    subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-t", str(seconds), "-i", str(VIBE_ACE), "-vn", "-b:a", "64k",
                    str(out)], check=True)
    return out.read_bytes()


@pytest.mark.slow
def test_a_radio_that_sends_garbage_then_goes_off_air_mid_segment_ends_the_dance_and_says_so(tmp_path):
    """The dance up to the end is kept, complete; since issue 13 the user also learns that the source died
    (exit 2, one line), where it once ended with exit 0 and no notice."""
    mp3 = _mp3(tmp_path, 8.0)
    half = len(mp3) // 2
    garbage = np.random.default_rng(2).bytes(8000)  # one second's worth of noise bytes in the middle
    _Radio.payload, _Radio.rate, _Radio.served = mp3[:half] + garbage + mp3[half:], 8000.0, 0
    out = tmp_path / "live.bvh"
    with http_folder(tmp_path, handler=_Radio) as url:
        proc = run("stream", f"{url}/radio", "-o", out, "--segment-seconds", "3", timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    error = [line for line in proc.stderr.splitlines() if line.startswith("error:")]
    assert len(error) == 1 and "broke off after" in error[0] and "no end mark" in error[0]
    clip = read_bvh(out)
    # It goes off air 8 s in (mid-segment): the dance covers what was heard, plus any time the
    # dancer kept dancing before the end was known (reported as stalls bridged), no more.
    bridged = re.search(r"([\d.]+) s of stalls bridged", proc.stdout)
    bridged_s = float(bridged.group(1)) if bridged else 0.0
    assert bridged_s < 6.0
    assert clip.duration_s == pytest.approx(8.0 + bridged_s, abs=0.6)
    assert np.all(np.isfinite(clip.local_rot))


@pytest.mark.slow
def test_a_dropped_connection_is_resumed_and_the_whole_song_is_danced(tmp_path):
    excerpt = tmp_path / "excerpt.ogg"
    subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-t", "12", "-i", str(VIBE_ACE), str(excerpt)], check=True)
    _DroppingServer.requests = []
    out = tmp_path / "live.bvh"
    with http_folder(tmp_path, handler=_DroppingServer) as url:
        proc = run("stream", f"{url}/excerpt.ogg", "-o", out, "--fast", "-q", timeout=120)
    assert proc.returncode == 0, proc.stderr
    first, resumed = _DroppingServer.requests[:2]
    assert first in (None, "bytes=0-") and int(re.match(r"bytes=(\d+)-", resumed).group(1)) > 0
    assert read_bvh(out).duration_s == pytest.approx(12.0, abs=0.2)


# -- issue 13, item 7: live faults ----------------------------------------------------------------


def _excerpt(tmp_path, fmt: str, seconds: float) -> Path:
    """``seconds`` of Vibe Ace as Ogg, mono WAV or a 64 kbit/s MP3 (8,000 bytes a second)."""
    out = tmp_path / f"excerpt.{fmt}"
    codec = {"ogg": [], "wav": ["-ac", "1"], "mp3": ["-b:a", "64k"]}[fmt]
    subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-t", str(seconds), "-i", str(VIBE_ACE), "-vn", *codec,
                    str(out)], check=True)
    return out


def _stream(*args, stdin: bytes | None = None, preexec=None, timeout=90):
    """``dancesynth stream`` as a user runs it (``run``, with standard input and process limits)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(REPO / ".cache" / "numba")}
    return subprocess.run([sys.executable, "-m", "dancesynth.cli", "stream", *map(str, args)], input=stdin,
                          capture_output=True, env=env, timeout=timeout, preexec_fn=preexec)


def _one_error(proc) -> str:
    stderr = proc.stderr.decode() if isinstance(proc.stderr, bytes) else proc.stderr
    assert "Traceback" not in stderr and "internal error" not in stderr, stderr
    errors = [line for line in stderr.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, stderr
    return errors[0]


@pytest.mark.parametrize("fmt", ["ogg", "wav"])
def test_junk_before_a_stream_on_stdin_is_skipped(tmp_path, fmt):
    """4 KB of noise before the stream (once: 'no audio could be decoded'); MP3 was always found by ffmpeg."""
    song = _excerpt(tmp_path, fmt, 6.0)
    junk = np.random.default_rng(3).bytes(4096)
    out = tmp_path / "live.bvh"
    proc = _stream("-", "-o", out, "--fast", "--segment-seconds", "2", stdin=junk + song.read_bytes())
    assert proc.returncode == 0, proc.stderr.decode()
    assert read_bvh(out).duration_s == pytest.approx(6.0, abs=0.2)


@pytest.mark.parametrize("fmt, stdin", [("ogg", False), ("ogg", True), ("wav", True)])
def test_a_source_cut_off_mid_stream_ends_with_an_error_and_keeps_the_dance(tmp_path, fmt, stdin):
    """A download or a pipe that dies half-way is no normal end (it was exit 0 and no notice)."""
    data = _excerpt(tmp_path, fmt, 10.0).read_bytes()
    cut = tmp_path / f"cut.{fmt}"
    cut.write_bytes(data[:len(data) // 2])
    out = tmp_path / "live.bvh"
    source = "-" if stdin else cut
    proc = _stream(source, "-o", out, "--fast", "--segment-seconds", "2", stdin=cut.read_bytes() if stdin else None)
    assert proc.returncode == 2
    error = _one_error(proc)
    assert "broke off" in error and "cut off" in error and str(out) in error
    assert read_bvh(out).duration_s == pytest.approx(5.0, abs=0.5)


def test_a_server_that_ignores_range_is_not_replayed_as_new_music(tmp_path):
    """ffmpeg's reconnect to a server that ignores Range played the file from its start again, forever
    (6,615 s 'heard' in 61 s): now the stream ends where the connection broke, with an error."""
    song = _excerpt(tmp_path, "mp3", 10.0)
    handler = range_ignoring(cut=0.4)
    out = tmp_path / "live.bvh"
    with http_folder(tmp_path, handler=handler) as url:
        proc = _stream(f"{url}/{song.name}", "-o", out, "--fast", "--segment-seconds", "2", timeout=60)
    assert proc.returncode == 2
    assert "broke off" in _one_error(proc)
    assert read_bvh(out).duration_s <= 0.4 * 10.0 + 0.5
    assert handler.requests == 1


def _disk_of(limit: int):
    def preexec():
        # A full disk for real, without root: a write past ``limit`` bytes fails with EFBIG.
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return preexec


def test_a_full_disk_leaves_a_complete_bvh_of_every_segment_written(tmp_path):
    """It left an unreadable BVH and an internal error; now the BVH holds each segment reported, also
    when more segments were already on their way when the disk filled up (20 s of music, 2 s segments)."""
    out = tmp_path / "live.bvh"
    song = _excerpt(tmp_path, "ogg", 20.0)
    proc = _stream(song, "-o", out, "--fast", "--segment-seconds", "2", preexec=_disk_of(150_000))
    assert proc.returncode == 2
    error = _one_error(proc)
    assert error.startswith(f"error: cannot write {out}:") and "File too large" in error
    ends = [float(m) for m in re.findall(rb"motion\s+[\d.]+-\s*([\d.]+) s", proc.stdout)]
    assert ends, proc.stdout.decode()
    clip = read_bvh(out)
    assert clip.duration_s == pytest.approx(ends[-1], abs=1.5 / clip.fps)
    assert np.all(np.isfinite(clip.local_rot))


def _frames_on_disk(path: Path) -> int:
    match = re.search(rb"Frames:\s*(\d+)", path.read_bytes()[:1 << 16]) if path.exists() else None
    return int(match.group(1)) if match else 0


@pytest.mark.slow
def test_a_radio_that_stalls_keeps_the_dancer_dancing_in_real_time(tmp_path):
    """4 s of music, 8 s of nothing on an open connection, 3 s more: motion reaches the BVH all through
    the stall at the wall clock's pace (a segment's wait at most), not in one burst when music returns."""
    mp3 = _excerpt(tmp_path, "mp3", 7.0).read_bytes()
    stall_s, segment_s = 8.0, 2.0
    handler = radio(mp3, 8000.0, stall_at=4 * 8000, stall_s=stall_s)
    out = tmp_path / "live.bvh"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(REPO / ".cache" / "numba")}
    with http_folder(tmp_path, handler=handler) as url:
        proc = subprocess.Popen([sys.executable, "-m", "dancesynth.cli", "stream", f"{url}/radio", "-o", str(out),
                                 "--segment-seconds", str(segment_s)], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, env=env)
        seen = []  # (wall time, frames on disk)
        deadline = time.monotonic() + 90
        while proc.poll() is None and time.monotonic() < deadline:
            seen.append((time.monotonic(), _frames_on_disk(out)))
            time.sleep(0.1)
        proc.kill()
        _, stderr = proc.communicate()
    start = handler.stall_until - stall_s
    during = [n for t, n in seen if start <= t <= handler.stall_until]
    # Motion for all the stall but the wait before it counts as one and a segment's cut.
    assert (during[-1] - during[0]) / 30.0 >= stall_s - 2 * segment_s - 0.5, seen
    assert "Traceback" not in stderr.decode()


def test_every_viewer_of_a_source_that_dies_is_told(tmp_path):
    """The web live view of a radio that goes off air: each viewer gets an error saying it broke off
    (it ended with an 'end' message, as if the song was over)."""
    from urllib.parse import urlencode

    from servers import uvicorn_server
    from serve_support import live_messages
    from dancesynth.web.server import create_app

    mp3 = _excerpt(tmp_path, "mp3", 5.0).read_bytes()
    with http_folder(tmp_path, handler=radio(mp3, 8000.0, stall_at=3 * 8000, resume=False)) as url, \
            uvicorn_server(create_app()) as server:
        query = urlencode({"url": f"{url}/radio", "segment_s": 1})
        results = [None, None]
        viewers = [threading.Thread(target=lambda i=i: results.__setitem__(i, live_messages(server, query, 60)))
                   for i in range(2)]
        for v in viewers:
            v.start()
        for v in viewers:
            v.join(timeout=90)
    for messages, _ in results:
        assert messages[-1]["type"] == "error" and "broke off" in messages[-1]["error"], messages[-3:]
        assert any(m["type"] == "frames" for m in messages)


@pytest.mark.parametrize("fmt", ["ogg", "wav"])
def test_a_stream_without_a_length_that_reaches_its_end_is_a_normal_end(tmp_path, fmt):
    """Issue 31: an http stream that ends without Content-Length was "the stream broke off" (exit 2) even when
    the Ogg stream ended with its last page and every second was danced; the container's own end decides."""
    song = _excerpt(tmp_path, fmt, 6.0)
    data = song.read_bytes()
    for payload, whole in ((data, True), (data[:len(data) // 2], False)):
        out = tmp_path / f"live-{whole}.bvh"
        with http_folder(tmp_path, handler=radio(payload, 400000.0, content_type=f"audio/{fmt}")) as url:
            proc = _stream(f"{url}/{song.name}", "-o", out, "--fast", "--segment-seconds", "2")
        if whole:
            assert proc.returncode == 0, proc.stderr.decode()
            assert read_bvh(out).duration_s == pytest.approx(6.0, abs=0.2)
        else:
            assert proc.returncode == 2 and "cut off" in _one_error(proc)

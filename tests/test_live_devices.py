"""Dancing to the computer's own sound: ``stream system`` and ``stream mic`` through a real PulseAudio server.

A private PulseAudio daemon (its own runtime folder) with a null sink stands in for the user's desktop:
a known song is played into it at real-time pace, as a media player would, and the dance hears it
through the sink's monitor. Skipped, with the reason, where no PulseAudio server can run.
"""

from __future__ import annotations

import os
import queue
import re
import shutil
import signal
import subprocess
import sys
import threading
import time

import pytest

from conftest import BUNDLED_MUSIC, REPO
from dancesynth.io.bvh import read_bvh
from test_cli import assert_clean_failure, run

VIBE_ACE = BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg"   # 130 bpm


@pytest.fixture(scope="module")
def sound_server(tmp_path_factory):
    """The environment of a running PulseAudio server whose default output is a null sink."""
    if shutil.which("pulseaudio") is None:
        pytest.skip("pulseaudio is not installed (bash scripts/setup.sh --test installs it)")
    runtime = tmp_path_factory.mktemp("xdg")
    runtime.chmod(0o700)
    env = {**os.environ, "XDG_RUNTIME_DIR": str(runtime), "NUMBA_CACHE_DIR": str(REPO / ".cache" / "numba")}
    env.pop("PULSE_SERVER", None)
    proc = subprocess.run(["pulseaudio", "--daemonize=yes", "--exit-idle-time=-1", "-n",
                           "--load=module-native-protocol-unix", "--load=module-null-sink sink_name=dancesynth_test"],
                          env=env, capture_output=True, text=True, timeout=30)
    deadline = time.monotonic() + 10
    while not (runtime / "pulse" / "native").exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    if proc.returncode != 0 or not (runtime / "pulse" / "native").exists():
        pytest.skip(f"no PulseAudio server could start here: {proc.stderr.strip()[-300:]}")
    yield env
    subprocess.run(["pulseaudio", "--kill"], env=env, capture_output=True, timeout=30)


def _dance_while_a_song_plays(source: str, env, out, segments: int) -> subprocess.CompletedProcess:
    """``dancesynth stream SOURCE`` while the song plays into the default output at real-time pace (as a media
    player does), until it has danced ``segments`` segments, then Ctrl-C: the dance ends with the segment being
    heard. Bounded: a stream that dances nothing within a minute is stopped all the same."""
    player = subprocess.Popen(["ffmpeg", "-hide_banner", "-loglevel", "error", "-re", "-t", "60", "-i",
                               str(VIBE_ACE), "-f", "pulse", "test player"], env=env, stdin=subprocess.DEVNULL)
    lines: queue.Queue = queue.Queue()
    try:
        proc = subprocess.Popen([sys.executable, "-m", "dancesynth.cli", "stream", source, "-o", str(out),
                                 "--segment-seconds", "3"], env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        threading.Thread(target=lambda: [lines.put(x) for x in proc.stdout] + [lines.put(None)], daemon=True).start()
        printed, danced, deadline = [], 0, time.monotonic() + 60
        while danced < segments and time.monotonic() < deadline:
            try:
                line = lines.get(timeout=max(0.1, deadline - time.monotonic()))
            except queue.Empty:
                break
            if line is None:
                break
            printed.append(line)
            danced += line.startswith("segment ")
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=60)            # (standard output is the reader thread's; standard error is short)
        stderr = proc.stderr.read()
        while (line := lines.get(timeout=10)) is not None:
            printed.append(line)
    finally:
        player.kill()
    stdout = "".join(printed)
    assert danced == segments, stdout + stderr
    assert proc.returncode == 0 and "stopping" in stderr and "Traceback" not in stderr, stderr
    return subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr)


def _danced_s(stdout: str) -> float:
    """Where the last segment the stream reported ends, in seconds of dance."""
    return float(re.findall(r"motion\s+[\d.]+-\s*([\d.]+) s", stdout)[-1])


def test_stream_system_dances_to_what_the_computer_plays(sound_server, tmp_path):
    out = tmp_path / "system.bvh"
    proc = _dance_while_a_song_plays("system", sound_server, out, 4)
    tempo = float(re.search(r"^style .*, ([\d.]+) bpm$", proc.stdout, re.M).group(1))
    assert min(abs(tempo - 130.3 * k) for k in (0.5, 1.0, 2.0)) < 4.0, proc.stdout   # the song's tempo was heard
    assert read_bvh(out).n_frames >= round(_danced_s(proc.stdout) * 30) - 1          # every segment danced is on disk


def test_stream_mic_reads_the_default_input(sound_server, tmp_path):
    # Here the default input is the null sink's monitor (the machine has no microphone): the song again.
    out = tmp_path / "mic.bvh"
    proc = _dance_while_a_song_plays("mic", sound_server, out, 2)
    assert read_bvh(out).n_frames >= round(_danced_s(proc.stdout) * 30) - 1


def test_no_sound_server_is_a_clear_error(tmp_path):
    empty = tmp_path / "runtime"
    empty.mkdir(mode=0o700)
    env = {**os.environ, "XDG_RUNTIME_DIR": str(empty), "PULSE_SERVER": f"unix:{empty}/none"}
    out = tmp_path / "live.bvh"
    proc = subprocess.run([sys.executable, "-m", "dancesynth.cli", "stream", "system", "-o", str(out)], env=env,
                          capture_output=True, text=True, timeout=60)
    assert_clean_failure(proc, out, "PulseAudio")
    assert_clean_failure(run("stream", "alsa:no-such-device", "-o", out), out, "arecord -L")

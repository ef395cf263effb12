"""Dancing to the computer's own sound: ``stream system`` and ``stream mic`` through a real PulseAudio server.

A private PulseAudio daemon (its own runtime folder) with a null sink stands in for the user's desktop:
a known song is played into it at real-time pace, as a media player would, and the dance hears it
through the sink's monitor. Skipped, with the reason, where no PulseAudio server can run.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
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


def _dance_while_a_song_plays(source: str, env, out, seconds: float) -> subprocess.CompletedProcess:
    """``dancesynth stream SOURCE`` for ``seconds`` while the song plays into the default output at real-time
    pace (as a media player does), then Ctrl-C: the dance ends with the segment being heard."""
    player = subprocess.Popen(["ffmpeg", "-hide_banner", "-loglevel", "error", "-re", "-t", str(seconds + 10), "-i",
                               str(VIBE_ACE), "-f", "pulse", "test player"], env=env, stdin=subprocess.DEVNULL)
    try:
        proc = subprocess.Popen([sys.executable, "-m", "dancesynth.cli", "stream", source, "-o", str(out),
                                 "--segment-seconds", "3", "-q"], env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        time.sleep(seconds)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        player.kill()
    assert proc.returncode == 0 and "stopping" in stderr and "Traceback" not in stderr, stderr
    return subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr)


def test_stream_system_dances_to_what_the_computer_plays(sound_server, tmp_path):
    out = tmp_path / "system.bvh"
    proc = _dance_while_a_song_plays("system", sound_server, out, 15)
    tempo = float(re.search(r"^style .*, ([\d.]+) bpm$", proc.stdout, re.M).group(1))
    assert min(abs(tempo - 130.3 * k) for k in (0.5, 1.0, 2.0)) < 4.0, proc.stdout   # the song's tempo was heard
    assert read_bvh(out).n_frames >= 6 * 30                                         # seconds of dance on disk


def test_stream_mic_reads_the_default_input(sound_server, tmp_path):
    # Here the default input is the null sink's monitor (the machine has no microphone): the song again.
    out = tmp_path / "mic.bvh"
    _dance_while_a_song_plays("mic", sound_server, out, 8)
    assert read_bvh(out).n_frames > 0


def test_no_sound_server_is_a_clear_error(tmp_path):
    empty = tmp_path / "runtime"
    empty.mkdir(mode=0o700)
    env = {**os.environ, "XDG_RUNTIME_DIR": str(empty), "PULSE_SERVER": f"unix:{empty}/none"}
    out = tmp_path / "live.bvh"
    proc = subprocess.run([sys.executable, "-m", "dancesynth.cli", "stream", "system", "-o", str(out)], env=env,
                          capture_output=True, text=True, timeout=60)
    assert_clean_failure(proc, out, "PulseAudio")
    assert_clean_failure(run("stream", "alsa:no-such-device", "-o", out), out, "arecord -L")

"""The command line as a user meets it: real processes, real files, every bad input."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from conftest import BUNDLED_MUSIC, REPO, SHARED_MOCAP

TRUMPET = BUNDLED_MUSIC / "sorohanro_-_solo-trumpet-06.ogg"


def run(*args, cwd=None, timeout=120):
    env = dict(os.environ)
    env.setdefault("NUMBA_CACHE_DIR", str(REPO / ".cache" / "numba"))
    return subprocess.run([sys.executable, "-m", "dancesynth.cli", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, env=env, timeout=timeout)


def cli(*args) -> subprocess.CompletedProcess:
    """The command line run in this process, as ``run`` but without starting Python again: for
    checks of what a command says and leaves behind (``run`` where the process itself matters)."""
    import contextlib
    import io

    from dancesynth.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return subprocess.CompletedProcess(list(args), code, out.getvalue(), err.getvalue())


def assert_clean_failure(proc, out: Path, *words):
    assert proc.returncode != 0, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    ours = [ln for ln in lines if ln.startswith("error:")]
    assert len(ours) == 1, proc.stderr
    for w in words:
        assert w.lower() in ours[0].lower(), ours[0]
    assert not out.exists()
    assert not list(out.parent.glob(f".{out.name}.*")), "a partial file was left behind"


@pytest.fixture
def out(tmp_path):
    return tmp_path / "dance.bvh"


def test_dance_on_a_bundled_song_writes_a_bvh_and_a_summary(tmp_path, out):
    proc = run("dance", TRUMPET, "-o", out)
    assert proc.returncode == 0, proc.stderr
    for word in ("tempo", "beats", "style", "segment", "wrote"):
        assert word in proc.stdout
    from dancesynth.io.bvh import read_bvh

    clip = read_bvh(out)
    assert clip.fps == pytest.approx(30.0)
    assert clip.n_frames == int(sf.info(TRUMPET).duration * 30) + 1


def test_styles_lists_the_bundled_styles():
    proc = run("styles")
    assert proc.returncode == 0, proc.stderr
    for name in ("salsa", "pop-82-103bpm", "pop-106-124bpm", "indian"):
        assert name in proc.stdout
    assert "jpop" not in proc.stdout          # the Perfume clips are not ours to redistribute


def test_missing_file(out):
    assert_clean_failure(cli("dance", out.parent / "nope.ogg", "-o", out), out, "nope.ogg")


def test_empty_file(tmp_path, out):
    empty = tmp_path / "empty.wav"
    empty.write_bytes(b"")
    assert_clean_failure(cli("dance", empty, "-o", out), out, "empty")


def test_text_file_named_mp3(tmp_path, out):
    fake = tmp_path / "song.mp3"
    fake.write_text("this is not music\n" * 50)
    assert_clean_failure(cli("dance", fake, "-o", out), out, "song.mp3")


def test_truncated_ogg(tmp_path, out):
    src = BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg"
    cut = tmp_path / "cut.ogg"
    cut.write_bytes(src.read_bytes()[: int(src.stat().st_size * 0.4)])
    assert_clean_failure(cli("dance", cut, "-o", out), out, "truncated")


def test_silence(tmp_path, out):
    path = tmp_path / "silence.wav"
    sf.write(path, np.zeros(22050 * 10, dtype=np.float32), 22050)
    assert_clean_failure(cli("dance", path, "-o", out), out, "silent")


def test_white_noise_dances_at_the_default_tempo(tmp_path, out):
    path = tmp_path / "noise.wav"
    sf.write(path, np.random.default_rng(0).normal(0, 0.2, 22050 * 10).astype(np.float32), 22050)
    proc = run("dance", path, "-o", out)
    assert proc.returncode == 0, proc.stderr
    assert "no clear beat" in proc.stdout and "100.0 bpm" in proc.stdout
    assert out.exists()


def test_two_second_song(tmp_path, out):
    y, sr = sf.read(TRUMPET)
    path = tmp_path / "short.wav"
    sf.write(path, y[: 2 * sr], sr)
    assert_clean_failure(cli("dance", path, "-o", out), out, "short")


def test_one_hour_song_is_refused_quickly(tmp_path, out):
    path = tmp_path / "hour.wav"
    rate = 8000
    with sf.SoundFile(path, "w", samplerate=rate, channels=1, subtype="PCM_U8") as fh:
        block = (np.random.default_rng(1).normal(0, 0.1, rate * 60)).astype(np.float32)
        for _ in range(60):
            fh.write(block)
    proc = run("dance", path, "-o", out, timeout=30)
    assert_clean_failure(proc, out, "--max-minutes")


def test_unknown_style(out):
    assert_clean_failure(cli("dance", TRUMPET, "-o", out, "--style", "tango"), out, "tango", "styles")


def test_database_folder_without_bvh(tmp_path, out):
    folder = tmp_path / "db"
    folder.mkdir()
    (folder / "readme.txt").write_text("no motion here")
    assert_clean_failure(cli("dance", TRUMPET, "-o", out, "--database", folder), out, "no motion files")


def test_malformed_bvh_inside_a_database(tmp_path, out):
    folder = tmp_path / "db" / "salsa"
    folder.mkdir(parents=True)
    good = REPO / "tests" / "data" / "mocap"
    for p in sorted(good.rglob("*.bvh"))[:1]:
        shutil.copy(p, folder / p.name)
    (folder / "broken.bvh").write_text("HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition "
                                       "Zposition Zrotation Xrotation Yrotation\n}\nMOTION\nFrames: 3\n"
                                       "Frame Time: 0.033333\n0 0 0 0 0 0\n0 0 0\n")
    env_cache = tmp_path / "cache"
    proc = subprocess.run([sys.executable, "-m", "dancesynth.cli", "dance", str(TRUMPET), "-o", str(out),
                           "--database", str(tmp_path / "db")], capture_output=True, text=True,
                          env={**os.environ, "DANCESYNTH_CACHE": str(env_cache)}, timeout=120)
    assert_clean_failure(proc, out, "broken.bvh")


def test_output_into_a_missing_folder(tmp_path):
    out = tmp_path / "missing" / "dance.bvh"
    proc = run("dance", TRUMPET, "-o", out)
    assert proc.returncode != 0 and "Traceback" not in proc.stderr
    assert "does not exist" in proc.stderr


@pytest.mark.skipif(not SHARED_MOCAP.is_dir(), reason="shared mocap not available")
def test_a_user_database_of_bvh_files_is_built_and_used(tmp_path, out):
    folder = tmp_path / "mydb" / "jpop"
    folder.mkdir(parents=True)
    for p in sorted((SHARED_MOCAP / "perfume_mit").glob("*.bvh")):
        shutil.copy(p, folder / p.name)
    env = {**os.environ, "DANCESYNTH_CACHE": str(tmp_path / "cache")}
    proc = subprocess.run([sys.executable, "-m", "dancesynth.cli", "styles", "--database", str(tmp_path / "mydb")],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "jpop" in proc.stdout
    proc = subprocess.run([sys.executable, "-m", "dancesynth.cli", "dance", str(TRUMPET), "-o", str(out),
                           "--database", str(tmp_path / "mydb")], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert out.exists()


def test_graph_thresholds_are_checked(out):
    assert_clean_failure(cli("dance", TRUMPET, "-o", out, "--thr", "0.5"), out, "THR")


@pytest.mark.parametrize("args, words", [(("--lookahead", "-1"), ("look-ahead", "0 to 600")),
                                         (("--lookahead", "nan"), ("look-ahead",)),
                                         (("--lookahead", "5", "--engine", "global"), ("--lookahead", "global"))])
def test_lookahead_is_checked(out, args, words):
    assert_clean_failure(cli("dance", TRUMPET, "-o", out, *args), out, *words)


def test_build_db_writes_a_database_that_dance_can_use(tmp_path, out):
    db = tmp_path / "built"
    proc = run("build-db", REPO / "tests" / "data" / "mocap", "-o", db)
    assert proc.returncode == 0, proc.stderr
    assert (db / "database.json").is_file()
    proc = run("dance", TRUMPET, "-o", out, "--database", db, "--style", "cmu_daz_salsa")
    assert proc.returncode == 0, proc.stderr
    assert "cmu_daz_salsa" in proc.stdout and out.exists()


@pytest.mark.parametrize("args, words", [
    (("--seed", "-1"), ("seed -1", "whole number")),             # issue 13: was exit 70, "internal error"
    (("--max-minutes", "nan"), ("length limit", "nan")),  # issue 13: switched the limit off
])
def test_nonsense_options_are_refused(out, args, words):
    assert_clean_failure(cli("dance", TRUMPET, "-o", out, *args), out, *words)


def test_dance_config_refuses_seeds_numpy_cannot_take():
    from dancesynth.api import DanceConfig
    from dancesynth.errors import InputError

    for seed in (-1, 2**63, 1.5, True):
        with pytest.raises(InputError, match="seed"):
            DanceConfig(seed=seed)
    assert DanceConfig(seed=2**63 - 1).seed == 2**63 - 1


def test_a_report_that_cannot_be_written_leaves_no_dance_behind(tmp_path, out):
    """Issue 13: the BVH was written, then the report failed. Both are written, or neither."""
    proc = run("dance", TRUMPET, "-o", out, "--report", tmp_path / "no_such_folder" / "r.json")
    assert_clean_failure(proc, out, "no_such_folder")


def test_a_full_disk_is_a_one_line_error_naming_the_file(tmp_path):
    """Issue 13: a write that fails half-way (a full disk: ENOSPC) leaves nothing and says why."""
    from dancesynth.errors import InputError
    from dancesynth.io.files import atomic_output

    target = tmp_path / "dance.bvh"
    with pytest.raises(InputError, match="cannot write .*dance.bvh: No space left on device"):
        with atomic_output(target) as fh:
            fh.write("x")
            raise OSError(28, "No space left on device")
    assert not target.exists() and not list(tmp_path.iterdir())


def test_ctrl_c_while_the_command_starts_says_interrupted_without_a_traceback():
    import signal

    command = Path(sys.executable).parent / "dancesynth"
    for delay in (0.05, 0.1, 0.15, 0.2, 0.3, 0.4):
        # Ctrl-C's default action restored in the child (a shell's background job would ignore it).
        proc = subprocess.Popen([str(command), "styles"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        time.sleep(delay)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
        assert "Traceback" not in err, (delay, err)
        assert proc.returncode in (0, 130, -signal.SIGINT), (delay, proc.returncode, err)
        if proc.returncode == 130:
            assert err.strip().splitlines()[-1] == "interrupted"


def test_the_last_fuzzed_option_failures_are_one_line_errors(tmp_path):
    """Issue 13, found by tests/fuzz/cli_target.py: each of these ended in exit 70."""
    song = tmp_path / "song.wav"
    sf.write(song, 0.2 * np.sin(2 * np.pi * 220 * np.arange(5 * 22050) / 22050), 22050)
    out = tmp_path / "o.bvh"
    for fps in ("0", "-0", "inf", "nan", "1e9"):
        assert_clean_failure(cli("stream", song, "-o", out, "--fast", "-q", "--fps", fps), out, "frame rate")
    unwritable = Path("/proc/o.bvh")  # its folder exists, but no file can be made there
    proc = cli("stream", song, "-o", unwritable, "--fast", "-q")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and str(unwritable) in proc.stderr
    proc = cli("bench", "--quick", "--out", "/proc/x")
    assert proc.returncode == 2 and "cannot write /proc/x" in proc.stderr
    for minutes in ("1e-300", "0", "nan", "inf"):
        proc = cli("train", "--config", "tiny", "--minutes", minutes, "--out", tmp_path / "w.pt", "-q")
        assert proc.returncode == 2 and "--minutes" in proc.stderr, proc.stderr
    assert not (tmp_path / "w.pt").exists()

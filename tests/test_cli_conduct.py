"""`dancesynth conduct` as a user meets it: real processes, real files, every bad input."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from procedural_songs import chorale_midi, drum_beats, phrase_song
from test_cli import cli

from conftest import BUNDLED_MUSIC, REPO
from dancesynth.bench import groundtruth as gt
from dancesynth.io.bvh import read_bvh
from dancesynth.kinematics import clip_fk
from dancesynth.motion.roles import find_roles
from dancesynth.music.notes import DRUM_CHANNEL, write_midi_parts

TRUMPET = BUNDLED_MUSIC / "sorohanro_-_solo-trumpet-06.ogg"


def run(*args, timeout=120):
    env = dict(os.environ)
    env.setdefault("NUMBA_CACHE_DIR", str(REPO / ".cache" / "numba"))
    return subprocess.run([sys.executable, "-m", "dancesynth.cli", "conduct", *map(str, args)],
                          capture_output=True, text=True, env=env, timeout=timeout)


def assert_clean_failure(proc, out: Path, *words):
    assert proc.returncode != 0, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), proc.stderr
    for w in words:
        assert w.lower() in lines[0].lower(), lines[0]
    assert not out.exists()
    assert not list(out.parent.glob(f".{out.name}.*")), "a partial file was left behind"


def assert_upper_body_dance(path: Path, duration_s: float):
    clip = read_bvh(path)
    assert clip.n_frames >= int(duration_s * 30)
    _, pos = clip_fk(clip)
    roles = find_roles(clip.skeleton)
    assert np.ptp(pos[:, roles.wrists[1]], axis=0).max() > 0.1       # the right hand draws
    assert np.ptp(pos[:, roles.ankles[0]], axis=0).max() < 1e-3      # the feet stand


def test_conduct_midi_with_a_real_drum_track(tmp_path):
    gt.write_midi(gt.SongSpec("song", (110,), duration_s=12.0, seed=2), tmp_path / "song.mid")
    out = tmp_path / "song.bvh"
    proc = run(tmp_path / "song.mid", "-o", out, "--param", "l1=0.3", "--param", "bounce=0.8")
    assert proc.returncode == 0, proc.stderr
    assert "segments" in proc.stdout and "wrote" in proc.stdout
    assert_upper_body_dance(out, 12.0)


def test_conduct_bach_chorale_from_music21(tmp_path):
    pytest.importorskip("music21")
    path = chorale_midi(tmp_path / "chorale.mid")
    listing = run(path, "--list-tracks")
    assert listing.returncode == 0
    assert "'Soprano'" in listing.stdout.splitlines()[0] and "<- melody" in listing.stdout.splitlines()[0]
    assert "<- rhythm" in listing.stdout.splitlines()[-1]
    config = tmp_path / "look.toml"
    config.write_text('style = "lively"\nw1 = 2.0\n')
    out = tmp_path / "chorale.bvh"
    proc = run(path, "-o", out, "--config", config, "--melody-track", "0", "--rhythm-track", "4")
    assert proc.returncode == 0, proc.stderr
    assert_upper_body_dance(out, 20.0)


@pytest.mark.slow
def test_conduct_a_recording(tmp_path):
    out = tmp_path / "trumpet.bvh"
    proc = run(TRUMPET, "-o", out)
    assert proc.returncode == 0, proc.stderr
    assert "(audio)" in proc.stdout
    assert_upper_body_dance(out, 5.0)


def _write_bad(tmp_path: Path, case: str) -> Path:
    path = tmp_path / f"{case}.mid"
    if case == "empty":
        path.write_bytes(b"")
    elif case == "corrupted":
        phrase_song(tmp_path / "whole.mid")
        data = bytearray((tmp_path / "whole.mid").read_bytes())
        path.write_bytes(bytes(data[:40]) + b"\xff\x00garbage")
    elif case == "drums_only":
        write_midi_parts(path, [("Drums", DRUM_CHANNEL, drum_beats(8))])
    elif case == "no_notes":
        write_midi_parts(path, [("Silence", 0, [])])
    return path


@pytest.mark.parametrize("case, words", [
    ("empty", ("not a readable MIDI file",)),
    ("corrupted", ("not a readable MIDI file",)),
    ("drums_only", ("no melody",)),
    ("no_notes", ("no notes",)),
])
def test_bad_midi_files(tmp_path, case, words):
    out = tmp_path / "out.bvh"
    assert_clean_failure(cli("conduct", _write_bad(tmp_path, case), "-o", out), out, *words)


def test_bad_options(tmp_path):
    song = phrase_song(tmp_path / "p.mid")
    out = tmp_path / "out.bvh"
    assert_clean_failure(cli("conduct", song, "-o", out, "--param", "l1=huge"), out, "l1", "number")
    assert_clean_failure(cli("conduct", song, "-o", out, "--param", "speed=3"), out, "unknown parameter")
    assert_clean_failure(cli("conduct", song, "-o", out, "--melody-track", "9"), out, "no part 9")
    assert_clean_failure(cli("conduct", song, "-o", tmp_path / "out.txt"), tmp_path / "out.txt", ".bvh")
    assert_clean_failure(cli("conduct", tmp_path / "missing.mid", "-o", out), out, "no such")
    assert_clean_failure(cli("conduct", TRUMPET, "-o", out, "--melody-track", "1"), out, "recording")
    assert_clean_failure(cli("conduct", TRUMPET, "--list-tracks"), out, "recording")

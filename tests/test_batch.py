"""``dancesynth batch``: a music library danced on a process pool and on a real local Ray cluster,
with a corrupt file among good ones, an interrupted run resumed, and workers killed mid-song."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import BUNDLED_MUSIC

import dancesynth
from dancesynth.batching.manifest import MANIFEST_NAME
from dancesynth.errors import InputError
from dancesynth.io.bvh import read_bvh

EXCERPT_S = 6.0
EVAL_KEYS = {"hit_rate", "bas_motion", "accent_recall_x_chance", "foot_skate_m_s", "jerk_vs_mocap"}
DANCESYNTH = Path(sys.executable).with_name("dancesynth")


@pytest.fixture(scope="module")
def library(tmp_path_factory) -> Path:
    """A small music library of real songs: excerpts of the bundled ones, in two albums, two songs
    called the same, and a corrupt file in the middle."""
    root = tmp_path_factory.mktemp("library")
    for name, source, start in (("a/hungarian", "Hungarian", 10), ("a/karissa", "Karissa", 20),
                                ("b/tchaikovsky", "Kevin_MacLeod_-_P_I", 30), ("b/vibe", "Kevin_MacLeod_-_Vibe", 5)):
        out = root / f"{name}.ogg"
        out.parent.mkdir(exist_ok=True)
        song = next(BUNDLED_MUSIC.glob(f"{source}*.ogg"))
        subprocess.run(["ffmpeg", "-v", "error", "-y", "-ss", str(start), "-t", str(EXCERPT_S), "-i", str(song),
                        "-c:a", "libvorbis", str(out)], check=True)
    shutil.copy(root / "a" / "hungarian.ogg", root / "b" / "same.ogg")
    shutil.copy(root / "b" / "vibe.ogg", root / "a" / "same.ogg")
    (root / "a" / "broken.ogg").write_bytes(b"OggS" + bytes(range(256)) * 8)   # a truncated, corrupt upload
    (root / "a" / "cover.jpg").write_bytes(b"\xff\xd8 not music")              # not audio: not a song
    return root


def records(out_dir: Path) -> list[dict]:
    return [json.loads(line) for line in (out_dir / MANIFEST_NAME).read_text().splitlines() if line.strip()]


def no_partial_files(out_dir: Path) -> bool:
    return not [p for p in out_dir.rglob("*") if p.name.endswith(".part")]


def run_cli(*args, timeout=300) -> subprocess.CompletedProcess:
    return subprocess.run([str(DANCESYNTH), *map(str, args)], capture_output=True, text=True, timeout=timeout)


def test_a_folder_on_the_process_pool_one_bad_song_never_stops_the_batch(library, tmp_path):
    out = tmp_path / "dances"
    result = dancesynth.batch(folder=library, out_dir=out, workers=2, evaluate=True)
    assert (result.done, result.failed, result.skipped) == (6, 1, 0)
    (song, error), = result.errors
    assert song.endswith("broken.ogg") and "broken.ogg" in error and "Traceback" not in error
    # The albums are kept, and two songs of the same name in two albums do not overwrite each other.
    danced = sorted(str(p.relative_to(out)) for p in out.rglob("*.bvh"))
    assert danced == ["a/hungarian.bvh", "a/karissa.bvh", "a/same.bvh", "b/same.bvh", "b/tchaikovsky.bvh",
                      "b/vibe.bvh"]
    for path in out.rglob("*.bvh"):
        clip = read_bvh(path)
        assert abs(clip.duration_s - EXCERPT_S) < 0.5, path   # a whole dance for each whole song
        assert clip.skeleton.n_joints == 22                    # on the default character, the mannequin
    lines = records(out)
    assert len(lines) == 7 and {r["status"] for r in lines} == {"done", "failed"}
    done = [r for r in lines if r["status"] == "done"]
    for r in done:
        assert r["summary"]["beats"] > 0 and r["timings_s"]["synthesis_s"] > 0 and r["attempts"] == 1
        assert r["provenance"]["engine"] == "streaming" and r["provenance"]["config"]["segment_s"] == 5.0
        assert EVAL_KEYS <= set(r["eval"])
    assert len({r["worker"] for r in done}) == 2                # both workers danced
    assert no_partial_files(out)


def test_the_cli_exit_code_says_a_song_failed_and_a_rerun_skips_finished_songs(library, tmp_path):
    out = tmp_path / "dances"
    first = run_cli("batch", "--folder", library, "-o", out, "--workers", "2", "--format", "glb")
    assert first.returncode == 1, first.stderr
    assert "broken.ogg" in first.stderr and "1 song(s) failed" in first.stderr and "Traceback" not in first.stderr
    assert "danced    6 song(s), 1 failed" in first.stdout
    made = {p: p.stat().st_mtime_ns for p in out.rglob("*.glb")}
    assert len(made) == 6 and all(p.read_bytes()[:4] == b"glTF" for p in made)
    again = run_cli("batch", "--folder", library, "-o", out, "--workers", "2", "--format", "glb")
    assert again.returncode == 1 and "6 already done (skipped)" in again.stdout     # only the broken one again
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*.glb")} == made            # finished dances untouched
    assert len(records(out)) == 8
    # Other settings are another batch: the finished songs are danced again with them.
    other = run_cli("batch", "--folder", library, "-o", out, "--workers", "2", "--format", "glb", "--seed", "3")
    assert "danced    6 song(s), 1 failed" in other.stdout


def test_a_rerun_with_nothing_to_do_is_decided_from_the_manifest_alone(library, tmp_path, monkeypatch):
    out = tmp_path / "dances"
    songs = [library / "b" / "vibe.ogg", library / "a" / "karissa.ogg"]
    assert dancesynth.batch(songs, out, workers=1).done == 2

    def must_not_run(*args, **kwargs):
        raise AssertionError("a batch with nothing to do loaded a character, the database or a worker")

    from dancesynth.batching import pool
    from dancesynth.export import formats
    from dancesynth.motion import catalog

    monkeypatch.setattr(pool, "run_local", must_not_run)
    monkeypatch.setattr(formats, "output_character", must_not_run)
    monkeypatch.setattr(catalog, "list_styles", must_not_run)
    again = dancesynth.batch(songs, out, workers=1)
    assert (again.done, again.failed, again.skipped) == (0, 0, 2) and len(records(out)) == 2


def test_an_interrupted_batch_leaves_nothing_partial_and_resumes(library, tmp_path):
    out = tmp_path / "dances"
    songs = sorted((library / "a").glob("*.ogg")) + sorted((library / "b").glob("*.ogg"))
    songs = [s for s in songs if s.name != "broken.ogg"]
    proc = subprocess.Popen([str(DANCESYNTH), "batch", *map(str, songs), "-o", str(out), "--workers", "1"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not ((out / MANIFEST_NAME).is_file() and records(out)):
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)     # a service manager stopping it, mid-way through the second song
    proc.communicate(timeout=60)
    assert proc.returncode == 143
    finished = [r["name"] for r in records(out)]
    assert 1 <= len(finished) < len(songs) and no_partial_files(out)
    assert sorted(p.name for p in out.glob("*.bvh")) == sorted(finished)
    kept = {n: (out / n).stat().st_mtime_ns for n in finished}
    resumed = run_cli("batch", *songs, "-o", out, "--workers", "1")
    assert resumed.returncode == 0, resumed.stderr
    assert f"{len(finished)} already done (skipped)" in resumed.stdout
    assert len(list(out.glob("*.bvh"))) == len(songs)
    assert all((out / n).stat().st_mtime_ns == t for n, t in kept.items())


def _children(pid: int) -> list[int]:
    try:
        text = Path(f"/proc/{pid}/task/{pid}/children").read_text()
    except OSError:
        return []
    return [int(c) for c in text.split()]


def _batch_workers(pid: int) -> list[int]:
    out = []
    for child in _children(pid):
        try:
            if b"spawn_main" in Path(f"/proc/{child}/cmdline").read_bytes():
                out.append(child)
        except OSError:
            pass
    return out


def test_a_worker_killed_mid_song_is_retried_once_then_reported(library, tmp_path):
    out = tmp_path / "dances"
    victim, other = library / "b" / "vibe.ogg", library / "a" / "same.ogg"
    proc = subprocess.Popen([str(DANCESYNTH), "batch", str(victim), str(other), "-o", str(out), "--workers", "1"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    killed: list[int] = []
    deadline = time.monotonic() + 120
    while len(killed) < 2 and time.monotonic() < deadline:   # the first worker, then the one that retries
        fresh = [w for w in _batch_workers(proc.pid) if w not in killed]
        if fresh:
            time.sleep(0.3)
            os.kill(fresh[0], signal.SIGKILL)
            killed.append(fresh[0])
        time.sleep(0.05)
    _, err = proc.communicate(timeout=120)
    assert len(killed) == 2
    assert proc.returncode == 1
    (failed,) = [r for r in records(out) if r["status"] == "failed"]
    assert failed["song"] == str(victim) and failed["attempts"] == 2
    assert "died (killed by signal 9), 2 times" in failed["error"] and victim.name in err
    assert [p.name for p in out.glob("*.bvh")] == ["same.bvh"]    # the next song still danced
    assert no_partial_files(out)


def test_bad_input_gets_a_clear_error(library, tmp_path):
    (tmp_path / "empty").mkdir()
    cases = [
        (["--folder", tmp_path / "empty", "-o", tmp_path / "o1"], "has no audio files"),
        (["--folder", tmp_path / "nowhere", "-o", tmp_path / "o2"], "does not exist"),
        ([library / "a" / "same.ogg", "-o", library / "a" / "same.ogg"], "is a file"),
        ([library / "a" / "same.ogg", "-o", library / "a" / "same.ogg" / "x"], "cannot create output folder"),
        (["--list", tmp_path / "missing.txt", "-o", tmp_path / "o3"], "does not exist"),
        (["-o", tmp_path / "o4"], "no songs to dance"),
        ([library / "a" / "same.ogg", "-o", tmp_path / "o5", "--character", "nobody"], "nobody"),
    ]
    for args, message in cases:
        proc = run_cli("batch", *args)
        assert proc.returncode == 2 and message in proc.stderr and "Traceback" not in proc.stderr, (args, proc.stderr)
    assert not (tmp_path / "o5").exists() or not list((tmp_path / "o5").iterdir())


def test_a_song_list_names_songs_relative_to_itself(library, tmp_path):
    listing = library / "songs.txt"
    listing.write_text("# my set\na/same.ogg\n\nb/same.ogg\n")
    result = dancesynth.batch(list_file=listing, out_dir=tmp_path / "o", workers=1, character="source")
    assert result.done == 2 and result.failed == 0
    names = sorted(p.name for p in (tmp_path / "o").glob("*.bvh"))
    assert len(names) == 2 and all(n.startswith("same-") for n in names)   # same name twice: told apart


def test_ray_missing_names_the_extra(tmp_path, library):
    code = ("import sys; sys.modules['ray'] = None\n"      # as on a machine without Ray installed
            "from dancesynth.cli import main\n"
            f"sys.exit(main(['batch', {str(library / 'a' / 'same.ogg')!r}, '-o', {str(tmp_path / 'o')!r}, '--ray']))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "pip install 'dancesynth[ray]'" in proc.stderr


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_ray_address_that_does_not_answer(library, tmp_path):
    ray = pytest.importorskip("ray")
    assert ray
    t = time.monotonic()
    proc = run_cli("batch", library / "a" / "same.ogg", "-o", tmp_path / "o", "--ray", f"127.0.0.1:{_free_port()}",
                   timeout=60)
    assert proc.returncode == 2 and "no Ray cluster answers" in proc.stderr
    assert time.monotonic() - t < 30


@pytest.fixture(scope="module")
def ray_cluster(tmp_path_factory):
    """A real local Ray head node, as a user starts one (`ray start --head`), stopped afterwards."""
    pytest.importorskip("ray")
    port = _free_port()
    temp = Path("/tmp") / f"dsray{port}"   # Ray's socket paths must stay short
    head = subprocess.Popen([str(Path(sys.executable).with_name("ray")), "start", "--head", "--block",
                             f"--port={port}", "--num-cpus=2", "--include-dashboard=false", "--disable-usage-stats",
                             f"--temp-dir={temp}"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    address = f"127.0.0.1:{port}"
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            break
        except OSError:
            time.sleep(0.5)
    yield address
    os.killpg(head.pid, signal.SIGKILL)   # the head and everything it started
    head.wait()
    shutil.rmtree(temp, ignore_errors=True)


def test_a_batch_on_a_local_ray_cluster_dances_as_the_pool_does(ray_cluster, library, tmp_path):
    songs = [library / "a" / "same.ogg", library / "b" / "same.ogg", library / "a" / "broken.ogg"]
    on_ray = dancesynth.batch(songs, tmp_path / "ray", ray=ray_cluster, format="bvh")
    on_pool = dancesynth.batch(songs, tmp_path / "pool", workers=2, format="bvh")
    assert (on_ray.done, on_ray.failed) == (2, 1) == (on_pool.done, on_pool.failed)
    for path in (tmp_path / "pool").glob("*.bvh"):
        assert (tmp_path / "ray" / path.name).read_bytes() == path.read_bytes()   # the same dances
    workers = {r["worker"] for r in records(tmp_path / "ray") if r["status"] == "done"}
    assert workers and not workers & {r["worker"] for r in records(tmp_path / "pool")}
    again = dancesynth.batch(songs, tmp_path / "ray", ray=ray_cluster)
    assert again.skipped == 2 and again.failed == 1


def test_dance_reuses_an_open_database(bundled_song):
    from dancesynth.motion import database

    assert database.open_database() is database.open_database()
    loads = []
    real = database._load_database
    database._load_database = lambda folder: loads.append(folder) or real(folder)
    try:
        music = dancesynth.analyze_music(path=BUNDLED_MUSIC / "sorohanro_-_solo-trumpet-06.ogg")
        a = dancesynth.dance(music)
        b = dancesynth.dance(music)
    finally:
        database._load_database = real
    assert loads == [] and np.array_equal(a.local_rot, b.local_rot)
    with pytest.raises(ValueError):   # shared by every caller: nobody can change it under the others
        database.open_database().styles["mj"].local_rot[0, 0, 0] = 1.0


def test_styles_listing_reads_only_what_it_shows(bundled_db):
    from dancesynth.motion.catalog import list_styles

    quick, full = list_styles(), list_styles(bundled_db)
    assert quick == full and len(quick) == len(bundled_db.styles)


def test_threads_are_set_on_purpose(tmp_path):
    code = ("import os, json\n"
            "from dancesynth.threads import limit_threads\n"
            "limit_threads()\n"
            "import numpy, torch\n"
            "from threadpoolctl import threadpool_info\n"
            "from dancesynth.threads import torch_threads\n"
            "torch_threads()\n"
            "print(json.dumps([max(i['num_threads'] for i in threadpool_info()), torch.get_num_threads()]))")
    for env, want in (({}, 1), ({"DANCESYNTH_THREADS": "2"}, 2)):
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                              env={**os.environ, **env, "OMP_NUM_THREADS": "7"})
        assert json.loads(proc.stdout) == [want, want], proc.stderr
    with pytest.raises(InputError):
        os.environ["DANCESYNTH_THREADS"] = "many"
        try:
            from dancesynth.threads import thread_count

            thread_count()
        finally:
            del os.environ["DANCESYNTH_THREADS"]

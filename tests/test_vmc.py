"""The live dance over the VMC protocol, as an avatar app receives it (a receiver written from the spec)."""

from __future__ import annotations

import json
import re
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import BUNDLED_MUSIC
from test_gltf_character import CLIENTS
from dancesynth.errors import InputError
from dancesynth.io.bvh import read_bvh
from dancesynth.kinematics import clip_fk
from dancesynth.live.vmc import VmcFrames, VmcSender, parse_address, unity_bone_name
from dancesynth.live.vmc_receiver import VmcReceiver, expected_positions, world_positions
from test_cli import assert_clean_failure, run


@pytest.fixture(scope="module")
def mannequin_dance(bundled_db):
    """A second and a half of captured dance on the default character, with its humanoid bones."""
    from dancesynth.retarget import on_character
    from dancesynth.retarget.character import load_character

    style = bundled_db.styles[sorted(bundled_db.styles)[0]]
    character = load_character("mannequin")
    src = style.clip(0)
    clip, _ = on_character(src.frames(0, int(1.5 * src.fps)), character)
    return clip, character


def _shown(tx, rx) -> list[tuple[int, object]]:
    """(frame shown, or -1 for a held pose; the frame as received) for every bundle sent, in order. A sender
    thread held up by a loaded machine skips frames rather than bursting them, so a frame may be missing."""
    assert len(rx.frames) == len(tx.log)      # over localhost UDP every bundle arrives
    shown = [s for s, *_ in tx.log]
    frames = [s for s in shown if s >= 0]
    assert frames == sorted(set(frames))      # in order, never twice
    return list(zip(shown, rx.frames))


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_receiver_rebuilds_every_frame_as_our_kinematics_says(mannequin_dance):
    clip, character = mannequin_dance
    frames = VmcFrames.of(clip, character.bones)
    truth, parent = expected_positions(clip, character.bones)
    assert {"Hips", "Spine", "Head", "LeftUpperArm", "RightLowerLeg"} <= set(frames.names)
    with VmcReceiver() as rx:
        with VmcSender("127.0.0.1", rx.port, clip.fps) as tx:
            half = clip.n_frames // 2          # two segments, both there before they are due: nothing held
            tx.push(VmcFrames(frames.names, frames.pos[:half], frames.rot[:half]))
            tx.push(VmcFrames(frames.names, frames.pos[half:], frames.rot[half:]))
        rx.wait_for(len(tx.log), 5.0)
    shown = _shown(tx, rx)
    assert tx.held == 0 and len(shown) + tx.skipped == clip.n_frames and shown[-1][0] == clip.n_frames - 1
    got = rx.frames
    assert np.all(np.diff([f.t for f in got]) > 0)                      # in order
    assert all(f.ok == 1 and f.root == ("root", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0) for f in got)
    err = max(np.abs(world_positions(f, frames.names, parent) - truth[k]).max() for k, f in shown)
    assert err < 1e-4, err


def test_a_late_segment_holds_the_pose_then_blends_back_onto_the_music(mannequin_dance):
    clip, character = mannequin_dance
    frames = VmcFrames.of(clip, character.bones)
    truth, parent = expected_positions(clip, character.bones)
    first = 20
    with VmcReceiver() as rx:
        with VmcSender("127.0.0.1", rx.port, clip.fps, margin_s=0.0) as tx:
            tx.push(VmcFrames(frames.names, frames.pos[:first], frames.rot[:first]))
            time.sleep(first / clip.fps + 0.7)   # the next segment comes 0.7 s late
            tx.push(VmcFrames(frames.names, frames.pos[first:], frames.rot[first:]))
        rx.wait_for(len(tx.log), 5.0)
    pairs = _shown(tx, rx)
    shown = [s for s, _ in pairs]
    hold = shown.index(-1)
    assert tx.held > 0 and shown[hold - 1] == first - 1                # held once the frames ran out
    resumed = next(s for s in shown[hold:] if s >= 0)
    assert resumed > first + 10                                        # back on the frame the music is at
    pos = np.array([world_positions(f, frames.names, parent) for _, f in pairs])
    # Each step between bundles, but across a skip of the sender's own (a loaded machine) or the resume.
    steps = [np.abs(b - a).max() for (s0, _), (s1, _), a, b in zip(pairs, pairs[1:], pos, pos[1:])
             if s0 < 0 or s1 < 0 or s1 == s0 + 1]
    jump = np.abs(truth[resumed] - truth[first - 1]).max()             # what cutting over would have shown
    natural = np.abs(np.diff(truth, axis=0)).max()
    assert jump > 2 * natural                                          # (a cut would be seen)
    assert max(steps) < max(0.5 * jump, 1.5 * natural)


def test_nobody_listening_costs_the_dance_nothing(mannequin_dance):
    clip, character = mannequin_dance
    frames = VmcFrames.of(clip, character.bones)
    with VmcSender("127.0.0.1", _free_udp_port(), clip.fps, margin_s=0.0) as tx:
        tx.push(VmcFrames(frames.names, frames.pos[:15], frames.rot[:15]))
    shown = [s for s, *_ in tx.log]
    assert shown == sorted(set(shown)) and shown[-1] == 14 and len(shown) + tx.skipped == 15


def test_unity_names_and_addresses():
    assert unity_bone_name("leftUpperArm") == "LeftUpperArm" and unity_bone_name("upperChest") == "UpperChest"
    assert [unity_bone_name(f"rightThumb{p}") for p in ("Metacarpal", "Proximal", "Distal")] == \
        ["RightThumbProximal", "RightThumbIntermediate", "RightThumbDistal"]
    assert parse_address("127.0.0.1:39540") == ("127.0.0.1", 39540)
    assert parse_address("localhost") == ("localhost", 39539)
    for bad in ("127.0.0.1:0", "127.0.0.1:99999", "127.0.0.1:port", "no-such-host.invalid:39539"):
        with pytest.raises(InputError, match="--vmc"):
            parse_address(bad)


def test_stream_to_a_vmc_app(tmp_path):
    song = tmp_path / "song.wav"
    subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-t", "6", "-i",
                    str(BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg"), "-ac", "1", str(song)], check=True)
    with VmcReceiver() as rx:
        proc = run("stream", song, "--fast", "-q", "--segment-seconds", "2", "--vmc", f"127.0.0.1:{rx.port}",
                   cwd=tmp_path, timeout=120)
        assert proc.returncode == 0, proc.stderr
        sent = int(re.search(r"(\d+) frames sent to", proc.stdout).group(1))
        rx.wait_for(sent, 5.0)
    assert not (tmp_path / "live.bvh").exists()                        # --vmc alone writes no file
    assert sent > 0 and len(rx.frames) == sent and {"Hips", "LeftHand", "Head"} <= set(rx.frames[-1].bones)
    # Both at once: the BVH and the app.
    with VmcReceiver() as rx:
        proc = run("stream", song, "--fast", "-q", "--vmc", f"127.0.0.1:{rx.port}", "-o", tmp_path / "d.bvh",
                   cwd=tmp_path, timeout=120)
    assert proc.returncode == 0 and (tmp_path / "d.bvh").exists() and len(rx.frames) > 0, proc.stderr
    # An app that is not listening costs the BVH nothing.
    proc = run("stream", song, "--fast", "-q", "--vmc", f"127.0.0.1:{_free_udp_port()}", "-o", tmp_path / "e.bvh",
               cwd=tmp_path, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert read_bvh(tmp_path / "e.bvh").n_frames == read_bvh(tmp_path / "d.bvh").n_frames
    assert_clean_failure(run("stream", song, "--fast", "--vmc", "127.0.0.1:70000", "-o", tmp_path / "x.bvh"),
                         tmp_path / "x.bvh", "--vmc")
    assert_clean_failure(run("stream", song, "--fast", "--vmc", "127.0.0.1:39539", "--character", "source",
                             "-o", tmp_path / "y.bvh"), tmp_path / "y.bvh", "--vmc")


@pytest.mark.skipif(shutil.which("node") is None or not (CLIENTS / "node_modules" / "@pixiv" / "three-vrm").is_dir()
                    or not Path("/usr/bin/chromium").exists(),
                    reason="needs node, chromium and the npm clients (bash scripts/setup.sh --test installs them)")
def test_three_vrm_fed_the_vmc_messages_poses_the_avatar_as_our_kinematics_and_our_vrma_do(tmp_path):
    """The VMC bundles, received and bridged to a page (``vrm_pose``), pose pixiv's three-vrm avatar in headless
    Chromium where our forward kinematics puts every bone, and look as the same dance played from our .vrma."""
    from PIL import Image

    from dancesynth.export.vrm import vrm_bytes, vrma_bytes
    from dancesynth.live.vmc_receiver import vrm_pose
    from dancesynth.retarget.mannequin import mannequin_character
    from gltf_models import MANNEQUIN_BONES
    from test_vrm import FRAMES, _lit_and_changed, mannequin_dance

    dance = mannequin_dance()
    avatar, animation, poses = tmp_path / "mannequin.vrm", tmp_path / "dance.vrma", tmp_path / "poses.json"
    avatar.write_bytes(vrm_bytes(mannequin_character()))
    animation.write_bytes(vrma_bytes(dance, MANNEQUIN_BONES))
    frames = VmcFrames.of(dance, MANNEQUIN_BONES)
    with VmcReceiver() as rx:
        with VmcSender("127.0.0.1", rx.port, dance.fps, margin_s=0.0) as tx:
            tx.push(frames)
        rx.wait_for(len(tx.log), 5.0)
    received = dict(_shown(tx, rx))
    assert tx.held == 0
    picked = [min((s for s in received if s >= 0), key=lambda s: abs(s - f)) for f in FRAMES]   # (a skip: the next)
    times = [f"{f / dance.fps:.9g}" for f in picked]
    poses.write_text(json.dumps({t: vrm_pose(received[f]) for t, f in zip(times, picked)}))
    reports = {}
    for name, source in (("vmc", poses), ("vrma", animation)):
        out = tmp_path / name
        out.mkdir()
        proc = subprocess.run(["node", str(CLIENTS / "vrm_check.mjs"), str(out), str(source), ",".join(times),
                               str(avatar), "/usr/bin/chromium"], capture_output=True, text=True, cwd=CLIENTS,
                              timeout=240)
        reports[name] = json.loads(proc.stdout)
        assert reports[name]["ok"] and reports[name]["errors"] == [], reports[name]["errors"]
    _, ours = clip_fk(dance)
    entry = reports["vmc"]["avatars"][0]
    for t, f in zip(times, picked):
        error = max(np.linalg.norm(np.array(entry["positions"][t][b]) - ours[f, j]) for b, j in MANNEQUIN_BONES.items())
        assert error < 0.003, (f, error)                                   # metres
    shots = {name: [tmp_path / name / f"0_{k}.png" for k in range(len(times))] for name in reports}
    lit, changed = _lit_and_changed(shots["vmc"], np.array(reports["vmc"]["background"]))
    assert min(lit) > 0.02 and min(changed) > 0.005                        # drawn, and moving
    for a, b in zip(shots["vmc"], shots["vrma"]):                          # as the .vrma shows it
        pa, pb = (np.asarray(Image.open(p).convert("RGB"), dtype=np.int16) for p in (a, b))
        assert (np.abs(pa - pb).max(axis=2) > 12).mean() < 0.002


def test_latency_sets_the_segment_length_and_bad_values_are_clear_errors(tmp_path):
    from dancesynth.cli_live import segment_length

    assert segment_length(None, None) == 5.0 and segment_length(2.0, None) == 2.0
    assert segment_length(None, 3.0) == pytest.approx(3.0)
    out = tmp_path / "live.bvh"
    song = BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg"
    assert_clean_failure(run("stream", song, "--latency", "0.5", "-o", out), out, "--latency 0.5", "at least 1 s")
    assert_clean_failure(run("stream", song, "--latency", "3", "--segment-seconds", "2", "-o", out), out, "not both")


def test_the_avatar_dances_a_whole_number_of_bars_behind_the_music(mannequin_dance):
    clip, character = mannequin_dance
    frames = VmcFrames.of(clip, character.bones)
    with VmcSender("127.0.0.1", _free_udp_port(), clip.fps, margin_s=2.0) as tx:
        tx.push(VmcFrames(frames.names, frames.pos[:5], frames.rot[:5]))
        heard_at = time.perf_counter() - 1.9          # the music began 1.9 s ago; bars of 1.6 s
        tx.align(heard_at, 1.6)                       # (well before the first frame is due, even on a busy machine)
    bars = (tx.log[0][1] - heard_at) / 1.6
    assert tx.delay_s == pytest.approx(tx.log[0][1] - heard_at) and abs(bars - round(bars)) < 1e-6
    assert round(bars) == 3                            # the first bar line after the clock's own start (about 3.9 s)


def test_a_full_socket_buffer_loses_bundles_never_the_dance(mannequin_dance):
    """Every third send finds the socket's buffer full (EAGAIN): that bundle is lost and counted, the clock goes on."""
    clip, character = mannequin_dance
    frames = VmcFrames.of(clip, character.bones)

    class FullEveryThird:
        def __init__(self, sock):
            self.sock, self.calls = sock, 0

        def sendto(self, data, address):
            self.calls += 1
            if self.calls % 3 == 0:
                raise BlockingIOError(11, "Resource temporarily unavailable")
            return self.sock.sendto(data, address)

        def close(self):
            self.sock.close()

    with VmcReceiver() as rx:
        with VmcSender("127.0.0.1", rx.port, clip.fps, margin_s=0.0) as tx:
            tx._sock = FullEveryThird(tx._sock)
            tx.push(VmcFrames(frames.names, frames.pos[:30], frames.rot[:30]))
        rx.wait_for(len(tx.log) - len(tx.log) // 3, 5.0)
    shown = [s for s, *_ in tx.log]
    assert shown == sorted(set(shown)) and shown[-1] == 29 and len(shown) + tx.skipped == 30   # every frame's turn
    lost = len(tx.log) // 3
    assert tx.stats()["lost"] == lost and len(rx.frames) == len(tx.log) - lost   # the refused never arrived


def test_vmc_listen_says_what_reaches_its_port(mannequin_dance, tmp_path):
    clip, character = mannequin_dance
    frames = VmcFrames.of(clip, character.bones)
    port = _free_udp_port()
    listener = subprocess.Popen([sys.executable, "-m", "dancesynth.cli", "vmc-listen", "--port", str(port),
                                 "--seconds", "4"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert "listening on 127.0.0.1" in listener.stdout.readline()
        with VmcSender("127.0.0.1", port, clip.fps, margin_s=0.0) as tx:
            tx.push(frames)
        stdout, stderr = listener.communicate(timeout=60)
    finally:
        listener.kill()
    assert listener.returncode == 0, stderr
    total = int(stdout.strip().splitlines()[-1].split()[0])
    assert total == len(tx.log) and f"{len(frames.names)} bones, e.g. Hips" in stdout, stdout
    # The port taken: a clear error.
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        busy = run("vmc-listen", "--port", taken.getsockname()[1], "--seconds", "1")
    assert busy.returncode == 2 and "cannot listen" in busy.stderr and "Traceback" not in busy.stderr

"""`dancesynth render` as a user meets it: an MP4 that ffprobe reads, with the song in it."""

from __future__ import annotations

import json
import subprocess

import pytest
import soundfile as sf

from conftest import BUNDLED_MUSIC
from test_cli import assert_clean_failure, cli, run

TRUMPET = BUNDLED_MUSIC / "sorohanro_-_solo-trumpet-06.ogg"


def test_render_writes_an_mp4_with_video_and_audio_of_the_songs_length(tmp_path):
    dance = tmp_path / "dance.bvh"
    assert run("dance", TRUMPET, "-o", dance, "-q").returncode == 0
    out = tmp_path / "dance.mp4"
    proc = run("render", dance, TRUMPET, "-o", out, "--width", "640", "--height", "360", timeout=180)
    assert proc.returncode == 0, proc.stderr
    assert "wrote" in proc.stdout
    probe = json.loads(subprocess.run(["ffprobe", "-v", "error", "-show_streams", "-of", "json", str(out)],
                                      capture_output=True, text=True, check=True).stdout)
    streams = {s["codec_type"]: s for s in probe["streams"]}
    duration = sf.info(TRUMPET).duration
    assert streams["video"]["codec_name"] == "h264" and streams["audio"]["codec_name"] == "aac"
    assert (streams["video"]["width"], streams["video"]["height"]) == (640, 360)
    for kind in ("video", "audio"):
        assert float(streams[kind]["duration"]) == pytest.approx(duration, abs=0.1)


def test_render_bad_input(tmp_path):
    dance = tmp_path / "dance.bvh"
    assert run("dance", TRUMPET, "-o", dance, "-q").returncode == 0
    assert_clean_failure(cli("render", dance, TRUMPET, "-o", tmp_path / "dance.avi"), tmp_path / "dance.avi", "mp4")
    not_bvh = tmp_path / "x.bvh"
    not_bvh.write_text("hello")
    assert_clean_failure(cli("render", not_bvh, TRUMPET, "-o", tmp_path / "x.mp4"), tmp_path / "x.mp4", "x.bvh")
    assert_clean_failure(cli("render", dance, TRUMPET, "-o", tmp_path / "big.mp4", "--width", "100000"),
                         tmp_path / "big.mp4", "width")


def frames_of(path, n_frames: int = 3):
    """``n_frames`` RGB frames spread over the video (ffmpeg decodes; numpy arrays)."""
    import numpy as np

    probe = subprocess.run(["ffprobe", "-v", "error", "-show_entries", "stream=width,height", "-select_streams", "v",
                            "-of", "csv=p=0", str(path)], capture_output=True, text=True, check=True).stdout
    w, h = map(int, probe.strip().split(","))
    raw = subprocess.run(["ffmpeg", "-v", "error", "-i", str(path), "-vf", "select=not(mod(n\\,40))", "-vsync", "0",
                          "-f", "rawvideo", "-pix_fmt", "rgb24", "-"], capture_output=True, check=True).stdout
    return np.frombuffer(raw, np.uint8).reshape(-1, h, w, 3)[:n_frames].astype(int)


def mannequin_pixels(img) -> int:
    """Pixels in the mannequin's navy trousers (dark, bluish: the stick figure's blue is bright)."""
    return int(((img.max(axis=-1) < 130) & (img[..., 2] - img[..., 0] > 25)).sum())


def test_dance_straight_to_mp4_shows_the_mannequin_dancing_with_the_song(tmp_path):
    out = tmp_path / "dance.mp4"
    proc = run("dance", TRUMPET, "-o", out, "-q", timeout=180)
    assert proc.returncode == 0, proc.stderr
    probe = json.loads(subprocess.run(["ffprobe", "-v", "error", "-show_streams", "-of", "json", str(out)],
                                      capture_output=True, text=True, check=True).stdout)
    assert {s["codec_type"] for s in probe["streams"]} == {"video", "audio"}
    frames = frames_of(out)
    assert all(mannequin_pixels(f) > 500 for f in frames)          # the skinned character, not sticks
    assert abs(frames[0] - frames[-1]).sum(axis=-1).astype(bool).sum() > 2000   # and it moves


def test_render_draws_the_mannequin_by_default_and_sticks_on_request(tmp_path):
    dance = tmp_path / "dance.bvh"
    assert run("dance", TRUMPET, "--character", "source", "-o", dance, "-q").returncode == 0
    videos = {}
    for figure in ("character", "stick"):
        out = tmp_path / f"{figure}.mp4"
        r = cli("render", dance, TRUMPET, "-o", out, "--figure", figure, "--width", "480", "--height", "270", "-q")
        assert r.returncode == 0, r.stderr
        videos[figure] = frames_of(out, 4)   # several poses: a dancer seen side-on shows little trouser
    assert mannequin_pixels(videos["character"]) > 5 * max(mannequin_pixels(videos["stick"]), 80)
    assert_clean_failure(cli("render", dance, TRUMPET, "-o", tmp_path / "x.mp4", "--character", "robot"),
                         tmp_path / "x.mp4", "unknown character")

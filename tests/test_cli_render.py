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

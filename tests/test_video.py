"""MP4 export: real ffmpeg/ffprobe on a dance made for the bundled 5-second trumpet song."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from conftest import BUNDLED_MUSIC

from dancesynth.errors import DanceSynthError, InputError
from dancesynth.export import render_video, render_video_files
from dancesynth.export import video as video_mod
from dancesynth.export.video import source_frames

TRUMPET = BUNDLED_MUSIC / "sorohanro_-_solo-trumpet-06.ogg"
LONG_SONG = BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg"
W, H = 640, 360

pytestmark = pytest.mark.skipif(shutil.which("ffmpeg") is None or shutil.which("ffprobe") is None,
                                reason="ffmpeg/ffprobe not installed")


def ffprobe(path: Path) -> dict:
    proc = subprocess.run(["ffprobe", "-v", "error", "-show_streams", "-show_format", "-of", "json", str(path)],
                          capture_output=True, text=True, check=True)
    return json.loads(proc.stdout)


def frame_at(path: Path, t: float, size=(W, H)) -> np.ndarray:
    """The decoded video frame shown at time ``t`` as an (H, W, 3) uint8 array."""
    proc = subprocess.run(["ffmpeg", "-v", "error", "-i", str(path), "-ss", f"{t:.3f}", "-frames:v", "1",
                           "-f", "rawvideo", "-pix_fmt", "rgb24", "pipe:1"], capture_output=True, check=True)
    return np.frombuffer(proc.stdout, np.uint8).reshape(size[1], size[0], 3)


def figure_mask(img: np.ndarray) -> np.ndarray:
    """Pixels of the dancer's limbs: strongly coloured, unlike the grey background, grid and shadow."""
    img = img.astype(int)
    return img.max(axis=-1) - img.min(axis=-1) > 60


def assert_nothing_written(out: Path):
    assert not out.exists()
    assert not list(out.parent.glob(f".{out.name}.*")), "a partial file was left behind"


@pytest.fixture(scope="module")
def dance_clip():
    import dancesynth

    return dancesynth.dance(TRUMPET)


@pytest.fixture(scope="module")
def dance_bvh(dance_clip, tmp_path_factory):
    import dancesynth

    path = tmp_path_factory.mktemp("bvh") / "trumpet.bvh"
    dancesynth.write_bvh(path, dance_clip)
    return path


@pytest.fixture(scope="module")
def rendered(dance_bvh, tmp_path_factory):
    out = tmp_path_factory.mktemp("video") / "trumpet.mp4"
    calls = []
    result = render_video_files(dance_bvh, TRUMPET, out, width=W, height=H,
                                progress=lambda done, total: calls.append((done, total)))
    return out, result, calls


def test_mp4_has_h264_video_and_aac_audio_of_the_songs_length(rendered, dance_clip):
    out, result, _ = rendered
    meta = ffprobe(out)
    video = [s for s in meta["streams"] if s["codec_type"] == "video"]
    audio = [s for s in meta["streams"] if s["codec_type"] == "audio"]
    assert len(video) == 1 and len(audio) == 1
    v, a = video[0], audio[0]
    assert v["codec_name"] == "h264" and v["pix_fmt"] == "yuv420p"
    # The renderer hands ffmpeg BT.601 limited-range Y'CbCr, and the stream says so (players need not guess).
    assert v.get("color_space") == "smpte170m" and v.get("color_range") == "tv"
    assert (v["width"], v["height"]) == (W, H)
    assert a["codec_name"] == "aac"
    assert int(v["nb_frames"]) == dance_clip.n_frames == result["frames"]
    assert v["r_frame_rate"] == "30/1"
    song_s = sf.info(str(TRUMPET)).duration
    assert float(v["duration"]) == pytest.approx(song_s, abs=0.1)
    assert float(a["duration"]) == pytest.approx(song_s, abs=0.1)
    # In sync: both streams start at t = 0.
    assert float(v.get("start_time", 0)) == pytest.approx(0.0, abs=0.02)
    assert float(a.get("start_time", 0)) == pytest.approx(0.0, abs=0.03)
    assert result["duration_s"] == pytest.approx(dance_clip.n_frames / 30.0)
    assert result["fps"] == 30.0 and result["audio"] is True and result["seconds"] > 0
    assert result["figure"] == "stick"  # no character given: the stick figure (tests/test_render_character.py)


def test_frames_show_the_dancer_moving(rendered):
    out, _, _ = rendered
    a, b = frame_at(out, 1.0), frame_at(out, 1.5)
    ma, mb = figure_mask(a), figure_mask(b)
    assert ma.sum() > 500 and mb.sum() > 500, "no dancer drawn"
    # The background is light and the dancer sits near the middle of the picture.
    assert np.median(a) > 200
    ys, xs = np.nonzero(ma)
    assert W * 0.2 < xs.mean() < W * 0.8 and H * 0.15 < ys.mean() < H * 0.85
    assert (ma != mb).sum() > 200, "two frames half a second apart look the same"


def test_progress_reports_every_frame_count_up_to_the_total(rendered, dance_clip):
    _, _, calls = rendered
    assert calls[0] == (0, dance_clip.n_frames) and calls[-1] == (dance_clip.n_frames, dance_clip.n_frames)
    done = [d for d, _ in calls]
    assert done == sorted(done)


def test_silent_video_at_another_frame_rate(dance_clip, tmp_path):
    out = tmp_path / "silent.mp4"
    result = render_video(dance_clip, None, out, width=320, height=180, fps=15)
    meta = ffprobe(out)
    assert [s["codec_type"] for s in meta["streams"]] == ["video"]
    v = meta["streams"][0]
    assert (v["width"], v["height"]) == (320, 180) and v["r_frame_rate"] == "15/1"
    expected = int(np.floor(dance_clip.duration_s * 15 + 1e-6)) + 1
    assert int(v["nb_frames"]) == expected == result["frames"]
    assert result["audio"] is False
    assert figure_mask(frame_at(out, 2.0, (320, 180))).sum() > 50
    assert oct(out.stat().st_mode & 0o777) != oct(0o600), "the output keeps mkstemp's private mode"


def test_nearest_frame_resampling():
    assert source_frames(5, 30.0, 30.0).tolist() == [0, 1, 2, 3, 4]
    assert source_frames(7, 30.0, 15.0).tolist() == [0, 2, 4, 6]
    assert source_frames(3, 30.0, 60.0).tolist() == [0, 0, 1, 2, 2]  # rint rounds half to even
    assert source_frames(1, 30.0, 24.0).tolist() == [0]


@pytest.mark.parametrize("name, kwargs, words", [
    ("dance.avi", {}, [".mp4"]),
    ("missing/dance.mp4", {}, ["does not exist"]),
    ("dance.mp4", {"width": 0}, ["width"]),
    ("dance.mp4", {"height": -540}, ["height"]),
    ("dance.mp4", {"width": 961}, ["even"]),
    ("dance.mp4", {"width": 7680, "height": 4320}, ["too large"]),
    ("dance.mp4", {"fps": 0}, ["frame rate"]),
])
def test_bad_arguments(dance_clip, tmp_path, name, kwargs, words):
    out = tmp_path / name
    with pytest.raises(InputError) as err:
        render_video(dance_clip, TRUMPET, out, **kwargs)
    for w in words:
        assert w in str(err.value)
    assert_nothing_written(out)


def test_bvh_that_does_not_parse(tmp_path):
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n")
    out = tmp_path / "dance.mp4"
    with pytest.raises(InputError, match="bad.bvh"):
        render_video_files(bad, TRUMPET, out)
    assert_nothing_written(out)


def test_audio_that_does_not_decode(dance_bvh, tmp_path):
    fake = tmp_path / "song.mp3"
    fake.write_text("this is not music\n" * 50)
    out = tmp_path / "dance.mp4"
    with pytest.raises(InputError, match="song.mp3"):
        render_video_files(dance_bvh, fake, out)
    assert_nothing_written(out)


def test_dance_and_song_of_different_lengths(dance_clip, tmp_path):
    out = tmp_path / "dance.mp4"
    with pytest.raises(InputError) as err:
        render_video(dance_clip, LONG_SONG, out)
    msg = str(err.value)
    assert "5.3 s" in msg and "61.5 s" in msg and "dancesynth dance" in msg
    assert_nothing_written(out)


def test_output_would_overwrite_the_song(dance_clip, tmp_path):
    song = tmp_path / "song.mp4"
    shutil.copy(TRUMPET, song)
    with pytest.raises(InputError, match="overwrite"):
        render_video(dance_clip, song, song)
    assert song.read_bytes() == TRUMPET.read_bytes()


def test_ffmpeg_missing(dance_clip, tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    out = tmp_path / "dance.mp4"
    with pytest.raises(InputError, match="ffmpeg"):
        render_video(dance_clip, TRUMPET, out)
    assert_nothing_written(out)


def test_ffmpeg_failure_leaves_no_file(dance_clip, tmp_path, monkeypatch):
    monkeypatch.setattr(video_mod, "X264_PRESET", "no-such-preset")
    out = tmp_path / "dance.mp4"
    with pytest.raises(DanceSynthError, match="cannot write .*dance.mp4: x264"):
        render_video(dance_clip, TRUMPET, out, width=160, height=90)
    assert_nothing_written(out)


def test_interrupt_leaves_the_old_file_and_no_partial(dance_clip, tmp_path):
    out = tmp_path / "dance.mp4"
    out.write_bytes(b"old video")

    def interrupt(done, total):
        if done >= 10:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        render_video(dance_clip, TRUMPET, out, width=160, height=90, progress=interrupt)
    assert out.read_bytes() == b"old video"
    assert not list(tmp_path.glob(".dance.mp4.*"))


_INTERRUPTED_RENDER = """
import signal
import sys
import time
from pathlib import Path
from dancesynth.export import render_video_files

# As in a terminal: a test run started as a shell's background job hands its children SIGINT ignored.
signal.signal(signal.SIGINT, signal.default_int_handler)

said = []

def progress(done, total):
    if done >= 20 and not said:
        said.append(done)
        print("rendering", flush=True)
    if said:
        time.sleep(0.05)  # keep rendering for seconds after saying so: a loaded test machine may take a while to signal

render_video_files(Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3]), progress=progress)
"""


def test_ctrl_c_in_a_real_process_leaves_no_partial_file(dance_bvh, tmp_path):
    """SIGINT goes to the whole process group, as Ctrl-C in a terminal does (ffmpeg has its own: Python handles it)."""
    import os
    import signal
    import sys

    out = tmp_path / "dance.mp4"
    proc = subprocess.Popen([sys.executable, "-c", _INTERRUPTED_RENDER, str(dance_bvh), str(TRUMPET), str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        assert proc.stdout.readline().strip() == "rendering", proc.stderr.read()
        assert list(tmp_path.glob(".dance.mp4.*.part")), "no temporary file while rendering"
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode != 0
    assert "KeyboardInterrupt" in err
    assert_nothing_written(out)


def test_the_camera_turns_with_the_dancer_so_she_mostly_faces_it():
    """Vibe Ace's salsa turns about: a camera fixed on her mean facing saw her face in about half the frames;
    turning slowly with her low-passed facing, it sees it in most, never whipping round."""
    from dancesynth.api import dance
    from dancesynth.export.camera import MAX_TURN_DEG_S, _facings, plan_shot
    from dancesynth.export.figure import build_figure, clip_pose, pose_points

    clip = dance(BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg", seed=0)
    fig = build_figure(clip.skeleton)
    frames = np.arange(clip.n_frames)
    facing = _facings(clip, frames, pose_points(*clip_pose(clip, frames), fig))[:, [0, 2]]
    shot = plan_shot(clip, fig, 16 / 9)
    to_camera = shot.direction[:, [0, 2]] / np.linalg.norm(shot.direction[:, [0, 2]], axis=1, keepdims=True)
    known = np.linalg.norm(facing, axis=1) > 0
    faces = (np.sum(facing * to_camera, axis=1) > 0)[known].mean()
    mean = facing[known].sum(axis=0)
    fixed = (facing[known] @ (mean / np.linalg.norm(mean)) > 0).mean()   # the old camera, before its 3/4 turn
    assert faces >= 0.75 and faces > fixed + 0.1, (faces, fixed)
    yaw = np.unwrap(np.arctan2(to_camera[:, 0], to_camera[:, 1]))
    assert np.degrees(np.abs(np.diff(yaw))).max() * clip.fps <= MAX_TURN_DEG_S + 1e-6

"""Decoding audio files: formats, rates, channels, and every bad file a user may give."""

from __future__ import annotations

import shutil
import subprocess
import sys

import numpy as np
import pytest
import soundfile as sf

import signals
from conftest import BUNDLED_MUSIC
from dancesynth.errors import InputError
from dancesynth.io.audio import audio_duration_s, load_audio, probe_audio

HAS_FFMPEG = shutil.which("ffmpeg") is not None and shutil.which("ffprobe") is not None
needs_ffmpeg = pytest.mark.skipif(not HAS_FFMPEG, reason="ffmpeg/ffprobe not installed")


def _one_line_error(exc_info, *needles):
    msg = str(exc_info.value)
    assert "\n" not in msg
    for needle in needles:
        assert needle.lower() in msg.lower(), msg
    return msg


@pytest.fixture(scope="module")
def tone():
    """6 s of a 440 Hz tone at half scale, at 44.1 kHz."""
    return signals.sine(440.0, 6.0, sr=44100, amplitude=0.5), 44100


# ----------------------------------------------------------------- good files

@pytest.mark.parametrize("ext,subtype,channels,rate", [
    ("wav", "PCM_U8", 1, 8000),
    ("wav", "PCM_16", 2, 44100),
    ("wav", "PCM_24", 1, 96000),
    ("wav", "FLOAT", 2, 48000),
    ("flac", "PCM_16", 2, 44100),
    ("ogg", "VORBIS", 2, 44100),
    ("mp3", "MPEG_LAYER_III", 2, 44100),
])
def test_formats_decode_to_mono_22050(tmp_path, ext, subtype, channels, rate):
    y = signals.sine(440.0, 6.0, sr=rate, amplitude=0.5)
    path = signals.write(tmp_path / f"tone.{ext}", y, rate, subtype=subtype, channels=channels)
    out, sr = load_audio(path)
    assert sr == 22050 and out.dtype == np.float32 and out.ndim == 1
    # mp3 adds encoder padding; everything else keeps the length exactly.
    assert abs(len(out) / sr - 6.0) < (0.06 if ext == "mp3" else 1e-3)
    # The same tone at the same level, whatever the container (mean of equal channels).
    rms = np.sqrt(np.mean(out[sr:-sr].astype(np.float64) ** 2))
    assert rms == pytest.approx(0.5 / np.sqrt(2), rel=0.03)


def test_stereo_kept_and_native_rate(tmp_path, tone):
    y, rate = tone
    left, right = y, 0.5 * y
    path = tmp_path / "stereo.wav"
    sf.write(path, np.stack([left, right], axis=1), rate, subtype="FLOAT")
    out, sr = load_audio(path, sr=None, mono=False)
    assert sr == rate and out.shape == (2, len(y))
    np.testing.assert_allclose(out[1], right, atol=1e-6)
    mono, _ = load_audio(path, sr=None)
    np.testing.assert_allclose(mono, 0.75 * y, atol=1e-6)


def test_duration_from_header(tmp_path, tone):
    y, rate = tone
    path = signals.write(tmp_path / "tone.flac", y, rate)
    assert audio_duration_s(path) == pytest.approx(6.0)
    assert probe_audio(path).backend == "soundfile"


@needs_ffmpeg
@pytest.mark.parametrize("ext,codec", [("m4a", "aac"), ("webm", "libopus")])
def test_ffmpeg_fallback(tmp_path, tone, ext, codec):
    y, rate = tone
    wav = signals.write(tmp_path / "tone.wav", y, rate, channels=2)
    path = tmp_path / f"tone.{ext}"
    subprocess.run(["ffmpeg", "-nostdin", "-v", "error", "-i", str(wav), "-c:a", codec, str(path)], check=True)
    info = probe_audio(path)
    assert info.backend == "ffmpeg" and info.channels == 2
    out, sr = load_audio(path)
    assert sr == 22050 and abs(len(out) / sr - 6.0) < 0.1
    rms = np.sqrt(np.mean(out[sr:-sr].astype(np.float64) ** 2))
    assert rms == pytest.approx(0.5 / np.sqrt(2), rel=0.05)


# ------------------------------------------------------------------ bad files

def test_missing_file(tmp_path):
    with pytest.raises(InputError) as exc:
        load_audio(tmp_path / "nope.mp3")
    _one_line_error(exc, "nope.mp3", "not found")


def test_folder(tmp_path):
    with pytest.raises(InputError) as exc:
        load_audio(tmp_path)
    _one_line_error(exc, str(tmp_path), "folder")


def test_empty_file(tmp_path):
    path = tmp_path / "empty.wav"
    path.write_bytes(b"")
    with pytest.raises(InputError) as exc:
        load_audio(path)
    _one_line_error(exc, "empty.wav", "empty")


def test_text_file_named_mp3(tmp_path):
    path = tmp_path / "notes.mp3"
    path.write_text("these are my notes, not a song\n" * 50)
    with pytest.raises(InputError) as exc:
        load_audio(path)
    _one_line_error(exc, "notes.mp3", "not an audio file")


def test_truncated_real_ogg(tmp_path, bundled_song):
    # 40 % of a 61 s song is 24 s: long enough to pass every other check.
    data = bundled_song.read_bytes()
    path = tmp_path / "cut.ogg"
    path.write_bytes(data[: int(len(data) * 0.4)])
    with pytest.raises(InputError) as exc:
        load_audio(path)
    _one_line_error(exc, "cut.ogg", "truncated or corrupt")


@pytest.mark.parametrize("ext,subtype", [("wav", "PCM_16"), ("flac", "PCM_16"), ("mp3", "MPEG_LAYER_III")])
def test_truncated_files(tmp_path, ext, subtype):
    y = signals.colored_noise(10.0, sr=22050, seed=1)
    full = signals.write(tmp_path / f"full.{ext}", y, 22050, subtype=subtype)
    data = full.read_bytes()
    path = tmp_path / f"cut.{ext}"
    path.write_bytes(data[: int(len(data) * 0.6)])
    with pytest.raises(InputError) as exc:
        load_audio(path)
    _one_line_error(exc, f"cut.{ext}", "truncated or corrupt")


@needs_ffmpeg
def test_truncated_m4a(tmp_path, tone):
    y, rate = tone
    wav = signals.write(tmp_path / "tone.wav", y, rate)
    full = tmp_path / "tone.m4a"
    subprocess.run(["ffmpeg", "-nostdin", "-v", "error", "-i", str(wav), "-c:a", "aac", str(full)], check=True)
    path = tmp_path / "cut.m4a"
    path.write_bytes(full.read_bytes()[: full.stat().st_size // 2])
    with pytest.raises(InputError) as exc:
        load_audio(path)
    _one_line_error(exc, "cut.m4a", "corrupt")


def test_an_hour_is_refused_before_decoding(tmp_path):
    path = tmp_path / "hour.wav"
    with sf.SoundFile(path, "w", samplerate=8000, channels=1, subtype="PCM_U8") as fh:
        block = np.zeros(8000 * 60, dtype=np.float32)
        for _ in range(60):
            fh.write(block)

    def never_decoded(*args, **kwargs):
        raise AssertionError("the hour was decoded before it was refused")

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("dancesynth.io.audio._decode_soundfile", never_decoded)
        mp.setattr("dancesynth.io.audio._decode_ffmpeg", never_decoded)
        with pytest.raises(InputError) as exc:
            load_audio(path)
    _one_line_error(exc, "hour.wav", "60.0 min", "--max-minutes")
    y, _ = load_audio(path, sr=None, max_duration_s=None)
    assert len(y) == 8000 * 3600


def test_too_short(tmp_path):
    path = signals.write(tmp_path / "blip.wav", signals.sine(440, 2.0), 22050)
    with pytest.raises(InputError) as exc:
        load_audio(path)
    _one_line_error(exc, "blip.wav", "too short", "at least 4 s")


def test_nan_samples(tmp_path):
    y = signals.sine(440, 5.0)
    y[1000] = np.nan
    path = signals.write(tmp_path / "nan.wav", y, 22050, subtype="FLOAT")
    with pytest.raises(InputError) as exc:
        load_audio(path)
    _one_line_error(exc, "nan.wav", "NaN")


def test_no_samples(tmp_path):
    path = tmp_path / "nothing.wav"
    sf.write(path, np.zeros(0, dtype=np.float32), 22050)
    with pytest.raises(InputError) as exc:
        load_audio(path)
    _one_line_error(exc, "nothing.wav", "no audio samples")


def test_ffmpeg_missing(tmp_path, monkeypatch):
    path = tmp_path / "song.m4a"
    path.write_bytes(b"\x00\x00\x00\x18ftypM4A " + bytes(2000))
    monkeypatch.setattr("dancesynth.io.audio.shutil.which", lambda name: None)
    with pytest.raises(InputError) as exc:
        load_audio(path)
    _one_line_error(exc, "song.m4a", "ffmpeg", "not installed")


def test_bad_sample_rate(tmp_path):
    path = signals.write(tmp_path / "tone.wav", signals.sine(440, 5.0), 22050)
    with pytest.raises(InputError):
        load_audio(path, sr=0)


def test_a_damaged_mp3_is_decoded_without_the_decoders_notes_on_stderr(tmp_path, capfd):
    """Issue 13: libsndfile's mpg123 printed "Note: Trying to resync..." straight onto the user's terminal."""
    mp3 = tmp_path / "song.mp3"
    subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-t", "8", "-i",
                    str(BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg"), str(mp3)], check=True)
    data = bytearray(mp3.read_bytes())
    rng = np.random.default_rng(1)
    for at in rng.integers(2000, len(data) - 50, 40):
        data[at:at + 50] = bytes(50)          # 40 holes in the frames
    mp3.write_bytes(bytes(data))
    capfd.readouterr()
    y, sr = load_audio(mp3)
    assert len(y) / sr == pytest.approx(8.0, abs=0.3) and np.all(np.isfinite(y))
    err = capfd.readouterr().err
    assert "resync" not in err.lower() and "mpg123" not in err, err


@pytest.mark.parametrize("container", ["wav", "aiff", "caf"])
@pytest.mark.parametrize("channels", [300, 1024, 4096, 65535])
def test_absurd_channel_counts_are_refused_before_decoding(tmp_path, container, channels):
    """Issue 31: a header claiming 65,535 channels made the down-mix's argument list too long for ffmpeg (exit
    70). Past 256 channels the header is refused, whichever reader would take it, in one line."""
    import struct

    from dancesynth.io.audio import MAX_CHANNELS, probe_audio

    plain = tmp_path / f"plain.{container}"
    codec = "pcm_s16le" if container == "wav" else "pcm_s16be"
    subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-f", "lavfi", "-i", "sine=frequency=440:duration=5",
                    "-ac", "1", "-ar", "8000", "-c:a", codec, str(plain)], check=True)
    buf = bytearray(plain.read_bytes())
    chunk, skip, code = {"wav": (b"fmt ", 10, "<H"), "aiff": (b"COMM", 8, ">H"), "caf": (b"desc", 36, ">I")}[container]
    at = buf.index(chunk) + skip
    struct.pack_into(code, buf, at, channels)
    bad = tmp_path / f"bad.{container}"
    bad.write_bytes(bytes(buf))
    with pytest.raises(InputError, match="channels"):
        probe_audio(bad)
    assert channels > MAX_CHANNELS
    proc = subprocess.run([sys.executable, "-m", "dancesynth.cli", "beats", str(bad)], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1

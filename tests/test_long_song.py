"""Long songs in bounded memory (issue 15): decoding and analysis a block at a time give the same
numbers as the whole song at once, and a long-ish song is held once, as float32 at the analysis
rate, not as float64 copies. (The 3/10/30-minute measurements: benchmarks/long_song.py.)"""

from __future__ import annotations

import shutil
import subprocess
import tracemalloc

import numpy as np
import pytest
import soundfile as sf

from conftest import BUNDLED_MUSIC
from dancesynth.io import audio
from dancesynth.io.audio import load_audio
from dancesynth.io.resampling import resample
from dancesynth.music import analyze_music, beat_intensity_db, onset_envelope, sounding_span
from dancesynth.music.intensity import cumulative_energy
from dancesynth.music.metre import frame_features
from dancesynth.music.onset import ANALYSIS_SR

SONG = BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg"     # 61 s, 44.1 kHz stereo
HAS_FFMPEG = shutil.which("ffmpeg") is not None and shutil.which("ffprobe") is not None


@pytest.fixture(scope="module")
def song_22k():
    return load_audio(SONG)[0]


def one_read(path) -> tuple[np.ndarray, int]:
    """The whole file read at once, as the decoder did before it streamed."""
    y, rate = sf.read(str(path), dtype="float32", always_2d=True)
    return y, rate


def test_decoding_in_small_blocks_gives_the_samples_of_one_read(monkeypatch):
    y, rate = one_read(SONG)
    mono = y @ np.full(y.shape[1], 1.0 / y.shape[1], np.float32)
    monkeypatch.setattr(audio, "_BLOCK_FRAMES", 4099)       # hundreds of blocks, none aligned with anything
    out, sr = load_audio(SONG)
    assert sr == 22050 and out.dtype == np.float32 and out.flags.c_contiguous
    assert np.array_equal(out, resample(mono, rate, 22050))
    native, _ = load_audio(SONG, sr=None)
    assert np.array_equal(native, mono) and not np.any(np.signbit(native) & (native == 0))
    stereo, _ = load_audio(SONG, sr=16000, mono=False)
    assert np.array_equal(stereo, resample(np.ascontiguousarray(y.T), rate, 16000))


@pytest.mark.skipif(not HAS_FFMPEG, reason="ffmpeg/ffprobe not installed")
def test_ffmpeg_decoding_is_read_from_the_pipe_in_blocks_with_the_same_samples(tmp_path, monkeypatch):
    mp3 = tmp_path / "song.mp3"
    subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-t", "12", "-i", str(SONG), str(mp3)], check=True)
    monkeypatch.setattr(audio, "_BLOCK_FRAMES", 3001)
    out, sr = load_audio(mp3)
    whole = subprocess.run(["ffmpeg", "-nostdin", "-loglevel", "error", "-i", str(mp3), "-af",
                            "pan=mono|c0=0.5*c0+0.5*c1", "-ar", "44100", "-f", "f32le", "-acodec", "pcm_f32le",
                            "pipe:1"], capture_output=True, check=True).stdout
    assert np.array_equal(out, resample(np.frombuffer(whole, dtype="<f4").copy(), 44100, sr))


def test_features_made_in_blocks_equal_those_of_the_whole_song(song_22k):
    y = song_22k
    n = len(y)
    # Running energy: the blocks carry the sum on in the same order as one cumulative sum.
    whole = np.concatenate(([0.0], np.cumsum(np.square(y, dtype=np.float64))))
    at = np.array([n, 0, 1, 441 * 1000 + 17, n - 1, 5, 5])
    assert np.array_equal(cumulative_energy(y, at, block=777), whole[at])
    beats = np.arange(0.3, n / ANALYSIS_SR, 0.46)
    edges = np.round(beats * ANALYSIS_SR).astype(np.int64)
    level = whole[edges[1:]] - whole[edges[:-1]]
    expected = np.maximum(20.0 * np.log10(np.sqrt(level / np.diff(edges))), -100.0)
    assert np.array_equal(beat_intensity_db(y, ANALYSIS_SR, beats), expected)
    assert sounding_span(y) == sounding_span(y.astype(np.float64))
    # The onset envelope keeps 1024 frames of spectrum, not the song's 3,000: the rest is transformed twice.
    assert np.array_equal(onset_envelope(y, kept_frames=1024), onset_envelope(y))
    # Metre cues: resampled to 12 kHz and framed as the samples stream, in blocks of any size; equal to
    # float32 rounding (the resampler's SIMD path rounds a block's edge differently on some CPUs).
    for a, b in zip(frame_features(y, block=5003), frame_features(y, block=n)):
        assert a.dtype == np.float32
        np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6 * np.abs(b).max())


def test_a_long_song_is_held_once_as_float32_at_the_analysis_rate(tmp_path):
    """Four minutes of stereo 44.1 kHz: analysis peaked at 300 MB (float64 copies of the song for the
    silence trim and the loudness, the decoded song twice at 44.1 kHz, whole-song spectrograms);
    now it holds the song once at 22050 Hz (21 MB) plus blocks and spectra of bounded size (~19 MB)."""
    y, rate = one_read(SONG)
    path = tmp_path / "long.wav"
    with sf.SoundFile(path, "w", samplerate=rate, channels=2, subtype="PCM_16") as fh:
        for _ in range(4):
            fh.write(y)
    analysed_bytes = 4 * len(y) * 4 * ANALYSIS_SR // rate
    tracemalloc.start()
    try:
        music = analyze_music(path=path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert music.duration_s == pytest.approx(4 * len(y) / rate, abs=1e-3) and music.n_beats > 400
    assert peak < analysed_bytes + 32 * 2 ** 20, f"analysis peaked at {peak / 2 ** 20:.0f} MB"


def test_retargeting_in_chunks_gives_the_frames_of_one_pass(bundled_db):
    from dancesynth.api import dance
    from dancesynth.retarget.character import load_character
    from dancesynth.retarget.solve import retarget

    clip = dance(SONG, database=bundled_db, style="mj", seed=1).frames(0, 300)
    character = load_character("mannequin")
    whole = retarget(clip, character, chunk_frames=10 ** 9)
    chunked = retarget(clip, character, chunk_frames=37)
    assert np.array_equal(whole.local_rot, chunked.local_rot) and np.array_equal(whole.root_pos, chunked.root_pos)


def test_beat_energy_in_chunks_equals_the_whole_clip_at_once(bundled_song, monkeypatch):
    """The dance's energy per beat (the metre summary of every dance) is computed a few thousand
    frames at a time, so a 30-minute dance never holds all its joint positions; same numbers."""
    import dancesynth
    from dancesynth.eval import motion_metrics
    from dancesynth.kinematics import clip_fk

    music = dancesynth.analyze_music(path=bundled_song)
    clip = dancesynth.dance(music)
    whole = motion_metrics.beat_interval_energy(clip, music.beat_times_s, global_pos=clip_fk(clip)[1])
    monkeypatch.setattr(motion_metrics, "ENERGY_CHUNK", 97)
    assert np.array_equal(motion_metrics.beat_interval_energy(clip, music.beat_times_s), whole)

"""Music analysis against analytic ground truth: click tracks, tones, noise, silence."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import signals
from conftest import BUNDLED_MUSIC
from dancesynth.errors import InputError
from dancesynth.music import (MIN_CONFIDENCE, analyze_music, beat_confidence, beat_intensity_db,
                              onset_envelope, sounding_span, steady_beat_grid, track_beats)

SR = signals.SR


def beat_hit_rate(estimated, truth, *, skip_s=2.0, window_s=0.05):
    """Fraction of true beats (away from the ends) with an estimate within ``window_s``."""
    estimated = np.asarray(estimated)
    end = truth[-1]
    inner = truth[(truth >= skip_s) & (truth <= end - skip_s)]
    if estimated.size == 0:
        return 0.0
    dist = np.min(np.abs(inner[:, None] - estimated[None, :]), axis=1)
    return float(np.mean(dist <= window_s))


# ------------------------------------------------------------------ beats

@pytest.mark.parametrize("bpm,offset_s", [(90, 0.37), (120, 0.25), (150, 0.61)])
def test_click_track_beats_and_tempo(bpm, offset_s):
    y, truth = signals.click_track(bpm, 14.0, offset_s=offset_s, accent_every=4)
    features = analyze_music(y=y, sr=SR)
    assert not features.default_tempo
    assert beat_hit_rate(features.beat_times_s, truth) >= 0.9
    assert features.tempo_bpm == pytest.approx(bpm, rel=0.02)
    assert features.beat_confidence > 2 * MIN_CONFIDENCE
    assert features.intensity_db.shape == (features.n_beats - 1,)


def test_tempo_between_frames_is_refined():
    # 128 bpm is 23.4 feature frames per beat: whole frames alone would say 130.4 bpm.
    y, truth = signals.click_track(128, 12.0, offset_s=0.2)
    features = analyze_music(y=y, sr=SR)
    assert features.tempo_bpm == pytest.approx(128, rel=0.005)


def test_no_beats_in_trailing_silence():
    y, truth = signals.click_track(120, 8.0, offset_s=0.5)
    y = np.concatenate([np.zeros(2 * SR, dtype=np.float32), y, np.zeros(4 * SR, dtype=np.float32)])
    features = analyze_music(y=y, sr=SR)
    assert not features.default_tempo
    assert features.beat_times_s[0] > 2.0 + 0.5 - 0.1
    assert features.beat_times_s[-1] < 2.0 + truth[-1] + 0.2
    assert beat_hit_rate(features.beat_times_s, truth + 2.0, skip_s=2.6) >= 0.9


def test_sounding_span():
    assert sounding_span(np.zeros(SR)) == (0, -1)
    y = np.zeros(3 * SR, dtype=np.float32)
    y[SR:2 * SR] = signals.sine(440, 1.0)
    first, last = sounding_span(y)
    assert abs(first - 50) <= 2 and abs(last - 100) <= 2


@pytest.mark.parametrize("ext,subtype,channels,rate", [
    ("wav", "PCM_U8", 1, 8000),
    ("wav", "PCM_16", 2, 22050),
    ("wav", "PCM_24", 1, 96000),
    ("wav", "FLOAT", 2, 44100),
    ("flac", "PCM_24", 2, 48000),
    ("ogg", "VORBIS", 2, 44100),
    ("mp3", "MPEG_LAYER_III", 1, 44100),
])
def test_same_beats_from_every_format(tmp_path, ext, subtype, channels, rate):
    y, truth = signals.click_track(120, 10.0, sr=rate, offset_s=0.3)
    path = signals.write(tmp_path / f"click.{ext}", y, rate, subtype=subtype, channels=channels)
    features = analyze_music(path=path)
    assert features.source == str(path)
    assert not features.default_tempo
    assert beat_hit_rate(features.beat_times_s, truth) >= 0.9
    assert features.tempo_bpm == pytest.approx(120, rel=0.02)


def test_samples_at_another_rate_and_stereo():
    y, truth = signals.click_track(120, 10.0, sr=44100)
    features = analyze_music(y=np.stack([y, y]), sr=44100)
    assert beat_hit_rate(features.beat_times_s, truth) >= 0.9
    assert features.duration_s == pytest.approx(10.0)


def test_track_beats_on_a_precomputed_envelope():
    y, truth = signals.click_track(120, 10.0)
    env = onset_envelope(y, SR)
    times, bpm, conf = track_beats(onset_env=env, sr=SR)
    times2, bpm2, conf2 = track_beats(y, SR)
    np.testing.assert_array_equal(times, times2)
    assert bpm == pytest.approx(120, rel=0.02) and conf == conf2 > MIN_CONFIDENCE
    with pytest.raises(InputError, match="unknown beat tracker"):
        track_beats(y, SR, tracker="nope")


# -------------------------------------------------------------- intensity

def test_intensity_steps_by_20_db():
    y, truth = signals.click_track(120, 12.0, offset_s=0.25)
    half = len(y) // 2
    y = y.copy()
    y[half:] *= 0.1
    db = beat_intensity_db(y, SR, truth)
    mid = truth[:-1] + 0.25
    loud, quiet = db[mid < 5.5], db[mid > 6.5]
    assert np.ptp(loud) < 0.5 and np.ptp(quiet) < 0.5
    assert loud.mean() - quiet.mean() == pytest.approx(20.0, abs=1.0)
    # Through the whole analysis too: tracked beats, same step.
    features = analyze_music(y=y, sr=SR)
    t = features.beat_times_s[:-1]
    step = np.median(features.intensity_db[t < 5.0]) - np.median(features.intensity_db[t > 7.0])
    assert step == pytest.approx(20.0, abs=1.0)


def test_full_scale_sine_is_minus_3_db():
    y = signals.sine(441.0, 5.0, amplitude=1.0)
    db = beat_intensity_db(y, SR, np.arange(0.0, 5.01, 0.5))
    np.testing.assert_allclose(db, -3.0103, atol=0.01)


def test_silence_gives_the_floor():
    db = beat_intensity_db(np.zeros(SR * 5, dtype=np.float32), SR, [0.0, 1.0, 2.5, 5.0])
    np.testing.assert_array_equal(db, [-100.0, -100.0, -100.0])
    assert beat_intensity_db(np.zeros(10), SR, [0.0]).shape == (0,)


# ------------------------------------------------------ no clear beat

@pytest.mark.parametrize("name,y", [
    ("white", signals.colored_noise(10.0, exponent=0.0, seed=3)),
    ("pink", signals.colored_noise(10.0, exponent=1.0, seed=4)),
    ("brown", signals.colored_noise(10.0, exponent=2.0, seed=5)),
    ("short white", signals.colored_noise(4.5, exponent=0.0, seed=6)),
    ("organ", signals.organ_chord(12.0)),
    ("long organ", signals.organ_chord(60.0)),
    ("organ with hiss", signals.organ_chord(12.0) + signals.colored_noise(12.0, rms_db=-70.0, seed=7)),
])
def test_no_clear_beat_falls_back_to_a_steady_grid(name, y):
    features = analyze_music(y=y, sr=SR, fallback_bpm=90.0)
    assert features.default_tempo, f"{name}: confidence {features.beat_confidence:.3f}"
    assert features.beat_confidence < MIN_CONFIDENCE
    assert features.tempo_bpm == 90.0
    duration = len(y) / SR
    np.testing.assert_allclose(np.diff(features.beat_times_s), 60.0 / 90.0)
    assert features.beat_times_s[0] == 0.0 and features.beat_times_s[-1] > duration - 60.0 / 90.0
    assert np.all(np.isfinite(features.intensity_db))


def test_steady_beat_grid():
    np.testing.assert_allclose(steady_beat_grid(2.0, 120.0), [0.0, 0.5, 1.0, 1.5, 2.0])
    with pytest.raises(InputError):
        steady_beat_grid(2.0, 0.0)


def test_confidence_of_degenerate_beats():
    env = np.ones(100)
    assert beat_confidence(env, []) == 0.0
    assert beat_confidence(env, [10]) == 0.0
    assert beat_confidence(np.zeros(100), [10, 30, 50, 70]) <= 0.0


# ---------------------------------------------------------------- bad input

@pytest.mark.parametrize("y", [np.zeros(SR * 10, dtype=np.float32),
                               signals.colored_noise(10.0, rms_db=-75.0)])
def test_silence_is_an_error(tmp_path, y):
    with pytest.raises(InputError, match="^the audio is silent: nothing to dance to"):
        analyze_music(y=y, sr=SR)
    path = signals.write(tmp_path / "quiet.flac", y, SR, subtype="PCM_24")
    with pytest.raises(InputError) as exc:
        analyze_music(path=path)
    assert "quiet.flac" in str(exc.value) and "\n" not in str(exc.value)


def test_too_short_and_too_long_samples():
    with pytest.raises(InputError, match="too short to find a beat.*at least 4 s"):
        analyze_music(y=signals.sine(440, 3.0), sr=SR)
    with pytest.raises(InputError, match="over the limit"):
        analyze_music(y=signals.sine(440, 12.0), sr=SR, max_duration_s=10.0)


def test_argument_errors():
    y = signals.sine(440, 5.0)
    with pytest.raises(InputError, match="exactly one"):
        analyze_music()
    with pytest.raises(InputError, match="exactly one"):
        analyze_music(path="x.wav", y=y, sr=SR)
    with pytest.raises(InputError, match="sample rate"):
        analyze_music(y=y)
    with pytest.raises(InputError, match="sr= describes"):
        analyze_music(path="x.wav", sr=SR)
    with pytest.raises(InputError, match="fallback tempo"):
        analyze_music(y=y, sr=SR, fallback_bpm=0.0)
    with pytest.raises(InputError, match="shape"):
        analyze_music(y=np.zeros((2, 2, SR * 5)), sr=SR)


def test_import_stays_light():
    code = "import sys, dancesynth.music, dancesynth.io.audio; assert 'librosa' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)


# --------------------------------------------------------------- real songs

BUNDLED = sorted(BUNDLED_MUSIC.glob("*.ogg"))


@pytest.mark.slow
@pytest.mark.parametrize("path", BUNDLED, ids=[p.stem[:24] for p in BUNDLED])
def test_bundled_songs_have_a_clear_beat(path):
    features = analyze_music(path=path)
    assert not features.default_tempo, f"confidence {features.beat_confidence:.3f}"
    assert features.beat_confidence >= 2 * MIN_CONFIDENCE
    assert 60.0 <= features.tempo_bpm <= 200.0
    assert features.n_beats >= 4
    assert np.all(np.isfinite(features.intensity_db)) and np.all(features.intensity_db > -100.0)

"""Music analysis against analytic ground truth: click tracks, drum loops, tones, noise, silence.

The default tracker ("dp", numpy only) is checked against the truth and against
librosa (onset envelope and tracker), which the tests import; the product must not.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import signals
from conftest import BUNDLED_MUSIC
from dancesynth.errors import InputError
from dancesynth.music import (FEATURE_FPS, MIN_CONFIDENCE, analyze_music, beat_confidence, beat_intensity_db,
                              dp_beat_track, estimate_tempo, mel_filterbank, onset_envelope, sounding_span,
                              steady_beat_grid, track_beats)

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


def beat_f_measure(reference, estimated, *, window_s=0.07):
    """F-measure of beat agreement: one-to-one matches within ``window_s`` (as mir_eval's, greedy)."""
    reference, estimated = np.asarray(reference), np.asarray(estimated)
    if reference.size == 0 or estimated.size == 0:
        return 0.0
    used = np.zeros(estimated.size, dtype=bool)
    hits = 0
    for r in reference:
        dist = np.where(used, np.inf, np.abs(estimated - r))
        j = int(np.argmin(dist))
        if dist[j] <= window_s:
            used[j] = True
            hits += 1
    precision, recall = hits / estimated.size, hits / reference.size
    return 0.0 if hits == 0 else 2 * precision * recall / (precision + recall)


TEST_SIGNALS = {
    "click": lambda bpm: signals.click_track(bpm, 30.0, offset_s=0.37, accent_every=4),
    "swing": lambda bpm: signals.swing_track(bpm, 30.0, offset_s=0.3),
    "drums": lambda bpm: signals.drum_loop(bpm, 30.0, offset_s=0.3),
}


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


def test_import_stays_light(tmp_path):
    code = "import sys, dancesynth.music, dancesynth.io.audio; assert 'librosa' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)
    # The default analysis of a file needs neither librosa (numba) nor scipy.signal.
    y, _ = signals.click_track(120, 6.0)
    path = signals.write(tmp_path / "click.ogg", y, SR, subtype="VORBIS")
    code = ("import sys; from dancesynth.music import analyze_music; "
            f"f = analyze_music(path={str(path)!r}); assert not f.default_tempo; "
            "heavy = [m for m in ('librosa', 'numba', 'scipy.signal') if m in sys.modules]; "
            "assert not heavy, heavy")
    subprocess.run([sys.executable, "-c", code], check=True)


# ------------------------------------------------- numpy tracker vs librosa

def test_mel_filterbank_and_onset_envelope_match_librosa():
    import librosa
    import librosa.onset

    np.testing.assert_allclose(mel_filterbank(SR, 2048), librosa.filters.mel(sr=SR, n_fft=2048), atol=1e-8)
    for y, truth in (signals.click_track(120, 10.0, offset_s=0.37, accent_every=4),
                     signals.drum_loop(100, 10.0, offset_s=0.11)):
        ours = onset_envelope(y, SR)
        theirs = librosa.onset.onset_strength(y=y, sr=SR, hop_length=441)
        assert ours.shape == theirs.shape
        np.testing.assert_allclose(ours, theirs, atol=1e-3 * theirs.max())
        # The onset peaks fall on the same frames, on the beats.
        peaks = [int(np.argmax(env[max(f - 5, 0):f + 6])) + max(f - 5, 0)
                 for env in (ours, theirs) for f in np.round(truth * FEATURE_FPS).astype(int)]
        half = len(peaks) // 2
        assert np.max(np.abs(np.subtract(peaks[:half], peaks[half:]))) <= 1
        assert np.max(np.abs(np.subtract(peaks[:half], truth * FEATURE_FPS))) <= 1.5


@pytest.mark.parametrize("kind,bpm", [("click", 60), ("click", 90), ("click", 120), ("click", 150),
                                      ("swing", 90), ("swing", 150), ("drums", 100), ("drums", 128)])
def test_default_tracker_finds_the_beats_like_librosa(kind, bpm):
    y, truth = TEST_SIGNALS[kind](bpm)
    ours = analyze_music(y=y, sr=SR)
    assert ours.meta["tracker"] == "varying" and not ours.default_tempo
    assert beat_hit_rate(ours.beat_times_s, truth) >= 0.9
    assert ours.tempo_bpm == pytest.approx(bpm, rel=0.02)
    theirs = analyze_music(y=y, sr=SR, tracker="librosa")
    assert beat_f_measure(theirs.beat_times_s, ours.beat_times_s) >= 0.95
    assert ours.beat_confidence == pytest.approx(theirs.beat_confidence, abs=0.05)


def test_fast_clicks_are_tracked_at_their_tempo_where_the_global_tracker_halves_it():
    # The log-normal tempo prior centred at 120 bpm prefers 90 to 180 (librosa's and
    # the global "dp" tracker take every other click); the default tracker sees the
    # onsets half-way between those beats and doubles its tempo.
    y, truth = signals.click_track(180, 30.0, offset_s=0.37, accent_every=4)
    halved = analyze_music(y=y, sr=SR, tracker="dp")
    assert halved.tempo_bpm == pytest.approx(90, rel=0.02)
    assert beat_hit_rate(truth, halved.beat_times_s, skip_s=0.0) >= 0.95  # every beat found is true
    features = analyze_music(y=y, sr=SR)
    assert features.tempo_bpm == pytest.approx(180, rel=0.02)
    assert beat_f_measure(truth, features.beat_times_s) >= 0.95


def test_dp_beat_track_reproduces_librosa_at_its_tempo(bundled_song):
    import librosa.beat
    import librosa.feature

    from dancesynth.io.audio import load_audio

    y, sr = load_audio(bundled_song, sr=SR)
    for env in (onset_envelope(y, sr), onset_envelope(signals.drum_loop(117, 20.0)[0], SR)):
        tempo, frames = librosa.beat.beat_track(onset_envelope=env, sr=SR, hop_length=441, trim=False)
        ours, bpm = dp_beat_track(env, FEATURE_FPS, bpm=float(np.atleast_1d(tempo)[0]))
        np.testing.assert_array_equal(ours, frames)
        # Our tempo estimate is librosa's, refined between lags (within one lag).
        theirs = float(librosa.feature.tempo(onset_envelope=env, sr=SR, hop_length=441)[0])
        lag = 60 * FEATURE_FPS / theirs
        assert abs(60 * FEATURE_FPS / estimate_tempo(env, FEATURE_FPS) - lag) <= 1.0


def test_dp_beat_track_on_a_motion_envelope_at_60_fps():
    fps, period = 60.0, 60.0 * 60.0 / 100.0  # 100 bpm: a beat every 36 frames
    t = np.arange(int(30 * fps))
    truth = np.arange(20.0, t.size, period)
    rng = np.random.default_rng(0)
    env = np.exp(-0.5 * ((t[:, None] - truth[None, :]) / 2.0) ** 2).sum(axis=1) + 0.05 * rng.random(t.size)
    frames, bpm = dp_beat_track(env, fps)
    assert frames.dtype == np.int64 and np.all(np.diff(frames) > 0)
    assert bpm == pytest.approx(100.0, rel=0.02)
    assert beat_hit_rate(frames / fps, truth / fps, skip_s=1.0, window_s=1.5 / fps) >= 0.95


def test_dp_beat_track_degenerate_input():
    for env in (np.zeros(500), np.zeros(0), np.ones(1)):
        frames, bpm = dp_beat_track(env, 50.0)
        assert frames.size == 0 and bpm == 0.0
    with pytest.raises(InputError):
        dp_beat_track(np.ones((2, 100)), 50.0)
    with pytest.raises(InputError):
        dp_beat_track(np.ones(100), 0.0)


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


@pytest.mark.slow
@pytest.mark.parametrize("path", BUNDLED, ids=[p.stem[:24] for p in BUNDLED])
def test_bundled_songs_default_tracker_agrees_with_librosa(path):
    # Same tempo (within 3%: ours is not rounded to whole frames) and mostly the same
    # beats on the songs with a steady tempo. Brahms' Hungarian Dance changes tempo
    # (librosa's one global tempo: 143.6 bpm; ours follows it, median 132.6 bpm).
    ours = analyze_music(path=path)
    theirs = analyze_music(path=path, tracker="librosa")
    if path.stem.startswith("Hungarian"):
        assert ours.beat_confidence > theirs.beat_confidence  # its beats sit better on the onsets
    else:
        assert ours.tempo_bpm == pytest.approx(theirs.tempo_bpm, rel=0.03)
        assert beat_f_measure(theirs.beat_times_s, ours.beat_times_s) >= 0.6
    assert not ours.default_tempo and not theirs.default_tempo


def test_a_melody_recording_cut_while_its_last_note_sounds(tmp_path):
    """Issue 13: ``conduct`` crashed with an IndexError on 2 of 3 real recordings: a note heard to the
    end of the file was measured past the signal's last sample."""
    import soundfile as sf

    from dancesynth.music.melody import audio_notes

    sr = 22050
    t = np.arange(int(6.2 * sr)) / sr  # ends halfway through a 0.4 s note
    freq = np.array([440, 494, 523, 587, 659, 698, 784, 880])[(t / 0.4).astype(int) % 8]
    y = 0.5 * np.sin(2 * np.pi * np.cumsum(freq) / sr)
    y[(t % 0.4) < 0.01] *= 0.2  # a small dip at each note's start, as a new note's attack
    sf.write(tmp_path / "scale.wav", y.astype(np.float32), sr)
    notes = audio_notes(tmp_path / "scale.wav")
    assert notes.n_notes >= 10 and np.all(np.isfinite(notes.intensity))
    assert set(np.unique(notes.pitch)) <= {69, 71, 72, 74, 76, 77, 79, 81}

"""Choosing a style and a metrical level by the time warp its beat pieces need (engines/beatgrid.py).

A beat piece -- a captured motion-beat interval played over one grid interval -- looks
natural played at 0.8-1.25x its captured speed. The style chooser counts, per style and
level (the beat, double time, half time, or levels that change with a mix's tempo), the
share of pieces expected in that range, and the summary says what was chosen, the
expected and the danced share, and warns when a style must be warped far.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from dancesynth.errors import InputError

from conftest import BUNDLED_MUSIC, REPO
from signals import SR, click_track, write

from dancesynth.api import analyse, dance
from dancesynth.engines.beatgrid import (NEAR_SHARE, RATE_RANGE, TARGET_SHARE, beat_grid, choose_style,
                                         fit_style, fit_summary, motion_intervals_s, style_fits)
from dancesynth.types import MusicFeatures

FISHIN = BUNDLED_MUSIC / "Karissa_Hobbs_-_Lets_Go_Fishin.ogg"   # 118.7 bpm (beats tracked at ~123)
VIBE_ACE = BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg"      # 130.3 bpm
TRUMPET = BUNDLED_MUSIC / "sorohanro_-_solo-trumpet-06.ogg"  # 122.6 bpm, 7 s
SUMMARY_KEYS = ("level", "sections", "rate_range", "in_range_expected", "in_range_actual", "warnings")


def run(*args, timeout=120):
    env = dict(os.environ)
    env.setdefault("NUMBA_CACHE_DIR", str(REPO / ".cache" / "numba"))
    return subprocess.run([sys.executable, "-m", "dancesynth.cli", *map(str, args)], capture_output=True,
                          text=True, env=env, timeout=timeout)


def in_range(rates) -> float:
    r = np.asarray(rates)
    return float(np.mean((r >= RATE_RANGE[0]) & (r <= RATE_RANGE[1])))


def steady(duration_s: float, bpm: float, *, offset_s: float = 0.4, bars: bool = True) -> MusicFeatures:
    """Beats every 60/bpm s, in 4/4 bars whose first downbeat is the second beat (a pickup)."""
    beats = np.arange(offset_s, duration_s, 60.0 / bpm)
    loud = -20 + 3 * np.sin(np.arange(len(beats) - 1) / 7.0)
    bib = (np.arange(len(beats)) - 1) % 4 if bars else None
    return MusicFeatures(duration_s, beats, loud, bpm, beats_per_bar=4 if bars else None, beat_in_bar=bib)


@pytest.fixture(scope="module")
def songs():
    return {p.name: analyse(p) for p in sorted(BUNDLED_MUSIC.glob("*.ogg"))}


@pytest.fixture(scope="module")
def whirl_on_fishin(songs, bundled_db):
    return dance(songs[FISHIN.name], database=bundled_db, style="whirl")


# --- the grid at every level -------------------------------------------------------------------


@pytest.mark.parametrize("bars", [True, False])
def test_half_time_grid_covers_the_song_with_every_second_beat(bars):
    music = steady(30.0, 150.0, bars=bars)
    grid = beat_grid(music, subdivide=0.5)
    assert grid.times_s[0] <= 0.0 < grid.times_s[1] and grid.times_s[-2] < 30.0 <= grid.times_s[-1]
    assert grid.intensity_db.shape == (grid.n_intervals,) and grid.subdivide == 0.5
    kept = grid.times_s[grid.is_music_beat]
    assert np.all(np.isin(kept, music.beat_times_s))
    np.testing.assert_allclose(np.diff(grid.times_s), 0.8)  # two beats of 0.4 s
    assert len(kept) == pytest.approx(len(music.beat_times_s) / 2, abs=1)
    if bars:  # the kept beats are the ones the downbeats fall on
        assert np.all(np.isin(music.beat_times_s[music.beat_in_bar == 0], kept))
    else:
        assert kept[0] == music.beat_times_s[0]


def test_beat_and_double_time_grids_are_as_before():
    music = steady(20.0, 60.0)
    one, two = beat_grid(music), beat_grid(music, subdivide=2)
    assert np.all(one.is_music_beat[1:-1]) and np.isin(music.beat_times_s, one.times_s).all()
    np.testing.assert_allclose(two.times_s[::2], one.times_s)
    np.testing.assert_allclose(two.times_s[1::2], one.times_s[:-1] + 0.5)
    np.testing.assert_array_equal(two.is_music_beat[::2], one.is_music_beat)
    assert not two.is_music_beat[1::2].any()


def test_sections_change_the_level_at_a_music_beat():
    music = steady(40.0, 120.0)
    grid = beat_grid(music, subdivide=((0, 2), (33, 1), (49, 0.5)))
    assert grid.times_s[0] <= 0.0 and grid.times_s[-1] >= 40.0
    assert np.all(np.diff(grid.times_s) > 0) and grid.intensity_db.shape == (grid.n_intervals,)
    d = np.diff(grid.times_s)
    b33, b49 = music.beat_times_s[33], music.beat_times_s[49]
    np.testing.assert_allclose(d[grid.times_s[:-1] < b33 - 1e-9], 0.25)
    np.testing.assert_allclose(d[(grid.times_s[:-1] >= b33 - 1e-9) & (grid.times_s[:-1] < b49 - 1e-9)], 0.5)
    np.testing.assert_allclose(d[grid.times_s[:-1] >= b49 - 1e-9], 1.0)
    assert np.all(np.isin(music.beat_times_s[:50], grid.times_s[grid.is_music_beat]))
    with pytest.raises(InputError):
        beat_grid(music, subdivide=0.4)
    with pytest.raises(InputError):
        beat_grid(music, subdivide=((3, 1),))


# --- the expected share ------------------------------------------------------------------------


def test_expected_share_counts_the_styles_own_beat_intervals(bundled_db):
    whirl = bundled_db.styles["whirl"]
    motion = motion_intervals_s(whirl)
    assert 0 < len(motion) < len(whirl.beat_frames)  # intervals across clips do not count
    # At the style's own median interval most pieces play near 1x; at 1.5x that interval almost none.
    at_own = style_fits(bundled_db, np.full(32, np.median(motion)), "whirl", levels=(1,))[0]
    assert at_own.share >= TARGET_SHARE and at_own.rate == pytest.approx(1.0)
    far = style_fits(bundled_db, np.full(32, np.median(motion) / 1.5), "whirl", levels=(1,))[0]
    assert far.share < 0.3 and far.rate == pytest.approx(1.5)


def test_whirl_on_a_119_bpm_song_fits_or_warns(whirl_on_fishin):
    s = whirl_on_fishin.provenance.summary
    assert s["style"] == "whirl" and s["level"] in ("beat", "double time", "half time")
    assert s["in_range_actual"] == pytest.approx(in_range(whirl_on_fishin.provenance.warp_rates))
    # 81 bpm against 119 bpm is a 2:3 relation: no level fits it, and the user is told.
    assert s["in_range_actual"] >= TARGET_SHARE or s["warnings"]
    assert s["in_range_expected"] < TARGET_SHARE
    assert len(s["warnings"]) == 1 and "whirl" in s["warnings"][0] and "--style" in s["warnings"][0]


def test_a_forced_style_is_danced_at_the_level_nearest_its_speed(songs, bundled_db):
    """Whirl (81 bpm) on 130 bpm music: half time (0.8x) instead of the beat (1.6x, up to 2.4x)."""
    music = songs[VIBE_ACE.name]
    fits = {f.subdivide: f for f in style_fits(bundled_db, np.diff(music.beat_times_s), "whirl")}
    clip = dance(music, database=bundled_db, style="whirl")
    s = clip.provenance.summary
    assert s["level"] == "half time" and s["subdivide"] == 0.5
    assert s["in_range_expected"] == pytest.approx(fits[0.5].share) and fits[0.5].share > 2 * fits[1].share
    rates = clip.provenance.warp_rates
    assert rates.max() < 1.5 and in_range(rates) > 0.4
    grid, beats = clip.provenance.grid_times_s, music.beat_times_s
    inside = grid[(grid >= beats[0]) & (grid <= beats[-1])]
    assert np.all(np.isin(inside, beats)) and len(inside) >= len(beats) // 2  # every second music beat


def test_default_choice_on_bundled_songs_keeps_pieces_in_range(songs, bundled_db):
    for name, music in songs.items():
        fits = style_fits(bundled_db, np.diff(music.beat_times_s), beat_in_bar=music.beat_in_bar)
        chosen, best = fit_style(bundled_db, music), max(f.share for f in fits)
        assert chosen.share >= best - NEAR_SHARE, name
        if best >= TARGET_SHARE:  # the database allows it
            assert chosen.share >= TARGET_SHARE, (name, chosen.style.name, chosen.level, chosen.share)
        assert (chosen.share >= TARGET_SHARE) == (not fit_summary(chosen, music)["warnings"])


@pytest.mark.parametrize("song, share", [(FISHIN.name, 0.85),
                                         ("Kevin_MacLeod_-_P_I_Tchaikovsky_Dance_of_the_Sugar_Plum_Fairy.ogg", TARGET_SHARE)])
def test_default_dance_plays_ninety_percent_of_pieces_in_range(songs, bundled_db, song, share):
    # Lets Go Fishin (123 bpm) sits in the gap jpop (126 bpm) left between the two salsa styles: 0.89
    # expected, and the summary warns; the other bundled songs keep 90 %.
    clip = dance(songs[song], database=bundled_db)
    assert clip.provenance.summary["in_range_expected"] >= share
    assert in_range(clip.provenance.warp_rates) >= share


def test_slow_click_track_is_danced_in_double_time(tmp_path, bundled_db):
    y, beats = click_track(60.0, 20.0)
    clip = dance(write(tmp_path / "slow.wav", y, SR), database=bundled_db)
    s = clip.provenance.summary
    assert s["tempo_bpm"] == pytest.approx(60.0, rel=0.02)
    assert s["level"] == "double time" and s["subdivide"] == 2 and not s["warnings"]
    grid = clip.provenance.grid_times_s
    assert np.all(np.min(np.abs(clip.provenance.music_beat_times_s[:, None] - grid[None, :]), axis=1) < 1e-9)
    assert style_fits(bundled_db, np.full(16, 1.0))[0].subdivide == 2
    assert choose_style(bundled_db, 60.0)[1] == 2  # the steady-tempo chooser the live runtime uses


def test_music_far_faster_than_every_style_is_danced_at_half_time(bundled_db):
    # (A click track this fast is heard at half its tempo by the beat tracker: given beats here.)
    clip = dance(steady(30.0, 250.0), database=bundled_db)
    s = clip.provenance.summary
    assert s["level"] == "half time" and s["in_range_expected"] >= 0.85   # 125 bpm halved: the 120-126 gap
    assert in_range(clip.provenance.warp_rates) > 0.6
    assert choose_style(bundled_db, 250.0)[1] in (1, 2)  # the live runtime cannot dance half time


def test_a_mix_changes_level_where_its_tempo_changes(tmp_path, bundled_db):
    """70 bpm then 130 bpm: double time, then the beat, on one style (and so one skeleton)."""
    y1, _ = click_track(70.0, 40.0)
    y2, _ = click_track(130.0, 40.0, offset_s=0.0)
    music = analyse(write(tmp_path / "mix.wav", np.concatenate([y1, y2]), SR))
    clip = dance(music, database=bundled_db)
    s = clip.provenance.summary
    assert [x["level"] for x in s["sections"]] == ["double time", "beat"] and s["level"] == "double time, then beat"
    assert s["sections"][1]["start_s"] == pytest.approx(40.0, abs=3.0)
    single = max(f.share for f in style_fits(bundled_db, np.diff(music.beat_times_s), sections=False))
    assert s["in_range_expected"] >= TARGET_SHARE > single
    rates = clip.provenance.warp_rates
    assert in_range(rates) > 0.75 and rates.max() < 2.0
    again = beat_grid(music, subdivide=s["subdivide"])  # the summary's subdivide rebuilds the grid (bench replays)
    np.testing.assert_allclose(again.times_s, clip.provenance.grid_times_s)


# --- the summary and the command line ----------------------------------------------------------


@pytest.mark.parametrize("engine", ["streaming", "global", "choreography"])
def test_summary_says_style_level_and_warp(engine, bundled_db):
    clip = dance(steady(20.0, 112.5), database=bundled_db, engine=engine)
    s = clip.provenance.summary
    for key in SUMMARY_KEYS:
        assert key in s, key
    assert s["level"] == "beat" and s["rate_range"] == list(RATE_RANGE)
    assert 0.0 <= s["in_range_expected"] <= 1.0
    assert s["in_range_actual"] == pytest.approx(in_range(clip.provenance.warp_rates))
    assert s["sections"] == [{"start_s": 0.0, "level": "beat", "subdivide": 1}]
    json.dumps({k: s[k] for k in SUMMARY_KEYS + ("subdivide", "typical_rate")})


def test_cli_warns_when_a_forced_style_is_warped_far(tmp_path):
    out = tmp_path / "whirl.bvh"
    proc = run("dance", TRUMPET, "-o", out, "--style", "whirl")
    assert proc.returncode == 0, proc.stderr
    warnings = [ln for ln in proc.stderr.splitlines() if ln.startswith("warning: ")]
    assert len(warnings) == 1 and "whirl" in warnings[0] and "Traceback" not in proc.stderr
    assert "style     whirl, at half time" in proc.stdout and "expected" in proc.stdout and out.exists()
    quiet = run("dance", TRUMPET, "-o", tmp_path / "q.bvh", "--style", "whirl", "-q")
    assert quiet.returncode == 0 and quiet.stdout == "" and quiet.stderr.startswith("warning: ")


def test_cli_does_not_warn_when_the_style_fits(tmp_path):
    proc = run("dance", BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg", "-o", tmp_path / "d.bvh")
    assert proc.returncode == 0, proc.stderr
    assert "warning" not in proc.stderr and "on the beat" in proc.stdout

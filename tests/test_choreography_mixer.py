"""The choreography mixer and engine on a bundled song and the bundled database."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dancesynth.api import DanceConfig, analyse, dance
from dancesynth.engines.choreography.engine import choreography_dance, style_bank
from dancesynth.provenance import make_provenance
from dancesynth.engines.choreography.mixer import MixerConfig, substitute_motifs
from dancesynth.errors import InputError
from dancesynth.eval import motion_metrics as mm
from dancesynth.bench.quality import at_fps
from dancesynth.bench.dances import found_motifs
from dancesynth.eval.evaluate import evaluate, mocap_reference
from dancesynth.io.bvh import read_bvh, write_bvh
from dancesynth.motion.database import MotionDatabase
from dancesynth.motion.motifs import chi2, load_motif_model
from dancesynth.motion.words import clip_words

STYLE = "salsa-133-150bpm"   # the style the bundled song (130 bpm) is danced in


def choreograph(music, db, config, model, **engine_options):
    """The choreography engine itself (``dance`` gives it no mixer options), with the record ``dance`` makes."""
    reference = read_bvh(config.recreate) if config.recreate is not None else None
    clip, run = choreography_dance(music, db, config, timings={}, motif_model=model, reference=reference,
                                   **engine_options)
    clip.provenance = make_provenance("choreography", "song", config, run, fps=config.fps, frames=clip.n_frames,
                                      timings={}, music=music)
    return clip


@pytest.fixture(scope="module")
def music(bundled_song):
    return analyse(bundled_song)


@pytest.fixture(scope="module")
def model():
    return load_motif_model()


@pytest.fixture(scope="module")
def danced(music, bundled_db, model):
    return choreograph(music, bundled_db, DanceConfig(engine="choreography", seed=3), model)


@pytest.fixture(scope="module")
def mocap(bundled_db):
    st = bundled_db.styles[STYLE]
    return [at_fps(st.clip(i), 30.0) for i in range(st.n_clips)]


def test_the_dance_follows_the_genre_signature(danced, model, bundled_db):
    s = danced.provenance.summary
    assert danced.provenance.style == STYLE and s["engine"] == "choreography"
    ids, plan = danced.provenance.motifs["motif_ids"], danced.provenance.motifs["motif_plan"]
    assert len(ids) == len(danced.provenance.grid_times_s) - 1
    # Where every word of the planned motif needs a stitch, a word the mocap dances right after the
    # previous beat's candidates may dance another motif instead (``off_plan_depth``), mostly without
    # a stitch (measured: 0.61-0.67 of beats as planned, seeds 0-3; 4 of 44 off-plan beats stitched).
    meant = substitute_motifs(style_bank(bundled_db.styles[STYLE], model), model.centroids)[plan]  # motifs it has
    off = np.flatnonzero(ids != meant)
    grid, cuts = danced.provenance.grid_times_s, danced.provenance.transition_times_s
    stitched = np.isin(np.round(grid[off], 6), np.round(cuts, 6))
    assert off.size and stitched.mean() < 0.25, (off.size, stitched.sum())
    assert s["plan_followed"] == pytest.approx(np.mean(ids == plan)) and s["plan_followed"] > 0.55
    # Measured 0.08-0.10 (0.007 with every beat as planned); the paper's full method 0.27, raw salsa clips 0.38.
    assert chi2(model.templates["salsa"], model.signature(ids)) < 0.15
    # The motion itself, cut at its beats, mostly dances the motifs it meant to (measured 0.84).
    found = found_motifs(danced, model, danced.provenance.grid_times_s)
    assert np.mean(found == ids[:len(found)]) > 0.7


def test_continuing_the_mocap_off_the_plan_stitches_less_and_moves_like_the_mocap(danced, music, bundled_db,
                                                                                 model, mocap):
    strict = choreograph(music, bundled_db, DanceConfig(engine="choreography", seed=3), model,
                         mixer=MixerConfig(off_plan_depth=0))
    np.testing.assert_array_equal(strict.provenance.motifs["motif_ids"], strict.provenance.motifs["motif_plan"])
    assert len(danced.provenance.transition_times_s) < 0.75 * len(strict.provenance.transition_times_s)  # 61 vs 94
    ref = mocap_reference(mocap, danced.fps)
    speed = [evaluate(d, mocap=ref)["joint_speed_p99_vs_mocap"] for d in (danced, strict)]
    assert abs(np.log(speed[0])) < abs(np.log(speed[1])), speed  # measured 1.13 vs 1.42


def test_words_are_real_words_with_their_beats_on_music_beats(danced, bundled_db):
    from dancesynth.motion.accents import cached_accent_beats

    st = bundled_db.styles[STYLE]
    words = danced.provenance.motifs["word_frames"]  # each word's beats as shown: at their visible stops
    assert np.isin(words, cached_accent_beats(st).frame).all()
    grid = danced.provenance.grid_times_s
    # The first output frame at or after each grid beat shows the word's first beat frame, or the
    # source frames just after it (at most what one output frame moves through the source).
    inside = (grid[:-1] >= 0) & (grid[:-1] * danced.fps < danced.n_frames - 1)
    at = np.ceil(grid[:-1][inside] * danced.fps - 1e-9).astype(int)
    step = st.fps / danced.fps * np.max(danced.provenance.warp_rates)
    ahead = danced.provenance.source_frames[at] - words[inside, 0]
    assert np.all((ahead >= -1e-6) & (ahead <= step + 1e-6))


def test_motion_beats_hit_music_beats_and_stitches_are_smooth(danced, music, mocap):
    jumps = danced.provenance.transition_times_s
    assert len(jumps) > 20   # words are re-placed often: smoothness is really tested
    scores = evaluate(danced, music_beats_s=music.beat_times_s, transitions_s=jumps,
                      warp_rates=danced.provenance.warp_rates, mocap=mocap_reference(mocap, danced.fps))
    assert scores["hit_rate"] > 0.45                          # measured 0.51 (streaming engine: 0.35)
    assert scores["jump_p99_vs_mocap"] < 1.0                  # measured 0.64
    assert scores["transition_frac_over_mocap_p99"] <= 0.02  # measured 0.0
    assert scores["transition_jump_vs_mocap_p99"] < 1.2       # measured 0.90


def test_planted_feet_are_held(danced, music, bundled_db, model, mocap):
    loose = choreograph(music, bundled_db, DanceConfig(engine="choreography", seed=3), model,
                        mixer=MixerConfig(foot_lock=False))
    held, free = mm.foot_skate(danced), mm.foot_skate(loose)
    # Measured on seeds 0-3: 0.47-0.56 held vs 0.50-0.60 free (a 5 % cut: most beats are stitches, and a
    # foot a stitch moves is released for 0.15 s); the mocap's own skating at 30 fps is 0.45 m/s.
    assert held < 0.97 * free, (held, free)
    assert held < 1.25 * np.mean([mm.foot_skate(c) for c in mocap])


def test_seeded_dances_repeat_and_differ(danced, music, bundled_db, model):
    again = choreograph(music, bundled_db, DanceConfig(engine="choreography", seed=3), model)
    other = choreograph(music, bundled_db, DanceConfig(engine="choreography", seed=4), model)
    np.testing.assert_array_equal(again.local_rot, danced.local_rot)
    assert np.mean(other.provenance.motifs["motif_ids"] != danced.provenance.motifs["motif_ids"]) > 0.5


def test_motifs_at_requested_times(music, bundled_db, model):
    present = np.unique(style_bank(bundled_db.styles[STYLE], model).motif)
    a, b = int(present[3]), int(present[-2])
    clip = dance(music, database=bundled_db, motif_at=(f"12.0=M{a}", f"30.5=M{b}"), seed=0)
    assert clip.provenance.summary["engine"] == "choreography"   # implied by the constraints
    grid = clip.provenance.grid_times_s
    for t, m in ((12.0, a), (30.5, b)):
        beat = np.searchsorted(grid, t, side="right") - 1
        assert grid[beat] <= t < grid[beat + 1]
        assert clip.provenance.motifs["motif_ids"][beat] == m


def test_a_motif_the_style_lacks_is_refused(music, bundled_db, model):
    present = set(np.unique(style_bank(bundled_db.styles["mj"], model).motif).tolist())
    missing = next(m for m in range(model.k) if m not in present)
    with pytest.raises(InputError, match=f"style 'mj' has no word of motif M{missing}"):
        choreograph(music, bundled_db, DanceConfig(style="mj", motif_at=(f"10=M{missing}",)), model)


@pytest.mark.parametrize("kw, needle", [({"motif_at": ("10=M999",)}, r"M0 \.\. M47"),
                                        ({"motif_at": ("100=M1",)}, "outside the song"),
                                        ({"motif_at": ("10=M1",), "engine": "streaming"}, "need the choreography")])
def test_bad_constraints(music, bundled_db, kw, needle):
    with pytest.raises(InputError, match=needle):
        dance(music, database=bundled_db, **kw)


def test_recreate_a_held_out_dance(music, bundled_db, model, tmp_path):
    st = bundled_db.styles[STYLE]
    held_out = MotionDatabase({st.name: st.without_clip(0)}, bundled_db.source)
    ref = tmp_path / "reference.bvh"
    write_bvh(ref, st.clip(0))
    clip = choreograph(music, held_out, DanceConfig(recreate=ref), model)
    # The reference's motifs: its words at its kinematic beats, as 'dancesynth motifs' shows them.
    wanted = np.resize(model.assign(clip_words(read_bvh(ref)).features), len(clip.provenance.motifs["motif_ids"]))
    # Danced: the word of every beat is one of the reference's motif there (≥ 80 % required).
    assert np.mean(clip.provenance.motifs["motif_ids"] == wanted) >= 0.8
    # Found again in the stitched motion (blends and foot IK move word starts): measured 0.87.
    found = found_motifs(clip, model, clip.provenance.grid_times_s)
    assert np.mean(found == wanted[:len(found)]) > 0.75
    assert clip.provenance.summary["recreate"] == str(ref)


def test_reference_on_another_skeleton_is_refused(music, bundled_db, model, tmp_path):
    ref = tmp_path / "mj.bvh"
    write_bvh(ref, bundled_db.styles["mj"].clip(0))
    with pytest.raises(InputError, match="skeleton of 31 joints .* no style uses"):
        choreograph(music, bundled_db, DanceConfig(style="salsa", recreate=ref), model)
    clip = bundled_db.styles[STYLE].clip(0)
    renamed = replace(clip.skeleton, names=tuple(f"bone{i}" for i in range(clip.skeleton.n_joints)))
    write_bvh(ref, replace(clip, skeleton=renamed))
    with pytest.raises(InputError):
        choreograph(music, bundled_db, DanceConfig(recreate=ref), model)


def test_reference_too_short_for_a_word_is_refused(music, bundled_db, model, tmp_path):
    ref = tmp_path / "short.bvh"
    write_bvh(ref, bundled_db.styles[STYLE].clip(0).frames(0, 12))
    with pytest.raises(InputError, match="no motion word|fewer than two motion beats"):
        choreograph(music, bundled_db, DanceConfig(recreate=ref), model)



def test_the_words_move_at_their_styles_pace(bundled_db, model):
    """Issue 31 item 5: a calm word stitches cheaply (small pose and velocity differences), so the mixer
    chose pop's calmest words: a 180 bpm song danced in pop-82-103bpm moved at 0.6x its mocap's p99 joint
    speed. The words' pace against their style's (``speed_weight``) brings it within the ±25 % guard."""
    from test_engine import music as synthetic

    song = synthetic(60.0, 180.0, seed=2)
    style = bundled_db.styles["pop-82-103bpm"]
    ref = mocap_reference([at_fps(style.clip(i), 30.0) for i in range(style.n_clips)], 30.0)
    config = DanceConfig(engine="choreography", style=style.name, seed=0)
    speed = {w: evaluate(choreograph(song, bundled_db, config, model, mixer=MixerConfig(speed_weight=w)),
                         mocap=ref)["joint_speed_p99_vs_mocap"] for w in (0.0, MixerConfig().speed_weight)}
    assert speed[0.0] < 0.75 and 0.75 <= speed[MixerConfig().speed_weight] <= 1.25, speed

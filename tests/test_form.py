"""The song's form in the dance: a returning section is danced as it was, by every engine."""

from __future__ import annotations

import shutil
from dataclasses import replace

import numpy as np
import pytest
from dancesynth.engines.form import bar_pairs, form_plan
from dancesynth.eval.form import body_shapes, correlation, form_score, shuffled_score
from dancesynth.types import MusicFeatures, Phrase, Section, SongStructure

needs_fluidsynth = pytest.mark.skipif(shutil.which("fluidsynth") is None, reason="fluidsynth not installed")


def _music(form: str, bars: int = 8, bpb: int = 4, beat_s: float = 0.5, pickup: int = 0,
           similarity: np.ndarray | None = None) -> MusicFeatures:
    """Analysed music of sections ``form`` ("ABA": A, B, then A again), ``bars`` bars each."""
    n_bars = bars * len(form)
    beats = beat_s * np.arange(pickup + n_bars * bpb + 1)
    in_bar = (np.arange(len(beats)) - pickup) % bpb
    bar_s = beats[pickup::bpb][:n_bars]
    sections = tuple(Section(0.0 if k == 0 else float(bar_s[k * bars]),
                             float(bar_s[(k + 1) * bars]) if (k + 1) * bars < n_bars else float(beats[-1]),
                             lab, "verse", k * bars, bars) for k, lab in enumerate(form))
    phrases = tuple(Phrase(float(bar_s[a]), a, 4, 4) for a in range(0, n_bars, 4))
    st = SongStructure(sections, phrases, tuple(bar_s), similarity)
    return MusicFeatures(duration_s=float(beats[-1]), beat_times_s=beats, intensity_db=np.full(len(beats) - 1, -20.0),
                         tempo_bpm=60.0 / beat_s, beat_in_bar=in_bar, beats_per_bar=bpb, structure=st)


def test_a_returning_section_pairs_each_beat_with_the_same_place_in_its_first_occurrence():
    music = _music("ABA", pickup=3)
    grid = np.r_[-0.5, music.beat_times_s]          # a grid beat before the song, as beat_grid makes
    plan = form_plan(music, grid, "same")
    first_a = 1 + 3                                  # grid beat of bar 0's downbeat (after the pickup)
    second_a = first_a + 2 * 8 * 4
    assert plan.source[second_a] == first_a
    assert np.array_equal(plan.source[second_a:second_a + 32], np.arange(first_a, first_a + 32))
    assert (plan.source[:second_a] == -1).all()      # nothing before the repeat replays anything
    assert plan.entry[second_a] and plan.entry[second_a + 4] and not plan.entry[second_a + 1]
    assert plan.fresh[first_a + 32] and not plan.fresh[first_a]   # B is new; the first section is not "new"
    assert plan.section_start[first_a + 32] and plan.section_start[second_a]
    assert [s.get("repeats") for s in plan.sections] == [None, None, 0]
    # Danced at double time, the half beats pair too.
    half = np.sort(np.r_[grid, grid[:-1] + 0.25])
    plan2 = form_plan(music, half, "same")
    assert (plan2.source >= 0).sum() == 64
    # --repeat off reports the sections and asks nothing.
    off = form_plan(music, grid, "off")
    assert not (off.source >= 0).any() and not off.fresh.any() and len(off.sections) == 3


def test_vary_dances_the_last_bars_of_each_phrase_anew_and_phrases_that_sound_alike_pair():
    music = _music("ABA")
    pairs = bar_pairs(music.structure, "vary", 0.5)
    assert pairs[16:24].tolist() == [0, 1, -2, -2, 4, 5, -2, -2]
    assert bar_pairs(music.structure, "vary", 0.0)[16:24].tolist() == list(range(8))
    assert (bar_pairs(music.structure, "vary", 1.0)[16:24] == -2).all()
    # Within a section, a phrase sounding like an earlier one replays it (bars 4-7 of A sound like 0-3).
    sim = np.eye(24)
    for a in range(4):
        sim[4 + a, a] = sim[a, 4 + a] = 0.9
    alike = _music("ABA", similarity=sim)
    pairs = bar_pairs(alike.structure, "same", 0.5)
    assert pairs[4:8].tolist() == [0, 1, 2, 3] and pairs[16:24].tolist() == list(range(8))
    assert (pairs[8:16] == -1).all()


def test_mirror_shows_a_replay_of_a_replay_as_the_moves_themselves():
    # A's second phrase repeats its first (mirrored); A's return mirrors A: its second phrase is then the
    # first phrase mirrored twice, the moves themselves (as the first A's second phrase, which it replays).
    sim = np.eye(24)
    for a in range(4):
        sim[4 + a, a] = sim[a, 4 + a] = 0.9
    music = _music("ABA", similarity=sim)
    grid = music.beat_times_s
    plan = form_plan(music, grid, "mirror")
    phrase2, again, again2 = 4 * 4, 16 * 4, 20 * 4     # grid beats of bars 4, 16 and 20
    assert plan.source[phrase2] == plan.source[again] == plan.source[again2] == 0
    danced = np.arange(len(grid))
    mirror = np.arange(len(grid)) + len(grid)          # each move's mirror image: another value
    want = plan.targets(danced, 0, len(grid), mirror)
    assert want[phrase2] == want[again] == mirror[0] and want[again2] == danced[0]
    assert plan.targets(danced, 0, len(grid))[again] == 0   # no mirror lookup: the same moves


def test_bad_repeat_options_are_clear_errors_and_write_nothing(tmp_path, bundled_song):
    from test_cli import run

    out = tmp_path / "d.bvh"
    for args, says in ((["--repeat", "again"], "--repeat"), (["--repeat", "vary", "--vary", "2"], "--vary 2"),
                       (["--vary", "nan"], "--vary nan")):
        proc = run("dance", bundled_song, "-o", out, *args)
        assert proc.returncode != 0 and "Traceback" not in proc.stderr and says in proc.stderr, proc.stderr
        assert not out.exists()


def test_the_structure_score_is_one_for_a_dance_that_repeats_as_the_music_and_chance_for_a_shuffled_one():
    labels = np.repeat(np.array([0, 1, 0, 2, 1]), 8)
    offset = np.tile(np.arange(8), 5)
    music = ((labels[:, None] == labels[None, :]) & (offset[:, None] == offset[None, :])).astype(float)
    sections = [(8 * k, 8) for k in range(5)]
    assert correlation(music, music) == pytest.approx(1.0)
    chance = shuffled_score(music, music, sections)
    assert chance < 0.3
    rng = np.random.default_rng(1)
    unrelated = rng.normal(size=(40, 40))
    assert abs(correlation(music, (unrelated + unrelated.T) / 2)) < 0.15


def test_a_dance_whose_bars_repeat_as_the_music_scores_high_and_body_shapes_ignore_heading(bundled_db):
    style = bundled_db.styles[sorted(bundled_db.styles)[0]]
    clip = max((style.clip(c) for c in range(style.n_clips)), key=lambda c: c.n_frames)
    fps = clip.fps
    bar_f = int(2.0 * fps)                       # 2 s bars, 4 beats of 0.5 s
    labels = [0, 1, 0, 1, 2, 0]
    pieces = {lab: np.arange(k * 3 * bar_f, k * 3 * bar_f + bar_f) for k, lab in enumerate(sorted(set(labels)))}
    frames = np.concatenate([pieces[lab] for lab in labels])
    assert frames.max() < clip.n_frames
    from dancesynth.types import MotionClip

    dance = MotionClip(clip.skeleton, fps, clip.root_pos[frames], clip.local_rot[frames])
    starts = np.arange(len(labels)) * 2.0
    n = len(labels)
    music_sim = np.array([[1.0 if labels[i] == labels[j] else 0.0 for j in range(n)] for i in range(n)])
    st = SongStructure((Section(0.0, 6.0, "A", "verse", 0, 3), Section(6.0, 12.0, "B", "verse", 3, 3)),
                       (), tuple(starts), music_sim)
    score = form_score(dance, st, 4)
    assert score["form_score"] > 0.8
    # Turned about the vertical and moved, the body keeps its shape.
    from scipy.spatial.transform import Rotation

    turn = Rotation.from_euler("y", 90, degrees=True)
    root_rot = Rotation.from_quat(dance.local_rot[:, 0])
    turned = replace(dance, local_rot=dance.local_rot.copy(), root_pos=turn.apply(dance.root_pos) + [1.0, 0.0, 2.0])
    turned.local_rot[:, 0] = (turn * root_rot).as_quat()
    t = np.arange(10) * 0.3
    assert np.allclose(body_shapes(dance, t), body_shapes(turned, t), atol=1e-6)


@needs_fluidsynth
def test_a_returning_section_replays_its_moves_in_every_engine(tmp_path, bundled_db):
    from dancesynth.api import analyse, dance
    from dancesynth.bench.groundtruth import render_song, structure_specs

    spec = next(s for s in structure_specs("tune") if s.name == "form-rondo88_4-4")
    song = render_song(spec, tmp_path)
    music = analyse(song.audio_path)
    labels = [s.label for s in music.structure.sections]
    assert labels.count(labels[1]) >= 2          # the chorus comes back
    for engine in ("streaming", "global", "choreography", "neural"):
        same = dance(music, database=bundled_db, engine=engine, repeat="same")
        off = dance(music, database=bundled_db, engine=engine, repeat="off")
        form = same.provenance.summary["form"]
        assert form["repeat"] == "same" and form["replayed_share"] >= 0.9, (engine, form)
        moved = _chorus_difference(same, music), _chorus_difference(off, music)
        assert moved[0] < 0.5 * moved[1], (engine, moved)   # the second chorus looks like the first
        s_same = form_score(same, music.structure, music.beats_per_bar)
        s_off = form_score(off, music.structure, music.beats_per_bar)
        assert s_same["form_score"] > s_same["form_chance"] + 0.15 and s_same["form_score"] > s_off["form_score"]
    # --repeat mirror: the second chorus is the first's mirror image (left and right swapped, x flipped).
    mirror = dance(music, database=bundled_db, repeat="mirror")
    assert "note" not in mirror.provenance.summary["form"]       # this style has mirrored takes
    assert _chorus_difference(mirror, music, mirrored=True) < 0.5 * _chorus_difference(mirror, music)


def _chorus_difference(clip, music, mirrored: bool = False) -> float:
    """Mean body-shape distance between the first chorus and its return, beat by beat (``mirrored``: the
    return's mirror image: left and right swapped, x flipped)."""
    secs = music.structure.sections
    first = next(s for s in secs if [t.label for t in secs].count(s.label) > 1)
    again = next(s for s in secs[secs.index(first) + 1:] if s.label == first.label)
    n = min(first.n_bars, again.n_bars) * music.beats_per_bar
    a = np.searchsorted(music.beat_times_s, first.start_s - 1e-6)
    b = np.searchsorted(music.beat_times_s, again.start_s - 1e-6)
    a = max(a, np.flatnonzero(music.beat_in_bar == 0)[first.first_bar])
    times_a, times_b = music.beat_times_s[a:a + n], music.beat_times_s[b:b + n]
    shape_a, shape_b = body_shapes(clip, times_a), body_shapes(clip, times_b)
    if mirrored:   # body_shapes' points: head, then left and right of wrists, elbows, knees, ankles
        shape_b = shape_b.reshape(n, -1, 3)[:, [0, 2, 1, 4, 3, 6, 5, 8, 7]] * [-1.0, 1.0, 1.0]
        shape_b = shape_b.reshape(n, -1)
    return float(np.mean(np.linalg.norm(shape_a - shape_b, axis=1)))


def _chord_song(bars: list[int], sr: int = 22050, bar_s: float = 2.0) -> np.ndarray:
    """Audio of one chord per bar (a bar's number picks its root), struck on each of its 4 beats."""
    t = np.arange(int(bar_s * sr)) / sr
    beat = np.exp(-6.0 * ((t % (bar_s / 4)) / (bar_s / 4)))
    out = []
    for root in bars:
        f = 220.0 * 2 ** (root / 12.0)
        chord = sum(np.sin(2 * np.pi * f * r * t) for r in (1.0, 2 ** (4 / 12), 2 ** (7 / 12)))
        out.append((0.2 * beat * chord).astype(np.float32))
    return np.concatenate(out)


def test_the_live_matcher_finds_a_repeat_only_after_hearing_it_and_replays_from_there():
    from dancesynth.live.form import LiveForm

    a, b = [0, 5, 7, 9, 2, 4], [1, 6, 11, 3, 8, 10]
    bars = a + b + a                                  # A B A, 6 bars each, 2 s bars of 4 beats
    sr, audio = 22050, _chord_song(a + b + a + [0])
    form = LiveForm(sr)
    heard_bars = []
    for bar in range(len(bars) + 1):
        form.push(audio[bar * 2 * sr:(bar + 1) * 2 * sr])
        if bar:   # a bar's beats are given once its audio is heard
            form.add_beats((bar - 1) * 2.0 + 0.5 * np.arange(4), [0, 1, 2, 3], 4)
        heard_bars.append(len(form.repeats))
    # Nothing repeats before the second A; its first two bars heard (bars 12 and 13), it is found.
    assert heard_bars[:14] == [0] * 14 and heard_bars[-1] >= 1
    assert form.repeats[0] == [12, 0] or tuple(form.repeats[0]) == (12, 0)
    plan = form.plan
    replayed = np.flatnonzero(plan.source >= 0)
    assert replayed.min() == 14 * 4                   # from the bar after the two that matched
    assert np.array_equal(plan.source[replayed], replayed - 12 * 4)
    assert plan.entry[14 * 4] and not plan.entry[14 * 4 + 1]


def test_off_streams_without_the_matcher():
    from dancesynth.live.form import LiveForm

    form = LiveForm(22050, "off")
    form.push(_chord_song([0, 5, 0, 5, 0, 5, 0, 5]))
    form.add_beats(0.5 * np.arange(32), np.arange(32) % 4, 4)
    assert len(form.plan.source) == 32 and not (form.plan.source >= 0).any() and not form.repeats


@needs_fluidsynth
def test_stream_and_dance_say_what_the_form_replayed(tmp_path):
    from test_cli import run

    from dancesynth.bench.groundtruth import render_song, structure_specs

    spec = next(s for s in structure_specs("tune") if s.name == "form-aaba124_4-4")
    song = render_song(spec, tmp_path)
    proc = run("stream", song.audio_path, "-o", tmp_path / "live.bvh", "--fast", "-q", "--repeat", "same")
    assert proc.returncode == 0, proc.stderr
    line = next(ln for ln in proc.stdout.splitlines() if ln.startswith("form "))
    assert "repeats bar" in line and "beats replayed" in line, line
    proc = run("dance", song.audio_path, "-o", tmp_path / "d.bvh", "--repeat", "same")
    line = next(ln for ln in proc.stdout.splitlines() if ln.startswith("form "))
    assert "A:" in line and "bars replay an earlier one, 100% of their beats" in line, line
    proc = run("dance", song.audio_path, "-o", tmp_path / "d.bvh")   # off by default: no form analysed
    assert not any(ln.startswith("form ") for ln in proc.stdout.splitlines())


def test_a_pause_is_no_repeat_live():
    from dancesynth.live.form import LiveForm

    sr = 22050
    form = LiveForm(sr)
    audio = np.concatenate([_chord_song([0, 5, 7, 9]), np.zeros(8 * 2 * sr, np.float32)])   # 4 bars, then 8 silent
    form.push(audio)
    form.add_beats(0.5 * np.arange(48), np.arange(48) % 4, 4)
    assert not form.repeats and not (form.plan.source >= 0).any()

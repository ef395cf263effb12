"""The procedural dancer's motion, measured on the produced skeleton (forward kinematics)."""

from __future__ import annotations

import numpy as np
import pytest
from procedural_songs import chorale_midi, phrase_song

from dancesynth.engines.procedural import ProceduralConfig, conduct_notes, default_skeleton
from dancesynth.engines.procedural.bezier import bezier_tangents
from dancesynth.engines.procedural.engine import plan_right_hand
from dancesynth.engines.procedural.segment import segment
from dancesynth.engines.procedural.speed import sample_path
from dancesynth.bench import groundtruth as gt
from dancesynth.io.bvh import read_bvh, write_bvh
from dancesynth.kinematics import clip_fk
from dancesynth.motion.roles import find_roles
from dancesynth.music.notes import midi_notes


@pytest.fixture(scope="module")
def songs(tmp_path_factory):
    """Three melodies: a generated song with a real drum kit, a Bach chorale, long/staccato phrases."""
    d = tmp_path_factory.mktemp("songs")
    gt.write_midi(gt.SongSpec("drums", (100,), duration_s=30.0, seed=4), d / "drums.mid")
    paths = {"drums": d / "drums.mid", "phrases": phrase_song(d / "phrases.mid")}
    try:
        import music21  # noqa: F401
        paths["chorale"] = chorale_midi(d / "chorale.mid")
    except ImportError:
        pass
    return {k: midi_notes(p) for k, p in paths.items()}


@pytest.fixture(scope="module")
def skeleton(bundled_db):
    return default_skeleton(bundled_db)


@pytest.fixture(scope="module")
def clips(songs, skeleton):
    return {k: conduct_notes(n, skeleton=skeleton) for k, n in songs.items()}


def _positions(clip):
    _, pos = clip_fk(clip)
    return pos, find_roles(clip.skeleton)


def test_hands_stay_in_reach_and_elbows_in_their_limits(clips):
    cfg = ProceduralConfig()
    for clip in clips.values():
        pos, roles = _positions(clip)
        for side in (0, 1):
            length = clip.meta["arm_length"][side]
            d = np.linalg.norm(pos[:, roles.wrists[side]] - pos[:, roles.shoulders[side]], axis=1)
            assert d.max() <= cfg.reach * length + 1e-6
        flex = clip.meta["elbow_flex_deg"]
        assert flex.min() >= cfg.elbow_min - 1e-6 and flex.max() <= cfg.elbow_max + 1e-6


def test_hand_speed_stays_under_the_limit(songs, clips, skeleton):
    for name, clip in clips.items():
        pos, roles = _positions(clip)
        speed = np.linalg.norm(np.diff(pos[:, roles.wrists[1]], axis=0), axis=1) * clip.fps
        assert speed.max() / clip.meta["arm_length"][1] <= ProceduralConfig().speed_limit, name
    # A lower limit slows the same song down.
    slow = conduct_notes(songs["drums"], ProceduralConfig(speed_limit=1.5), skeleton=skeleton)
    pos, roles = _positions(slow)
    speed = np.linalg.norm(np.diff(pos[:, roles.wrists[1]], axis=0), axis=1) * slow.fps
    assert speed.max() / slow.meta["arm_length"][1] <= 1.5 * 1.1


def test_right_hand_stops_suddenly_on_beat_notes(clips):
    for name, clip in clips.items():
        pos, roles = _positions(clip)
        fps = clip.fps
        speed = np.linalg.norm(np.diff(pos[:, roles.wrists[1]], axis=0), axis=1) * fps  # interval k -> k+1
        ratios = []
        for tb in clip.meta["beat_note_times_s"]:
            k = int(np.floor(tb * fps + 1e-6))
            if k < 5:
                continue
            # Within one frame of the beat the hand is nearly still, after moving fast just before.
            ratios.append(speed[k:k + 2].min() / speed[k - 4:k].max())
        assert len(ratios) > 10, name
        assert max(ratios) < 0.5 and np.median(ratios) < 0.1, name
        # ... and every sudden stop (speed falling by 70% in one frame) is at a beat or rest note.
        stops = np.flatnonzero((speed[1:] < 0.3 * speed[:-1]) & (speed[:-1] > 0.2)) + 1
        corners = clip.meta["keyframe_times_s"][clip.meta["corner"]]
        assert len(stops) > 10
        assert np.max(np.min(np.abs(stops[:, None] / fps - corners[None, :]), axis=1)) <= 1.0 / fps + 1e-9, name


def test_path_is_c1_at_regular_notes_and_cornered_at_beats(songs):
    cfg = ProceduralConfig()
    notes = songs["drums"]
    keys, path, _ = plan_right_hand(notes, segment(notes, cfg), cfg)
    h = 1e-5
    inner = np.arange(1, len(keys.times_s) - 1)
    t = keys.times_s[inner]
    p = sample_path(path, cfg, np.concatenate([t - h, t, t + h]))
    before, at, after = np.split(p, 3)
    v_in, v_out = (at - before) / h, (after - at) / h
    regular = ~keys.corner[inner]
    assert regular.sum() >= 10
    # Regular notes: velocity continuous (same speed, same direction) in time.
    scale = np.linalg.norm(v_in[regular], axis=1)
    assert np.all(scale > 1e-3)
    assert np.max(np.linalg.norm(v_out[regular] - v_in[regular], axis=1) / scale) < 0.02
    # Beat and rest notes: the hand arrives moving and leaves from rest ...
    corner = keys.corner[inner]
    assert np.all(np.linalg.norm(v_out[corner], axis=1) < 0.02 * np.linalg.norm(v_in[corner], axis=1))
    # ... and the path itself turns sharply there (Fig. 6): the tangents in and out differ.
    t_in = bezier_tangents(path.ctrl[inner - 1], np.array([1.0]))[:, 0]
    t_out = bezier_tangents(path.ctrl[inner], np.array([0.0]))[:, 0]
    cos = np.sum(t_in * t_out, axis=1) / (np.linalg.norm(t_in, axis=1) * np.linalg.norm(t_out, axis=1))
    assert np.all(np.degrees(np.arccos(np.clip(cos[corner], -1, 1))) > 20)
    assert np.all(cos[regular] > 1 - 1e-9)


def test_left_hand_reaches_out_on_long_notes_and_drops_on_staccato(songs, clips):
    clip, notes = clips["phrases"], songs["phrases"]
    pos, roles = _positions(clip)
    fps = clip.fps
    length = clip.meta["arm_length"][0]
    wrist, chest = pos[:, roles.wrists[0]], pos[:, roles.shoulders[0]]
    out = (wrist - chest)[:, 0] * np.sign(pos[0, roles.shoulders[0], 0])  # sideways, away from the body
    long_mid = notes.onset_s[notes.duration_16 > 4] + 0.5
    stacc = notes.onset_s[notes.staccato]
    assert len(long_mid) >= 6 and len(stacc) >= 6
    far = out[np.round(long_mid * fps).astype(int)]
    rest = out[np.round((stacc + 0.8) * fps).astype(int)]  # on the eighths after the staccato
    assert np.min(far) > np.max(rest) + 0.3 * length
    # Staccato: the left hand drops most of the way within 0.1 s, then stops dead.
    y = wrist[:, 1]
    for t in stacc:
        k = int(round(t * fps))
        drop = y[k] - y[k + 3]
        assert drop > 0.5 * ProceduralConfig().staccato_drop * length
        assert abs(y[k + 5] - y[k + 4]) < 0.2 * drop  # stopped


def test_head_and_torso_keep_a_minimum_time_between_turns(clips):
    cfg = ProceduralConfig()
    clip = clips["drums"]
    pos, roles = _positions(clip)
    head = pos[:, roles.head]
    for axis, gap in ((2, cfg.nod_turn), (0, cfg.sway_turn)):
        v = np.diff(head[:, axis])
        moving = np.abs(v) > 1e-6
        s = np.sign(v[moving])
        turns = np.flatnonzero(moving)[np.flatnonzero(np.diff(s) != 0) + 1]
        assert len(turns) > 10
        assert np.min(np.diff(turns)) / clip.fps >= gap - 2.0 / clip.fps


def test_legs_stand_still_on_the_ground(clips):
    clip = clips["drums"]
    pos, roles = _positions(clip)
    feet = pos[:, [j for j in roles.ankles + roles.toes if j >= 0]]
    assert np.ptp(feet, axis=0).max() < 1e-9          # feet planted
    assert abs(feet[..., 1].min()) < 1e-6             # on the floor
    assert np.ptp(clip.root_pos, axis=0).max() == 0.0


def test_bvh_round_trip_and_determinism(tmp_path, songs, clips, skeleton):
    clip = clips["phrases"]
    write_bvh(tmp_path / "c.bvh", clip)
    back = read_bvh(tmp_path / "c.bvh", to_metres=False)
    _, a = clip_fk(clip)
    _, b = clip_fk(back)
    assert back.n_frames == clip.n_frames
    assert np.max(np.abs(a - b)) < 1e-4
    again = conduct_notes(songs["phrases"], skeleton=skeleton)
    assert np.array_equal(again.local_rot, clip.local_rot)


def test_larger_l1_draws_larger_curves(songs, skeleton):
    notes = songs["drums"]
    extent = {}
    for style in ("e1", "e2"):
        from dancesynth.engines.procedural import make_config

        clip = conduct_notes(notes, make_config(style=style), skeleton=skeleton)
        extent[style] = np.ptp(clip.meta["right_hand_plan"][:, 1])
    assert extent["e1"] > extent["e2"]

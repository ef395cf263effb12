"""Visible artefacts (``eval.artefacts``) on analytic motions, and on real dances of the bundled database."""

from __future__ import annotations

import numpy as np
import pytest

from dancesynth import rotations as rot
from dancesynth.errors import InputError
from dancesynth.eval.artefacts import hand_in_head_frames, new_steps, one_frame_steps
from dancesynth.types import MotionClip, Skeleton

R3 = ("Zrotation", "Xrotation", "Yrotation")
SHOULDER = np.array([0.15, 1.4, 0.0])  # world position of LeftArm at rest
HEAD_CENTRE = np.array([0.0, 1.7, 0.0])  # middle of the head bone (Head at 1.6 m, its End Site 0.2 m above)


def swaying(n_frames: int = 40, n_joints: int = 4, deg_per_frame: float = 3.0) -> np.ndarray:
    """Local rotations (F, J, 4): every joint turns steadily about its own axis, a few degrees a frame."""
    t = np.arange(n_frames)[:, None, None]
    axes = np.eye(3)[np.arange(n_joints) % 3][None]
    return rot.exp(np.radians(deg_per_frame) * t * axes * np.ones((n_frames, n_joints, 1)))


def turned(q: np.ndarray, deg: float, axis=(0.0, 0.0, 1.0)) -> np.ndarray:
    return rot.mul(rot.exp(np.radians(deg) * np.asarray(axis)), q)


# -- one_frame_steps -------------------------------------------------------------------------------------------


def test_a_joint_that_flips_once_is_counted_once():
    q = swaying()
    q[12:, 1] = turned(q[12:, 1], 90.0)   # from frame 12 on, joint 1 is turned by 90 degrees: one step
    assert one_frame_steps(q).tolist() == [[11, 1]]


def test_a_single_bad_frame_is_counted_once():
    q = swaying()
    q[20, 2] = turned(q[20, 2], 60.0)     # one frame out of line, there and back
    assert one_frame_steps(q).tolist() == [[19, 2]]


def test_a_fast_smooth_spin_is_not_a_step():
    q = swaying(deg_per_frame=45.0)       # 45 degrees every frame: fast, but no frame stands out
    assert one_frame_steps(q).size == 0


def test_steps_below_the_threshold_or_not_isolated_do_not_count():
    q = swaying()
    q[10:, 0] = turned(q[10:, 0], 25.0)   # under 30 degrees
    assert one_frame_steps(q).size == 0
    assert one_frame_steps(q, threshold_deg=20.0).tolist() == [[9, 0]]
    fast = swaying(deg_per_frame=15.0)
    fast[10:, 0] = turned(fast[10:, 0], 40.0)  # its neighbours turn 15 degrees: more than a third of it
    assert one_frame_steps(fast).size == 0


def test_a_step_at_either_end_counts_and_clips_work_too():
    q = swaying(n_frames=5)
    q[-1, 3] = turned(q[-1, 3], 80.0)
    clip = MotionClip(small_body(), 30.0, np.zeros((5, 3)), np.tile(rot.IDENTITY, (5, small_body().n_joints, 1)))
    clip.local_rot[:, :4] = q
    assert one_frame_steps(q).tolist() == [[3, 3]]
    assert one_frame_steps(clip).tolist() == [[3, 3]]


def test_bad_input_is_a_clear_error():
    with pytest.raises(InputError, match="threshold_deg"):
        one_frame_steps(swaying(), threshold_deg=0)
    with pytest.raises(InputError, match="frames, joints, 4"):
        one_frame_steps(np.zeros((10, 4)))


def test_new_steps_leaves_out_the_sources_own_glitches_but_not_cuts():
    source = swaying()
    source[15:, 1] = turned(source[15:, 1], 70.0)   # a glitch in the capture itself
    dance = source.copy()
    dance[30:, 2] = turned(dance[30:, 2], 50.0)     # one the rendering added
    assert one_frame_steps(dance).tolist() == [[14, 1], [29, 2]]
    assert new_steps(dance, source).tolist() == [[29, 2]]
    # Across a cut the source jumps between pieces of mocap: that explains nothing.
    assert new_steps(dance, source, cuts=[14]).tolist() == [[14, 1], [29, 2]]


def test_a_snap_the_source_makes_smaller_is_the_sources_own_played_faster():
    source = swaying()
    source[15:, 1] = turned(source[15:, 1], 25.0)   # under the threshold in the capture...
    source[30:, 2] = turned(source[30:, 2], 10.0)
    dance = swaying()
    dance[15:, 1] = turned(dance[15:, 1], 40.0)     # ...shown 1.6x as fast: still the capture's
    dance[30:, 2] = turned(dance[30:, 2], 40.0)     # a 10-degree wobble does not explain a 40-degree snap
    assert one_frame_steps(dance).tolist() == [[14, 1], [29, 2]]
    assert new_steps(dance, source).tolist() == [[29, 2]]


# -- feet_vs_source -----------------------------------------------------------------------------------------------


def _salsa_as_danced(bundled_db, seconds: float = 12.0):
    """A salsa clip played as captured at 30 fps (every 2nd frame of 60), with its flat source frames."""
    from dataclasses import replace

    st = bundled_db.styles["salsa-133-150bpm"]
    clips = [st.clip(c) for c in range(st.n_clips)]
    frames = np.arange(0, int(seconds * st.fps), 2)
    c = st.clip_names.index("60_06_scaled")
    clip = clips[c]
    dance = replace(clip, fps=30.0, local_rot=clip.local_rot[frames], root_pos=clip.root_pos[frames], contacts=None,
                    meta={})
    return dance, frames + int(st.clip_starts[c]), clips, st.clip_starts


def test_a_dance_that_plays_its_source_as_captured_adds_nothing_to_the_feet(bundled_db):
    from dancesynth.eval.artefacts import feet_vs_source

    dance, source, clips, starts = _salsa_as_danced(bundled_db)
    r = feet_vs_source(dance, source, clips, starts)
    assert r["share"] == 1.0
    assert r["foot_skate_vs_source"] == pytest.approx(1.0, abs=1e-9)
    assert r["pfc_vs_source"] == pytest.approx(1.0, abs=1e-9)


def test_feet_slid_by_the_rendering_show_against_the_source(bundled_db):
    from dataclasses import replace

    from dancesynth.eval.artefacts import feet_vs_source

    dance, source, clips, starts = _salsa_as_danced(bundled_db)
    t = np.arange(dance.n_frames) / dance.fps
    slid = dance.root_pos.copy()
    slid[:, 0] += 0.08 * np.sin(2 * np.pi * 1.5 * t)  # the whole body, feet too, swept 8 cm to and fro
    r = feet_vs_source(replace(dance, root_pos=slid), source, clips, starts)
    assert r["foot_skate_vs_source"] > 1.3 and r["pfc_vs_source"] > 1.3


def test_runs_end_at_cuts_and_short_runs_are_left_out(bundled_db):
    from dancesynth.eval.artefacts import feet_vs_source

    dance, source, clips, starts = _salsa_as_danced(bundled_db)
    cut = source.copy()
    cut[200:] -= 300          # a jump back in the source at frame 200 (6.7 s) ...
    cut[320:] += 600          # ... and forward at 320: a 4 s run in between
    r = feet_vs_source(dance, cut, clips, starts, min_run_s=5.0)
    assert r["share"] == pytest.approx(200 / dance.n_frames)  # the middle and last runs are too short
    assert feet_vs_source(dance, cut, clips, starts, min_run_s=100.0)["foot_skate_vs_source"] is None
    with pytest.raises(InputError, match="one source frame per dance frame"):
        feet_vs_source(dance, source[:-1], clips, starts)


# -- hand_in_head_frames -----------------------------------------------------------------------------------------


def small_body() -> Skeleton:
    """Legs, a spine with a head (End Site 0.2 m above it), and a left arm 0.335 m long from shoulder to wrist."""
    names = ("Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "RightUpLeg", "RightLeg", "RightFoot", "Spine", "Head",
             "LeftArm", "LeftForeArm", "LeftHand")
    parents = np.array([-1, 0, 1, 2, 0, 4, 5, 0, 7, 7, 9, 10])
    offsets = np.array([[0, 0, 0], [0.1, 0, 0], [0, -0.45, 0], [0, -0.4, 0], [-0.1, 0, 0], [0, -0.45, 0],
                        [0, -0.4, 0], [0, 0.5, 0], [0, 0.1, 0], [0.15, -0.1, 0], [0.17, 0, 0], [0.165, 0, 0]])
    channels = (("Xposition", "Yposition", "Zposition") + R3,) + (R3,) * 11
    return Skeleton(names, parents, offsets, channels, {8: np.array([0.0, 0.2, 0.0])})


def arm_raised_to_the_head(n_frames: int, raised) -> MotionClip:
    """Hips 1.0 m up; in ``raised`` frames the left arm swings up so that the wrist sits in the head's middle."""
    sk = small_body()
    local = np.tile(rot.IDENTITY, (n_frames, sk.n_joints, 1))
    to_head = HEAD_CENTRE - SHOULDER
    assert np.isclose(np.linalg.norm(to_head), 0.335, atol=1e-3)
    angle = np.arctan2(to_head[1], to_head[0])      # from the arm's rest direction (+X) about +Z
    local[raised, 9] = rot.exp(np.array([0.0, 0.0, angle]))
    return MotionClip(sk, 30.0, np.tile([0.0, 1.0, 0.0], (n_frames, 1)), local)


def test_a_hand_at_the_head_counts():
    raised = np.zeros(20, dtype=bool)
    raised[5:10] = True
    clip = arm_raised_to_the_head(20, raised)
    assert hand_in_head_frames(clip) == pytest.approx(0.25)
    assert hand_in_head_frames(clip, radius_m=None) == pytest.approx(0.25)  # half the 0.2 m head bone


def test_a_hand_at_rest_is_not_in_the_head():
    clip = arm_raised_to_the_head(10, np.zeros(10, dtype=bool))
    assert hand_in_head_frames(clip) == 0.0
    with pytest.raises(InputError, match="radius_m"):
        hand_in_head_frames(clip, radius_m=-1.0)


# -- real dances ---------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module", params=["Kevin_MacLeod_-_Vibe_Ace.ogg", "Karissa_Hobbs_-_Lets_Go_Fishin.ogg"])
def song_music(request):
    # Vibe Ace is danced in salsa; Lets Go Fishin in the small jpop style, whose mocap barely
    # accelerates, so its transitions have the least room (one left jpop's elbow mid-hit: 1.08x p99).
    from dancesynth.bench.common import load_song

    return load_song(request.param)


@pytest.fixture(scope="module")
def mocap_refs():
    return {}


def _reference(style, fps, refs):
    from dancesynth.bench.quality import at_fps
    from dancesynth.eval.evaluate import mocap_reference

    if style.name not in refs:
        refs[style.name] = mocap_reference([at_fps(style.clip(c), fps) for c in range(style.n_clips)], fps)
    return refs[style.name]


@pytest.mark.parametrize("engine", ["streaming", "global"])
def test_real_dances_have_no_snaps_and_no_transition_rougher_than_the_mocap(bundled_db, song_music, mocap_refs,
                                                                           engine):
    """The regression test of the rendering: no one-frame joint snap that the mocap does not have, and no
    transition that changes a joint's angular velocity more than the style's mocap does in its roughest 1 %."""
    from dancesynth.api import dance
    from dancesynth.eval.evaluate import evaluate
    from dancesynth.motion.resample import sample_frames

    clip = dance(song_music, database=bundled_db, engine=engine)
    style = bundled_db.styles[clip.provenance.style]
    source, _, _ = sample_frames(style.local_rot, style.root_pos, clip.provenance.source_frames)
    jumps = np.asarray(clip.provenance.transition_times_s)
    cuts = np.ceil(jumps * clip.fps - 1e-9).astype(np.int64) - 1
    snaps = new_steps(clip, source, cuts=cuts)
    assert snaps.size == 0, [(int(f), clip.skeleton.names[j]) for f, j in snaps]
    assert len(jumps) > 10
    scores = evaluate(clip, transitions_s=jumps, mocap=_reference(style, clip.fps, mocap_refs))
    assert scores["transition_jump_vs_mocap_p99"] <= 1.0

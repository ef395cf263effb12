"""Motion words: cutting at beats, time normalisation and the invariances of the features."""

from __future__ import annotations

import numpy as np
import pytest

from dancesynth import rotations as rot
from dancesynth.errors import InputError, ModelError
from dancesynth.motion.words import (FEATURE_DIM, LANDMARKS, WORD_FRAMES, clip_landmarks, clip_words,
                                     frame_features, landmark_indices, style_words, word_features)
from dancesynth.types import MotionClip, Skeleton

# A plain humanoid: (name, parent, offset in metres)
BODY = [("Hips", -1, (0, 1.0, 0)), ("Spine", 0, (0, 0.2, 0)), ("Head", 1, (0, 0.4, 0)),
        ("LeftArm", 1, (0.2, 0.3, 0)), ("LeftForeArm", 3, (0.3, 0, 0)), ("LeftHand", 4, (0.25, 0, 0)),
        ("RightArm", 1, (-0.2, 0.3, 0)), ("RightForeArm", 6, (-0.3, 0, 0)), ("RightHand", 7, (-0.25, 0, 0)),
        ("LeftUpLeg", 0, (0.1, 0, 0)), ("LeftLeg", 9, (0, -0.45, 0)), ("LeftFoot", 10, (0, -0.45, 0)),
        ("RightUpLeg", 0, (-0.1, 0, 0)), ("RightLeg", 12, (0, -0.45, 0)), ("RightFoot", 13, (0, -0.45, 0))]


def humanoid(rename=None) -> Skeleton:
    body = [((rename or {}).get(b[0], b[0]),) + b[1:] for b in BODY]
    return Skeleton(tuple(b[0] for b in body), np.array([b[1] for b in body]), np.array([b[2] for b in body]),
                    tuple(("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
                          for _ in body))


def linear_clip(n=60, fps=30.0, velocity=(0.5, 0.0, -1.0), hand_velocity=(0.0, 0.3, 0.6), yaw_deg=0.0):
    """Root and left hand move in straight lines at constant speed; the body faces ``yaw_deg``."""
    sk = humanoid()
    t = np.arange(n) / fps
    root = np.array([1.0, 1.0, 2.0]) + t[:, None] * np.asarray(velocity)
    local_rot = np.tile(rot.IDENTITY, (n, sk.n_joints, 1))
    local_rot[:, 0] = rot.about_y(np.radians(yaw_deg))
    local_pos = np.tile(sk.offsets, (n, 1, 1))
    local_pos[:, 5] = sk.offsets[5] + t[:, None] * np.asarray(hand_velocity)  # the hand slides along its arm
    return MotionClip(sk, fps, root, local_rot, local_pos)


def test_landmarks_are_found_by_name():
    idx = landmark_indices(humanoid())
    names = [humanoid().names[i] for i in idx]
    assert names == ["Hips", "Head", "LeftArm", "RightArm", "LeftForeArm", "RightForeArm", "LeftHand",
                     "RightHand", "LeftUpLeg", "RightUpLeg", "LeftLeg", "RightLeg", "LeftFoot", "RightFoot"]
    assert FEATURE_DIM == 3 * len(LANDMARKS) + 3 == 45


def test_words_are_cut_at_the_given_beats_and_resampled_exactly_on_linear_motion():
    fps = 30.0
    clip = linear_clip(fps=fps)
    words = clip_words(clip, beat_frames=[10, 35, 50])
    assert words.features.shape == (2, WORD_FRAMES, FEATURE_DIM) and words.features.dtype == np.float32
    assert list(words.start) == [10, 35] and list(words.end) == [35, 50]
    hand = 3 * LANDMARKS.index("wrist_l")
    for w, (s, e) in enumerate([(10, 35), (35, 50)]):
        t_s = (s + (e - s) * np.arange(WORD_FRAMES) / 12) / fps      # 25 frames / 12: fractional samples
        expected_hand = np.array([0.2 + 0.3 + 0.25, 0.2 + 0.3, 0.0]) + t_s[:, None] * [0.0, 0.3, 0.6]
        np.testing.assert_allclose(words.features[w, :, hand:hand + 3], expected_hand, atol=1e-5)
        np.testing.assert_allclose(words.features[w, :, -3:], np.tile([0.5, 0.0, -1.0], (13, 1)), atol=1e-5)
    # the same beats from the clip's metadata
    clip.meta["beat_frames"] = np.array([35, 10, 50])
    np.testing.assert_array_equal(clip_words(clip).features, words.features)


def test_the_heading_frame_faces_plus_z():
    # facing +X (yaw 90 degrees) and walking forward along +X at 1 m/s: forward velocity is +Z
    clip = linear_clip(velocity=(1.0, 0.0, 0.0), hand_velocity=(0, 0, 0), yaw_deg=90.0)
    f = clip_words(clip, beat_frames=[0, 24]).features[0]
    np.testing.assert_allclose(f[:, -3:], np.tile([0.0, 0.0, 1.0], (13, 1)), atol=1e-6)
    head = 3 * LANDMARKS.index("head")
    np.testing.assert_allclose(f[0, head:head + 3], [0.0, 0.6, 0.0], atol=1e-6)
    wrist_l = 3 * LANDMARKS.index("wrist_l")
    assert f[0, wrist_l] == pytest.approx(0.75, abs=1e-6)  # the left hand stays on the dancer's +X side


def test_frame_features_agree_with_a_word_of_twelve_frames():
    clip = linear_clip(velocity=(0.3, 0.1, 0.2), yaw_deg=30.0)
    pos, root_rot = clip_landmarks(clip)
    via_words = word_features(pos, root_rot, clip.fps, [5], [17])[0]
    via_frames = frame_features(pos[5:18], root_rot[5:18], clip.fps)
    np.testing.assert_allclose(via_words, via_frames, atol=1e-9)
    batched = frame_features(np.stack([pos[5:18], pos[5:18]]), np.stack([root_rot[5:18]] * 2), clip.fps)
    assert batched.shape == (2, 13, FEATURE_DIM)


def moved(clip: MotionClip, yaw_deg: float, shift) -> MotionClip:
    """The same dance performed elsewhere on the floor, facing elsewhere."""
    q = rot.about_y(np.radians(yaw_deg))
    root_rot = clip.local_rot.copy()
    root_rot[:, 0] = rot.mul(q, clip.local_rot[:, 0])
    return MotionClip(clip.skeleton, clip.fps, rot.apply(q, clip.root_pos) + np.asarray(shift), root_rot,
                      meta=dict(clip.meta))


def test_features_ignore_where_the_dancer_stands_and_faces(bundled_db):
    clip = bundled_db.styles["mj"].clip(0)
    a = clip_words(clip).features
    b = clip_words(moved(clip, 123.0, (3.0, 0.0, -7.5))).features
    assert len(a) > 10
    np.testing.assert_allclose(a, b, atol=2e-5)
    # but a different movement is a different word
    assert np.abs(a[1:] - a[:-1]).max() > 0.1


def test_style_words_stay_inside_clips(perfume_db, bundled_db):
    style = perfume_db.styles["jpop"]
    words = style_words(style)
    assert len(words) == len(style.beat_frames) - style.n_clips
    assert np.all(style.clip_of_frame(words.start) == words.clip)
    assert np.all(style.clip_of_frame(words.end) == words.clip)
    assert words.genre == "jpop" and words.style == "jpop"
    first = style.clip(1)
    own = clip_words(first)
    np.testing.assert_allclose(own.features, words.features[words.clip == 1], atol=1e-6)


def test_a_clip_too_short_for_a_word_is_refused():
    with pytest.raises(InputError, match="fewer than two motion beats"):
        clip_words(linear_clip(n=40), beat_frames=[12])
    with pytest.raises(InputError, match="fewer than two motion beats"):
        clip_words(linear_clip(n=5))  # kinematic beats of 5 frames: none


def test_a_skeleton_without_arms_is_refused():
    sk = humanoid({"LeftHand": "LeftFin", "RightHand": "RightFin"})  # hands not named as hands
    with pytest.raises(ModelError, match="shoulder_l"):
        landmark_indices(sk)


def test_bad_word_intervals_are_refused():
    clip = linear_clip(n=30)
    pos, root_rot = clip_landmarks(clip)
    for starts, ends in (([5], [5]), ([5], [30]), ([-1], [4])):
        with pytest.raises(InputError, match="start < end"):
            word_features(pos, root_rot, clip.fps, starts, ends)

"""Motion words: the motion between two consecutive motion beats, time-normalised.

Aristidou et al. (Rhythm is a Dancer, §3) cut a dance at its motion beats and resample
each piece to a fixed length (13 frames) so that a step danced slowly and the same
step danced fast look alike; the words are then embedded and clustered into motifs
(``embedding.py``, ``motifs.py``).

The feature of one frame (``FEATURE_DIM`` = 45 numbers), precisely, so that another
implementation (e.g. a torch loss) can match it number for number:

1. ``rel = p[l] - p[root]`` for the 14 ``LANDMARKS`` ``l`` (the root's own entry is 0);
2. rotated into the *heading frame*: ``apply(inv(H), rel)`` where ``H = about_y(yaw)``
   and ``yaw = heading(root rotation)`` of the word's first frame -- after it the
   dancer faces +Z at the start of the word, Y stays up; heading is measured on the
   root's local +Z axis (``rotations.heading``);
3. then the root velocity in m/s in the same frame: the central difference of the
   root positions divided by the time between the two samples (one-sided at the
   first and last frame; ``np.gradient`` with ``edge_order=1`` for uniform samples).

Positions are metres (the database's unit). A word's 13 frames sample its interval
``[start, end]`` (frames, inclusive: both beats belong to the word) at
``start + i (end - start) / 12``, i = 0..12, linearly interpolating the *global*
positions; the root rotation is only needed at the first frame, which is a beat
frame, so it is never interpolated. A word of ``end - start`` frames at ``fps``
lasts ``(end - start) / fps`` seconds, so its 13 samples are ``(end - start) / (12 fps)``
seconds apart.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import rotations as rot
from ..errors import InputError, ModelError
from ..kinematics import fk
from ..types import MotionClip, Skeleton

WORD_FRAMES = 13
LANDMARKS = ("root", "head", "shoulder_l", "shoulder_r", "elbow_l", "elbow_r", "wrist_l", "wrist_r",
             "hip_l", "hip_r", "knee_l", "knee_r", "ankle_l", "ankle_r")
FEATURE_DIM = 3 * len(LANDMARKS) + 3


def landmark_indices(skeleton: Skeleton) -> np.ndarray:
    """The joint index of each of ``LANDMARKS`` in ``skeleton`` (14,), found by name.

    Raises ``ModelError`` when the skeleton has no recognisable legs, arms or head.
    """
    from .roles import find_roles

    r = find_roles(skeleton)
    idx = np.array([r.root, r.head, *r.shoulders, *r.elbows, *r.wrists, *r.hips, *r.knees, *r.ankles],
                   dtype=np.int64)
    missing = [name for name, j in zip(LANDMARKS, idx) if j < 0]
    if missing:
        raise ModelError(f"cannot find the {', '.join(missing)} joint(s) in skeleton "
                         f"({', '.join(skeleton.names[:8])}, ...): motion words need a head, two arms "
                         "and two legs named e.g. Head, LeftArm/LeftForeArm/LeftHand, LeftUpLeg/LeftLeg/LeftFoot")
    return idx


def _heading_frame(global_root_rot: np.ndarray) -> np.ndarray:
    """The yaw-only rotation of the first frame: (..., 4)."""
    return rot.about_y(rot.heading(global_root_rot[..., 0, :]))


def _velocity(root: np.ndarray, times_s: np.ndarray) -> np.ndarray:
    """Central differences of ``root`` (..., F, 3) over sample times (..., F); one-sided at the ends."""
    if root.shape[-2] < 2:
        return np.zeros_like(root)
    pad_x = np.concatenate([root[..., :1, :], root, root[..., -1:, :]], axis=-2)
    pad_t = np.concatenate([times_s[..., :1], times_s, times_s[..., -1:]], axis=-1)
    # Interior: (x[i+1] - x[i-1]) / (t[i+1] - t[i-1]); at the ends the padding makes it one-sided.
    dx = pad_x[..., 2:, :] - pad_x[..., :-2, :]
    dt = pad_t[..., 2:] - pad_t[..., :-2]
    return dx / np.maximum(dt, 1e-9)[..., None]


def _features(global_pos, heading_rot, times_s) -> np.ndarray:
    """Feature frames from landmark positions (..., F, 14, 3), a heading (..., 4) and sample times (..., F)."""
    inv_h = rot.inv(heading_rot)[..., None, None, :]
    rel = rot.apply(inv_h, global_pos - global_pos[..., :1, :])
    vel = rot.apply(inv_h[..., 0, :], _velocity(global_pos[..., 0, :], times_s))
    lead = global_pos.shape[:-2]
    return np.concatenate([rel.reshape(lead + (3 * len(LANDMARKS),)), vel], axis=-1)


def frame_features(global_pos, global_root_rot, fps, heading_rot=None) -> np.ndarray:
    """Per-frame word features (..., F, FEATURE_DIM) of uniformly sampled frames.

    ``global_pos`` (..., F, 14, 3): global positions of the ``LANDMARKS`` (index an FK
    result with ``landmark_indices``); ``global_root_rot`` (..., F, 4): global root
    rotation; ``fps``: samples per second (a scalar or one per leading index);
    ``heading_rot`` (..., 4): the frame to express everything in (only its yaw should
    be non-zero); by default the heading of the first frame. See the module docstring.
    """
    global_pos = np.asarray(global_pos, dtype=np.float64)
    global_root_rot = np.asarray(global_root_rot, dtype=np.float64)
    if global_pos.ndim < 3 or global_pos.shape[-2:] != (len(LANDMARKS), 3):
        raise InputError(f"global_pos must be (..., frames, {len(LANDMARKS)}, 3), got {global_pos.shape}")
    if heading_rot is None:
        heading_rot = _heading_frame(global_root_rot)
    n = global_pos.shape[-3]
    fps = np.asarray(fps, dtype=np.float64)[..., None]
    times = np.broadcast_to(np.arange(n) / fps, global_pos.shape[:-2])
    return _features(global_pos, np.asarray(heading_rot, dtype=np.float64), times)


def features_at(global_pos, global_root_rot, fps, times) -> np.ndarray:
    """Word features sampled at fractional frame ``times`` (W, T) of one sequence.

    ``global_pos`` (F, 14, 3) and ``global_root_rot`` (F, 4) are the landmarks of a whole
    clip; each row of ``times`` (increasing, in frames) gives one word's samples. The
    heading is the root's at the (rounded) first sample time. Used by ``word_features``
    with uniform samples and by the embedding's training with warped ones.
    """
    global_pos = np.asarray(global_pos, dtype=np.float64)
    times = np.clip(np.asarray(times, dtype=np.float64), 0, len(global_pos) - 1)
    lo = np.minimum(np.floor(times).astype(np.int64), len(global_pos) - 2) if len(global_pos) > 1 \
        else np.zeros(times.shape, dtype=np.int64)
    hi = np.minimum(lo + 1, len(global_pos) - 1)
    a = (times - lo)[..., None, None]
    pos = global_pos[lo] * (1.0 - a) + global_pos[hi] * a
    first = np.rint(times[:, 0]).astype(np.int64)
    heading = rot.about_y(rot.heading(np.asarray(global_root_rot, dtype=np.float64)[first]))
    return _features(pos, heading, times / float(fps))


def word_features(global_pos, global_root_rot, fps, starts, ends) -> np.ndarray:
    """Features (W, WORD_FRAMES, FEATURE_DIM) of the words ``[starts[i], ends[i]]`` (frames, inclusive).

    ``global_pos`` (F, 14, 3) landmark positions and ``global_root_rot`` (F, 4) of one
    clip. Each interval is resampled linearly to 13 frames in the heading frame of its
    first frame.
    """
    starts = np.asarray(starts, dtype=np.int64).reshape(-1)
    ends = np.asarray(ends, dtype=np.int64).reshape(-1)
    n = len(np.asarray(global_pos))
    if starts.shape != ends.shape or np.any(ends <= starts) or np.any(starts < 0) or np.any(ends >= n):
        raise InputError(f"word intervals must satisfy 0 <= start < end < {n} (the number of frames)")
    if starts.size == 0:
        return np.zeros((0, WORD_FRAMES, FEATURE_DIM))
    u = np.linspace(0.0, 1.0, WORD_FRAMES)
    times = starts[:, None] + (ends - starts)[:, None] * u
    return features_at(global_pos, global_root_rot, fps, times)


@dataclass(frozen=True)
class MotionWords:
    """The motion words of a style or a clip, with where each came from."""

    features: np.ndarray   # (W, WORD_FRAMES, FEATURE_DIM) float32
    style: str             # style name ("" for a single clip)
    genre: str
    clip: np.ndarray       # (W,) clip index within the style (0 for a single clip)
    start: np.ndarray      # (W,) flat frame index of the word's first beat
    end: np.ndarray        # (W,) flat frame index of the next beat

    def __len__(self) -> int:
        return len(self.features)


def clip_landmarks(clip: MotionClip) -> tuple[np.ndarray, np.ndarray]:
    """Global landmark positions (F, 14, 3) and global root rotations (F, 4) of a clip."""
    sk = clip.skeleton
    idx = landmark_indices(sk)
    g_rot, g_pos = fk(clip.local_rot, clip.root_pos, sk.offsets, sk.parents, clip.local_pos, only=idx)
    return g_pos[:, idx], g_rot[:, 0]


def _pairs(beats: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    beats = np.unique(np.asarray(beats, dtype=np.int64))
    return beats[:-1], beats[1:]


def kinematic_beat_frames(clip: MotionClip) -> np.ndarray:
    """The clip's kinematic beats: minima of the smoothed summed joint speed (Aristidou §5.2.1)."""
    from . import beats as motion_beats
    from ..kinematics import clip_fk

    _, g_all = clip_fk(clip)
    return motion_beats.kinematic_beats(motion_beats.summed_speed(g_all, clip.fps), clip.fps)[0]


def clip_words(clip: MotionClip, beat_frames=None) -> MotionWords:
    """The words between consecutive beats of one clip.

    Beats are ``beat_frames`` if given, else ``clip.meta["beat_frames"]``, else the
    clip's kinematic beats (summed-speed minima, §5.2.1). ``start``/``end`` are frames
    of the clip. Raises ``InputError`` if the clip has fewer than two beats.
    """
    pos, root_rot = clip_landmarks(clip)
    if beat_frames is None:
        beat_frames = clip.meta.get("beat_frames")
    if beat_frames is None:
        beat_frames = kinematic_beat_frames(clip)
    beats = np.asarray(beat_frames, dtype=np.int64)
    beats = beats[(beats >= 0) & (beats < clip.n_frames)]
    starts, ends = _pairs(beats)
    if starts.size == 0:
        raise InputError(f"the motion ({clip.n_frames} frames, {clip.duration_s:.1f} s) has fewer than two "
                         "motion beats, so no motion word can be cut from it: use a longer dance")
    feats = word_features(pos, root_rot, clip.fps, starts, ends).astype(np.float32)
    zeros = np.zeros(len(starts), dtype=np.int64)
    return MotionWords(feats, "", str(clip.meta.get("genre", "")), zeros, starts, ends)


def style_words(style) -> MotionWords:
    """Every consecutive pair of motion beats inside one clip of a database ``Style``."""
    feats, clips, starts, ends = [], [], [], []
    for c in range(style.n_clips):
        a, b = int(style.clip_starts[c]), int(style.clip_starts[c + 1])
        beats = style.beat_frames[(style.beat_frames >= a) & (style.beat_frames < b)]
        s, e = _pairs(beats)
        if s.size == 0:
            continue
        clip = style.clip(c)
        pos, root_rot = clip_landmarks(clip)
        feats.append(word_features(pos, root_rot, style.fps, s - a, e - a).astype(np.float32))
        clips.append(np.full(len(s), c, dtype=np.int64))
        starts.append(s)
        ends.append(e)
    if not feats:
        empty = np.zeros(0, dtype=np.int64)
        return MotionWords(np.zeros((0, WORD_FRAMES, FEATURE_DIM), np.float32), style.name, style.genre,
                           empty, empty, empty)
    return MotionWords(np.concatenate(feats), style.name, style.genre, np.concatenate(clips),
                       np.concatenate(starts), np.concatenate(ends))

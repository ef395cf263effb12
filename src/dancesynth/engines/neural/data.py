"""Training data for the pose generator (Aristidou et al. §4.1), cut from the motion database.

Every frame becomes one *pose vector* (what the network predicts and is fed back):

- joint rotations in the continuous 6-D form (the first two columns of each local
  rotation matrix, Zhou et al. 2019): quaternions double-cover and Euler angles wrap,
  a network regressing either jumps; the root's rotation is stored without its yaw;
- root motion in the heading frame of the previous frame: forward/sideways speed
  (m/s), turning speed (rad/s) and height (m), so a dance can be generated anywhere
  on the floor facing any way;
- (left, right) foot contacts (0/1).

Beside it every frame gets *conditioning* (what the network is told):

- beat features from the motion's own beats (our mocap has no music): the phase
  within the current beat interval as (sin, cos), and the interval length;
- the target motif as a *motif word* (the paper's motif representation): a real
  motion word of the motif (``motion/words.py`` features: 14 landmarks relative to
  the root and the root's velocity, 13 samples over the word), given to each frame
  as its sample at the frame's phase and its sample half a word ahead, which in the
  second half of a word is the *next* word's motif word (``exemplar_samples``);

and every motion word gets a *music* vector for AdaIN, made of what a song gives as
well as a dance (see docs/neural.md): the beat interval's intensity, z-scored within
the dance (motion: kinetic energy, music: sound level in dB), its change from the
previous beat, and the beat length.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from ... import rotations as rot
from ...motion.database import Style
from ...motion.features import interval_energy
from ...motion.resample import resample_clip_arrays
from ...motion.words import FEATURE_DIM, WORD_FRAMES, clip_words
from ...types import MotionClip

TRAIN_FPS = 30.0          # the generator works at 30 fps; output is resampled to the requested rate
ROOT_DIMS = 4             # forward speed, sideways speed, turning speed, height
MUSIC_DIMS = 3            # intensity z-score, its change, log beat length
BEAT_DIMS = 3             # sin/cos of the beat phase, log beat length
REF_BEAT_S = 0.5          # beat lengths are given as log(length / REF_BEAT_S)
LOOKAHEAD = 0.5           # the second motif-word sample is half a word ahead
COND_DIMS = BEAT_DIMS + 2 * FEATURE_DIM


def pose_dims(n_joints: int) -> int:
    return 6 * n_joints + ROOT_DIMS + 2


# ---------------------------------------------------------------------------------------------
# Pose vectors


def _yaw_of(q: np.ndarray) -> np.ndarray:
    return rot.heading(q)


def encode_pose(local_rot: np.ndarray, root_pos: np.ndarray, contacts: np.ndarray, fps: float) -> np.ndarray:
    """(F, 6J + 6) pose vectors of a motion (see the module docstring)."""
    local_rot = np.asarray(local_rot, dtype=np.float64)
    f, j = local_rot.shape[:2]
    yaw = np.unwrap(_yaw_of(local_rot[:, 0]))
    rots = local_rot.copy()
    rots[:, 0] = rot.mul(rot.about_y(-yaw), local_rot[:, 0])     # root without its heading
    mats = Rotation.from_quat(rots.reshape(-1, 4)).as_matrix().reshape(f, j, 3, 3)
    six = mats[..., :, :2].reshape(f, j * 6)
    step = np.diff(root_pos, axis=0, prepend=root_pos[:1])
    local_step = rot.apply(rot.about_y(-np.r_[yaw[:1], yaw[:-1]]), step)   # in the previous frame's heading
    dyaw = np.diff(yaw, prepend=yaw[:1])
    if f > 1:  # the first frame has no predecessor: give it the second frame's speed
        local_step[0], dyaw[0] = local_step[1], dyaw[1]
    root = np.stack([local_step[:, 2] * fps, local_step[:, 0] * fps, dyaw * fps, root_pos[:, 1]], axis=1)
    return np.concatenate([six, root, np.asarray(contacts, dtype=np.float64).reshape(f, 2)], axis=1).astype(np.float32)


def six_to_matrix(six: np.ndarray) -> np.ndarray:
    """(..., 6) -> (..., 3, 3) by Gram-Schmidt on the two stored columns."""
    a, b = six[..., 0::2], six[..., 1::2]
    x = a / np.maximum(np.linalg.norm(a, axis=-1, keepdims=True), 1e-8)
    b = b - np.sum(x * b, axis=-1, keepdims=True) * x
    y = b / np.maximum(np.linalg.norm(b, axis=-1, keepdims=True), 1e-8)
    return np.stack([x, y, np.cross(x, y)], axis=-1)


def decode_pose(poses: np.ndarray, fps: float, *, yaw0: float = 0.0, xz0=(0.0, 0.0)):
    """Pose vectors (F, 6J + 6) -> ``(local_rot (F, J, 4), root_pos (F, 3), contacts (F, 2) bool)``.

    The root trajectory is integrated from its speeds starting at ``xz0`` facing ``yaw0``.
    """
    poses = np.asarray(poses, dtype=np.float64)
    f = len(poses)
    j = (poses.shape[1] - ROOT_DIMS - 2) // 6
    mats = six_to_matrix(poses[:, :6 * j].reshape(f, j, 6))
    q = Rotation.from_matrix(mats.reshape(-1, 3, 3)).as_quat().reshape(f, j, 4)
    root = poses[:, 6 * j:6 * j + ROOT_DIMS]
    yaw = yaw0 + np.cumsum(root[:, 2] / fps) - root[0, 2] / fps
    q[:, 0] = rot.mul(rot.about_y(yaw), q[:, 0])
    prev_yaw = np.r_[yaw[:1], yaw[:-1]]
    step = rot.apply(rot.about_y(prev_yaw), np.stack([root[:, 1], np.zeros(f), root[:, 0]], axis=1) / fps)
    step[0] = 0.0
    xz = np.asarray(xz0, dtype=np.float64) + np.cumsum(step[:, [0, 2]], axis=0)
    root_pos = np.stack([xz[:, 0], root[:, 3], xz[:, 1]], axis=1)
    return q, root_pos, poses[:, 6 * j + ROOT_DIMS:] > 0.5


# ---------------------------------------------------------------------------------------------
# Beat and music features


def beat_phase(n_frames: int, beat_frames: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per frame: beat interval index, phase in [0, 1) and interval length (s).

    ``beat_frames`` are (fractional) frame positions of beats; frames before the first
    or after the last beat extend the nearest interval.
    """
    b = np.asarray(beat_frames, dtype=np.float64)
    t = np.arange(n_frames, dtype=np.float64)
    k = np.clip(np.searchsorted(b, t, side="right") - 1, 0, len(b) - 2)
    length = b[k + 1] - b[k]
    phase = np.mod((t - b[k]) / length, 1.0)
    return k, phase, length / fps


def beat_features(phase: np.ndarray, length_s: np.ndarray) -> np.ndarray:
    """(F, BEAT_DIMS): sin and cos of the beat phase, log beat length."""
    return np.stack([np.sin(2 * np.pi * phase), np.cos(2 * np.pi * phase),
                     np.log(np.maximum(length_s, 1e-3) / REF_BEAT_S)], axis=1).astype(np.float32)


def music_vectors(intensity: np.ndarray, length_s: np.ndarray) -> np.ndarray:
    """(W, MUSIC_DIMS) AdaIN inputs of W beat intervals from their intensity and length.

    ``intensity`` is anything loudness-like (dB for music, log energy for motion): it
    is z-scored within the piece, so only its shape over time matters.
    """
    x = np.asarray(intensity, dtype=np.float64)
    z = (x - x.mean()) / max(x.std(), 1e-6) if len(x) else x
    dz = np.diff(z, prepend=z[:1])
    return np.stack([z, dz, np.log(np.maximum(length_s, 1e-3) / REF_BEAT_S)], axis=1).astype(np.float32)


def hamming_weights(phase: np.ndarray) -> np.ndarray:
    """Per frame weight (F,) of its word's AdaIN: a raised-cosine bump over the word.

    The Hamming window ``0.54 - 0.46 cos(2 pi phase)`` rescaled to run from exactly
    0 at the word's boundaries to 1 in its middle -- which makes it the Hann window
    ``sin^2(pi phase)`` -- so a word's first pose is never modified and words join
    as the LSTM made them (the plain Hamming window would leave 8 % at the joins).
    """
    return (np.sin(np.pi * np.asarray(phase, dtype=np.float64)) ** 2).astype(np.float32)


def exemplar_samples(exemplars: np.ndarray, k: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """(F, 2 * FEATURE_DIM): each frame's motif word at its phase, and half a word ahead.

    ``exemplars`` (W, 13, D) holds one motif word per beat interval, ``k`` (F,) the
    interval of each frame and ``phase`` (F,) its phase in it. Half a word ahead lies
    in the next interval in the second half of a word: the network sees the next
    motif coming (the last interval looks at its own end).
    """
    ex = np.asarray(exemplars, dtype=np.float32)
    k, phase = np.asarray(k), np.asarray(phase, dtype=np.float64)

    def at(kk, pp):
        u = np.clip(pp, 0.0, 1.0) * (WORD_FRAMES - 1)
        lo = np.minimum(np.floor(u).astype(np.int64), WORD_FRAMES - 2)
        a = (u - lo)[:, None].astype(np.float32)
        return ex[kk, lo] * (1.0 - a) + ex[kk, lo + 1] * a

    ahead = phase + LOOKAHEAD
    nxt = (ahead >= 1.0) & (k + 1 < len(ex))
    k2 = np.where(nxt, k + 1, k)
    p2 = np.where(nxt, ahead - 1.0, np.minimum(ahead, 1.0))
    return np.concatenate([at(k, phase), at(k2, p2)], axis=1)


def conditioning(phase, length_s, exemplars, k) -> np.ndarray:
    """(F, COND_DIMS): beat features and motif-word samples of every frame."""
    return np.concatenate([beat_features(phase, length_s), exemplar_samples(exemplars, k, phase)], axis=1)


# ---------------------------------------------------------------------------------------------
# Sequences of a style


@dataclass
class Sequence:
    """One dance at ``TRAIN_FPS`` with everything the generator is trained on."""

    name: str                # the clip's
    poses: np.ndarray        # (F, P) pose vectors
    phase: np.ndarray        # (F,) beat phase
    length_s: np.ndarray     # (F,) length of the frame's beat interval
    word: np.ndarray         # (F,) index of the word (beat interval) containing each frame
    window: np.ndarray       # (F,) AdaIN weight (0 at word boundaries)
    words: np.ndarray        # (W, 13, FEATURE_DIM) features of each word (its own motif word)
    motifs: np.ndarray       # (W,) motif id of each word (-1: none)
    music: np.ndarray        # (W, MUSIC_DIMS) per word
    beat_frames: np.ndarray  # (W + 1,) fractional frame positions of the beats
    first: int               # frames [first, last) lie between the first and last beat
    last: int
    rate: float = 1.0        # the clip played this much faster (augmentation) ...
    mirrored: bool = False   # ... and left-right mirrored


def style_sequences(style: Style, motif_model=None, *, clips=None, rates=(1.0,),
                    mirror: bool = False) -> list[Sequence]:
    """The clips of ``style`` (all, or the indices ``clips``) as training sequences, optionally augmented.

    Every clip is played at each speed in ``rates`` (1.15: 15 % faster, so shorter
    beats and faster steps) and, with ``mirror``, also left-right mirrored
    (``motion.mirror``). Words are cut at the motion beats of each version at
    ``TRAIN_FPS`` and their motifs assigned by ``motif_model`` (-1 without one): a
    mirrored word is usually another motif.
    """
    out = []
    versions = [(r, False) for r in rates] + ([(r, True) for r in rates] if mirror else [])
    for c in range(style.n_clips) if clips is None else clips:
        clip = style.clip(c)
        beats_src = np.asarray(clip.meta["beat_frames"], dtype=np.float64)
        if len(beats_src) < 3:
            continue
        a, b = style.clip_starts[c], style.clip_starts[c + 1]
        log_energy = np.log(interval_energy(style.energy[a:b], beats_src.astype(np.int64), style.fps) + 1e-3)
        for rate, mirrored in versions:
            local_rot, root_pos, contacts = clip.local_rot, clip.root_pos, clip.contacts
            if mirrored:
                from ...motion.mirror import mirror_motion

                local_rot, root_pos, contacts = mirror_motion(style.skeleton, local_rot, root_pos, contacts)
            local_rot, root_pos, contacts = resample_clip_arrays(local_rot, root_pos, contacts,
                                                                 style.fps * rate, TRAIN_FPS)
            seq = _sequence(clip.meta["name"], style.skeleton, local_rot, root_pos, contacts,
                            beats_src * TRAIN_FPS / (style.fps * rate), log_energy, motif_model)
            if seq is not None:
                out.append(replace(seq, rate=rate, mirrored=mirrored))
    return out


def _sequence(name, skeleton, local_rot, root_pos, contacts, beats, log_energy, motif_model) -> Sequence | None:
    n = len(local_rot)
    beats = beats[beats <= n - 1]
    frames = np.rint(beats).astype(np.int64)
    if len(beats) < 3 or np.any(np.diff(frames) < 1):
        return None
    k, phase, length_s = beat_phase(n, beats, TRAIN_FPS)
    words = clip_words(MotionClip(skeleton, TRAIN_FPS, root_pos, local_rot), frames).features
    motifs = motif_model.assign(words) if motif_model is not None else np.full(len(words), -1)
    return Sequence(name=name, poses=encode_pose(local_rot, root_pos, contacts, TRAIN_FPS),
                    phase=phase.astype(np.float32),
                    length_s=length_s.astype(np.float32), word=k, window=hamming_weights(phase),
                    words=words.astype(np.float32), motifs=np.asarray(motifs, dtype=np.int64),
                    music=music_vectors(log_energy[:len(beats) - 1], np.diff(beats) / TRAIN_FPS),
                    beat_frames=beats, first=int(np.ceil(beats[0])), last=int(np.floor(beats[-1])))


def normaliser(sequences: list[Sequence]) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation of the pose vectors (constant dimensions get std 1)."""
    allp = np.concatenate([s.poses for s in sequences])
    mean, std = allp.mean(0), allp.std(0)
    std = np.where(std < 1e-4, 1.0, std)
    n = allp.shape[1]
    mean[n - 2:], std[n - 2:] = 0.0, 1.0      # contacts stay 0/1 (trained with a logistic loss)
    return mean.astype(np.float32), std.astype(np.float32)


def pose_spread(sequences: list[Sequence], mean: np.ndarray, std: np.ndarray) -> np.ndarray:
    """Each pose channel's standard deviation within one sequence, normalised, averaged over the sequences.

    The "global variance" of the training data (Toda & Tokuda 2007): how far a dance strays from its
    own average pose, which ``restore_spread`` gives back to generated motion.
    """
    return np.mean([((s.poses - mean) / std).std(axis=0) for s in sequences], axis=0).astype(np.float32)


def restore_spread(z: np.ndarray, spread: np.ndarray, channels: int, cap: float) -> np.ndarray:
    """Global-variance post-filter: widen each of the first ``channels`` channels of normalised poses ``z``
    about the dance's own mean until it strays as far as the training data does (``pose_spread``), by at
    most ``cap`` times.

    A network trained on squared and angular errors regresses toward the mean: its joint angles reach
    their extremes less often than mocap (docs/neural.md, "Realism"). The gain is constant over the
    dance, so timing, posture and the order of moves are untouched; only the amplitude grows.
    """
    z = np.array(z, dtype=np.float32)
    mu, sd = z[:, :channels].mean(axis=0), z[:, :channels].std(axis=0)
    gain = np.clip(spread[:channels] / np.maximum(sd, 1e-6), 1.0, cap)
    z[:, :channels] = mu + (z[:, :channels] - mu) * gain
    return z

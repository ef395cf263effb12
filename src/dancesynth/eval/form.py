"""Does the dance follow the song's form? The structure-consistency score.

The music's bars are compared with each other by how they sound (``SongStructure.similarity``:
the same notes in the same order, the same instruments); the dance's bars by how they move:
each bar is its body's shape at ``SAMPLES_PER_BEAT`` points a beat (head, hands, elbows,
knees and feet about the root, turned to face forward and scaled by the leg, so any rig
compares), cosine-compared after z-scoring over the song. The score is the correlation of
the two matrices over every pair of bars: 1 when the dance's bars are as alike as the
music's, 0 when their likeness has nothing to do with it.

Chance is the same dance with its bars shuffled within each section (``shuffled_score``):
the sections' own kind of move kept, which bar repeats which lost. A dance scores above it
only by dancing a returning section as it danced it before.
"""

from __future__ import annotations

import numpy as np

from ..kinematics import fk
from ..motion.roles import find_roles
from ..types import MotionClip, SongStructure

SAMPLES_PER_BEAT = 2
SHUFFLES = 50


def body_shapes(clip: MotionClip, times_s: np.ndarray) -> np.ndarray:
    """(T, D) the body's shape at each time: limb ends about the root, facing forward, in leg lengths."""
    roles = find_roles(clip.skeleton)
    joints = [j for j in (roles.head, *roles.wrists, *roles.elbows, *roles.knees, *roles.ankles) if j >= 0]
    frames = np.clip(np.rint(np.asarray(times_s) * clip.fps).astype(np.int64), 0, clip.n_frames - 1)
    sk = clip.skeleton
    _, pos = fk(clip.local_rot[frames], clip.root_pos[frames], sk.offsets, sk.parents,
                None if clip.local_pos is None else clip.local_pos[frames])   # the sampled frames only
    root = pos[:, roles.root]
    across = pos[:, roles.hips[0]] - pos[:, roles.hips[1]]
    yaw = np.arctan2(across[:, 2], across[:, 0])       # the hips' line, turned onto +x (Y up)
    c, s = np.cos(yaw), np.sin(yaw)
    rel = pos[:, joints] - root[:, None]
    x = c[:, None] * rel[..., 0] + s[:, None] * rel[..., 2]
    z = -s[:, None] * rel[..., 0] + c[:, None] * rel[..., 2]
    shape = np.stack([x, rel[..., 1], z], axis=-1)
    leg = np.linalg.norm(pos[0, roles.hips[0]] - pos[0, roles.ankles[0]]) or 1.0
    return shape.reshape(len(frames), -1) / leg


def dance_bar_similarity(clip: MotionClip, bar_starts_s, beats_per_bar: int, end_s: float) -> np.ndarray:
    """(bars, bars) cosine similarity of the dance's bars (``body_shapes`` through each, z-scored)."""
    starts = np.asarray(bar_starts_s, dtype=np.float64)
    ends = np.r_[starts[1:], min(end_s, starts[-1] + np.median(np.diff(starts)) if len(starts) > 1 else end_s)]
    n = beats_per_bar * SAMPLES_PER_BEAT
    times = starts[:, None] + (np.arange(n) + 0.5)[None, :] / n * (ends - starts)[:, None]
    shapes = body_shapes(clip, times.ravel())
    shapes = (shapes - shapes.mean(axis=0)) / np.maximum(shapes.std(axis=0), 1e-9)
    v = shapes.reshape(len(starts), -1)
    v = v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-9)
    return v @ v.T


def correlation(music: np.ndarray, dance: np.ndarray) -> float | None:
    """Pearson correlation of two bar similarity matrices over every pair of distinct bars."""
    n = min(len(music), len(dance))
    if n < 3:
        return None
    iu = np.triu_indices(n, 1)
    a, b = music[:n, :n][iu], dance[:n, :n][iu]
    if a.std() < 1e-9 or b.std() < 1e-9:
        return None
    return float(np.corrcoef(a, b)[0, 1])


def shuffled_score(music: np.ndarray, dance: np.ndarray, section_bars, seed: int = 0,
                   shuffles: int = SHUFFLES) -> float | None:
    """Chance: the mean ``correlation`` with the dance's bars shuffled within each section
    (``section_bars``: each section's (first bar, bars))."""
    rng = np.random.default_rng(seed)
    n = min(len(music), len(dance))
    scores = []
    for _ in range(shuffles):
        order = np.arange(n)
        for a, k in section_bars:
            part = order[a:min(a + k, n)]
            order[a:min(a + k, n)] = rng.permutation(part)
        score = correlation(music, dance[np.ix_(order, order)])
        if score is not None:
            scores.append(score)
    return float(np.mean(scores)) if scores else None


def form_score(clip: MotionClip, structure: SongStructure, beats_per_bar: int, seed: int = 0) -> dict:
    """The dance's structure-consistency score against its song's form, with chance beside it."""
    if structure.similarity is None or len(structure.bar_starts_s) < 3:
        return {"form_score": None, "form_chance": None}
    dance = dance_bar_similarity(clip, structure.bar_starts_s, beats_per_bar, clip.n_frames / clip.fps)
    music = structure.similarity
    sections = [(s.first_bar, s.n_bars) for s in structure.sections]
    return {"form_score": correlation(music, dance), "form_chance": shuffled_score(music, dance, sections, seed)}

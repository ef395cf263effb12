"""Move a dance onto a character: rest-pose alignment, matched bone directions, scaled root, planted feet.

For each humanoid bone both rigs have (``humanoid``):
1. *Rest alignment.* The two rest poses need not agree (T-pose vs A-pose, bones whose
   local axes point anywhere, a model facing -Z). The hips' rest frames (left-right axis
   of the upper legs, world up) give the turn between the rigs; each bone then adds the
   swing taking its rest direction onto the source's.
2. *Motion.* A target bone turns by the source bone's rotation away from its rest, after
   that alignment, and is then swung so its segment points exactly where the source's
   segment points at that frame (twist comes from the source's rotation). Bones the
   target has and the source lacks stay at rest relative to their parent.
3. *Root.* The mid-point of the upper legs follows the source's, scaled by the ratio of
   leg lengths and measured from the floor, so root height over the floor keeps its
   proportion to leg length and steps keep their proportion to stride.
4. *Feet.* Each leg is solved by two-bone IK so the ankle lands where the source's ankle
   lands (scaled, never below the target's standing ankle height): the target slides
   no more than the source, relative to its size, and does not sink into the floor.
Everything is batched over frames; a 3-minute dance takes a fraction of a second.
"""

from __future__ import annotations

import numpy as np

from .. import rotations as rot
from ..kinematics import _rotation_between, _unit, fk
from ..types import MotionClip
from .character import Character
from .humanoid import FINGER_BONES, SIDES, find_bones, leg_length, mapped_pairs, segment_ends

UP = np.array([0.0, 1.0, 0.0])
_FINGER_PREVIOUS = {s + f + b: s + f + a for s in SIDES for f, parts in FINGER_BONES.items()
                    for a, b in zip(parts, parts[1:])}
MIN_SEGMENT_M = 0.01      # shorter bone segments have no reliable direction
GROUND_PERCENTILE = 1.0
REACH = 0.998             # IK targets are kept this far inside a leg's full length, where knees still bend ...
REACH_MAX = 0.9999        # ... and a leg is never solved straighter than this
# Frames solved at a time by ``retarget``: its working memory is ~30 kB a frame.
CHUNK_FRAMES = 2048
DROP_SMOOTH_S = 0.15      # the hips sink to let the legs reach over about this long   # the source's ankle height when standing: a low percentile, robust to a glitch


def retarget(clip: MotionClip, character: Character, source_bones: dict[str, int] | None = None, *,
             source_ground: float | None = None, chunk_frames: int = CHUNK_FRAMES) -> MotionClip:
    """``clip`` danced by ``character``: a MotionClip on ``character.skeleton`` with the same frames.

    ``source_ground``: the source's standing ankle height, when known (a stream's segments share
    one, so the floor does not move between them); by default measured on ``clip``.

    Frames are solved ``chunk_frames`` at a time (every step but two is per frame; the floor
    and the hips' drop look at all frames and are computed between the passes), so the memory
    is the result plus a few numbers per frame, however long the dance; the numbers are the
    same as solving all frames at once.
    """
    src_bones = source_bones or find_bones(clip.skeleton, what="the dance's skeleton")
    tgt = character.skeleton
    tgt_bones = character.bones
    pairs = mapped_pairs(src_bones, tgt_bones)
    ends = segment_ends(src_bones, tgt_bones)

    n_j = clip.skeleton.n_joints
    _, p_src_rest = fk(np.tile(rot.IDENTITY, (n_j, 1)), np.zeros(3), clip.skeleton.offsets, clip.skeleton.parents)
    g_tgt_rest, p_tgt_rest = fk(character.rest_rot, character.rest_root, tgt.offsets, tgt.parents)

    ends = {b: e for b, e in ends.items()   # a segment needs a length on both rigs to have a direction
            if min(np.linalg.norm(p_src_rest[src_bones[e]] - p_src_rest[src_bones[b]]),
                   np.linalg.norm(p_tgt_rest[tgt_bones[e]] - p_tgt_rest[tgt_bones[b]])) > MIN_SEGMENT_M}
    align = _rest_alignment(pairs, ends, src_bones, tgt_bones, p_src_rest, p_tgt_rest)

    scale = leg_length(p_tgt_rest, tgt_bones) / leg_length(p_src_rest, src_bones)
    src_ground = _chunked_ground(clip, src_bones, chunk_frames) if source_ground is None else source_ground
    tgt_ground = character.ankle_ground if character.ankle_ground is not None else _ground(p_tgt_rest[None],
                                                                                            tgt_bones)
    n = clip.n_frames
    legs = [tgt_bones[s + "UpperLeg"] for s in SIDES]
    leg_joints = [tgt_bones[s + b] for s in SIDES for b in ("UpperLeg", "LowerLeg", "Foot")]
    g = np.empty((n, tgt.n_joints, 4))             # global rotations, then (in place) the local ones
    root_pos = np.empty((n, 3))
    leg_pos = np.empty((n, len(leg_joints), 3))    # the legs' joints, all the feet need
    ankles = {side: np.empty((n, 3)) for side in SIDES}
    need = np.empty(n)
    for a, b in _chunks(n, chunk_frames):
        g_src, p_src = fk(clip.local_rot[a:b], clip.root_pos[a:b], clip.skeleton.offsets, clip.skeleton.parents,
                          None if clip.local_pos is None else clip.local_pos[a:b])
        g[a:b] = _global_rotations(b - a, character, pairs, ends, src_bones, tgt_bones, align,
                                   g_src, p_src, p_src_rest, g_tgt_rest, p_tgt_rest)
        pos = _positions(g[a:b], np.zeros((b - a, 3)), tgt)
        src_mid = p_src[:, [src_bones[s + "UpperLeg"] for s in SIDES]].mean(axis=1)
        # Translation moves every joint alike: shift the root so the upper legs' mid-point lands where it should.
        root_pos[a:b] = _scaled(src_mid, scale, src_ground, tgt_ground) - pos[:, legs].mean(axis=1)
        pos += root_pos[a:b, None]
        chunk_ankles = {}
        for side in SIDES:
            target = _scaled(p_src[:, src_bones[side + "Foot"]], scale, src_ground, tgt_ground)
            target[:, 1] = np.maximum(target[:, 1], tgt_ground)   # never below the standing ankle height
            ankles[side][a:b] = chunk_ankles[side] = target
        need[a:b] = _reach_need(pos, tgt_bones, chunk_ankles)
        leg_pos[a:b] = pos[:, leg_joints]
    drop = _smooth_drop(need, clip.fps)
    root_pos[:, 1] -= drop
    leg_pos[:, :, 1] -= drop[:, None]
    for a, b in _chunks(n, chunk_frames):
        for i, side in enumerate(SIDES):
            _plant_leg(g[a:b], tgt_bones, side, ankles[side][a:b], *leg_pos[a:b, 3 * i:3 * i + 3].transpose(1, 0, 2))
        chunk = g[a:b]
        local = rot.mul(rot.inv(chunk[:, tgt.parents[1:]]), chunk[:, 1:])
        chunk[:, 1:] = local
    if not (np.isfinite(root_pos).all() and np.isfinite(g).all()):   # never a file full of NaN
        from ..errors import InputError

        raise InputError(f"cannot put the dance on {character.name}: its rig gives no finite pose (degenerate bones?)")
    return MotionClip(tgt, clip.fps, root_pos, g, meta=dict(clip.meta), provenance=clip.provenance)


def _chunks(n: int, size: int):
    """``(start, stop)`` of consecutive blocks of at most ``size`` frames covering ``0..n``."""
    size = max(int(size), 1)
    return [(a, min(a + size, n)) for a in range(0, n, size)]


def _chunked_ground(clip: MotionClip, bones: dict[str, int], chunk_frames: int) -> float:
    """``_ground`` of the clip's positions, the ankles' forward kinematics a chunk of frames at a time."""
    feet = [bones["leftFoot"], bones["rightFoot"]]
    sk = clip.skeleton
    lowest = np.empty(clip.n_frames)
    for a, b in _chunks(clip.n_frames, chunk_frames):
        _, p = fk(clip.local_rot[a:b], clip.root_pos[a:b], sk.offsets, sk.parents,
                  None if clip.local_pos is None else clip.local_pos[a:b], only=feet)
        lowest[a:b] = p[:, feet, 1].min(axis=1)
    return float(np.percentile(lowest, GROUND_PERCENTILE))


def _body_frame(p_rest: np.ndarray, bones: dict[str, int]) -> np.ndarray:
    """A rest pose's body axes as a rotation: x towards the left upper leg, y up, z forward."""
    left = p_rest[bones["leftUpperLeg"]] - p_rest[bones["rightUpperLeg"]]
    left = _unit(left - UP * (left @ UP))
    return np.stack([left, UP, np.cross(left, UP)], axis=1)   # columns are the axes


def _rest_alignment(pairs, ends, src_bones, tgt_bones, p_src_rest, p_tgt_rest) -> dict[str, np.ndarray]:
    """Per bone, the world rotation taking the target's rest onto the source's rest."""
    from scipy.spatial.transform import Rotation

    body = Rotation.from_matrix(_body_frame(p_src_rest, src_bones) @ _body_frame(p_tgt_rest, tgt_bones).T).as_quat()
    align = {}
    for bone, s, t in pairs:
        if bone in ends and bone != "hips":
            e = ends[bone]
            u_t = rot.apply(body, p_tgt_rest[tgt_bones[e]] - p_tgt_rest[t])
            u_s = p_src_rest[src_bones[e]] - p_src_rest[s]
            align[bone] = rot.mul(_rotation_between(u_t, u_s), body)
        else:
            align[bone] = body
    # A bone with no segment of its own (a hand, a foot without toes, the head) keeps the alignment of
    # the bone it hangs from; ``pairs`` is in canonical order, so that bone is already aligned.
    hangs_from = {"Hand": "LowerArm", "Foot": "LowerLeg", "Toes": "Foot"}
    for bone, _, _ in pairs:
        if bone in ends or bone == "hips":
            continue
        if bone == "head":
            above = [b for b in ("neck", "upperChest", "chest", "spine") if b in align]
        elif bone in _FINGER_PREVIOUS:      # a fingertip bone turns as the bone before it
            above = [_FINGER_PREVIOUS[bone]]
        else:
            part = next(k for k in hangs_from if bone.endswith(k)) if bone.endswith(tuple(hangs_from)) else None
            above = [bone[:-len(part)] + hangs_from[part]] if part else []
        align[bone] = next((align[b] for b in above if b in align), body)
    return align


def _global_rotations(n_frames, character, pairs, ends, src_bones, tgt_bones, align,
                      g_src, p_src, p_src_rest, g_tgt_rest, p_tgt_rest) -> np.ndarray:
    tgt = character.skeleton
    by_joint = {t: (bone, s) for bone, s, t in pairs}
    g = np.empty((n_frames, tgt.n_joints, 4))
    for j in range(tgt.n_joints):
        if j not in by_joint:
            parent = g[:, tgt.parents[j]] if j else np.tile(g_tgt_rest[0], (n_frames, 1))
            g[:, j] = rot.mul(parent, character.rest_rot[j]) if j else parent
            continue
        bone, s = by_joint[j]
        # The source's rest is the zero rotation (BVH), so its turn away from rest is its global rotation.
        g[:, j] = rot.mul(g_src[:, s], rot.mul(align[bone], g_tgt_rest[j]))
        if bone in ends and bone != "hips":   # the hips turn with the body; their "segment" may be ~0 long
            e = ends[bone]
            rest_dir = rot.apply(rot.inv(g_tgt_rest[j]), p_tgt_rest[tgt_bones[e]] - p_tgt_rest[j])
            now = rot.apply(g[:, j], rest_dir)
            want = p_src[:, src_bones[e]] - p_src[:, s]
            g[:, j] = rot.mul(_rotation_between(now, want), g[:, j])
    return g


def source_ground(clip: MotionClip, bones: dict[str, int]) -> float:
    """The standing ankle height of ``clip`` (for ``retarget(..., source_ground=)``)."""
    return _chunked_ground(clip, bones, CHUNK_FRAMES)


def _ground(positions: np.ndarray, bones: dict[str, int]) -> float:
    """The ankles' height when standing: a low percentile of the lower ankle over the frames."""
    ankles = positions[:, [bones["leftFoot"], bones["rightFoot"]], 1].min(axis=1)
    return float(np.percentile(ankles, GROUND_PERCENTILE))


def _scaled(points: np.ndarray, scale: float, src_ground: float, tgt_ground: float) -> np.ndarray:
    """Source positions in the target's space: scaled about the floor below the source's ankles."""
    out = points * scale
    out[..., 1] = (points[..., 1] - src_ground) * scale + tgt_ground
    return out


def _positions(g: np.ndarray, root_pos: np.ndarray, skeleton) -> np.ndarray:
    pos = np.empty(g.shape[:2] + (3,))
    pos[:, 0] = root_pos
    for j in range(1, skeleton.n_joints):
        p = skeleton.parents[j]
        pos[:, j] = pos[:, p] + rot.apply(g[:, p], skeleton.offsets[j])
    return pos


def _reach_need(pos, bones, ankles: dict) -> np.ndarray:
    """(F,) how far the root must come down for both legs to reach their ankle targets: a target's
    legs, in proportion, can be a little shorter than the source's where the source stands
    straight-legged."""
    need = np.zeros(len(pos))
    for side, target in ankles.items():
        hip, knee, ankle = (bones[side + b] for b in ("UpperLeg", "LowerLeg", "Foot"))
        reach = REACH * (np.linalg.norm(pos[:, knee] - pos[:, hip], axis=-1)
                         + np.linalg.norm(pos[:, ankle] - pos[:, knee], axis=-1))
        v = target - pos[:, hip]
        across = np.minimum(np.linalg.norm(v[:, [0, 2]], axis=-1), reach)
        need = np.maximum(need, -v[:, 1] - np.sqrt(reach ** 2 - across ** 2))
    return need


def _smooth_drop(need: np.ndarray, fps: float) -> np.ndarray:
    """(F,) how far to lower the root: ``_reach_need`` raised to the frames around each need, then
    smoothed, so the hips sink gently, not in a pop."""
    from scipy.ndimage import gaussian_filter1d, maximum_filter1d

    window = max(1, int(round(DROP_SMOOTH_S * fps)))
    return gaussian_filter1d(maximum_filter1d(np.maximum(need, 0.0), 2 * window + 1), window / 2, mode="nearest")


def _plant_leg(g, bones, side: str, target: np.ndarray, h: np.ndarray, k: np.ndarray, a: np.ndarray) -> None:
    """Two-bone IK of one leg so its ankle reaches ``target`` (F, 3) from hip, knee and ankle at
    ``h``, ``k``, ``a`` (F, 3); turns the upper and lower leg in ``g``. Joints below the knee keep
    their world rotation."""
    hip, knee = bones[side + "UpperLeg"], bones[side + "LowerLeg"]
    l1 = np.linalg.norm(k - h, axis=-1)
    l2 = np.linalg.norm(a - k, axis=-1)
    to_target = target - h
    d = np.clip(np.linalg.norm(to_target, axis=-1), np.abs(l1 - l2) + 1e-6, (l1 + l2) * REACH_MAX)
    axis = _unit(to_target)
    pole = (k - h) - axis * np.sum((k - h) * axis, axis=-1, keepdims=True)   # the knee's current side
    pole = _unit(pole)
    along = (l1 ** 2 - l2 ** 2 + d ** 2) / (2 * d)
    across = np.sqrt(np.maximum(l1 ** 2 - along ** 2, 0.0))
    new_knee = h + axis * along[:, None] + pole * across[:, None]
    new_ankle = h + axis * d[:, None]
    turn_hip = _rotation_between(k - h, new_knee - h)
    g[:, hip] = rot.mul(turn_hip, g[:, hip])
    shin = rot.apply(turn_hip, a - k)
    g[:, knee] = rot.mul(_rotation_between(shin, new_ankle - new_knee), rot.mul(turn_hip, g[:, knee]))

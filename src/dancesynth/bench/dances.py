"""Each engine's dance of a song, and what the structure and realism sections measure on any dance: the
motifs found again in its motion, whether they follow the engine's plan, and its liveliness.
"""

from __future__ import annotations

import time

import numpy as np

from .quality import walk_dance

GENRE = "salsa"   # the genre with dances enough for a motif template (and the neural model's)
MOCAP_FPS = 30.0  # the dances' frame rate: speeds and one-frame steps depend on it


def found_motifs(clip, model, beat_times_s) -> np.ndarray:
    """The motif of every beat interval, found again in the motion: words cut at the beats, re-embedded.

    One id per interval of ``beat_times_s``, so index i is the engine's plan for beat i; -1
    where the interval is not inside the motion (a beat grid extended before the song's start
    or past its end). Cutting at the distinct frames instead merged two such intervals into
    one and shifted every later id by one against the plan.
    """
    from ..motion.words import clip_landmarks, word_features

    frames = np.rint(np.asarray(beat_times_s, dtype=np.float64) * clip.fps).astype(np.int64)
    frames = np.clip(frames, 0, clip.n_frames - 1)
    inside = frames[1:] > frames[:-1]
    ids = np.full(len(inside), -1, dtype=np.int64)
    if inside.any():
        pos, root_rot = clip_landmarks(clip)
        feats = word_features(pos, root_rot, clip.fps, frames[:-1][inside], frames[1:][inside])
        ids[inside] = model.assign(feats.astype(np.float32))
    return ids


def liveliness(clip) -> dict:
    """Hand in head (share of frames), root travel (m/min), p99 joint speed (m/s) and one-frame steps of a motion.

    The speeds are ``motion_metrics``' own (as ``evaluate``'s ``root_travel_m_s`` and
    ``joint_speed_p99_m_s``), from one forward kinematics shared with the head test.
    """
    from ..eval.artefacts import hand_in_head_frames, one_frame_steps
    from ..eval.motion_metrics import joint_speeds, root_travel_speed
    from ..kinematics import clip_fk

    g_rot, g_pos = clip_fk(clip)
    out = {"hand_in_head": hand_in_head_frames(clip, global_rot=g_rot, global_pos=g_pos),  # NaN: no head found
           "root_travel_m_per_min": 60.0 * root_travel_speed(clip),
           "joint_speed_p99": float(np.percentile(joint_speeds(clip, global_pos=g_pos), 99))}
    return {**{k: v if np.isfinite(v) else None for k, v in out.items()},
            "one_frame_steps": int(len(one_frame_steps(clip)))}


def plan_followed(clip, found) -> float | None:
    """Share of planned beats whose motif found again in the motion is the planned one (None: no plan)."""
    motifs = clip.provenance.motifs
    plan = motifs.get("motif_ids", motifs.get("motif_plan"))  # what the engine meant to dance on each beat
    if plan is None:
        return None
    n = min(len(plan), len(found))
    planned = (np.asarray(plan[:n]) >= 0) & (np.asarray(found[:n]) >= 0)  # -1: no plan there / not in the motion
    return float(np.mean(np.asarray(found[:n])[planned] == np.asarray(plan[:n])[planned])) if planned.any() else None


def engine_dances(music, db, seed: int, engines, style: str | None = GENRE, accent_timing: bool = True) -> dict:
    """Each engine's dance of ``music`` in ``style`` (None: the product's choice), with the wall time it took;
    ``accent_timing`` as ``DanceConfig``'s (False: each piece at one rate, on the same path)."""
    from ..api import dance
    from ..engines.graph.engine import EngineConfig
    from ..engines.graph.meta_graph import GraphConfig

    kinds = {"streaming": dict(follow_signature=True, render=EngineConfig(signature_weight=0.0)),  # counts only
             "lookahead": dict(follow_signature=True, render=EngineConfig(signature_weight=0.0), lookahead_s=5.0),
             "signature": dict(follow_signature=True), "global": dict(engine="global"),
             "choreography": dict(engine="choreography"), "neural": dict(engine="neural"),
             "network": dict(engine="neural", restore_spread=False),   # without the spread post-filter
             "paper": dict(graph=GraphConfig.paper(), render=EngineConfig.paper())}  # Xu et al. as printed
    out = {}
    for name in engines:
        t = time.perf_counter()
        if name == "random_walk":
            ref = out.get("streaming") or dance(music, database=db, style=style, seed=seed)
            clip = walk_dance(db.styles[ref.provenance.style], music, subdivide=ref.provenance.summary["subdivide"],
                              seed=seed, fps=ref.fps, accent_timing=accent_timing)
        elif name in kinds:
            clip = dance(music, database=db, style=style, seed=seed, accent_timing=accent_timing, **kinds[name])
        else:
            continue
        out[name] = clip
        clip.meta.setdefault("bench_wall_s", time.perf_counter() - t)
    return out


def same_path(a, b) -> bool:
    """Whether two dances walk the same path: the same style, jumps at the same times and the same source
    frame on every beat (what ``accent_timing`` must leave alone)."""
    pa, pb = a.provenance, b.provenance
    if pa.style != pb.style or not np.array_equal(pa.transition_times_s, pb.transition_times_s):
        return False
    if pa.source_frames is None or pb.source_frames is None or len(pa.source_frames) != len(pb.source_frames):
        return pa.source_frames is None and pb.source_frames is None
    beats = np.asarray(pa.grid_times_s, dtype=np.float64)
    frames = np.clip(np.rint(beats * a.fps).astype(np.int64), 0, len(pa.source_frames) - 1)
    # Within 2 source frames: a beat falls between the dance's frames, where the two timings differ a little.
    return bool(np.allclose(np.asarray(pa.source_frames)[frames], np.asarray(pb.source_frames)[frames], atol=2.0))

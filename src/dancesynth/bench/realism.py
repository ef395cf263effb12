"""Realism and diversity against held-out mocap: FID_k, FID_g, Div_k, Div_g of every mocap engine.

For one style (the largest unless configured), each seed holds ``realism_fraction`` of its
clips out (``realism.held_out_split``; the two dancers of a take go out together) and
scores, against those held-out clips (``realism.realism_scores``: windows of
``realism_window_s`` seconds every half window, features normalised by the held-out
windows):

- ``mocap``: the style's remaining clips themselves -- the floor: real motion of the
  same style that is not the reference;
- ``frozen``: the middle pose of the first remaining clip held still for each song's
  length -- the ceiling no dance should come near;
- every mocap engine (``bench.dances.engine_dances``: streaming, streaming +
  signature, global DP, choreography mixer, random walk) with the product defaults on
  every configured song, given a database that holds only the reduced style: the
  dances, their graphs and the motif model they plan with are made from the remaining
  clips and never see the held-out ones. The neural engine is left out: its shipped
  model was trained on every salsa clip, held-out ones included.

The seed picks the split and is also the dances' seed. Means over seeds; each seed's
numbers in ``seeds``. The numbers are not comparable with AIST++ tables.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .common import MUSIC_DIR, BenchConfig, Progress, largest_style, load_song, table
from ..types import MotionClip
from ..errors import InputError

ENGINES = ("streaming", "signature", "global", "choreography", "random_walk")
TITLES = {"mocap": "remaining mocap (floor)", "frozen": "frozen pose", "streaming": "streaming (Xu)",
          "signature": "streaming + signature", "global": "global DP", "choreography": "choreography mixer",
          "random_walk": "random walk"}
METRICS = ("fid_k", "fid_g", "div_k", "div_g", "n_generated")
REFERENCE_KEYS = ("div_k_ref", "div_g_ref", "n_reference")
NOTE = ("not comparable with AIST++ tables: other skeletons (SMPL joints found by name, the rest left out), other "
        "data, windows instead of whole sequences, features normalised by the held-out windows; FID from few "
        "windows is biased upwards, so compare rows of one table only")


def frozen_pose(clip: MotionClip, duration_s: float, fps: float) -> MotionClip:
    """The middle pose of ``clip`` held still for ``duration_s`` seconds at ``fps``."""
    n, mid = int(np.floor(duration_s * fps + 1e-6)) + 1, clip.n_frames // 2
    return MotionClip(clip.skeleton, fps, np.repeat(clip.root_pos[mid:mid + 1], n, axis=0),
                      np.repeat(clip.local_rot[mid:mid + 1], n, axis=0))


def _songs(cfg: BenchConfig) -> list[tuple[str, object]]:
    names = cfg.realism_songs or tuple(sorted(p.name for p in MUSIC_DIR.glob("*.ogg")))
    songs = [(Path(name).name, load_song(name, cfg.realism_max_s)) for name in names]
    songs = [(name, music) for name, music in songs if music.duration_s >= cfg.realism_min_s]
    if not songs:
        raise InputError(f"no song of the realism section lasts {cfg.realism_min_s:g} s or more: "
                         "configure longer songs (realism_songs) or a lower realism_min_s")
    return songs


def realism_section(cfg: BenchConfig, db, progress: Progress | None = None) -> dict:
    """FID_k, FID_g, Div_k, Div_g of the mocap floor, a frozen pose and each engine against held-out mocap."""
    from ..motion.database import MotionDatabase
    from .dances import engine_dances
    from ..eval.realism import held_out_split, realism_scores

    unknown = set(cfg.realism_engines) - set(ENGINES)
    if unknown:
        raise InputError(f"realism_engines {sorted(unknown)}: use mocap engines only ({', '.join(ENGINES)})")
    if cfg.realism_seeds < 1:
        raise InputError(f"realism_seeds = {cfg.realism_seeds}: score at least one held-out split")
    style = db.styles[cfg.realism_style] if cfg.realism_style else largest_style(db)
    songs = _songs(cfg)
    engines = tuple(e for e in ENGINES if e in cfg.realism_engines)
    rows = ("mocap", "frozen", *engines)
    per_seed = []
    for seed in range(cfg.realism_seeds):
        t0 = time.perf_counter()
        reduced, held = held_out_split(style, fraction=cfg.realism_fraction, seed=seed)
        rest = [reduced.clip(i) for i in range(reduced.n_clips)]
        only = MotionDatabase({reduced.name: reduced})
        generated = {row: [] for row in rows}
        generated["mocap"] = rest
        for i, (name, music) in enumerate(songs):
            if progress:
                progress(f"realism: seed {seed}, {name} ({i + 1}/{len(songs)})")
            dances = engine_dances(music, only, seed, engines, style=reduced.name)
            for engine, clip in dances.items():
                generated[engine].append(clip)
            fps = next(iter(dances.values())).fps if dances else 30.0
            generated["frozen"].append(frozen_pose(rest[0], music.duration_s, fps))
        t1 = time.perf_counter()
        if progress:
            progress(f"realism: seed {seed}, scoring {len(rows)} rows against {len(held)} held-out clips")
        scores = realism_scores(generated, held, window_s=cfg.realism_window_s)
        per_seed.append({
            "seed": seed, "held_out": [c.meta.get("name", "?") for c in held], "remaining_clips": reduced.n_clips,
            "held_out_s": float(sum(c.duration_s for c in held)), "remaining_s": float(reduced.duration_s),
            "scores": scores, "timings_s": {"dances": t1 - t0, "metrics": time.perf_counter() - t1}})
    first = per_seed[0]["scores"]["mocap"]
    return {"style": style.name, "clips": style.n_clips, "skeleton_joints": style.skeleton.n_joints,
            "smpl_joints": first["joints"], "dim_k": first["dim_k"], "dim_g": first["dim_g"],
            "window_s": first["window_s"], "stride_s": first["stride_s"], "normalise": first["normalise"],
            "geometric_min_std": first["geometric_min_std"], "fraction": cfg.realism_fraction,
            "songs": [{"song": n, "duration_s": m.duration_s, "tempo_bpm": m.tempo_bpm} for n, m in songs],
            "rows": list(rows),
            "mean": {row: {k: float(np.mean([s["scores"][row][k] for s in per_seed])) for k in METRICS}
                     for row in rows},
            "reference": {k: float(np.mean([s["scores"]["mocap"][k] for s in per_seed])) for k in REFERENCE_KEYS},
            "seeds": per_seed, "note": NOTE}


def _table(title: str, rows: list[str], scores: dict, reference: dict) -> str:
    body = [[TITLES[row]] + [scores[row][k] for k in METRICS] for row in rows]
    body.append(["held-out mocap (reference)", None, None] + [reference[k] for k in REFERENCE_KEYS])
    return table(title, ["generated", "FID_k", "FID_g", "Div_k", "Div_g", "windows"], body, [0, 1, 1, 2, 2, 0])


def format_realism(s: dict, *, per_seed: bool = False) -> str:
    """The mean table (and with ``per_seed`` one table per held-out split), with its notes."""
    seeds = [x["seed"] for x in s["seeds"]]
    out = [_table(f"Realism vs held-out mocap, style {s['style']} ({s['clips']} clips, {s['skeleton_joints']} "
                  f"joints -> {len(s['smpl_joints'])} SMPL joints, {s['dim_k']}-d kinetic, {s['dim_g']}-d "
                  f"geometric), {s['fraction']:.0%} held out, mean over {len(seeds)} split(s)",
                  s["rows"], s["mean"], s["reference"])]
    if per_seed:
        for x in s["seeds"]:
            out.append(_table(f"seed {x['seed']}: held out {', '.join(x['held_out'])} ({x['held_out_s']:.0f} s); "
                              f"{x['remaining_clips']} clips ({x['remaining_s']:.0f} s) remain", s["rows"],
                              x["scores"], x["scores"]["mocap"]))
    songs = "; ".join(f"{x['song']} ({x['duration_s']:.0f} s)" for x in s["songs"])
    notes = [f"dances on {len(s['songs'])} song(s): {songs}; frozen pose: one pose of the remaining mocap held still",
             f"windows of {s['window_s']:g} s every {s['stride_s']:g} s, features normalised by the held-out windows "
             f"({s['normalise']}; geometric scales at least {s['geometric_min_std']:g}); lower FID is better, Div "
             "should be near the held-out mocap's own",
             s["note"]]
    return "\n\n".join(out) + "\n" + "\n".join(f"  {n}" for n in notes)

"""A neural model's realism, plan-following and liveliness in about a minute: for comparing trained variants.

    .venv/bin/python benchmarks/neural_quick.py [--model PATH] [--seeds 5] [--json OUT]

Dances the 4 bundled songs longer than 20 s with ``--seeds`` seeds each, on the salsa
database without the take the model held out, and prints for the neural engine with and
without its spread post-filter, beside the streaming engine on the same songs and seeds:
FID_k, FID_g and Div_k against that held-out take; the share of beats whose motif found
again is the planned one; chi2 to the salsa template; hand in head, root travel, p99 joint
speed, one-frame steps; the mean kinetic energy and acceleration over joints; and the
geometric relations that separate the generated motion from the mocap most.
Section 6 of ``dancesynth bench`` (``benchmarks/neural_bench.py``) is the full measurement.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", type=Path, default=None, help="weights to measure (default: the shipped model)")
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)

    from dancesynth.api import analyse, dance
    from dancesynth.bench.common import MUSIC_DIR
    from dancesynth.bench.dances import GENRE, found_motifs, liveliness, plan_followed
    from dancesynth.bench.structure import _chi2_ids, held_out_database
    from dancesynth.engines.neural.store import find_model, load_model
    from dancesynth.eval.realism import realism_scores, window_features
    from dancesynth.eval.realism_features import GEOMETRIC_FEATURES
    from dancesynth.motion.database import open_database
    from dancesynth.motion.motifs import load_motif_model

    model_path = args.model or find_model(GENRE)
    held = set(load_model(model_path).info.get("held_out_clips") or ())
    db = open_database()
    only, reference = held_out_database(db, held)
    if not reference:
        print(f"the model names no held-out clip of this database ({sorted(held)})", file=sys.stderr)
        return 1
    songs = [m for m in (analyse(p) for p in sorted(MUSIC_DIR.glob("*.ogg"))) if m.duration_s >= 20.0]
    dances = {"streaming": [], "neural": [], "network alone": []}
    for music in songs:
        for seed in range(args.seeds):
            dances["streaming"].append(dance(music, database=only, style=GENRE, seed=seed))
            dances["neural"].append(dance(music, database=only, style=GENRE, seed=seed, model=str(model_path)))
            dances["network alone"].append(dance(music, database=only, style=GENRE, seed=seed, model=str(model_path),
                                                 restore_spread=False))
    scores = realism_scores(dances, reference)
    motifs = load_motif_model(db)
    kin, geo = {}, {}
    for name, clips in (("held-out take", reference), *dances.items()):
        k, g, _ = window_features(clips)
        k = k.reshape(len(k), -1, 3).mean(axis=1)                  # over joints: KE_h, KE_v, EE
        kin[name], geo[name] = k.mean(axis=0), g.mean(axis=0)
    result = {"model": str(model_path), "songs": len(songs), "seeds": args.seeds, "engines": {}}
    for name, clips in dances.items():
        rows = []
        for clip in clips:
            found = found_motifs(clip, motifs, clip.provenance.grid_times_s)
            rows.append({"plan_followed": plan_followed(clip, found),
                         "chi2": _chi2_ids(motifs, motifs.templates[GENRE], found), **liveliness(clip)})
        mean = {k: float(np.mean([r[k] for r in rows if r[k] is not None])) if any(r[k] is not None for r in rows)
                else None for k in rows[0]}
        result["engines"][name] = {**{k: scores[name][k] for k in ("fid_k", "fid_g", "div_k", "div_g")}, **mean,
                                   "kinetic_energy_h": float(kin[name][0]), "acceleration": float(kin[name][2])}
    gap = np.argsort(-np.abs(geo["neural"] - geo["held-out take"]))[:8]
    result["geometric"] = {GEOMETRIC_FEATURES[f][0]: {n: float(v[f]) for n, v in geo.items()} for f in gap}
    result["reference_kinetic"] = {"kinetic_energy_h": float(kin["held-out take"][0]),
                                   "acceleration": float(kin["held-out take"][2])}

    columns = {"fid_k": "FID_k", "fid_g": "FID_g", "div_k": "Div_k", "plan_followed": "plan", "chi2": "chi2",
               "hand_in_head": "hand in head", "root_travel_m_per_min": "root m/min", "joint_speed_p99": "p99 m/s",
               "one_frame_steps": "1-fr. steps", "kinetic_energy_h": "KE_h m2/s2", "acceleration": "accel m/s2"}
    keys = tuple(columns)
    print(f"{model_path} on {len(songs)} songs x {args.seeds} seeds, against {', '.join(sorted(held))}")
    print(f"{'':24s}" + "".join(f"{columns[k]:>13s}" for k in keys))
    for name, r in result["engines"].items():
        print(f"{name:24s}" + "".join(f"{'-' if r[k] is None else format(r[k], '.3g'):>13s}" for k in keys))
    ref = result["reference_kinetic"]
    print(f"{'held-out take':24s}" + " " * 13 * 9 + f"{ref['kinetic_energy_h']:>13.3g}{ref['acceleration']:>13.3g}")
    print("\nshare of frames (geometric relations furthest from the held-out take)")
    for rel, v in result["geometric"].items():
        print(f"  {rel:28s} held out {v['held-out take']:.2f}  streaming {v['streaming']:.2f}  neural {v['neural']:.2f}")
    if args.json:
        args.json.write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

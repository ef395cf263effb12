"""Train the shipped neural model and measure it (the numbers of docs/neural.md).

    .venv/bin/python scripts/train_neural.py                      # train small on salsa (25 min), then evaluate
    .venv/bin/python scripts/train_neural.py --eval-only [--model PATH] [--seeds 3]

Training writes ``src/dancesynth/data/models/neural/salsa.pt`` (+ .json). Evaluation
dances every bundled song with a few seeds and reports, per dance and on average:
inference speed (x real time), chi2 of the dance's motif signature to the salsa
template and the share of beats whose motif is the planned one (words cut at the
beats it dances to, as the benchmark's Table I), and the beat-alignment metrics of
``dancesynth eval``; the raw salsa mocap clips are measured as in Table I (their own
beats, leave-one-out template). Results go to ``--json``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SONGS = sorted((ROOT / "src/dancesynth/data/music").glob("*.ogg"))
KEYS = ("bas_music", "hit_rate", "aligned_beat_ratio", "kinematic_beat_ratio", "intensity_spearman",
        "jump_p99_vs_mocap", "jerk_vs_mocap", "foot_skate_m_s", "ground_penetration_m")


def evaluate_model(seeds: int) -> dict:
    from dancesynth.api import analyse, dance
    from dancesynth.bench.structure import found_motifs, mocap_chi2
    from dancesynth.eval.evaluate import evaluate, mocap_reference
    from dancesynth.motion.database import open_database
    from dancesynth.motion.motifs import chi2, load_motif_model

    db = open_database()
    motifs = load_motif_model()
    template = motifs.templates["salsa"]
    rows = []
    refs = {}
    for song in SONGS:
        music = analyse(song)
        for seed in range(seeds):
            t = time.perf_counter()
            clip = dance(music, engine="neural", style="salsa", seed=seed)
            wall = time.perf_counter() - t
            style = db.styles[clip.provenance.style]
            if style.name not in refs:
                refs[style.name] = mocap_reference([style.clip(c) for c in range(style.n_clips)], clip.fps)
            m = evaluate(clip, music_beats_s=music.beat_times_s, music_loudness_db=music.intensity_db,
                         mocap=refs[style.name])
            # As the benchmark's Table I: words cut at the beats it dances to, found again in the motion.
            found = found_motifs(clip, motifs, clip.provenance.grid_times_s)
            plan = clip.provenance.motifs["motif_plan"][:len(found)]
            rows.append({"song": song.name, "seed": seed, "style": style.name, "duration_s": music.duration_s,
                         "synthesis_s": clip.provenance.summary["timings_s"]["synthesis_s"], "dance_s": wall,
                         "realtime_x": clip.provenance.summary["realtime_factor"],
                         "chi2_salsa": chi2(template, np.bincount(found, minlength=motifs.k)),
                         "plan_followed": float(np.mean(found == plan)), **{k: m[k] for k in KEYS}})
            print(json.dumps(rows[-1]), file=sys.stderr)
    mocap = [r["chi2"] for r in mocap_chi2(db, motifs)]
    mean = {k: float(np.mean([r[k] for r in rows if r[k] is not None]))
            for k in ("realtime_x", "chi2_salsa", "plan_followed", *KEYS)}
    return {"dances": rows, "mean": mean, "mocap_chi2_salsa_mean": float(np.mean(mocap)),
            "mocap_chi2_salsa_per_clip": mocap}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, default=25.0)
    ap.add_argument("--config", default="small")
    ap.add_argument("--eval-only", action="store_true")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--json", type=Path, default=Path("neural-eval.json"))
    args = ap.parse_args()
    if not args.eval_only:
        from dancesynth.engines.neural.store import SHIPPED
        from dancesynth.engines.neural.train import train

        info = train("salsa", args.config, minutes=args.minutes, out=SHIPPED)
        print(json.dumps({k: v for k, v in info.items() if k != "curve"}, indent=1))
    result = evaluate_model(args.seeds)
    args.json.write_text(json.dumps(result, indent=1))
    print(json.dumps(result["mean"], indent=1))
    print(f"mocap chi2 to the salsa template (mean over clips): {result['mocap_chi2_salsa_mean']:.3f}")


if __name__ == "__main__":
    main()

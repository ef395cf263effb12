"""How much of a long dance replays the last minute: the product beside its baselines.

    python benchmarks/replay_baselines.py [--split test|tune] [--count 10]
                                          [--out benchmarks/results/replay_baselines.json]

On the generated 3-minute songs of a split (``bench.vocabulary.long_specs``; ``test`` is what is
reported, no constant was chosen on it), each song is danced in the style the product chooses by

- the product (the streaming engine with its defaults),
- Xu et al.'s objective and graph as printed (``--paper``),
- a random walk on the same graph (``bench.quality.walk_dance``, seed 0): no memory, no objective,
- the raw mocap: the style's longest captured take looped beat for beat, what fast songs were
  danced with before issue 30 (a take played once replays nothing, by construction).

Each number is ``eval.repetition``'s: the share of music beats replaying a source beat danced in the
previous 60 s. Replay has no chance level; the random walk is the reference.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
ROWS = (("product", "product (streaming, defaults)"), ("paper", "Xu et al. as printed (--paper)"),
        ("random_walk", "random walk, same graph"), ("take_looped", "raw mocap: longest take looped"))


def looped_take(style, beat_times_s) -> float:
    """The replayed share of the style's longest take played beat for beat, looped to fill the song."""
    from dancesynth.eval.repetition import repetition

    c = int(np.argmax(np.diff(style.clip_starts)))
    first, end = style.clip_starts[c], style.clip_starts[c + 1]
    beats = np.count_nonzero((style.beat_frames >= first) & (style.beat_frames < end))
    ids = [("take", i % max(beats, 1)) for i in range(len(beat_times_s))]
    return repetition(ids, beat_times_s)["replayed_share"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--split", choices=("test", "tune"), default="test", help="which long songs to dance")
    ap.add_argument("--count", type=int, default=10, help="how many of the split's songs (at most 10)")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "replay_baselines.json")
    args = ap.parse_args()
    from dancesynth.api import dance, with_repetition
    from dancesynth.bench.accents import _songs
    from dancesynth.bench.common import BenchConfig, table
    from dancesynth.bench.quality import walk_dance
    from dancesynth.bench.vocabulary import long_specs
    from dancesynth.engines.graph.engine import EngineConfig
    from dancesynth.engines.graph.meta_graph import GraphConfig
    from dancesynth.motion.database import open_database

    t0 = time.perf_counter()
    cfg = replace(BenchConfig.quick(), accent_songs=(),
                  groundtruth_specs=tuple(long_specs(args.split, args.count, 180.0)))
    songs = [s for s in _songs(cfg, lambda m: print(m, file=sys.stderr)) if s["set"] == "generated"]
    db = open_database()
    rows = []
    for song in songs:
        music = song["music"]
        product = dance(music, database=db)
        style = product.provenance.style
        paper = dance(music, database=db, style=style, graph=GraphConfig.paper(), render=EngineConfig.paper())
        walk = walk_dance(db.styles[style], music, subdivide=product.provenance.summary["subdivide"], seed=0,
                          fps=product.fps)
        rows.append({"song": song["name"], "style": style, "tempo_bpm": round(music.tempo_bpm, 1),
                     "product": product.provenance.summary["repetition"]["replayed_share"],
                     "paper": paper.provenance.summary["repetition"]["replayed_share"],
                     "random_walk": with_repetition(walk.provenance, db, music, product.fps)
                     .summary["repetition"]["replayed_share"],
                     "take_looped": looped_take(db.styles[style], music.beat_times_s)})
        print(f"{song['name']}: " + ", ".join(f"{k} {rows[-1][k]:.3f}" for k, _ in ROWS), file=sys.stderr)
    summary = {k: {"mean": float(np.mean([r[k] for r in rows])), "max": float(np.max([r[k] for r in rows]))}
               for k, _ in ROWS}
    print(table(f"Replayed share of beats (previous 60 s), {len(rows)} generated 3-minute songs, {args.split} split",
                ["dance", "mean", "worst song"], [[title, summary[k]["mean"], summary[k]["max"]] for k, title in ROWS],
                [0, 3, 3], notes=["no chance level: the random walk is the reference; a take played once replays "
                                  "nothing, so the raw mocap is shown looped"]))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"split": args.split, "songs": rows, "summary": summary,
                                    "wall_s": time.perf_counter() - t0}, indent=1))
    print(f"wrote {args.out} ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

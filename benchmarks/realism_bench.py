"""FID_k / FID_g / Div_k / Div_g of our dances against mocap held out of the database.

    .venv/bin/python benchmarks/realism_bench.py [--seeds 3] [--window-s 5] [--out benchmarks/results]

A thin wrapper around the ``realism`` section of ``dancesynth bench``
(``dancesynth.bench.realism.realism_section``, full settings: the largest style,
20 % of its clips held out per seed, every bundled song of at least 20 s, every mocap
engine, the mocap floor and a frozen pose). What it adds to the bench: the section
alone, its own number of held-out splits and window, one table per split, and
``realism_bench.json``. The numbers are not comparable with AIST++ tables (other
skeletons, joints, data, windows; see docs/metrics.md).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
from dataclasses import replace
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=3, help="held-out splits to average over (seeds 0 .. N-1)")
    ap.add_argument("--window-s", type=float, default=5.0, help="window length in seconds (stride: half of it)")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(REPO / "src"))
    from dancesynth.bench.common import BenchConfig
    from dancesynth.bench.realism import format_realism, realism_section
    from dancesynth.motion.database import open_database

    cfg = replace(BenchConfig.full(), sections=("realism",), realism_seeds=args.seeds,
                  realism_window_s=args.window_s)
    result = realism_section(cfg, open_database(), lambda m: print(m, file=sys.stderr, flush=True))
    result["machine"] = {"python": platform.python_version(), "platform": platform.platform()}
    print(format_realism(result, per_seed=True))
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "realism_bench.json"
    path.write_text(json.dumps(result, indent=1))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

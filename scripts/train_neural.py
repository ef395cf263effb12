"""Train the shipped neural model into the package, then measure it against issue 16's targets.

    .venv/bin/python scripts/train_neural.py                 # train small on salsa (about 7 min on 2 cores), then measure
    .venv/bin/python scripts/train_neural.py --eval-only     # measure the shipped weights only

Training writes ``src/dancesynth/data/models/neural/salsa.pt`` (+ ``.json``, ``.png``);
``dancesynth train --out DIR`` does the same anywhere else. The same config, data and
seed give the same weights on one machine. Measuring is ``benchmarks/neural_bench.py``
(section 6 of the bench on the bundled and generated songs, and the inference speed).
"""

from __future__ import annotations

import argparse
import json
import runpy
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default="small")
    ap.add_argument("--steps", type=int, default=None, help="training steps (default: the config's)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--eval-only", action="store_true")
    args = ap.parse_args()
    if not args.eval_only:
        from dancesynth.engines.neural.store import SHIPPED
        from dancesynth.engines.neural.train import train

        info = train("salsa", args.config, steps=args.steps, seed=args.seed, out=SHIPPED)
        print(json.dumps({k: v for k, v in info.items() if k not in ("curve", "config")}, indent=1))
    sys.argv = [str(ROOT / "benchmarks" / "neural_bench.py")]
    runpy.run_path(sys.argv[0], run_name="__main__")
    return 0


if __name__ == "__main__":
    sys.exit(main())

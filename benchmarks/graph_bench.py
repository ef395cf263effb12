"""Run the package benchmark (``dancesynth.bench.run``) and print its tables.

    python benchmarks/graph_bench.py [--quick] [--out benchmarks/results]

A thin wrapper kept for old instructions: ``dancesynth bench`` does the same. The
tables: Xu et al. Fig. 4 (time per segment, fit on D*N*P*L), growth with the database
replicated 1x-10x (time, peak memory), the bundled graphs and a 3-minute song end to
end, the quality table on the bundled music, and beat tracking on generated songs.
Writes ``bench.json`` into the output folder.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="the quick benchmark (under two minutes)")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(REPO / "src"))
    from dancesynth.bench.run import format_bench, run_bench

    result = run_bench(quick=args.quick, out_dir=args.out, progress=lambda m: print(m, file=sys.stderr, flush=True))
    print(format_bench(result))
    print(f"wrote {args.out / 'bench.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

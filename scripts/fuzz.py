"""Fuzz every parser and decoder dancesynth owns and print a table of outcomes.

    python scripts/fuzz.py [--cases N] [--seed S] [--targets bvh,audio,...] [--json PATH]

Each target (tests/fuzz/*_target.py) makes N deterministic cases for the seed
and runs them in a child process watched for hangs (> 10 s) and memory (> 2 GB).
Failing inputs are saved beside the JSON (in fuzz-failures/) to replay them.
dancesynth is imported as Python finds it: PYTHONPATH=/some/src fuzzes that tree.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from fuzz.harness import TARGETS, failure_lines, run_target, table  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=int, default=10_000, help="cases per target (default 10000)")
    ap.add_argument("--cases-for", default="", help="per-target counts, e.g. cli=300,web=2000")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--targets", default=",".join(TARGETS), help=f"comma-separated, of {','.join(TARGETS)}")
    ap.add_argument("--json", type=Path, default=REPO / "benchmarks" / "results" / "fuzz.json")
    ap.add_argument("--workdir", type=Path, default=None, help="seeds and scratch (default: a temporary folder)")
    args = ap.parse_args(argv)
    names = [t.strip() for t in args.targets.split(",") if t.strip()]
    unknown = [t for t in names if t not in TARGETS]
    if unknown:
        ap.error(f"unknown target(s) {', '.join(unknown)}; choose from {', '.join(TARGETS)}")
    counts = {k: int(v) for k, _, v in (x.partition("=") for x in args.cases_for.split(",") if x)}

    import dancesynth

    print(f"dancesynth from {Path(dancesynth.__file__).parent}, seed {args.seed}", flush=True)
    failures_dir = args.json.parent / "fuzz-failures"
    results = []
    with tempfile.TemporaryDirectory(prefix="dancesynth-fuzz-") as tmp:
        workdir = args.workdir or Path(tmp)
        for name in names:
            n = counts.get(name, args.cases)
            t0 = time.monotonic()
            try:
                result = run_target(name, n, args.seed, workdir / name, failures_dir=failures_dir)
            except Exception as exc:  # a target this source tree cannot run (an API it lacks)
                import traceback

                where = traceback.extract_tb(exc.__traceback__)[-1]
                print(f"{name}: n/a ({type(exc).__name__}: {exc} at {where.filename}:{where.lineno})", flush=True)
                continue
            print(f"{name}: {result.cases} cases in {time.monotonic() - t0:.0f} s", flush=True)
            results.append(result)
    print()
    print(table(results))
    lines = failure_lines(results)
    print("\nFailures (deduplicated):\n" + (lines or "none"))
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"seed": args.seed, "dancesynth": str(Path(dancesynth.__file__).parent),
                                     "targets": [r.as_json() for r in results]}, indent=1) + "\n")
    print(f"\nwrote {args.json}")
    return 1 if any(r.failures for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())

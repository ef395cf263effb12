"""What the database can dance, before and after issue 30: ``dancesynth bench`` section 9 with the old database's
minutes per genre beside it.

    python benchmarks/vocabulary_bench.py [--before REV] [--quick] [--split test|tune]
                                          [--out benchmarks/results/vocabulary_bench.json]

``--split tune`` dances the tuning songs (the ones the repeat penalty, foot-slide and jump costs and the
easing limit were chosen on) instead of the reported test songs. The tables are those of
``dancesynth.bench.vocabulary``; the JSON has every number per song.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BEFORE = "7f6caad"   # main before issue 30 (the database with jpop, without G1 Moves)


def before_rows(rev: str) -> list[dict]:
    from dancesynth.motion.catalog import list_styles

    with tempfile.TemporaryDirectory() as tmp:
        tar = subprocess.run(["git", "-C", str(REPO), "archive", rev, "src/dancesynth/data/database"],
                             capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", tmp], input=tar, check=True)
        return list_styles(Path(tmp) / "src/dancesynth/data/database")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--before", default=BEFORE, help="git revision of the database to compare with")
    ap.add_argument("--quick", action="store_true", help="the quick generated set and 4 long songs")
    ap.add_argument("--split", choices=("test", "tune"), default="test", help="which long songs to dance")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "vocabulary_bench.json")
    args = ap.parse_args()
    from dancesynth.bench.common import BenchConfig
    from dancesynth.bench.vocabulary import format_vocabulary, genre_minutes, totals, vocabulary
    from dancesynth.io.files import jsonable
    from dancesynth.motion.database import open_database

    t0 = time.perf_counter()
    cfg = replace(BenchConfig.quick() if args.quick else BenchConfig.full(), vocabulary_split=args.split)
    res = vocabulary(cfg, open_database(), lambda m: print(m, file=sys.stderr))
    rows = before_rows(args.before)
    genres = genre_minutes(rows)
    res["before"] = {"revision": args.before, "genres": genres, "totals": totals(genres, rows)}
    res["wall_s"] = time.perf_counter() - t0
    print(format_vocabulary(res, res["before"]))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(jsonable(res), indent=1))
    print(f"wrote {args.out} ({res['wall_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Loading a character takes time linear in its file: the mannequin .glb with extra nodes added as
long chains (up to the 256-deep limit) or as many short ones, timed per kB.

    python benchmarks/character_load.py [--json benchmarks/results/character_load.json]
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

from fuzz.character_target import glb_container, make_seeds, split_glb  # noqa: E402


def with_nodes(seed: bytes, count: int, chain: int) -> bytes:
    """The model with ``count`` extra skin joints hung below its first node in chains ``chain`` deep."""
    doc, blob = split_glb(seed)
    first = len(doc["nodes"])
    for k in range(count):
        below = [first + k + 1] if (k + 1) % chain else []
        doc["nodes"].append({"name": f"x{k}", "translation": [0, 0.001, 0], "children": below})
    doc["nodes"][0].setdefault("children", []).extend(range(first, first + count, chain))
    return glb_container(doc, blob)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path, default=REPO / "benchmarks" / "results" / "character_load.json")
    args = ap.parse_args()
    from dancesynth.errors import InputError
    from dancesynth.retarget.character import load_character

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        make_seeds(tmp / "seeds")
        seed = (tmp / "seeds" / "model.glb").read_bytes()
        print(f"{'extra nodes':>11} {'chain':>6} {'kB':>7} {'load s':>7} {'ms per kB':>9}  outcome")
        for count, chain in [(0, 1), (2_500, 250), (5_000, 250), (10_000, 250), (20_000, 250), (40_000, 250),
                             (10_000, 1), (40_000, 1), (10_000, 5_000)]:
            path = tmp / f"m{count}_{chain}.glb"
            path.write_bytes(with_nodes(seed, count, chain))
            t0 = time.perf_counter()
            try:
                load_character(path)
                outcome = "loaded"
            except InputError as err:
                outcome = "error: " + str(err)[:60]
            took = time.perf_counter() - t0
            kb = path.stat().st_size / 1024
            rows.append({"extra_nodes": count, "chain": chain, "kB": round(kb, 1), "load_s": round(took, 3),
                         "ms_per_kB": round(1000 * took / kb, 3), "outcome": outcome})
            print(f"{count:>11} {chain:>6} {kb:>7.0f} {took:>7.3f} {1000 * took / kb:>9.3f}  {outcome}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(rows, indent=1) + "\n")
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

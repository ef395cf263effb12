"""What one 5 s streaming segment costs, phase by phase, and the search on a 10x database.

    .venv/bin/python benchmarks/segment_speed.py [--repeats 7] [--times 10] [--out benchmarks/results]

On the largest bundled style and the README's song (as in ``dancesynth bench``'s Fig. 4), the
whole song is danced in 5 s segments ``--repeats`` times, each time with a fresh engine:

- search: the per-segment DP (Xu et al. eq. 7-9);
- stitch: beat pieces to frames (time warp, placement, inertialized blends);
- foot lock: planted feet held by leg IK;
- step: one whole ``GraphEngine.step``, the three and its bookkeeping (the issue's target: <= 8 ms);
- BVH text: ``format_bvh`` of the segment's frames (on the style's own skeleton);
- total: step + BVH text.

Per segment the fastest repeat counts (each phase on its own, so the phases need not add
up to the step); the table gives the median and the slowest segment, and the CPU time per
segment of the fastest whole repeat (the machine may be shared: CPU time says where the
work went, and the load average is recorded). The last row is the search alone with the
largest style replicated ``--times`` x (the issue's target: < 20 ms; its graph is built once,
about a minute, then reloaded from the cache). Prints the table and writes
``segment_speed.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=7, help="dances of the whole song per measurement")
    ap.add_argument("--times", type=int, default=10, help="database replication for the last row (0: skip it)")
    ap.add_argument("--segment-s", type=float, default=5.0)
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(REPO / "src"))
    from dancesynth.bench.common import DEFAULT_SONG, largest_style, load_song, table
    from dancesynth.bench.speed import SEGMENT_PHASES, replicated_search, segment_costs
    from dancesynth.engines.graph.cache import load_graph
    from dancesynth.motion.database import open_database

    def progress(message):
        print(message, file=sys.stderr, flush=True)

    db = open_database()
    music = load_song(DEFAULT_SONG)
    style = largest_style(db).material  # what the product dances: mirrored takes too
    graph, _ = load_graph(style)
    result = {"song": DEFAULT_SONG, "song_s": music.duration_s, "load_avg": os.getloadavg(),
              "machine": {"cpus": os.cpu_count(), "python": platform.python_version()},
              "segments": segment_costs(style, graph, music, segment_s=args.segment_s, repeats=args.repeats,
                                        progress=progress)}
    if args.times > 1:
        result["replicated"] = replicated_search(db, music, times=args.times, segment_s=args.segment_s,
                                                 repeats=min(args.repeats, 3), progress=progress)
    print(format_result(result, table, SEGMENT_PHASES))
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "segment_speed.json").write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out / 'segment_speed.json'}")
    return 0


LABELS = {"search": "search", "stitch": "stitch", "foot_lock": "foot lock", "step": "step (search + render)",
          "bvh_text": "BVH text", "total": "total (step + BVH text)"}


def format_result(result: dict, table, phases) -> str:
    s = result["segments"]
    rows = [[LABELS[p], s["phases_ms"][p]["median"], s["phases_ms"][p]["max"]] for p in phases]
    rep = result.get("replicated")
    if rep:
        rows.append([f"search, database x{rep['times']} (N = {rep['N']})", rep["search_ms"]["median"],
                     rep["search_ms"]["max"]])
    return table(
        f"Per {s['segment_s']:g} s segment: style {s['style']} (N = {s['N']}, D = {s['D']:.2f}), song "
        f"{result['song']} ({result['song_s']:.1f} s, {s['segments']} segments), fastest of {s['repeats']} repeats",
        ["phase", "median ms", "max ms"], rows, [0, 2, 2],
        notes=[f"CPU per segment (step + BVH text, fastest whole repeat): {s['cpu_ms_per_segment']:.2f} ms; "
               f"load average at the start {result['load_avg'][0]:.2f} on {result['machine']['cpus']} CPUs",
               "step = one GraphEngine.step; targets (issue 15): step <= 8 ms, the x10 search < 20 ms"])


if __name__ == "__main__":
    sys.exit(main())

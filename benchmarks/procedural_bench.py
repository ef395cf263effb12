"""Benchmark of the procedural dancer (Loi & Li): segmentation and whole-song generation.

    .venv/bin/python benchmarks/procedural_bench.py [--out benchmarks/results]

1. Segmentation of 250/500/1000/2000-note melodies (the first notes of a long
   generated song with drums, ``bench.groundtruth``): the prefix DP the engine uses
   and the paper's Fig. 2 table (O(n^3), vectorised); both must find the same cost.
2. Whole songs, end to end as ``dancesynth conduct`` runs them (reading the notes,
   segmenting, planning, posing, writing the BVH): a 3-minute generated MIDI song
   with a drum kit, and a bundled recording.

Prints a table and writes ``procedural_bench.json`` into the output folder.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
AUDIO_SONG = "Kevin_MacLeod_-_Vibe_Ace.ogg"


def best_of(fn, repeats: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def bench_segmentation(tmp: Path) -> list[dict]:
    import numpy as np

    from dancesynth.engines.procedural.config import ProceduralConfig
    from dancesynth.engines.procedural.segment import (segment_costs, segment_fig2, segment_prefix,
                                                        segmentation_cost)
    from dancesynth.bench import groundtruth as gt
    from dancesynth.music.notes import midi_notes

    gt.write_midi(gt.SongSpec("long", (120,), duration_s=700.0, seed=11), tmp / "long.mid")
    melody = midi_notes(tmp / "long.mid", max_duration_s=None)
    cfg = ProceduralConfig()
    rows = []
    for n in (250, 500, 1000, 2000):
        notes = replace(melody, **{k: getattr(melody, k)[:n] for k in (
            "onset_s", "pitch", "duration_16", "intensity", "is_beat", "sounding_s", "rest_after")})
        t_cost, costs = best_of(lambda: segment_costs(notes, cfg), 3)
        t_prefix, a = best_of(lambda: segment_prefix(costs), 3)
        t_fig2, b = best_of(lambda: segment_fig2(costs), 1 if n >= 1000 else 3)
        same = bool(np.isclose(segmentation_cost(costs, a), segmentation_cost(costs, b), atol=1e-12))
        rows.append({"notes": n, "segments": len(a), "costs_s": t_cost, "prefix_dp_s": t_prefix,
                     "fig2_table_s": t_fig2, "same_optimum": same})
    return rows


def bench_song(path: Path, out: Path) -> dict:
    from dancesynth.api import conduct
    from dancesynth.io.bvh import write_bvh

    t = time.perf_counter()
    clip = conduct(path)
    t_write = time.perf_counter()
    write_bvh(out, clip)
    s = clip.provenance.summary
    done = time.perf_counter()
    return {"song": path.name, "input": s["input"], "duration_s": s["duration_s"], "notes": s["notes"],
            "segments": s["segments"], "frames": s["frames"], "total_s": done - t, "write_s": done - t_write,
            **{k: v for k, v in s["timings_s"].items()}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(REPO / "src"))
    from dancesynth.bench import groundtruth as gt
    from dancesynth.io.files import atomic_output

    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        seg = bench_segmentation(tmp)
        gt.write_midi(gt.SongSpec("three-minutes", (116,), duration_s=180.0, seed=5), tmp / "song.mid")
        songs = [bench_song(tmp / "song.mid", tmp / "song.bvh"),
                 bench_song(REPO / "src" / "dancesynth" / "data" / "music" / AUDIO_SONG, tmp / "audio.bvh")]
    print("segmentation (seconds; best of 3, Fig. 2 table at 1000+ notes: one run)")
    print(f"{'notes':>6} {'segments':>9} {'costs':>8} {'prefix DP':>10} {'Fig. 2 table':>13} {'same optimum':>13}")
    for r in seg:
        print(f"{r['notes']:>6} {r['segments']:>9} {r['costs_s']:>8.4f} {r['prefix_dp_s']:>10.4f} "
              f"{r['fig2_table_s']:>13.3f} {str(r['same_optimum']):>13}")
    print("\nwhole songs (seconds)")
    print(f"{'song':<32} {'input':>6} {'length':>7} {'notes':>6} {'read notes':>11} {'segment':>8} {'plan':>6} "
          f"{'pose':>6} {'write':>6} {'total':>6}")
    for r in songs:
        print(f"{r['song'][:32]:<32} {r['input']:>6} {r['duration_s']:>7.1f} {r['notes']:>6} {r['notes_s']:>11.2f} "
              f"{r['segment_s']:>8.3f} {r['plan_s']:>6.3f} {r['pose_s']:>6.2f} {r['write_s']:>6.2f} {r['total_s']:>6.2f}")
    args.out.mkdir(parents=True, exist_ok=True)
    result = {"machine": {"python": platform.python_version(), "processor": platform.processor(),
                          "system": platform.platform()},
              "segmentation": seg, "songs": songs}
    with atomic_output(args.out / "procedural_bench.json") as fh:
        json.dump(result, fh, indent=1)
        fh.write("\n")
    print(f"\nwrote {args.out / 'procedural_bench.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

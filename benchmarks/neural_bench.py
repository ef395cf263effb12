"""The neural generator against its targets (issue 16): section 6 of ``dancesynth bench`` on more songs.

    .venv/bin/python benchmarks/neural_bench.py [--seeds 3] [--no-generated] [--out benchmarks/results]

A thin wrapper around the ``structure`` section (``dancesynth.bench.structure``):
Table I (chi2 to the salsa template), the liveliness and artefact table (hand in
head, root travel, p99 joint speed, one-frame steps, plan followed, accents x
chance) beside the raw salsa mocap, the neural realism block (FID_k / FID_g against
the take the model never saw, beside the streaming engine's on a database without
it) and the neural targets with pass/fail. What it adds to the bench: the
generated ground-truth songs (exact beats, ``bench.groundtruth``, quick set) beside
the bundled ones, the neural engine's inference speed in a warm process and in a
fresh ``dancesynth dance`` process, and ``neural_bench.json``.
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

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SPEED_SONG = REPO / "src/dancesynth/data/music/Kevin_MacLeod_-_Vibe_Ace.ogg"


def speed(runs: int = 3) -> dict:
    """Synthesis x real time of the neural engine: warm (best and median of ``runs``) and one fresh CLI run."""
    from dancesynth.api import analyse, dance

    music = analyse(SPEED_SONG)
    dance(music, engine="neural")   # loads torch and the weights once
    warm = [dance(music, engine="neural", seed=s).provenance.summary["realtime_factor"] for s in range(runs)]
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        cli = Path(sys.executable).parent / "dancesynth"
        subprocess.run([str(cli), "dance", str(SPEED_SONG), "--engine", "neural", "-q", "-o", str(Path(tmp) / "n.bvh")],
                       check=True, capture_output=True)
        cli_s = time.perf_counter() - t
    return {"song": SPEED_SONG.name, "duration_s": music.duration_s, "warm_realtime_x": warm,
            "warm_realtime_x_median": float(np.median(warm)), "cli_wall_s": cli_s,
            "cli_realtime_x": music.duration_s / cli_s}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--no-generated", action="store_true", help="only the bundled songs")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    args = ap.parse_args(argv)

    from dancesynth.bench.common import MUSIC_DIR, BenchConfig
    from dancesynth.bench.run import run_bench
    from dancesynth.bench.structure import format_structure

    songs = [p.name for p in sorted(MUSIC_DIR.glob("*.ogg"))]
    if not args.no_generated:
        from dancesynth.bench.groundtruth import ground_truth_set
        from dancesynth.motion.database import cache_dir

        songs += [str(s.audio_path) for s in ground_truth_set(cache_dir() / "groundtruth", quick=True)]
    cfg = replace(BenchConfig.full(), sections=("structure",), structure_songs=tuple(songs),
                  structure_seeds=args.seeds, fig12_seeds=2, recreate_clips=4)
    with tempfile.TemporaryDirectory() as tmp:
        result = run_bench(quick=False, out_dir=Path(tmp), config=cfg,
                           progress=lambda msg: print(msg, file=sys.stderr, flush=True))
    s = result["structure"]
    if "skipped" in s:
        print(f"the structure section did not run: {s['skipped']}", file=sys.stderr)
        return 1
    print(format_structure(s))
    sp = speed()
    print(f"\nneural inference on {sp['song']} ({sp['duration_s']:.0f} s), one thread: warm "
          f"{sp['warm_realtime_x_median']:.1f}x real time (median of {len(sp['warm_realtime_x'])}); a fresh "
          f"'dancesynth dance' process, imports and writing included: {sp['cli_wall_s']:.1f} s "
          f"({sp['cli_realtime_x']:.1f}x)")
    out = {"songs": songs, "seeds": args.seeds, "structure": s, "speed": sp, "targets": result["targets"],
           "machine": result["machine"]}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "neural_bench.json").write_text(json.dumps(out, indent=1, default=float))
    print(f"wrote {args.out / 'neural_bench.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

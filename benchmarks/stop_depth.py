"""How deep the mocap's own accents stop the body: the source of ``EvalParams.visible_stop_depth``.

    .venv/bin/python benchmarks/stop_depth.py [--fps 30]

For every captured take of every bundled style (mirrors are not captured, so not counted), at
the dances' frame rate: the stop depth (``motion.beats.stop_depths``) of each kinematic beat
within +-50 ms of one of the take's own motion beats, and of the others. Prints a table per
style and over all, and writes benchmarks/results/stop_depth.json. The pooled median of the
on-beat depths is the threshold of a visible accent.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    from dancesynth.bench.quality import at_fps
    from dancesynth.eval import beat_metrics as bm
    from dancesynth.eval import motion_metrics as mm
    from dancesynth.motion.beats import stop_depths
    from dancesynth.motion.database import open_database

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "stop_depth.json")
    args = ap.parse_args()
    rows, pooled_on, pooled_off = {}, [], []
    for name, style in open_database().styles.items():
        on, off = [], []
        for c in range(style.n_clips):
            clip = at_fps(style.clip(c), args.fps)
            kin, _, smooth = mm.kinematic_beats(clip)
            depth = stop_depths(smooth, np.round(kin * clip.fps).astype(np.int64))
            hit = bm.on_beats(kin, clip.meta["beat_times_s"], window_s=bm.DEFAULT_HIT_WINDOW_S)
            on += depth[hit].tolist()
            off += depth[~hit].tolist()
        rows[name] = {"takes": style.n_clips, "on_beat": len(on), "off_beat": len(off),
                      "on_beat_quartiles": np.percentile(on, [25, 50, 75]).tolist() if on else None,
                      "off_beat_median": float(np.median(off)) if off else None}
        pooled_on += on
        pooled_off += off
    pooled = {"on_beat": len(pooled_on), "on_beat_quartiles": np.percentile(pooled_on, [25, 50, 75]).tolist(),
              "off_beat": len(pooled_off), "off_beat_median": float(np.median(pooled_off)),
              "visible_stop_depth_in_use": mm.VISIBLE_STOP_DEPTH}
    print(f"Stop depth of the mocap's kinematic beats at {args.fps:g} fps (1 = a full stop)")
    print(f"{'style':22s} {'takes':>5s} {'on beat':>7s} {'p25':>5s} {'median':>6s} {'p75':>5s} {'off beat':>8s} "
          f"{'median':>6s}")
    for name, r in list(rows.items()) + [("all", {**pooled, "takes": sum(r["takes"] for r in rows.values())})]:
        q = r["on_beat_quartiles"] or [float("nan")] * 3
        print(f"{name:22s} {r['takes']:5d} {r['on_beat']:7d} {q[0]:5.3f} {q[1]:6.3f} {q[2]:5.3f} {r['off_beat']:8d} "
              f"{r['off_beat_median'] or float('nan'):6.3f}")
    print(f"visible_stop_depth in use: {mm.VISIBLE_STOP_DEPTH} (the pooled on-beat median, rounded)")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"fps": args.fps, "styles": rows, "all": pooled}, indent=1) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

"""The neural engine's joint-speed guard song by song (issue 31 item 5), which bench section 7 does not dance.

    .venv/bin/python benchmarks/neural_speed_guard.py [--split test|tune]

Dances the bundled songs and the split's generated songs (60-180 bpm) with ``--engine neural`` and prints
each dance's p99 joint speed over its style's mocap's (the guard: within +-25 %) beside the range the
mocap itself spans over stretches as long as the song (``bench.accents.mocap_speed_range``), with and
without the beat warp's speed limit (``engines.neural.engine.WARP_SPEED_PERCENTILE``), and the accents
each keeps. Writes benchmarks/results/neural_speed_guard.json. About a minute.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path
from unittest import mock

import numpy as np

REPO = Path(__file__).resolve().parents[1]
KEYS = ("joint_speed_p99_vs_mocap", "accent_precision", "accent_recall", "visible_accent_precision_x_chance",
        "intensity_spearman")


def main() -> None:
    from dancesynth.api import dance
    from dancesynth.bench.accents import SPEED_GUARD, _songs, mocap_speed_range
    from dancesynth.bench.common import BenchConfig
    from dancesynth.bench.quality import at_fps
    from dancesynth.engines.neural import engine as neural
    from dancesynth.eval.evaluate import evaluate, mocap_reference
    from dancesynth.motion.database import open_database

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", choices=("test", "tune"), default="test")
    args = ap.parse_args()
    db = open_database()
    songs = _songs(replace(BenchConfig.full(), groundtruth_split=args.split), None)
    refs, rows = {}, []
    for song in songs:
        row = {"song": song["name"], "set": song["set"], "tempo_bpm": song["music"].tempo_bpm}
        for name, percentile in (("limited", neural.WARP_SPEED_PERCENTILE), ("unlimited", None)):
            with mock.patch.object(neural, "WARP_SPEED_PERCENTILE", percentile):
                clip = dance(song["music"], database=db, engine="neural")
            style = db.styles[clip.provenance.style]
            if style.name not in refs:
                clips = [at_fps(style.clip(c), clip.fps) for c in range(style.n_clips)]
                refs[style.name] = (mocap_reference(clips, clip.fps), clips)
            ref, clips = refs[style.name]
            r = evaluate(clip, mocap=ref, music_beats_s=song["beats"], music_loudness_db=song["loudness"])
            row[name] = {k: r.get(k) for k in KEYS}
            row["style"] = style.name
            row["mocap_range"] = mocap_speed_range(clips, ref.joint_speed_p99_m_s, clip.duration_s)
        rows.append(row)
        print(f"{song['name'][:28]:>28} {row['tempo_bpm']:6.1f} "
              f"{row['style']:>17}  p99 / mocap {row['unlimited']['joint_speed_p99_vs_mocap']:.2f} -> "
              f"{row['limited']['joint_speed_p99_vs_mocap']:.2f}  (mocap's own {row['mocap_range'][0]:.2f}-"
              f"{row['mocap_range'][1]:.2f})", flush=True)
    summary = {}
    for name in ("unlimited", "limited"):
        ratio = np.array([r[name]["joint_speed_p99_vs_mocap"] for r in rows])
        outside = np.abs(ratio - 1.0) > SPEED_GUARD
        beyond = outside & np.array([not lo <= x <= hi for x, (lo, hi) in zip(ratio, (r["mocap_range"] for r in rows))])
        generated = np.array([r["set"] == "generated" for r in rows])
        summary[name] = {"outside": int(outside.sum()), "outside_generated": int(outside[generated].sum()),
                         "outside_mocap_range": int(beyond.sum()), "dances": len(rows),
                         "furthest_from_1": float(np.abs(ratio - 1.0).max()),
                         **{f"mean_{k}": float(np.nanmean([r[name][k] if r[name][k] is not None else np.nan
                                                           for r in rows])) for k in KEYS}}
        s = summary[name]
        print(f"{name:>10}: outside +-25 % {s['outside']} of {s['dances']} ({s['outside_generated']} generated; "
              f"{s['outside_mocap_range']} outside the mocap's own range too), furthest from 1 "
              f"{s['furthest_from_1']:.2f}; precision {s['mean_accent_precision']:.3f}, recall "
              f"{s['mean_accent_recall']:.3f}, visible x chance {s['mean_visible_accent_precision_x_chance']:.2f}, "
              f"Spearman {s['mean_intensity_spearman']:.3f}")
    out = REPO / "benchmarks" / "results" / "neural_speed_guard.json"
    out.write_text(json.dumps({"split": args.split, "warp_speed_percentile": neural.WARP_SPEED_PERCENTILE,
                               "summary": summary, "songs": rows}, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()

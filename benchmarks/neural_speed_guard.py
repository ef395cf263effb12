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
    from dancesynth.bench.accents import _songs, mocap_speed_range, mocap_speeds, speed_guard
    from dancesynth.bench.common import BenchConfig
    from dancesynth.bench.quality import at_fps, mean_scores
    from dancesynth.engines.neural import engine as neural
    from dancesynth.eval.evaluate import evaluate, mocap_reference
    from dancesynth.motion.database import open_database

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--split", choices=("test", "tune"), default="test")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "neural_speed_guard.json")
    args = ap.parse_args()
    db = open_database()
    songs = _songs(replace(BenchConfig.full(), groundtruth_split=args.split), None)
    settings = {"limited": neural.WARP_SPEED_PERCENTILE, "unlimited": None}
    refs, rows = {}, []
    for song in songs:
        # As bench section 7's per-song records, with the two settings for engines (``speed_guard``).
        row = {"song": song["name"], "set": song["set"], "tempo_bpm": song["music"].tempo_bpm, "scores": {},
               "speed_range": {}}
        for name, percentile in settings.items():
            with mock.patch.object(neural, "WARP_SPEED_PERCENTILE", percentile):
                clip = dance(song["music"], database=db, engine="neural")
            style = db.styles[clip.provenance.style]
            if style.name not in refs:
                clips = [at_fps(style.clip(c), clip.fps) for c in range(style.n_clips)]
                refs[style.name] = (mocap_reference(clips, clip.fps), mocap_speeds(clips))
            ref, speeds = refs[style.name]
            r = evaluate(clip, mocap=ref, music_beats_s=song["beats"], music_loudness_db=song["loudness"])
            row["scores"][name] = {k: r.get(k) for k in KEYS}
            row["style"], row["rate"] = style.name, clip.provenance.run.fit["typical_rate"]   # captured / danced beat
            row["speed_range"][name] = mocap_speed_range(speeds, clip.fps, ref.joint_speed_p99_m_s, clip.duration_s)
        rows.append(row)
        lo, hi = row["speed_range"]["limited"]
        print(f"{song['name'][:28]:>28} {row['tempo_bpm']:6.1f} {row['style']:>17}  p99 / mocap "
              f"{row['scores']['unlimited']['joint_speed_p99_vs_mocap']:.2f} -> "
              f"{row['scores']['limited']['joint_speed_p99_vs_mocap']:.2f}  (mocap's own {lo:.2f}-{hi:.2f})", flush=True)
    guard = speed_guard(rows, settings)
    generated = speed_guard([r for r in rows if r["set"] == "generated"], settings)
    summary = {}
    for name in settings:
        ratio = np.array([r["scores"][name]["joint_speed_p99_vs_mocap"] for r in rows])
        summary[name] = s = {**guard[name], "outside_generated": generated[name]["outside"],
                             "furthest_from_1": float(np.abs(ratio - 1.0).max()),
                             **{f"mean_{k}": v for k, v in mean_scores([r["scores"][name] for r in rows]).items()}}
        print(f"{name:>10}: outside +-25 % {s['outside']} of {s['dances']} ({s['outside_generated']} generated; "
              f"{s['outside_mocap_range']} outside the mocap's own range too), furthest from 1 "
              f"{s['furthest_from_1']:.2f}; precision {s['mean_accent_precision']:.3f}, recall "
              f"{s['mean_accent_recall']:.3f}, visible x chance {s['mean_visible_accent_precision_x_chance']:.2f}, "
              f"Spearman {s['mean_intensity_spearman']:.3f}")
    out = args.out
    out.write_text(json.dumps({"split": args.split, "warp_speed_percentile": neural.WARP_SPEED_PERCENTILE,
                               "summary": summary, "songs": rows}, indent=1) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()

"""Write the benchmark's ground-truth songs: MIDI with exactly known beats, rendered by fluidsynth.

    python scripts/make_groundtruth.py OUT_DIR [--quick] [--split test|tune]

For every song OUT_DIR/groundtruth-<key>/ gets NAME.mid, NAME.wav and NAME.beats.json
({"beats": [seconds...], "spec": {...}}). Needs fluidsynth and a General MIDI soundfont
(apt-get install fluidsynth timgm6mb-soundfont). See docs/beat-tracking.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from dancesynth.errors import DanceSynthError
from dancesynth.bench.groundtruth import ground_truth_set


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out_dir", type=Path)
    ap.add_argument("--quick", action="store_true", help="the 8-song subset")
    ap.add_argument("--split", choices=("test", "tune"), default="test",
                    help="test: the songs the bench reports; tune: where the engines' constants were chosen")
    args = ap.parse_args()
    try:
        songs = ground_truth_set(args.out_dir, quick=args.quick, split=args.split,
                                 progress=lambda msg: print(msg, file=sys.stderr))
    except DanceSynthError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for song in songs:
        print(f"{song.audio_path}  {len(song.beats_s)} beats  {song.tags}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""How well ``music.structure`` finds a song's form, on generated songs of known form (issue 32 item 1).

    .venv/bin/python benchmarks/music_structure.py [--split tune|test|both]

Each split's songs (``bench.groundtruth.structure_specs``: verse / chorus / bridge forms, 88-156 bpm,
3/4 and 4/4, half with a pickup, every repeat with one instrument more) are rendered by fluidsynth,
analysed as ``dancesynth beats`` analyses any song (its own beats and downbeats, not the truth), and
scored with mir_eval: boundary F-measure at +-0.5 s (the song's start and end trimmed) and pairwise
label F. Chance: the same number of boundaries on the 4-bar phrase grid at random (seeded), each
section labelled at random among as many labels as found. The constants were chosen on ``tune``;
``test`` is reported. Prints a table and writes benchmarks/results/music_structure.json.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def run(split: str) -> dict:
    from dancesynth.bench.form import section_chance as chance, section_scores as score
    from dancesynth.bench.groundtruth import ground_truth_set, structure_specs
    from dancesynth.io.audio import load_audio
    from dancesynth.io.files import cache_dir
    from dancesynth.music import analyze_music
    from dancesynth.music.onset import ANALYSIS_SR
    from dancesynth.music.structure import song_structure

    rng = np.random.default_rng(0)
    rows = []
    for song in ground_truth_set(cache_dir() / "groundtruth", specs=structure_specs(split)):
        music = analyze_music(path=song.audio_path)
        samples, sr = load_audio(song.audio_path, sr=ANALYSIS_SR, mono=True)
        t0 = time.perf_counter()   # the structure alone, on the samples analyze_music(structure=True) shares
        st = song_structure(samples, sr, music.beat_times_s, music.beat_in_bar, music.beats_per_bar,
                            music.duration_s)
        took = time.perf_counter() - t0
        est = [(s.start_s, s.end_s, s.label) for s in st.sections]
        f, pw = score(list(song.sections), est)
        bar_s = np.r_[music.beat_times_s[music.beat_in_bar == 0], music.duration_s]
        ch = np.mean([chance(list(song.sections), est, bar_s, rng) for _ in range(20)], axis=0)
        rows.append({"song": song.name, "truth": "".join(s[2] for s in song.sections),
                     "found": "".join(s.label for s in st.sections), "names": [s.name for s in st.sections],
                     "boundary_f": f, "pairwise_f": pw, "chance_boundary_f": float(ch[0]),
                     "chance_pairwise_f": float(ch[1]), "structure_s": took, "duration_s": music.duration_s})
    keys = ("boundary_f", "pairwise_f", "chance_boundary_f", "chance_pairwise_f")
    return {"songs": rows, "mean": {k: float(np.mean([r[k] for r in rows])) for k in keys}}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--split", default="both", choices=("tune", "test", "both"))
    args = ap.parse_args()
    out = {}
    for split in (("tune", "test") if args.split == "both" else (args.split,)):
        out[split] = run(split)
        print(f"\n{split}: {'song':28s} {'truth':8s} {'found':9s} {'bound F':>7s} {'pair F':>7s} "
              f"{'chance':>13s} {'s':>5s}")
        for r in out[split]["songs"]:
            print(f"       {r['song']:28s} {r['truth']:8s} {r['found']:9s} {r['boundary_f']:7.2f} "
                  f"{r['pairwise_f']:7.2f} {r['chance_boundary_f']:6.2f}/{r['chance_pairwise_f']:.2f} "
                  f"{r['structure_s']:5.2f}")
        m = out[split]["mean"]
        print(f"       {'mean':28s} {'':8s} {'':9s} {m['boundary_f']:7.2f} {m['pairwise_f']:7.2f} "
              f"{m['chance_boundary_f']:6.2f}/{m['chance_pairwise_f']:.2f}")
    path = REPO / "benchmarks" / "results" / "music_structure.json"
    if args.split == "both":
        path.write_text(json.dumps(out, indent=1))
        print(f"\nwrote {path}")
    print(json.dumps({k: v["mean"] for k, v in out.items()}))


if __name__ == "__main__":
    main()

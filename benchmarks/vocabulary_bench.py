"""What the database can dance: minutes per genre, the tempo map, repetition, and the guards per style.

    python benchmarks/vocabulary_bench.py [--before REV] [--quick] [--out benchmarks/results/vocabulary_bench.json]

1. ``genres``: captured minutes per genre and style (and their licences) of the bundled database,
   beside the database at git revision ``--before`` (default: the last one before issue 30).
2. ``tempo_map``: for every tempo 60-180 bpm, the style the product chooses, and the most material
   (minutes within 0.8-1.25x of the captured speed) any style has there at any level.
3. ``songs``: every bundled song, the generated set (60-180 bpm, steps, ramps, 3/4 and 4/4, with exact
   beats) and ten more generated 3-minute songs in 3/4 and 4/4: the style and level danced, the material
   it had, the share of beats replaying a source beat danced in the previous 60 s, the longest such run.
4. ``guards``: per style danced (the product's choice on those songs, plus each style of at least 2
   minutes forced on the generated songs its tempo map covers): visible accents against chance both
   ways, isolated one-frame steps over 30 degrees the mocap does not have, foot skating and p99 joint
   speed beside the style's own mocap (each clip alone).
The same tables every run; the JSON has every number per song.
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
BEFORE = "7f6caad"   # main before issue 30 (the database with jpop, without G1 Moves)


def genre_minutes(rows: list[dict]) -> dict:
    out: dict = {}
    for r in rows:
        g = out.setdefault(r["genre"], {"minutes": 0.0, "styles": [], "licence": set()})
        g["minutes"] += r["minutes"]
        g["styles"].append(f"{r['name']} ({r['minutes']:.1f})")
        g["licence"].update(r["licence"].split(", ") if r.get("licence") else ["unrecorded"])
    return {k: {**v, "licence": sorted(v["licence"])} for k, v in sorted(out.items())}


def before_rows(rev: str) -> list[dict]:
    from dancesynth.motion.catalog import list_styles

    with tempfile.TemporaryDirectory() as tmp:
        tar = subprocess.run(["git", "-C", str(REPO), "archive", rev, "src/dancesynth/data/database"],
                             capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", tmp], input=tar, check=True)
        return list_styles(Path(tmp) / "src/dancesynth/data/database")


def extra_specs():
    from dancesynth.bench.groundtruth import SongSpec

    tempi = (72, 88, 104, 118, 126, 138, 146, 164, 172, 178)
    return [SongSpec(f"long{b}_{3 if i % 2 else 4}-4", (b,), beats_per_bar=3 if i % 2 else 4, duration_s=180.0,
                     seed=100 + i, pickup_beats=i % 3 if i % 2 else i % 4, drums=i % 3 != 2)
            for i, b in enumerate(tempi)]


def songs(quick: bool) -> list[dict]:
    from dancesynth.bench.accents import _songs
    from dancesynth.bench.common import BenchConfig
    from dancesynth.bench.groundtruth import song_specs

    specs = song_specs(quick=quick) + (extra_specs()[::3] if quick else extra_specs())
    cfg = replace(BenchConfig.quick() if quick else BenchConfig.full(), accent_songs=None, groundtruth_specs=specs)
    return _songs(cfg, lambda m: print(m, file=sys.stderr))


def dance_song(song: dict, db, style: str | None = None) -> tuple:
    from dancesynth.api import dance

    clip = dance(song["music"], database=db, style=style)
    s = clip.provenance.summary
    rep = s["repetition"]
    return clip, {"song": song["name"], "set": song["set"], "duration_s": round(song["music"].duration_s, 1),
                  "tempo_bpm": round(song["music"].tempo_bpm, 1), "beats_per_bar": song["beats_per_bar"],
                  "style": s["style"], "forced": style is not None, "level": s.get("level"),
                  "in_range_expected": s.get("in_range_expected"), "material_minutes": rep["material_minutes"],
                  "replayed_share": rep["replayed_share"], "longest_repeat_beats": rep["longest_repeat_beats"],
                  "reason": s.get("style_reason")}


def guards(db, danced: list[tuple], progress) -> dict:
    """Per style: the mean accent scores and guards of its dances, and its mocap's own numbers."""
    from dancesynth.bench.accents import _mocap_evaluate, _score
    from dancesynth.bench.quality import at_fps, mocap_scores
    from dancesynth.eval.evaluate import mocap_reference

    by_style: dict = {}
    for clip, row, song in danced:
        by_style.setdefault(row["style"], []).append((clip, song))
    out = {}
    for name, items in sorted(by_style.items()):
        progress(f"guards: {name} ({len(items)} dances)")
        st = db.styles[name]
        fps = items[0][0].fps
        clips = [at_fps(st.clip(c), fps) for c in range(st.n_clips)]
        ref = mocap_reference(clips, fps)
        sources = [st.clip(c) for c in range(st.n_clips)]
        scores = [_score(clip, song, ref, st, sources) for clip, song in items]
        mocap = mocap_scores(_mocap_evaluate, clips, None)["mean"]

        def mean(key, rows=scores):
            vals = [r[key] for r in rows if r.get(key) is not None and np.isfinite(r[key])]
            return float(np.mean(vals)) if vals else None

        out[name] = {"dances": len(items), "accent_precision_x_chance": mean("accent_precision_x_chance"),
                     "accent_recall_x_chance": mean("accent_recall_x_chance"),
                     "min_accent_x_chance": min(min(r["accent_precision_x_chance"], r["accent_recall_x_chance"])
                                                for r in scores),
                     "one_frame_steps": int(sum(r.get("one_frame_steps") or 0 for r in scores)),
                     "foot_skate_m_s": mean("foot_skate_m_s"), "mocap_foot_skate_m_s": mocap.get("foot_skate_m_s"),
                     "foot_skate_vs_mocap": mean("foot_skate_vs_mocap"),
                     "joint_speed_p99_vs_mocap": mean("joint_speed_p99_vs_mocap"),
                     "worst_joint_speed_p99_vs_mocap": max(r["joint_speed_p99_vs_mocap"] for r in scores)}
    return out


def fmt(x, d=2):
    return "-" if x is None else (f"{x:.{d}f}" if isinstance(x, float) else str(x))


def report(res: dict) -> str:
    lines = ["1. Captured minutes per genre (mirrored takes: none, not counted)",
             f"{'genre':<12}{'before':>8}{'after':>8}  licence  styles (after)"]
    for g in sorted(set(res["genres"]["before"]) | set(res["genres"]["after"])):
        b, a = res["genres"]["before"].get(g), res["genres"]["after"].get(g)
        lines.append(f"{g:<12}{fmt(b and b['minutes'], 1):>8}{fmt(a and a['minutes'], 1):>8}  "
                     f"{', '.join((a or b)['licence'])}  {', '.join(a['styles']) if a else '(left out)'}")
    for k in ("before", "after"):
        t = res["totals"][k]
        lines.append(f"{k}: {t['minutes']:.1f} min; styles >= 2 min: {t['styles_2min']}; "
                     f"genres >= 10 min: {', '.join(t['genres_10min']) or 'none'}")
    lines += ["", "2. Tempo map (minutes of material within 0.8-1.25x; full map: dancesynth styles --tempo-map)",
              f"{'bpm':>5}  {'chosen':<34}{'most material anywhere':>24}"]
    for r in res["tempo_map"]:
        if r["tempo_bpm"] % 10 == 0:
            best = max(r["styles"], key=lambda x: x["minutes"]) if r["styles"] else None
            lines.append(f"{r['tempo_bpm']:>5.0f}  {r['chosen'] + ' (' + r['chosen_level'] + ')':<34}"
                         f"{(best['style'] + ' ' + fmt(best['minutes'], 1)) if best else 'none':>24}")
    lines.append(f"tempi 70-180 bpm with a style of >= 5 min: {res['tempo_cover']['covered']} of "
                 f"{res['tempo_cover']['tempi']}; short: {res['tempo_cover']['short'] or 'none'}")
    lines += ["", "3. Songs (product's choice): style, material, repetition",
              f"{'song':<34}{'bpm':>6}{'style':>18}{'level':>12}{'min':>6}{'replay':>8}{'run':>5}"]
    for r in res["songs"]:
        lines.append(f"{r['song'][:33]:<34}{r['tempo_bpm']:>6.0f}{r['style']:>18}{r['level']:>12}"
                     f"{r['material_minutes']:>6.1f}{r['replayed_share']:>8.0%}{r['longest_repeat_beats']:>5}")
    t = res["targets"]
    lines.append(f"songs danced from < 2 min: {t['under_2min']}; 3-minute songs: replayed share max "
                 f"{t['long_replay_max']:.0%}, mean {t['long_replay_mean']:.0%} (target <= 10 %)")
    lines += ["", "4. Guards per style (streaming; x chance both ways >= 2.5; steps 0; skate <= mocap + 10 %; "
              "p99 joint speed within +-25 %)",
              f"{'style':<18}{'dances':>7}{'prec x':>8}{'rec x':>7}{'min x':>7}{'steps':>6}{'skate':>7}{'mocap':>7}"
              f"{'skate/m':>8}{'p99/m':>7}{'worst':>7}"]
    for name, g in res["guards"].items():
        lines.append(f"{name:<18}{g['dances']:>7}{fmt(g['accent_precision_x_chance']):>8}"
                     f"{fmt(g['accent_recall_x_chance']):>7}{fmt(g['min_accent_x_chance']):>7}{g['one_frame_steps']:>6}"
                     f"{fmt(g['foot_skate_m_s'], 3):>7}{fmt(g['mocap_foot_skate_m_s'], 3):>7}"
                     f"{fmt(g['foot_skate_vs_mocap']):>8}{fmt(g['joint_speed_p99_vs_mocap']):>7}"
                     f"{fmt(g['worst_joint_speed_p99_vs_mocap']):>7}")
    return "\n".join(lines)


def totals(genres: dict, rows: list[dict]) -> dict:
    return {"minutes": sum(r["minutes"] for r in rows), "styles_2min": sum(r["minutes"] >= 2 for r in rows),
            "genres_10min": [g for g, v in genres.items() if v["minutes"] >= 10]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--before", default=BEFORE, help="git revision of the database to compare with")
    ap.add_argument("--quick", action="store_true", help="the quick generated set and 4 long songs")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "vocabulary_bench.json")
    args = ap.parse_args()
    from dancesynth.engines.beatgrid import tempo_map
    from dancesynth.motion.catalog import list_styles
    from dancesynth.motion.database import open_database

    t0 = time.perf_counter()
    progress = lambda m: print(m, file=sys.stderr)   # noqa: E731
    db = open_database()
    after, before = list_styles(), before_rows(args.before)
    res = {"genres": {"before": genre_minutes(before), "after": genre_minutes(after)}}
    res["totals"] = {k: totals(res["genres"][k], rows) for k, rows in (("before", before), ("after", after))}
    res["tempo_map"] = tempo_map(db, range(60, 181))
    short = [r["tempo_bpm"] for r in res["tempo_map"] if 70 <= r["tempo_bpm"] <= 180
             and max([x["minutes"] for x in r["styles"]] or [0]) < 5]
    res["tempo_cover"] = {"tempi": 111, "covered": 111 - len(short), "short": short}
    danced = []
    for song in songs(args.quick):
        progress(f"dancing {song['name']}")
        clip, row = dance_song(song, db)
        danced.append((clip, row, song))
    # Every style of at least 2 minutes, forced on the generated songs whose tempo it covers with 2 minutes.
    chosen = {r["style"] for _, r, _ in danced}
    for st in db.styles.values():
        if st.duration_s < 120 or st.name in chosen:
            continue
        for song in [s for _, _, s in danced if s["set"] == "generated"]:
            bpm = round(song["music"].tempo_bpm)
            row = next((r for r in res["tempo_map"] if r["tempo_bpm"] == min(max(bpm, 60), 180)), None)
            if row and any(x["style"] == st.name for x in row["styles"]):
                clip, r = dance_song(song, db, st.name)
                danced.append((clip, r, song))
    res["songs"] = [r for _, r, _ in danced]
    longs = [r["replayed_share"] for r in res["songs"] if r["duration_s"] >= 170 and not r["forced"]]
    res["targets"] = {"under_2min": sum(r["material_minutes"] < 2 for r in res["songs"] if not r["forced"]),
                      "long_replay_max": max(longs) if longs else 0.0,
                      "long_replay_mean": float(np.mean(longs)) if longs else 0.0}
    res["guards"] = guards(db, danced, progress)
    res["wall_s"] = time.perf_counter() - t0
    text = report(res)
    print(text)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    from dancesynth.io.files import jsonable

    args.out.write_text(json.dumps(jsonable(res), indent=1))
    print(f"wrote {args.out} ({res['wall_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""What the database can dance: minutes per genre, the tempo map, repetition, and the guards per style.

1. ``genres``: captured minutes per genre and style of the bundled database, the minutes of mirrored
   takes beside them (never counted in the captured totals), and the licences.
2. ``tempo_map``: for every tempo 60-180 bpm, the style the product chooses, and the most material
   (captured minutes within 0.8-1.25x of their speed) any style has there at any level.
3. ``songs``: the accent section's songs (bundled, and generated with exact beats) and generated songs of
   ``vocabulary_long_s`` (3 minutes) in 3/4 and 4/4: the style and level the product dances, the
   material it had, the share of beats replaying a source beat danced in the previous 60 s
   (``eval.repetition``), the longest such run, and the same share counting a take's mirror image as
   the take itself (``replayed_share_strict``).
4. ``guards``: per style danced (the product's choice on those songs, plus each style of at least 2
   minutes forced on the generated songs its tempo map covers): visible accents against chance both ways,
   isolated one-frame steps over 30 degrees the mocap does not have, foot skating and p99 joint speed
   beside the style's own captured takes (each clip alone).

The long songs come in two splits: ``test`` (seeds 100-109, what the bench reports) and ``tune`` (seeds
200-209, other tempi: where the repeat penalty, the foot-slide and jump costs and the easing limit were
chosen). No constant was chosen on the test split.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..api import dance
from ..engines.beatgrid import MIN_MATERIAL_MINUTES, tempo_map
from ..errors import InputError
from ..eval.evaluate import mocap_reference
from ..eval.repetition import repetition
from ..motion.catalog import list_styles
from .accents import _mocap_evaluate, _score
from .accents import _songs as accent_songs
from .common import BenchConfig, Progress
from .groundtruth import SongSpec, song_specs
from .quality import at_fps, mocap_scores

#: Tempi of the 3-minute songs of each split (odd ones in 3/4), and the first seed.
LONG_SONGS = {"test": ((72, 88, 104, 118, 126, 138, 146, 164, 172, 178), 100),
              "tune": ((80, 96, 112, 124, 134, 150, 170, 92, 142, 160), 200)}
TEMPO_COVER_BPM = (70, 180)    # every tempo here should have a style with ...
TEMPO_COVER_MINUTES = 5.0      # ... this much material at some level


def long_specs(split: str, count: int, duration_s: float) -> list:
    """The generated long songs of a split: ``count`` of them, alternately 4/4 and 3/4, with pickups."""
    if split not in LONG_SONGS:
        raise InputError(f"vocabulary split {split!r}: use one of {', '.join(LONG_SONGS)}")
    tempi, seed = LONG_SONGS[split]
    return [SongSpec(f"{split}{b}_{3 if i % 2 else 4}-4", (b,), beats_per_bar=3 if i % 2 else 4,
                     duration_s=float(duration_s), seed=seed + i,
                     pickup_beats=i % 3 if i % 2 else i % 4, drums=i % 3 != 2)
            for i, b in enumerate(tempi[:count])]


def genre_minutes(rows: list[dict]) -> dict:
    """Per genre: captured and mirrored minutes, its styles and licences (``list_styles`` rows)."""
    out: dict = {}
    for r in rows:
        g = out.setdefault(r["genre"], {"minutes": 0.0, "mirrored_minutes": 0.0, "styles": [], "licence": set()})
        g["minutes"] += r["minutes"]
        g["mirrored_minutes"] += r.get("mirrored_minutes", 0.0)
        g["styles"].append(f"{r['name']} ({r['minutes']:.1f})")
        g["licence"].update(r["licence"].split(", ") if r.get("licence") else ["unrecorded"])
    return {k: {**v, "licence": sorted(v["licence"])} for k, v in sorted(out.items())}


def totals(genres: dict, rows: list[dict]) -> dict:
    return {"minutes": sum(r["minutes"] for r in rows),
            "mirrored_minutes": sum(r.get("mirrored_minutes", 0.0) for r in rows),
            "styles_2min": sum(r["minutes"] >= 2 for r in rows),
            "genres_10min": [g for g, v in genres.items() if v["minutes"] >= 10]}


def _songs(cfg: BenchConfig, progress) -> list[dict]:
    specs = list(cfg.groundtruth_specs) if cfg.groundtruth_specs else None
    if specs is None:
        specs = song_specs(quick=cfg.groundtruth_quick, split=cfg.groundtruth_split)
    specs += long_specs(cfg.vocabulary_split, cfg.vocabulary_long_songs, cfg.vocabulary_long_s)
    return accent_songs(replace(cfg, groundtruth_specs=tuple(specs)), progress)


def _strict(sources: tuple) -> float:
    """The replayed share with a take's mirror image counted as the take itself (the song's form's replays
    aside, as ``dance``'s own count leaves them)."""
    ids = [(s["clip"].removesuffix(" (mirrored)"), s["source_position"]) for s in sources]
    asked = [s.get("form_replay", False) for s in sources]
    return repetition(ids, [s["time_s"] for s in sources], asked=asked)["replayed_share"] if ids else 0.0


def dance_song(song: dict, db, style: str | None = None) -> tuple:
    clip = dance(song["music"], database=db, style=style)
    s = clip.provenance.summary
    rep = s["repetition"]
    sources = [dict(b, time_s=float(t)) for b, t in zip(clip.provenance.beat_sources, song["music"].beat_times_s)]
    return clip, {"song": song["name"], "set": song["set"], "duration_s": round(song["music"].duration_s, 1),
                  "tempo_bpm": round(song["music"].tempo_bpm, 1), "beats_per_bar": song["beats_per_bar"],
                  "style": s["style"], "forced": style is not None, "level": s.get("level"),
                  "in_range_expected": s.get("in_range_expected"), "material_minutes": rep["material_minutes"],
                  "mirrored_minutes": rep.get("mirrored_minutes", 0.0), "replayed_share": rep["replayed_share"],
                  "replayed_share_strict": _strict(tuple(sources)),
                  "longest_repeat_beats": rep["longest_repeat_beats"], "reason": s.get("style_reason")}


def guards(db, danced: list[tuple], progress=None) -> dict:
    """Per style: the mean accent scores and guards of its dances, and its captured takes' own numbers."""
    by_style: dict = {}
    for clip, row, song in danced:
        by_style.setdefault(row["style"], []).append((clip, song))
    out = {}
    for name, items in sorted(by_style.items()):
        if progress:
            progress(f"vocabulary: guards of {name} ({len(items)} dances)")
        st = db.styles[name]
        fps = items[0][0].fps
        clips = [at_fps(st.clip(c), fps) for c in range(st.n_clips)]   # the captured takes
        ref = mocap_reference(clips, fps)
        danced_from = st.material   # the dance's source frames index its material (mirrored takes too)
        sources = [danced_from.clip(c) for c in range(danced_from.n_clips)]
        scores = [_score(clip, song, ref, danced_from, sources) for clip, song in items]
        mocap = mocap_scores(_mocap_evaluate, clips, None)["mean"]

        def over(key, pick=np.mean):
            """``pick`` (the mean) of ``key`` over the dances that have it."""
            vals = [r[key] for r in scores if r.get(key) is not None and np.isfinite(r[key])]
            return float(pick(vals)) if vals else None

        out[name] = {"dances": len(items), "accent_precision_x_chance": over("accent_precision_x_chance"),
                     "accent_recall_x_chance": over("accent_recall_x_chance"),
                     "min_accent_x_chance": min(min(r["accent_precision_x_chance"], r["accent_recall_x_chance"])
                                                for r in scores),
                     "one_frame_steps": int(sum(r.get("one_frame_steps") or 0 for r in scores)),
                     "foot_skate_m_s": over("foot_skate_m_s"), "mocap_foot_skate_m_s": mocap.get("foot_skate_m_s"),
                     "foot_skate_vs_mocap": over("foot_skate_vs_mocap"),
                     "worst_foot_skate_vs_mocap": over("foot_skate_vs_mocap", max),
                     "joint_speed_p99_vs_mocap": over("joint_speed_p99_vs_mocap"),
                     "worst_joint_speed_p99_vs_mocap": over("joint_speed_p99_vs_mocap",
                                                            lambda v: max(v, key=lambda x: abs(x - 1.0))),
                     "root_travel_vs_mocap": over("root_travel_vs_mocap")}
    return out


def vocabulary(cfg: BenchConfig, db, progress: Progress | None = None) -> dict:
    rows = list_styles(db)
    genres = genre_minutes(rows)
    res = {"split": cfg.vocabulary_split, "genres": genres, "totals": totals(genres, rows)}
    res["tempo_map"] = tempo_map(db, range(60, 181))
    lo, hi = TEMPO_COVER_BPM
    short = [r["tempo_bpm"] for r in res["tempo_map"] if lo <= r["tempo_bpm"] <= hi
             and max([x["minutes"] for x in r["styles"]] or [0]) < TEMPO_COVER_MINUTES]
    res["tempo_cover"] = {"tempi": hi - lo + 1, "covered": hi - lo + 1 - len(short), "short": short,
                          "minutes": TEMPO_COVER_MINUTES}
    danced = []
    songs = _songs(cfg, progress)
    for i, song in enumerate(songs):
        if progress:
            progress(f"vocabulary: song {i + 1}/{len(songs)}: {song['name']}")
        clip, row = dance_song(song, db)
        danced.append((clip, row, song))
    # Every style of at least 2 minutes, forced on the generated songs whose tempo it covers with 2 minutes.
    chosen = {r["style"] for _, r, _ in danced}
    by_bpm = {r["tempo_bpm"]: r for r in res["tempo_map"]}
    for st in db.styles.values():
        if st.captured_s / 60 < MIN_MATERIAL_MINUTES or st.name in chosen:
            continue
        for song in [s for _, _, s in danced if s["set"] == "generated"]:
            row = by_bpm.get(float(min(max(round(song["music"].tempo_bpm), 60), 180)))
            if row and any(x["style"] == st.name for x in row["styles"]):
                clip, r = dance_song(song, db, st.name)
                danced.append((clip, r, song))
    res["songs"] = [r for _, r, _ in danced]
    longs = [r for r in res["songs"] if r["duration_s"] >= 0.95 * cfg.vocabulary_long_s and not r["forced"]]
    res["targets"] = {
        "under_2min": sum(r["material_minutes"] < MIN_MATERIAL_MINUTES for r in res["songs"] if not r["forced"]),
        "long_songs": len(longs),
        **{f"long_replay_{k}": (float(f([r[key] for r in longs])) if longs else None)
           for key, k, f in (("replayed_share", "max", max), ("replayed_share", "mean", np.mean),
                             ("replayed_share_strict", "strict_max", max),
                             ("longest_repeat_beats", "run_max", max))}}
    res["guards"] = guards(db, danced, progress)
    return res


def _fmt(x, d=2):
    return "-" if x is None else (f"{x:.{d}f}" if isinstance(x, float) else str(x))


def format_vocabulary(res: dict, before: dict | None = None) -> str:
    """The section's four tables; ``before``: the genres and totals of an older database to show beside."""
    old = (before or {}).get("genres", {})
    lines = ["Captured minutes per genre (mirrored takes apart, never counted as captured)",
             f"{'genre':<12}{'before':>8}{'captured':>10}{'mirrored':>10}  licence  styles"]
    for g in sorted(set(old) | set(res["genres"])):
        b, a = old.get(g), res["genres"].get(g)
        lines.append(f"{g:<12}{_fmt(b and b['minutes'], 1):>8}{_fmt(a and a['minutes'], 1):>10}"
                     f"{_fmt(a and a.get('mirrored_minutes'), 1):>10}  {', '.join((a or b)['licence'])}  "
                     f"{', '.join(a['styles']) if a else '(left out)'}")
    for label, t in (("before", (before or {}).get("totals")), ("now", res["totals"])):
        if t:
            lines.append(f"{label}: {t['minutes']:.1f} captured min (+{t.get('mirrored_minutes', 0.0):.1f} mirrored); "
                         f"styles >= 2 min: {t['styles_2min']}; genres >= 10 min: {', '.join(t['genres_10min']) or 'none'}")
    c = res["tempo_cover"]
    lines += ["", "Tempo map (captured minutes within 0.8-1.25x; full map: dancesynth styles --tempo-map)",
              f"{'bpm':>5}  {'chosen (level, minutes)':<38}  most material anywhere"]
    for r in res["tempo_map"][::10]:   # 60, 70, ... 180 bpm
        best = max(r["styles"], key=lambda x: x["minutes"]) if r["styles"] else None
        chosen = f"{r['chosen']} ({r['chosen_level']}, {r['chosen_minutes']:.1f})"
        lines.append(f"{r['tempo_bpm']:>5.0f}  {chosen:<38}  "
                     f"{(best['style'] + ' ' + best['level'] + ' ' + _fmt(best['minutes'], 1)) if best else 'none'}")
    lines.append(f"tempi {TEMPO_COVER_BPM[0]}-{TEMPO_COVER_BPM[1]} bpm with a style of >= {c['minutes']:g} min: "
                 f"{c['covered']} of {c['tempi']}; short: {c['short'] or 'none'}")
    lines += ["", f"Songs (the product's choice; 'strict': a mirrored take counts as its take; split {res['split']})",
              f"{'song':<34}{'bpm':>6}{'style':>18}{'level':>12}{'min':>6}{'replay':>8}{'strict':>8}{'run':>5}"]
    for r in res["songs"]:
        if not r["forced"]:
            lines.append(f"{r['song'][:33]:<34}{r['tempo_bpm']:>6.0f}{r['style']:>18}{r['level']:>12}"
                         f"{r['material_minutes']:>6.1f}{r['replayed_share']:>8.0%}{r['replayed_share_strict']:>8.0%}"
                         f"{r['longest_repeat_beats']:>5}")
    t = res["targets"]
    if t["long_songs"]:
        lines.append(f"songs danced from < 2 min: {t['under_2min']}; {t['long_songs']} long songs: replayed share max "
                     f"{t['long_replay_max']:.0%}, mean {t['long_replay_mean']:.0%} (target <= 10 %), strict max "
                     f"{t['long_replay_strict_max']:.0%}, longest run {t['long_replay_run_max']:.0f} beats")
    lines += ["", "Guards per style (streaming; x chance both ways >= 2.5; steps 0; skate <= mocap + 10 %; "
              "p99 joint speed within +-25 %; means, and the worst dance)",
              f"{'style':<18}{'dances':>7}{'prec x':>8}{'rec x':>7}{'min x':>7}{'steps':>6}{'skate':>7}{'mocap':>7}"
              f"{'skate/m':>8}{'worst':>7}{'p99/m':>7}{'worst':>7}{'travel':>7}"]
    for name, g in res["guards"].items():
        lines.append(f"{name:<18}{g['dances']:>7}{_fmt(g['accent_precision_x_chance']):>8}"
                     f"{_fmt(g['accent_recall_x_chance']):>7}{_fmt(g['min_accent_x_chance']):>7}{g['one_frame_steps']:>6}"
                     f"{_fmt(g['foot_skate_m_s'], 3):>7}{_fmt(g['mocap_foot_skate_m_s'], 3):>7}"
                     f"{_fmt(g['foot_skate_vs_mocap']):>8}{_fmt(g['worst_foot_skate_vs_mocap']):>7}"
                     f"{_fmt(g['joint_speed_p99_vs_mocap']):>7}{_fmt(g['worst_joint_speed_p99_vs_mocap']):>7}"
                     f"{_fmt(g['root_travel_vs_mocap']):>7}")
    return "\n".join(lines)

"""Global structure (Aristidou et al.): how close each engine's dance is to its genre.

Six measurements, all on the salsa genre (the one with enough dances for a template:
26 clips; the neural model is trained on it):

- **Table I**: chi2 (eq. 11) between a dance's motif signature and the salsa template,
  for the raw mocap dances, the streaming graph engine with and without the signature
  term, the global DP, a random walk, the choreography mixer and the neural generator.
  Every dance is measured the same way: its motion is cut at the beats it dances to
  (the beat grid; a mocap clip at its own motion beats), each word re-embedded and
  assigned its motif. A mocap clip is compared with the template of the *other*
  salsa clips (the template is their mean; in-sample it would be judged against
  itself). Where an engine knows which motif it danced, that chi2 is kept too.
- **Fig. 12**: chi2 of the first t seconds against t, several seeds, on the longest song.
- **Metrics**: every engine's beat alignment, intensity and smoothness (``evaluate``),
  beside the raw mocap's.
- **Re-creation** (§5.5.1): each clip of one salsa style in turn is the reference,
  held out of the style, and re-created on a song; the share of beats whose motif
  equals the reference's -- as danced, and as found again in the output.
- **Liveliness** (issue 16): per dance and per engine, beside the raw salsa clips (at
  30 fps): frames with a wrist inside the head, root travel per minute, p99 joint
  speed (both also / the mocap's), one-frame joint steps over 30°, the share of beats
  whose motif found again equals the planned one, accent precision and recall / chance.
- **Neural realism**: FID_k and FID_g of the neural and the streaming dances against the
  salsa clips the neural model never saw (its ``held_out_clips``), the streaming engine
  dancing from a database without them; and the neural generator's targets, pass or fail.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from .common import MUSIC_DIR, BenchConfig, Progress, load_song, table
from .dances import GENRE, MOCAP_FPS, engine_dances, found_motifs, liveliness, plan_followed
from .quality import at_fps, mean_scores

ENGINES = ("mocap", "streaming", "signature", "global", "random_walk", "choreography", "neural")
TITLES = {"mocap": "raw mocap*", "streaming": "streaming (Xu)", "signature": "streaming + signature",
          "global": "global DP", "random_walk": "random walk", "choreography": "choreography mixer",
          "neural": "neural (acLSTM)", "network": "neural, network alone"}
ACCENT_X_CHANCE = ("accent_precision_x_chance", "accent_recall_x_chance", "visible_accent_precision_x_chance",
                   "visible_accent_recall_x_chance")
METRIC_KEYS = ("hit_rate", "bas_music", "aligned_beat_ratio", *ACCENT_X_CHANCE, "intensity_spearman",
               "transition_jump_vs_mocap_p99", "jump_p99_vs_mocap", "jerk_vs_mocap", "foot_skate_m_s", "pfc")
#: Per dance (and per mocap clip), what ``liveliness`` measures; engines' means beside the mocap's.
LIVE_KEYS = ("hand_in_head", "root_travel_m_per_min", "joint_speed_p99", "one_frame_steps")
NOTES = ("chi2: eq. (11) between the signature of the motifs found again in the motion (cut at the beats it "
         "dances to, re-embedded, assigned) and the salsa template; 'danced': the motifs the engine chose, where "
         "it knows them",
         "* raw mocap: each salsa clip at its own motion beats, against the template of the other salsa clips "
         "(leave one out); 'danced' for the mocap is the same clip against the template it is part of")


def _chi2_ids(model, template, ids) -> float | None:
    from ..motion.motifs import chi2

    ids = np.asarray(ids)
    ids = ids[ids >= 0]
    return chi2(template, np.bincount(ids, minlength=model.k)) if ids.size else None


def _engines(cfg: BenchConfig) -> tuple[tuple[str, ...], dict | None, str | None]:
    """The engines to run; the neural model's info (None without it) and why it is left out (None if it runs)."""
    names = [e for e in ENGINES if e != "mocap" and e in cfg.structure_engines]
    info, why = None, None
    if "neural" in names:
        from ..errors import ModelError

        try:  # a missing or foreign model (or no torch) leaves the other engines' numbers
            from ..engines.neural.store import SHIPPED, load_model

            info = load_model(SHIPPED / f"{GENRE}.pt").info
        except (ImportError, ModelError) as exc:
            why = f"{type(exc).__name__}: {exc}"
        if why:
            names.remove("neural")
    return tuple(names), info, why


def mocap_chi2(db, model) -> list[dict]:
    """Every salsa clip: chi2 against the leave-one-out template and the in-sample one."""
    from ..motion.motifs import chi2

    styles = db.styles_of(GENRE)
    clips = [(st, c) for st in styles for c in range(st.n_clips)]
    ids = []
    for st, c in clips:
        clip = st.clip(c)
        found = found_motifs(clip, model, clip.meta["beat_frames"] / clip.fps)
        ids.append(found[found >= 0])
    sigs = np.array([np.bincount(i, minlength=model.k) / len(i) for i in ids])
    template = model.templates[GENRE]
    rows = []
    for (st, c), sig, i in zip(clips, sigs, ids):
        loo = (len(sigs) * template - sig) / (len(sigs) - 1)   # the template is the mean of the clips' signatures
        rows.append({"clip": st.clip_names[c], "style": st.name, "words": int(len(i)),
                     "chi2": chi2(np.maximum(loo, 0.0), sig), "chi2_in_sample": chi2(template, sig)})
    return rows


def structure(cfg: BenchConfig, db, progress: Progress | None = None, out_dir: Path | None = None) -> dict:
    from ..motion.motifs import load_motif_model
    from ..eval.evaluate import evaluate

    model = load_motif_model(db)
    template = model.templates[GENRE]
    engines, neural_info, neural_skipped = _engines(cfg)
    mocap_rows = mocap_chi2(db, model)
    refs = {st.name: [at_fps(st.clip(c), MOCAP_FPS) for c in range(st.n_clips)] for st in db.styles_of(GENRE)}
    mocap_live = [{"clip": c.meta["name"], **liveliness(c)} for clips in refs.values() for c in clips]
    live_ref = {k: _mean(r[k] for r in mocap_live) for k in LIVE_KEYS}
    songs = cfg.structure_songs or tuple(sorted(p.name for p in MUSIC_DIR.glob("*.ogg")))
    per_dance, danced_songs = [], []
    for i, song in enumerate(songs):
        music = load_song(song, cfg.structure_max_s)
        if music.duration_s < cfg.structure_min_s:
            continue
        danced_songs.append((Path(song).name, music))
        for seed in range(cfg.structure_seeds):
            if progress:
                progress(f"structure: {Path(song).name} ({i + 1}/{len(songs)}), seed {seed}")
            for name, clip in engine_dances(music, db, seed, engines).items():
                grid = clip.provenance.grid_times_s
                found = found_motifs(clip, model, grid)
                jumps = np.asarray(clip.provenance.transition_times_s, dtype=float)
                scores = evaluate(clip, music_beats_s=music.beat_times_s, music_loudness_db=music.intensity_db,
                                  transitions_s=jumps[(jumps >= 0) & (jumps <= clip.duration_s)],
                                  warp_rates=clip.provenance.warp_rates, mocap=refs[clip.provenance.style])
                danced = clip.provenance.motifs.get("motif_ids")
                live = liveliness(clip)
                live.update(root_travel_vs_mocap=_ratio(live["root_travel_m_per_min"],
                                                        live_ref["root_travel_m_per_min"]),
                            joint_speed_p99_vs_mocap=_ratio(live["joint_speed_p99"], live_ref["joint_speed_p99"]),
                            plan_followed=plan_followed(clip, found))
                per_dance.append({"song": Path(song).name, "seed": seed, "engine": name, "style": clip.provenance.style,
                                  "duration_s": music.duration_s, "words": int(np.sum(found >= 0)),
                                  "chi2": _chi2_ids(model, template, found),
                                  "chi2_danced": None if danced is None else _chi2_ids(model, template, danced),
                                  "wall_s": clip.meta["bench_wall_s"], "liveliness": live,
                                  "scores": {k: scores.get(k) for k in METRIC_KEYS}})
    table_i = {"mocap": {"chi2": float(np.mean([r["chi2"] for r in mocap_rows])),
                         "chi2_danced": float(np.mean([r["chi2_in_sample"] for r in mocap_rows])),
                         "dances": len(mocap_rows)}}
    for name in engines:
        rows = [r for r in per_dance if r["engine"] == name]
        table_i[name] = {"chi2": _mean(r["chi2"] for r in rows), "chi2_danced": _mean(r["chi2_danced"] for r in rows),
                         "chi2_min": _reduce((r["chi2"] for r in rows), np.min),
                         "chi2_max": _reduce((r["chi2"] for r in rows), np.max),
                         "dances": len(rows), "wall_s": _mean(r["wall_s"] for r in rows)}
    mocap_metrics = _mocap_metrics(db, refs, cfg.mocap_max_clips)
    metrics = {"mocap": mocap_metrics}
    metrics.update({name: mean_scores([r["scores"] for r in per_dance if r["engine"] == name]) for name in engines})
    live = {"mocap": {**live_ref, "root_travel_vs_mocap": 1.0, "joint_speed_p99_vs_mocap": 1.0,
                      "one_frame_steps_total": int(sum(r["one_frame_steps"] for r in mocap_live)),
                      "dances": len(mocap_live), "plan_followed": None}}
    for name in engines:
        rows = [r["liveliness"] for r in per_dance if r["engine"] == name]
        live[name] = {**mean_scores(rows), "one_frame_steps_total": int(sum(r["one_frame_steps"] for r in rows)),
                      "dances": len(rows)}
    for name in live:  # the accents beside chance, as the metrics table has them
        live[name].update({k: metrics[name].get(k) for k in ACCENT_X_CHANCE})
    s = {"genre": GENRE, "k": model.k, "engines": ["mocap", *engines], "table_i": table_i, "dances": per_dance,
         "mocap_clips": mocap_rows, "metrics": metrics, "liveliness": live, "mocap_liveliness": mocap_live,
         "neural_skipped": neural_skipped,
         "neural_realism": neural_realism(cfg, db, neural_info, danced_songs, progress) if "neural" in engines
         else {"skipped": "the neural engine " + ("could not run" if neural_skipped else "was not selected")},
         "fig12": fig12(cfg, db, model, engines, progress, out_dir=out_dir),
         "recreation": recreation(cfg, db, model, progress), "notes": list(NOTES)}
    s["neural_targets"] = neural_targets(s)
    return s


# The neural generator's targets (issue 16): (name, how to read it from the section, lowest, highest).
NEURAL_TARGETS = (
    ("chi2 to the salsa template", lambda s: s["table_i"]["neural"]["chi2"], None, 0.30),
    ("beats whose motif follows the plan", lambda s: s["liveliness"]["neural"]["plan_followed"], 0.5, None),
    ("frames with a hand in the head", lambda s: s["liveliness"]["neural"]["hand_in_head"], None, 0.02),
    ("root travel / mocap's", lambda s: s["liveliness"]["neural"]["root_travel_vs_mocap"], 0.7, 1.3),
    ("p99 joint speed / mocap's", lambda s: s["liveliness"]["neural"]["joint_speed_p99_vs_mocap"], 0.7, 1.3),
    ("one-frame joint steps > 30°, all dances", lambda s: s["liveliness"]["neural"]["one_frame_steps_total"],
     None, 0),
    ("FID_k / streaming's (held-out mocap)", lambda s: s["neural_realism"]["fid_k_ratio"], None, 1.5),
    ("FID_g / streaming's (held-out mocap)", lambda s: s["neural_realism"]["fid_g_ratio"], None, 1.5),
    ("accent precision / chance", lambda s: s["liveliness"]["neural"]["accent_precision_x_chance"], 2.0, None),
    ("accent recall / chance", lambda s: s["liveliness"]["neural"]["accent_recall_x_chance"], 2.0, None),
)


def neural_targets(s: dict) -> dict:
    """Each neural target: its value, bounds and whether it is met (None where this run did not measure it)."""
    out = {}
    for name, read, lo, hi in NEURAL_TARGETS:
        try:
            value = read(s)
        except (KeyError, TypeError):
            value = None
        met = None if value is None else bool((lo is None or value >= lo) and (hi is None or value <= hi))
        out[name] = {"value": value, "min": lo, "max": hi, "met": met}
    return out


def held_out_database(db, held) -> tuple:
    """``(db without the clips named in held, those clips at MOCAP_FPS)``, for the genre's styles.

    The shipped motif model is kept (``db.source``): the streaming engine only counts motifs with it.
    """
    from ..motion.database import MotionDatabase

    styles, reference = {}, []
    for st in db.styles_of(GENRE):
        out = [c for c in range(st.n_clips) if st.clip_names[c] in held]
        reference += [at_fps(st.clip(c), MOCAP_FPS) for c in out]
        for c in reversed(out):  # the last first: without_clip renumbers the clips after it
            st = st.without_clip(c)
        styles[st.name] = st
    return MotionDatabase(styles, db.source), reference


def neural_realism(cfg: BenchConfig, db, info: dict | None, songs: list, progress) -> dict:
    """FID_k / FID_g of the neural and the streaming dances against the salsa clips the neural model never saw.

    The streaming engine dances from a database without those clips, so that neither
    engine has seen the reference (``bench.realism`` does the same with random splits).
    """
    from ..errors import InputError
    from ..eval.realism import realism_scores
    from .realism import NOTE

    held = set((info or {}).get("held_out_clips") or ())
    if not held:
        return {"skipped": "the neural model names no held-out clips"}
    only, reference = held_out_database(db, held)
    if not reference:
        return {"skipped": f"held-out clips {sorted(held)} are not in this database"}
    if not songs:
        return {"skipped": "no song was danced"}
    generated = {"neural": [], "network": [], "streaming": []}
    for name, music in songs:
        for seed in range(cfg.structure_seeds):
            if progress:
                progress(f"structure: neural realism on {name}, seed {seed}")
            for engine, clip in engine_dances(music, only, seed, tuple(generated)).items():
                generated[engine].append(clip)
    try:
        scores = realism_scores(generated, reference, window_s=cfg.realism_window_s)
    except InputError as exc:  # too little held-out motion or too short songs for one window
        return {"skipped": str(exc)}
    keep = ("fid_k", "fid_g", "div_k", "div_g", "n_generated", "n_reference")
    return {"held_out": [c.meta["name"] for c in reference], "reference_s": float(sum(c.duration_s for c in reference)),
            "dances": len(generated["neural"]), "scores": {e: {k: scores[e][k] for k in keep} for e in scores},
            "fid_k_ratio": _ratio(scores["neural"]["fid_k"], scores["streaming"]["fid_k"]),
            "fid_g_ratio": _ratio(scores["neural"]["fid_g"], scores["streaming"]["fid_g"]),
            "network_fid_ratios": [_ratio(scores["network"][k], scores["streaming"][k]) for k in ("fid_k", "fid_g")],
            "note": NOTE}


def _reduce(values, how=np.mean):
    """``how`` of the values that are not None (None when there are none)."""
    v = [x for x in values if x is not None]
    return float(how(v)) if v else None


def _mean(values):
    return _reduce(values)


def _ratio(a, b) -> float | None:
    return None if a is None or b is None or not b > 0 else float(a / b)


def _mocap_metrics(db, refs: dict, max_clips: int | None) -> dict:
    """The raw salsa clips' own metrics against their motion beats (as the quality table's mocap row)."""
    from .quality import mocap_scores
    from ..eval.evaluate import evaluate

    rows = [mocap_scores(evaluate, clips, max_clips)["mean"] for clips in refs.values()]
    return {k: mean_scores(rows).get(k) for k in METRIC_KEYS}


def fig12(cfg: BenchConfig, db, model, engines, progress, *, out_dir: Path | None) -> dict:
    """chi2 of the dance so far against time, per engine and seed, on one song (the paper's Fig. 12)."""
    song = cfg.fig12_song or max((p.name for p in MUSIC_DIR.glob("*.ogg")),
                                 key=lambda n: (MUSIC_DIR / n).stat().st_size)
    music = load_song(song, cfg.structure_max_s)
    template = model.templates[GENRE]
    step_s = cfg.fig12_step_s
    times = np.arange(step_s, music.duration_s + 1e-9, step_s)
    curves = {}
    for seed in range(cfg.fig12_seeds):
        if progress:
            progress(f"structure: Fig. 12 on {song}, seed {seed}")
        for name, clip in engine_dances(music, db, seed, [e for e in engines if e in cfg.fig12_engines]).items():
            grid = clip.provenance.grid_times_s
            found = found_motifs(clip, model, grid)
            starts = grid[:len(found)]
            curves.setdefault(name, []).append([_chi2_ids(model, template, found[starts < t]) for t in times])
    result = {"song": song, "duration_s": music.duration_s, "times_s": times.tolist(), "curves": curves}
    if out_dir is not None and curves:
        result["plot"] = str(plot_fig12(result, Path(out_dir) / "fig12_chi2.png"))
    return result


def plot_fig12(result: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 4))
    t = np.asarray(result["times_s"])
    for i, (name, runs) in enumerate(result["curves"].items()):
        for j, run in enumerate(runs):
            y = np.array([np.nan if v is None else v for v in run], dtype=float)
            ax.plot(t, y, color=f"C{i}", alpha=0.8, lw=1.2, label=TITLES[name] if j == 0 else None)
    ax.axhline(0.2, color="grey", ls=":", lw=1)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("chi2 to the salsa template")
    ax.set_title(f"Signature of the dance so far ({Path(result['song']).stem[:40]}; one line per seed)")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def recreation(cfg: BenchConfig, db, model, progress) -> dict:
    """§5.5.1 on held-out dances: each clip of the style is the reference and is left out of it."""
    from ..api import DanceConfig
    from ..engines.choreography.engine import choreography_dance
    from ..io.bvh import read_bvh, write_bvh
    from ..motion.database import MotionDatabase
    from ..motion.words import clip_words

    st = db.styles[cfg.recreate_style]
    music = load_song(cfg.recreate_song, cfg.structure_max_s)
    chosen = range(st.n_clips) if cfg.recreate_clips is None else range(min(cfg.recreate_clips, st.n_clips))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for c in chosen:
            if progress:
                progress(f"structure: re-creating {st.clip_names[c]} ({c + 1}/{len(chosen)})")
            ref = Path(tmp) / f"{st.clip_names[c]}.bvh"
            write_bvh(ref, st.clip(c))
            held_out = MotionDatabase({st.name: st.without_clip(c)}, db.source)
            reference = read_bvh(ref)
            clip, run = choreography_dance(music, held_out, DanceConfig(recreate=ref, style=st.name), timings={},
                                           motif_model=model, reference=reference)
            wanted = np.resize(model.assign(clip_words(reference).features), len(run.motifs["motif_ids"]))
            found = found_motifs(clip, model, run.grid_times_s)
            rows.append({"reference": st.clip_names[c], "beats": int(len(wanted)),
                         "danced": float(np.mean(run.motifs["motif_ids"] == wanted)),
                         "found_again": float(np.mean((found == wanted[:len(found)])[found >= 0]))})
    return {"style": st.name, "song": cfg.recreate_song, "rows": rows,
            "danced_mean": _mean(r["danced"] for r in rows), "found_again_mean": _mean(r["found_again"] for r in rows),
            "found_again_min": _reduce((r["found_again"] for r in rows), np.min)}


def format_structure(s: dict) -> str:
    from ..eval.evaluate import format_table

    t = s["table_i"]
    rows = [[TITLES[e], t[e]["dances"], t[e]["chi2"], t[e].get("chi2_min"), t[e].get("chi2_max"),
             t[e].get("chi2_danced")] for e in s["engines"]]
    out = [table(f"Table I: chi2 to the {s['genre']} template (K = {s['k']} motifs), mean over dances",
                 ["engine", "dances", "chi2", "min", "max", "danced"], rows, [0, 0, 3, 3, 3, 3], s["notes"])]
    f = s["fig12"]
    if f.get("curves"):
        marks = [i for i, x in enumerate(f["times_s"]) if x in (30.0, 60.0) or i == len(f["times_s"]) - 1]
        head = ["engine"] + [f"{f['times_s'][i]:.0f} s" for i in marks]
        body = [[TITLES[n]] + [_mean(run[i] for run in runs) for i in marks] for n, runs in f["curves"].items()]
        out += ["", table(f"Fig. 12: chi2 of the dance so far on {f['song']} (mean over "
                          f"{len(next(iter(f['curves'].values())))} seeds)", head, body, [0] + [3] * len(marks),
                          [f"plot: {f['plot']}"] if f.get("plot") else [])]
    out += ["", "Beat alignment, intensity and smoothness (mean over dances; mocap: its own motion beats)",
            format_table({TITLES[e]: s["metrics"][e] for e in s["engines"]})]
    out += ["", format_liveliness(s)]
    r = s["recreation"]
    if r["rows"]:
        out += ["", table(f"Re-creation of held-out dances (§5.5.1): {r['style']} clips re-created on {r['song']}",
                          ["reference", "beats", "motif as danced", "found again in the motion"],
                          [[x["reference"], x["beats"], x["danced"], x["found_again"]] for x in r["rows"]]
                          + [["mean", None, r["danced_mean"], r["found_again_mean"]]], [0, 0, 2, 2])]
    return "\n".join(out)


PERCENT_TARGETS = ("beats whose motif follows the plan", "frames with a hand in the head")


def _pct(v):
    return None if v is None else 100.0 * v


def format_liveliness(s: dict) -> str:
    """The liveliness table, the neural realism beside the streaming engine's, and the neural targets."""
    live = s["liveliness"]
    keys = ("hand_in_head", "root_travel_m_per_min", "root_travel_vs_mocap", "joint_speed_p99",
            "joint_speed_p99_vs_mocap", "one_frame_steps", "plan_followed", *ACCENT_X_CHANCE)
    rows = [[TITLES[e], live[e]["dances"]] + [_pct(live[e].get(k)) if k in ("hand_in_head", "plan_followed")
                                              else live[e].get(k) for k in keys] for e in s["engines"]]
    notes = ["hand: a wrist within 8 cm of the head's centre; steps: isolated one-frame joint turns over 30° "
             "(eval.artefacts), per dance; plan: beats whose motif found again equals the one the engine planned "
             "(neural: motif_plan; signature-following engines: motif_ids)",
             "* raw mocap: every salsa clip at 30 fps, mean per clip (its steps are capture glitches; accents "
             "against its own motion beats)"]
    if s.get("neural_skipped"):
        notes.append(f"neural left out: {s['neural_skipped']}")
    out = [table("Liveliness and artefacts (mean per dance)",
                 ["engine", "dances", "hand in head %", "root m/min", "/ mocap", "p99 speed m/s", "/ mocap",
                  "1-frame steps", "plan followed %", "precision / chance", "recall / chance",
                  "visible: precision / chance", "recall / chance"],
                 rows, [0, 0, 2, 1, 2, 2, 2, 1, 1, 2, 2, 2, 2], notes)]
    r = s["neural_realism"]
    if "skipped" in r:
        out += ["", f"Neural realism vs held-out mocap: skipped ({r['skipped']})"]
    else:
        sc = r["scores"]
        body = [[TITLES[e]] + [sc[e][k] for k in ("fid_k", "fid_g", "div_k", "div_g", "n_generated")]
                for e in ("neural", "network", "streaming") if e in sc]
        body.append(["neural / streaming", r["fid_k_ratio"], r["fid_g_ratio"], None, None, None])
        if "network_fid_ratios" in r:
            body.append(["network alone / streaming", *r["network_fid_ratios"], None, None, None])
        out += ["", table(f"Neural realism vs the salsa mocap it never saw ({', '.join(r['held_out'])}: "
                          f"{r['reference_s']:.0f} s, {sc['neural']['n_reference']} windows), {r['dances']} dances "
                          "per engine", ["generated", "FID_k", "FID_g", "Div_k", "Div_g", "windows"], body,
                          [0, 2, 2, 2, 2, 0], ["streaming: from a database without the held-out clips; network alone: "
                                               "the neural engine without its spread post-filter (--paper)",
                                               r["note"]])]
    body = []
    for name, t in s["neural_targets"].items():
        scale = _pct if name in PERCENT_TARGETS else (lambda v: v)
        lo, hi = scale(t["min"]), scale(t["max"])
        bound = f"{lo:g}-{hi:g}" if lo is not None and hi is not None else (
            f">= {lo:g}" if lo is not None else f"<= {hi:g}")
        body.append([name + (" %" if name in PERCENT_TARGETS else ""), bound, scale(t["value"]),
                     "-" if t["met"] is None else ("pass" if t["met"] else "FAIL")])
    out += ["", table("Neural generator targets (issue 16)", ["target", "bound", "neural", "met"], body,
                      [0, 0, 3, 0])]
    return "\n".join(out)

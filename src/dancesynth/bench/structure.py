"""Global structure (Aristidou et al.): how close each engine's dance is to its genre.

Four measurements, all on the salsa genre (the one with enough dances for a template:
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
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from .common import MUSIC_DIR, BenchConfig, Progress, load_song, table
from .quality import at_fps, mean_scores, walk_dance

GENRE = "salsa"
ENGINES = ("mocap", "streaming", "signature", "global", "random_walk", "choreography", "neural")
TITLES = {"mocap": "raw mocap*", "streaming": "streaming (Xu)", "signature": "streaming + signature",
          "global": "global DP", "random_walk": "random walk", "choreography": "choreography mixer",
          "neural": "neural (acLSTM)"}
METRIC_KEYS = ("hit_rate", "bas_music", "aligned_beat_ratio", "intensity_spearman", "transition_jump_vs_mocap_p99",
               "jump_p99_vs_mocap", "jerk_vs_mocap", "foot_skate_m_s", "pfc")
NOTES = ("chi2: eq. (11) between the signature of the motifs found again in the motion (cut at the beats it "
         "dances to, re-embedded, assigned) and the salsa template; 'danced': the motifs the engine chose, where "
         "it knows them",
         "* raw mocap: each salsa clip at its own motion beats, against the template of the other salsa clips "
         "(leave one out); 'danced' for the mocap is the same clip against the template it is part of")


def found_motifs(clip, model, beat_times_s) -> np.ndarray:
    """The motif of every beat interval, found again in the motion: words cut at the beats, re-embedded."""
    from ..motion.motifs import beat_frames_at
    from ..motion.words import clip_words

    return model.assign(clip_words(clip, beat_frames_at(clip, beat_times_s)).features)


def _chi2_ids(model, template, ids) -> float | None:
    from ..motion.motifs import chi2

    ids = np.asarray(ids)
    ids = ids[ids >= 0]
    return chi2(template, np.bincount(ids, minlength=model.k)) if ids.size else None


def engine_dances(music, db, seed: int, engines, style: str | None = GENRE) -> dict:
    """Each engine's dance of ``music`` in ``style`` (None: the product's choice), with the wall time it took."""
    from ..api import dance
    from ..engines.graph.engine import EngineConfig
    from ..engines.graph.meta_graph import GraphConfig

    kinds = {"streaming": dict(follow_signature=True, render=EngineConfig(signature_weight=0.0)),  # counts only
             "lookahead": dict(follow_signature=True, render=EngineConfig(signature_weight=0.0), lookahead_s=5.0),
             "signature": dict(follow_signature=True), "global": dict(engine="global"),
             "choreography": dict(engine="choreography"), "neural": dict(engine="neural"),
             "paper": dict(graph=GraphConfig.paper(), render=EngineConfig.paper())}  # Xu et al. as printed
    out = {}
    for name in engines:
        t = time.perf_counter()
        if name == "random_walk":
            ref = out.get("streaming") or dance(music, database=db, style=style, seed=seed)
            clip = walk_dance(db.styles[ref.provenance.style], music, subdivide=ref.provenance.summary["subdivide"],
                              seed=seed, fps=ref.fps)
        elif name in kinds:
            clip = dance(music, database=db, style=style, seed=seed, **kinds[name])
        else:
            continue
        out[name] = clip
        clip.meta.setdefault("bench_wall_s", time.perf_counter() - t)
    return out


def _engines(cfg: BenchConfig) -> tuple[str, ...]:
    from ..engines.neural.store import SHIPPED

    names = [e for e in ENGINES if e != "mocap"]
    try:
        import torch  # noqa: F401 -- the neural engine needs it
    except ImportError:
        names.remove("neural")
    if "neural" in names and not (SHIPPED / f"{GENRE}.pt").is_file():
        names.remove("neural")
    return tuple(n for n in names if n in cfg.structure_engines)


def mocap_chi2(db, model) -> list[dict]:
    """Every salsa clip: chi2 against the leave-one-out template and the in-sample one."""
    from ..motion.motifs import chi2

    styles = db.styles_of(GENRE)
    clips = [(st, c) for st in styles for c in range(st.n_clips)]
    ids = []
    for st, c in clips:
        clip = st.clip(c)
        ids.append(found_motifs(clip, model, clip.meta["beat_frames"] / clip.fps))
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
    engines = _engines(cfg)
    mocap_rows = mocap_chi2(db, model)
    refs = {st.name: [at_fps(st.clip(c), 30.0) for c in range(st.n_clips)] for st in db.styles_of(GENRE)}
    songs = cfg.structure_songs or tuple(sorted(p.name for p in MUSIC_DIR.glob("*.ogg")))
    per_dance = []
    for i, song in enumerate(songs):
        music = load_song(song, cfg.structure_max_s)
        if music.duration_s < cfg.structure_min_s:
            continue
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
                per_dance.append({"song": Path(song).name, "seed": seed, "engine": name, "style": clip.provenance.style,
                                  "duration_s": music.duration_s, "words": int(len(found)),
                                  "chi2": _chi2_ids(model, template, found),
                                  "chi2_danced": None if danced is None else _chi2_ids(model, template, danced),
                                  "wall_s": clip.meta["bench_wall_s"],
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
    return {"genre": GENRE, "k": model.k, "engines": ["mocap", *engines], "table_i": table_i, "dances": per_dance,
            "mocap_clips": mocap_rows, "metrics": metrics,
            "fig12": fig12(cfg, db, model, engines, progress, out_dir=out_dir),
            "recreation": recreation(cfg, db, model, progress), "notes": list(NOTES)}


def _reduce(values, how=np.mean):
    """``how`` of the values that are not None (None when there are none)."""
    v = [x for x in values if x is not None]
    return float(how(v)) if v else None


def _mean(values):
    return _reduce(values)


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
                         "found_again": float(np.mean(found == wanted[:len(found)]))})
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
    r = s["recreation"]
    if r["rows"]:
        out += ["", table(f"Re-creation of held-out dances (§5.5.1): {r['style']} clips re-created on {r['song']}",
                          ["reference", "beats", "motif as danced", "found again in the motion"],
                          [[x["reference"], x["beats"], x["danced"], x["found_again"]] for x in r["rows"]]
                          + [["mean", None, r["danced_mean"], r["found_again_mean"]]], [0, 0, 2, 2])]
    return "\n".join(out)

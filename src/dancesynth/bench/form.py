"""Does the dance follow the song's form? Every engine with ``--repeat off`` and ``same``.

On the generated songs of known form (``groundtruth.structure_specs``: verse / chorus /
bridge patterns whose repeats change instruments; the split of ``BenchConfig.groundtruth_split``,
"test" reported, "tune" where the constants were chosen) each engine dances the song from its
audio, as a user's would be, once without the form and once with it. Per dance:

- the structure-consistency score (``eval.form``: the music's bar self-similarity against the
  dance's), beside its chance level (the same dance, bars shuffled within sections);
- the share of the beats the form paired that danced what their pair did (the engine's own
  account: the same graph node, word or motif);
- the guards: accents against the true beats (x chance, visible ones too), one-frame steps,
  the largest transition jump and the foot skating against the style's mocap, FID_k and Div_k
  against the style's clips.

A random walk on the same graph, which knows no form, is the baseline; the same walk with
every paired beat showing its pair's frames (``engines.form.replay_motion``: exact replays of
real mocap, re-timed and blended in) is what replaying alone reaches on this score, and what
it costs FID_k and Div_k. Each song is danced once per ``BenchConfig.form_seeds`` (the default dance and
two seeds: one dance's Div_k and FID_k swing by 10-20 %); means over songs and seeds.
"""

from __future__ import annotations

import numpy as np

from .common import BenchConfig, Progress, split_name, table
from .quality import at_fps, mean_scores

ENGINES = ("streaming", "global", "choreography", "neural")
KEYS = ("form_score", "form_chance", "replayed_share", "accent_precision_x_chance", "accent_recall_x_chance",
        "visible_accent_precision_x_chance", "visible_accent_recall_x_chance", "one_frame_steps",
        "transition_jump_vs_mocap_p99", "foot_skate_vs_mocap", "fid_k", "div_k", "div_k_ref")
LABELS = {"form_score": "structure consistency (music vs dance bar similarity, r)",
          "form_chance": "  chance (bars shuffled within sections)",
          "replayed_share": "paired beats danced as their pair (the engine's account)",
          "accent_precision_x_chance": "accent precision × chance", "accent_recall_x_chance": "accent recall × chance",
          "visible_accent_precision_x_chance": "visible accent precision × chance",
          "visible_accent_recall_x_chance": "visible accent recall × chance",
          "one_frame_steps": "one-frame joint steps > 30° (total over every dance)",
          "transition_jump_vs_mocap_p99": "largest transition jump / mocap p99",
          "foot_skate_vs_mocap": "foot skating / the style's mocap's (guard ≤ 1.1)",
          "fid_k": "FID_k against the style's clips", "div_k": "Div_k", "div_k_ref": "  the clips' own Div_k"}


def section_scores(ref, est) -> tuple[float, float]:
    """mir_eval's boundary F-measure at +-0.5 s (the song's start and end trimmed) and pairwise label F of
    sections ``est`` against ``ref``, each a list of (start s, end s, label)."""
    import mir_eval

    ref_i = np.array([[a, b] for a, b, _ in ref])
    est_i = np.array([[a, b] for a, b, _ in est])
    est_i[-1, 1] = ref_i[-1, 1] = max(ref_i[-1, 1], est_i[-1, 1])
    f = mir_eval.segment.detection(ref_i, est_i, window=0.5, trim=True)[2]
    pw = mir_eval.segment.pairwise(ref_i, [x[2] for x in ref], est_i, [x[2] for x in est])[2]
    return float(f), float(pw)


def section_chance(ref, est, bar_s, rng) -> tuple[float, float]:
    """``section_scores`` of random sections like ``est``'s: as many, starting on random 4-bar lines,
    labelled at random among as many labels."""
    lines = bar_s[4:-1:4]
    k = min(len(est) - 1, len(lines))
    starts = np.r_[0.0, np.sort(rng.choice(lines, size=k, replace=False))] if k else np.array([0.0])
    ends = np.r_[starts[1:], ref[-1][1]]
    labels = rng.integers(0, len({x[2] for x in est}), size=len(starts))
    return section_scores(ref, [(a, b, str(lab)) for a, b, lab in zip(starts, ends, labels)])


def form_songs(cfg: BenchConfig, progress: Progress | None = None) -> list[dict]:
    """The generated songs of known form, analysed (with their structure) from their audio."""
    from ..api import analyse
    from .accents import _default_cache
    from .groundtruth import ground_truth_set, structure_specs

    songs = ground_truth_set(cfg.groundtruth_dir or _default_cache(),
                             specs=list(cfg.form_specs or structure_specs(cfg.groundtruth_split)), progress=progress)
    return [{"name": s.name, "path": s.audio_path, "music": analyse(s.audio_path), "beats": s.beats_s,
             "sections": s.sections} for s in songs]


def _walk_fit(music, db) -> tuple[str, int]:
    """The style and metrical level the product dances ``music`` in: the random walk's, for a fair baseline."""
    from ..api import dance

    ours = dance(music, database=db, repeat="off")
    return ours.provenance.style, ours.provenance.summary["subdivide"]


def _dance(name: str, music, db, repeat: str, seed: int | None, walk_fit: tuple[str, int] | None):
    from ..api import dance
    from ..engines.beatgrid import beat_grid
    from ..engines.form import form_plan, replay_motion
    from .quality import walk_dance

    if name != "random_walk":
        return dance(music, database=db, engine=name, repeat=repeat, seed=seed)
    style, sub = walk_fit
    walk = walk_dance(db.styles[style], music, subdivide=sub, seed=seed or 0)
    if repeat == "off":
        return walk
    grid = beat_grid(music, subdivide=sub).times_s
    replayed, _ = replay_motion(walk, grid, form_plan(music, grid, repeat))
    replayed.provenance = walk.provenance
    return replayed


def _scores(clip, song: dict, db, refs: dict) -> dict:
    from ..eval.artefacts import one_frame_steps
    from ..eval.evaluate import evaluate, mocap_reference
    from ..eval.form import form_score
    from ..eval.realism import realism

    music, prov = song["music"], clip.provenance
    style = db.styles[prov.style]
    if style.name not in refs:
        clips = [at_fps(style.clip(c), clip.fps) for c in range(style.n_clips)]
        refs[style.name] = (clips, mocap_reference(clips, clip.fps))
    clips, reference = refs[style.name]
    jumps = np.asarray(prov.transition_times_s, dtype=float)
    r = evaluate(clip, music_beats_s=song["beats"], transitions_s=jumps[(jumps >= 0) & (jumps <= clip.duration_s)],
                 mocap=reference)
    out = {k: r.get(k) for k in KEYS if k in r}
    out["one_frame_steps"] = int(len(one_frame_steps(clip)))
    out.update(form_score(clip, music.structure, music.beats_per_bar))
    form = prov.summary.get("form") or {}
    out["replayed_share"] = form.get("replayed_share")
    real = realism([clip], clips)
    out.update(fid_k=real["fid_k"], div_k=real["div_k"], div_k_ref=real["div_k_ref"])
    return out


def form_section(cfg: BenchConfig, db, progress: Progress | None = None) -> dict:
    songs = form_songs(cfg, progress)
    refs: dict = {}
    per_song = []
    for i, song in enumerate(songs):
        if progress:
            progress(f"form: song {i + 1}/{len(songs)}: {song['name']}")
        rows = {}
        walk_fit = _walk_fit(song["music"], db) if "random_walk" in cfg.form_engines else None
        for name in cfg.form_engines:
            for repeat in ("off", "same"):
                runs = [_scores(_dance(name, song["music"], db, repeat, seed, walk_fit), song, db, refs) for seed in cfg.form_seeds]
                rows[f"{name}/{repeat}"] = {**mean_scores(runs),
                                            "one_frame_steps": sum(r["one_frame_steps"] for r in runs)}
        music = song["music"]
        found = [(s.start_s, s.end_s, s.label) for s in music.structure.sections]
        bound_f, pair_f = section_scores(list(song["sections"]), found)
        bar_s = np.r_[music.beat_times_s[music.beat_in_bar == 0], music.duration_s]
        rng = np.random.default_rng(0)
        chance = np.mean([section_chance(list(song["sections"]), found, bar_s, rng) for _ in range(20)], axis=0)
        per_song.append({"song": song["name"], "tempo_bpm": music.tempo_bpm,
                         "sections_found": "".join(s[2] for s in found),
                         "sections_true": "".join(s[2] for s in song["sections"]), "boundary_f": bound_f,
                         "pairwise_f": pair_f, "boundary_f_chance": float(chance[0]),
                         "pairwise_f_chance": float(chance[1]), "scores": rows, "live": live_form(song, db)})
    columns = list(dict.fromkeys(k for s in per_song for k in s["scores"]))
    summary = {c: mean_scores([s["scores"][c] for s in per_song if c in s["scores"]]) for c in columns}
    for c in columns:
        summary[c]["one_frame_steps"] = int(sum(s["scores"][c].get("one_frame_steps") or 0 for s in per_song))
        scores = [s["scores"][c].get("form_score") for s in per_song if s["scores"][c].get("form_score") is not None]
        summary[c]["form_score_min"] = min(scores) if scores else None
    music = {k: float(np.mean([s[k] for s in per_song])) if per_song else None
             for k in ("boundary_f", "boundary_f_chance", "pairwise_f", "pairwise_f_chance")}
    for k in ("boundaries_within_a_bar", "live_replayed_share"):
        vals = [s["live"][k] for s in per_song if s["live"][k] is not None]
        music[k] = float(np.mean(vals)) if vals else None
    return {"engines": list(cfg.form_engines), "split": split_name(cfg), "seeds": len(cfg.form_seeds),
            "songs": per_song, "music": music, "summary": summary}


def format_form(s: dict) -> str:
    m = s["music"]
    songs = table("Sections found (mir_eval: boundary F at ±0.5 s, pairwise label F)",
                  ["song", "true", "found", "boundary F", "pairwise F"],
                  [[x["song"], x["sections_true"], x["sections_found"], x["boundary_f"], x["pairwise_f"]]
                   for x in s["songs"]] + [["mean (chance)", "", "", f"{m['boundary_f']:.2f} ({m['boundary_f_chance']:.2f})",
                                            f"{m['pairwise_f']:.2f} ({m['pairwise_f_chance']:.2f})"]])
    cols = s["summary"]
    keys = list(KEYS[:1]) + ["form_score_min"] + list(KEYS[1:])
    labels = {**LABELS, "form_score_min": "  the lowest song's"}
    rows = [[labels[k]] + [cols[c].get(k) for c in cols] for k in keys]
    dances = table(f"The dances, engine/--repeat ({len(s['songs'])} songs of known form, {s.get('split', 'test')} "
                   f"split, {s.get('seeds', 1)} dances each; means; random_walk/same: the walk with every paired "
                   "beat showing its pair's frames)", ["", *cols], rows)
    live = (f"Live (streamed, --repeat same): offline boundaries found live within a bar "
            f"{_pct(m['boundaries_within_a_bar'])}; paired beats danced as their pair live "
            f"{_pct(m['live_replayed_share'])}")
    return songs + "\n\n" + live + "\n\n" + dances


def _pct(x) -> str:
    return "-" if x is None else f"{x:.0%}"


def section_pairs(music) -> tuple[np.ndarray, np.ndarray]:
    """The music beats of every repeated section (a label heard before) and, beat for beat, the beats at
    the same place in that label's first section: what the issue counts as a replay."""
    form, bpb = music.structure, music.beats_per_bar
    first_beat = np.flatnonzero(np.asarray(music.beat_in_bar) == 0)
    first_of: dict[str, int] = {}
    a, b = [], []
    for k, sec in enumerate(form.sections):
        j = first_of.setdefault(sec.label, k)
        for bar in range(min(sec.n_bars, form.sections[j].n_bars) if j != k else 0):
            x, y = sec.first_bar + bar, form.sections[j].first_bar + bar
            if x < len(first_beat):
                a += list(first_beat[x] + np.arange(bpb))
                b += list(first_beat[y] + np.arange(bpb))
    a, b = np.array(a, dtype=np.int64), np.array(b, dtype=np.int64)
    keep = a < len(music.beat_times_s)
    return a[keep], b[keep]


def live_form(song: dict, db) -> dict:
    """The song streamed (as fast as it decodes) with ``--repeat same``: the share of the offline
    analysis's section boundaries the live one found within a bar, and the share of the beats of
    the offline analysis's repeated sections (``section_pairs``) whose live beats danced the graph
    node of their pair's."""
    from ..live.runtime import LiveConfig, run_live
    from ..live.sources import AudioSource

    with AudioSource(str(song["path"]), realtime=False) as src:
        summary = run_live(src, lambda clip: None, config=LiveConfig(database=db, repeat="same"), realtime=False)
    form, music = summary["form"], song["music"]
    bar_s = np.asarray(form["bar_starts_s"])
    live = bar_s[[b for b in form["section_bars"] if b < len(bar_s)]][1:]
    offline = np.array([s.start_s for s in music.structure.sections[1:]])
    bar_len = 60.0 / music.tempo_bpm * music.beats_per_bar
    found = [bool(live.size) and float(np.min(np.abs(live - t))) <= bar_len for t in offline]
    # The offline pairs, beat for beat, looked up on the live beats.
    grid = np.asarray(music.beat_times_s)
    pairs, source = section_pairs(music)
    times, danced = np.asarray(form["beat_times_s"]), np.asarray(form["danced"])
    n = min(len(times), len(danced))

    def live_beat(t):
        k = np.clip(np.searchsorted(times[:n], t), 1, n - 1)
        k = np.where(np.abs(times[k - 1] - t) < np.abs(times[k] - t), k - 1, k)
        return k, np.abs(times[k] - t) < 0.1

    a, ok_a = live_beat(grid[pairs])
    b, ok_b = live_beat(grid[source])
    ok = ok_a & ok_b
    return {"boundaries_within_a_bar": float(np.mean(found)) if found else None,
            "live_replayed_share": float(np.mean(danced[a[ok]] == danced[b[ok]])) if ok.any() else None,
            "live_repeats": form["repeats"], "live_section_bars": form["section_bars"]}

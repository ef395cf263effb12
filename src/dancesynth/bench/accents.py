"""Are the dance's visible accents on the beats? Every mocap engine, beside chance, a random walk and the mocap.

For each song -- the bundled music (its tracked beats and metre are the reference)
and the generated songs with exactly known beats and bars (``groundtruth``; the
dance is made from the audio, as a user's would be, and scored against the truth) --
each engine dances with the product defaults, and ``evaluate`` scores it:

- precision and recall of its kinematic beats (speed minima) against the beats at
  +-50 ms, each beside its chance level (the same kinematic beats circularly shifted)
  and the ratio to it; the same against downbeats; the share of bars whose strongest
  accent is on the downbeat (4/4 songs; chance 1/4); on 3/4 songs, the period
  (2, 3 or 4 beats) at which the per-beat kinetic energy repeats most;
- the guards: playback rates within [0.8, 1.25], intensity Spearman, transition
  jumps and foot skating beside the style's mocap, one-frame joint steps.

Visible accents are counted again with only the kinematic beats that stop the body as much as the
mocap's median accent does (``stop_depth_on_beats``; ``EvalParams.visible_stop_depth``), and every
engine with accent timing dances each song again without it, in the same style and on the same path
(``same_path`` checks), so the table shows what the easing adds to what the chosen pieces give.

The joint-speed guard (p99 within ±25 % of the style's mocap) is also checked song by song, beside
the range the style's own mocap spans over stretches as long as the song (``mocap_speed_range``):
over 5 s a stretch of salsa mocap lies outside ±25 % of its whole p99 four times in ten, over 90 s
almost never, so a short song's dance is judged against what the capture itself does at that length.

The raw mocap row scores each clip of the styles danced against its own motion
beats (it has no music); the paper row is the streaming engine with Xu et al.'s objective and
graph as printed (``--paper``); the lookahead row is the streaming engine with ``--lookahead 5``
(opt-in, not among the guarded engines). Means over songs per engine; per song in the JSON.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .common import MUSIC_DIR, BenchConfig, Progress, load_song, split_name, table
from .quality import at_fps, mean_scores, mocap_scores

TITLES = {"streaming": "streaming", "lookahead": "+lookahead", "signature": "+signature", "global": "global DP",
          "choreography": "choreography", "random_walk": "random walk", "paper": "paper", "mocap": "mocap*"}
ACCENT_KEYS = ("accent_precision", "accent_precision_chance", "accent_precision_x_chance", "accent_recall",
               "accent_recall_chance", "accent_recall_x_chance", "stop_depth_on_beats", "visible_accent_precision",
               "visible_accent_precision_chance", "visible_accent_precision_x_chance", "visible_accent_recall",
               "visible_accent_recall_chance", "visible_accent_recall_x_chance")
KEYS = ACCENT_KEYS + ("downbeat_recall", "downbeat_recall_chance",
        "bar_accent_on_downbeat", "bar_accent_chance", "warp_in_range", "intensity_spearman",
        "transition_jump_vs_mocap_p99", "worst_transition_jump_vs_mocap_p99", "jump_p99_vs_mocap",
        "joint_speed_p99_vs_mocap", "root_travel_vs_mocap", "foot_skate_m_s", "foot_skate_vs_mocap", "pfc",
        "pfc_vs_mocap", "foot_skate_vs_source", "pfc_vs_source", "source_share", "one_frame_steps")
LABELS = {"accent_precision": "precision: kinematic beats on a beat (±50 ms)",
          "accent_precision_chance": "  chance (circular shift)", "accent_precision_x_chance": "  × chance",
          "accent_recall": "recall: beats with a kinematic beat (±50 ms)",
          "accent_recall_chance": "  chance (circular shift)", "accent_recall_x_chance": "  × chance",
          "stop_depth_on_beats": "stop depth of those on a beat (median; 1 = full stop)",
          "visible_accent_precision": "precision, visible accents only (stop depth ≥ mocap's median accent's)",
          "visible_accent_precision_chance": "  chance (circular shift)", "visible_accent_precision_x_chance":
          "  × chance", "visible_accent_recall": "recall, visible accents only",
          "visible_accent_recall_chance": "  chance (circular shift)", "visible_accent_recall_x_chance": "  × chance",
          "downbeat_recall": "downbeats with a kinematic beat", "downbeat_recall_chance": "  chance",
          "bar_accent_on_downbeat": "bars with the strongest accent on the 1 (4/4)",
          "bar_accent_chance": "  chance (1 / beats per bar)",
          "warp_in_range": "beat pieces played at rate 0.8-1.25",
          "intensity_spearman": "Spearman(loudness, kinetic energy)",
          "transition_jump_vs_mocap_p99": "largest transition jump / mocap p99",
          "worst_transition_jump_vs_mocap_p99": "  the worst song's",
          "joint_speed_p99_vs_mocap": "p99 joint speed / mocap's (guard ±25 %)",
          "root_travel_vs_mocap": "root travel / mocap's (guard ±25 %)",
          "jump_p99_vs_mocap": "p99 frame jump / mocap's", "foot_skate_m_s": "foot speed on the floor, m/s",
          "pfc": "foot contact score PFC (EDGE)",
          "foot_skate_vs_mocap": "  / the style's mocap's (guard ≤ 1.1)",
          "pfc_vs_mocap": "  / the style's mocap's (guard ≤ 1.1)",
          "foot_skate_vs_source": "floor foot speed / the same source frames' as captured",
          "pfc_vs_source": "PFC / the same source frames' as captured",
          "source_share": "  share of the dance in uncut runs of 1 s or more (those compared)",
          "one_frame_steps": "one-frame joint steps > 30° not in the source (total)"}
UNEASED_KEYS = ("accent_precision", "accent_recall", "stop_depth_on_beats", "visible_accent_precision",
                "visible_accent_precision_x_chance", "visible_accent_recall", "visible_accent_recall_x_chance",
                "same_path")
UNEASED_LABELS = {"accent_precision": "precision", "accent_recall": "recall", "stop_depth_on_beats": "stop depth",
                  "visible_accent_precision": "visible precision", "visible_accent_precision_x_chance": "  × chance",
                  "visible_accent_recall": "visible recall", "visible_accent_recall_x_chance": "  × chance",
                  "same_path": "share of songs on the same path"}
PLAIN_ALREADY = ("paper",)  # engines that play each piece at one rate already: uneased is the same dance
MOCAP_NOTE = ("* mocap: each clip of the styles danced, against its own motion beats (no music, no bars, "
              "no loudness, no transitions); its one-frame steps are its own capture glitches, per clip")


def _songs(cfg: BenchConfig, progress) -> list[dict]:
    """The bundled songs (tracked beats as reference) and the generated ones (exact beats and bars)."""
    from ..music import analyze_music

    out = []
    for name in cfg.accent_songs or tuple(sorted(p.name for p in MUSIC_DIR.glob("*.ogg"))):
        music = load_song(name)
        out.append({"name": Path(name).name, "set": "bundled", "music": music, "beats": music.beat_times_s,
                     "loudness": music.intensity_db, "beat_in_bar": music.beat_in_bar,
                     "beats_per_bar": music.beats_per_bar})
    if cfg.accent_generated:
        from ..io.audio import load_audio
        from ..music.intensity import beat_intensity_db
        from .groundtruth import ground_truth_set

        root = cfg.groundtruth_dir or _default_cache()
        for song in ground_truth_set(root, quick=cfg.groundtruth_quick, specs=cfg.groundtruth_specs,
                                     split=cfg.groundtruth_split):
            music = analyze_music(path=song.audio_path)
            y, sr = load_audio(song.audio_path, sr=22050, mono=True)
            out.append({"name": song.name, "set": "generated", "music": music, "beats": song.beats_s,
                        "loudness": beat_intensity_db(y, sr, song.beats_s), "beat_in_bar": song.beat_in_bar,
                        "beats_per_bar": song.beats_per_bar})
    if progress:
        progress(f"accents: {len(out)} songs")
    return out


def _default_cache() -> Path:
    from ..motion.database import cache_dir

    return cache_dir() / "groundtruth"


def _score(clip, song: dict, reference, style, source_clips: list) -> dict:
    from ..motion.resample import sample_frames
    from ..eval.artefacts import feet_vs_source, new_steps
    from ..eval.evaluate import evaluate

    jumps = np.asarray(clip.provenance.transition_times_s, dtype=float)
    jumps = jumps[(jumps >= 0) & (jumps <= clip.duration_s)]
    rates = np.asarray(clip.provenance.warp_rates, dtype=float)
    r = evaluate(clip, music_beats_s=song["beats"], music_loudness_db=song["loudness"],
                 beat_in_bar=song["beat_in_bar"], beats_per_bar=song["beats_per_bar"], transitions_s=jumps,
                 warp_rates=rates, mocap=reference)
    r["warp_in_range"] = float(np.mean((rates >= 0.8) & (rates <= 1.25))) if rates.size else None
    # Snaps the mocap itself does not make at the frames shown (a capture glitch is the source's own),
    # counting every jump between pieces as a place the source cannot explain.
    shown, _, _ = sample_frames(style.local_rot, style.root_pos, np.asarray(clip.provenance.source_frames))
    cut = np.round(jumps * clip.fps).astype(np.int64)
    r["one_frame_steps"] = int(len(new_steps(clip, shown, cuts=np.r_[cut - 1, cut])))
    # What rendering adds to the feet, apart from which pieces were picked.
    feet = feet_vs_source(clip, clip.provenance.source_frames, source_clips, style.clip_starts)
    r.update(foot_skate_vs_source=feet["foot_skate_vs_source"], pfc_vs_source=feet["pfc_vs_source"],
             source_share=feet["share"])
    return r


def _uneased(name: str, clip, song: dict, db, seed: int) -> dict:
    """The accents of the same engine's dance with the accent timing off, in the same style: on the same path
    (``same_path`` says whether it was), what the path's own stops give without the easing."""
    from .dances import engine_dances, same_path
    from .quality import walk_dance
    from ..eval.evaluate import evaluate

    if name == "random_walk":   # its style and level are the eased walk's: no reference dance to make again
        plain = walk_dance(db.styles[clip.provenance.style], song["music"],
                           subdivide=clip.provenance.summary["subdivide"], seed=seed, fps=clip.fps, accent_timing=False)
    else:
        plain = engine_dances(song["music"], db, seed, [name], style=clip.provenance.style, accent_timing=False)[name]
    r = evaluate(plain, music_beats_s=song["beats"])
    return {**{k: r.get(k) for k in ACCENT_KEYS}, "same_path": float(same_path(clip, plain))}


def accents(cfg: BenchConfig, db, progress: Progress | None = None) -> dict:
    from .dances import engine_dances
    from ..eval.evaluate import mocap_reference

    songs = _songs(cfg, progress)
    clips_by_style, refs, sources, speeds, speed_ranges = {}, {}, {}, {}, {}
    per_song = []
    for i, song in enumerate(songs):
        if progress:
            progress(f"accents: song {i + 1}/{len(songs)}: {song['name']}")
        scores, styles, uneased, ranges = {}, {}, {}, {}
        for name, clip in engine_dances(song["music"], db, cfg.seed, cfg.accent_engines, style=None).items():
            key = (clip.provenance.style, clip.fps)
            if key not in refs:
                clips_by_style[key] = [at_fps(db.styles[key[0]].clip(c), clip.fps)
                                       for c in range(db.styles[key[0]].n_clips)]
                refs[key] = mocap_reference(clips_by_style[key], clip.fps)
                speeds[key] = mocap_speeds(clips_by_style[key])
            st = db.styles[key[0]].material  # the dance's source frames index its material
            if st.name not in sources:
                sources[st.name] = [st.clip(c) for c in range(st.n_clips)]
            scores[name] = _score(clip, song, refs[key], st, sources[st.name])
            span = (*key, round(clip.duration_s))
            if span not in speed_ranges:
                speed_ranges[span] = mocap_speed_range(speeds[key], clip.fps, refs[key].joint_speed_p99_m_s,
                                                       clip.duration_s)
            ranges[name] = speed_ranges[span]
            styles[name] = clip.provenance.style
            uneased[name] = _uneased(name, clip, song, db, cfg.seed) if name not in PLAIN_ALREADY else \
                {**{k: scores[name].get(k) for k in ACCENT_KEYS}, "same_path": 1.0}   # its timing is plain
        per_song.append({"song": song["name"], "set": song["set"], "tempo_bpm": song["music"].tempo_bpm,
                         "beats_per_bar": song["beats_per_bar"], "styles": styles, "scores": scores,
                         "uneased": uneased, "speed_range": ranges})
    mocap = {}
    for (style, _), clips in clips_by_style.items():
        if progress:
            progress(f"accents: raw mocap of {style}")
        rows = mocap_scores(_mocap_evaluate, clips, cfg.mocap_max_clips)
        mocap[style] = rows["mean"]
    return {"engines": list(cfg.accent_engines), "songs": per_song, "mocap": mocap, "split": split_name(cfg),
            "summary": summarise(per_song, mocap, cfg.accent_engines),
            "speed_guard": speed_guard(per_song, cfg.accent_engines)}


SPEED_GUARD = 0.25       # p99 joint speed within +-25 % of the style's mocap's (issue 31 item 5)
SPEED_RANGE = (5.0, 95.0)  # the percentiles of the mocap's own stretches that bound its range


def mocap_speeds(clips: list) -> np.ndarray:
    """(F, J) the joint speeds of a style's mocap ``clips`` end to end, each clip's its own (no joins)."""
    from ..eval.motion_metrics import joint_speeds

    return np.concatenate([joint_speeds(c) for c in clips if c.n_frames > 1])


def mocap_speed_range(speeds: np.ndarray, fps: float, reference_p99: float, duration_s: float,
                      windows: int = 200) -> list[float]:
    """The ``SPEED_RANGE`` percentiles, over ``windows`` stretches of ``duration_s`` of a style's mocap
    (``mocap_speeds`` at ``fps``), of their p99 joint speed over ``reference_p99``, the whole mocap's: how
    far the capture itself strays from its own p99 at that length."""
    n = int(round(duration_s * fps))
    if n >= len(speeds) or n < 2:
        return [1.0, 1.0]
    starts = np.unique(np.linspace(0, len(speeds) - n, windows).astype(np.int64))
    p99 = np.array([np.percentile(speeds[a:a + n], 99) for a in starts]) / reference_p99
    return [float(v) for v in np.percentile(p99, SPEED_RANGE)]


def speed_guard(per_song: list[dict], engines) -> dict:
    """Per engine: the dances whose p99 joint speed lies outside +-``SPEED_GUARD`` of the style's mocap, and
    of those, the ones outside the mocap's own range over as long a stretch too."""
    out = {}
    for e in engines:
        rows = [(s["song"], s["scores"][e].get("joint_speed_p99_vs_mocap"), s.get("speed_range", {}).get(e))
                for s in per_song if e in s["scores"]]
        rows = [r for r in rows if r[1] is not None]
        outside = [r for r in rows if abs(r[1] - 1.0) > SPEED_GUARD]
        beyond = [r for r in outside if r[2] is not None and not r[2][0] <= r[1] <= r[2][1]]
        out[e] = {"dances": len(rows), "outside": len(outside), "outside_mocap_range": len(beyond),
                  "songs_outside": [{"song": r[0], "ratio": r[1], "mocap_range": r[2]} for r in outside]}
    return out


def _mocap_evaluate(clip, **kwargs):
    from ..eval.artefacts import one_frame_steps
    from ..eval.evaluate import evaluate

    r = evaluate(clip, **kwargs)
    r["one_frame_steps"] = int(len(one_frame_steps(clip)))  # the capture's own glitches
    return r


def summarise(per_song: list[dict], mocap: dict, engines) -> dict:
    """Per engine and song set (bundled, generated): the mean of each key; 3/4 periods; the mocap row."""
    out = {}
    for subset in ("bundled", "generated"):
        rows = [s for s in per_song if s["set"] == subset]
        if not rows:
            continue
        table_ = {}
        for e in engines:
            scored = [s["scores"][e] for s in rows if e in s["scores"]]
            four = [s["scores"][e] for s in rows if e in s["scores"] and s["beats_per_bar"] == 4]
            three = [s["scores"][e] for s in rows if e in s["scores"] and s["beats_per_bar"] == 3]
            m = mean_scores(scored)
            m["bar_accent_on_downbeat"] = mean_scores(four).get("bar_accent_on_downbeat") if four else None
            m["bar_accent_chance"] = 0.25 if four else None
            m["waltz_period_3"] = (float(np.mean([r.get("energy_period_beats") == 3 for r in three]))
                                   if three else None)
            m["one_frame_steps"] = int(sum(r.get("one_frame_steps") or 0 for r in scored))
            plain = mean_scores([s["uneased"][e] for s in rows if e in s.get("uneased", {})])
            m.update({f"uneased_{k}": plain.get(k) for k in UNEASED_KEYS})
            worst = [r["transition_jump_vs_mocap_p99"] for r in scored if r.get("transition_jump_vs_mocap_p99")]
            m["worst_transition_jump_vs_mocap_p99"] = max(worst) if worst else None
            table_[e] = m
        out[subset] = table_
    out["mocap"] = mean_scores(list(mocap.values())) if mocap else {}
    return out


def format_accents(s: dict) -> str:
    blocks = []
    for subset, title in (("bundled", "bundled music (tracked beats and metre)"),
                          ("generated", f"generated songs (exact beats and bars; {s.get('split', 'test')} split)")):
        if subset not in s["summary"]:
            continue
        cols = s["summary"][subset]
        n = sum(1 for x in s["songs"] if x["set"] == subset)
        header = ["metric"] + [TITLES[e] for e in cols] + [TITLES["mocap"]]
        rows = [[LABELS[k]] + [cols[e].get(k) for e in cols] + [s["summary"]["mocap"].get(k)] for k in KEYS]
        # The same paths with the accent timing off: what the chosen pieces' own stops give (mocap: as captured).
        rows += [[f"uneased, same path: {UNEASED_LABELS[k]}"] + [cols[e].get(f"uneased_{k}") for e in cols]
                 + [s["summary"]["mocap"].get(k)] for k in UNEASED_KEYS]
        rows.append(["3/4 songs danced with a 3-beat energy period"] + [cols[e].get("waltz_period_3") for e in cols]
                    + [None])
        blocks.append(table(f"Visible accents, {title}: mean over {n} songs", header, rows,
                            [0] + [2] * (len(header) - 1)))
    guard = s.get("speed_guard")
    if guard:
        blocks.append("  p99 joint speed outside ±25 % of the style's mocap, song by song (and of those, outside the "
                      f"mocap's own {SPEED_RANGE[0]:g}-{SPEED_RANGE[1]:g} % range over stretches as long as the song):")
        for e, g in guard.items():
            worst = ", ".join(f"{x['song'][:28]} {x['ratio']:.2f}" + (f" [{x['mocap_range'][0]:.2f}-"
                              f"{x['mocap_range'][1]:.2f}]" if x["mocap_range"] else "") for x in g["songs_outside"])
            blocks.append(f"    {TITLES[e]:<14}{g['outside']:>3} of {g['dances']:<3} ({g['outside_mocap_range']})"
                          + (f"  {worst}" if worst else ""))
    return "\n".join(blocks + [f"  {MOCAP_NOTE}"])

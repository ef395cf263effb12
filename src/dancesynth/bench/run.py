"""``dancesynth bench``: the benchmark as a library call.

    result = run_bench(quick=True, out_dir=Path("bench-out"), progress=print)
    print(format_bench(result))

Sections (each records ``{"skipped": reason}`` instead when it cannot run, and the
others still run):

1. ``fig4`` -- Xu et al. Fig. 4: synthesis time per segment (streaming step vs the
   global DP over the same music length) and the fit of time on D*N*P*L.
2. ``scaling`` -- build time, search time and peak memory with the database
   replicated 1x..10x (a fresh process per size).
3. ``pipeline`` -- the bundled graphs built and reloaded, a 3-minute song to BVH.
4. ``quality`` -- every metric of ``dancesynth.eval.evaluate`` for our dance, the
   global-DP baseline, a random walk on the same graph and the raw mocap.
5. ``beat_tracking`` -- every beat tracker on generated songs with exact beats.
6. ``structure`` -- Aristidou et al.'s global structure: chi2 to the genre template
   per engine (Table I), its convergence (Fig. 12, plotted to ``fig12_chi2.png``),
   each engine's metrics beside the raw mocap, re-creation of held-out dances.
7. ``accents`` -- the dance's visible accents against beats and bars, every mocap
   engine beside chance, a random walk and the raw mocap, with the guards.
8. ``realism`` -- FID_k, FID_g, Div_k, Div_g of every mocap engine, a frozen pose
   and the mocap floor against clips held out of the salsa style with the most takes.
9. ``vocabulary`` -- what the database can dance: minutes per genre, the tempo map,
   repetition on 3-minute songs, and the guards per style.
10. ``form`` -- the song's form: sections found on generated songs of known form, and every
   engine's structure-consistency score with ``--repeat off`` and ``same``, with the guards.

``run_bench`` writes ``bench.json`` into ``out_dir`` and returns the same dict;
``format_bench`` turns it into the tables (same layout every run of a mode).
Library code never prints: progress goes to ``progress(message)``.
"""

from __future__ import annotations

import json
import os
import platform
import time
import traceback
from dataclasses import asdict
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from .common import SECTIONS, BenchConfig, Progress, skipped
from ..errors import InputError
from ..io.files import jsonable

__all__ = ["BenchConfig", "SECTIONS", "run_bench", "format_bench"]

BENCH_FORMAT = 1
TITLES = {"fig4": "1. Synthesis time per segment (Xu et al. Fig. 4)",
          "scaling": "2. Growth with the database",
          "pipeline": "3. Graphs and a song end to end",
          "quality": "4. Quality on the bundled music",
          "beat_tracking": "5. Beat tracking on generated ground truth",
          "structure": "6. Global structure: motifs and signatures (Aristidou et al.)",
          "accents": "7. Visible accents on beats and bars",
          "realism": "8. Realism and diversity against held-out mocap (FID_k, FID_g, Div_k, Div_g)",
          "vocabulary": "9. Vocabulary: material per genre and tempo, repetition, guards per style",
          "form": "10. The song's form: sections found, repeats danced again"}


def machine_info() -> dict:
    import scipy

    return {"cpus": os.cpu_count(), "affinity_cpus": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity")
            else None, "machine": platform.machine(), "processor": platform.processor() or platform.machine(),
            "system": f"{platform.system()} {platform.release()}", "python": platform.python_version(),
            "numpy": np.__version__, "scipy": scipy.__version__}


class _Skip(Exception):
    """A section cannot run here (a missing program or module): recorded, not raised."""


def run_bench(*, quick: bool, out_dir: Path, progress: Progress | None = None,
              config: BenchConfig | None = None) -> dict:
    """Run the benchmark; write ``out_dir/bench.json`` and return the same dict.

    ``quick`` picks ``BenchConfig.quick()`` (under two minutes on a 2-core CPU)
    instead of ``BenchConfig.full()``; ``config`` overrides both (tests shrink it).
    """
    from .. import __version__

    cfg = config or (BenchConfig.quick() if quick else BenchConfig.full())
    unknown = set(cfg.sections) - set(SECTIONS)
    if unknown:
        raise InputError(f"unknown bench section(s) {sorted(unknown)}: use {', '.join(SECTIONS)}")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    result = {"format": BENCH_FORMAT, "mode": "quick" if quick else "full", "dancesynth": __version__,
              "started": datetime.now(timezone.utc).isoformat(timespec="seconds"), "machine": machine_info(),
              "config": jsonable(asdict(cfg)), "timings_s": {}}
    t_all = time.perf_counter()
    shared: dict = {}
    for name in SECTIONS:
        if name not in cfg.sections:
            result[name] = {"skipped": "not selected"}
            continue
        if progress:
            progress(f"section {name}")
        t = time.perf_counter()
        try:
            result[name] = _run_section(name, cfg, shared, progress, out_dir)
        except _Skip as exc:
            result[name] = {"skipped": str(exc)}
        except Exception as exc:  # one broken section must not lose the others' numbers
            result[name] = {"skipped": f"failed: {type(exc).__name__}: {exc}",
                            "traceback": traceback.format_exc(limit=8)}
        result["timings_s"][name] = time.perf_counter() - t
    result["timings_s"]["total"] = time.perf_counter() - t_all
    result["targets"] = targets(result)
    result = jsonable(result)
    tmp = out_dir / ".bench.json.part"
    tmp.write_text(json.dumps(result, indent=1))
    os.replace(tmp, out_dir / "bench.json")
    return result


def _run_section(name: str, cfg: BenchConfig, shared: dict, progress, out_dir: Path) -> dict:
    if name in ("fig4", "scaling", "pipeline", "quality", "structure", "accents", "realism", "vocabulary", "form") \
            and "db" not in shared:
        from ..motion.database import open_database

        shared["db"] = open_database()
    if name in ("fig4", "scaling") and "music" not in shared:
        from .common import load_song

        shared["music"] = load_song(cfg.song, cfg.song_max_s)
    if name == "fig4":
        from .speed import fig4

        return fig4(cfg, shared["db"], shared["music"], progress)
    if name == "scaling":
        from .speed import scaling

        return scaling(cfg, shared["db"], shared["music"], progress)
    if name == "pipeline":
        from .speed import pipeline

        return pipeline(cfg, shared["db"], progress)
    if name == "quality":
        from .quality import quality

        return quality(cfg, shared["db"], progress)
    if name == "structure":
        from .structure import structure

        return structure(cfg, shared["db"], progress, out_dir)
    if name == "accents":
        import shutil

        from .accents import accents

        if cfg.accent_generated and shutil.which("fluidsynth") is None:
            raise _Skip("fluidsynth is not installed (apt-get install fluidsynth timgm6mb-soundfont)")
        return accents(cfg, shared["db"], progress)
    if name == "realism":
        from .realism import realism_section

        return realism_section(cfg, shared["db"], progress)
    if name == "vocabulary":
        import shutil

        from .vocabulary import vocabulary

        if shutil.which("fluidsynth") is None:
            raise _Skip("fluidsynth is not installed (apt-get install fluidsynth timgm6mb-soundfont)")
        return vocabulary(cfg, shared["db"], progress)
    if name == "form":
        import shutil

        from .form import form_section

        if shutil.which("fluidsynth") is None:
            raise _Skip("fluidsynth is not installed (apt-get install fluidsynth timgm6mb-soundfont)")
        return form_section(cfg, shared["db"], progress)
    if name == "beat_tracking":
        import shutil

        from ..errors import InputError

        if shutil.which("fluidsynth") is None:
            raise _Skip("fluidsynth is not installed (apt-get install fluidsynth timgm6mb-soundfont)")
        from .beats import beat_tracking

        try:
            return beat_tracking(cfg, progress)
        except InputError as exc:  # no soundfont, a render failed: say what to install
            raise _Skip(str(exc)) from None
    raise ValueError(name)


def _form_music(key: str):
    return lambda s: s["music"][key]


def _lowest_same(key: str):
    """The lowest mean of ``key`` over the engines dancing with ``--repeat same`` (not the walk replayed)."""
    return lambda s: min(v[key] for k, v in s["summary"].items() if k.endswith("/same") and k != "random_walk/same")


def _form_ratio(key: str, combine):
    """``combine`` (min, max) over the engines of the mean ``key`` with ``--repeat same`` over that with ``off``."""
    return lambda s: combine(v[key] / s["summary"][k.replace("/same", "/off")][key] for k, v in s["summary"].items()
                             if k.endswith("/same") and k != "random_walk/same")


def _accent(subset: str, engine: str, key: str):
    return lambda s: s["summary"][subset][engine][key]


#: The mocap engines a user dances with; the random walk is the baseline they are compared to.
_DANCING = ("streaming", "signature", "global", "choreography")


def _furthest(key: str, centre: float = 1.0):
    """|ratio - centre| at its largest over the mocap engines and song sets (centre 1: a guard within
    +-x; centre 0: the largest ratio)."""
    def read(s):
        return max(abs(s["summary"][subset][e][key] - centre) for subset in ("bundled", "generated")
                   if subset in s["summary"] for e in _DANCING
                   if s["summary"][subset].get(e, {}).get(key) is not None)
    return read


def _every_dance(key: str, combine, subset: str | None = None):
    """``combine`` (max, sum) of ``key`` over every song (of ``subset``: "bundled", "generated") danced by the
    mocap engines."""
    return lambda s: combine(x["scores"][e][key] or 0 for x in s["songs"] for e in _DANCING if e in x["scores"]
                             and subset in (None, x["set"]))


def _neural(name: str, centre: float | None = None):
    """A neural target's value from the structure section (centre: its distance from it, for a +-x bound)."""
    def read(s):
        v = s["neural_targets"][name]["value"]
        return v if centre is None else abs(v - centre)
    return read


# The visible-accent targets (issue 12), per engine and song set: (what, key, limit).
ACCENT_ENGINES = ("streaming", "global", "choreography")
ACCENT_TARGETS = (("recall", "accent_recall", 0.7), ("precision", "accent_precision", 0.6),
                  ("recall x chance", "accent_recall_x_chance", 2.5),
                  ("precision x chance", "accent_precision_x_chance", 2.5),
                  ("pieces at rate 0.8-1.25", "warp_in_range", 0.9))


def _accent_target(what: str, engine: str, subset: str) -> str:
    return f"accent {what}, {engine}, {subset} songs"


# The product's performance targets (README): name -> (section, how to read the value, limit).
TARGETS = {
    "search per 5 s segment, ms (largest style)": ("fig4", lambda s: _row(s, "segment_s", 5.0)
                                                   ["stream_search_ms"]["median"], 2.0),
    "search per 5 s segment, ms (database x10)": ("scaling", lambda s: _row(s, "times", 10)["search_ms_median"],
                                                  20.0),
    "building every bundled graph, s": ("pipeline", lambda s: s["graph_build_total_s"], 10.0),
    "reloading a graph from the cache, s": ("pipeline", lambda s: max(g["reload_ms"] for g in s["graphs"]) / 1e3,
                                            0.5),
    "a 3-minute song to BVH, s": ("pipeline", lambda s: s["wall_s_median"] if s["song_s"] >= 180 else None, 5.0),
    "peak memory, default graph, MB": ("scaling", lambda s: max(_row(s, "times", 1)[k] for k in
                                                                 ("build_peak_mb", "stream_peak_mb")), 1024.0),
    "peak memory, database x10, MB": ("scaling", lambda s: max(_row(s, "times", 10)[k] for k in
                                                                ("build_peak_mb", "stream_peak_mb")), 1024.0),
    # Aristidou et al.'s global structure (issue 6): signature-following engines near the genre template.
    "chi2 to the template, streaming + signature": ("structure", lambda s: s["table_i"]["signature"]["chi2"], 0.2),
    "chi2 to the template, choreography mixer": ("structure", lambda s: s["table_i"]["choreography"]["chi2"], 0.2),
    "chi2 to the template, neural generator": ("structure", lambda s: s["table_i"]["neural"]["chi2"], 0.30),
    # The neural generator's liveliness and realism (issue 16), as bench.structure.NEURAL_TARGETS measures them.
    "neural: beats whose motif follows the plan": ("structure", _neural("beats whose motif follows the plan"), 0.5,
                                                   "at least"),
    "neural: frames with a hand in the head": ("structure", _neural("frames with a hand in the head"), 0.02),
    **{f"neural: {what} / mocap's, distance from 1": ("structure", _neural(f"{what} / mocap's", 1.0), 0.3)
       for what in ("root travel", "p99 joint speed")},
    "neural: one-frame joint steps over 30°": ("structure", _neural("one-frame joint steps > 30°, all dances"), 0),
    **{f"neural: {fid} / streaming's vs held-out mocap": ("structure", _neural(f"{fid} / streaming's (held-out "
                                                                                "mocap)"), 1.5)
       for fid in ("FID_k", "FID_g")},
    **{f"neural: accent {what} x chance": ("structure", _neural(f"accent {what} / chance"), 2.0, "at least")
       for what in ("precision", "recall")},
    "re-created beats with another motif, as danced": ("structure", lambda s: 1 - s["recreation"]["danced_mean"],
                                                       0.2),
    "re-created beats with another motif, found again": ("structure",
                                                         lambda s: 1 - s["recreation"]["found_again_mean"], 0.2),
    # Visible accents (issue 12): the dance's stops on the beats, well above chance, with guards.
    **{_accent_target(what, engine, subset): ("accents", _accent(subset, engine, key), limit, "at least")
       for subset in ("bundled", "generated") for engine in ACCENT_ENGINES for what, key, limit in ACCENT_TARGETS},
    "bars with the strongest accent on the 1, streaming, generated 4/4": (
        "accents", _accent("generated", "streaming", "bar_accent_on_downbeat"), 0.6, "at least"),
    "3/4 songs danced with a 3-beat period, streaming, generated": (
        "accents", _accent("generated", "streaming", "waltz_period_3"), 0.9, "at least"),
    "transition jump / mocap p99, every engine and song": ("accents", _every_dance("transition_jump_vs_mocap_p99",
                                                                                 max), 1.0),
    **{f"{what} / mocap's, furthest from 1 (mean per engine and set)": ("accents", _furthest(key), 0.25)
       for what, key in (("p99 joint speed", "joint_speed_p99_vs_mocap"), ("root travel", "root_travel_vs_mocap"))},
    # Issue 31 item 5: the speed guard on every song of 60-180 bpm (the generated set), not on average ...
    "p99 joint speed / the style's mocap's, every engine and generated song, furthest from 1": (
        "accents", _every_dance("joint_speed_p99_vs_mocap", lambda xs: max(abs(x - 1.0) for x in xs if x),
                                subset="generated"), 0.25),
    # ... and on every song beside what the mocap itself does: a 5 s stretch of salsa mocap lies outside
    # +-25 % of its whole p99 four times in ten (bench.accents.mocap_speed_range).
    "dances outside the speed guard and the mocap's own range over as long a stretch, every engine and song": (
        "accents", lambda s: sum(s["speed_guard"][e]["outside_mocap_range"] for e in _DANCING
                                 if e in s.get("speed_guard", {})), 0),
    **{f"{what} / the style's mocap's, highest (mean per engine and set)": ("accents", _furthest(key, 0.0), 1.1)
       for what, key in (("foot speed on the floor", "foot_skate_vs_mocap"), ("PFC", "pfc_vs_mocap"))},
    "one-frame joint steps over 30°, every engine and song": ("accents", _every_dance("one_frame_steps", sum), 0),
    # Realism (bench.realism): no worse than today's streaming dance. 34 is the streaming dance's FID_k as
    # measured before the section existed (benchmarks/results/realism_bench.json: 33.4, salsa-120-150bpm,
    # 3 held-out splits, 4 songs, mocap floor 29.6); quick mode scores one split on one song, a noisier reading.
    "FID_k, streaming vs held-out mocap": ("realism", lambda s: s["mean"]["streaming"]["fid_k"], 34.0),
    # What the database can dance (issue 30): only shippable data, material at every tempo, no looped clips.
    "captured minutes of shippable dance (mirrored takes not counted)": (
        "vocabulary", lambda s: s["totals"]["minutes"], 30.0, "at least"),
    "styles with at least 2 captured minutes": ("vocabulary", lambda s: s["totals"]["styles_2min"], 4, "at least"),
    "genres with at least 10 captured minutes": ("vocabulary", lambda s: len(s["totals"]["genres_10min"]), 2,
                                                 "at least"),
    "tempi 70-180 bpm without a style of 5 min material": ("vocabulary", lambda s: len(s["tempo_cover"]["short"]), 0),
    "songs danced from under 2 minutes of material": ("vocabulary", lambda s: s["targets"]["under_2min"], 0),
    "3-minute songs: beats replaying the last minute, worst song": (
        "vocabulary", lambda s: s["targets"]["long_replay_max"], 0.10),
    "accents x chance, every style (mean per style, lower way)": (
        "vocabulary", lambda s: min(min(g["accent_precision_x_chance"], g["accent_recall_x_chance"])
                                    for g in s["guards"].values()), 2.5, "at least"),
    "one-frame joint steps over 30°, every style": (
        "vocabulary", lambda s: sum(g["one_frame_steps"] for g in s["guards"].values()), 0),
    "foot speed on the floor / the style's mocap's, every style (mean)": (
        "vocabulary", lambda s: max(g["foot_skate_vs_mocap"] for g in s["guards"].values()), 1.1),
    "p99 joint speed / the style's mocap's, every style (mean), distance from 1": (
        "vocabulary", lambda s: max(abs(g["joint_speed_p99_vs_mocap"] - 1.0) for g in s["guards"].values()), 0.25),
    # The song's form (issue 32): sections found, and every engine dancing a returning section again.
    **{f"{what}": ("form", _form_music(key), limit, "at least") for what, key, limit in (
        ("sections found: boundary F at ±0.5 s, generated songs of known form", "boundary_f", 0.8),
        ("sections found: pairwise label F, generated songs of known form", "pairwise_f", 0.8),
        ("live: offline section boundaries found within a bar", "boundaries_within_a_bar", 0.8),
        ("live: paired beats danced as their pair, --repeat same", "live_replayed_share", 0.6))},
    **{what: ("form", _lowest_same(key), limit, "at least") for what, key, limit in (
        ("structure consistency (music vs dance bars), every engine with --repeat same, lowest mean",
         "form_score", 0.5),
        ("paired beats danced as their pair, --repeat same, every engine, lowest", "replayed_share", 0.8))},
    "Div_k with --repeat same / off, every engine, lowest": ("form", _form_ratio("div_k", min), 0.9, "at least"),
    "FID_k with --repeat same / off, every engine, highest": ("form", _form_ratio("fid_k", max), 1.0),
}


def _row(section: dict, key: str, value) -> dict:
    for r in section["rows"]:
        if r[key] == value:
            return r
    raise KeyError(f"no row with {key} = {value}")


# Targets measured on a reference that a choice was made on (issue 31 item 7): the bench marks them. The
# generated songs are the "test" split (bench.groundtruth.SPLITS: other tempi and seeds than the "tune" split
# the accent timing, accent costs and beat tracker were chosen on); the 3-minute songs are the vocabulary's
# "test" split; the neural spread cap was chosen on the tune split (benchmarks/spread_cap_select.py). What
# remains: the bundled songs, which the engines' constants were also looked at on, and the streaming FID
# limit, which is the streaming dance's own earlier reading.
CHOSEN_ON_REFERENCE = {
    **{_accent_target(what, engine, "bundled"): "the bundled songs: the engines' accent constants were also "
       "looked at on them" for engine in ACCENT_ENGINES for what, _, _ in ACCENT_TARGETS},
    "FID_k, streaming vs held-out mocap": "the limit is this dance's own earlier reading on the same split",
}


def targets(result: dict) -> dict:
    """Each target: its value, limit and whether it is met (``None`` where this run did not measure it), and
    ``chosen_on``: why the reference it is measured on is not untouched (``None``: a test split)."""
    out = {}
    for name, (section, read, limit, *how) in TARGETS.items():
        at_least = how == ["at least"]
        try:
            value = None if skipped(result.get(section, {})) else read(result[section])
        except (KeyError, TypeError, ValueError):
            value = None
        met = None if value is None else bool(value >= limit if at_least else value <= limit)
        out[name] = {"value": value, "limit": limit, "at_least": at_least, "met": met,
                     "chosen_on": CHOSEN_ON_REFERENCE.get(name)}
    return out


def format_bench(result: dict) -> str:
    """The benchmark's tables as text: a header, then each section's table (or why it was skipped)."""
    from .accents import format_accents
    from .realism import format_realism
    from .beats import format_beat_tracking
    from .quality import format_quality
    from .speed import format_fig4, format_pipeline, format_scaling
    from .structure import format_structure
    from .vocabulary import format_vocabulary
    from .form import format_form

    formatters = {"fig4": format_fig4, "scaling": format_scaling, "pipeline": format_pipeline,
                  "quality": format_quality, "beat_tracking": format_beat_tracking, "structure": format_structure,
                  "accents": format_accents, "realism": format_realism, "vocabulary": format_vocabulary,
                  "form": format_form}
    m = result.get("machine", {})
    timings = result.get("timings_s", {})
    out = [f"dancesynth {result.get('dancesynth', '?')} bench ({result.get('mode', '?')}), {result.get('started', '')}",
           f"machine: {m.get('cpus')} CPUs ({m.get('processor')}), {m.get('system')}, Python {m.get('python')}, "
           f"numpy {m.get('numpy')}, scipy {m.get('scipy')}"]
    for name in SECTIONS:
        section = result.get(name, {"skipped": "missing"})
        took = timings.get(name)
        out.append("")
        out.append(f"== {TITLES[name]}" + (f" [{took:.1f} s]" if took is not None else ""))
        reason = skipped(section)
        if reason:
            out.append(f"skipped: {reason}")
            continue
        try:
            out.append(formatters[name](section))
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            out.append(f"(cannot format this section: {type(exc).__name__}: {exc})")
    if result.get("targets"):
        out += ["", "Targets (†: measured where a constant was chosen too, see the notes)"]
        width = max(len(k) for k in result["targets"]) + 2
        notes = {}
        for name, t in result["targets"].items():
            verdict = "not measured" if t["met"] is None else (
                f"{t['value']:.3g} ({'>=' if t.get('at_least') else '<='} {t['limit']:g}): "
                f"{'met' if t['met'] else 'NOT MET'}")
            out.append(f"  {(name + (' †' if t.get('chosen_on') else '')).ljust(width)}  {verdict}")
            if t.get("chosen_on"):
                notes.setdefault(t["chosen_on"], []).append(name)
        out += [f"  † {why}" for why in notes]
    if "total" in timings:
        out += ["", f"total {timings['total']:.1f} s"]
    return "\n".join(out)


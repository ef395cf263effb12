"""Choose the speed guard's settings on the tune split, apart from what the bench reports (issue 31 item 5).

    .venv/bin/python benchmarks/speed_guard_select.py [--settings before,chosen] [--engines streaming,global,choreography]

Dances the generated songs of the ``tune`` split (25 songs, 60-180 bpm, every kind; tuning seeds) with
each engine, eased and with the accent timing off on the same path, and scores each against its style's
mocap: the songs whose p99 joint speed lies outside +-25 % of the mocap's (the guard), the mean and
extremes of that ratio, accent precision and visible precision x chance, and the floor foot speed
against the mocap's (a guard of its own, at most 1.1) and the worst transition jump against the
mocap's p99 frame jump. A setting is the easing's
per-frame speed limit (``ease_speed_percentile``, None: none), the decays' limb speed and how long they
may last for it (the mixer's ``limb_speed``, ``decay.BLEND_UNHURRIED_S``; the graph engines keep plain
decays) and the mixer's word pace cost
(``MixerConfig.speed_weight``). The product's defaults are the setting ``chosen``. Prints a table and
writes benchmarks/results/speed_guard_select.json.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
GUARD = 0.25
#: name -> (speed percentile, decay limb speed m/s, longest decay for it s, word pace weight)
SETTINGS = {
    "before": (None, np.inf, 1.0, 0.0),
    "p99": (99.0, np.inf, 1.0, 0.0),
    "p97": (97.0, np.inf, 1.0, 0.0),
    "p93": (93.0, np.inf, 1.0, 0.0),
    "p96+decays-1s+pace4": (96.0, 1.0, 1.0, 4.0),
    "p96+decays+pace4": (96.0, 1.0, 0.4, 4.0),
    "chosen": (96.0, 1.0, 0.4, 2.0),
}


@contextlib.contextmanager
def defaults(cls, **values):
    """``cls()``'s field defaults changed for the duration (the engines build their configs themselves)."""
    init = cls.__init__
    names = [f.name for f in dataclasses.fields(cls) if f.init]
    old = init.__defaults__
    new = list(old)
    for name, value in values.items():
        new[names.index(name) - (len(names) - len(old))] = value
    init.__defaults__ = tuple(new)
    try:
        yield
    finally:
        init.__defaults__ = old


@contextlib.contextmanager
def setting(pct, limb_speed, longest, pace):
    from dancesynth.engines import decay
    from dancesynth.engines.choreography import engine as choreography
    from dancesynth.engines.choreography.mixer import MixerConfig
    from dancesynth.engines.graph.engine import EngineConfig

    saved = decay.BLEND_UNHURRIED_S, choreography.choreography_dance.__kwdefaults__
    decay.BLEND_UNHURRIED_S = longest
    mixer = dataclasses.replace(MixerConfig(), ease_speed_percentile=pct, speed_weight=pace,
                                limb_speed=None if not np.isfinite(limb_speed) else limb_speed)
    choreography.choreography_dance.__kwdefaults__ = {**saved[1], "mixer": mixer}
    try:
        with defaults(EngineConfig, ease_speed_percentile=pct):
            yield
    finally:
        decay.BLEND_UNHURRIED_S, choreography.choreography_dance.__kwdefaults__ = saved


def main() -> None:
    from dancesynth.bench.accents import _songs
    from dancesynth.bench.common import BenchConfig
    from dancesynth.bench.dances import engine_dances
    from dancesynth.bench.quality import at_fps
    from dancesynth.eval.evaluate import evaluate, mocap_reference
    from dancesynth.motion.database import open_database

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--settings", default="before,chosen", help=f"of {', '.join(SETTINGS)}")
    ap.add_argument("--engines", default="streaming,global,choreography")
    ap.add_argument("--songs", type=int, default=None, help="only the first N songs (a smoke test)")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks/results/speed_guard_select.json")
    args = ap.parse_args()
    engines = args.engines.split(",")
    db = open_database()
    songs = [s for s in _songs(dataclasses.replace(BenchConfig.full(), groundtruth_split="tune"), None)
             if s["set"] == "generated"][:args.songs]
    refs = {}
    out = {"split": "tune", "songs": [s["name"] for s in songs], "settings": {}}
    for name in args.settings.split(","):
        t = time.perf_counter()
        rows = []
        with setting(*SETTINGS[name]):
            for s in songs:
                for engine in engines:
                    eased = engine_dances(s["music"], db, 0, [engine], style=None)[engine]
                    style = eased.provenance.style
                    plain = engine_dances(s["music"], db, 0, [engine], style=style, accent_timing=False)[engine]
                    if style not in refs:
                        st = db.styles[style]
                        refs[style] = mocap_reference([at_fps(st.clip(c), 30.0) for c in range(st.n_clips)], 30.0)
                    e, u = (evaluate(d, mocap=refs[style], music_beats_s=s["beats"],
                                     transitions_s=np.asarray(d.provenance.transition_times_s, dtype=float))
                            for d in (eased, plain))
                    rows.append({"song": s["name"], "engine": engine, "style": style,
                                 "eased": e["joint_speed_p99_vs_mocap"], "uneased": u["joint_speed_p99_vs_mocap"],
                                 "precision": e["accent_precision"], "foot_skate": e["foot_skate_vs_mocap"],
                                 "transition_jump": e.get("transition_jump_vs_mocap_p99") or 0.0,
                                 "visible_x_chance": e["visible_accent_precision_x_chance"]})
        summary = {}
        for engine in engines:
            r = [x for x in rows if x["engine"] == engine]
            p99 = np.array([x["eased"] for x in r])
            summary[engine] = {"outside": int(np.sum(np.abs(p99 - 1) > GUARD)),
                               "outside_uneased": int(sum(abs(x["uneased"] - 1) > GUARD for x in r)),
                               "p99_mean": float(p99.mean()), "p99_min": float(p99.min()), "p99_max": float(p99.max()),
                               "precision": float(np.mean([x["precision"] for x in r])),
                               "visible_x_chance": float(np.mean([x["visible_x_chance"] for x in r])),
                               "foot_skate": float(np.mean([x["foot_skate"] for x in r])),
                               "worst_transition_jump": float(max(x["transition_jump"] for x in r))}
        out["settings"][name] = {"values": dict(zip(("speed_percentile", "decay_limb_m_s", "decay_longest_s",
                                                     "word_pace"), map(_plain, SETTINGS[name]))),
                                 "summary": summary, "songs": rows, "wall_s": time.perf_counter() - t}
        print(f"{name} ({time.perf_counter() - t:.0f} s)")
        for engine, m in summary.items():
            print(f"  {engine:>12}: outside {m['outside']:>2}/{len(songs)} (uneased {m['outside_uneased']:>2}), "
                  f"p99 / mocap {m['p99_mean']:.3f} [{m['p99_min']:.2f}, {m['p99_max']:.2f}], precision "
                  f"{m['precision']:.3f}, visible x chance {m['visible_x_chance']:.2f}, floor foot speed / "
                  f"mocap {m['foot_skate']:.2f}, worst transition jump / mocap p99 {m['worst_transition_jump']:.2f}",
                  flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(out, indent=1))
    print(f"wrote {args.out}")


def _plain(x):
    return None if x is None or (isinstance(x, float) and not np.isfinite(x)) else x


if __name__ == "__main__":
    main()

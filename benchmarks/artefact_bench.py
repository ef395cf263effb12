"""Visible artefacts of rendered dances, per engine, against the style's own mocap.

    python benchmarks/artefact_bench.py [--songs A.ogg B.ogg] [--engines streaming global signature]
                                        [--mix-s 600] [--styles pop-106-124bpm mj] [--src SRC] [--before OLD.json]
                                        [--out benchmarks/results/artefact_bench.json]

For every bundled song (and a ``--mix-s`` long mix of them, looped with ffmpeg) and
every engine (``streaming``, ``global``, ``signature`` = streaming with
``follow_signature``), one dance with the product defaults (``--styles``: also the
default song danced in those styles), and:

- ``steps``: isolated one-frame joint snaps over 30 degrees
  (``eval.artefacts.one_frame_steps``) that the source mocap does not have at the
  same frame and joint (``new_steps`` against the mocap as played: sampled at the
  dance's source frames); ``steps_all`` counts every snap;
- ``tj_p99``: the largest angular-velocity jump at a transition / the style's mocap
  99th-percentile frame jump (``evaluate``'s ``transition_jump_vs_mocap_p99``; <= 1 is
  no worse than the mocap's own 1 % roughest frames); ``tj_vs_own_beats``: each
  transition's jump over the larger of that p99 and the source's own jump at those very
  beats (the old piece playing on through its last beat, the new one arriving at its
  first): a beat where the mocap itself stops hard is no fault of the join;
- ``pfc`` (EDGE) beside the style's mocap, and the peak root acceleration it divides
  by (``root_acc_max``: a dance whose joins are smoother has a lower peak, hence a
  higher PFC for the same foot motion);
- ``skate`` (foot speed on the floor, m/s) beside the style's mocap (each clip alone
  at the dance's frame rate, averaged over clips, as ``dancesynth bench``'s quality
  table) and beside the played source (``source_skate``, frames next to a cut left
  out): what the choice of mocap brings, and what the rendering adds;
- ``hand_in_head`` (share of frames) and ``penetration_m`` (mean depth below the floor).

``--src`` imports dancesynth from another source folder (e.g. a copy taken before a
change) to measure it with the same script; ``--before`` embeds such a result in the
JSON and prints before -> after.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
ENGINES = ("streaming", "global", "signature")
COLUMNS = (("transitions", "trans", 0), ("steps", "steps", 0), ("tj_p99", "tj/p99", 2),
           ("tj_vs_own_beats", "tj/own", 2), ("pfc", "pfc", 3), ("mocap_pfc", "mocap pfc", 3),
           ("root_acc_max", "root acc", 1), ("mocap_root_acc_max", "mocap acc", 1), ("skate", "skate", 3),
           ("mocap_skate", "mocap sk.", 3), ("skate_vs_mocap", "sk/mocap", 2), ("skate_vs_source", "sk/source", 2),
           ("hand_in_head", "hand/head", 3), ("penetration_m", "penetr. m", 4))


def mix_song(folder: Path, songs: list[Path], seconds: float) -> Path:
    """The songs back to back, looped until ``seconds``, as one wav (ffmpeg concat)."""
    from dancesynth.io.audio import load_audio  # only to know the lengths

    order, total = [], 0.0
    while total < seconds:
        for s in songs:
            order.append(s)
            total += len(load_audio(s, sr=8000)[0]) / 8000.0
            if total >= seconds:
                break
    out = folder / "mix.wav"
    inputs = [a for s in order for a in ("-i", str(s))]
    graph = "".join(f"[{i}:a]" for i in range(len(order))) + f"concat=n={len(order)}:v=0:a=1[a]"
    subprocess.run(["ffmpeg", "-v", "error", "-y", *inputs, "-filter_complex", graph, "-map", "[a]",
                    "-ac", "1", "-ar", "22050", "-t", f"{seconds:.3f}", str(out)], check=True)
    return out


class StyleReference:
    """A style's mocap at the dances' frame rate: jump distribution, pfc, foot skate (computed once)."""

    def __init__(self, style, fps):
        from dancesynth.eval import motion_metrics as mm
        from dancesynth.eval.artefacts import hand_in_head_frames, one_frame_steps
        from dancesynth.bench.quality import at_fps
        from dancesynth.eval.evaluate import mocap_reference

        clips = [at_fps(style.clip(c), fps) for c in range(style.n_clips)]
        self.jumps = mocap_reference(clips, fps)
        self.pfc = float(np.mean([mm.pfc(c) for c in clips]))
        self.skate = float(np.nanmean([mm.foot_skate(c) for c in clips]))
        self.root_acc_max = float(np.mean([_root_acc_max(c) for c in clips]))
        self.hand_in_head = float(np.nanmean([hand_in_head_frames(c) for c in clips]))
        self.steps_per_min = sum(len(one_frame_steps(c)) for c in clips) / sum(c.duration_s for c in clips) * 60


def measure(clip, style, ref: StyleReference) -> dict:
    from dancesynth.eval import motion_metrics as mm
    from dancesynth.eval.artefacts import hand_in_head_frames, new_steps, one_frame_steps
    from dancesynth.eval.evaluate import evaluate
    from dancesynth.motion.resample import sample_frames
    from dancesynth.types import MotionClip

    jumps = np.asarray(clip.provenance.transition_times_s, dtype=float)
    jumps = jumps[(jumps >= 0) & (jumps <= clip.duration_s)]
    ev = evaluate(clip, transitions_s=jumps, mocap=ref.jumps)
    # The source as played: the mocap at the dance's source frames (time warp included), no blend,
    # no foot lock, not re-placed; at a cut it teleports.
    local, root, _ = sample_frames(style.local_rot, style.root_pos, clip.provenance.source_frames)
    played = MotionClip(clip.skeleton, clip.fps, root, local)
    cuts = np.ceil(np.asarray(clip.provenance.transition_times_s) * clip.fps - 1e-9).astype(np.int64) - 1
    steps = new_steps(clip, local, cuts=cuts)
    source_skate = _skate_away_from(played, cuts)
    return {"style": style.name, "duration_s": clip.duration_s, "transitions": int(len(jumps)),
            "steps": int(len(steps)), "steps_all": int(len(one_frame_steps(clip))),
            "step_joints": sorted({clip.skeleton.names[j] for j in steps[:, 1]}),
            "mocap_steps_per_min": ref.steps_per_min,
            "tj_p99": ev["transition_jump_vs_mocap_p99"],
            "tj_vs_own_beats": _vs_own_beats(clip, style, jumps, ev["mocap_jump_p99_deg_s"]),
            "jump_max_vs_p99": _ratio(ev["jump_max_deg_s"], ev["mocap_jump_p99_deg_s"]),
            "pfc": ev["pfc"], "mocap_pfc": ref.pfc, "pfc_vs_mocap": _ratio(ev["pfc"], ref.pfc),
            "root_acc_max": _root_acc_max(clip), "mocap_root_acc_max": ref.root_acc_max,
            "skate": ev["foot_skate_m_s"], "mocap_skate": ref.skate,
            "skate_vs_mocap": _ratio(ev["foot_skate_m_s"], ref.skate),
            "source_skate": source_skate, "skate_vs_source": _ratio(ev["foot_skate_m_s"], source_skate),
            "hand_in_head": hand_in_head_frames(clip), "mocap_hand_in_head": ref.hand_in_head,
            "penetration_m": mm.ground_penetration(clip)}


def _vs_own_beats(clip, style, jumps, p99):
    """The largest transition jump over the larger of the mocap's p99 and the source's own jump at
    those very beats: the old piece playing on through its last beat, the new one arriving at its
    first (each at its own warp rate, +-2 frames). <= 1: no join is rougher than the mocap itself,
    in general or at that beat."""
    from dancesynth.eval import motion_metrics as mm
    from dancesynth.motion.resample import sample_frames
    from dancesynth.types import MotionClip

    if not len(jumps) or not p99:
        return None
    src = np.asarray(clip.provenance.source_frames, dtype=float)
    at_join = mm.transition_jumps(clip, jumps)
    worst = 0.0
    for t, jump in zip(jumps, at_join):
        f = int(np.clip(np.ceil(t * clip.fps - 1e-9), 2, clip.n_frames - 2))  # the first frame of the new piece
        own = p99
        for start, rate in ((src[f - 1], src[f - 1] - src[f - 2]), (src[f], src[f + 1] - src[f])):
            c = int(style.clip_of_frame(int(start)))
            frames = np.clip(start + rate * np.arange(-2, 3), style.clip_starts[c], style.clip_starts[c + 1] - 1)
            local, root, _ = sample_frames(style.local_rot, style.root_pos, frames)
            own = max(own, float(mm.angular_velocity_jumps(MotionClip(style.skeleton, clip.fps, root, local)).max()))
        worst = max(worst, jump / own)
    return worst


def _skate_away_from(motion, cuts):
    """Foot skate of ``motion`` (m/s) leaving out the frames next to a cut, where it teleports."""
    from dancesynth.eval import motion_metrics as mm

    feet = mm.feet_of(motion)
    on_floor = feet[..., 1].min(axis=2) <= mm.floor_height(feet) + mm.DEFAULT_CONTACT_HEIGHT_M
    for c in cuts:
        on_floor[max(c - 1, 0):c + 3] = False
    return mm.foot_skate(motion, contacts=on_floor)


def _root_acc_max(motion):
    """Peak root acceleration (m/s^2), upward part clamped at 0: the scale EDGE's PFC divides by."""
    acc = np.diff(motion.root_pos, n=2, axis=0) * motion.fps ** 2
    acc[:, 1] = np.maximum(acc[:, 1], 0.0)
    return float(np.linalg.norm(acc, axis=-1).max())


def _ratio(a, b):
    return None if a is None or b is None or not b > 0 else float(a) / float(b)


def run(songs, engines, mix_s, styles=(), progress=print) -> dict:
    from dancesynth.api import dance
    from dancesynth.bench.common import DEFAULT_SONG, MUSIC_DIR, load_song
    from dancesynth.motion.database import open_database

    db = open_database()
    paths = [Path(s) if Path(s).is_file() else MUSIC_DIR / s for s in songs]
    refs, rows = {}, []
    with tempfile.TemporaryDirectory() as tmp:
        items = [(p.name, p, None) for p in paths]
        if mix_s:
            items.append((f"mix {mix_s / 60:.0f} min", mix_song(Path(tmp), paths, mix_s), None))
        items += [(f"{DEFAULT_SONG} as {st}", MUSIC_DIR / DEFAULT_SONG, st) for st in styles]
        for name, path, style_name in items:
            music = load_song(str(path))
            for engine in engines:
                t = time.perf_counter()
                kw = {"engine": "global"} if engine == "global" else {"follow_signature": engine == "signature"}
                clip = dance(music, database=db, style=style_name, **kw)
                style = db.styles[clip.provenance.style]
                if (style.name, clip.fps) not in refs:
                    refs[(style.name, clip.fps)] = StyleReference(style, clip.fps)
                row = {"song": name, "engine": engine, **measure(clip, style, refs[(style.name, clip.fps)]),
                       "seconds": time.perf_counter() - t}
                rows.append(row)
                progress(f"{name[:24]:24s} {engine:9s} " + " ".join(f"{k}={_cell(row[k], d)}" for k, _, d in COLUMNS))
    return {"rows": rows, "summary": summary(rows), "dancesynth": _package_path()}


SUMMARY = (("steps", "new one-frame steps", sum), ("tj_p99", "worst transition jump / mocap p99", "max"),
           ("tj_vs_own_beats", "... / max(p99, the source's own jump at those beats)", "max"),
           ("skate_vs_mocap", "worst skate / style mocap", "max"),
           ("skate_vs_source", "worst skate / own source", "max"), ("pfc_vs_mocap", "worst pfc / mocap", "max"))


def summary(rows) -> dict:
    """Per engine, over the bundled songs and the mix (not the forced styles): totals and worsts."""
    out = {}
    for engine in dict.fromkeys(r["engine"] for r in rows):
        mine = [r for r in rows if r["engine"] == engine and " as " not in r["song"]]
        out[engine] = {key: (int(sum(r[key] for r in mine)) if how is sum else _max(r[key] for r in mine))
                       for key, _, how in SUMMARY}
    return out


def _max(values):
    values = [v for v in values if v is not None]
    return max(values) if values else None


def _cell(v, digits):
    if v is None:
        return "-"
    return f"{v:.{digits}f}" if isinstance(v, float) else str(v)


def format_table(result) -> str:
    head = ["song", "engine", "style"] + [title for _, title, _ in COLUMNS]
    body = [[r["song"][:28], r["engine"], r["style"][:16]] + [_cell(r[k], d) for k, _, d in COLUMNS]
            for r in result["rows"]]
    widths = [max(len(x[i]) for x in [head] + body) for i in range(len(head))]
    lines = ["  ".join(c.ljust(w) if i < 3 else c.rjust(w) for i, (c, w) in enumerate(zip(x, widths)))
             for x in [head] + body]
    lines.insert(1, "  ".join("-" * w for w in widths))
    lines += ["", _format_summary(result["summary"], result.get("before", {}).get("summary"))]
    return "\n".join(lines)


def _format_summary(after, before=None) -> str:
    lines = ["over the bundled songs and the mix" + (" (before -> after)" if before else "") + ":"]
    for engine, s in after.items():
        cells = []
        for key, title, _ in SUMMARY:
            now = _cell(s[key], 2)
            cells.append(f"{title} {_cell(before[engine][key], 2)} -> {now}" if before and engine in before
                         else f"{title} {now}")
        lines.append(f"  {engine}: " + "; ".join(cells))
    return "\n".join(lines)


def _package_path() -> str:
    import dancesynth

    return str(Path(dancesynth.__file__).parent)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--songs", nargs="*", default=None, help="bundled song names or paths (default: all bundled)")
    ap.add_argument("--engines", nargs="*", default=list(ENGINES), choices=ENGINES)
    ap.add_argument("--mix-s", type=float, default=600.0, help="length of the looped mix (0: none)")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "artefact_bench.json")
    ap.add_argument("--styles", nargs="*", default=[], help="also dance the default song in these styles")
    ap.add_argument("--src", type=Path, default=REPO / "src", help="import dancesynth from this folder")
    ap.add_argument("--before", type=Path, help="a result of this script on older code, kept for comparison")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(args.src))
    from dancesynth.bench.common import MUSIC_DIR

    songs = args.songs or sorted(p.name for p in MUSIC_DIR.glob("*.ogg"))
    result = run(songs, args.engines, args.mix_s, args.styles,
                 progress=lambda m: print(m, file=sys.stderr, flush=True))
    if args.before:
        result["before"] = json.loads(args.before.read_text())
    print(format_table(result))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

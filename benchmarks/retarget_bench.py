"""Retargeting, measured: every bundled style danced on every kind of character a user brings.

    .venv/bin/python benchmarks/retarget_bench.py [--out benchmarks/results]

Sources: a dance of each bundled style (Daz salsa, CMU, Perfume skeletons) on the bundled
song. Targets: the built-in rigs (mannequin, mixamo, vrm, smpl, cmu); rigs a user would
bring, as files: a Mixamo-named BVH in centimetres resting in an A-pose with longer legs
and shorter arms than ours, a Character Creator BVH from the CMU iClone conversions (101
joints with twist and share helpers, its floor where its own frames stand), each bundled
source skeleton as a BVH, and the mannequin as a VRM 1.0 avatar. Per pair: bone-direction
error (median, 95th percentile), foot skating per leg length (target vs source), ground
penetration, root height per leg length; targets: median <= 5 deg, skating <= source + 10 %,
penetration <= 2 cm, root height within 5 % of the source's. Then the time to retarget and
export a 3-minute dance as .glb (target <= 1 s). Prints a table and writes retarget_bench.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))   # the user-like rigs the tests use too

from user_rigs import apose_mixamo_bvh  # noqa: E402

SONG = REPO / "src" / "dancesynth" / "data" / "music" / "Kevin_MacLeod_-_Vibe_Ace.ogg"
CC_RIG = Path("/work/shared/data/mocap/cmu_iclone_cc/002_01.bvh")
TARGETS = {"direction_deg": 5.0, "skate_ratio": 1.10, "penetration_m": 0.02, "root_height_ratio": 0.05,
           "export_3min_s": 1.0}


def style_rig_bvh(folder: Path, style) -> Path:
    from dancesynth.io.bvh import format_bvh

    path = folder / f"{style.name}_rig.bvh"
    path.write_text(format_bvh(style.clip(0).frames(0, 60)))
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    args = ap.parse_args(argv)

    from dancesynth.api import dance
    from dancesynth.eval.retarget import retarget_quality
    from dancesynth.export.formats import encode_dance
    from dancesynth.motion.database import open_database
    from dancesynth.retarget.character import load_character
    from dancesynth.retarget.humanoid import find_bones
    from dancesynth.retarget.solve import retarget

    db = open_database()
    styles = list(db.styles.values())
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        targets = {n: n for n in ("mannequin", "mixamo", "vrm", "smpl", "cmu")}
        targets["mixamo A-pose cm (bvh)"] = apose_mixamo_bvh(tmp)
        if CC_RIG.is_file():
            targets["Character Creator (bvh)"] = CC_RIG
        for st in styles:
            if st.name in ("salsa-133-150bpm", "pop-82-103bpm", "mj", "whirl"):   # one per distinct skeleton layout
                targets[f"{st.name} skeleton (bvh)"] = style_rig_bvh(tmp, st)
        vrm = _vrm_avatar(tmp)
        if vrm is not None:
            targets["mannequin VRM 1.0 (vrm)"] = vrm
        characters = {name: load_character(spec) for name, spec in targets.items()}

        rows = []
        for st in styles:
            clip = dance(SONG, database=db, style=st.name, seed=1)
            src_bones = find_bones(clip.skeleton)
            for name, ch in characters.items():
                t0 = time.perf_counter()
                out = retarget(clip, ch, src_bones)
                dt = time.perf_counter() - t0
                q = retarget_quality(clip, out, src_bones, ch.bones)
                rows.append({"style": st.name, "target": name, "joints": ch.skeleton.n_joints,
                             "retarget_s_per_min": dt / (clip.duration_s / 60), **q})

        long_clip = _tiled(dance(SONG, database=db, style="salsa-133-150bpm", seed=1), 180.0)
        timing = {}
        for fmt, ch_name in ((".glb", "mannequin"), (".bvh", "mannequin"), (".vrma", "mannequin")):
            ch = characters[ch_name]
            best = np.inf
            for _ in range(3):
                t0 = time.perf_counter()
                data = encode_dance(fmt, retarget(long_clip, ch), ch)
                best = min(best, time.perf_counter() - t0)
            timing[f"retarget+{fmt[1:]}_3min_s"] = best
            timing[f"{fmt[1:]}_3min_bytes"] = len(data)

    _print(rows, timing)
    checks = _checks(rows, timing)
    print("\n" + "\n".join(f"{'PASS' if ok else 'FAIL'}  {what}" for what, ok in checks.items()))
    args.out.mkdir(parents=True, exist_ok=True)
    from dancesynth.io.files import jsonable

    (args.out / "retarget_bench.json").write_text(json.dumps(jsonable(
        {"targets": TARGETS, "rows": rows, "timing": timing, "checks": checks}), indent=1) + "\n")
    return 0 if all(checks.values()) else 1


def _vrm_avatar(folder: Path) -> Path | None:
    try:
        from dancesynth.export.vrm import vrm_bytes
        from dancesynth.retarget.character import builtin_character
    except ImportError:
        return None
    path = folder / "mannequin.vrm"
    path.write_bytes(vrm_bytes(builtin_character("mannequin")))
    return path


def _tiled(clip, seconds: float):
    from dancesynth.types import MotionClip

    reps = int(np.ceil(seconds * clip.fps / clip.n_frames))
    n = int(seconds * clip.fps)
    return MotionClip(clip.skeleton, clip.fps, np.tile(clip.root_pos, (reps, 1))[:n],
                      np.tile(clip.local_rot, (reps, 1, 1))[:n])


def _ok(r) -> dict:
    return {"direction": r["bone_direction_median_deg"] <= TARGETS["direction_deg"],
            "skate": r["skate_target"] <= r["skate_source"] * TARGETS["skate_ratio"] + 1e-9,
            "penetration": r["penetration_target_m"] <= TARGETS["penetration_m"],
            "root": abs(r["root_height_target"] / r["root_height_source"] - 1) <= TARGETS["root_height_ratio"]}


def _checks(rows, timing) -> dict:
    out = {}
    for key, label in (("direction", f"bone direction median <= {TARGETS['direction_deg']} deg"),
                       ("skate", "foot skating <= source + 10 %"),
                       ("penetration", f"ground penetration <= {TARGETS['penetration_m'] * 100:g} cm"),
                       ("root", "root height / leg length within 5 % of the source's")):
        out[f"{label}: {sum(_ok(r)[key] for r in rows)}/{len(rows)} pairs"] = all(_ok(r)[key] for r in rows)
    out[f"retarget + .glb export of a 3-minute dance <= {TARGETS['export_3min_s']:g} s"] = \
        timing["retarget+glb_3min_s"] <= TARGETS["export_3min_s"]
    return out


def _print(rows, timing) -> None:
    head = (f"{'style':<18}{'target':<30}{'joints':>7}{'dir med':>9}{'dir p95':>9}{'skate src':>10}"
            f"{'skate tgt':>10}{'pen src':>9}{'pen tgt':>9}{'root src':>9}{'root tgt':>9}")
    print(head)
    print("-" * len(head))
    for r in rows:
        flag = "" if all(_ok(r).values()) else "  <-- " + ", ".join(k for k, v in _ok(r).items() if not v)
        print(f"{r['style']:<18}{r['target']:<30}{r['joints']:>7}{r['bone_direction_median_deg']:>8.2f}°"
              f"{r['bone_direction_p95_deg']:>8.2f}°{r['skate_source']:>10.3f}{r['skate_target']:>10.3f}"
              f"{r['penetration_source_m'] * 100:>7.1f}cm{r['penetration_target_m'] * 100:>7.1f}cm"
              f"{r['root_height_source']:>9.3f}{r['root_height_target']:>9.3f}{flag}")
    print("\nskate: ankle speed on planted frames, leg lengths per second; root: upper-leg mid-point height "
          "over the floor per leg length")
    for k, v in timing.items():
        print(f"{k:<28}{v:.3f}" if k.endswith("_s") else f"{k:<28}{v}")


if __name__ == "__main__":
    sys.exit(main())

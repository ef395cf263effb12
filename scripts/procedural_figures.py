"""Draw the pictures of docs/procedural.md (deterministic; about half a minute).

    .venv/bin/python scripts/procedural_figures.py [--out docs/img]

- procedural_frames.png: six frames of the character conducting a generated song
  (the product's own renderer), the right hand's last second drawn as a trail.
- procedural_trajectories.png: the right hand's path over three segments for the
  styles e1, e2 (the paper's two experiments: large and small L1) and lively.
- procedural_params.png: one segment drawn with one parameter changed at a time.
- procedural_speed.png: the right hand's speed, with beat notes (sudden stops).
- procedural_left_hand.png: the left hand on long and staccato notes.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

from dancesynth.engines.procedural import conduct_notes, default_skeleton, make_config  # noqa: E402
from dancesynth.engines.procedural.engine import plan_right_hand  # noqa: E402
from dancesynth.engines.procedural.segment import segment  # noqa: E402
from dancesynth.engines.procedural.speed import sample_path  # noqa: E402
from dancesynth.bench import groundtruth as gt  # noqa: E402
from dancesynth.kinematics import clip_fk  # noqa: E402
from dancesynth.motion.roles import find_roles  # noqa: E402
from dancesynth.motion.database import open_database  # noqa: E402
from dancesynth.music.notes import DRUM_CHANNEL, midi_notes, write_midi_parts  # noqa: E402


def _conduct(notes):
    clip = conduct_notes(notes, skeleton=default_skeleton(open_database()))
    return clip, clip_fk(clip)[1], find_roles(clip.skeleton)


def _save(fig, out: Path, plt) -> None:
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)


def songs(tmp: Path):
    gt.write_midi(gt.SongSpec("demo", (100,), duration_s=30.0, seed=4), tmp / "demo.mid")
    # Long notes, a staccato pair and running eighths, with a kick on every beat.
    melody, drums = [], [(b, 0.25, 36, 100) for b in range(24)]
    for bar, p in enumerate((60, 65, 67, 72, 67, 64)):
        melody += [(4 * bar, 1.9, p, 90), (4 * bar + 2, 0.15, p + 2, 100), (4 * bar + 2.5, 0.15, p + 4, 100),
                   (4 * bar + 3, 0.5, p + 5, 70), (4 * bar + 3.5, 0.5, p + 7, 70)]
    write_midi_parts(tmp / "phrases.mid", [("Melody", 0, melody), ("Drums", DRUM_CHANNEL, drums)], tempo_bpm=120)
    return midi_notes(tmp / "demo.mid"), midi_notes(tmp / "phrases.mid")


def frames_picture(notes, out: Path) -> None:
    from PIL import Image, ImageDraw

    from dancesynth.export.render import FrameRenderer, figure_points

    clip, pos, roles = _conduct(notes)
    renderer = FrameRenderer(clip, 480, 400)
    wrist = roles.wrists[1]
    picks = np.round(np.linspace(4.0, 16.0, 6) * clip.fps).astype(int)
    sheet = Image.new("RGB", (3 * 480, 2 * 400), "white")
    for n, f in enumerate(picks):
        img = renderer.draw(int(f), figure_points(clip, renderer.fig, np.array([f]))[0])
        cam = renderer.camera(int(f))
        trail = cam.to_pixels(cam.to_camera(pos[max(0, f - int(clip.fps)):f + 1, wrist])) / renderer.supersample
        ImageDraw.Draw(img).line([tuple(p) for p in trail], fill=(200, 30, 30), width=3)
        ImageDraw.Draw(img).text((10, 10), f"t = {f / clip.fps:.1f} s", fill=(0, 0, 0))
        sheet.paste(img, ((n % 3) * 480, (n // 3) * 400))
    sheet.save(out)


def _path_xy(notes, cfg, t0, t1):
    keys, path, _ = plan_right_hand(notes, segment(notes, cfg), cfg)
    t = np.linspace(t0, t1, 600)
    p = sample_path(path, cfg, t)
    sel = (keys.times_s >= t0) & (keys.times_s <= t1)
    return p, keys.pos[sel], keys.corner[sel]


def trajectories_picture(notes, out: Path, plt) -> None:
    cfg0 = make_config()
    bounds = segment(notes, cfg0)
    t0, t1 = notes.onset_s[bounds[1][0] - 1], notes.onset_s[bounds[3][1] - 1]
    fig, axes = plt.subplots(1, 3, figsize=(13, 4), sharex=True, sharey=True)
    for ax, style in zip(axes, ("e1", "e2", "lively")):
        p, k, corner = _path_xy(notes, make_config(style=style), t0, t1)
        ax.plot(p[:, 0], p[:, 1], "-", color="tab:blue", lw=1.5)
        ax.plot(k[~corner, 0], k[~corner, 1], "o", color="tab:green", ms=5, label="regular note")
        ax.plot(k[corner, 0], k[corner, 1], "s", color="tab:red", ms=5, label="beat or rest note")
        ax.set_title(f"style {style}")
        ax.set_xlabel("x (arm lengths, towards the midline)")
        ax.set_aspect("equal")
    axes[0].set_ylabel("height (arm lengths from the shoulder)")
    axes[0].legend(loc="lower left", fontsize=8)
    fig.suptitle(f"Right-hand path over three segments ({t0:.1f}-{t1:.1f} s), cf. Loi & Li Fig. 10")
    _save(fig, out, plt)


def params_picture(notes, out: Path, plt) -> None:
    cfg0 = make_config()
    bounds = segment(notes, cfg0)
    t0, t1 = notes.onset_s[bounds[2][0] - 1], notes.onset_s[bounds[2][1] - 1]
    changes = [("l1", (0.05, 0.45)), ("l2", (0.0, 0.45)), ("bounce", (0.0, 1.0)), ("y_scale", (0.015, 0.06))]
    fig, axes = plt.subplots(1, len(changes), figsize=(15, 3.8), sharey=True)
    for ax, (name, values) in zip(axes, changes):
        for v, colour in zip(values, ("tab:blue", "tab:orange")):
            cfg = make_config(params=[f"{name}={v}"])
            p, k, corner = _path_xy(notes, cfg, t0, t1)
            ax.plot(p[:, 0], p[:, 1], "-", color=colour, label=f"{name} = {v}")
            ax.plot(k[corner, 0], k[corner, 1], "s", color=colour, ms=4)
        ax.set_title(name)
        ax.legend(fontsize=8)
        ax.set_aspect("equal")
    axes[0].set_ylabel("height (arm lengths)")
    fig.suptitle("One segment of the right hand's path, one parameter changed (squares: beat/rest notes)")
    _save(fig, out, plt)


def speed_picture(notes, out: Path, plt) -> None:
    clip, pos, roles = _conduct(notes)
    speed = np.linalg.norm(np.diff(pos[:, roles.wrists[1]], axis=0), axis=1) * clip.fps
    t = (np.arange(len(speed)) + 0.5) / clip.fps
    sel = (t > 6) & (t < 14)
    fig, ax = plt.subplots(figsize=(12, 3.2))
    ax.plot(t[sel], speed[sel], "-", color="tab:blue", label="right wrist speed (m/s)")
    for i, tb in enumerate(clip.meta["beat_note_times_s"]):
        if 6 < tb < 14:
            ax.axvline(tb, color="tab:red", lw=0.8, alpha=0.7, label="beat note" if i == 0 or tb < 6.7 else None)
    ax.set_xlabel("time (s)")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title("Speed profile (Loi & Li Fig. 7): accelerate into a beat note, stop dead, start again from rest")
    _save(fig, out, plt)


def left_hand_picture(notes, out: Path, plt) -> None:
    clip, pos, roles = _conduct(notes)
    t = np.arange(clip.n_frames) / clip.fps
    rel = pos[:, roles.wrists[0]] - pos[:, roles.shoulders[0]]
    fig, ax = plt.subplots(figsize=(12, 3.2))
    ax.plot(t, rel[:, 0], label="left wrist: out to the side (m)")
    ax.plot(t, rel[:, 1], label="left wrist: height below the shoulder (m)")
    for a, b in clip.meta["long_notes_s"]:
        ax.axvspan(a, b, color="tab:green", alpha=0.15)
    for s in clip.meta["staccato_s"]:
        ax.axvline(s, color="tab:red", lw=0.8)
    ax.set_xlim(0, 8)
    ax.set_xlabel("time (s); green: long notes, red: staccato notes")
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title("Left hand (§V.G): out on long notes, a quick drop and dead stop on staccato notes")
    _save(fig, out, plt)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "img")
    args = ap.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as d:
        demo, phrases = songs(Path(d))
    frames_picture(demo, args.out / "procedural_frames.png")
    trajectories_picture(demo, args.out / "procedural_trajectories.png", plt)
    params_picture(demo, args.out / "procedural_params.png", plt)
    speed_picture(demo, args.out / "procedural_speed.png", plt)
    left_hand_picture(phrases, args.out / "procedural_left_hand.png", plt)
    for name in sorted(args.out.glob("procedural_*.png")):
        print(f"wrote {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

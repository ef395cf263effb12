"""``dancesynth eval`` as a library call: files in, one JSON-ready dict out.

This is the only evaluation module that reads files: it loads the dance (BVH),
analyses the song the way ``dancesynth dance`` does, finds the mocap to compare
with, and runs the pure ``evaluate`` on each motion.
"""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..types import FALLBACK_BPM, MotionClip, MusicFeatures
from .evaluate import EvalParams, evaluate, mocap_reference

# A dance and its song may differ by this much (fraction of the song, plus 1 s)
# before the pairing is refused: a dance of another song is no dance of this one.
DURATION_TOLERANCE = 0.1


def load_dance_report(path: Path) -> dict:
    """The JSON ``dancesynth dance --report`` wrote (transitions, warp rates, style)."""
    try:
        report = json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise InputError(f"{path}: no such report file") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{path}: not a dance report ({exc}); write one with `dancesynth dance --report`") from None
    if not isinstance(report, dict) or "transition_times_s" not in report:
        raise InputError(f"{path}: not a dance report (no transition_times_s); "
                         "write one with `dancesynth dance --report`")
    return report


def _pick_mocap(dance: MotionClip, music: MusicFeatures, style: str | None, report: dict | None, database):
    """The source mocap to compare with: ``style``, else the report's, else the best match of skeleton and
    tempo; ``None`` when no style has the dance's skeleton."""
    from ..motion.database import MotionDatabase, open_database

    db = database if isinstance(database, MotionDatabase) else open_database(database)
    name = style or (report or {}).get("style")
    if name:
        candidates = db.styles_of(name)  # raises InputError naming the choices
    else:   # a style on the dance's own skeleton; else any, for a humanoid (read on its rig: eval.rigs)
        joints = set(dance.skeleton.names)
        candidates = [s for s in db.styles.values() if set(s.skeleton.names) == joints]
        if not candidates:
            from ..retarget.humanoid import find_bones

            try:
                find_bones(dance.skeleton)
            except InputError:
                return None
            candidates = [s for s in db.styles.values() if s.captured_s >= 120.0] or list(db.styles.values())
    tempo = music.tempo_bpm if music.tempo_bpm > 0 else FALLBACK_BPM
    return min(candidates, key=lambda s: abs(np.log2(np.median(s.clip_tempo_bpm) / tempo)))


@lru_cache(maxsize=8)
def _style_reference(style, fps: float):
    """A style's mocap statistics (once per style and frame rate: a batch evaluates many dances)."""
    return mocap_reference([style.clip(i) for i in range(style.n_clips)], fps)


def evaluate_files(dance_path: Path, song_path: Path, *, reference_path: Path | None = None,
                   report_path: Path | None = None, style: str | None = None, database=None,
                   params: EvalParams = EvalParams()) -> dict:
    """Every metric for the dance in ``dance_path`` against ``song_path`` (and for a reference motion).

    Returns ``{"dance": metrics, "reference": metrics (with reference_path),
    "song": {...}, "mocap_style": name or None, "params": {...}}``. The metrics of
    ``dancesynth.eval.evaluate``; transition and time-warp metrics need the dance's
    report (``dance --report``), the mocap comparisons a style of the database.
    """
    from ..io.bvh import read_bvh
    from ..music import analyze_music

    dance = read_bvh(dance_path)
    music = analyze_music(path=song_path, structure=True)
    _check_durations(dance, music, dance_path, song_path)
    report = load_dance_report(report_path) if report_path is not None else None
    reference = read_bvh(reference_path) if reference_path is not None else None
    result = evaluate_dance(dance, music, report=report, style=style, database=database, params=params,
                            reference=reference)
    result["song"]["path"] = str(song_path)
    return result


def evaluate_dance(dance: MotionClip, music: MusicFeatures, *, report: dict | None = None, style: str | None = None,
                   database=None, params: EvalParams = EvalParams(), reference: MotionClip | None = None) -> dict:
    """``evaluate_files`` for a dance and song already in memory (``report``: ``Provenance.report()``).

    The dance (and ``reference``) is measured on the skeleton of the mocap it is compared with
    (``eval.rigs.on_rig_of``): the same dance gives the same numbers whichever rig it was written on."""
    from dataclasses import asdict

    from .rigs import on_rig_of

    mocap = _pick_mocap(dance, music, style, report, database)
    if mocap is not None:
        dance = on_rig_of(dance, mocap)
        reference = None if reference is None else on_rig_of(reference, mocap)

    def reference_of(clip):
        return None if mocap is None else _style_reference(mocap, clip.fps)

    common = dict(music_beats_s=music.beat_times_s, music_loudness_db=music.intensity_db, params=params,
                  beat_in_bar=music.beat_in_bar, beats_per_bar=music.beats_per_bar)
    result = {
        "dance": evaluate(dance, transitions_s=report["transition_times_s"] if report else None,
                          warp_rates=report["warp_rates"] if report else None,
                          mocap=reference_of(dance), **common),
        "song": {"path": music.source, "duration_s": music.duration_s, "tempo_bpm": music.tempo_bpm,
                 "beats": len(music.beat_times_s), "beat_confidence": music.beat_confidence,
                 "default_tempo": music.default_tempo, "beats_per_bar": music.beats_per_bar,
                 "metre_confidence": music.meta.get("metre_confidence")},
        "mocap_style": None if mocap is None else mocap.name,
        "params": asdict(params),
    }
    if reference is not None:
        result["reference"] = evaluate(reference, mocap=reference_of(reference), **common)
    if music.structure is not None:   # does the dance follow the song's form (eval.form)
        from .form import form_score

        result["song"]["sections"] = music.structure.report()["sections"]
        for key in ("dance", "reference"):
            if key in result and music.beats_per_bar:
                result[key].update(form_score(dance if key == "dance" else reference, music.structure,
                                              music.beats_per_bar))
    return result


def _check_durations(dance: MotionClip, music: MusicFeatures, dance_path, song_path) -> None:
    if abs(dance.duration_s - music.duration_s) > DURATION_TOLERANCE * music.duration_s + 1.0:
        raise InputError(f"{dance_path} lasts {dance.duration_s:.1f} s but {song_path} lasts "
                         f"{music.duration_s:.1f} s: evaluate a dance against the song it was made for "
                         "(or cut the song to the dance's length, e.g. ffmpeg -t)")


def beat_plot_data(dance: MotionClip, music_beats_s, params: EvalParams = EvalParams()) -> dict:
    """The curves of Aristidou et al.'s Fig. 7: speed, smoothed speed, kinematic beats, music beats."""
    from .motion_metrics import kinematic_beats

    beats_s, speed, smoothed = kinematic_beats(dance, smooth_s=params.beat_smooth_s, polyorder=params.beat_polyorder,
                                               min_separation_s=params.beat_min_separation_s,
                                               min_prominence_frac=params.beat_min_prominence_frac)
    return {"time_s": np.arange(dance.n_frames) / dance.fps, "speed": speed, "smoothed": smoothed,
            "kinematic_beats_s": beats_s, "music_beats_s": np.asarray(music_beats_s, dtype=float)}


def plot_beats(data: dict, out_path: Path, *, title: str = "", window_s: tuple[float, float] | None = None) -> None:
    """Draw ``beat_plot_data`` as a PNG (or any format matplotlib writes by suffix)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io.files import atomic_output

    t = data["time_s"]
    lo, hi = window_s if window_s else (0.0, float(t[-1]) if t.size else 0.0)
    shown = (t >= lo) & (t <= hi)
    fig, ax = plt.subplots(figsize=(12, 3.6), dpi=110)
    ax.plot(t[shown], data["speed"][shown], color="0.75", lw=1, label="summed joint speed")
    ax.plot(t[shown], data["smoothed"][shown], color="tab:blue", lw=1.6, label="smoothed (Savitzky-Golay)")
    first = True
    for b in data["music_beats_s"][(data["music_beats_s"] >= lo) & (data["music_beats_s"] <= hi)]:
        ax.axvline(b, color="tab:red", lw=0.9, alpha=0.7, label="music beat" if first else None)
        first = False
    kb = data["kinematic_beats_s"][(data["kinematic_beats_s"] >= lo) & (data["kinematic_beats_s"] <= hi)]
    ax.plot(kb, np.interp(kb, t, data["smoothed"]), "o", color="tab:green", ms=5, label="kinematic beat")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("speed (m/s, summed over joints)")
    ax.set_xlim(lo, hi)
    ax.set_title(title or "motion speed, kinematic beats and music beats")
    ax.legend(loc="upper right", fontsize=8, ncol=4)
    fig.tight_layout()
    suffix = Path(out_path).suffix.lower().lstrip(".") or "png"
    try:
        with atomic_output(out_path, "wb") as fh:
            fig.savefig(fh, format=suffix)
    except ValueError as exc:
        raise InputError(f"cannot write a plot as {out_path}: {exc}; use .png, .pdf or .svg") from None
    finally:
        plt.close(fig)

"""Beat-tracking table: every tracker on generated songs whose beats are known exactly.

The songs come from ``dancesynth.eval.groundtruth`` (MIDI rendered by fluidsynth);
each tracker in ``dancesynth.music.beats.TRACKERS`` runs through
``dancesynth.music.track_beats`` on the decoded audio, and is scored with
``beat_tracking_scores`` (F-measure within 70 ms, continuity CMLt/AMLt, the first
5 s skipped). Speed is audio duration over tracking time (onset envelope included),
after one untimed warm-up call per tracker (librosa compiles its kernels then).

The ``streaming`` row is the live tracker (``dancesynth.live.beats``) fed each song
as a stream: 0.1 s chunks, ``update()`` every 5 s of audio (a segment), ``flush()``
at the end; its beats are those a live dancer got, scored the same way. Its speed
counts every push, update and flush.
"""

from __future__ import annotations

import time

import numpy as np

from .bench_common import BenchConfig, Progress, table

# Tag groups of the F-measure columns: name -> predicate on a song's tags.
TAG_GROUPS = {
    "constant": lambda t: t.get("tempo") == "constant",
    "step": lambda t: t.get("tempo") == "step",
    "ramp": lambda t: t.get("tempo") == "ramp",
    "swing": lambda t: bool(t.get("swing")),
    "3/4": lambda t: t.get("meter") == "3/4",
    "no drums": lambda t: not t.get("drums", True),
}
SCORES = ("f_measure", "cmlc", "cmlt", "amlc", "amlt")
STREAMING = "streaming"
STREAM_CHUNK_S = 0.1
STREAM_UPDATE_S = 5.0


def _scorer():
    """``beat_tracking_scores`` from the metrics module, wherever it lives; mir_eval as the fallback."""
    for module in ("metrics", "evaluate"):
        try:
            mod = __import__(f"{__package__}.{module}", fromlist=["beat_tracking_scores"])
            return mod.beat_tracking_scores, f"dancesynth.eval.{module}.beat_tracking_scores"
        except (ImportError, AttributeError):
            continue
    import mir_eval

    def scores(reference_beats_s, estimated_beats_s, *, window_s=0.07, skip_s=5.0) -> dict:
        ref = mir_eval.beat.trim_beats(np.asarray(reference_beats_s, float), min_beat_time=skip_s)
        est = mir_eval.beat.trim_beats(np.asarray(estimated_beats_s, float), min_beat_time=skip_s)
        f = mir_eval.beat.f_measure(ref, est, f_measure_threshold=window_s)
        cmlc, cmlt, amlc, amlt = mir_eval.beat.continuity(ref, est)
        return {"f_measure": f, "cmlc": cmlc, "cmlt": cmlt, "amlc": amlc, "amlt": amlt}

    return scores, "mir_eval (fallback: no beat_tracking_scores in dancesynth.eval)"


def beat_tracking(cfg: BenchConfig, progress: Progress | None = None) -> dict:
    from ..io.audio import load_audio
    from ..live.beats import LATENCY_S, stream_beats
    from ..motion.database import cache_dir
    from ..music import track_beats
    from ..music.beats import TRACKERS
    from .groundtruth import ground_truth_set

    score, scorer = _scorer()
    trackers = list(cfg.trackers or sorted(TRACKERS) + [STREAMING])
    kwargs = {"quick": cfg.groundtruth_quick, "progress": progress}
    if cfg.groundtruth_specs is not None:
        kwargs["specs"] = list(cfg.groundtruth_specs)
    songs = ground_truth_set(cfg.groundtruth_dir or cache_dir() / "groundtruth", **kwargs)
    if not songs:
        raise RuntimeError("the ground-truth set is empty")
    audio = []
    for song in songs:
        y, sr = load_audio(song.audio_path)
        audio.append((y, sr))
    results = {}
    for name in trackers:
        if progress:
            progress(f"beat tracking: {name} on {len(songs)} songs")
        if name == STREAMING:
            def run(y, sr):
                return stream_beats(y, sr, chunk_s=STREAM_CHUNK_S, update_every_s=STREAM_UPDATE_S)[0]
        else:
            def run(y, sr, name=name):
                return track_beats(y, sr, tracker=name)[0]
        run(*audio[0])  # warm-up, untimed
        per_song = []
        for song, (y, sr) in zip(songs, audio):
            t = time.perf_counter()
            est = run(y, sr)
            secs = time.perf_counter() - t
            s = {k: float(v) for k, v in score(song.beats_s, est).items()}
            per_song.append({"song": song.name, "tags": dict(song.tags), "duration_s": len(y) / sr,
                             "time_s": secs, **s})
        results[name] = {"mean": _summary(per_song), "songs": per_song}
    streaming = {"latency_s": LATENCY_S, "chunk_s": STREAM_CHUNK_S, "update_every_s": STREAM_UPDATE_S}
    return {"trackers": trackers, "songs": [s.name for s in songs], "scorer": scorer,
            **({"streaming": streaming} if STREAMING in trackers else {}),
            "groups": {g: sum(1 for s in songs if pred(s.tags)) for g, pred in TAG_GROUPS.items()},
            "results": results}


def _summary(per_song: list[dict]) -> dict:
    out = {k: _nanmean([s.get(k) for s in per_song]) for k in SCORES}
    out["speed_x_realtime"] = float(sum(s["duration_s"] for s in per_song) / max(sum(s["time_s"] for s in per_song),
                                                                                  1e-12))
    for g, pred in TAG_GROUPS.items():
        out[f"f_{g}"] = _nanmean([s["f_measure"] for s in per_song if pred(s["tags"])])
    return out


def _nanmean(values) -> float | None:
    """Mean of the finite values; None when there is none (a group without songs)."""
    vals = [float(v) for v in values if v is not None and np.isfinite(float(v))]
    return float(np.mean(vals)) if vals else None


def format_beat_tracking(s: dict) -> str:
    groups = list(TAG_GROUPS)
    rows = [[name, r["mean"]["f_measure"], r["mean"]["cmlt"], r["mean"]["amlt"], r["mean"]["speed_x_realtime"]]
            + [r["mean"][f"f_{g}"] for g in groups] for name, r in s["results"].items()]
    counts = ", ".join(f"{g} {n}" for g, n in s["groups"].items())
    notes = [f"F within 70 ms, continuity within 17.5% of the beat, first 5 s skipped; scored by {s['scorer']}",
             f"songs per group: {counts} (- : no song in the group)"]
    if "streaming" in s:
        st = s["streaming"]
        notes.append(f"streaming: the live tracker fed {st['chunk_s']:g} s chunks and updated every "
                     f"{st['update_every_s']:g} s; a beat is given once {st['latency_s']:g} s old (its latency)")
    return table(
        f"Beat tracking on {len(s['songs'])} generated songs with exact beats (MIDI rendered by fluidsynth)",
        ["tracker", "F", "CMLt", "AMLt", "x real time"] + [f"F {g}" for g in groups], rows,
        [0, 3, 3, 3, 0] + [3] * len(groups), notes=notes)

"""Beat-tracking table: every tracker on generated songs whose beats are known exactly.

The songs come from ``dancesynth.bench.groundtruth`` (MIDI rendered by fluidsynth);
each tracker in ``dancesynth.music.beats.TRACKERS`` runs through
``dancesynth.music.track_beats`` on the decoded audio, and is scored with
``eval.beat_metrics.beat_tracking_scores`` (F-measure within 70 ms, continuity CMLt/AMLt,
McKinney's P-score, the first 5 s skipped). Speed is audio duration over tracking time (onset envelope included),
after one untimed warm-up call per tracker (librosa compiles its kernels then).

The ``streaming`` row is the live tracker (``dancesynth.live.beats``) fed each song
as a stream: 0.1 s chunks, ``update()`` every 5 s of audio (a segment), ``flush()``
at the end; its beats are those a live dancer got, scored the same way. Its speed
counts every push, update and flush.

Downbeats and metre (``downbeat_tracking``): the bars' first beats as
``analyze_music`` finds them (``dancesynth.music.metre``), as the live tracker gives
them, and as counting 4/4 from the first tracked beat would (the chance row: the
generated songs start on any beat of the bar), scored by the same F-measure (70 ms,
first 5 s skipped) against the generator's exact bar positions, with the metre
(3 or 4) right or wrong per song. ``metre_report`` adds the bundled songs (no truth:
what was found, and how often the live count agrees with the offline one) and is
what docs/beat-tracking.md quotes.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from .common import BenchConfig, Progress, split_name, table

# Tag groups of the F-measure columns: name -> predicate on a song's tags.
TAG_GROUPS = {
    "constant": lambda t: t.get("tempo") == "constant",
    "step": lambda t: t.get("tempo") == "step",
    "ramp": lambda t: t.get("tempo") == "ramp",
    "swing": lambda t: bool(t.get("swing")),
    "3/4": lambda t: t.get("meter") == "3/4",
    "no drums": lambda t: not t.get("drums", True),
}
SCORES = ("f_measure", "cmlc", "cmlt", "amlc", "amlt", "p_score")
STREAMING = "streaming"
STREAM_CHUNK_S = 0.1
STREAM_UPDATE_S = 5.0
# Rows of the downbeat table.
ANALYSIS = "analysis"
FIRST_BEAT = "first beat, 4/4"
# The live count is compared with the offline one after this long (it settles over a few bars).
SETTLE_S = 10.0


SCORER = "dancesynth.eval.beat_metrics.beat_tracking_scores (mir_eval's definitions)"


def beat_tracking(cfg: BenchConfig, progress: Progress | None = None) -> dict:
    from ..io.audio import load_audio
    from ..live.beats import LATENCY_S, stream_updates
    from ..motion.database import cache_dir
    from ..music import track_beats
    from ..music.beats import TRACKERS
    from .groundtruth import ground_truth_set

    from ..eval.beat_metrics import beat_tracking_scores as score

    trackers = list(cfg.trackers or sorted(TRACKERS) + [STREAMING])
    kwargs = {"quick": cfg.groundtruth_quick, "progress": progress, "split": cfg.groundtruth_split}
    if cfg.groundtruth_specs is not None:
        kwargs["specs"] = list(cfg.groundtruth_specs)
    songs = ground_truth_set(cfg.groundtruth_dir or cache_dir() / "groundtruth", **kwargs)
    if not songs:
        raise RuntimeError("the ground-truth set is empty")
    audio = []
    for song in songs:
        y, sr = load_audio(song.audio_path)
        audio.append((y, sr))
    results, streamed = {}, []
    for name in trackers:
        if progress:
            progress(f"beat tracking: {name} on {len(songs)} songs")
        if name == STREAMING:
            def run(y, sr):
                return stream_updates(y, sr, chunk_s=STREAM_CHUNK_S, update_every_s=STREAM_UPDATE_S)
        else:
            def run(y, sr, name=name):
                return track_beats(y, sr, tracker=name)[0]
        run(*audio[0])  # warm-up, untimed
        per_song = []
        for song, (y, sr) in zip(songs, audio):
            t = time.perf_counter()
            est = run(y, sr)
            secs = time.perf_counter() - t
            if name == STREAMING:   # the updates also carry the bar positions, scored below
                streamed.append(est)
                est = np.concatenate([u.beat_times_s for u in est])
            s = {k: float(v) for k, v in score(song.beats_s, est).items()}
            per_song.append({"song": song.name, "tags": dict(song.tags), "duration_s": len(y) / sr,
                             "time_s": secs, **s})
        results[name] = {"mean": _summary(per_song), "songs": per_song}
    if progress:
        progress(f"downbeats and metre on {len(songs)} songs")
    downbeats = downbeat_tracking(songs, audio, streamed=streamed or None)
    streaming = {"latency_s": LATENCY_S, "chunk_s": STREAM_CHUNK_S, "update_every_s": STREAM_UPDATE_S}
    return {"trackers": trackers, "songs": [s.name for s in songs], "scorer": SCORER, "split": split_name(cfg),
            **({"streaming": streaming} if STREAMING in trackers else {}),
            "groups": {g: sum(1 for s in songs if pred(s.tags)) for g, pred in TAG_GROUPS.items()},
            "results": results, "downbeats": downbeats}


def downbeat_tracking(songs, audio, *, streamed: list | None = None) -> dict:
    """Downbeat F-measure and metre accuracy per song and on average, for each way of counting bars.

    ``songs``: ``GroundTruthSong`` with bar positions; ``audio``: their ``(y, sr)``;
    ``streamed``: per song, the live tracker's ``BeatUpdate`` list (a ``streaming``
    row when given). Rows: ``analysis`` (``analyze_music``; ``metre_ms``: the metre's
    share of its time), ``streaming``, and ``first beat, 4/4`` (chance).
    """
    from ..music import analyze_music
    from ..music.metre import default_positions, track_metre

    from ..eval.beat_metrics import beat_tracking_scores as score

    rows = {ANALYSIS: [], STREAMING: [], FIRST_BEAT: []}
    for k, (song, (y, sr)) in enumerate(zip(songs, audio)):
        music = analyze_music(y=y, sr=sr)
        t = time.perf_counter()
        track_metre(y, sr, beat_times_s=music.beat_times_s, end_s=music.duration_s, steady_grid=music.default_tempo)
        metre_ms = 1e3 * (time.perf_counter() - t)
        rows[ANALYSIS].append({**_downbeat_scores(song, music.beat_times_s, music.beat_in_bar, music.beats_per_bar,
                                                  score), "confidence": float(music.meta["metre_confidence"]),
                               "metre_ms": metre_ms, "duration_s": len(y) / sr})
        rows[FIRST_BEAT].append(_downbeat_scores(song, music.beat_times_s, default_positions(music.n_beats), 4,
                                                 score))
        if streamed is not None:
            updates = streamed[k]
            beats = np.concatenate([u.beat_times_s for u in updates])
            positions = np.concatenate([u.beat_in_bar for u in updates])
            rows[STREAMING].append(_downbeat_scores(song, beats, positions, updates[-1].beats_per_bar, score))
    if streamed is None:
        del rows[STREAMING]
    return {"songs": [s.name for s in songs],
            "groups": {g: sum(1 for s in songs if pred(s.tags)) for g, pred in DOWNBEAT_GROUPS.items()},
            "results": {name: {"mean": _downbeat_summary(r), "songs": r} for name, r in rows.items()}}


# Tag groups of the downbeat columns.
DOWNBEAT_GROUPS = {
    "3/4": lambda t: t.get("meter") == "3/4",
    "4/4": lambda t: t.get("meter") == "4/4",
    "pickup": lambda t: bool(t.get("pickup")),
    "no drums": lambda t: not t.get("drums", True),
}


def _downbeat_scores(song, beats_s, beat_in_bar, beats_per_bar: int, score) -> dict:
    """One song's downbeat F-measure (the ``score`` of beats applied to the bars' first beats) and metre."""
    positions = np.asarray(beat_in_bar)
    estimated = np.asarray(beats_s)[positions == 0] if positions.size else np.zeros(0)
    return {"song": song.name, "tags": dict(song.tags), "beats_per_bar": int(beats_per_bar),
            "true_beats_per_bar": int(song.beats_per_bar), "metre_correct": int(beats_per_bar) == song.beats_per_bar,
            "downbeat_f": float(score(song.downbeats_s, estimated)["f_measure"])}


def _downbeat_summary(per_song: list[dict]) -> dict:
    out = {"downbeat_f": _nanmean([s["downbeat_f"] for s in per_song]),
           "metre_accuracy": _nanmean([float(s["metre_correct"]) for s in per_song])}
    for g, pred in DOWNBEAT_GROUPS.items():
        out[f"f_{g}"] = _nanmean([s["downbeat_f"] for s in per_song if pred(s["tags"])])
    out["failures"] = [s["song"] for s in per_song if not s["metre_correct"] or s["downbeat_f"] < 0.9]
    if per_song and "metre_ms" in per_song[0]:
        out["metre_ms_per_minute"] = float(sum(s["metre_ms"] for s in per_song)
                                           / max(sum(s["duration_s"] for s in per_song) / 60.0, 1e-12))
    return out


def bundled_metres(paths=None, *, streaming: bool = True) -> list[dict]:
    """What the metre analysis finds in real songs (default: the bundled ones), which have no truth.

    Per song: tempo, metre, confidence, the jumps of the bar count (phase changes),
    the first downbeats, and with ``streaming`` the live tracker's final metre and the
    fraction of its beats after ``SETTLE_S`` (matched to an offline beat within 70 ms)
    that have the offline bar position.
    """
    from ..io.audio import load_audio
    from ..live.beats import stream_updates
    from ..music import analyze_music
    from .common import MUSIC_DIR

    out = []
    for path in sorted(MUSIC_DIR.glob("*.ogg")) if paths is None else [Path(p) for p in paths]:
        music = analyze_music(path=path)
        positions = music.beat_in_bar
        row = {"song": path.stem, "duration_s": music.duration_s, "tempo_bpm": music.tempo_bpm,
               "beats": music.n_beats, "beats_per_bar": music.beats_per_bar,
               "confidence": float(music.meta["metre_confidence"]),
               "jumps": int(np.count_nonzero(np.diff(positions) % music.beats_per_bar != 1)),
               "first_downbeats_s": [round(float(t), 2) for t in music.downbeat_times_s[:4]]}
        if streaming:
            y, sr = load_audio(path)
            updates = stream_updates(y, sr, chunk_s=STREAM_CHUNK_S, update_every_s=STREAM_UPDATE_S)
            live = np.concatenate([u.beat_times_s for u in updates])
            live_positions = np.concatenate([u.beat_in_bar for u in updates])
            nearest = np.clip(np.searchsorted(music.beat_times_s, live), 1, max(music.n_beats - 1, 1))
            nearest -= np.abs(music.beat_times_s[nearest - 1] - live) < np.abs(music.beat_times_s[nearest] - live)
            matched = (np.abs(music.beat_times_s[nearest] - live) <= 0.07) & (live >= SETTLE_S)
            row["live_beats_per_bar"] = updates[-1].beats_per_bar
            row["live_agreement"] = (float(np.mean(live_positions[matched] == positions[nearest[matched]]))
                                     if matched.any() else None)
        out.append(row)
    return out


def metre_report(cache_dir=None, *, quick: bool = False, bundled: bool = True, progress: Progress | None = None
                 ) -> dict:
    """Downbeats and metre on the generated set (offline, live, chance) and on the bundled songs.

    ``cache_dir``: where the generated songs are rendered (default: the dancesynth cache).
    """
    from ..io.audio import load_audio
    from ..live.beats import stream_updates
    from ..motion.database import cache_dir as default_cache
    from .groundtruth import ground_truth_set

    songs = ground_truth_set(Path(cache_dir) if cache_dir else default_cache() / "groundtruth", quick=quick,
                             progress=progress)
    audio = [load_audio(s.audio_path) for s in songs]
    if progress:
        progress(f"streaming {len(songs)} songs")
    streamed = [stream_updates(y, sr, chunk_s=STREAM_CHUNK_S, update_every_s=STREAM_UPDATE_S) for y, sr in audio]
    if progress:
        progress("downbeats and metre")
    out = {"downbeats": downbeat_tracking(songs, audio, streamed=streamed)}
    if bundled:
        if progress:
            progress("bundled songs")
        out["bundled"] = bundled_metres()
    return out


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
    rows = [[name, r["mean"]["f_measure"], r["mean"]["cmlt"], r["mean"]["amlt"], r["mean"].get("p_score"),
             r["mean"]["speed_x_realtime"]] + [r["mean"][f"f_{g}"] for g in groups] for name, r in s["results"].items()]
    counts = ", ".join(f"{g} {n}" for g, n in s["groups"].items())
    notes = [f"F within 70 ms, continuity within 17.5% of the beat, P-score within 20% of the beat, first 5 s "
             f"skipped; scored by {s['scorer']}",
             f"songs per group: {counts} (- : no song in the group)"]
    if "streaming" in s:
        st = s["streaming"]
        notes.append(f"streaming: the live tracker fed {st['chunk_s']:g} s chunks and updated every "
                     f"{st['update_every_s']:g} s; a beat is given once {st['latency_s']:g} s old (its latency)")
    text = table(
        f"Beat tracking on {len(s['songs'])} generated songs with exact beats (MIDI rendered by fluidsynth; "
        f"{s.get('split', 'test')} split)",
        ["tracker", "F", "CMLt", "AMLt", "P", "x real time"] + [f"F {g}" for g in groups], rows,
        [0, 3, 3, 3, 3, 0] + [3] * len(groups), notes=notes)
    return text + ("\n\n" + format_downbeat_tracking(s["downbeats"]) if "downbeats" in s else "")


def format_downbeat_tracking(d: dict) -> str:
    groups = list(DOWNBEAT_GROUPS)
    rows = [[name, r["mean"]["downbeat_f"], r["mean"]["metre_accuracy"]] + [r["mean"][f"f_{g}"] for g in groups]
            for name, r in d["results"].items()]
    counts = ", ".join(f"{g} {n}" for g, n in d["groups"].items())
    notes = ["downbeat F: the bars' first beats within 70 ms, first 5 s skipped; metre: 3 or 4 beats per bar right",
             f"songs per group: {counts}; '{FIRST_BEAT}' counts bars from the first tracked beat (chance)"]
    analysis = d["results"].get(ANALYSIS, {}).get("mean", {})
    if analysis.get("metre_ms_per_minute") is not None:
        notes.append(f"the metre analysis takes {analysis['metre_ms_per_minute']:.0f} ms per minute of audio")
    for name, r in d["results"].items():
        if name == FIRST_BEAT:
            continue
        bad = [f"{x['song']} (metre {x['beats_per_bar']} for {x['true_beats_per_bar']}, F {x['downbeat_f']:.2f})"
               for x in r["songs"] if x["song"] in r["mean"]["failures"]]
        notes.append(f"{name}: " + ("; ".join(bad) if bad else "no song with a wrong metre or downbeat F < 0.9"))
    return table(f"Downbeats and metre on {len(d['songs'])} generated songs (exact bar positions)",
                 ["bars from", "downbeat F", "metre right"] + [f"F {g}" for g in groups], rows,
                 [0, 3, 3] + [3] * len(groups), notes=notes)


def format_metre_report(report: dict) -> str:
    """``metre_report`` as text: the generated set's table, then what was found in each bundled song."""
    out = [format_downbeat_tracking(report["downbeats"])]
    if report.get("bundled"):
        rows = [[r["song"][:40], r["tempo_bpm"], r["beats_per_bar"], r["confidence"], r["jumps"],
                 " ".join(f"{t:.2f}" for t in r["first_downbeats_s"]), r.get("live_beats_per_bar"),
                 r.get("live_agreement")] for r in report["bundled"]]
        out += ["", table("Bundled songs (no truth: what the analysis finds)",
                          ["song", "bpm", "metre", "confidence", "jumps", "first downbeats (s)", "live metre",
                           "live = offline"], rows, [0, 1, 0, 2, 0, 0, 0, 2],
                          notes=["jumps: changes of phase in the bar count; live = offline: live beats after "
                                 f"{SETTLE_S:g} s with the offline bar position"])]
    return "\n".join(out)

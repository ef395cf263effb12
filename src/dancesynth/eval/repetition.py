"""How much of a dance replays material it has already danced: what a viewer sees as a loop.

A dance made of captured motion shows, on every music beat, some frame of some clip.
``beat_sources`` reads which (from the dance's per-frame source positions); ``repetition``
counts the music beats that replay a *source beat* -- the captured motion beat nearest that
frame, to half a beat (``source_position``: in half time a music beat falls midway between two
motion beats, which is not a replay of either) -- already danced within the previous
``window_s`` seconds, and the longest run of consecutive music beats that all do (a looped
phrase is a long run; a move coming round once in a while is not). A mirrored take is a clip
of its own: the same move on the other side is not counted as a replay.
"""

from __future__ import annotations

import numpy as np

WINDOW_S = 60.0


def beat_sources(source_frames, fps: float, beat_times_s, style) -> list[dict]:
    """Per music beat: ``{"clip", "file", "frame", "source_beat", "source_position"}`` -- the style's clip
    danced at that beat, its source file, the frame within the clip (at the style's frame rate), the
    index of the style's nearest motion beat and the frame's place among the style's motion beats
    to half a beat (3.5: midway between beats 3 and 4). ``source_frames``: the style's flat frame
    each dance frame shows."""
    src = np.asarray(source_frames, dtype=np.float64)
    times = np.asarray(beat_times_s, dtype=np.float64)
    if src.size == 0 or times.size == 0:
        return []
    at = np.clip(np.round(times * fps).astype(np.int64), 0, len(src) - 1)
    flat = np.clip(np.round(src[at]).astype(np.int64), 0, style.n_frames - 1)
    clip = style.clip_of_frame(flat)
    beats = np.asarray(style.beat_frames)
    nearest = np.clip(np.searchsorted(beats, flat), 1, max(len(beats) - 1, 1)) if beats.size > 1 else np.zeros_like(flat)
    if beats.size > 1:
        nearest = np.where(np.abs(beats[nearest - 1] - flat) <= np.abs(beats[nearest] - flat), nearest - 1, nearest)
    position = nearest.astype(np.float64)
    if beats.size > 1:  # the fractional place between the motion beats around the frame, in halves
        i = np.clip(np.searchsorted(beats, flat, side="right") - 1, 0, len(beats) - 2)
        phase = np.clip((flat - beats[i]) / np.maximum(beats[i + 1] - beats[i], 1), 0.0, 1.0)
        position = np.round(2.0 * (i + phase)) / 2.0
    return [{"clip": style.clip_names[c], "file": style.clip_sources[c], "frame": int(f - style.clip_starts[c]),
             "source_beat": int(b), "source_position": float(p)} for c, f, b, p in zip(clip, flat, nearest, position)]


def repetition(source_beats, beat_times_s, *, window_s: float = WINDOW_S, asked=None) -> dict:
    """``{"replayed_share", "longest_repeat_beats", "distinct_source_beats", "beats"}`` of a dance whose
    music beat k shows source beat ``source_beats[k]`` (any hashable id) at ``beat_times_s[k]``.
    ``asked`` (bool per beat): beats the song's form asked to replay (``engines/form.py``); they are
    not counted as loops, and ``form_replays`` says how many there were."""
    ids = list(source_beats)
    times = np.asarray(beat_times_s, dtype=np.float64)
    if len(ids) != len(times):
        raise ValueError("one source beat per music beat")
    last_seen: dict = {}
    replayed = np.zeros(len(ids), dtype=bool)
    for k, (b, t) in enumerate(zip(ids, times)):
        seen = last_seen.get(b)
        replayed[k] = seen is not None and t - seen <= window_s
        last_seen[b] = t
    form = np.zeros(len(ids), bool) if asked is None else np.asarray(asked, bool)
    replayed &= ~form
    longest = run = 0
    for r in replayed:
        run = run + 1 if r else 0
        longest = max(longest, run)
    return {"replayed_share": float(replayed.mean()) if len(ids) else 0.0, "longest_repeat_beats": int(longest),
            "distinct_source_beats": len(set(ids)), "beats": len(ids), "window_s": float(window_s),
            "form_replays": int(form.sum())}

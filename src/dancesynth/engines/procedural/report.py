"""A few lines saying what ``conduct`` did (for the CLI; library code returns them, never prints)."""

from __future__ import annotations


def summary_lines(summary: dict, output) -> list[str]:
    s, tm = summary, summary["timings_s"]
    lines = [f"song      {s['song']} ({s['input']}): {s['duration_s']:.1f} s, {s['tempo_bpm']:.1f} bpm",
             f"melody    {s['notes']} notes: {s['beat_notes']} on beats, {s['long_notes']} long, "
             f"{s['staccato_notes']} staccato",
             f"segments  {s['segments']} (DP {tm['segment_s'] * 1e3:.1f} ms); "
             f"{s['rescaled_segments']} flattened to stay in reach",
             f"time      notes {tm['notes_s']:.2f} s, plan {tm['plan_s']:.2f} s, pose {tm['pose_s']:.2f} s",
             f"wrote     {output} ({s['frames']} frames at {s['fps']:g} fps)"]
    return lines


def parts_lines(song_path) -> list[str]:
    """The MIDI parts of a file with the ones ``conduct`` would choose marked."""
    from pathlib import Path

    from ...errors import InputError
    from ...music.melody import MIDI_SUFFIXES
    from ...music.notes import choose_parts, read_midi

    if Path(song_path).suffix.lower() not in MIDI_SUFFIXES:
        raise InputError(f"{song_path}: --list-tracks lists the parts of a MIDI file; a recording has none")
    song = read_midi(song_path)
    try:
        mel, rhy = choose_parts(song)
    except InputError:  # a drums-only file still lists its parts
        mel, rhy = None, None
    marks = {getattr(mel, "index", -1): "  <- melody", getattr(rhy, "index", -1): "  <- rhythm"}
    return [p.describe() + marks.get(p.index, "") for p in song.parts]

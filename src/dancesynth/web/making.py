"""Making the dances the page shows: a song danced onto a built-in or a user's character, a span of one
danced again, and either described as the page reads it. Each runs in a worker thread (``server.DanceQueue``)."""

from __future__ import annotations

import functools
from pathlib import Path

from .dances import StoredDance

CAMERA_RATE_HZ = 10   # the follow view's yaw, sent this often a second (it is low-passed over seconds)


@functools.lru_cache(maxsize=None)
def builtin_character(name: str):
    """A built-in character (``retarget.rigs.LAYOUTS``), loaded once: they never change."""
    from ..retarget.character import load_character

    return load_character(name)


@functools.lru_cache(maxsize=None)
def rest_glb(name: str) -> bytes:
    """A built-in character standing in its rest pose (one frame), as GLB bytes, made once."""
    from ..export.formats import encode_dance
    from ..types import MotionClip

    target = builtin_character(name)
    rest = MotionClip(target.skeleton, 30.0, target.rest_root[None], target.rest_rot[None])
    return encode_dance(".glb", rest, target)


def make_dance(song_path: Path, style: str | None, seed: int | None, engine: str, character: str | Path,
               database, bone_map: Path | None = None) -> tuple[dict, StoredDance]:
    """Dance, move the dance onto ``character`` (a built-in's name, or a user's file with its ``bone_map``),
    and describe it for the page. Runs in a worker thread."""
    from ..api import analyse, dance
    from ..retarget.character import load_character
    from ..retarget.humanoid import find_bones
    from ..retarget.solve import retarget, source_ground

    # The user's file first: one that cannot be a character is refused before the dance is made.
    target = (load_character(character, bone_map=bone_map) if isinstance(character, Path)
              else builtin_character(character))
    music = analyse(song_path, structure=False)   # kept: a span re-danced needs no second analysis
    clip = dance(music, style=style, seed=seed, engine=engine, database=database)
    ground = source_ground(clip, find_bones(clip.skeleton, what="the dance's skeleton"))
    moved = retarget(clip, target, source_ground=ground)
    made = StoredDance(moved, target, song_path, title=song_path.name, music=music, provenance=clip.provenance,
                       source=(clip.skeleton.names, ground))
    return described(made), made


def redance(old: StoredDance, start_s: float, end_s: float, seed: int | None, style: str | None,
            motif: str | None, database) -> tuple[dict, StoredDance]:
    """``old`` with a span danced again (``edit.redance_span``) on the same character and floor."""
    from ..edit import redance_span
    from ..retarget.solve import retarget

    names, ground = old.source

    def onto(part):
        return retarget(part, old.character, source_ground=ground if part.skeleton.names == names else None)

    edited, _ = redance_span(old.clip, old.music, start_s, end_s, database=database, provenance=old.provenance,
                             seed=seed, style=style, motif=motif, onto=onto)
    made = StoredDance(edited, old.character, old.song_path, title=old.title, upload_key=old.upload_key,
                       music=old.music, provenance=edited.provenance, source=old.source, audio_url=old.audio_url)
    return described(made), made


def described(made: StoredDance) -> dict:
    """The dance as the page reads it (its BVH, beats, bars, sections; what made it)."""
    from ..export.camera import follow_yaw

    if made.has_mesh or made.character.source is not None:
        # The page asks for it next: make it here, in the dance's turn; a user's model is made while its
        # file is still there (it is removed once the request is answered).
        made.encoded("glb")
    prov, moved = made.provenance, made.clip
    s = prov.summary
    step = max(int(round(moved.fps / CAMERA_RATE_HZ)), 1)   # frames between the follow view's yaw values
    sections = [{"start_s": round(float(x["start_s"]), 4), "level": x["level"]} for x in s.get("sections", [])]
    beats = prov.music_beat_times_s
    return {"bvh": made.encoded("bvh").decode("utf-8"), "fps": moved.fps, "frames": moved.n_frames,
            "duration_s": float(s["duration_s"]), "tempo_bpm": float(s["tempo_bpm"]),
            "beats": [round(float(t), 4) for t in beats],
            "downbeats": [round(float(t), 4) for t, k in zip(beats, prov.music_beat_in_bar) if k == 0],
            "style": s["style"], "default_tempo": bool(s["default_tempo"]), "engine": s["engine"],
            "character": made.character.name, "mesh": made.has_mesh, "joints": list(moved.skeleton.names),
            "sections": sections, "beats_per_bar": int(s["beats_per_bar"]) if s.get("beats_per_bar") else None,
            "form": [{"start_s": round(float(x["start_s"]), 3), "label": x["label"], "name": x["name"],
                      "replays": x.get("repeats")} for x in s.get("form", {}).get("sections", [])],
            "edits": [{k: e[k] for k in ("start_s", "end_s", "seed", "style", "engine", "motif")}
                      for e in s.get("edits", [])],
            "camera": {"rate_hz": moved.fps / step, "yaw": [round(float(y), 3) for y in follow_yaw(moved)[::step]]}}

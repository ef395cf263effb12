"""A dance read on the rig of the mocap it is measured against, so every analysis gives the same answer
whichever rig the dance was written on.

A dance on the mannequin and the same dance on its source skeleton differ in proportions and joints
(fingers, twist bones, a neck), and so in everything measured from joint positions: the motion words
``motifs`` embeds (chi2 0.66 against 0.16 to the salsa template for one dance), summed joint speeds,
foot heights. The motif templates and the mocap statistics were measured on the database's own
skeletons, so a dance is retargeted onto the skeleton of the style it is compared with (through the
humanoid mapping, ``retarget``) before it is measured: a dance already on it is measured as it is.
"""

from __future__ import annotations

import hashlib
import json
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..errors import DanceSynthError
from ..io.files import cache_dir
from ..motion.motifs import dance_motifs
from ..motion.words import landmark_indices
from ..retarget.character import rig_character
from ..retarget.solve import retarget
from ..types import MotionClip

GUESS_MIN_S = 120.0  # a genre needs this much captured dance to be guessed (the style chooser's 2 minutes)


def on_rig_of(dance: MotionClip, style) -> MotionClip:
    """``dance`` on ``style``'s skeleton (``dance`` itself when it is on it already)."""
    if tuple(dance.skeleton.names) == tuple(style.skeleton.names):
        return dance
    moved = retarget(dance, _rig(style))
    moved.meta = {**dance.meta, "analysed_on": style.name}
    return moved


@lru_cache(maxsize=8)
def _rig(style):
    """``style``'s rig as a character (a few FK passes over a take: once per style)."""
    return rig_character(style.clip(0), what=f"style {style.name}")


def _largest(database, genre: str):
    """The genre's style with the most frames: the skeleton its template is read on."""
    return max(database.styles_of(genre), key=lambda s: s.n_frames)


def genre_motifs(dance: MotionClip, model, database, genre: str | None = None) -> dict:
    """``motion.motifs.dance_motifs`` of ``dance`` against ``genre``'s template (the nearest one when none
    is named), with its chi2 to every genre's: each measured on that genre's skeleton (its largest
    style's), the dance read on it."""
    landmark_indices(dance.skeleton)   # a skeleton without legs, arms or head: the motion words' own error
    if genre is not None:
        model.check_genre(genre)
    genres = [g for g in model.genres if g in database.genres()] or [genre or model.genres[0]]
    if genre is not None and genre not in genres:
        genres.append(genre)
    results = {}
    for g in genres:
        results[g] = dance_motifs(on_rig_of(dance, _largest(database, g)), model, genre=g)
    # A guess among the genres with material enough for a template to mean something (a 30-second genre's
    # template, from one or three takes, is near anything; any, where none has), each chi2 over the typical
    # one of that genre's own takes: a broad template (pop's many routines) is near more dances, and the
    # motifs are partly the rig's, so a salsa take read on the robot's rig is near pop's template.
    big = [g for g in results if sum(st.captured_s for st in database.styles_of(g)) >= GUESS_MIN_S] or list(results)
    typical = genre_baselines(model, database, big)
    chosen = genre or min(big, key=lambda g: results[g]["chi2"] / max(typical.get(g, 1.0), 1e-3))
    out = dict(results[chosen])
    out["chi2_by_genre"] = {**out["chi2_by_genre"], **{g: r["chi2"] for g, r in results.items()}}
    out["genre_guessed"] = genre is None
    out["read_on"] = _largest(database, chosen).name
    if typical:
        out["chi2_over_own_takes"] = {g: round(results[g]["chi2"] / max(typical[g], 1e-3), 4) for g in typical}
    return out


def genre_baselines(model, database, genres) -> dict[str, float]:
    """Per genre of ``genres``: the median chi2 to its template of its own captured takes (of 10 s or more),
    each read as a dance is (``dance_motifs``, at its kinematic beats). Cached on disk by the model and
    the styles' contents."""
    h = hashlib.blake2b(model.fingerprint().encode(), digest_size=12)
    for g in sorted(genres):
        for st in database.styles_of(g):
            h.update(f"{g}|{st.name}|{st.fingerprint}".encode())
    h.update(Path(__file__).read_bytes())
    path = cache_dir() / "motifs" / f"baselines-{h.hexdigest()}.json"
    try:
        return {g: float(v) for g, v in json.loads(path.read_text()).items()}
    except (OSError, ValueError, AttributeError):
        pass
    out = {}
    for g in genres:
        takes = [st.clip(c) for st in database.styles_of(g) for c in range(st.n_clips)
                 if st.clip_starts[c + 1] - st.clip_starts[c] >= 10.0 * st.fps]
        values = []
        for clip in takes:
            try:
                values.append(dance_motifs(clip, model, genre=g)["chi2"])
            except DanceSynthError:   # a take too short for a word at its kinematic beats
                continue
        out[g] = float(np.median(values)) if values else 1.0
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(out))
    except OSError:
        pass  # an unwritable cache: computed again next time
    return out

"""Motion files of every format dancesynth reads, and the genre their public sets' names carry.

``read_motion`` picks the reader by suffix: ``.bvh`` (``bvh.read_bvh``: CMU's BVH conversions,
LaFAN1, Motorica, Bandai Namco, ...), ``.pkl`` (``aist.read_aist``: AIST++) and ``.amc``
(``asf_amc.read_amc``, with the subject's ``.asf`` beside it: CMU's originals). CMU trials that
a converter labelled 120 fps while CMU lists them at 60 are corrected (``cmu_fps_fix``).

``genre_from_name`` reads the genre from the naming of the public sets (docs/importers.md):

- AIST++ / AIST Dance DB: ``gBR_sBM_cAll_d04_mBR0_ch01`` -- the ``g`` code is the genre;
- Motorica Dance: ``kthjazz_gCH_sFM_cAll_d02_mCH_ch01_...`` -- same convention, own codes;
- LaFAN1: ``dance1_subject1`` -- the theme ``dance`` (other themes are not dance: None);
- Bandai Namco Research Motion Dataset: ``dataset-1_dance-long_normal_001`` -- ``dance``;
- CMU (``60_01.bvh``, ``05_11.amc``, cgspeed/Daz/iClone spellings): the dance trials of CMU's
  index (``CMU_DANCE``), others None.
"""

from __future__ import annotations

import re
from pathlib import Path

from ..errors import InputError
from ..types import MotionClip
from .aist import read_aist
from .asf_amc import cmu_fps_fix, cmu_subject_trial, read_amc
from .bvh import read_bvh

__all__ = ["MOTION_SUFFIXES", "read_motion", "genre_from_name", "cmu_fps_fix", "AIST_GENRES",
           "MOTORICA_GENRES", "CMU_DANCE"]

MOTION_SUFFIXES = (".bvh", ".pkl", ".amc")

# AIST++ genre codes (the dataset's visualizer/categ2name.json).
AIST_GENRES = {"BR": "break", "PO": "pop", "LO": "lock", "MH": "middle-hiphop", "LH": "la-hiphop",
               "HO": "house", "WA": "waack", "KR": "krump", "JS": "street-jazz", "JB": "ballet-jazz"}
# Motorica Dance Dataset style codes (its README: Hiphop gLH, Krumping gKR, Popping gPO, Locking
# gLO, Jazz gJZ, Charleston gCH, Tapping gTP, Casual gCA). Shared codes keep AIST's label where the
# style is the same (popping, locking, krump); Motorica calls gLH plain "Hiphop".
MOTORICA_GENRES = {"LH": "hiphop", "KR": "krump", "PO": "pop", "LO": "lock", "JZ": "jazz", "CH": "charleston",
                   "TP": "tap", "CA": "casual"}


def _trials(genre: str, *trials: int) -> dict:
    return {t: genre for t in trials}


# CMU trials that CMU's index describes as dance (B. Hahne's 2008 listing of CMU's descriptions):
# subject -> genre for every trial, or {trial: genre}. Trials of walks, warm-ups and poses are left out.
CMU_DANCE: dict[int, str | dict[int, str]] = {
    5: _trials("modern", *range(2, 21)),                     # "modern dance"; 05_01 is a walk
    49: _trials("modern", 9, 10, 11, 12, 13, 14, 16, 17, 22),  # "modern dance, gymnastics": the dance trials
    55: {1: "whirl", 2: "lambada"},                          # "dance, whirl"; "lambada dance"
    60: "salsa", 61: "salsa",                                # salsa lead and follow
    85: _trials("break", 3, 4, 8, 10, 11, 12, 13, 14),       # "breakdance": the sequences and footwork
    90: {28: "break", 30: "russian", 31: "russian"},         # "breakdance", "russian dance"
    93: {3: "charleston", 4: "charleston", 5: "charleston", 8: "charleston", 6: "lindy-hop"},
    103: {3: "charleston", 4: "charleston", 5: "charleston", 8: "charleston", 6: "lindy-hop"},
    94: "indian",                                            # "indian dance" (trials undescribed)
    131: "mj",                                               # "Michael Jackson styled motions"
}

_GCODE = re.compile(r"^(?:([a-z][a-z0-9]*)_)?g([A-Z]{2})_s([A-Z]{2})_", re.IGNORECASE)
_LAFAN = re.compile(r"^([a-z]+?)(\d+)_subject(\d+)$", re.IGNORECASE)
_BANDAI = re.compile(r"^dataset-\d+_([a-z\-]+)_[a-z\-]+_\d+$", re.IGNORECASE)


def read_motion(path) -> MotionClip:
    """Read a motion file of any supported format (``MOTION_SUFFIXES``) into a ``MotionClip``."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".bvh":
        clip = read_bvh(path)
        fixed = cmu_fps_fix(path, clip.fps)
        if fixed != clip.fps:
            clip.meta["fps_in_file"] = clip.fps
            clip.fps = fixed
        return clip
    if suffix == ".pkl":
        return read_aist(path)
    if suffix == ".amc":
        return read_amc(path)
    if suffix == ".asf":
        raise InputError(f"{path}: an .asf file is a skeleton without motion; pass the .amc files that use it "
                         "(kept in the same folder)")
    raise InputError(f"{path}: unknown motion format {suffix or '(no suffix)'!r}; dancesynth reads "
                     f"{', '.join(MOTION_SUFFIXES)} (BVH, AIST++ motion pickles, CMU ASF/AMC)")


def genre_from_name(path) -> str | None:
    """The genre a public set's file name states, or ``None`` (not a set we know, or not dance)."""
    stem = Path(str(path)).name
    for suffix in MOTION_SUFFIXES:
        if stem.lower().endswith(suffix):
            stem = stem[: -len(suffix)]
    m = _GCODE.match(stem)
    if m:
        prefix, code = m.group(1), m.group(2).upper()
        if prefix:   # Motorica prefixes its names with the session ("kthjazz_", "kthstreet_", "kthmisc_")
            return MOTORICA_GENRES.get(code)
        return AIST_GENRES.get(code) or MOTORICA_GENRES.get(code)
    m = _BANDAI.match(stem)
    if m:
        return "dance" if m.group(1).lower().startswith("dance") else None
    m = _LAFAN.match(stem)
    if m:
        return "dance" if m.group(1).lower() == "dance" else None
    st = cmu_subject_trial(stem)
    if st is not None:
        entry = CMU_DANCE.get(st[0])
        return entry.get(st[1]) if isinstance(entry, dict) else entry
    return None

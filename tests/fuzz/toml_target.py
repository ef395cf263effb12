"""TOML a user writes: a database's ``genres.toml`` (``collect_sources``) and ``conduct --config`` (``load_config``).

Mutates: documents built by hypothesis of every TOML shape (tables, arrays,
inline tables, strings, integers up to 2^63, floats with nan/inf, booleans,
dates) around the keys the loaders know (``[genres]`` patterns; the procedural
parameters, ``style`` and a ``[procedural]`` table); and byte mutations of valid
documents (broken syntax, bad UTF-8).

Sane: genres: (genre name, BVH file) pairs, every file inside the folder;
config: a ``ProceduralConfig`` whose every parameter is a finite number.
"""

from __future__ import annotations

import datetime
import json
import math
from pathlib import Path

from .harness import Case, Insane, Target, hypothesis_examples, mutate_bytes, rng_for, write_file

PARAMETERS = ["w1", "l1", "l2", "bounce", "fps", "max_segment_notes", "speed_limit", "reach", "elbow_min",
              "elbow_max", "nod", "ideal_range", "ideal_duration", "y_scale", "sweep_width"]
VALID = {
    "genres": '[genres]\nsalsa = ["salsa/*.bvh"]\nhouse = "house/*.bvh"\n',
    "config": 'style = "calm"\nl1 = 0.2\nmax_segment_notes = 40\n[procedural]\nbounce = 0.5\n',
}


def toml_value(v) -> str:
    """TOML text of a Python value (inline tables and arrays, so a document is one key per line)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # JSON strings are TOML basic strings
    if isinstance(v, (datetime.date, datetime.time)):
        return v.isoformat()
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    return "{" + ", ".join(f"{json.dumps(k)} = {toml_value(x)}" for k, x in v.items()) + "}"


def toml_document(doc: dict) -> str:
    return "".join(f"{json.dumps(k)} = {toml_value(v)}\n" for k, v in doc.items())


class TomlTarget(Target):
    name = "toml"
    suffix = ".toml"
    mutates = "hypothesis-built genres.toml / conduct --config documents of every shape; byte mutations"
    sane = "genres: (name, .bvh inside the folder) pairs; config: every parameter finite"

    def prepare(self, workdir: Path) -> None:
        for genre in ("salsa", "house", "odd name"):
            folder = workdir / "toml_db" / genre
            folder.mkdir(parents=True, exist_ok=True)
            (folder / "clip.bvh").write_text("HIERARCHY\n")  # never read: only listed

    def cases(self, n: int, seed: int, workdir: Path) -> list[Case]:
        rng = rng_for(seed, "toml")
        n_mut = n // 4
        out = []
        for i in range(n_mut):
            kind = ("genres", "config")[i % 2]
            data, how = mutate_bytes(rng, VALID[kind].encode())
            out.append(Case(f"{kind}:bytes:{how}", (kind, data)))
        for kind, doc in hypothesis_examples(_documents(), n - n_mut, seed):
            out.append(Case(f"{kind}:built", (kind, toml_document(doc).encode("utf-8", "surrogatepass"))))
        return out

    def run(self, case: Case, workdir: Path) -> None:
        kind, data = case.data
        if kind == "genres":
            from dancesynth.motion.sources import collect_sources

            folder = workdir / "toml_db"
            (folder / "genres.toml").write_bytes(data)
            for genre, path in collect_sources(folder):
                if not isinstance(genre, str) or not path.is_file() or folder.resolve() not in path.resolve().parents:
                    raise Insane(f"a source outside the folder or not a file: {genre!r} {path}")
        else:
            from dataclasses import fields

            from dancesynth.engines.procedural.config import load_config

            path = workdir / "config.toml"
            path.write_bytes(data)
            cfg = load_config(path)
            for f in fields(cfg):
                v = getattr(cfg, f.name)
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                    raise Insane(f"parameter {f.name} = {v!r}")

    def save(self, case: Case, folder: Path, stem: str) -> Path:
        kind, data = case.data
        return write_file(folder, f"{stem}-{kind}.toml", data)


def _documents():
    """(kind, document) pairs: the known keys with values of any TOML type, and stray keys."""
    from hypothesis import strategies as st

    text = st.one_of(st.sampled_from(["salsa/*.bvh", "*.bvh", "**/*.bvh", "../*", "/etc/*", "", "[", "calm",
                                      "default", "e1", "1e999", "nan", "inf", "-1", "0.2", "3", " 7 "]),
                     st.text(max_size=12))
    scalar = st.one_of(text, st.integers(-(2 ** 63), 2 ** 63 - 1), st.sampled_from([0, 1, 2, 48, 500, 501, -1]),
                       st.floats(), st.booleans(), st.dates(), st.times(), st.datetimes())
    value = st.recursive(scalar, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                         st.dictionaries(text, inner, max_size=3)), max_leaves=8)
    genres = st.one_of(st.dictionaries(text, st.one_of(text, st.lists(text, max_size=3), value), max_size=4), value)
    genres_doc = st.fixed_dictionaries({"genres": genres}, optional={"other": value})
    params = st.dictionaries(st.sampled_from(PARAMETERS + ["style", "unknown", "procedural"]), value, max_size=4)
    good_params = st.dictionaries(st.sampled_from(PARAMETERS),
                                  st.one_of(st.floats(), st.integers(-5, 600), st.sampled_from(
                                      ["0.3", "nan", "inf", "-inf", "1e308", "2", "abc", ""])), max_size=3)
    config_doc = st.one_of(params, good_params,
                           st.fixed_dictionaries({"procedural": st.one_of(good_params, value)}))
    return st.one_of(st.tuples(st.just("genres"), genres_doc), st.tuples(st.just("config"), config_doc))


TARGET = TomlTarget()

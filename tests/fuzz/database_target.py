"""Database folders a user gives (``open_database``, as ``--database DIR`` does).

Mutates: (1) a saved database (the bundled ``database.json`` cut to its smallest
style, with that style's ``.npz``): keys removed or given other types and odd
values (fps 0/nan, parents out of range, style names with "../"), arrays of the
``.npz`` replaced by ones of the wrong shape, type or range, and byte mutations
of both files; (2) folders of BVH files: real 3 s clips beside one-frame
clips, empty or binary ``.bvh`` files, another skeleton, a 1000 fps capture,
non-BVH files, symlinks (to files, to folders, to themselves, dangling) and a
broken ``genres.toml``.

Sane: at least one style; per style a positive finite fps, frames and clip ranges
that agree, unit quaternions, finite positions and energies, beats inside the
frames, a skeleton whose parents precede their children; every clip can be taken out.
"""

from __future__ import annotations

import io
import json
import os
import random
import shutil
from pathlib import Path

import numpy as np

from .harness import Case, Insane, Target, mutate_bytes, rng_for

REPO = Path(__file__).resolve().parents[2]
BUNDLED = REPO / "src" / "dancesynth" / "data" / "database"
STYLE = "whirl"  # the smallest bundled style
ARRAYS = ["rot_q", "moving", "static_rot", "root_pos", "contacts", "energy", "beat_frames", "clip_starts",
          "clip_tempo_bpm"]


class DatabaseTarget(Target):
    name = "database"
    mutates = "saved databases (database.json keys/values, .npz arrays and bytes); BVH folders with odd files"
    sane = ">=1 style; fps, frames, clip ranges, beats and skeleton consistent and finite"

    def __init__(self):
        self._seeds = Path("db_seeds")

    def prepare(self, workdir: Path) -> None:
        seeds = self._seeds = workdir / "db_seeds"
        if (seeds / "clips").is_dir():
            return
        (seeds / "saved").mkdir(parents=True, exist_ok=True)
        index = json.loads((BUNDLED / "database.json").read_text())
        index["styles"] = {STYLE: index["styles"][STYLE]}
        (seeds / "saved" / "database.json").write_text(json.dumps(index))
        shutil.copy(BUNDLED / f"{STYLE}.npz", seeds / "saved" / f"{STYLE}.npz")
        from dancesynth.io.bvh import format_bvh
        from dancesynth.motion.database import load_database

        style = load_database(BUNDLED).styles["mj"]
        part = seeds / "part"
        part.mkdir(exist_ok=True)
        for k in range(2):  # 3-second excerpts: long enough for beats, short enough to analyse quickly
            clip = style.clip(k)
            clip = clip.frames(0, min(clip.n_frames, int(3 * clip.fps)))
            (part / f"clip{k}.bvh").write_text(format_bvh(clip))
            if k == 0:
                (part / "one_frame.bvh").write_text(format_bvh(clip.frames(0, 1)))
        part.rename(seeds / "clips")

    def cases(self, n: int, seed: int, workdir: Path) -> list[Case]:
        seeds = workdir / "db_seeds"
        index = json.loads((seeds / "saved" / "database.json").read_text())
        npz = (seeds / "saved" / f"{STYLE}.npz").read_bytes()
        rng = rng_for(seed, "database")
        out = []
        for i in range(n):
            r = rng.random()
            if r < 0.1:  # a build: seconds each, so a tenth of the cases
                out.append(_bvh_folder_case(rng))
            elif r < 0.5:
                doc, how = _mutate_json(rng, json.loads(json.dumps(index)))
                out.append(Case(f"json:{how}", ("saved", doc, None)))
            elif r < 0.8:
                out.append(Case("npz:" + (how := _npz_change(rng)), ("saved", None, how)))
            else:
                which = rng.choice(["json", "npz"])
                data, how = mutate_bytes(rng, json.dumps(index).encode() if which == "json" else npz)
                out.append(Case(f"{which}-bytes:{how}", ("saved-bytes", which, data)))
        return out

    def run(self, case: Case, workdir: Path) -> None:
        from dancesynth.motion.database import open_database

        folder = workdir / "case_db"
        if folder.exists() or folder.is_symlink():
            shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir()
        os.environ["DANCESYNTH_CACHE"] = str(workdir / "cache")  # builds are cached here, not for the user
        _make_folder(case.data, folder, workdir / "db_seeds")
        db = open_database(folder)
        check_database(db)

    def save(self, case: Case, folder: Path, stem: str) -> Path:
        out = folder / stem
        if out.exists():
            shutil.rmtree(out)
        out.mkdir(parents=True)
        _make_folder(case.data, out, self._seeds)
        return out


def check_database(db) -> None:
    if not db.styles:
        raise Insane("a database with no styles")
    for name, st in db.styles.items():
        F, J = st.n_frames, st.skeleton.n_joints
        if not (np.isfinite(st.fps) and 1 <= st.fps <= 1000):
            raise Insane(f"style {name}: fps {st.fps}")
        if st.local_rot.shape != (F, J, 4) or st.root_pos.shape != (F, 3) or len(st.energy) != F \
                or len(st.contacts) != F:
            raise Insane(f"style {name}: array shapes disagree")
        starts = np.asarray(st.clip_starts)
        if len(starts) != st.n_clips + 1 or starts[0] != 0 or starts[-1] != F or np.any(np.diff(starts) <= 0):
            raise Insane(f"style {name}: clip ranges do not cover the frames")
        if len(st.clip_tempo_bpm) != st.n_clips or not np.all(np.isfinite(st.clip_tempo_bpm)):
            raise Insane(f"style {name}: clip tempi")
        for what, arr in (("local_rot", st.local_rot), ("root_pos", st.root_pos), ("energy", st.energy),
                          ("offsets", st.skeleton.offsets)):
            if not np.all(np.isfinite(arr)):
                raise Insane(f"style {name}: non-finite {what}")
        if F and np.max(np.abs(np.linalg.norm(st.local_rot, axis=-1) - 1)) > 1e-3:
            raise Insane(f"style {name}: rotations are not unit quaternions")
        b = np.asarray(st.beat_frames)
        if len(b) and (b.min() < 0 or b.max() >= F):
            raise Insane(f"style {name}: beats outside the frames")
        p = np.asarray(st.skeleton.parents)
        if len(p) != J or p[0] != -1 or np.any(p[1:] < 0) or np.any(p[1:] >= np.arange(1, J)):
            raise Insane(f"style {name}: skeleton parents")
        for k in range(st.n_clips):
            st.clip(k)


# ----------------------------------------------------------------------------- saved databases

_ODD = [None, 0, -1, 1e308, float("nan"), "", "x", [], {}, [1, 2], {"a": 1}, True, 2 ** 70, "../../etc/passwd"]


def _mutate_json(rng: random.Random, doc: dict) -> tuple[dict, str]:
    """Delete a key or give it an odd value, somewhere in the document (sometimes a named hot spot)."""
    style = doc["styles"][STYLE]
    r = rng.random()
    if r < 0.15:
        key = rng.choice(["../x", "", "a/b", "whirl/../whirl", "..", "x" * 300, "whirl\x00"])
        doc["styles"] = {key: style}
        return doc, f"style name {key[:20]!r}"
    if r < 0.3:
        sk = style["skeleton"]
        field = rng.choice(["parents", "offsets", "names", "channels", "end_sites"])
        values = {"parents": [[-1, 5, 0], [0] * len(sk["parents"]), [-1] + [99] * (len(sk["parents"]) - 1),
                              [-1] + list(range(len(sk["parents"]) - 1))[::-1]],
                  "offsets": [[[0, 0]] * len(sk["offsets"]), [[float("nan")] * 3] * len(sk["offsets"]), []],
                  "names": [["a"] * len(sk["names"]), sk["names"][:2], [1] * len(sk["names"])],
                  "channels": [[], [["Bad"]] * len(sk["channels"])],
                  "end_sites": [{"999": [0, 1, 0]}, {"x": [0]}, []]}[field]
        sk[field] = rng.choice(values)
        return doc, f"skeleton.{field}"
    # any path
    path, node = [], doc
    while isinstance(node, (dict, list)) and node and rng.random() < 0.75:
        key = rng.choice(list(node)) if isinstance(node, dict) else rng.randrange(len(node))
        path.append(key)
        if not isinstance(node[key], (dict, list)) or rng.random() < 0.3:
            break
        node = node[key]
    if not path:
        return rng.choice(_ODD) if rng.random() < 0.3 else doc, "root"
    parent = doc
    for k in path[:-1]:
        parent = parent[k]
    if isinstance(parent, dict) and rng.random() < 0.4:
        del parent[path[-1]]
        return doc, f"delete {'/'.join(map(str, path))}"
    parent[path[-1]] = rng.choice(_ODD)
    return doc, f"set {'/'.join(map(str, path))}={parent[path[-1]]!r}"[:80]


def _npz_change(rng: random.Random) -> str:
    key = rng.choice(ARRAYS + ["<missing>", "<extra>"])
    how = rng.choice(["empty", "nan", "short", "long", "float", "huge", "negative", "2d", "object"])
    return f"{key}:{how}"


def _changed_npz(npz: bytes, change: str) -> bytes:
    key, how = change.split(":")
    with np.load(io.BytesIO(npz)) as z:
        arr = {k: z[k] for k in z.files}
    if key == "<missing>":
        arr.pop(ARRAYS[len(how) % len(ARRAYS)])
    elif key == "<extra>":
        arr["extra"] = np.zeros(3)
    else:
        a = arr[key]
        arr[key] = {
            "empty": lambda: a[:0],
            "nan": lambda: np.full(a.shape, np.nan),
            "short": lambda: a[: max(0, len(a) // 2)],
            "long": lambda: np.concatenate([a, a]),
            "float": lambda: a.astype(np.float64) + 0.5,
            "huge": lambda: np.full(a.shape, 2 ** 40 if a.dtype.kind in "iu" else 1e308).astype(
                a.dtype if a.dtype.kind in "iuf" else np.float64),
            "negative": lambda: -np.abs(a.astype(np.float64)) - 1,
            "2d": lambda: np.atleast_2d(a)[:, :1] if a.ndim > 1 else a[:, None],
            "object": lambda: np.array(["x"] * max(1, len(a))),
        }[how]()
    buf = io.BytesIO()
    np.savez(buf, **arr)
    return buf.getvalue()


# ----------------------------------------------------------------------------- folders of BVH files

_EXTRAS = ["one_frame", "empty", "binary", "other_skeleton", "fast_capture", "text_file", "link_file", "link_dir",
           "link_loop", "link_dangling", "bad_manifest", "good_manifest", "nested", "unreadable"]


def _bvh_folder_case(rng: random.Random) -> Case:
    extras = rng.sample(_EXTRAS, rng.randrange(1, 4))
    clips = rng.choice([0, 1, 1, 2])
    return Case(f"bvh-folder: {clips} clips + {'+'.join(extras)}", ("bvh", clips, extras))


def _make_folder(data, folder: Path, seeds: Path) -> None:
    kind = data[0]
    if kind == "saved":
        _, doc, change = data
        saved = seeds / "saved"
        (folder / "database.json").write_text(json.dumps(doc) if doc is not None else
                                              (saved / "database.json").read_text())
        npz = (saved / f"{STYLE}.npz").read_bytes()
        (folder / f"{STYLE}.npz").write_bytes(_changed_npz(npz, change) if change else npz)
    elif kind == "saved-bytes":
        _, which, blob = data
        shutil.copy(seeds / "saved" / "database.json", folder / "database.json")
        shutil.copy(seeds / "saved" / f"{STYLE}.npz", folder / f"{STYLE}.npz")
        (folder / ("database.json" if which == "json" else f"{STYLE}.npz")).write_bytes(blob)
    else:
        _, clips, extras = data
        genre = folder / "jpop"
        genre.mkdir()
        for k in range(clips):
            shutil.copy(seeds / "clips" / f"clip{k}.bvh", genre / f"clip{k}.bvh")
        good = (seeds / "clips" / "clip0.bvh").read_text()
        for extra in extras:
            _add_extra(extra, folder, genre, good, seeds)


def _add_extra(extra: str, folder: Path, genre: Path, good: str, seeds: Path) -> None:
    if extra == "one_frame":
        shutil.copy(seeds / "clips" / "one_frame.bvh", genre / "one_frame.bvh")
    elif extra == "empty":
        (genre / "empty.bvh").write_text("")
    elif extra == "binary":
        (genre / "binary.bvh").write_bytes(bytes(range(256)) * 4)
    elif extra == "other_skeleton":
        import sys

        sys.path.insert(0, str(REPO / "tests"))
        from bvh_samples import TWO_JOINTS

        (genre / "two_joints.bvh").write_text(TWO_JOINTS)
    elif extra == "fast_capture":  # the same motion declared at 1000 fps (3000 frames: 3 s)
        head, _, motion = good.partition("MOTION")
        lines = motion.strip().splitlines()
        rows = (lines[2:] * 34)[:3000]
        (genre / "fast.bvh").write_text(f"{head}MOTION\nFrames: {len(rows)}\nFrame Time: 0.001\n" + "\n".join(rows))
    elif extra == "text_file":
        (genre / "notes.txt").write_text("not motion")
        (genre / "readme.BVH.txt").write_text("HIERARCHY")
    elif extra == "link_file":
        (genre / "link.bvh").symlink_to(seeds / "clips" / "clip0.bvh")
    elif extra == "link_dir":
        (folder / "linked").symlink_to(genre, target_is_directory=True)
    elif extra == "link_loop":
        (genre / "loop").symlink_to(genre, target_is_directory=True)
    elif extra == "link_dangling":
        (genre / "gone.bvh").symlink_to(folder / "does-not-exist.bvh")
    elif extra == "bad_manifest":
        (folder / "genres.toml").write_text('[genres]\njpop = ["jpop/*.bvh"\n')
    elif extra == "good_manifest":
        (folder / "genres.toml").write_text('[genres]\njpop = ["jpop/*.bvh"]\nnothing = "none/*.bvh"\n')
    elif extra == "nested":
        deep = genre
        for d in range(30):
            deep = deep / f"d{d}"
        deep.mkdir(parents=True)
        (deep / "deep.bvh").write_text(good)
    elif extra == "unreadable":
        (genre / "locked.bvh").write_text(good)
        os.chmod(genre / "locked.bvh", 0)


TARGET = DatabaseTarget()

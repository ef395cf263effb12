"""BVH reading (``dancesynth.io.bvh.read_bvh``) and writing back what was read.

Mutates: real BVH files (the bundled database's clips written as BVH, the test
mocap, ``tests/bvh_samples.py``) line by line (hostile numbers, lost or doubled
lines, wrong Frames / Frame Time, swapped keywords) and byte by byte; and builds
BVH text from scratch with hypothesis: random hierarchies and deep chains, channel
lists (any order, case, count), frame counts and times, nan/inf/1e308/huge ints.

Sane: fps within 1-1000, at least one frame, finite positions and unit
quaternions of the right shapes; writing the clip back and reading it again gives
the same skeleton, frames and motion (or our error).
"""

from __future__ import annotations

import random
import re
from pathlib import Path

import numpy as np

from .harness import HOSTILE_NUMBERS, Case, Insane, Target, hypothesis_examples, mutate_bytes, rng_for

REPO = Path(__file__).resolve().parents[2]
FRAMES_PER_SEED = 40  # short seeds: a case should take milliseconds
_NUMBER = re.compile(r"(?<![\w.])-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?")
_CHANNELS = ["Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation"]


def _shorten(text: str, frames: int = FRAMES_PER_SEED) -> str:
    head, _, motion = text.partition("MOTION")
    lines = [ln for ln in motion.strip().splitlines()]
    rows = lines[2:2 + frames]
    return f"{head}MOTION\nFrames: {len(rows)}\n{lines[1].strip()}\n" + "\n".join(rows) + "\n"


class BVHTarget(Target):
    name = "bvh"
    suffix = ".bvh"
    mutates = "line/byte mutations of bundled-database, test-mocap and sample BVH; hypothesis-built hierarchies"
    sane = "1-1000 fps, >=1 frame, finite positions, unit quaternions; write + re-read agrees"

    def prepare(self, workdir: Path) -> None:
        seeds = workdir / "bvh_seeds"
        if seeds.is_dir() and any(seeds.iterdir()):
            return
        seeds.mkdir(parents=True, exist_ok=True)
        import sys

        sys.path.insert(0, str(REPO / "tests"))
        from bvh_samples import TWO_JOINTS

        from dancesynth.io.bvh import format_bvh
        from dancesynth.motion.database import open_database

        (seeds / "two_joints.bvh").write_text(TWO_JOINTS)
        for path in sorted((REPO / "tests" / "data" / "mocap").glob("*/*.bvh")):
            (seeds / f"mocap_{path.stem}.bvh").write_text(_shorten(path.read_text(encoding="latin-1")))
        for name, style in sorted(open_database().styles.items()):
            clip = style.clip(0)
            clip = clip.frames(0, min(FRAMES_PER_SEED, clip.n_frames))
            (seeds / f"db_{name}.bvh").write_text(format_bvh(clip))

    def cases(self, n: int, seed: int, workdir: Path) -> list[Case]:
        seeds = [p.read_text() for p in sorted((workdir / "bvh_seeds").glob("*.bvh"))]
        n_built = n // 3
        rng = rng_for(seed, "bvh", "mutate")
        out = []
        for i in range(n - n_built):
            text = seeds[i % len(seeds)]
            if rng.random() < 0.25:
                data, how = mutate_bytes(rng, text.encode("latin-1"))
                out.append(Case(f"bytes:{how}", data))
            else:
                text, how = _mutate_lines(rng, text)
                out.append(Case(f"lines:{how}", text.encode("latin-1", "replace")))
        out += [Case("built:" + label, text.encode("utf-8", "surrogateescape"))
                for label, text in hypothesis_examples(_bvh_documents(), n_built, seed)]
        return out

    def run(self, case: Case, workdir: Path) -> None:
        from dancesynth.io.bvh import format_bvh, parse_bvh, read_bvh

        path = workdir / "case.bvh"
        path.write_bytes(case.data)
        clip = read_bvh(path)
        check_clip(clip)
        again = parse_bvh(format_bvh(clip), units="m", drop_tpose=False)
        check_same(clip, again)


def check_clip(clip) -> None:
    """A clip read from a file: shapes, finite values, unit quaternions, a real frame rate."""
    F, J = clip.n_frames, clip.skeleton.n_joints
    if not (np.isfinite(clip.fps) and 1.0 <= clip.fps <= 1000.0):
        raise Insane(f"fps out of range: {clip.fps}")
    if F < 1:
        raise Insane(f"no frames: {F}")
    if clip.root_pos.shape != (F, 3) or clip.local_rot.shape != (F, J, 4):
        raise Insane(f"shapes: root_pos {clip.root_pos.shape}, local_rot {clip.local_rot.shape}, {F} frames {J} joints")
    for what, arr in (("root_pos", clip.root_pos), ("local_rot", clip.local_rot),
                      ("offsets", clip.skeleton.offsets), ("local_pos", clip.local_pos)):
        if arr is not None and not np.all(np.isfinite(arr)):
            raise Insane(f"non-finite {what}")
    if np.max(np.abs(np.linalg.norm(clip.local_rot, axis=-1) - 1.0)) > 1e-6:
        raise Insane("rotations are not unit quaternions")
    if len(set(clip.skeleton.names)) != J:
        raise Insane("joint names are not unique")


def check_same(a, b) -> None:
    """What was written and read back means the same motion (to the writer's 6 decimals)."""
    if a.skeleton.names != b.skeleton.names or list(a.skeleton.parents) != list(b.skeleton.parents):
        raise Insane("round trip: the hierarchy changed")
    if a.n_frames != b.n_frames:
        raise Insane(f"round trip: {a.n_frames} frames became {b.n_frames}")
    if abs(a.fps - b.fps) > 1e-5 * a.fps:
        raise Insane(f"round trip: {a.fps} fps became {b.fps}")
    scale = 1.0 + np.abs(a.root_pos)
    if np.max(np.abs(a.root_pos - b.root_pos) / scale) > 1e-5:
        raise Insane("round trip: root positions changed")
    dot = np.abs(np.sum(a.local_rot * b.local_rot, axis=-1))
    if np.min(dot) < np.cos(1e-3 / 2):  # more than a milliradian apart
        raise Insane(f"round trip: rotations changed by up to {np.degrees(2 * np.arccos(min(1, np.min(dot)))):.3g} deg")
    if (a.local_pos is None) != (b.local_pos is None):
        raise Insane("round trip: joint position channels appeared or vanished")
    if a.local_pos is not None and np.max(np.abs(a.local_pos - b.local_pos) / (1 + np.abs(a.local_pos))) > 1e-5:
        raise Insane("round trip: joint positions changed")


# ----------------------------------------------------------------------------- mutating real files


def _mutate_lines(rng: random.Random, text: str) -> tuple[str, str]:
    lines = text.split("\n")
    done = []
    for _ in range(rng.choice((1, 1, 2, 3))):
        op = rng.choice(("number", "number", "frames", "frame_time", "delete", "duplicate", "swap",
                         "keyword", "channels", "truncate", "chain"))
        k = rng.randrange(len(lines))
        if op == "number":
            nums = list(_NUMBER.finditer(lines[k]))
            if nums:
                m = rng.choice(nums)
                lines[k] = lines[k][:m.start()] + rng.choice(HOSTILE_NUMBERS) + lines[k][m.end():]
        elif op in ("frames", "frame_time"):
            key = "Frames:" if op == "frames" else "Frame Time:"
            values = (["0", "-1", "1", "2", "10000000000", "99999999999999999999", "1.5", "x", ""] if op == "frames"
                      else ["0", "-0.0333", "1e-300", "1e-9", "0.000999", "0.001", "1", "1.0001", "1e300", "nan",
                            "inf", ".0083333", "0.016667", "1e308", "3"])
            for j, ln in enumerate(lines):
                if ln.strip().startswith(key):
                    lines[j] = f"{key} {rng.choice(values)}"
        elif op == "delete" and len(lines) > 1:
            del lines[k]
        elif op == "duplicate":
            lines.insert(k, lines[k])
        elif op == "swap":
            j = rng.randrange(len(lines))
            lines[k], lines[j] = lines[j], lines[k]
        elif op == "keyword":
            words = ["ROOT", "JOINT", "End", "Site", "OFFSET", "CHANNELS", "{", "}", "MOTION", "HIERARCHY", ""]
            toks = lines[k].split()
            if toks:
                toks[rng.randrange(len(toks))] = rng.choice(words)
                lines[k] = " ".join(toks)
        elif op == "channels":
            idx = [j for j, ln in enumerate(lines) if "CHANNELS" in ln]
            if idx:
                j = rng.choice(idx)
                chans = rng.sample(_CHANNELS, rng.randrange(0, 7))
                count = rng.choice([len(chans), len(chans), len(chans) + 1, -1, 10 ** 20])
                lines[j] = f"CHANNELS {count} " + " ".join(c.lower() if rng.random() < 0.2 else c for c in chans)
        elif op == "truncate":
            lines = lines[:max(k, 1)]
        elif op == "chain":  # a deep chain of joints under the root
            depth = rng.choice((50, 499, 500, 501, 2000))
            at = next((j for j, ln in enumerate(lines) if "CHANNELS" in ln), 1) + 1
            chain = [f"JOINT c{d} {{ OFFSET 0 1 0 CHANNELS 3 Zrotation Xrotation Yrotation" for d in range(depth)]
            chain += ["End Site { OFFSET 0 1 0 }"] + ["}"] * depth
            lines[at:at] = chain
            timing = next((j for j, ln in enumerate(lines) if ln.startswith("Frame Time")), len(lines))
            for j in range(timing + 1, len(lines)):  # the frame lines need the extra channels
                if lines[j].strip():
                    lines[j] += " 0" * (3 * depth)
        done.append(op)
    return "\n".join(lines), "+".join(done)


# ----------------------------------------------------------------------------- building files


def _bvh_documents():
    """A hypothesis strategy of (label, BVH text): random skeletons and motion, odd numbers included."""
    from hypothesis import strategies as st

    odd = st.one_of(st.sampled_from(HOSTILE_NUMBERS), st.floats().map(repr),
                    st.integers(-10 ** 30, 10 ** 30).map(str))

    @st.composite
    def document(draw):
        n = draw(st.one_of(st.integers(1, 12), st.integers(1, 12), st.sampled_from([100, 499, 500, 501, 600])))
        chain = n > 12
        parents = [-1] + [(j - 1 if chain else draw(st.integers(0, j - 1))) for j in range(1, n)]
        channel_sets = []
        for j in range(min(n, 12)):
            chans = draw(st.lists(st.sampled_from(_CHANNELS), unique=True, max_size=6))
            if draw(st.integers(0, 9)) == 0:
                chans = [c.upper() for c in chans]
            channel_sets.append(chans)
        channels = [channel_sets[j % len(channel_sets)] for j in range(n)]
        miscount = draw(st.integers(0, 19)) == 0
        fill = random.Random(draw(st.integers(0, 2 ** 32)))
        offsets = [[f"{fill.uniform(-50, 50):.4f}" for _ in range(3)] for _ in range(min(n, 12))]
        odd_values = [draw(odd) for _ in range(draw(st.sampled_from([0, 0, 0, 1, 1, 2, 3])))]
        odd_in_offsets = [v for v in odd_values if fill.random() < 0.3]
        for v in odd_in_offsets:
            offsets[fill.randrange(len(offsets))][fill.randrange(3)] = v
        end_sites = {j for j in range(n) if j not in parents[1:]} if draw(st.booleans()) else set()
        children = [[] for _ in range(n)]
        for j in range(1, n):
            children[parents[j]].append(j)
        out = ["HIERARCHY"]
        stack = [(0, 0, False)]
        while stack:  # depth first without recursion (chains are thousands deep)
            j, depth, closing = stack.pop()
            pad = "  " * depth
            if closing:
                out.append(pad + "}")
                continue
            off = offsets[j % len(offsets)]
            count = len(channels[j]) + (1 if miscount and j == 0 else 0)
            out += [f"{pad}{'ROOT' if j == 0 else 'JOINT'} j{j}", pad + "{", f"{pad}  OFFSET {' '.join(off)}",
                    f"{pad}  CHANNELS {count} {' '.join(channels[j])}".rstrip()]
            if j in end_sites:
                out += [f"{pad}  End Site", pad + "  {", f"{pad}    OFFSET 0 1 0", pad + "  }"]
            stack.append((j, depth, True))
            stack += [(c, depth + 1, False) for c in reversed(children[j])]
        n_ch = sum(len(c) for c in channels)
        frames = draw(st.one_of(st.integers(1, 20), st.integers(1, 20), st.sampled_from([0, -1, 10 ** 12])))
        rows = max(0, min(frames, 20)) + draw(st.sampled_from([0, 0, 0, 0, 0, 0, 1, -1]))
        frame_time = draw(st.one_of(st.sampled_from(["0.0333333", ".0083333", "0.016667", "0.04", "1", "0.001"]),
                                    st.floats(0.0005, 1.5).map(repr), odd))
        out += ["MOTION", f"Frames: {frames}", f"Frame Time: {frame_time}"]
        values = [[f"{fill.uniform(-90, 90):.3f}" for _ in range(n_ch)] for _ in range(max(rows, 0))]
        for v in odd_values[len(odd_in_offsets):]:  # the other odd values go among the motion's
            if values and n_ch:
                values[fill.randrange(len(values))][fill.randrange(n_ch)] = v
        out += [" ".join(row) for row in values]
        label = f"{n} joints{' chain' if chain else ''}, {frames} frames x {n_ch} ch, frame time {frame_time}"
        return label, "\n".join(out) + "\n"

    return document()


TARGET = BVHTarget()

"""Writing a ``MotionClip`` as BVH that Blender, three.js and other tools import.

The skeleton's hierarchy, names, channel layout and End Sites are kept; the root
OFFSET is written as zero (its position is in the channels); Euler angles vary
continuously over frames; the file is written atomically.

The MOTION rows are formatted a block of frames at a time by numpy (``format_rows``,
the same bytes as ``"%.6f"`` per value) and a file is written block by block, so a
long dance never holds its whole text in memory.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from .. import rotations as rot
from ..errors import InputError
from ..types import POSITION_CHANNELS, ROTATION_CHANNELS, MotionClip
from .files import atomic_output

#: Frames formatted per block: big enough that numpy's per-call cost is spread thin, small
#: enough that a block's working arrays stay in the CPU cache.
BLOCK_FRAMES = 64


def write_bvh(path, clip: MotionClip, *, precision: int = 6) -> None:
    """Write ``clip`` to ``path`` as BVH (atomically: a failure leaves no partial file)."""
    hierarchy, values = bvh_values(clip, precision=precision)
    with atomic_output(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(_motion_header(hierarchy, clip))
        for block in row_blocks(values, precision):
            fh.write(block)


def _full_order(rot_axes: str) -> str:
    """A three-axis Euler order that starts with the axes a joint animates."""
    return rot_axes + "".join(a for a in "ZXY" if a not in rot_axes)


def format_bvh(clip: MotionClip, *, precision: int = 6) -> str:
    """BVH text of ``clip``: the skeleton's hierarchy, names, channel layout and End Sites.

    See ``bvh_values`` for the conventions.
    """
    hierarchy, values = bvh_values(clip, precision=precision)
    return _motion_header(hierarchy, clip) + "".join(row_blocks(values, precision))


def _motion_header(hierarchy: str, clip: MotionClip) -> str:
    return f"{hierarchy}\nMOTION\nFrames: {clip.n_frames}\nFrame Time: {1.0 / clip.fps:.8f}\n"


def bvh_parts(clip: MotionClip, *, precision: int = 6) -> tuple[str, list[str]]:
    """The HIERARCHY section (without a final newline) and one text row per frame."""
    hierarchy, values = bvh_values(clip, precision=precision)
    return hierarchy, "".join(row_blocks(values, precision)).split("\n")[:-1]


def row_blocks(values: np.ndarray, precision: int = 6, block: int = BLOCK_FRAMES):
    """The MOTION rows of ``values`` (frames, channels), ``block`` frames of text at a time."""
    for start in range(0, len(values), block):
        yield format_rows(values[start:start + block], precision)


def bvh_values(clip: MotionClip, *, precision: int = 6) -> tuple[str, np.ndarray]:
    """The HIERARCHY section (without a final newline) and the channel values (frames, channels)
    in file order.

    The root OFFSET is written as zero on the axes the root animates (its position
    is all in the channels), so Blender and three.js place the root alike. Euler
    angles come from ``rotations.to_euler`` and so vary continuously over frames.
    Lengths are written in the clip's unit (metres for a clip read by ``read_bvh``).
    A joint without rotation channels is written without them, losing its rotation.
    """
    if not isinstance(precision, int) or not 0 <= precision <= 17:
        raise InputError(f"precision={precision!r}; give the number of decimals as an integer from 0 to 17")
    sk = clip.skeleton
    n_f = clip.n_frames
    if n_f == 0:
        raise InputError("cannot write a BVH file with no frames; the clip is empty")
    channels = [tuple(c) for c in sk.channels]
    for j, joint in enumerate(sk.names):
        if not joint or any(ch.isspace() or ch in "{}" for ch in joint):
            raise InputError(f"cannot write joint name {joint!r} to BVH: names must be one word without braces")
        if sk.names.index(joint) != j:
            raise InputError(f"cannot write a BVH file: joint name {joint!r} appears twice; rename one")
        bad = [c for c in channels[j] if c not in POSITION_CHANNELS + ROTATION_CHANNELS]
        if bad or len(set(channels[j])) != len(channels[j]):
            raise InputError(f"cannot write joint {joint!r}: invalid channel list {channels[j]}")
    if not any(channels):
        raise InputError("cannot write a BVH file: no joint of the skeleton has channels")
    arrays = {"root_pos": clip.root_pos, "local_rot": clip.local_rot}
    if clip.local_pos is not None:
        arrays["local_pos"] = clip.local_pos
    for what, arr in arrays.items():
        if not np.all(np.isfinite(arr)):
            raise InputError(f"cannot write a BVH file: the clip's {what} holds NaN or infinite values")

    # Root OFFSET: zero where channels carry the position, else the (constant) position.
    root_offset = clip.root_pos[0].copy()
    for c in channels[0]:
        if c in POSITION_CHANNELS:
            root_offset[POSITION_CHANNELS.index(c)] = 0.0

    # BVH lists channels in the order the HIERARCHY visits joints (depth first), which
    # need not be our index order for a skeleton built in code.
    children = [[] for _ in range(sk.n_joints)]
    for j in range(1, sk.n_joints):
        children[sk.parents[j]].append(j)
    visit, stack = [], [0]
    while stack:
        j = stack.pop()
        visit.append(j)
        stack.extend(reversed(children[j]))
    values = _channel_values(clip, channels, visit, root_offset)

    num = f"{{:.{precision}f}}".format
    out = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        pad = "\t" * depth
        out.append(f"{pad}{'ROOT' if j == 0 else 'JOINT'} {sk.names[j]}")
        out.append(f"{pad}{{")
        off = root_offset if j == 0 else sk.offsets[j]
        out.append(f"{pad}\tOFFSET {num(off[0])} {num(off[1])} {num(off[2])}")
        out.append(f"{pad}\tCHANNELS {len(channels[j])}" + "".join(" " + c for c in channels[j]))
        for child in children[j]:
            emit(child, depth + 1)
        if j in sk.end_sites:
            e = sk.end_sites[j]
            out.append(f"{pad}\tEnd Site")
            out.append(f"{pad}\t{{")
            out.append(f"{pad}\t\tOFFSET {num(e[0])} {num(e[1])} {num(e[2])}")
            out.append(f"{pad}\t}}")
        out.append(f"{pad}}}")

    emit(0, 0)
    return "\n".join(out), values


def _channel_values(clip: MotionClip, channels: list, visit: list, root_offset: np.ndarray) -> np.ndarray:
    """The MOTION values (frames, channels) in file order, filled ``rot.EULER_CHUNK`` frames at a
    time (a whole 30-minute dance's Euler angles at once were 60 MB more)."""
    sk, n_f = clip.skeleton, clip.n_frames
    groups: dict[str, list[int]] = {}
    for j, chans in enumerate(channels):
        axes = "".join(c[0] for c in chans if c in ROTATION_CHANNELS)
        if axes:
            groups.setdefault(_full_order(axes), []).append(j)
    # Where each joint's channels go: (column, position axis or None, rotation index)
    columns, col = {}, 0
    for j in visit:
        r, out = 0, []
        for c in channels[j]:
            if c in POSITION_CHANNELS:
                out.append((col, POSITION_CHANNELS.index(c), None))
            else:
                out.append((col, None, r))
                r += 1
            col += 1
        columns[j] = out
    values = np.zeros((n_f, col))
    prev: dict[str, np.ndarray | None] = {order: None for order in groups}
    for a in range(0, n_f, rot.EULER_CHUNK):
        b = min(a + rot.EULER_CHUNK, n_f)
        for order, joints in groups.items():
            with warnings.catch_warnings():
                # At gimbal lock SciPy warns and picks one of the equivalent triples; fine here.
                warnings.filterwarnings("ignore", message="Gimbal lock", category=UserWarning)
                angles = rot.to_euler(clip.local_rot[a:b, joints], order, prev=prev[order])  # continuous
            prev[order] = angles[-1]
            for k, j in enumerate(joints):
                for c, _, r in columns[j]:
                    if r is not None:
                        values[a:b, c] = angles[:, k, r]
        for j in visit:
            for c, axis, _ in columns[j]:
                if axis is None:
                    continue
                if j == 0:
                    values[a:b, c] = clip.root_pos[a:b, axis] - root_offset[axis]
                elif clip.local_pos is not None:
                    values[a:b, c] = clip.local_pos[a:b, j, axis] - sk.offsets[j, axis]
    return values


def format_rows(values: np.ndarray, precision: int = 6) -> str:
    """``"%.{precision}f"`` of every value, space-separated, each row ended by a newline.

    The same bytes as Python's formatting, made by numpy for the whole block at once: each
    value is rounded to an integer count of ``10**-precision`` and its digits are written
    straight into the text's bytes. Python formats the rare values where that rounding could
    differ from Python's exact decimal one (a product within an ulp of a half) or that are too
    big for it, and they are placed in the same text.
    """
    values = np.asarray(values, dtype=np.float64)
    n, c = values.shape
    if n == 0 or c == 0:
        return "\n" * n
    flat = values.ravel()
    with np.errstate(over="ignore", invalid="ignore"):
        scaled = np.abs(flat) * (10.0 ** precision)
        # rint(scaled) is the exact decimal rounding unless the product's own rounding error (at
        # most an ulp of it) could have carried it across a half, or it is too big for int64.
        slow = (np.abs(scaled - np.floor(scaled) - 0.5) <= scaled * 2.0 ** -50) | ~(scaled < 2.0 ** 52)
    np.rint(scaled, out=scaled)
    scaled[slow] = 0.0
    scaled = scaled.astype(np.int64)
    unit = 10 ** precision
    whole = scaled // unit
    frac = scaled - whole * unit
    n_whole = np.ones(len(flat), dtype=np.int64)  # digits before the point
    k, top = 1, int(whole.max())
    while 10 ** k <= top:
        n_whole += whole >= 10 ** k
        k += 1
    neg = np.signbit(flat)  # also -0.0 and tiny negatives, which Python writes as -0.000000
    dot = 1 if precision > 0 else 0
    width = n_whole + (precision + dot) + neg
    slow_at = np.flatnonzero(slow)
    slow_text = [(f"%.{precision}f" % flat[i]).encode("ascii") for i in slow_at]
    width[slow_at] = [len(t) for t in slow_text]
    # Each value's bytes end just before its separator; fill them right to left, digit by digit.
    end = np.cumsum(width + 1) - 1
    out = np.empty(int(end[-1]) + 1, dtype=np.uint8)
    out[end] = ord(" ")
    out[end[c - 1::c]] = ord("\n")
    pos = end - 1
    for _ in range(precision):
        q = frac // 10
        out[pos] = frac - q * 10 + ord("0")
        frac = q
        pos -= 1
    if dot:
        out[pos] = ord(".")
        pos -= 1
    out[pos] = whole % 10 + ord("0")
    for j in range(1, k):
        whole //= 10
        more = np.flatnonzero(n_whole > j)
        out[pos[more] - j] = whole[more] % 10 + ord("0")
    signed = np.flatnonzero(neg)
    out[pos[signed] - n_whole[signed]] = ord("-")
    for i, text in zip(slow_at, slow_text):
        out[end[i] - len(text):end[i]] = np.frombuffer(text, dtype=np.uint8)
    return out.tobytes().decode("ascii")


class BVHStreamWriter:
    """A BVH file that grows segment by segment and is a complete BVH after every ``append``.

    The header is written with the first frames; ``Frames:`` has a fixed-width
    field that is rewritten in place after the new rows are flushed, so a reader
    that opens the file between appends sees every frame declared so far. The
    hierarchy (and the root OFFSET) come from the first appended clip.
    """

    COUNT_WIDTH = 12

    def __init__(self, path, *, precision: int = 6):
        self.path = Path(path)
        if not self.path.parent.is_dir():
            raise InputError(f"cannot write {self.path}: folder {self.path.parent} does not exist (create it first)")
        self.precision = precision
        self.frames = 0
        self._fh = None
        self._count_at = 0

    def append(self, clip: MotionClip) -> None:
        if clip.n_frames == 0:
            return
        hierarchy, values = bvh_values(clip, precision=self.precision)
        if self._fh is None:
            self._fh = open(self.path, "w", encoding="utf-8", newline="\n")
            self._fh.write(hierarchy + "\nMOTION\nFrames: ")
            self._count_at = self._fh.tell()
            self._fh.write(" " * self.COUNT_WIDTH + f"\nFrame Time: {1.0 / clip.fps:.8f}\n")
        self._fh.seek(0, 2)
        for block in row_blocks(values, self.precision):
            self._fh.write(block)
        self._fh.flush()
        self.frames += clip.n_frames
        self._fh.seek(self._count_at)
        self._fh.write(f"{self.frames:<{self.COUNT_WIDTH}d}")
        self._fh.flush()

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def __enter__(self) -> "BVHStreamWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

"""Writing a ``MotionClip`` as BVH that Blender, three.js and other tools import.

The skeleton's hierarchy, names, channel layout and End Sites are kept; the root
OFFSET is written as zero (its position is in the channels); Euler angles vary
continuously over frames; the file is written atomically.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from .. import rotations as rot
from ..errors import InputError
from ..types import POSITION_CHANNELS, ROTATION_CHANNELS, MotionClip
from .files import atomic_output

def write_bvh(path, clip: MotionClip, *, precision: int = 6) -> None:
    """Write ``clip`` to ``path`` as BVH (atomically: a failure leaves no partial file)."""
    text = format_bvh(clip, precision=precision)
    with atomic_output(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(text)


def _full_order(rot_axes: str) -> str:
    """A three-axis Euler order that starts with the axes a joint animates."""
    return rot_axes + "".join(a for a in "ZXY" if a not in rot_axes)


def format_bvh(clip: MotionClip, *, precision: int = 6) -> str:
    """BVH text of ``clip``: the skeleton's hierarchy, names, channel layout and End Sites.

    See ``bvh_parts`` for the conventions.
    """
    hierarchy, rows = bvh_parts(clip, precision=precision)
    return "\n".join([hierarchy, "MOTION", f"Frames: {clip.n_frames}", f"Frame Time: {1.0 / clip.fps:.8f}",
                      *rows]) + "\n"


def bvh_parts(clip: MotionClip, *, precision: int = 6) -> tuple[str, list[str]]:
    """The HIERARCHY section (without a final newline) and one text row per frame.

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

    # Channel values, column by column, in file order.
    euler: dict[int, np.ndarray] = {}
    groups: dict[str, list[int]] = {}
    for j, chans in enumerate(channels):
        axes = "".join(c[0] for c in chans if c in ROTATION_CHANNELS)
        if axes:
            groups.setdefault(_full_order(axes), []).append(j)
    for order, joints in groups.items():
        with warnings.catch_warnings():
            # At gimbal lock SciPy warns and picks one of the equivalent triples; fine here.
            warnings.filterwarnings("ignore", message="Gimbal lock", category=UserWarning)
            angles = rot.to_euler(clip.local_rot[:, joints], order)  # (F, k, 3), continuous along frames
        for k, j in enumerate(joints):
            euler[j] = angles[:, k]
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

    columns = []
    for j in visit:
        r = 0
        for c in channels[j]:
            if c in POSITION_CHANNELS:
                axis = POSITION_CHANNELS.index(c)
                if j == 0:
                    columns.append(clip.root_pos[:, axis] - root_offset[axis])
                elif clip.local_pos is not None:
                    columns.append(clip.local_pos[:, j, axis] - sk.offsets[j, axis])
                else:
                    columns.append(np.zeros(n_f))
            else:
                columns.append(euler[j][:, r])
                r += 1
    values = np.stack(columns, axis=1) if columns else np.zeros((n_f, 0))

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
    row = " ".join([f"%.{precision}f"] * values.shape[1])
    return "\n".join(out), [row % tuple(v) for v in values.tolist()]


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
        hierarchy, rows = bvh_parts(clip, precision=self.precision)
        if self._fh is None:
            self._fh = open(self.path, "w", encoding="utf-8", newline="\n")
            self._fh.write(hierarchy + "\nMOTION\nFrames: ")
            self._count_at = self._fh.tell()
            self._fh.write(" " * self.COUNT_WIDTH + f"\nFrame Time: {1.0 / clip.fps:.8f}\n")
        self._fh.seek(0, 2)
        self._fh.write("\n".join(rows) + "\n")
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

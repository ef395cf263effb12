"""BVH motion files: read the common dialects into a ``MotionClip``, write one back.

Reading accepts any channel order per joint, position channels on any joint, End
Sites, tabs/spaces/CRLF, blank lines and short ``Frame Time`` spellings such as
``.0083333``. The MOTION block is parsed with numpy, so a file of thousands of
frames reads in a fraction of a second.

Conventions of the returned clip (see ``dancesynth.types``):

- BVH rotation channels are intrinsic rotations in listed order, so the channels
  ``Zrotation Xrotation Yrotation`` become ``rotations.from_euler(angles, "ZXY")``.
- The root's position channels are read as the tools that wrote the file meant them
  (``root_channels_absolute``): absolute (Blender, Mixamo and MotionBuilder write the
  rest position as the OFFSET and the absolute position in the channels, and Blender
  reads them so) or added to the OFFSET (iClone writes channels relative to it, and
  three.js always adds); the OFFSET is folded into ``root_pos`` and
  ``skeleton.offsets[0]`` is zero, so a file we write (a zero root OFFSET) means the
  same to every reader. ``meta["root_channels"]`` says which reading was taken.
- Non-root joints with position channels get ``local_pos`` = OFFSET + channel
  values (for every joint, so ``kinematics.fk`` can use it directly); otherwise
  ``local_pos`` is ``None``.
- Lengths are converted to metres (``detect_units`` guesses the file's unit from
  the rest pose; ``units=`` overrides), and the T-pose frame that converters put
  first is dropped (``drop_tpose``). ``clip.meta`` records what was done.

Writing keeps the hierarchy, names, channel layout and End Sites of the skeleton,
writes a zero root OFFSET and continuity-preserving Euler angles, and goes
through ``files.atomic_output`` so that a failure leaves no partial file.
"""

from __future__ import annotations

import io
import math
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import rotations as rot
from ..errors import InputError
from ..types import POSITION_CHANNELS, ROTATION_CHANNELS, MotionClip, Skeleton
from .bvh_writer import format_bvh, write_bvh
from .files import decode_text
from .skeleton_units import UNITS, detect_units, is_tpose_first_frame, resolve_units, standing_height

__all__ = ["UNITS", "read_bvh", "parse_bvh", "write_bvh", "format_bvh", "detect_units", "standing_height",
           "is_tpose_first_frame"]

_CHANNEL_NAMES = {c.lower(): c for c in POSITION_CHANNELS + ROTATION_CHANNELS}
# What a motion file may state (checked as it is read): frame rates and coordinates past these are
# corrupt or hostile files (10^300 fps, an offset of 1e308 that makes every position infinite).
FPS_RANGE = (1.0, 1000.0)
MAX_VALUE = 1e6  # any OFFSET or channel value, in the file's units (cm or m; degrees)
MAX_JOINTS = 500  # a 20,000-joint chain took 11 s to read and a 1,000-joint one could not be written
# 500 joints take ~100 bytes each; a HIERARCHY far longer is refused before it is tokenised (15 MB took 3 s).
MAX_HEADER_CHARS = 2_000_000
_KEYWORDS = {"HIERARCHY", "ROOT", "JOINT", "END", "OFFSET", "CHANNELS", "MOTION", "{", "}"}
_TOKEN = re.compile(r"[{}]|[^\s{}]+")
_MOTION_LINE = re.compile(r"^[ \t]*MOTION[ \t]*$", re.MULTILINE)

# --------------------------------------------------------------------------- reading


@dataclass
class _Raw:
    """What the file says, before unit conversion and clip building."""

    names: list[str] = field(default_factory=list)
    parents: list[int] = field(default_factory=list)
    offsets: list[tuple[float, float, float]] = field(default_factory=list)
    channels: list[tuple[str, ...]] = field(default_factory=list)
    end_sites: dict[int, tuple[float, float, float]] = field(default_factory=dict)
    frame_time: float = 0.0
    frame_time_text: str = ""
    values: np.ndarray | None = None  # (frames, channels)


def read_bvh(path, *, to_metres: bool = True, units=None, drop_tpose: bool = True) -> MotionClip:
    """Read a BVH file into a ``MotionClip`` (metres, T-pose dropped by default).

    ``units`` overrides unit detection: a name of ``UNITS`` ("m", "cm", "mm", "in",
    "asf", "daz128") or metres per file unit as a number. ``to_metres=False`` keeps
    the file's lengths (the unit is still detected and recorded). ``clip.meta`` gets
    ``name`` (file stem), ``source`` (path), ``source_units``, ``metres_per_unit``,
    ``in_metres`` and ``dropped_tpose``. Raises ``InputError`` for a missing,
    unreadable or malformed file, naming the file and, where it helps, the line.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such BVH file; check the path")
    if path.is_dir():
        raise InputError(f"{path}: is a folder, not a BVH file; pass the path of a .bvh file")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot read the file ({exc.strerror}); check its permissions") from exc
    text = _decode(data, str(path))
    return parse_bvh(text, name=str(path), to_metres=to_metres, units=units, drop_tpose=drop_tpose)


def parse_bvh(text: str, *, name: str = "<string>", to_metres: bool = True, units=None,
              drop_tpose: bool = True) -> MotionClip:
    """Parse BVH text into a ``MotionClip``; ``name`` is used in error messages and ``meta``."""
    raw = _parse(text, name)
    return _build_clip(raw, name, to_metres=to_metres, units=units, drop_tpose=drop_tpose)


def _decode(data: bytes, name: str) -> str:
    return decode_text(data, empty=f"{name}: the file is empty; a BVH file starts with a HIERARCHY section",
                       binary=f"{name}: not a BVH file (it looks binary); BVH is a text format starting with "
                              "HIERARCHY")


def _parse(text: str, name: str) -> _Raw:
    # One line ending from here on (files mix CRLF headers with LF motion, or use bare CR).
    text = text.replace("\r\n", "\n").replace("\r", "\n").lstrip("\ufeff")
    if not text.strip():
        raise InputError(f"{name}: the file is empty; a BVH file starts with a HIERARCHY section")
    if "\x00" in text:
        raise InputError(f"{name}: not a BVH file (it looks binary); BVH is a text format starting with HIERARCHY")
    m = _MOTION_LINE.search(text)
    header = text if m is None else text[: m.start()]
    if len(header) > MAX_HEADER_CHARS:
        raise InputError(f"{name}: the HIERARCHY section is {len(header) / 1e6:.1f} MB long, more than a skeleton "
                         f"of at most {MAX_JOINTS} joints needs ({MAX_HEADER_CHARS / 1e6:g} MB); the file is corrupt "
                         "or not a character")
    raw = _Raw()
    _parse_hierarchy(header, name, raw)
    if m is None:
        raise InputError(f"{name}: no MOTION section after the HIERARCHY; the file is truncated or not a BVH file")
    motion_lineno = text.count("\n", 0, m.start()) + 1
    _parse_motion(text[m.end():], motion_lineno, name, raw)
    return raw


def _tokens(header: str):
    out = []
    for lineno, line in enumerate(header.splitlines(), 1):
        for tok in _TOKEN.findall(line):
            out.append((tok, lineno))
    return out


def _parse_hierarchy(header: str, name: str, raw: _Raw) -> None:
    toks = _tokens(header)
    n = len(toks)
    pos = 0

    def err(msg, line=None):
        where = f"{name}: line {line}: " if line else f"{name}: "
        return InputError(where + msg)

    def take(what):
        nonlocal pos
        if pos >= n:
            last = toks[-1][1] if toks else 1
            raise err(f"the HIERARCHY ends early, expected {what}; unbalanced braces or a truncated file", last)
        pos += 1
        return toks[pos - 1]

    def number(what):
        tok, line = take(what)
        try:
            v = float(tok)
        except ValueError:
            raise err(f"expected a number for {what}, found {tok!r}; fix the OFFSET line", line) from None
        if not (math.isfinite(v) and abs(v) <= MAX_VALUE):
            raise err(f"{what} is {tok}; OFFSET values must be finite numbers within ±{MAX_VALUE:g}", line)
        return v

    tok, line = take("HIERARCHY")
    if tok.upper() != "HIERARCHY":
        raise err(f"not a BVH file: expected HIERARCHY, found {tok[:40]!r}; BVH files start with HIERARCHY", line)
    tok, line = take("ROOT")
    if tok.upper() != "ROOT":
        raise err(f"expected ROOT after HIERARCHY, found {tok[:40]!r}; the skeleton needs a ROOT joint", line)

    stack: list[tuple[int, int]] = []  # open joints: (joint index, line of its "{")
    seen: dict[str, int] = {}
    has_offset: set[int] = set()
    pending = ("ROOT", line)  # a ROOT/JOINT/End keyword waiting for its name and "{"
    while True:
        if pending is not None:
            kind, kline = pending
            pending = None
            if kind == "END":
                tok, line = take("'Site' after 'End'")
                if tok.upper() != "SITE":
                    raise err(f"expected 'End Site', found 'End {tok}'", line)
                parent = stack[-1][0]
                if parent in raw.end_sites:
                    raise err(f"joint {raw.names[parent]!r} has two End Sites; keep one", kline)
                tok, line = take("'{' after End Site")
                if tok != "{":
                    raise err(f"expected '{{' after End Site, found {tok!r}", line)
                tok, line = take("OFFSET in End Site")
                if tok.upper() != "OFFSET":
                    raise err(f"expected OFFSET inside End Site, found {tok!r}", line)
                raw.end_sites[parent] = (number("End Site OFFSET x"), number("End Site OFFSET y"),
                                         number("End Site OFFSET z"))
                tok, line = take("'}' closing the End Site")
                if tok != "}":
                    raise err(f"expected '}}' closing the End Site, found {tok!r}; unbalanced braces", line)
            else:
                tok, line = take(f"a name after {kind}")
                if tok in ("{", "}") or line != kline:  # the name shares the keyword's line
                    raise err(f"{kind} has no name (found {tok!r}); every joint needs a unique name", line)
                # A name with spaces becomes one word joined by "_", as Blender's importer does.
                parts = [tok]
                while pos < n and toks[pos][1] == line and toks[pos][0] != "{":
                    parts.append(toks[pos][0])
                    pos += 1
                tok = "_".join(parts)
                if tok in seen:
                    raise err(f"duplicate joint name {tok!r} (first defined on line {seen[tok]}); "
                              "joint names must be unique, rename one", line)
                seen[tok] = line
                idx = len(raw.names)
                if idx >= MAX_JOINTS:
                    raise err(f"more than {MAX_JOINTS} joints: no body needs so many (a hand has 20, a face rig "
                              "a few dozen); the file is corrupt or not a character", line)
                raw.names.append(tok)
                raw.parents.append(stack[-1][0] if stack else -1)
                raw.offsets.append((0.0, 0.0, 0.0))
                raw.channels.append(())
                b, bline = take(f"'{{' after {kind} {tok}")
                if b != "{":
                    raise err(f"expected '{{' after {kind} {tok}, found {b!r}", bline)
                stack.append((idx, bline))
        if pos >= n:
            if stack:
                j, opened = stack[-1]
                raise err(f"unbalanced braces: {len(stack)} '{{' not closed (joint {raw.names[j]!r} opened on line "
                          f"{opened}); add the missing '}}' or check for a truncated file", toks[-1][1])
            break
        tok, line = take("a keyword")
        key = tok.upper()
        if key == "}":
            if not stack:
                raise err("unbalanced braces: '}' closes nothing; remove it", line)
            j, _ = stack.pop()
            if j not in has_offset:
                raise err(f"joint {raw.names[j]!r} has no OFFSET; add 'OFFSET x y z'", line)
            if not stack:
                if pos < n:
                    tok, line = toks[pos]
                    if tok.upper() == "ROOT":
                        raise err("a second ROOT; only one skeleton per file is supported, split the file", line)
                    if tok == "}":
                        raise err("unbalanced braces: '}' closes nothing; remove it", line)
                    raise err(f"unexpected {tok[:40]!r} after the ROOT joint was closed; expected MOTION", line)
                break
        elif not stack:
            raise err(f"unexpected {tok[:40]!r}", line)
        elif key in ("JOINT", "END"):
            pending = (key, line)
        elif key == "OFFSET":
            j = stack[-1][0]
            raw.offsets[j] = (number("OFFSET x"), number("OFFSET y"), number("OFFSET z"))
            has_offset.add(j)
        elif key == "CHANNELS":
            j = stack[-1][0]
            ctok, cline = take("the channel count")
            try:
                count = int(ctok)
            except ValueError:
                raise err(f"expected a channel count after CHANNELS, found {ctok!r}", cline) from None
            if count < 0:
                raise err(f"negative channel count {count}", cline)
            names = []
            while pos < n and toks[pos][1] == cline and toks[pos][0].upper() not in _KEYWORDS:
                names.append(toks[pos][0])
                pos += 1
            if len(names) != count:
                raise err(f"CHANNELS says {count} channels but lists {len(names)} ({' '.join(names)}); "
                          "make the count match the names", cline)
            norm = []
            for c in names:
                c2 = _CHANNEL_NAMES.get(c.lower())
                if c2 is None:
                    raise err(f"unknown channel {c!r} for joint {raw.names[j]!r}; channels are "
                              f"{', '.join(POSITION_CHANNELS + ROTATION_CHANNELS)}", cline)
                norm.append(c2)
            if len(set(norm)) != len(norm):
                raise err(f"joint {raw.names[j]!r} lists a channel twice ({' '.join(names)})", cline)
            raw.channels[j] = tuple(norm)
        elif key == "MOTION":
            raise err("MOTION inside the HIERARCHY; unbalanced braces", line)
        else:
            raise err(f"unexpected {tok[:40]!r} inside joint {raw.names[stack[-1][0]]!r}; "
                      "expected OFFSET, CHANNELS, JOINT, End Site or '}'", line)


def _parse_motion(body: str, motion_lineno: int, name: str, raw: _Raw) -> None:
    # body starts right after the word MOTION, so lines[k] is file line motion_lineno + k.
    lines = body.split("\n")
    i = 0

    def next_nonblank():
        nonlocal i
        while i < len(lines) and not lines[i].strip():
            i += 1
        if i >= len(lines):
            return None, motion_lineno + len(lines) - 1
        i += 1
        return lines[i - 1].strip(), motion_lineno + i - 1

    # Header lines are matched loosely ("Frames:10", "Frame Time:  .0083").
    line, lineno = next_nonblank()
    m = re.fullmatch(r"Frames\s*:?\s*(\S+)", line or "", re.IGNORECASE)
    if m is None:
        raise InputError(f"{name}: line {lineno}: expected 'Frames: N' after MOTION, found {(line or '')[:40]!r}; "
                         "add the Frames line")
    try:
        n_frames = int(m.group(1))
    except ValueError:
        raise InputError(f"{name}: line {lineno}: 'Frames:' needs a whole number, found {m.group(1)[:40]!r}") from None
    if n_frames <= 0:
        raise InputError(f"{name}: line {lineno}: 'Frames: {n_frames}'; a BVH file needs at least one frame of motion")
    line, lineno = next_nonblank()
    m = re.fullmatch(r"Frame\s*Time\s*:?\s*(\S+)", line or "", re.IGNORECASE)
    if m is None:
        raise InputError(f"{name}: line {lineno}: expected 'Frame Time: seconds' after 'Frames:', "
                         f"found {(line or '')[:40]!r}; add the Frame Time line (e.g. 'Frame Time: 0.0083333')")
    try:
        frame_time = float(m.group(1))
    except ValueError:
        raise InputError(f"{name}: line {lineno}: Frame Time {m.group(1)[:40]!r} is not a number") from None
    if not (math.isfinite(frame_time) and 1.0 / FPS_RANGE[1] <= frame_time <= 1.0 / FPS_RANGE[0]):
        raise InputError(f"{name}: line {lineno}: Frame Time {m.group(1)[:40]} must be a number of seconds from "
                         f"{1.0 / FPS_RANGE[1]:g} to {1.0 / FPS_RANGE[0]:g} ({FPS_RANGE[0]:g}-{FPS_RANGE[1]:g} fps; "
                         "e.g. 0.0083333 for 120 fps)")
    raw.frame_time = frame_time
    raw.frame_time_text = m.group(1)

    n_ch = sum(len(c) for c in raw.channels)
    if n_ch == 0:
        raise InputError(f"{name}: no joint has CHANNELS; a BVH skeleton needs at least the root's channels")
    data_first_line = motion_lineno + i  # file line number of lines[i]
    data = "\n".join(lines[i:])
    values = None
    try:
        # numpy's C parser: ~10x faster than splitting in Python for big files.
        with warnings.catch_warnings():   # "input contained no data": the check below says it in our words
            warnings.simplefilter("ignore")
            values = np.loadtxt(io.StringIO(data), dtype=np.float64, comments=None, ndmin=2)
    except ValueError:
        pass
    if values is None or values.shape != (n_frames, n_ch):
        _diagnose_motion(lines[i:], data_first_line, n_frames, n_ch, name)
        raise InputError(f"{name}: the MOTION block cannot be read as {n_frames} lines of {n_ch} numbers")
    finite = np.isfinite(values) & (np.abs(values) <= MAX_VALUE)
    if not finite.all():
        f, c = np.argwhere(~finite)[0]
        line_of = _nonblank_line_numbers(lines[i:], data_first_line)
        raise InputError(f"{name}: line {line_of[f]}: value {values[f, c]} (frame {f}, channel {c + 1}) is "
                         f"not finite or lies beyond ±{MAX_VALUE:g}; fix or re-export the motion")
    raw.values = values


def _nonblank_line_numbers(lines, first_line):
    return [first_line + k for k, ln in enumerate(lines) if ln.strip()]


def _diagnose_motion(lines, first_line, n_frames, n_ch, name) -> None:
    """Find the first problem of a MOTION block that numpy refused; raise a precise ``InputError``."""
    rows = [(first_line + k, ln.split()) for k, ln in enumerate(lines) if ln.strip()]
    need = f"'Frames: {n_frames}' x {n_ch} channels"
    for k, (lineno, toks) in enumerate(rows[:n_frames]):
        if len(toks) != n_ch:
            if k == len(rows) - 1 and len(toks) < n_ch:
                break  # the last line was cut short: report truncation below
            raise InputError(f"{name}: line {lineno}: {len(toks)} values on a frame line, but the HIERARCHY "
                             f"declares {n_ch} channels; each frame must be one line of {n_ch} numbers")
        for v in toks:
            try:
                float(v)
            except ValueError:
                raise InputError(f"{name}: line {lineno}: {v[:40]!r} is not a number; frame lines hold "
                                 "numbers only") from None
    got = sum(len(t) for _, t in rows)
    if got < n_frames * n_ch or len(rows) < n_frames:
        raise InputError(f"{name}: the MOTION block is truncated: {need} needs {n_frames * n_ch} values on "
                         f"{n_frames} lines, found {got} values on {len(rows)} lines; re-export the file or "
                         "correct the Frames count")
    if len(rows) > n_frames:
        raise InputError(f"{name}: line {rows[n_frames][0]}: extra values after the {n_frames} frames that "
                         "'Frames:' announces; correct the Frames count or remove the extra lines")


def _fps_from_frame_time(frame_time: float, text: str) -> float:
    """Frames per second; snaps to a whole rate when ``text`` is that rate's rounded frame time.

    Exporters print 1/60 as 0.016667 or 1/120 as .0083333; taking the reciprocal
    literally would give 59.9988 fps and drift by frames over a long clip.
    """
    fps = 1.0 / frame_time
    whole = round(fps)
    digits = len(text.split(".")[1]) if "." in text and "e" not in text.lower() else None
    if whole > 0 and digits is not None:
        if abs(1.0 / whole - frame_time) <= 0.5 * 10.0 ** -digits * (1 + 1e-9):
            return float(whole)
    return fps


def root_channels_absolute(offset: np.ndarray, channels: dict) -> bool:
    """Whether the root's position ``channels`` (axis -> values over frames) are absolute positions, not
    additions to its ``offset``: the reading under which they stay nearer the rest position (on a tie,
    added, BVH's textbook reading). A file whose root OFFSET is zero on those axes reads the same either
    way (True)."""
    axes = [a for a in channels if abs(offset[a]) > 1e-9]
    if not axes or not len(next(iter(channels.values()))):
        return True
    as_absolute = sum(float(np.median(np.abs(channels[a] - offset[a]))) for a in axes)
    as_added = sum(float(np.median(np.abs(channels[a]))) for a in axes)
    return as_absolute < as_added


def _build_clip(raw: _Raw, name: str, *, to_metres: bool, units, drop_tpose: bool) -> MotionClip:
    n_j = len(raw.names)
    offsets = np.array(raw.offsets, dtype=np.float64).reshape(n_j, 3)
    parents = np.array(raw.parents, dtype=np.int64)
    values = raw.values
    n_f = values.shape[0]

    root_pos = np.repeat(offsets[:1], n_f, axis=0)
    # The root's channels are the first columns of a frame.
    root_axes = [(POSITION_CHANNELS.index(c), col) for col, c in enumerate(raw.channels[0]) if c in POSITION_CHANNELS]
    absolute = root_channels_absolute(offsets[0], {axis: values[:, col] for axis, col in root_axes})
    local_rot = np.empty((n_f, n_j, 4))
    local_pos = None
    col = 0
    euler_groups: dict[str, list[tuple[int, list[int]]]] = {}
    for j, chans in enumerate(raw.channels):
        rot_cols, order = [], ""
        for c in chans:
            if c in POSITION_CHANNELS:
                axis = POSITION_CHANNELS.index(c)
                if j == 0:
                    root_pos[:, axis] = values[:, col] + (0.0 if absolute else offsets[0, axis])
                else:
                    if local_pos is None:
                        local_pos = np.broadcast_to(offsets, (n_f, n_j, 3)).copy()
                    local_pos[:, j, axis] += values[:, col]
            else:
                rot_cols.append(col)
                order += c[0]
            col += 1
        if order:
            euler_groups.setdefault(order, []).append((j, rot_cols))
        else:
            local_rot[:, j] = rot.IDENTITY
    # One vectorised conversion per distinct Euler order (files use one or two).
    for order, members in euler_groups.items():
        joints = [j for j, _ in members]
        cols = np.array([c for _, c in members])  # (joints, len(order))
        local_rot[:, joints] = rot.from_euler(values[:, cols], order)

    offsets[0] = 0.0  # folded into root_pos
    if local_pos is not None:
        local_pos[:, 0] = 0.0
    end_sites = {j: np.array(o, dtype=np.float64) for j, o in raw.end_sites.items()}
    skeleton = Skeleton(tuple(raw.names), parents, offsets, tuple(raw.channels), end_sites)
    fps = _fps_from_frame_time(raw.frame_time, raw.frame_time_text)
    clip = MotionClip(skeleton, fps, root_pos, local_rot, local_pos)

    if units is None:
        unit_name, scale = detect_units(skeleton, clip=clip)
    else:
        unit_name, scale = resolve_units(units, name)
    if to_metres and scale != 1.0:
        clip = MotionClip(skeleton.scaled(scale), fps, root_pos * scale, local_rot,
                          None if local_pos is None else local_pos * scale)
    dropped = bool(drop_tpose and is_tpose_first_frame(clip))
    if dropped:
        clip = clip.frames(1, clip.n_frames)
    clip.meta.update({
        "name": Path(name).stem if name != "<string>" else name,
        "source": name,
        "source_units": unit_name,
        "metres_per_unit": scale,
        "in_metres": bool(to_metres),
        "dropped_tpose": dropped,
        "root_channels": "absolute" if absolute else "added to the OFFSET",
    })
    return clip

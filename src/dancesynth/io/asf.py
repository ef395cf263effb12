"""Acclaim ASF skeleton files (CMU's original release): what ``asf_amc.read_amc`` animates.

An ``.asf`` file holds the skeleton: ``:units`` (``length 0.45`` is CMU's), ``:root``
(channel ``order``, ``axis`` order, rest ``position``/``orientation``), ``:bonedata``
(per bone a world-space ``direction``, a ``length``, an ``axis`` -- three angles and the
order they are applied in -- and the ``dof`` that the motion file animates) and
``:hierarchy`` (``parent child child ...``). ``asf_amc`` says how its bones become joints.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError
from .files import decode_text, read_user_file

MAX_ASF_BYTES = 2_000_000        # CMU's are ~10 kB
MAX_BONES = 500
MAX_VALUE = 1e6                  # any length, position or angle in the files
ROT_DOFS = ("rx", "ry", "rz")


@dataclass
class AsfSkeleton:
    """An ASF skeleton as the file states it (file units, angles in radians)."""

    name: str
    names: list[str]                  # root first, then bones, parents before children
    parents: list[int]
    directions: np.ndarray            # (J, 3) unit vectors, world axes (root: zero)
    lengths: np.ndarray               # (J,) file units (root: 0)
    axes: list[Rotation]              # C per joint
    dofs: list[tuple[str, ...]]       # AMC columns per joint, lower case ("tx", "rx", ...)
    length_unit: float = 1.0          # ":units length"
    angle_deg: bool = True            # ":units angle"
    root_position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    source: str = ""

    @property
    def n_joints(self) -> int:
        return len(self.names)


def read_asf(path) -> AsfSkeleton:
    """Parse an Acclaim ``.asf`` skeleton file; ``InputError`` names the file and line of a fault."""
    path = Path(path)
    text = read_text(path, MAX_ASF_BYTES, "ASF skeleton")
    return parse_asf(text, name=str(path))


def parse_asf(text: str, *, name: str = "<asf>") -> AsfSkeleton:
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    section = None
    units = {"length": 1.0, "angle": "deg"}
    root = {"order": ["TX", "TY", "TZ", "RX", "RY", "RZ"], "axis": "XYZ", "position": [0.0] * 3,
            "orientation": [0.0] * 3}
    bones: list[dict] = []
    bone = None
    hierarchy: list[tuple[int, list[str]]] = []
    in_hier = False
    skel_name = Path(name).stem
    seen_sections = set()

    def err(msg, lineno):
        return InputError(f"{name}: line {lineno}: {msg}")

    for lineno, raw in enumerate(lines, 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        toks = line.split()
        if toks[0].startswith(":"):
            section = toks[0][1:].lower()
            seen_sections.add(section)
            if section == "name" and len(toks) > 1:
                skel_name = " ".join(toks[1:])
            if section == "units" and len(toks) > 1:   # ":units" with values on the same line
                toks = toks[1:]
            else:
                continue
        key = toks[0].lower()
        if section == "units":
            if key == "length" and len(toks) > 1:
                units["length"] = _num(toks[1], "the length unit", err, lineno)
                if not units["length"] > 0:
                    raise err(f"':units length {toks[1]}' must be positive", lineno)
            elif key == "angle" and len(toks) > 1:
                if toks[1].lower() not in ("deg", "rad"):
                    raise err(f"unknown angle unit {toks[1]!r}; ASF files use 'deg' or 'rad'", lineno)
                units["angle"] = toks[1].lower()
        elif section == "root":
            if key == "order":
                root["order"] = [t.upper() for t in toks[1:]]
                bad = [t for t in root["order"] if t not in ("TX", "TY", "TZ", "RX", "RY", "RZ")]
                if bad or len(set(root["order"])) != len(root["order"]):
                    raise err(f"root order {' '.join(toks[1:])!r}: use each of TX TY TZ RX RY RZ at most once", lineno)
            elif key == "axis" and len(toks) > 1:
                root["axis"] = _axis_order(toks[1], err, lineno)
            elif key in ("position", "orientation"):
                root[key] = [_num(t, f"root {key}", err, lineno) for t in toks[1:4]]
                if len(root[key]) != 3:
                    raise err(f"root {key} needs three numbers", lineno)
        elif section == "bonedata":
            if key == "begin":
                if bone is not None:
                    raise err("'begin' inside a bone; a previous bone lacks its 'end'", lineno)
                bone = {"line": lineno, "dof": (), "axis": ([0.0] * 3, "XYZ"), "direction": None, "length": None}
            elif key == "end":
                if bone is None:
                    raise err("'end' without 'begin'", lineno)
                _finish_bone(bone, err)
                bones.append(bone)
                if len(bones) > MAX_BONES:
                    raise err(f"more than {MAX_BONES} bones: the file is corrupt or not a body", lineno)
                bone = None
            elif bone is None:
                raise err(f"{toks[0]!r} outside a begin ... end bone block", lineno)
            elif key == "name" and len(toks) > 1:
                bone["name"] = toks[1]
            elif key == "direction":
                bone["direction"] = [_num(t, "a direction", err, lineno) for t in toks[1:4]]
                if len(bone["direction"]) != 3:
                    raise err("direction needs three numbers", lineno)
            elif key == "length" and len(toks) > 1:
                bone["length"] = _num(toks[1], "the bone length", err, lineno)
                if bone["length"] < 0:
                    raise err(f"negative bone length {toks[1]}", lineno)
            elif key == "axis":
                if len(toks) != 5:
                    raise err("axis needs three angles and an order, e.g. 'axis 0 0 20 XYZ'", lineno)
                bone["axis"] = ([_num(t, "an axis angle", err, lineno) for t in toks[1:4]],
                                _axis_order(toks[4], err, lineno))
            elif key == "dof":
                dof = tuple(t.lower() for t in toks[1:])
                bad = [d for d in dof if d not in ROT_DOFS + ("tx", "ty", "tz", "l")]
                if bad or len(set(dof)) != len(dof):
                    raise err(f"dof {' '.join(toks[1:])!r}: use each of rx ry rz (tx ty tz l) at most once", lineno)
                bone["dof"] = dof
            # id, limits and the limit lines "(a b)", bodymass, cofmass: not needed
        elif section == "hierarchy":
            if key == "begin":
                in_hier = True
            elif key == "end":
                in_hier = False
            elif in_hier:
                hierarchy.append((lineno, toks))
    if bone is not None:
        raise InputError(f"{name}: the bone opened on line {bone['line']} has no 'end'; the file is truncated")
    for need in ("bonedata", "hierarchy"):
        if need not in seen_sections:
            raise InputError(f"{name}: no :{need} section; not an Acclaim ASF skeleton (or truncated)")
    if not hierarchy:
        raise InputError(f"{name}: the :hierarchy section is empty; it lists 'parent child ...' lines")
    return _assemble(name, skel_name, units, root, bones, hierarchy)


def _finish_bone(bone: dict, err) -> None:
    if "name" not in bone:
        raise err("a bone has no name", bone["line"])
    if bone["direction"] is None or bone["length"] is None:
        raise err(f"bone {bone['name']!r} needs a direction and a length", bone["line"])
    extra = [d for d in bone["dof"] if d not in ROT_DOFS]
    if extra:
        raise err(f"bone {bone['name']!r} animates {' '.join(extra)}: only rotation dofs (rx ry rz) are "
                  "supported on bones other than the root", bone["line"])


def _assemble(name, skel_name, units, root, bones, hierarchy) -> AsfSkeleton:
    by_name = {}
    for b in bones:
        if b["name"] in by_name or b["name"] == "root":
            raise InputError(f"{name}: line {b['line']}: bone name {b['name']!r} is used twice")
        by_name[b["name"]] = b
    children: dict[str, list[str]] = {}
    parent_of: dict[str, str] = {}
    for lineno, toks in hierarchy:
        p = toks[0]
        if p != "root" and p not in by_name:
            raise InputError(f"{name}: line {lineno}: the hierarchy names {p!r}, which :bonedata does not define")
        for c in toks[1:]:
            if c not in by_name:
                raise InputError(f"{name}: line {lineno}: the hierarchy names {c!r}, which :bonedata does not define")
            if c in parent_of:
                raise InputError(f"{name}: line {lineno}: bone {c!r} has two parents ({parent_of[c]!r} and {p!r})")
            parent_of[c] = p
            children.setdefault(p, []).append(c)
    # Depth first from the root, as a BVH file lists joints (parents before children).
    order, parents = ["root"], [-1]
    stack = [(c, 0) for c in reversed(children.get("root", []))]
    while stack:
        b, p = stack.pop()
        if len(order) > MAX_BONES:
            raise InputError(f"{name}: the hierarchy loops or has more than {MAX_BONES} bones")
        order.append(b)
        parents.append(p)
        stack.extend((c, len(order) - 1) for c in reversed(children.get(b, [])))
    unreached = [b for b in by_name if b not in order]
    if unreached:
        raise InputError(f"{name}: bones {', '.join(unreached[:5])} do not hang below the root in :hierarchy "
                         "(a loop, or a missing parent line)")
    deg = units["angle"] == "deg"
    n = len(order)
    directions, lengths, axes, dofs = np.zeros((n, 3)), np.zeros(n), [], []
    root_axis = _euler(root["axis"], root["orientation"], deg)
    root_dofs = tuple(t.lower() for t in root["order"])
    for j, b in enumerate(order):
        if j == 0:
            axes.append(root_axis)
            dofs.append(root_dofs)
            continue
        info = by_name[b]
        d = np.array(info["direction"], dtype=np.float64)
        norm = np.linalg.norm(d)
        if norm < 1e-12 and info["length"] > 0:
            raise InputError(f"{name}: line {info['line']}: bone {b!r} has a zero direction")
        directions[j] = d / norm if norm >= 1e-12 else d
        lengths[j] = info["length"]
        angles, ax_order = info["axis"]
        axes.append(_euler(ax_order, angles, deg))
        dofs.append(info["dof"])
    return AsfSkeleton(skel_name, order, parents, directions, lengths, axes, dofs, float(units["length"]), deg,
                       np.array(root["position"], dtype=np.float64), name)


def _axis_order(tok: str, err, lineno) -> str:
    order = tok.upper()
    if len(order) != 3 or sorted(order) != ["X", "Y", "Z"]:
        raise err(f"axis order {tok!r} must be a permutation of XYZ", lineno)
    return order


def _euler(order: str, angles_xyz, deg: bool) -> Rotation:
    """Rotation from angles given about X, Y, Z, applied in ``order`` (first letter first)."""
    by_axis = dict(zip("XYZ", angles_xyz))
    return Rotation.from_euler(order.lower(), [by_axis[a] for a in order], degrees=deg)


def _num(tok: str, what: str, err, lineno) -> float:
    try:
        v = float(tok)
    except ValueError:
        raise err(f"expected a number for {what}, found {tok[:40]!r}", lineno) from None
    if not (math.isfinite(v) and abs(v) <= MAX_VALUE):
        raise err(f"{what} is {tok[:40]}; numbers must be finite and within ±{MAX_VALUE:g}", lineno)
    return v


def read_text(path: Path, limit: int, what: str) -> str:
    """An ASF or AMC file's text, at most ``limit`` bytes; ``InputError`` for an empty or binary file."""
    data = read_user_file(path, limit=limit, what=f"{what} file {path}")
    return decode_text(data, empty=f"{path}: the file is empty",
                       binary=f"{path}: not an {what} file (it looks binary); ASF and AMC are text")

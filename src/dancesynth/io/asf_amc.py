"""Acclaim ASF/AMC motion capture (CMU's original release) read into a ``MotionClip``.

An ``.asf`` file holds the skeleton: ``:units`` (``length 0.45`` is CMU's), ``:root``
(channel ``order``, ``axis`` order, rest ``position``/``orientation``), ``:bonedata``
(per bone a world-space ``direction``, a ``length``, an ``axis`` -- three angles and the
order they are applied in -- and the ``dof`` that the motion file animates) and
``:hierarchy`` (``parent child child ...``). An ``.amc`` file holds the frames: a frame
number on its own line, then one ``bone value value ...`` line per animated bone.

The Acclaim transform (as CMU's viewer and the common parsers apply it): a bone's rest
frame is ``C`` (its axis angles); a frame's dof angles make ``M``; in world-aligned rest
frames the bone's local rotation is ``L = C M C^-1`` and the bone's end is its start plus
``(rotations of the chain) * direction * length``. So each bone becomes a joint at its start
(its parent bone's end) with rotation ``L``; its children sit ``direction * length`` from
it; the identity pose is the ASF rest pose. Euler angles follow the listed order, first
listed applied first (``axis 0 0 20 XYZ`` is ``Rz(20) Ry(0) Rx(0)``; ``dof rx ry rz`` is
``Rz Ry Rx``), the convention of CMU's own ``amc`` viewer.

Lengths: CMU writes inches divided by ``:units length`` (CMU's FAQ: metres = value *
(1/0.45) * 2.54/100 = 0.056444); ``units=`` overrides. CMU's world is Y up and the
skeleton faces +Z, as dancesynth's. CMU bone names (``lfemur``, ``ltibia``, ...) become
the names of CMU's BVH conversions (``LeftUpLeg``, ``LeftLeg``, ...) that the humanoid
finders read; ``meta["asf_names"]`` keeps the originals.

AMC files state no frame rate: CMU captured at 120 fps, except the subjects its trial
table lists at 60 fps (``CMU_60FPS_SUBJECTS``); ``cmu_fps_fix`` applies that table.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError
from .files import read_user_file
from ..types import MotionClip, Skeleton
from .skeleton_units import resolve_units

__all__ = ["read_amc", "read_asf", "find_asf", "cmu_fps_fix", "cmu_subject_trial", "AsfSkeleton",
           "CMU_FPS", "CMU_60FPS_SUBJECTS", "CMU_BVH_NAMES"]

CMU_FPS = 120.0
# Subjects CMU's trial table lists at 60 fps (every trial), and single trials of other
# subjects. Source: the per-trial frame-rate column of CMU's table, as reproduced in
# DragonForgedTheArtist/IClone-CMU-Mocap "CMU data.csv"; for 60 and 61 the motion confirms it
# (salsa steps at 1.8 steps/s at 60 fps, 3.6 at 120).
CMU_60FPS_SUBJECTS = frozenset({33, 34, 42, 60, 61, 62, 74, 75, 77, 79, 80, 87, 88, 89})
CMU_60FPS_TRIALS = frozenset({(136, 19)})   # subject 136 is at 120 fps but for this one trial

# CMU's ASF bone names -> the joint names of CMU's BVH conversions (cgspeed's
# MotionBuilder-friendly release, the layout of dancesynth's built-in "cmu" rig).
CMU_BVH_NAMES = {"root": "Hips", "lowerback": "LowerBack", "upperback": "Spine", "thorax": "Spine1",
                 "lowerneck": "Neck", "upperneck": "Neck1", "head": "Head"}
for _s, _side in (("l", "Left"), ("r", "Right")):
    CMU_BVH_NAMES.update({f"{_s}hipjoint": f"{_s.upper()}HipJoint", f"{_s}femur": f"{_side}UpLeg",
                          f"{_s}tibia": f"{_side}Leg", f"{_s}foot": f"{_side}Foot", f"{_s}toes": f"{_side}ToeBase",
                          f"{_s}clavicle": f"{_side}Shoulder", f"{_s}humerus": f"{_side}Arm",
                          f"{_s}radius": f"{_side}ForeArm", f"{_s}wrist": f"{_side}Hand",
                          f"{_s}hand": f"{_side}FingerBase", f"{_s}fingers": f"{_side}HandIndex1",
                          f"{_s}thumb": f"{_s.upper()}Thumb"})

MAX_ASF_BYTES = 2_000_000        # CMU's are ~10 kB
MAX_AMC_BYTES = 200_000_000      # CMU's longest are ~30 MB
MAX_BONES = 500
MAX_VALUE = 1e6                  # any length, position or angle in the files
ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
JOINT_CHANNELS = ("Zrotation", "Yrotation", "Xrotation")   # the channels CMU's BVH conversions write
_ROT_DOFS = ("rx", "ry", "rz")
_CMU_NAME = re.compile(r"^0*(\d{1,3})_0*(\d{1,3})(?:$|[_\-. ])")


# --------------------------------------------------------------------------- CMU naming


def cmu_subject_trial(path) -> tuple[int, int] | None:
    """CMU subject and trial from a file name like ``60_01.bvh``, ``05_11.amc``, ``55_01_cmu.bvh``."""
    m = _CMU_NAME.match(Path(str(path)).name)
    return (int(m.group(1)), int(m.group(2))) if m else None


def cmu_fps_fix(path, fps: float) -> float:
    """The frame rate CMU lists for a CMU trial that a converter labelled 120 fps.

    cgspeed's BVH conversion writes ``Frame Time: 0.008333`` (120 fps) into every file, but
    CMU's trial table lists subjects 60 and 61 (salsa) and a few others at 60 fps: for files
    named after such a trial (``60_01.bvh``) and stated at 120 fps this returns 60; any other
    file keeps ``fps``.
    """
    st = cmu_subject_trial(path)
    if st is None or abs(float(fps) - CMU_FPS) > 0.5:
        return fps
    if st[0] in CMU_60FPS_SUBJECTS or st in CMU_60FPS_TRIALS:
        return 60.0
    return fps


# --------------------------------------------------------------------------- ASF


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
    text = _read_text(path, MAX_ASF_BYTES, "ASF skeleton")
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
                bad = [d for d in dof if d not in _ROT_DOFS + ("tx", "ty", "tz", "l")]
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
    extra = [d for d in bone["dof"] if d not in _ROT_DOFS]
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


# --------------------------------------------------------------------------- AMC


def find_asf(amc_path) -> Path:
    """The skeleton of an AMC file: ``<subject>.asf`` beside ``<subject>_<trial>.amc``, or the only .asf there."""
    amc_path = Path(amc_path)
    folder = amc_path.parent
    subject = amc_path.stem.split("_")[0]
    for cand in (folder / f"{subject}.asf", folder / f"{subject}.ASF"):
        if cand.is_file():
            return cand
    asfs = sorted(p for p in folder.glob("*") if p.suffix.lower() == ".asf" and p.is_file()) if folder.is_dir() else []
    if len(asfs) == 1:
        return asfs[0]
    found = f"{len(asfs)} .asf files ({', '.join(p.name for p in asfs[:4])})" if asfs else "no .asf file"
    raise InputError(f"{amc_path}: cannot find its skeleton: expected {subject}.asf beside it, found {found}; "
                     "put the subject's .asf file in the same folder")


def read_amc(path, asf=None, *, fps: float | None = None, units=None) -> MotionClip:
    """Read an Acclaim ``.amc`` motion with its ``.asf`` skeleton into a ``MotionClip`` in metres.

    ``asf``: a path or an ``AsfSkeleton``; by default found beside the AMC (``find_asf``).
    ``fps``: the capture rate (AMC files do not say); by default CMU's, 120 fps or 60 for the
    subjects CMU lists at 60 (``cmu_fps_fix``). ``units``: metres per ASF length unit (a number
    or a ``UNITS`` name), overriding the ASF's ``:units length`` (inches / length).
    """
    path = Path(path)
    if not isinstance(asf, AsfSkeleton):
        asf = read_asf(find_asf(path) if asf is None else asf)
    text = _read_text(path, MAX_AMC_BYTES, "AMC motion")
    frame_numbers, values, angle_deg = _parse_amc(text, str(path), asf)
    if fps is None:
        fps = cmu_fps_fix(path, CMU_FPS)
    if not (isinstance(fps, (int, float)) and math.isfinite(fps) and 1.0 <= fps <= 1000.0):
        raise InputError(f"{path}: fps={fps!r}; give the capture rate in frames per second (1 to 1000)")
    if units is None:
        unit_name, scale = f"inches/{asf.length_unit:g}", 0.0254 / asf.length_unit
    else:
        unit_name, scale = resolve_units(units, str(path))
    return _build_clip(asf, values, angle_deg, scale, float(fps), path, unit_name, frame_numbers)


def _parse_amc(text: str, name: str, asf: AsfSkeleton):
    """(frame numbers, per-joint value arrays (F, n_dof), angles in degrees?) of an AMC text."""
    index = {b: j for j, b in enumerate(asf.names)}
    animated = [j for j in range(asf.n_joints) if asf.dofs[j]]
    rows: dict[int, list] = {j: [] for j in animated}
    frames: list[int] = []
    angle_deg = asf.angle_deg
    current: set | None = None
    last_line = 0

    def close_frame(lineno):
        if current is not None and len(current) != len(animated):
            missing = [asf.names[j] for j in animated if j not in current]
            raise InputError(f"{name}: line {lineno}: frame {frames[-1]} lacks bones {', '.join(missing[:5])}; "
                             "the file is truncated, or it was written for another skeleton")

    for lineno, raw in enumerate(text.split("\n"), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        last_line = lineno
        if line.startswith(":"):
            if frames:
                raise InputError(f"{name}: line {lineno}: header {line[:40]!r} after the first frame")
            key = line.split()[0].upper()
            if key == ":DEGREES":
                angle_deg = True
            elif key == ":RADIANS":
                angle_deg = False
            continue
        toks = line.split()
        if len(toks) == 1 and toks[0].isdigit():
            close_frame(lineno)
            number = int(toks[0])
            if frames and number != frames[-1] + 1:
                raise InputError(f"{name}: line {lineno}: frame {number} follows frame {frames[-1]}; frames must be "
                                 "numbered one after another (a frame is missing or the file is garbled)")
            frames.append(number)
            current = set()
            continue
        if current is None:
            raise InputError(f"{name}: line {lineno}: {toks[0][:40]!r} before the first frame number; not an AMC "
                             "motion file (an AMC file lists ':FULLY-SPECIFIED', ':DEGREES', then numbered frames)")
        j = index.get(toks[0])
        if j is None:
            raise InputError(f"{name}: line {lineno}: bone {toks[0][:40]!r} is not in the skeleton {asf.source}; "
                             "is this the right .asf file?")
        if j in current:
            raise InputError(f"{name}: line {lineno}: bone {toks[0]!r} appears twice in frame {frames[-1]}")
        n_dof = len(asf.dofs[j])
        if len(toks) - 1 != n_dof:
            raise InputError(f"{name}: line {lineno}: bone {toks[0]!r} has {len(toks) - 1} values, its dof line "
                             f"in the ASF declares {n_dof} ({' '.join(asf.dofs[j]) or 'none'})")
        try:
            vals = [float(t) for t in toks[1:]]
        except ValueError:
            bad = next(t for t in toks[1:] if not _is_float(t))
            raise InputError(f"{name}: line {lineno}: {bad[:40]!r} is not a number") from None
        if not all(math.isfinite(v) and abs(v) <= MAX_VALUE for v in vals):
            raise InputError(f"{name}: line {lineno}: values must be finite numbers within ±{MAX_VALUE:g}")
        rows[j].append(vals)
        current.add(j)
    if not frames:
        raise InputError(f"{name}: no frames; an AMC file lists numbered frames (the file is empty or truncated)")
    close_frame(last_line)
    values = {j: np.array(rows[j], dtype=np.float64).reshape(len(frames), len(asf.dofs[j])) for j in animated}
    return frames, values, angle_deg


def _is_float(tok: str) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


def _build_clip(asf: AsfSkeleton, values, angle_deg: bool, scale: float, fps: float, path: Path,
                unit_name: str, frame_numbers) -> MotionClip:
    n_f, n_j = len(frame_numbers), asf.n_joints
    local_rot = np.zeros((n_f, n_j, 4))
    local_rot[..., 3] = 1.0
    root_pos = np.repeat(asf.root_position[None] * scale, n_f, axis=0)
    for j in range(n_j):
        dofs = asf.dofs[j]
        if not dofs:
            continue
        v = values[j]
        rot_cols = [k for k, d in enumerate(dofs) if d in _ROT_DOFS]
        if j == 0:  # the root's translation channels are absolute positions
            for k, d in enumerate(dofs):
                if d in ("tx", "ty", "tz"):
                    root_pos[:, "xyz".index(d[1])] = v[:, k] * scale
        if not rot_cols:
            continue
        axes = "".join(dofs[k][1] for k in rot_cols)          # e.g. "xyz": first listed applied first
        m = Rotation.from_euler(axes, v[:, rot_cols], degrees=angle_deg)
        c = asf.axes[j]
        local_rot[:, j] = (c * m * c.inv()).as_quat()          # L = C M C^-1, scalar last (x, y, z, w)
    # A joint sits at its bone's start, i.e. its parent bone's end: direction * length of the parent.
    parents = np.array(asf.parents)
    bone_vec = asf.directions * asf.lengths[:, None] * scale
    offsets = np.zeros((n_j, 3))
    offsets[1:] = bone_vec[parents[1:]]      # the root has no length: its children start at it
    end_sites = {j: bone_vec[j].copy() for j in range(1, n_j) if not np.any(parents == j)}
    names = tuple(CMU_BVH_NAMES.get(b, b) for b in asf.names)
    if len(set(names)) != n_j:
        names = tuple(asf.names)     # a skeleton mixing both spellings keeps its own
    channels = tuple(ROOT_CHANNELS if j == 0 else JOINT_CHANNELS for j in range(n_j))
    skeleton = Skeleton(names, parents, offsets, channels, end_sites)
    clip = MotionClip(skeleton, fps, root_pos, local_rot)
    clip.meta.update({
        "name": path.stem,
        "source": str(path),
        "source_format": "asf/amc",
        "skeleton_source": asf.source,
        "asf_names": tuple(asf.names),
        "source_units": unit_name,
        "metres_per_unit": scale,
        "in_metres": True,
        "dropped_tpose": False,
        "first_frame_number": int(frame_numbers[0]),
    })
    return clip


def _read_text(path: Path, limit: int, what: str) -> str:
    data = read_user_file(path, limit=limit, what=f"{what} file {path}")
    if not data.strip():
        raise InputError(f"{path}: the file is empty")
    if b"\x00" in data[:65536]:
        raise InputError(f"{path}: not an {what} file (it looks binary); ASF and AMC are text")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return data.decode("latin-1")

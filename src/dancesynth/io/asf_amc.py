"""Acclaim ASF/AMC motion capture (CMU's original release) read into a ``MotionClip``.

An ``.asf`` file (read by ``io.asf``) holds the skeleton: ``:units`` (``length 0.45`` is CMU's), ``:root``
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
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError
from ..types import MotionClip, Skeleton
from .asf import MAX_VALUE, ROT_DOFS, AsfSkeleton, read_asf, read_text
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

MAX_AMC_BYTES = 200_000_000      # CMU's longest are ~30 MB
ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
JOINT_CHANNELS = ("Zrotation", "Yrotation", "Xrotation")   # the channels CMU's BVH conversions write
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
    text = read_text(path, MAX_AMC_BYTES, "AMC motion")
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
        rot_cols = [k for k, d in enumerate(dofs) if d in ROT_DOFS]
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


"""AIST++ dance motion (``motions/*.pkl``) read onto dancesynth's built-in ``smpl`` rig.

Each AIST++ motion file is a pickled dict (layout from the AIST++ API, google/aistplusplus_api
``loader.py`` and ``processing/run_estimate_smpl.py``, and the dataset's download page):

- ``smpl_poses``   (N, 72) -- or (N, 24, 3) -- axis-angle rotation of SMPL's 24 joints, in
  SMPL's joint order, radians; joint 0 (the pelvis) is the global orientation;
- ``smpl_trans``   (N, 3) root translation, in the capture's units (cm) times the body scale;
- ``smpl_scaling`` (1,) that body scale (the fitted SMPL body was scaled by it);
- ``smpl_loss``    the fitting loss (ignored).

Frames are at exactly 60 fps. The API's SMPL model computes ``joints * scaling + transl``,
so ``smpl_trans / smpl_scaling`` is the root's path at SMPL's own size, in metres (the API's
demo does exactly this). The world is Y up (as EDGE's loader notes), SMPL's rest pose a
T-pose facing +Z with the left side towards +X -- the pose of dancesynth's ``smpl`` rig, so
the axis-angles are the rig's local rotations unchanged. No SMPL model file is needed: the
rig's rest offsets (dancesynth's canonical 1.74 m body) stand in for the fitted body shape,
and the clip is put on the floor (its lowest joints at the rig's rest height), since the
capture's floor height is not in the file.

A pickle can run code when loaded, so the file is read with an unpickler that can build
numpy arrays and nothing else: any other class or function in the file is refused with an
``InputError`` before it can be called.
"""

from __future__ import annotations

import io
import math
import pickle
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from .. import kinematics
from ..errors import InputError
from .files import read_user_file
from ..retarget.rigs import rig_skeleton
from ..types import MotionClip, Skeleton

try:  # numpy >= 2 keeps these in numpy._core; pickles written by numpy 1 name numpy.core
    from numpy._core import multiarray as _multiarray
    from numpy._core import numeric as _numeric
except ImportError:  # pragma: no cover - numpy 1
    from numpy.core import multiarray as _multiarray
    from numpy.core import numeric as _numeric

__all__ = ["read_aist", "load_pickle_arrays", "AIST_FPS", "SMPL_JOINTS", "MAX_PICKLE_BYTES"]

AIST_FPS = 60.0                      # "frame-by-frame under exact 60 FPS" (AIST++ download page)
MAX_PICKLE_BYTES = 64_000_000        # the longest AIST++ motion (48 s) is ~1 MB
SMPL_JOINTS = 24
FLOOR_PERCENTILE = 5.0               # frame-wise lowest joint: its 5th percentile is the floor (jumps lift it)


# --------------------------------------------------------------------------- a pickle that only holds arrays


def _reconstruct(cls, shape, dtype):
    # numpy pickles an array as _reconstruct(ndarray, (0,), b'b') plus its state; any other
    # call (a subclass, or a huge shape that would allocate before any data is read) is refused.
    if cls is not np.ndarray or tuple(shape) != (0,):
        raise InputError("the pickle builds an array in a way numpy never writes; refused")
    return _multiarray._reconstruct(cls, shape, dtype)


def _latin1_encode(text, encoding="latin1"):
    # Protocol-2 pickles store bytes as _codecs.encode(str, "latin1"); no other codec is needed.
    if not isinstance(text, str) or str(encoding).lower().replace("-", "") != "latin1":
        raise InputError("the pickle calls _codecs.encode in a way numpy never writes; refused")
    return text.encode("latin1")


_ALLOWED = {}
for _mod in ("numpy.core", "numpy._core"):
    _ALLOWED[(f"{_mod}.multiarray", "_reconstruct")] = _reconstruct
    _ALLOWED[(f"{_mod}.multiarray", "scalar")] = _multiarray.scalar
    _ALLOWED[(f"{_mod}.numeric", "_frombuffer")] = _numeric._frombuffer
_ALLOWED.update({("numpy", "ndarray"): np.ndarray, ("numpy", "dtype"): np.dtype,
                 ("_codecs", "encode"): _latin1_encode})


class _ArraysOnly(pickle.Unpickler):
    """An unpickler for dicts, lists, numbers, strings and numpy arrays; every other global is refused."""

    def find_class(self, module, name):
        try:
            return _ALLOWED[(module, name)]
        except KeyError:
            raise InputError(f"the pickle asks for {module}.{name}; a motion file holds only numpy arrays, "
                             "so it was refused unread (the file is not an AIST++ motion, or it was tampered "
                             "with)") from None

    def persistent_load(self, pid):
        raise InputError("the pickle refers to external objects (persistent ids); refused")


def load_pickle_arrays(path, *, max_bytes: int = MAX_PICKLE_BYTES):
    """Load a pickle that may hold only containers, numbers, strings and numpy arrays.

    Raises ``InputError`` for a missing, oversized, truncated or corrupt file, and for a
    pickle that names any class or function other than numpy's array builders (``os.system``
    and the like are refused before anything is called).
    """
    path = Path(path)
    data = read_user_file(path, limit=max_bytes, what=f"motion pickle {path}")
    if not data:
        raise InputError(f"{path}: the file is empty")
    try:
        return _ArraysOnly(io.BytesIO(data), encoding="latin1").load()
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None
    except Exception as exc:   # a damaged pickle raises any of a dozen exception types
        raise InputError(f"{path}: not a readable pickle ({type(exc).__name__}: {str(exc)[:80]}); the file is "
                         "truncated or corrupt, download it again") from None


# --------------------------------------------------------------------------- AIST++ motion


def read_aist(path, *, fps: float = AIST_FPS, on_floor: bool = True) -> MotionClip:
    """Read an AIST++ motion ``.pkl`` into a ``MotionClip`` on the ``smpl`` rig, metres, Y up.

    ``on_floor`` lifts or lowers the whole clip so its lowest joints stand at the rig's rest
    height (``meta["floor_shift_m"]`` says by how much). ``clip.meta`` also records
    ``smpl_scaling`` and the usual ``name``/``source``.
    """
    path = Path(path)
    data = load_pickle_arrays(path)
    poses, trans, scale = _motion_arrays(data, str(path))
    n = poses.shape[0]
    local_rot = Rotation.from_rotvec(poses.reshape(-1, 3)).as_quat().reshape(n, SMPL_JOINTS, 4)
    root_pos = trans / scale

    rig, _ = rig_skeleton("smpl")
    rest_root = rig.offsets[0].copy()
    offsets = rig.offsets.copy()
    offsets[0] = 0.0   # as read_bvh: the root's place is all in root_pos
    skeleton = Skeleton(rig.names, rig.parents, offsets, rig.channels, dict(rig.end_sites))
    shift = 0.0
    if on_floor:
        _, g_pos = kinematics.fk(local_rot, root_pos, offsets, skeleton.parents)
        floor = float(np.percentile(g_pos[..., 1].min(axis=1), FLOOR_PERCENTILE))
        _, rest = kinematics.fk(np.tile([0.0, 0.0, 0.0, 1.0], (SMPL_JOINTS, 1)), rest_root, offsets,
                                skeleton.parents)
        shift = float(rest[:, 1].min()) - floor
        root_pos = root_pos + np.array([0.0, shift, 0.0])
    clip = MotionClip(skeleton, float(fps), root_pos, local_rot)
    clip.meta.update({
        "name": path.stem,
        "source": str(path),
        "source_format": "aist++",
        "rig": "smpl",
        "smpl_scaling": float(scale),
        "source_units": "smpl_trans / smpl_scaling",
        "metres_per_unit": 1.0 / float(scale),
        "in_metres": True,
        "dropped_tpose": False,
        "floor_shift_m": shift,
    })
    return clip


def _motion_arrays(data, name: str):
    """(poses (N, 24, 3), trans (N, 3), scale) from an AIST++ motion dict, checked."""
    if not isinstance(data, dict):
        raise InputError(f"{name}: holds a {type(data).__name__}, not an AIST++ motion (a dict with smpl_poses, "
                         "smpl_trans, smpl_scaling)")
    missing = [k for k in ("smpl_poses", "smpl_trans", "smpl_scaling") if k not in data]
    if missing:
        keys = ", ".join(sorted(map(str, data))[:8]) or "none"
        hint = (" -- it is a keypoints file; AIST++ motions are the files in motions/"
                if any(str(k).startswith("keypoints") for k in data) else "")
        raise InputError(f"{name}: no {', '.join(missing)} (keys: {keys}){hint}")
    poses = _numeric_array(data["smpl_poses"], "smpl_poses", name)
    trans = _numeric_array(data["smpl_trans"], "smpl_trans", name)
    scale = _numeric_array(data["smpl_scaling"], "smpl_scaling", name).reshape(-1)
    if poses.ndim == 2 and poses.shape[1] == SMPL_JOINTS * 3:
        poses = poses.reshape(-1, SMPL_JOINTS, 3)
    if poses.ndim != 3 or poses.shape[1:] != (SMPL_JOINTS, 3) or poses.shape[0] == 0:
        raise InputError(f"{name}: smpl_poses has shape {poses.shape}; AIST++ stores (frames, 72) axis-angles")
    if trans.shape != (poses.shape[0], 3):
        raise InputError(f"{name}: smpl_trans has shape {trans.shape}, smpl_poses {poses.shape[0]} frames; "
                         "they must agree (frames, 3)")
    if scale.size != 1 or not (math.isfinite(scale[0]) and scale[0] > 0):
        raise InputError(f"{name}: smpl_scaling must be one positive number, got {scale[:3]}")
    if not (np.all(np.isfinite(poses)) and np.all(np.isfinite(trans))):
        raise InputError(f"{name}: smpl_poses or smpl_trans holds NaN or infinite values; the file is corrupt")
    if np.abs(poses).max() > 1e3 or np.abs(trans / scale[0]).max() > 1e4:
        raise InputError(f"{name}: smpl_poses or smpl_trans holds values no motion has; the file is corrupt")
    return poses, trans, float(scale[0])


def _numeric_array(value, key: str, name: str) -> np.ndarray:
    arr = np.asarray(value)
    if arr.dtype.kind not in "fiu":
        raise InputError(f"{name}: {key} is not a numeric array (dtype {arr.dtype}); the file is not an AIST++ motion")
    return arr.astype(np.float64)

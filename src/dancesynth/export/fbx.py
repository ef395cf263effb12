"""A dance as FBX, written by Blender: our ``.glb`` goes in, Blender's own FBX exporter writes the file.

FBX is a closed format with no free writer we could ship, so we run the ``blender`` program
(``DANCESYNTH_BLENDER`` names another one) headless on ``blender_fbx.py``, our script: it
imports the ``.glb`` with Blender's glTF importer and exports FBX for game engines, the way
Mixamo's own files are: Y up, the character facing +Z, centimetres (``UnitScaleFactor`` 1),
the armature node untransformed, joints in the rest pose, one take with a key on every
frame, no extra leaf bones. Unity (which scales centimetres by 0.01 on import) and Unreal
(which works in centimetres) both see a 1.7 m character as 1.7 m. We only run the program,
so Blender's GPL stays outside our package. Blender takes 1-2.5 s to start and about
1 ms a frame for a 22-joint rig.

A ``.glb`` with only a skeleton has no skin, and Blender's importer would make empties of
its joints, not bones; so before Blender sees it we add a skin over every joint, bound in
the skeleton's zero-rotation pose (a BVH rig's rest pose; the built-in rigs' T-pose), which
becomes the FBX rest pose. A ``.glb`` with a skinned mesh keeps its own skin.
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.files import atomic_path

BLENDER_ENV = "DANCESYNTH_BLENDER"
SCRIPT = Path(__file__).with_name("blender_fbx.py")
TIMEOUT_S = 120.0             # Blender's start-up and import (2-3 s here), with room for a slow machine
TIMEOUT_PER_KEY_S = 2e-4      # the exporter samples every bone on every frame: 70 us each here
ERROR_MARK = "dancesynth-fbx: "   # blender_fbx.py starts its own error lines with this
_END = "_end"                 # export.gltf names an End Site's leaf node <joint>_end: not a bone
_FLOAT, _MAT4 = 5126, "MAT4"


def write_fbx(path, glb: bytes, *, fps: float, name: str = "dance") -> Path:
    """Write the dance in ``glb`` (``export.gltf.glb_bytes``) to ``path`` as FBX, atomically."""
    path = Path(path)
    with atomic_path(path) as tmp:
        _export(glb, tmp, fps, name)
    return path


def fbx_bytes(glb: bytes, *, fps: float, name: str = "dance") -> bytes:
    """The dance in ``glb`` as the bytes of an FBX file; ``name`` names its take (the clip in Unity)."""
    with tempfile.TemporaryDirectory(prefix="dancesynth-fbx-") as folder:
        out = Path(folder) / "dance.fbx"
        _export(glb, out, fps, name)
        return out.read_bytes()


def find_blender() -> str:
    """The Blender program to run, or an ``InputError`` saying how to get one."""
    wanted = os.environ.get(BLENDER_ENV) or "blender"
    found = shutil.which(wanted)
    if found is None:
        where = f"{BLENDER_ENV}={wanted}" if os.environ.get(BLENDER_ENV) else "blender on PATH"
        raise InputError("writing .fbx needs Blender (apt-get install blender, or https://www.blender.org): "
                         f"{where} not found; write .glb instead")
    return found


def timeout_s(n_frames: int, n_joints: int) -> float:
    """How long Blender may take for a dance of ``n_frames`` on ``n_joints`` before we give up on it."""
    return TIMEOUT_S + TIMEOUT_PER_KEY_S * n_frames * n_joints


def _export(glb: bytes, out: Path, fps: float, name: str) -> None:
    """Run Blender on ``glb``, writing ``out``; any failure is one ``InputError`` line."""
    if not (math.isfinite(fps) and fps > 0):
        raise InputError(f"cannot write FBX at {fps} fps: the frame rate must be positive")
    blender = find_blender()
    name = name.strip() or "dance"
    glb, n_frames, n_joints = _skinned(glb, fps)
    with tempfile.TemporaryDirectory(prefix="dancesynth-fbx-") as folder:
        src = Path(folder) / "dance.glb"
        src.write_bytes(glb)
        # --python-exit-code: an exception in our script must fail the run, not end it with 0.
        command = [blender, "-b", "--factory-startup", "--python-exit-code", "3", "--python", str(SCRIPT), "--",
                   str(src), str(out), repr(float(fps)), str(n_frames), name]
        limit = timeout_s(n_frames, n_joints)
        try:
            proc = subprocess.run(command, capture_output=True, text=True, errors="replace", timeout=limit)
        except subprocess.TimeoutExpired:
            raise InputError(f"Blender did not write the FBX within {round(limit, 1):g} s (it was stopped); "
                             "write .glb instead") from None
        except OSError as exc:
            raise InputError(f"cannot run Blender ({blender}): {exc.strerror or exc}") from None
    if proc.returncode != 0 or not out.is_file() or out.stat().st_size == 0:
        raise InputError(f"Blender could not write the FBX (exit code {proc.returncode}): "
                         f"{_last_error(proc.stdout, proc.stderr)}")


def _last_error(stdout: str, stderr: str) -> str:
    """The line of Blender's output that says what went wrong: our script's own, else the last on stderr."""
    lines = [ln.strip() for ln in (stderr + "\n" + stdout).splitlines() if ln.strip()]
    ours = [ln[len(ERROR_MARK):] for ln in lines if ln.startswith(ERROR_MARK)]
    if ours:
        return ours[-1]
    err = [ln.strip() for ln in stderr.splitlines() if ln.strip()]
    return (err or lines or ["no output"])[-1]


def _skinned(glb: bytes, fps: float) -> tuple[bytes, int, int]:
    """``glb`` with a skin over its skeleton if it has none; the animation's frames; the skin's joints."""
    import pygltflib as g

    try:
        gltf = g.GLTF2.load_from_bytes(glb)
        blob = bytearray(gltf.binary_blob() or b"")
    except Exception as exc:  # pygltflib raises anything on a damaged file
        raise InputError(f"cannot write FBX: the glTF given is not readable ({type(exc).__name__}: {exc})") from None
    n_frames = _frames(gltf, fps)
    if gltf.skins:
        return glb, n_frames, max(len(skin.joints) for skin in gltf.skins)
    joints = _joints(gltf)
    if not joints:
        raise InputError("cannot write FBX: the glTF has no skeleton")
    inverse_bind = np.linalg.inv(_rest_world(gltf, joints))
    blob.extend(b"\0" * (-len(blob) % 4))
    # glTF matrices are column-major: each 4x4 is written transposed.
    data = np.ascontiguousarray(inverse_bind.transpose(0, 2, 1), dtype=np.float32).tobytes()
    gltf.bufferViews.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data)))
    blob.extend(data)
    gltf.accessors.append(g.Accessor(bufferView=len(gltf.bufferViews) - 1, componentType=_FLOAT,
                                     count=len(joints), type=_MAT4))
    gltf.skins = [g.Skin(name="Armature", joints=joints, skeleton=joints[0],
                         inverseBindMatrices=len(gltf.accessors) - 1)]
    gltf.buffers[0].byteLength = len(blob)
    gltf.set_binary_blob(bytes(blob))
    return b"".join(gltf.save_to_bytes()), n_frames, len(joints)


def _frames(gltf, fps: float) -> int:
    """Frames in the first animation: its last key time at ``fps``, plus the frame at time 0."""
    # glTF requires every key-time accessor to state its max: no need to read the times.
    ends = [gltf.accessors[s.input].max for s in gltf.animations[0].samplers] if gltf.animations else []
    if not ends or any(not e for e in ends):
        raise InputError("cannot write FBX: the glTF has no animation with key times")
    return int(round(max(e[0] for e in ends) * fps)) + 1


def _joints(gltf) -> list[int]:
    """The scene's nodes that are skeleton joints, in node order: not meshes, not End Site leaves."""
    nodes = gltf.nodes
    joints, todo = [], list(gltf.scenes[gltf.scene or 0].nodes)
    while todo:
        i = todo.pop()
        children = nodes[i].children or []
        end_site = not children and (nodes[i].name or "").endswith(_END)
        if nodes[i].mesh is None and not end_site:
            joints.append(i)
        todo.extend(children)
    return sorted(joints)


def _rest_world(gltf, joints: list[int]) -> np.ndarray:
    """Each joint's world matrix (J, 4, 4) with every rotation zero: its nodes' translations only."""
    parent = {c: i for i, n in enumerate(gltf.nodes) for c in (n.children or [])}

    def world(i: int) -> np.ndarray:
        m = np.eye(4)
        m[:3, 3] = gltf.nodes[i].translation or (0.0, 0.0, 0.0)
        return world(parent[i]) @ m if i in parent else m

    return np.array([world(i) for i in joints])

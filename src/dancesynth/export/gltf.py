"""A dance as glTF 2.0 binary (``.glb``): its skeleton as a node hierarchy, its motion as one animation,
and, when given, the character's skinned mesh.

glTF is Y-up, in metres, with quaternions in (x, y, z, w) order: our own conventions
(DESIGN.md), so nothing is converted. Each joint is a node placed at its BVH offset and
rotated by its local rotation; the root's translation follows the dance; an End Site
becomes a leaf node so the last bone of a chain has its length. Joints that never turn
get no animation channel. Tools that retarget an animated skeleton (Blender, three.js,
Unity) read it as it is.

A ``Mesh`` (``retarget.character``) becomes a skinned mesh: a node beside the skeleton's
root at the scene's top (glTF ignores a skinned mesh node's own transform, and the
validator wants it at the root), a skin whose joints are the joint nodes, and inverse bind
matrices from the character's rest pose (its rest rotations at its rest root position),
the pose the mesh was modelled in. Its vertex colours tint a plain, slightly rough white
material. Written with pygltflib.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError
from ..io.files import atomic_path
from ..kinematics import fk
from ..types import MotionClip

_STILL = 1e-7              # a joint whose rotation changes less than this never turns
_COMPONENT = {np.dtype(np.float32): 5126, np.dtype(np.uint8): 5121, np.dtype(np.uint16): 5123,
              np.dtype(np.uint32): 5125}   # glTF componentType of each array type we write
_VERTICES, _INDICES = 34962, 34963       # bufferView targets: ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER


def write_glb(path, clip: MotionClip, mesh=None, *, rest_rot=None, rest_root=None) -> Path:
    """Write ``clip`` (and ``mesh`` skinned to its skeleton) to ``path`` (``.glb``) atomically; returns the path.

    See ``glb_bytes`` for the arguments.
    """
    path = Path(path)
    data = glb_bytes(clip, mesh, rest_rot=rest_rot, rest_root=rest_root)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return path


def glb_bytes(clip: MotionClip, mesh=None, *, rest_rot=None, rest_root=None) -> bytes:
    """``clip`` as the bytes of a ``.glb`` file, with ``mesh`` (a ``retarget.character.Mesh``) skinned to it.

    The mesh is modelled in the skeleton's rest pose: local rotations ``rest_rot`` (J, 4)
    (default identity) with the root at ``rest_root`` (3,) (default the root's offset), as a
    ``Character`` has them.
    """
    import pygltflib as g

    sk = clip.skeleton
    local_rot = one_hemisphere(clip.local_rot).astype(np.float32)
    times = (np.arange(clip.n_frames) / clip.fps).astype(np.float32)
    blob = GlbBlob(g)

    nodes = []
    for j, name in enumerate(sk.names):
        translation = clip.root_pos[0] if j == 0 else sk.offsets[j]
        nodes.append(g.Node(name=name, translation=[float(v) for v in translation],
                            rotation=[float(v) for v in local_rot[0, j]], children=[]))
    for j in range(1, sk.n_joints):
        nodes[sk.parents[j]].children.append(j)
    for j, tip in sorted(sk.end_sites.items()):
        nodes.append(g.Node(name=f"{sk.names[j]}_end", translation=[float(v) for v in tip]))
        nodes[j].children.append(len(nodes) - 1)

    time_acc = blob.accessor(times[:, None], g.SCALAR, bounds=True)  # a sampler's input needs its min and max
    samplers, channels = [], []

    def animate(node: int, path: str, values: np.ndarray, kind: str) -> None:
        samplers.append(g.AnimationSampler(input=time_acc, output=blob.accessor(values, kind),
                                           interpolation="LINEAR"))
        channels.append(g.AnimationChannel(sampler=len(samplers) - 1, target=g.AnimationChannelTarget(node=node,
                                                                                                      path=path)))

    animate(0, "translation", clip.root_pos, g.VEC3)
    for j in range(sk.n_joints):
        if np.abs(local_rot[:, j] - local_rot[:1, j]).max() > _STILL:
            animate(j, "rotation", local_rot[:, j], g.VEC4)
        if j > 0 and clip.local_pos is not None and np.abs(clip.local_pos[:, j] - sk.offsets[j]).max() > _STILL:
            animate(j, "translation", clip.local_pos[:, j], g.VEC3)

    gltf = g.GLTF2(asset=g.Asset(version="2.0", generator="dancesynth"), scene=0,
                   scenes=[g.Scene(name="dance", nodes=[0])], nodes=nodes,
                   animations=[g.Animation(name="dance", samplers=samplers, channels=channels)])
    if mesh is not None:
        _add_skinned_mesh(gltf, blob, clip, mesh, rest_rot, rest_root)
    gltf.accessors, gltf.bufferViews = blob.accessors, blob.views
    gltf.buffers = [g.Buffer(byteLength=len(blob.data))]
    gltf.set_binary_blob(bytes(blob.data))
    return b"".join(gltf.save_to_bytes())


class GlbBlob:
    """The binary chunk being written, with the bufferViews and accessors that point into it."""

    def __init__(self, g):
        self.g, self.data, self.views, self.accessors = g, bytearray(), [], []

    def accessor(self, array: np.ndarray, kind: str, *, dtype=np.float32, target: int | None = None,
                 bounds: bool = False) -> int:
        """Append ``array`` (count, ...) as one accessor of ``kind`` (SCALAR, VEC3, ...); returns its index."""
        g = self.g
        data = np.ascontiguousarray(array, dtype=dtype)
        self.views.append(g.BufferView(buffer=0, byteOffset=len(self.data), byteLength=data.nbytes, target=target))
        self.data.extend(data.tobytes())
        self.data.extend(b"\0" * (-len(self.data) % 4))  # every view starts 4-byte aligned
        flat = data.reshape(data.shape[0], -1)
        extra = {"min": flat.min(axis=0).tolist(), "max": flat.max(axis=0).tolist()} if bounds else {}
        self.accessors.append(g.Accessor(bufferView=len(self.views) - 1, componentType=_COMPONENT[data.dtype],
                                         count=data.shape[0], type=kind, **extra))
        return len(self.accessors) - 1


def _add_skinned_mesh(gltf, blob: GlbBlob, clip: MotionClip, mesh, rest_rot, rest_root) -> None:
    """Add ``mesh`` to ``gltf``, skinned to the joint nodes 0..J-1, as a second root node of the scene."""
    g = blob.g
    sk = clip.skeleton
    n_joints = sk.n_joints
    rest_rot = np.tile([0.0, 0.0, 0.0, 1.0], (n_joints, 1)) if rest_rot is None else np.asarray(rest_rot, float)
    rest_root = sk.offsets[0] if rest_root is None else np.asarray(rest_root, float)
    positions = np.asarray(mesh.positions, dtype=np.float32)
    n_vertices = len(positions)
    joints = np.asarray(mesh.joints)
    indices = np.asarray(mesh.indices)
    if rest_rot.shape != (n_joints, 4) or rest_root.shape != (3,):
        raise InputError(f"the rest pose must be ({n_joints}, 4) rotations and a (3,) root position, "
                         f"got {rest_rot.shape} and {rest_root.shape}")
    if (np.shape(mesh.normals) != (n_vertices, 3) or np.shape(mesh.colours) != (n_vertices, 3)
            or joints.shape != (n_vertices, 4) or np.shape(mesh.weights) != (n_vertices, 4)
            or indices.ndim != 2 or indices.shape[1] != 3 or len(indices) == 0):
        raise InputError("the mesh's arrays disagree on its number of vertices, or it has no triangles")
    if joints.min() < 0 or joints.max() >= n_joints or indices.min() < 0 or indices.max() >= n_vertices:
        raise InputError(f"the mesh refers to a joint beyond the skeleton's {n_joints} or a vertex it lacks")
    weights = _normalised_weights(mesh.weights)
    joints = np.where(weights > 0, joints, 0)   # glTF: an unused slot names joint 0

    index_type = np.uint16 if n_vertices <= 65535 else np.uint32
    attributes = g.Attributes(
        POSITION=blob.accessor(positions, g.VEC3, target=_VERTICES, bounds=True),
        NORMAL=blob.accessor(_unit32(mesh.normals), g.VEC3, target=_VERTICES),
        COLOR_0=blob.accessor(np.clip(mesh.colours, 0.0, 1.0), g.VEC3, target=_VERTICES),
        JOINTS_0=blob.accessor(joints, g.VEC4, dtype=np.uint8 if n_joints <= 256 else np.uint16, target=_VERTICES),
        WEIGHTS_0=blob.accessor(weights, g.VEC4, target=_VERTICES))
    primitive = g.Primitive(attributes=attributes, material=0, mode=g.TRIANGLES,
                            indices=blob.accessor(indices.reshape(-1, 1), g.SCALAR, dtype=index_type,
                                                  target=_INDICES))
    gltf.materials = [g.Material(name="body", pbrMetallicRoughness=g.PbrMetallicRoughness(
        baseColorFactor=[1.0, 1.0, 1.0, 1.0], metallicFactor=0.0, roughnessFactor=0.8))]
    gltf.meshes = [g.Mesh(name="body", primitives=[primitive])]
    ibm = _inverse_bind_matrices(sk, rest_rot, rest_root)
    gltf.skins = [g.Skin(name="skeleton", joints=list(range(n_joints)), skeleton=0,
                         inverseBindMatrices=blob.accessor(ibm, g.MAT4))]
    gltf.nodes.append(g.Node(name="body", mesh=0, skin=0))
    gltf.scenes[0].nodes.append(len(gltf.nodes) - 1)


def _inverse_bind_matrices(sk, rest_rot: np.ndarray, rest_root: np.ndarray) -> np.ndarray:
    """(J, 16) column-major inverses of each joint's world transform in the rest pose."""
    g_rot, g_pos = fk(rest_rot, rest_root, sk.offsets, sk.parents)
    inv_r = Rotation.from_quat(g_rot).as_matrix().transpose(0, 2, 1)   # a rotation's inverse is its transpose
    m = np.zeros((sk.n_joints, 4, 4))
    m[:, :3, :3] = inv_r
    m[:, :3, 3] = -np.einsum("jab,jb->ja", inv_r, g_pos)
    m[:, 3, 3] = 1.0
    return m.transpose(0, 2, 1).reshape(sk.n_joints, 16)


def _normalised_weights(weights) -> np.ndarray:
    """Non-negative float32 weights summing to 1 as exactly as float32 allows: glTF readers (and the
    validator) check the sum, so the rounding is put on each vertex's largest weight."""
    w = np.clip(np.asarray(weights, dtype=np.float64), 0.0, None)
    total = w.sum(axis=1, keepdims=True)
    if np.any(total <= 0) or not np.all(np.isfinite(total)):
        raise InputError("every vertex of the mesh needs a positive skin weight")
    w32 = (w / total).astype(np.float32)
    rows = np.arange(len(w32))
    big = np.argmax(w32, axis=1)
    rest = w32.astype(np.float64).sum(axis=1) - w32[rows, big]
    w32[rows, big] = (1.0 - rest).astype(np.float32)
    return w32


def _unit32(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return (v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)).astype(np.float32)


def one_hemisphere(q: np.ndarray) -> np.ndarray:
    """Each joint's quaternions made continuous over time (q and -q are one rotation): glTF players
    interpolate the components linearly, so a sign flip between frames would swing the joint round."""
    q = np.array(q, dtype=np.float64)
    turned = np.where(np.sum(q[1:] * q[:-1], axis=-1) < 0, -1.0, 1.0)   # (F-1, J): frame f vs f-1
    q[1:] *= np.cumprod(turned, axis=0)[..., None]                       # relative to frame 0
    return q

"""The dance added to the user's own glTF / GLB / VRM model: their file, plus one animation named "dance".

Everything in the file is kept (meshes, materials, VRM extensions, their own animations, after
ours: players play the first); the dance's keyframes are appended to its binary buffer and a new
animation drives the nodes the
character was loaded from (``Character.nodes``): a rotation channel for every joint and a
translation channel for the hips. The clip is in the character's world frame and metres
(``retarget.gltf_character``), so the hips' rotation and translation are taken back into the
hips' parent space (``Character.armature``: its rotation and scale, e.g. an FBX 0.01 node).
A ``.gltf`` with separate buffer and image files comes out as one self-contained ``.glb``.
"""

from __future__ import annotations

import mimetypes

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError
from ..retarget.character import Character
from ..retarget.gltf_file import buffer_bytes, open_gltf, read_uri
from ..types import MotionClip
from .gltf import one_hemisphere
from .vrm import GlbBuilder

_IMAGE_MAGIC = {b"\x89PNG": "image/png", b"\xff\xd8\xff": "image/jpeg", b"RIFF": "image/webp",
                b"\xabKTX 20": "image/ktx2"}


def onto_model_bytes(character: Character, clip: MotionClip) -> bytes:
    """``character.source`` as ``.glb`` bytes with ``clip`` (on ``character.skeleton``) as its animation "dance"."""
    if character.source is None or character.nodes is None:
        raise InputError(f"character {character.name!r} was not loaded from a glTF file; there is no model to add "
                         "the dance to")
    if clip.skeleton.n_joints != len(character.nodes):
        raise InputError(f"the dance has {clip.skeleton.n_joints} joints but {character.source.name}'s skeleton "
                         f"has {len(character.nodes)}: retarget it onto this character first")
    gltf = open_gltf(character.source)
    nodes = gltf.nodes or []
    if max(character.nodes) >= len(nodes):
        raise InputError(f"{character.source.name} changed since it was loaded: load the character again")
    out = GlbBuilder(gltf, _one_buffer(gltf, character.source))
    for i in character.nodes:
        _trs_only(nodes[i])   # an animated node may not carry a matrix

    arm = np.asarray(character.armature, dtype=np.float64)   # uniform scale times rotation, and a shift
    arm_rot = Rotation.from_matrix(arm[:3, :3] / np.cbrt(np.linalg.det(arm[:3, :3])))
    root_pos = np.linalg.solve(arm[:3, :3], (clip.root_pos - arm[:3, 3]).T).T
    local_rot = np.array(clip.local_rot, dtype=np.float64)
    local_rot[:, 0] = (arm_rot.inv() * Rotation.from_quat(local_rot[:, 0])).as_quat()
    local_rot = one_hemisphere(local_rot)
    out.animation("dance", clip.fps, [(character.nodes[0], "translation", root_pos)]
                  + [(node, "rotation", local_rot[:, j]) for j, node in enumerate(character.nodes)])
    return out.glb()


def _one_buffer(gltf, path) -> bytes:
    """All of ``gltf``'s buffers, and images kept in files or data: URIs, joined into one binary blob
    (the .glb's); the buffer views and images are pointed into it."""
    import pygltflib as g

    blob = bytearray()
    starts = []
    for data in buffer_bytes(gltf, path):
        starts.append(len(blob))
        blob.extend(data)
        blob.extend(b"\0" * (-len(blob) % 8))  # keeps every view's alignment
    for view in gltf.bufferViews or []:
        if not isinstance(view.buffer, int) or not 0 <= view.buffer < len(starts):
            raise InputError(f"{path.name} is corrupt: a buffer view refers to buffer {view.buffer!r}")
        view.byteOffset = starts[view.buffer] + (view.byteOffset or 0)
        view.buffer = 0
    for image in gltf.images or []:
        if image.uri is None:
            continue
        data = read_uri(image.uri, path.parent, path.name)
        mime = image.mimeType or next((m for magic, m in _IMAGE_MAGIC.items() if data.startswith(magic)), None) \
            or mimetypes.guess_type(image.uri.split("?")[0])[0]
        gltf.bufferViews.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data)))
        blob.extend(data)
        blob.extend(b"\0" * (-len(blob) % 8))
        image.bufferView, image.mimeType, image.uri = len(gltf.bufferViews) - 1, mime, None
    return bytes(blob)


def _trs_only(node) -> None:
    """Replace a node's matrix by the translation, rotation and scale it holds (glTF animates TRS only)."""
    if node.matrix is None:
        return
    m = np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T
    scale = np.linalg.norm(m[:3, :3], axis=0)
    node.translation = m[:3, 3].tolist()
    node.rotation = Rotation.from_matrix(m[:3, :3] / scale).as_quat().tolist()
    node.scale = scale.tolist()
    node.matrix = None

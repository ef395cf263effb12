"""A dance as glTF 2.0 binary (``.glb``): its skeleton as a node hierarchy, its motion as one animation.

glTF is Y-up, in metres, with quaternions in (x, y, z, w) order: our own conventions
(DESIGN.md), so nothing is converted. Each joint is a node placed at its BVH offset and
rotated by its local rotation; the root's translation follows the dance; an End Site
becomes a leaf node so the last bone of a chain has its length. Joints that never turn
get no animation channel. There is no mesh yet: tools that retarget an animated skeleton
(Blender, three.js, Unity) read it as it is. Written with pygltflib.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.files import atomic_path
from ..types import MotionClip

_FLOAT = 5126              # glTF componentType FLOAT
_STILL = 1e-7              # a joint whose rotation changes less than this never turns


def write_glb(path, clip: MotionClip) -> Path:
    """Write ``clip`` to ``path`` (``.glb``) atomically; returns the path."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_bytes(glb_bytes(clip))
    return path


def glb_bytes(clip: MotionClip) -> bytes:
    """``clip`` as the bytes of a ``.glb`` file."""
    import pygltflib as g

    sk = clip.skeleton
    local_rot = _one_hemisphere(clip.local_rot).astype(np.float32)
    times = (np.arange(clip.n_frames) / clip.fps).astype(np.float32)
    blob = bytearray()
    views, accessors = [], []

    def accessor(array: np.ndarray, kind: str, bounds: bool = False) -> int:
        data = np.ascontiguousarray(array, dtype=np.float32)
        views.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=data.nbytes))
        blob.extend(data.tobytes())
        blob.extend(b"\0" * (-len(blob) % 4))  # every view starts 4-byte aligned
        count = data.shape[0]
        extra = {"min": data.min(axis=0).reshape(-1).tolist(), "max": data.max(axis=0).reshape(-1).tolist()} \
            if bounds else {}
        accessors.append(g.Accessor(bufferView=len(views) - 1, componentType=_FLOAT, count=count, type=kind,
                                    **extra))
        return len(accessors) - 1

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

    time_acc = accessor(times[:, None], g.SCALAR, bounds=True)  # a sampler's input needs its min and max
    samplers, channels = [], []

    def animate(node: int, path: str, values: np.ndarray, kind: str) -> None:
        samplers.append(g.AnimationSampler(input=time_acc, output=accessor(values, kind), interpolation="LINEAR"))
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
                   animations=[g.Animation(name="dance", samplers=samplers, channels=channels)],
                   accessors=accessors, bufferViews=views, buffers=[g.Buffer(byteLength=len(blob))])
    gltf.set_binary_blob(bytes(blob))
    return b"".join(gltf.save_to_bytes())


def _one_hemisphere(q: np.ndarray) -> np.ndarray:
    """Each joint's quaternions made continuous over time (q and -q are one rotation): glTF players
    interpolate the components linearly, so a sign flip between frames would swing the joint round."""
    q = np.array(q, dtype=np.float64)
    turned = np.where(np.sum(q[1:] * q[:-1], axis=-1) < 0, -1.0, 1.0)   # (F-1, J): frame f vs f-1
    q[1:] *= np.cumprod(turned, axis=0)[..., None]                       # relative to frame 0
    return q

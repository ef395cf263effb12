"""VRM: a dance as a VRM Animation (``.vrma``) for any VRM avatar, and the mannequin as a VRM 1.0 avatar.

A ``.vrma`` (VRMC_vrm_animation 1.0) is a glTF binary whose nodes are the humanoid bones in
the VRM T-pose (metres, Y up, facing +Z) and whose first animation moves them: a rotation
track per bone, relative to its rest (identity: the T-pose), and the hips' translation in
world space. Players take each bone's rotation relative to its nearest humanoid parent
(three-vrm-animation does exactly that), so the file holds only humanoid bones, each
parented to the nearest humanoid bone above it: joints between bones (a CMU ``LHipJoint``)
fold into the rotations instead of being dropped.

``vrm_bytes`` writes a character with a mesh (the mannequin) as a ``VRMC_vrm`` 1.0 avatar:
the skinned glTF of ``export.gltf`` plus the VRM meta and humanoid bone table.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..kinematics import clip_fk, fk
from ..retarget.character import Character
from ..retarget.humanoid import REQUIRED
from ..rotations import IDENTITY, inv, mul
from ..types import MotionClip
from .gltf import GlbBlob, one_hemisphere, glb_bytes

VRM_LICENSE = "https://vrm.dev/licenses/1.0/"
META = {"name": "dancesynth mannequin", "version": "1.0", "authors": ["dancesynth"], "licenseUrl": VRM_LICENSE,
        "avatarPermission": "everyone", "commercialUsage": "corporation", "allowRedistribution": True,
        "modification": "allowModificationRedistribution", "creditNotation": "unnecessary",
        "allowExcessivelyViolentUsage": False, "allowExcessivelySexualUsage": False,
        "allowPoliticalOrReligiousUsage": False, "allowAntisocialOrHateUsage": False}


class GlbBuilder(GlbBlob):
    """A ``pygltflib.GLTF2`` and its one binary buffer (``blob``: what it holds already), grown by
    appending arrays as accessors and whole animations; ``glb()`` returns the ``.glb`` bytes."""

    def __init__(self, gltf, blob: bytes = b""):
        import pygltflib as g

        super().__init__(g)
        self.gltf = gltf
        self.data.extend(blob)
        self.data.extend(b"\0" * (-len(self.data) % 4))
        # Appended views and accessors go straight into the file's own lists.
        self.views = gltf.bufferViews = gltf.bufferViews or []
        self.accessors = gltf.accessors = gltf.accessors or []

    def animation(self, name: str, fps: float, tracks) -> None:
        """Add an animation sampled at ``fps``; ``tracks`` yields (node, path, values): path "rotation"
        with values (F, 4) or "translation" with (F, 3)."""
        g = self.g
        samplers, channels, time_acc = [], [], None
        for node, path, values in tracks:
            if time_acc is None:  # a sampler's input needs its min and max
                time_acc = self.accessor((np.arange(len(values)) / fps)[:, None], g.SCALAR, bounds=True)
            kind = g.VEC4 if path == "rotation" else g.VEC3
            samplers.append(g.AnimationSampler(input=time_acc, output=self.accessor(values, kind),
                                               interpolation="LINEAR"))
            channels.append(g.AnimationChannel(sampler=len(samplers) - 1,
                                               target=g.AnimationChannelTarget(node=node, path=path)))
        # First: players (three.js examples, model viewers) play a file's first animation.
        self.gltf.animations = [g.Animation(name=name, samplers=samplers, channels=channels)] + \
            (self.gltf.animations or [])

    def glb(self) -> bytes:
        self.gltf.buffers = [self.g.Buffer(byteLength=len(self.data))]
        self.gltf.set_binary_blob(bytes(self.data))
        return b"".join(self.gltf.save_to_bytes())


@dataclass(frozen=True)
class HumanoidTracks:
    """A dance as VRM humanoid bones (parents first): each bone's rest translation from its nearest
    humanoid parent (the hips': from the floor), the hips' position per frame, and each bone's rotation
    per frame relative to that parent, in the VRM T-pose's frame (metres, Y up, facing +Z)."""

    bones: tuple[str, ...]     # (B,) VRM humanoid bone names, the hips first
    joints: tuple[int, ...]    # (B,) their joints in the clip's skeleton
    parent: tuple[int, ...]    # (B,) index of each bone's humanoid parent (-1: the hips)
    rest_local: np.ndarray     # (B, 3)
    hips_pos: np.ndarray       # (F, 3)
    rotations: np.ndarray      # (F, B, 4) (x, y, z, w), one hemisphere along time


def humanoid_tracks(clip: MotionClip, bones: dict[str, int], *, what: str = "a VRM Animation") -> HumanoidTracks:
    """``clip`` as ``HumanoidTracks``; ``bones`` maps VRM humanoid bone names to its joints, whose zero
    rotation must be the VRM T-pose (every built-in rig's rest pose is). Players take each bone's rotation
    relative to its nearest humanoid parent (three-vrm-animation does exactly that): joints between bones
    (a CMU ``LHipJoint``) fold into the rotations instead of being dropped."""
    sk = clip.skeleton
    missing = [b for b in REQUIRED if b not in bones]
    if missing:
        raise InputError(f"cannot write {what}: the rig has no {', '.join(missing)} bone")
    joint_bone = {}
    for bone, j in bones.items():
        if not 0 <= j < sk.n_joints or j in joint_bone:
            raise InputError(f"cannot write {what}: bone {bone} is joint {j}, which is missing or taken")
        joint_bone[j] = bone
    hips = bones["hips"]
    joints = sorted(joint_bone)   # parents come first, as in the skeleton

    def bone_parent(j: int) -> int:
        """The nearest joint above ``j`` that is a humanoid bone (-1 for the hips)."""
        p = sk.parents[j]
        while p >= 0 and p not in joint_bone:
            p = sk.parents[p]
        return p

    up = {j: bone_parent(j) for j in joints}
    if up[hips] != -1 or any(up[j] < 0 for j in joints if j != hips):
        raise InputError(f"cannot write {what}: every humanoid bone must be below the hips")
    _, rest = fk(np.tile(IDENTITY, (sk.n_joints, 1)), sk.offsets[0], sk.offsets, sk.parents)
    floor = np.zeros(3)
    if rest[hips, 1] <= 1e-3:   # a BVH rig rooted at the origin (OFFSET 0 0 0): its floor is its lowest joint
        floor[1] = rest[:, 1].min()
    rest = rest - floor
    if rest[hips, 1] <= 1e-3:
        raise InputError(f"cannot write {what}: the rig's rest pose must stand on the floor (y = 0) "
                         "with the hips above it")
    g_rot, g_pos = clip_fk(clip)
    index = {j: k for k, j in enumerate(joints)}
    local = np.stack([g_rot[:, j] if j == hips else mul(inv(g_rot[:, up[j]]), g_rot[:, j]) for j in joints], axis=1)
    return HumanoidTracks(tuple(joint_bone[j] for j in joints), tuple(joints),
                          tuple(-1 if j == hips else index[up[j]] for j in joints),
                          np.array([rest[j] - rest[up[j]] if j != hips else rest[j] for j in joints]),
                          g_pos[:, hips] - floor, one_hemisphere(local))


def vrma_bytes(clip: MotionClip, bones: dict[str, int]) -> bytes:
    """``clip`` as the bytes of a ``.vrma`` (``humanoid_tracks``: the bones' zero rotation must be the VRM T-pose)."""
    import pygltflib as g

    tracks = humanoid_tracks(clip, bones)
    names = clip.skeleton.names
    nodes = [g.Node(name=names[j], children=[c for c, p in enumerate(tracks.parent) if p == k],
                    translation=[float(v) for v in tracks.rest_local[k]])
             for k, j in enumerate(tracks.joints)]
    gltf = g.GLTF2(asset=g.Asset(version="2.0", generator="dancesynth"), scene=0,
                   scenes=[g.Scene(name="dance", nodes=[0])], nodes=nodes,
                   extensionsUsed=["VRMC_vrm_animation"],
                   extensions={"VRMC_vrm_animation": {"specVersion": "1.0", "humanoid": {"humanBones": {
                       bone: {"node": k} for k, bone in enumerate(tracks.bones)}}}})
    out = GlbBuilder(gltf)
    out.animation("dance", clip.fps, [(0, "translation", tracks.hips_pos)]
                  + [(k, "rotation", tracks.rotations[:, k]) for k in range(len(tracks.bones))])
    return out.glb()


def vrm_bytes(character: Character) -> bytes:
    """``character`` (with a mesh: the mannequin) as the bytes of a VRM 1.0 avatar (``.vrm``), standing in
    its rest pose, facing +Z; its humanoid bones are ``character.bones``."""
    import pygltflib as g

    if character.mesh is None:
        raise InputError(f"character {character.name!r} has no mesh: a VRM avatar needs one")
    missing = [b for b in REQUIRED if b not in character.bones]
    if missing:
        raise InputError(f"cannot write {character.name!r} as a VRM avatar: it has no {', '.join(missing)} bone")
    sk = character.skeleton
    rest = MotionClip(sk, 30.0, np.asarray(character.rest_root, float)[None],
                      np.asarray(character.rest_rot, float)[None])
    # glb_bytes writes joint j as node j; its one-frame animation is dropped (an avatar holds no motion).
    gltf = g.GLTF2.load_from_bytes(glb_bytes(rest, character.mesh, rest_rot=character.rest_rot,
                                             rest_root=character.rest_root))
    out = _without_animations(gltf)
    gltf.extensionsUsed = ["VRMC_vrm"]
    gltf.extensions = {"VRMC_vrm": {"specVersion": "1.0", "meta": dict(META),
                                    "humanoid": {"humanBones": {b: {"node": int(j)}
                                                                for b, j in character.bones.items()}}}}
    return out.glb()


def _without_animations(gltf) -> GlbBuilder:
    """``gltf`` with its animations removed and a binary buffer holding only what its meshes and skins use."""
    old, views, accessors = gltf.binary_blob(), gltf.bufferViews, gltf.accessors
    gltf.animations, gltf.bufferViews, gltf.accessors = [], [], []
    out = GlbBuilder(gltf)
    moved = {}

    def move(i):
        if i is None or i in moved:
            return moved.get(i)
        acc, view = copy.copy(accessors[i]), copy.copy(views[accessors[i].bufferView])
        out.data.extend(old[view.byteOffset or 0:(view.byteOffset or 0) + view.byteLength])
        view.byteOffset = len(out.data) - view.byteLength
        out.data.extend(b"\0" * (-len(out.data) % 4))
        out.views.append(view)
        acc.bufferView = len(out.views) - 1
        out.accessors.append(acc)
        moved[i] = len(out.accessors) - 1
        return moved[i]

    for mesh in gltf.meshes or []:
        for prim in mesh.primitives:
            for key, i in vars(prim.attributes).items():
                setattr(prim.attributes, key, move(i))
            prim.indices = move(prim.indices)
    for skin in gltf.skins or []:
        skin.inverseBindMatrices = move(skin.inverseBindMatrices)
    return out

"""A character a dance can be put on: a rig (skeleton, rest pose, humanoid bones), maybe a skinned mesh.

``load_character(spec)`` takes a built-in's name (``rigs.LAYOUTS``) or a file: a BVH (its
joint names, hierarchy and offsets are the rig; its rest pose is the zero rotation), or a
glTF/GLB/VRM (0.x or 1.0) model, whose skin's joints (or, for a VRM without a skin, its
humanoid bones' nodes), node rest pose and, for VRM, humanoid bone table define the target. Bones are found by ``humanoid.find_bones``; a TOML file
(``[bones]``, humanoid bone = joint name) overrides what it finds.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..rotations import IDENTITY
from ..types import MotionClip, Skeleton


@dataclass(frozen=True, eq=False)
class Mesh:
    """A skinned triangle mesh bound to a character's skeleton in its rest pose.

    Positions and normals are in metres, in the rest pose (the bind pose), in the
    character's world frame (Y up). ``joints``/``weights``: up to four skeleton joints per
    vertex with weights summing to 1. ``colours``: linear RGB per vertex, 0..1.
    """

    positions: np.ndarray   # (V, 3) float32
    normals: np.ndarray     # (V, 3) float32, unit
    indices: np.ndarray     # (T, 3) uint32, counter-clockwise seen from outside
    joints: np.ndarray      # (V, 4) uint16
    weights: np.ndarray     # (V, 4) float32
    colours: np.ndarray     # (V, 3) float32


@dataclass(frozen=True, eq=False)
class Character:
    """A retargeting target.

    ``skeleton`` is rooted at the character's hips, offsets in metres. ``rest_rot`` (J, 4)
    holds each joint's local rotation in the rest pose (identity for a BVH rig; a glTF
    model's node rotations; the root's includes the rotation of everything above the
    hips), so forward kinematics of ``rest_rot`` at ``rest_root`` is the rest pose in world
    space. ``bones`` maps VRM humanoid bone names to joint indices. A file character keeps
    the file (``source``) and each joint's glTF node (``nodes``) so the dance can be added to
    the user's own model; ``armature`` is the 4x4 world transform of the hips' parent node
    (metres), which the exporter undoes for the hips' animated translation.
    """

    name: str
    skeleton: Skeleton
    bones: dict[str, int]
    rest_rot: np.ndarray
    rest_root: np.ndarray
    mesh: Mesh | None = None
    source: Path | None = None
    nodes: tuple[int, ...] | None = None
    armature: np.ndarray = field(default_factory=lambda: np.eye(4))
    kind: str = "builtin"     # "builtin" | "bvh" | "gltf" | "vrm0" | "vrm1" | "source" | "rig"
    ankle_ground: float | None = None   # ankles' height when standing on the floor; None: as in the rest pose
    metres_per_unit: float = 1.0        # the lengths of the character's own file (a BVH rig in cm: 0.01)

    def in_own_units(self, clip: MotionClip) -> MotionClip:
        """``clip`` (on this character, in metres) in the lengths of the character's file: a BVH rig in
        centimetres gets its dance back in centimetres (glTF and VRM are metres by definition)."""
        return clip.scaled(1.0 / self.metres_per_unit)


DEFAULT_CHARACTER = "mannequin"
FILE_KINDS = {".bvh": "BVH rig", ".glb": "glTF binary model", ".gltf": "glTF model", ".vrm": "VRM avatar (0.x or 1.0)"}


def builtin_character(name: str) -> Character:
    """A built-in character by name (``rigs.LAYOUTS``); only the mannequin has a mesh."""
    from .rigs import LAYOUTS, rig_skeleton

    if name not in LAYOUTS:
        raise InputError(f"unknown character {name!r}: use one of {', '.join(LAYOUTS)} or a .bvh/.glb/.gltf/.vrm file")
    if name == "mannequin":
        from .mannequin import mannequin_character

        return mannequin_character()
    skeleton, bones = rig_skeleton(name)
    return Character(name, skeleton, bones, np.tile(IDENTITY, (skeleton.n_joints, 1)), skeleton.offsets[0].copy())


def source_character(skeleton: Skeleton) -> Character:
    """The skeleton a dance was made on, as a character (its bones found where they can be)."""
    from .humanoid import find_bones

    try:
        bones = find_bones(skeleton)
    except InputError:
        bones = {}
    return Character("source", skeleton, bones, np.tile(IDENTITY, (skeleton.n_joints, 1)), skeleton.offsets[0].copy(),
                     kind="source")


def load_character(spec, *, bone_map=None) -> Character:
    """A character from a built-in name or a file (see the module docstring); ``bone_map``: a TOML path.
    Its humanoid bones and rest pose are checked here (``humanoid.check_bones``), before any dance is made."""
    character = _load(spec, bone_map)
    return checked(character, what=character.source.name if character.source is not None else character.name)


def checked(character: Character, *, what: str) -> Character:
    """``character`` if a dance can be put on it (``humanoid.check_bones``), else ``InputError``."""
    from ..kinematics import fk
    from .humanoid import check_bones

    sk = character.skeleton
    _, rest = fk(character.rest_rot, character.rest_root, sk.offsets, sk.parents)
    check_bones(sk, character.bones, rest, what=what)
    return character


def _load(spec, bone_map) -> Character:
    from .humanoid import BONES, REQUIRED, find_bones, read_bone_map
    from .rigs import LAYOUTS

    overrides = read_bone_map(bone_map) if bone_map is not None else None
    if str(spec) in LAYOUTS and not Path(str(spec)).suffix:
        character = builtin_character(str(spec))
        if overrides:
            character = replace(character, bones=find_bones(character.skeleton, overrides, what=character.name))
        return character
    path = Path(spec)
    kind = FILE_KINDS.get(path.suffix.lower())
    if kind is None:
        if not path.suffix:
            raise InputError(f"unknown character {str(spec)!r}: use one of {', '.join(LAYOUTS)} "
                             f"or a file ({', '.join(FILE_KINDS)})")
        raise InputError(f"character {path}: cannot read {path.suffix} files; use {', '.join(FILE_KINDS)}")
    if not path.is_file():
        raise InputError(f"character file {path} does not exist")
    if path.suffix.lower() == ".bvh":
        return _bvh_character(path, overrides)
    from .gltf_character import load_gltf_character

    character = load_gltf_character(path)
    if overrides or any(b not in character.bones for b in REQUIRED):
        # A VRM's own table names what it names; the bone map, then the rig's names and hierarchy, the rest.
        names = {b: character.skeleton.names[j] for b, j in character.bones.items() if b in BONES}
        character = replace(character, bones=find_bones(character.skeleton, {**names, **(overrides or {})},
                                                        what=path.name))
    return character


def _bvh_character(path: Path, overrides) -> Character:
    """A BVH rig: its offsets and names; its rest pose is the zero rotation. The floor is where its
    own frames stand (a BVH's rest pose says nothing about where the floor is)."""
    from ..io.bvh import read_bvh

    clip = read_bvh(path)
    return replace(rig_character(clip, overrides, what=path.name), name=path.stem, source=path, kind="bvh",
                   metres_per_unit=float(clip.meta.get("metres_per_unit", 1.0)))


def rig_character(clip: MotionClip, overrides=None, *, what: str = "the rig") -> Character:
    """The skeleton of ``clip`` as a character: its offsets and names, the zero rotation as its rest pose,
    its floor where the clip's frames stand. A BVH rig, or a database style's skeleton (``clip`` one of
    its takes): what analyses retarget a dance onto, to read it as that mocap is read."""
    from ..kinematics import clip_fk
    from .humanoid import find_bones

    bones = find_bones(clip.skeleton, overrides, what=what)
    _, pos = clip_fk(clip)
    ankles = pos[:, [bones["leftFoot"], bones["rightFoot"]], 1].min(axis=1)
    sk = clip.skeleton
    return Character("rig", sk, bones, np.tile(IDENTITY, (sk.n_joints, 1)), sk.offsets[0].copy(), kind="rig",
                     ankle_ground=float(np.percentile(ankles, 1.0)))

"""A user's rigged glTF, GLB or VRM model as a ``Character``: the rig is read here, the file by
``gltf_file`` and the mesh by ``gltf_mesh``.

The skeleton is the model's skin joints under the hips: the VRM humanoid table names the
hips (VRM 0.x: extension ``VRM``, a list of ``{bone, node}``; VRM 1.0: ``VRMC_vrm``, a map
``bone -> {node}``); a plain glTF has no table, so its skeleton is rooted at the common
ancestor of the skin's joints and the caller finds the bones by name. A VRM without a skin
(many hang each body part's mesh straight from its bone node) has the humanoid bones as its
skeleton, and its meshes move rigidly with them; a plain glTF without a skin is refused, as
nothing says which nodes are its bones. Lengths come out in metres whatever scale sits above
the rig (FBX conversions often put a 0.01 node there), and each joint remembers its glTF node
so ``export.onto_model`` can add a dance to the file itself. VRM 0.x models face -Z (their
exporter turned them round), 1.0 and glTF ones +Z; ``kind`` says which, and the retargeter
aligns by the hips' frame either way.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError
from ..io.bvh import MAX_JOINTS
from ..types import Skeleton
from .character import Character
from .gltf_file import invalid_file, open_gltf
from .gltf_mesh import user_mesh
from .rigs import JOINT_CHANNELS, ROOT_CHANNELS

# VRM 0.x named the thumb bones one joint up from VRM 1.0; the canonical rig uses 1.0's names.
_VRM0_THUMBS = {f"{s}{old}": f"{s}{new}" for s in ("left", "right")
                for old, new in (("ThumbProximal", "ThumbMetacarpal"), ("ThumbIntermediate", "ThumbProximal"))}
_SCALE_TOL = 1e-4   # relative spread of a scale's three factors still called uniform
MAX_NODE_DEPTH = 256   # nodes from a scene root down to any node (a rig's deepest finger is about 40)


def load_gltf_character(path) -> Character:
    """The rig and mesh of the glTF / GLB / VRM model at ``path``."""
    path = Path(path)
    gltf = open_gltf(path)
    try:
        return _character(gltf, path)
    except InputError:
        raise
    except Exception as exc:  # a field of the wrong type or shape somewhere in the JSON
        raise invalid_file(path, exc) from None


def _character(gltf, path: Path) -> Character:
    name = path.name
    nodes = gltf.nodes or []
    n = len(nodes)

    def node_index(i, what: str) -> int:
        if isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < n:
            raise InputError(f"{name} is corrupt: {what} refers to node {i!r}, which does not exist")
        return i

    parent = [-1] * n
    for i, nd in enumerate(nodes):
        for c in nd.children or []:
            if parent[node_index(c, f"node {i}'s children")] != -1 or c == i:
                raise InputError(f"{name} is corrupt: node {c} has more than one parent")
            parent[c] = i
    skins = [[node_index(j, f"skin {s}") for j in (skin.joints or [])] for s, skin in enumerate(gltf.skins or [])]
    kind, human = _humanoid(gltf.extensions or {}, name)
    human = {bone: node_index(i, f"the VRM humanoid bone {bone}") for bone, i in human.items()}
    # A VRM's humanoid table names its bones even where no skin does (meshes hung from bone nodes);
    # in a plain glTF only a skin says which nodes are bones.
    if not any(skins) and "hips" not in human:
        raise InputError(f"{name} has no skin: a character needs a skinned mesh (a rigged model) or a VRM "
                         "avatar's humanoid bones")

    _check_depth(parent, name)

    def ancestors(i: int) -> list[int]:
        """``i`` and the nodes above it, up to its scene root (at most ``MAX_NODE_DEPTH``)."""
        chain = [i]
        while parent[chain[-1]] >= 0:
            chain.append(parent[chain[-1]])
        return chain

    joints = set().union(*skins, human.values())
    if len(joints) > 4 * MAX_JOINTS:   # before any walk up the tree: the skeleton's count is checked below
        raise InputError(f"{name} has {len(joints)} skin joints; a character has at most {MAX_JOINTS}")

    if "hips" in human:
        root = human["hips"]
    else:  # no table (or one without hips): the caller finds the bones by name
        human = {}
        biggest = max(skins, key=len)
        common = set(ancestors(biggest[0]))
        for j in biggest[1:]:
            common &= set(ancestors(j))
        if not common:
            raise InputError(f"{name}'s skin joints are not one hierarchy: a character needs one skeleton")
        root = next(a for a in ancestors(biggest[0]) if a in common)  # the lowest common ancestor

    # Every skin joint and humanoid bone under the root joins, with the nodes on the way to it. (Not
    # every node under it: a skinless VRM's mesh nodes there are often squashed by non-uniform scales.)
    members = {root}
    for j in joints:
        chain = ancestors(j)
        if root in chain:
            members.update(chain[:chain.index(root)])
    order, stack = [], [root]
    while stack:  # depth first, children in file order: parents come before their children
        i = stack.pop()
        order.append(i)
        stack.extend(reversed([c for c in nodes[i].children or [] if c in members]))
    if len(order) > MAX_JOINTS:
        raise InputError(f"{name}'s skeleton has {len(order)} joints; a character has at most {MAX_JOINTS} (BVH, "
                         "which every dance can be written as, holds no more)")
    index = {node: k for k, node in enumerate(order)}

    above = ancestors(root)[1:]
    trs = {i: _node_trs(nodes[i], name, i) for i in above + order}
    # The armature: the world transform of everything above the root (a rotation, a uniform scale, a shift).
    world_rot, world_pos, world_scale = Rotation.identity(), np.zeros(3), 1.0
    for i in reversed(above):
        t, r, s = trs[i]
        world_pos = world_pos + world_rot.apply(world_scale * t)
        world_rot, world_scale = world_rot * r, world_scale * s
    armature = np.eye(4)
    armature[:3, :3] = world_rot.as_matrix() * world_scale
    armature[:3, 3] = world_pos

    scale = {}   # each member's world scale: what turns its children's translations into metres
    offsets, rest_rot = np.zeros((len(order), 3)), np.zeros((len(order), 4))
    for k, i in enumerate(order):
        t, r, s = trs[i]
        if k == 0:
            offsets[0] = world_pos + world_rot.apply(world_scale * t)
            rest_rot[0] = (world_rot * r).as_quat()
            scale[i] = world_scale * s
        else:
            offsets[k] = scale[parent[i]] * t
            rest_rot[k] = r.as_quat()
            scale[i] = scale[parent[i]] * s
    if not (np.all(np.isfinite(offsets)) and np.all(np.isfinite(armature))) or scale[root] <= 0:
        raise InputError(f"{name} is corrupt: its joints' transforms are not finite")

    names = _unique_names([nodes[i].name for i in order], order)
    parents = np.array([-1] + [index[parent[i]] for i in order[1:]])
    skeleton = Skeleton(tuple(names), parents, offsets,
                        tuple(ROOT_CHANNELS if k == 0 else JOINT_CHANNELS for k in range(len(order))))
    bones = {bone: index[i] for bone, i in human.items() if i in index}
    mesh = user_mesh(gltf, path, skins, index, ancestors, set(above))
    return Character(name=_title(gltf.extensions or {}) or path.stem, skeleton=skeleton, bones=bones,
                     rest_rot=rest_rot, rest_root=offsets[0].copy(), mesh=mesh, source=path,
                     nodes=tuple(order), armature=armature, kind=kind)


def _check_depth(parent: list[int], name: str) -> None:
    """Every node at most ``MAX_NODE_DEPTH`` below its scene root, and no cycle: each node is walked
    once (depths remembered), so this is linear in the number of nodes."""
    depth = [0 if p < 0 else -1 for p in parent]
    for i in range(len(parent)):
        path = []
        while depth[i] < 0:
            path.append(i)
            i = parent[i]
            if len(path) > MAX_NODE_DEPTH:
                raise InputError(f"{name} is corrupt: its node hierarchy has a cycle or is over {MAX_NODE_DEPTH} "
                                 "nodes deep")
        for k, j in enumerate(reversed(path), 1):
            depth[j] = depth[i] + k
        if path and depth[path[0]] > MAX_NODE_DEPTH:
            raise InputError(f"{name}'s node hierarchy is {depth[path[0]]} nodes deep; at most {MAX_NODE_DEPTH} "
                             "are read")


def _humanoid(extensions: dict, name: str) -> tuple[str, dict]:
    """(kind, VRM 1.0 bone name -> node) from the VRM extensions; a plain glTF has none."""
    try:
        if isinstance(extensions.get("VRMC_vrm"), dict):
            table = extensions["VRMC_vrm"].get("humanoid", {}).get("humanBones", {})
            return "vrm1", {bone: entry["node"] for bone, entry in table.items()}
        if isinstance(extensions.get("VRM"), dict):
            table = extensions["VRM"].get("humanoid", {}).get("humanBones", [])
            return "vrm0", {_VRM0_THUMBS.get(e["bone"], e["bone"]): e["node"] for e in table
                            if e.get("bone") is not None and e.get("node", -1) != -1}
    except (AttributeError, KeyError, TypeError):
        raise InputError(f"{name} is corrupt: its VRM humanoid bone table cannot be read") from None
    return "gltf", {}


def _title(extensions: dict) -> str | None:
    """The avatar's name from its VRM meta, if it has one."""
    for key, field in (("VRMC_vrm", "name"), ("VRM", "title")):
        meta = extensions.get(key, {}).get("meta") if isinstance(extensions.get(key), dict) else None
        if isinstance(meta, dict) and isinstance(meta.get(field), str) and meta[field].strip():
            return meta[field].strip()
    return None


def _node_trs(node, name: str, i: int) -> tuple[np.ndarray, Rotation, float]:
    """A node's local (translation, rotation, uniform scale); a non-uniform or mirroring scale is refused."""
    if node.matrix is not None and list(node.matrix) != [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]:
        m = np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T   # glTF matrices are column-major
        t, a = m[:3, 3], m[:3, :3]
        scale = np.linalg.norm(a, axis=0)
        det = np.linalg.det(a)
        r = Rotation.from_matrix(a / np.where(scale > 0, scale, 1.0)) if det > 0 else None
    else:
        t = np.asarray(node.translation if node.translation is not None else [0, 0, 0], dtype=np.float64)
        q = np.asarray(node.rotation if node.rotation is not None else [0, 0, 0, 1], dtype=np.float64)
        scale = np.asarray(node.scale if node.scale is not None else [1, 1, 1], dtype=np.float64)
        det = np.prod(scale)
        if t.shape != (3,) or q.shape != (4,) or scale.shape != (3,) or not np.all(np.isfinite(q)) \
                or np.linalg.norm(q) < 1e-6:
            raise InputError(f"{name} is corrupt: node {i} has a malformed transform")
        r = Rotation.from_quat(q)
    label = f"node {node.name!r}" if node.name else f"node {i}"
    if det <= 0 or r is None or np.ptp(scale) > _SCALE_TOL * np.max(scale):
        raise InputError(f"{name}: {label} has a non-uniform or mirroring scale {np.round(scale, 4).tolist()}; "
                         "apply the scale in your modelling tool (Blender: Object > Apply > Scale) and export again")
    return t, r, float(np.mean(scale))


def _unique_names(names, nodes) -> list[str]:
    """Node names made usable as joint names: a missing one becomes ``node<i>``, a repeated one gets
    its node index appended."""
    names = [nm if isinstance(nm, str) and nm.strip() else f"node{i}" for nm, i in zip(names, nodes)]
    seen = {}
    for nm in names:
        seen[nm] = seen.get(nm, 0) + 1
    out, taken = [], set()
    for nm, i in zip(names, nodes):
        unique = nm if seen[nm] == 1 else f"{nm}_node{i}"
        while unique in taken:
            unique += "_"
        taken.add(unique)
        out.append(unique)
    return out

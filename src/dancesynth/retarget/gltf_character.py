"""A user's rigged glTF, GLB or VRM model as a ``Character``.

The skeleton is the model's skin joints under the hips: the VRM humanoid table names the
hips (VRM 0.x: extension ``VRM``, a list of ``{bone, node}``; VRM 1.0: ``VRMC_vrm``, a map
``bone -> {node}``); a plain glTF has no table, so its skeleton is rooted at the common
ancestor of the skin's joints and the caller finds the bones by name. Lengths come out in
metres whatever scale sits above the rig (FBX conversions often put a 0.01 node there), and
each joint remembers its glTF node so ``export.onto_model`` can add a dance to the file
itself. VRM 0.x models face -Z (their exporter turned them round), 1.0 and glTF ones +Z;
``kind`` says which, and the retargeter aligns by the hips' frame either way.

The mesh (``Character.mesh``, what videos draw) is every triangle primitive skinned to the
rig, plus any unskinned mesh hanging from one of its joints (glasses on the head), put in
the rest pose as glTF skinning does (each vertex by its joints' rest world transforms
times their inverse bind matrices), so it lands in the skeleton's frame in metres. Each
vertex keeps its four heaviest joints, a skin joint outside the skeleton counted as its
nearest ancestor in it. Colours are the material's base colour (factor x COLOR_0 x the
texture at the vertex's UV, nearest texel; a VRM 0.x MToon's ``_MainTex`` when the glTF
material has none), linear RGB; a texture that cannot be read is drawn mid grey.
Triangles of see-through material (alpha MASK or BLEND) whose corners are mostly
transparent are dropped, and double-sided ones get a back face, as the renderer culls.

Files are parsed with pygltflib after the GLB container is checked here; everything a
broken file can get wrong becomes one ``InputError`` line, never a traceback.
"""

from __future__ import annotations

import base64
import binascii
import io
import json
import os
import struct
import urllib.parse
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError
from ..types import Skeleton
from .character import Character, Mesh
from .rigs import JOINT_CHANNELS, ROOT_CHANNELS

_GLB_MAGIC, _JSON_CHUNK, _BIN_CHUNK = b"glTF", 0x4E4F534A, 0x004E4942
# VRM 0.x named the thumb bones one joint up from VRM 1.0; the canonical rig uses 1.0's names.
_VRM0_THUMBS = {f"{s}{old}": f"{s}{new}" for s in ("left", "right")
                for old, new in (("ThumbProximal", "ThumbMetacarpal"), ("ThumbIntermediate", "ThumbProximal"))}
_SCALE_TOL = 1e-4   # relative spread of a scale's three factors still called uniform


def load_gltf_character(path) -> Character:
    """The rig and skinned mesh of the glTF / GLB / VRM model at ``path``."""
    path = Path(path)
    gltf = open_gltf(path)
    try:
        return _character(gltf, path)
    except InputError:
        raise
    except Exception as exc:  # a field of the wrong type or shape somewhere in the JSON
        raise _invalid(path, exc) from None


def _invalid(path: Path, exc: Exception) -> InputError:
    detail = (str(exc).splitlines() or [""])[0][:120]
    return InputError(f"{path.name} is not a valid glTF file ({type(exc).__name__}{': ' + detail if detail else ''})")


def open_gltf(path):
    """``path`` parsed as a ``pygltflib.GLTF2`` (a .glb's binary chunk attached), or ``InputError``."""
    import pygltflib

    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read {path}: {exc.strerror or exc}") from None
    blob = None
    if data[:4] == _GLB_MAGIC:
        text, blob = _split_glb(data, path.name)
    else:
        try:
            text = data.decode("utf-8-sig")
            raw = json.loads(text)
        except (UnicodeDecodeError, ValueError):
            raise InputError(f"{path.name} is not a glTF file: expected a .glb or .vrm (binary glTF) or a .gltf "
                             "(JSON)") from None
        _check_gltf_json(raw, path.name)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            gltf = pygltflib.GLTF2.gltf_from_json(text)
    except Exception as exc:  # pygltflib meets a field it cannot read
        raise _invalid(path, exc) from None
    if blob is not None:
        gltf.set_binary_blob(blob)
    return gltf


def _split_glb(data: bytes, name: str) -> tuple[str, bytes | None]:
    """The JSON text and binary chunk of a GLB container, checked against its own lengths."""
    if len(data) < 20:
        raise InputError(f"{name} is truncated: a binary glTF is at least 20 bytes, this one {len(data)}")
    version, length = struct.unpack_from("<II", data, 4)
    if version != 2:
        raise InputError(f"{name} is binary glTF version {version}; only glTF 2.0 is supported")
    if length > len(data):
        raise InputError(f"{name} is truncated: its header says {length} bytes, the file has {len(data)}")
    chunks, at = [], 12
    while at + 8 <= length:
        size, kind = struct.unpack_from("<II", data, at)
        if at + 8 + size > length:
            raise InputError(f"{name} is truncated or corrupt: a chunk runs past the end of the file")
        chunks.append((kind, data[at + 8:at + 8 + size]))
        at += 8 + size
    if not chunks or chunks[0][0] != _JSON_CHUNK:
        raise InputError(f"{name} is corrupt: a binary glTF starts with a JSON chunk")
    try:
        text = chunks[0][1].decode("utf-8")
        raw = json.loads(text)
    except (UnicodeDecodeError, ValueError):
        raise InputError(f"{name} is corrupt: its JSON chunk does not parse") from None
    _check_gltf_json(raw, name)
    blob = chunks[1][1] if len(chunks) > 1 and chunks[1][0] == _BIN_CHUNK else None
    return text, blob


def _check_gltf_json(raw, name: str) -> None:
    asset = raw.get("asset") if isinstance(raw, dict) else None
    if not isinstance(asset, dict) or not str(asset.get("version", "")).startswith("2."):
        raise InputError(f"{name} is not a glTF 2.0 file (JSON without an asset version 2.x)")


def buffer_bytes(gltf, path) -> list[bytes]:
    """The bytes of each of ``gltf``'s buffers: the .glb's binary chunk, a data: URI, or a file next to
    ``path``; each cut to its declared length."""
    name, folder = Path(path).name, Path(path).parent
    out = []
    for i, buf in enumerate(gltf.buffers or []):
        if buf.uri is None:
            data = gltf.binary_blob() if i == 0 else None
            if data is None:
                raise InputError(f"{name} is corrupt: buffer {i} has no data")
        else:
            data = read_uri(buf.uri, folder, name)
        if len(data) < (buf.byteLength or 0):
            raise InputError(f"{name} is truncated: buffer {i} holds {len(data)} of its {buf.byteLength} bytes")
        out.append(bytes(data[:buf.byteLength]))
    return out


def read_uri(uri: str, folder: Path, name: str) -> bytes:
    """The bytes a glTF URI points at: a base64 data: URI or a file relative to the model's folder."""
    if uri.startswith("data:"):
        try:
            return base64.b64decode(uri.partition(",")[2], validate=True)
        except (binascii.Error, ValueError):
            raise InputError(f"{name} is corrupt: a data: URI is not valid base64") from None
    file = folder / urllib.parse.unquote(uri)
    try:
        return file.read_bytes()
    except OSError as exc:
        raise InputError(f"{name} refers to {uri}, which cannot be read: {exc.strerror or exc}; keep the "
                         "files a .gltf names next to it") from None


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
    if not any(skins):
        raise InputError(f"{name} has no skin: a character needs a skinned mesh (a rigged model)")

    kind, human = _humanoid(gltf.extensions or {}, name)
    human = {bone: node_index(i, f"the VRM humanoid bone {bone}") for bone, i in human.items()}

    def ancestors(i: int) -> list[int]:
        """``i`` and the nodes above it, up to its scene root (a cycle is a corrupt file)."""
        chain = [i]
        while parent[chain[-1]] >= 0:
            chain.append(parent[chain[-1]])
            if len(chain) > n:
                raise InputError(f"{name} is corrupt: its node hierarchy has a cycle")
        return chain

    biggest = max(skins, key=len)
    if "hips" in human:
        root = human["hips"]
    else:  # no table (or one without hips): the caller finds the bones by name
        human = {}
        common = set(ancestors(biggest[0]))
        for j in biggest[1:]:
            common &= set(ancestors(j))
        if not common:
            raise InputError(f"{name}'s skin joints are not one hierarchy: a character needs one skeleton")
        root = next(a for a in ancestors(biggest[0]) if a in common)  # the lowest common ancestor

    # Every skin joint and humanoid bone under the root joins, with the nodes on the way to it.
    members = {root}
    for j in set().union(*skins, human.values()):
        chain = ancestors(j)
        if root in chain:
            members.update(chain[:chain.index(root)])
    order, stack = [], [root]
    while stack:  # depth first, children in file order: parents come before their children
        i = stack.pop()
        order.append(i)
        stack.extend(reversed([c for c in nodes[i].children or [] if c in members]))
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
    mesh = _user_mesh(gltf, path, skins, index, ancestors, set(above))
    return Character(name=_title(gltf.extensions or {}) or path.stem, skeleton=skeleton, bones=bones,
                     rest_rot=rest_rot, rest_root=offsets[0].copy(), mesh=mesh, source=path,
                     nodes=tuple(order), armature=armature, kind=kind)


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


# --- the user's mesh ------------------------------------------------------------------------------

_COMPONENT = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_TRIANGLES, _CLAMP, _MIRROR = 4, 33071, 33648    # primitive mode, sampler wrap modes (REPEAT: the rest)
_SRGB_TO_LINEAR = np.where(np.arange(256) <= 10, np.arange(256) / 255 / 12.92,
                           ((np.arange(256) / 255 + 0.055) / 1.055) ** 2.4).astype(np.float32)
_MID_GREY = float(_SRGB_TO_LINEAR[128])           # what a texture that cannot be read is drawn as
_MAX_INFLUENCES = 4


def _user_mesh(gltf, path: Path, skins: list[list[int]], index: dict[int, int], ancestors, above: set) -> Mesh | None:
    """The model's meshes that move with the skeleton (``index``: node -> joint), in the rest pose in
    world metres; None when no mesh does (videos then draw a stick figure)."""
    reader = _Reader(gltf, path)
    nodes = gltf.nodes or []
    worlds: dict[int, np.ndarray] = {}

    def world(i: int) -> np.ndarray:
        """Node ``i``'s rest world matrix (4x4, scale included), its ancestors' kept for the next call."""
        chain = ancestors(i)
        known = next((k for k, a in enumerate(chain) if a in worlds), len(chain))
        m = worlds[chain[known]] if known < len(chain) else np.eye(4)
        for a in reversed(chain[:known]):
            m = worlds[a] = m @ _local_matrix(nodes[a])
        return m

    def joint_of(i: int, skinned: bool) -> int | None:
        """Our joint for node ``i``: it or its nearest ancestor in the skeleton. A skin joint above the
        hips (a root bone) moves with them; anything else outside the rig has none."""
        return next((index[a] for a in ancestors(i) if a in index), 0 if skinned and i in above else None)

    binds: dict[int, tuple[np.ndarray, np.ndarray] | None] = {}

    def skin_binds(s: int) -> tuple[np.ndarray, np.ndarray] | None:
        """Skin ``s``'s (rest world x inverse bind) matrices (n, 4, 4) and our joint for each of its joints;
        None when a joint lies outside the rig."""
        if s not in binds:
            joints = [joint_of(j, True) for j in skins[s]]
            if not skins[s] or None in joints:
                binds[s] = None
            else:
                ibm = gltf.skins[s].inverseBindMatrices
                n = len(skins[s])
                ibm = np.tile(np.eye(4), (n, 1, 1)) if ibm is None else \
                    reader.accessor(ibm, f"skin {s}'s inverse bind matrices", ("MAT4",)).reshape(-1, 4, 4)
                if len(ibm) < n:
                    raise reader.corrupt(f"skin {s} has {len(ibm)} inverse bind matrices for {n} joints")
                # glTF matrices are column-major: each stored 4x4 is the transpose.
                binds[s] = np.stack([world(j) for j in skins[s]]) @ ibm[:n].transpose(0, 2, 1), np.array(joints)
        return binds[s]

    drawn = []   # (primitive, its skin matrices and joints, skinned?, label) of each that moves with the rig
    for i, nd in enumerate(nodes):
        if nd.mesh is None:
            continue
        if nd.skin is not None:   # glTF ignores a skinned mesh node's own transform
            bound = skin_binds(reader.check_index(gltf.skins, nd.skin, "skin", f"node {i}"))
        else:                     # moved rigidly by the joint it hangs from
            joint = joint_of(i, False)
            bound = None if joint is None else (world(i)[None], np.array([joint]))
        if bound is None:
            continue
        m = reader.check_index(gltf.meshes, nd.mesh, "mesh", f"node {i}")
        for p, prim in enumerate(gltf.meshes[m].primitives or []):
            if prim.mode in (None, _TRIANGLES) and prim.attributes.POSITION is not None:
                drawn.append((prim, bound, nd.skin is not None, f"mesh {m} primitive {p}"))
    reader.decode_textures({_base_texture(gltf, material, prim.material) for prim, *_, what in drawn
                            if (material := _material(reader, prim, what)) is not None} - {None})
    parts = [part for prim, bound, skinned, what in drawn
             if (part := _primitive(reader, prim, *bound, skinned=skinned, what=what)) is not None and len(part[2])]
    if not parts:
        return None
    base = np.cumsum([0] + [len(part[0]) for part in parts[:-1]])
    positions, normals, triangles, joints, weights, colours = (
        np.concatenate([part[k] + (b if k == 2 else 0) for part, b in zip(parts, base)]) for k in range(6))
    if not (np.isfinite(positions).all() and np.isfinite(normals).all()):
        raise reader.corrupt("its mesh's rest pose is not finite")
    return Mesh(positions.astype(np.float32), normals.astype(np.float32), triangles.astype(np.uint32),
                joints.astype(np.uint16), weights.astype(np.float32), colours.astype(np.float32))


def _primitive(reader: "_Reader", prim, binds: np.ndarray, joint_map: np.ndarray, *, skinned: bool, what: str):
    """One triangle primitive as (positions, normals, triangles, joints, weights, colours) in the rest
    pose; ``binds``: the (rest world x inverse bind) matrix of each skin joint, ``joint_map``: our joint
    for each. None for a skinned node's primitive without skin weights (nothing says where it goes)."""
    a = prim.attributes
    pos = reader.accessor(a.POSITION, f"{what}'s POSITION", ("VEC3",), as_float=True)
    n = len(pos)
    if skinned:
        slots, weights = _influences(reader, a, n, what)
        if slots is None:
            return None
        if slots.size and not 0 <= slots.min() <= slots.max() < len(binds):
            raise reader.corrupt(f"{what} is bound to joints beyond its skin's {len(binds)}")
    else:
        slots, weights = np.zeros((n, 1), np.int64), np.ones((n, 1))
    blend = np.zeros((n, 3, 4))   # each vertex's blend of its joints' matrices (V, 3, 4): glTF skinning at rest
    for k in range(slots.shape[1]):
        blend += weights[:, k, None, None] * binds[slots[:, k], :3]
    positions = np.einsum("vab,vb->va", blend[:, :, :3], pos) + blend[:, :, 3]

    if prim.indices is None:
        if n % 3:
            raise reader.corrupt(f"{what} has {n} vertices and no indices: not whole triangles")
        triangles = np.arange(n).reshape(-1, 3)
    else:
        triangles = reader.accessor(prim.indices, f"{what}'s indices", ("SCALAR",), integer=True).reshape(-1)
        if len(triangles) % 3 or (len(triangles) and not 0 <= triangles.min() <= triangles.max() < n):
            raise reader.corrupt(f"{what}'s indices are not whole triangles of its {n} vertices")
        triangles = triangles.reshape(-1, 3).astype(np.int64)

    if a.NORMAL is None:
        normals = _smooth_normals(positions, triangles)
    else:
        nrm = reader.accessor(a.NORMAL, f"{what}'s NORMAL", ("VEC3",), as_float=True, count=n)
        # The cofactor matrix (the inverse transpose times the determinant) keeps normals normal
        # under any scale or shear the bind matrices carry.
        cols = blend[:, :, :3].transpose(0, 2, 1)
        cofactor = np.cross(cols[:, [1, 2, 0]], cols[:, [2, 0, 1]])
        normals = _unit(np.einsum("vkc,vk->vc", cofactor, nrm))

    joints, weights = _heaviest(joint_map[slots], weights)
    colours, alpha = _albedo(reader, prim, n, what)
    material = _material(reader, prim, what)
    if material is not None and material.alphaMode in ("MASK", "BLEND"):
        # Per-vertex colours cannot be see-through: keep a triangle where it is mostly opaque.
        cutoff = material.alphaCutoff if material.alphaMode == "MASK" and material.alphaCutoff is not None else 0.5
        triangles = triangles[alpha[triangles].mean(axis=1) >= cutoff]
    if material is not None and material.doubleSided:
        # The renderer culls back faces: a double-sided sheet (a skirt, hair cards) gets a turned copy.
        positions, joints, weights, colours = (np.concatenate([x, x]) for x in (positions, joints, weights, colours))
        normals = np.concatenate([normals, -normals])
        triangles = np.concatenate([triangles, triangles[:, ::-1] + n])
    return positions, normals, triangles, joints, weights, colours


def _influences(reader: "_Reader", attributes, n: int, what: str) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Each vertex's skin slots (V, K) and weights (V, K) summing to 1 from JOINTS_0/WEIGHTS_0 (and _1 ...),
    or (None, None) when it has none."""
    slots, weights = [], []
    while (getattr(attributes, f"JOINTS_{len(slots)}", None) is not None
           and getattr(attributes, f"WEIGHTS_{len(slots)}", None) is not None):
        k = len(slots)
        slots.append(reader.accessor(getattr(attributes, f"JOINTS_{k}"), f"{what}'s JOINTS_{k}", ("VEC4",),
                                     integer=True, count=n))
        weights.append(reader.accessor(getattr(attributes, f"WEIGHTS_{k}"), f"{what}'s WEIGHTS_{k}", ("VEC4",),
                                       as_float=True, count=n))
    if not slots:
        return None, None
    slots = np.concatenate(slots, axis=1).astype(np.int64)
    weights = np.clip(np.concatenate(weights, axis=1).astype(np.float64), 0.0, None)
    total = weights.sum(axis=1)
    weights[total <= 0, 0] = 1.0   # an unweighted vertex (invalid, but it happens) follows its first joint
    return slots, weights / weights.sum(axis=1, keepdims=True)


def _heaviest(joints: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each vertex's four heaviest joints (V, 4) (a joint met in several slots counted once, with their
    weights summed) and their weights, renormalised; an unused slot names joint 0 with weight 0."""
    joints, weights = joints.copy(), weights.copy()
    k = joints.shape[1]
    for a in range(k):
        for b in range(a + 1, k):
            same = joints[:, b] == joints[:, a]
            weights[same, a] += weights[same, b]
            weights[same, b] = 0.0
    if k < _MAX_INFLUENCES:
        pad = ((0, 0), (0, _MAX_INFLUENCES - k))
        joints, weights = np.pad(joints, pad), np.pad(weights, pad)
    keep = np.argsort(-weights, axis=1, kind="stable")[:, :_MAX_INFLUENCES]
    joints, weights = np.take_along_axis(joints, keep, 1), np.take_along_axis(weights, keep, 1)
    weights /= weights.sum(axis=1, keepdims=True)
    return np.where(weights > 0, joints, 0), weights


def _albedo(reader: "_Reader", prim, n: int, what: str) -> tuple[np.ndarray, np.ndarray]:
    """Linear RGB (V, 3) and alpha (V,) of a primitive's vertices: base colour factor x COLOR_0 x texture."""
    material = _material(reader, prim, what)
    pbr = material.pbrMetallicRoughness if material is not None else None
    factor = np.ones(4)
    if pbr is not None and pbr.baseColorFactor is not None:
        factor = np.asarray(pbr.baseColorFactor, dtype=np.float64).reshape(4)
    colour = np.tile(factor, (n, 1))
    if prim.attributes.COLOR_0 is not None:
        c = reader.accessor(prim.attributes.COLOR_0, f"{what}'s COLOR_0", ("VEC3", "VEC4"), as_float=True, count=n)
        colour[:, :c.shape[1]] *= c
    texture = _base_texture(reader.gltf, material, prim.material) if material is not None else None
    if texture is not None:
        t, tex_coord, transform = texture
        uv_attr = getattr(prim.attributes, f"TEXCOORD_{tex_coord}", None)
        image = reader.texture(t)
        if image is not None and uv_attr is not None:
            uv = reader.accessor(uv_attr, f"{what}'s TEXCOORD_{tex_coord}", ("VEC2",), as_float=True, count=n)
            if transform is not None:
                m = np.reshape(transform, (2, 3))
                uv = uv @ m[:, :2].T + m[:, 2]
            colour *= _sample(*image, uv)
        elif np.allclose(factor[:3], 1.0):   # nothing says what colour it is
            colour[:, :3] *= _MID_GREY
    elif material is None and prim.attributes.COLOR_0 is None:
        colour[:, :3] = _MID_GREY
    return np.clip(colour[:, :3], 0.0, 1.0), colour[:, 3]


def _material(reader: "_Reader", prim, what: str):
    """A primitive's material, or None (glTF's default material)."""
    if prim.material is None:
        return None
    return reader.gltf.materials[reader.check_index(reader.gltf.materials, prim.material, "material", what)]


def _base_texture(gltf, material, m: int) -> tuple[int, int, tuple | None] | None:
    """(texture, texCoord, UV transform) of a material's base colour: glTF's own (which VRM 1.0's MToon
    uses too), else a VRM 0.x MToon's ``_MainTex`` (its materialProperties entry of the same name, or
    index)."""
    pbr = material.pbrMetallicRoughness
    info = pbr.baseColorTexture if pbr is not None else None
    if info is not None and isinstance(info.index, int):
        tex_coord = info.texCoord if isinstance(info.texCoord, int) else 0
        transform = (info.extensions or {}).get("KHR_texture_transform")
        if isinstance(transform, dict) and isinstance(transform.get("texCoord"), int):
            tex_coord = transform["texCoord"]
        return info.index, tex_coord, _uv_transform(transform)
    vrm = (gltf.extensions or {}).get("VRM")
    props = vrm.get("materialProperties") if isinstance(vrm, dict) else None
    if not isinstance(props, list):
        return None
    props = [e for e in props if isinstance(e, dict)]
    entry = next((e for e in props if material.name and e.get("name") == material.name),
                 props[m] if m < len(props) else {})
    main = (entry.get("textureProperties") or {}).get("_MainTex") if isinstance(entry, dict) else None
    return (main, 0, None) if isinstance(main, int) and not isinstance(main, bool) else None


def _uv_transform(ext) -> tuple[float, ...] | None:
    """A KHR_texture_transform (offset, rotation, scale: atlases, tiling) as the 2x3 matrix, row by row,
    that takes a vertex's UV to where the texture is sampled; None for none (or one that is malformed)."""
    try:
        (ox, oy), r, (sx, sy) = ext.get("offset", (0, 0)), ext.get("rotation", 0), ext.get("scale", (1, 1))
        c, s = np.cos(float(r)), np.sin(float(r))
        return tuple(float(v) for v in (c * sx, s * sy, ox, -s * sx, c * sy, oy))
    except (AttributeError, TypeError, ValueError):
        return None


def _sample(texels: np.ndarray, wrap: tuple[int, int], uv: np.ndarray) -> np.ndarray:
    """Linear RGBA (V, 4) of the texel nearest each UV (glTF's UV origin is the image's top left)."""
    h, w = texels.shape[:2]
    uv = np.clip(np.nan_to_num(uv), -1e6, 1e6)
    x = _wrap(np.floor(uv[:, 0] * w).astype(np.int64), w, wrap[0])
    y = _wrap(np.floor(uv[:, 1] * h).astype(np.int64), h, wrap[1])
    texel = texels[y, x]
    alpha = texel[:, 3:] / np.float32(255) if texel.shape[1] == 4 else np.ones((len(texel), 1), np.float32)
    return np.concatenate([_SRGB_TO_LINEAR[texel[:, :3]], alpha], axis=1)


def _wrap(i: np.ndarray, size: int, mode: int) -> np.ndarray:
    if mode == _CLAMP:
        return np.clip(i, 0, size - 1)
    if mode == _MIRROR:
        i = np.mod(i, 2 * size)
        return np.where(i >= size, 2 * size - 1 - i, i)
    return np.mod(i, size)


def _smooth_normals(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Each vertex's normal as the area-weighted mean of its triangles' (a file may leave them out)."""
    corner = positions[triangles]
    face = np.cross(corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0])   # its length: twice the area
    at = triangles.reshape(-1)
    return _unit(np.stack([np.bincount(at, np.repeat(face[:, k], 3), minlength=len(positions))
                           for k in range(3)], axis=1))


def _unit(v: np.ndarray) -> np.ndarray:
    """Rows made unit length; a zero row (a vertex of no triangle, a degenerate one) points up."""
    size = np.linalg.norm(v, axis=1, keepdims=True)
    return np.where(size > 1e-12, v / np.where(size > 1e-12, size, 1.0), [0.0, 1.0, 0.0])


def _local_matrix(node) -> np.ndarray:
    """A node's local transform as a 4x4 matrix."""
    if node.matrix is not None:
        return np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T   # glTF matrices are column-major
    m = np.eye(4)
    rotation = Rotation.from_quat(node.rotation if node.rotation is not None else [0, 0, 0, 1]).as_matrix()
    m[:3, :3] = rotation * np.asarray(node.scale if node.scale is not None else [1, 1, 1], dtype=np.float64)
    m[:3, 3] = node.translation if node.translation is not None else [0, 0, 0]
    return m


class _Reader:
    """A model's accessors and textures as arrays: its buffers read once, each texture decoded once."""

    def __init__(self, gltf, path: Path):
        self.gltf, self.path = gltf, path
        self._buffers = None
        self._textures: dict[int, tuple[np.ndarray, tuple[int, int]] | None] = {}

    def corrupt(self, detail: str) -> InputError:
        return InputError(f"{self.path.name} is corrupt: {detail}")

    def check_index(self, items, i, kind: str, what: str) -> int:
        if isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < len(items or []):
            raise self.corrupt(f"{what} refers to {kind} {i!r}, which does not exist")
        return i

    @property
    def buffers(self) -> list[bytes]:
        if self._buffers is None:
            self._buffers = buffer_bytes(self.gltf, self.path)
        return self._buffers

    def accessor(self, i, what: str, types: tuple[str, ...], *, integer=False, as_float=False,
                 count: int | None = None) -> np.ndarray:
        """Accessor ``i`` as a (count, components) array, sparse values substituted. ``integer``: it must
        hold integers (indices, joints); ``as_float``: integers become floats as a normalized accessor's
        do (the glTF spec allows only normalized ones there); ``count``: the count it must have."""
        acc = self.gltf.accessors[self.check_index(self.gltf.accessors, i, "accessor", what)]
        dtype = _COMPONENT.get(acc.componentType)
        if acc.type not in types or dtype is None:
            raise self.corrupt(f"{what} is a {acc.type} accessor of component type {acc.componentType}; "
                               f"expected {' or '.join(types)}")
        n = acc.count
        if isinstance(n, bool) or not isinstance(n, int) or n < 0 or (count is not None and n != count):
            raise self.corrupt(f"{what} has {n!r} elements" + (f", not {count}" if count is not None else ""))
        width = _WIDTH[acc.type]
        out = np.zeros((n, width), dtype) if acc.bufferView is None else \
            self._view(acc.bufferView, acc.byteOffset or 0, n, width, dtype, what)
        if acc.sparse is not None and acc.sparse.count:
            sparse = acc.sparse
            at = self._view(sparse.indices.bufferView, sparse.indices.byteOffset or 0, sparse.count, 1,
                            _COMPONENT.get(sparse.indices.componentType, "<f4"), f"{what}'s sparse indices").ravel()
            if at.dtype.kind != "u" or at.max() >= n:
                raise self.corrupt(f"{what}'s sparse indices are not indices of its {n} elements")
            out = out.copy()
            out[at] = self._view(sparse.values.bufferView, sparse.values.byteOffset or 0, sparse.count, width,
                                 dtype, f"{what}'s sparse values")
        if integer and out.dtype.kind == "f":
            raise self.corrupt(f"{what} holds floats where integers belong")
        if out.dtype.kind != "f" and not integer and (acc.normalized or as_float):
            out = np.maximum(out / np.float32(np.iinfo(out.dtype).max), -1.0).astype(np.float32)
        return out

    def _view(self, v, offset: int, count: int, width: int, dtype: str, what: str) -> np.ndarray:
        """``count`` elements of ``width`` components read from bufferView ``v`` at ``offset``, its stride
        honoured (a read-only view of the buffer)."""
        view = self.gltf.bufferViews[self.check_index(self.gltf.bufferViews, v, "bufferView", what)]
        data = self.buffers[self.check_index(self.buffers, view.buffer, "buffer", f"bufferView {v}")]
        item = np.dtype(dtype).itemsize
        stride = view.byteStride or width * item
        start, end = (view.byteOffset or 0), (view.byteOffset or 0) + (view.byteLength or 0)
        need = start + offset + (stride * (count - 1) + width * item if count else 0)
        if offset < 0 or stride < width * item or need > end or end > len(data):
            raise self.corrupt(f"{what} runs past the end of bufferView {v} or its buffer")
        return np.ndarray((count, width), dtype, data, start + offset, (stride, item))

    def texture(self, t: int) -> tuple[np.ndarray, tuple[int, int]] | None:
        """Texture ``t`` as (H, W, 3 or 4) uint8 sRGB(A) texels and its (S, T) wrap modes; None when it
        cannot be read (a missing file, an unknown format such as KTX2), and the caller draws it grey."""
        if t not in self._textures:
            self._textures[t] = None
            textures = self.gltf.textures or []
            if 0 <= t < len(textures):
                tex = textures[t]
                # A WebP or DDS version in an extension comes first; PIL reads those.
                sources = [e.get("source") for e in (tex.extensions or {}).values() if isinstance(e, dict)]
                image = next((im for im in map(self._image, sources + [tex.source]) if im is not None), None)
                samplers = self.gltf.samplers or []
                sampler = samplers[tex.sampler] if isinstance(tex.sampler, int) and 0 <= tex.sampler < len(samplers) \
                    else None
                wrap = (sampler.wrapS, sampler.wrapT) if sampler is not None else (None, None)
                self._textures[t] = None if image is None else (image, wrap)
        return self._textures[t]

    def decode_textures(self, textures) -> None:
        """Decode these (texture, ...) side by side: decoding (PNG's zlib) is the slow part of
        loading an avatar, and Pillow lets go of the GIL while it decodes."""
        from concurrent.futures import ThreadPoolExecutor

        if not textures:
            return
        _ = self.buffers   # read once, before the threads share them
        with ThreadPoolExecutor(max_workers=min(8, os.cpu_count() or 1)) as pool:
            list(pool.map(self.texture, {t for t, *_ in textures}))

    def _image(self, i) -> np.ndarray | None:
        from PIL import Image

        images = self.gltf.images or []
        if isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < len(images):
            return None
        image = images[i]
        try:
            if image.bufferView is not None:
                view = self.gltf.bufferViews[image.bufferView]
                start = view.byteOffset or 0
                data = self.buffers[view.buffer][start:start + view.byteLength]
            elif image.uri:
                data = read_uri(image.uri, self.path.parent, self.path.name)
            else:
                return None
            with Image.open(io.BytesIO(data)) as img:
                return np.asarray(img if img.mode in ("RGB", "RGBA") else img.convert("RGBA"))
        except Exception:  # noqa: BLE001 -- decoders fail in many ways; an unreadable texture is drawn grey
            return None

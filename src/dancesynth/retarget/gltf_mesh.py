"""A user's model's meshes as the ``Mesh`` videos draw, bound to the character's skeleton.

Every triangle primitive skinned to the rig is used, plus any unskinned mesh hanging from one of
its joints (glasses on the head; every part of a VRM made without a skin), put in the rest pose as
glTF skinning does (each vertex by its joints' rest world transforms times their inverse bind
matrices; an unskinned mesh by its node's rest world transform), so it lands in the skeleton's
frame in metres. Each vertex keeps its four heaviest joints, a skin joint outside the skeleton
counted as its nearest ancestor in it. Colours are the material's base colour (factor x COLOR_0 x
the texture at the vertex's UV, nearest texel; a VRM 0.x MToon's ``_MainTex`` when the glTF
material has none), linear RGB; a texture that cannot be read, or of more than
``MAX_TEXTURE_PIXELS``, is drawn mid grey, and one larger than ``KEPT_TEXTURE_SIDE`` on a side is
averaged down to it (a vertex's colour needs no more). Triangles of
see-through material (alpha MASK or BLEND) whose corners are mostly transparent are dropped, and
double-sided ones get a back face, as the renderer culls.
"""

from __future__ import annotations

import io
import os
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from .character import Mesh
from .gltf_file import GltfReader

_TRIANGLES, _CLAMP, _MIRROR = 4, 33071, 33648    # primitive mode, sampler wrap modes (REPEAT: the rest)
_SRGB_TO_LINEAR = np.where(np.arange(256) <= 10, np.arange(256) / 255 / 12.92,
                           ((np.arange(256) / 255 + 0.055) / 1.055) ** 2.4).astype(np.float32)
_MID_GREY = float(_SRGB_TO_LINEAR[128])           # what a texture that cannot be read is drawn as
_MAX_INFLUENCES = 4
MAX_TEXTURE_PIXELS = 8192 * 4096   # decoded at most (a 4096 x 4096 RGBA texture is 64 MB in memory)
KEPT_TEXTURE_SIDE = 2048
TEXTURE_FORMATS = ("PNG", "JPEG", "WEBP", "DDS")   # what glTF and its extensions carry; no other decoder runs
MAX_VERTICES = 2_000_000           # drawn in all (an avatar has 10^4-10^5)


def user_mesh(gltf, path: Path, skins: list[list[int]], index: dict[int, int], ancestors, above: set) -> Mesh | None:
    """The model's meshes that move with the skeleton (``index``: node -> joint), in the rest pose in
    world metres; None when no mesh does (videos then draw a stick figure)."""
    reader = _MeshReader(gltf, path)
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
    if sum(len(part[0]) for part in parts) > MAX_VERTICES:
        raise reader.corrupt(f"its meshes have over {MAX_VERTICES} vertices; a character is drawn with at most that many")
    base = np.cumsum([0] + [len(part[0]) for part in parts[:-1]])
    positions, normals, triangles, joints, weights, colours = (
        np.concatenate([part[k] + (b if k == 2 else 0) for part, b in zip(parts, base)]) for k in range(6))
    if not (np.isfinite(positions).all() and np.isfinite(normals).all()):
        raise reader.corrupt("its mesh's rest pose is not finite")
    return Mesh(positions.astype(np.float32), normals.astype(np.float32), triangles.astype(np.uint32),
                joints.astype(np.uint16), weights.astype(np.float32), colours.astype(np.float32))


def _primitive(reader: "_MeshReader", prim, binds: np.ndarray, joint_map: np.ndarray, *, skinned: bool, what: str):
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


def _influences(reader: "_MeshReader", attributes, n: int, what: str) -> tuple[np.ndarray | None, np.ndarray | None]:
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


def _albedo(reader: "_MeshReader", prim, n: int, what: str) -> tuple[np.ndarray, np.ndarray]:
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


def _material(reader: "_MeshReader", prim, what: str):
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


class _MeshReader(GltfReader):
    """A ``GltfReader`` that also decodes textures, each once."""

    def __init__(self, gltf, path: Path):
        super().__init__(gltf, path)
        self._textures: dict[int, tuple[np.ndarray, tuple[int, int]] | None] = {}

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
        with warnings.catch_warnings(), ThreadPoolExecutor(max_workers=min(4, os.cpu_count() or 1)) as pool:
            warnings.simplefilter("ignore")   # a decoder's complaint about a texture is not the user's error
            list(pool.map(self.texture, {t for t, *_ in textures}))

    def _image(self, i) -> np.ndarray | None:
        from PIL import Image

        if isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < len(self.gltf.images or []):
            return None
        try:
            data = self.image_bytes(i)
            if data is None:
                return None
            with Image.open(io.BytesIO(data), formats=TEXTURE_FORMATS) as img:
                if img.width * img.height > MAX_TEXTURE_PIXELS:   # read from the header: nothing decoded yet
                    return None
                img.draft("RGB", (KEPT_TEXTURE_SIDE, KEPT_TEXTURE_SIDE))   # a JPEG decodes smaller at once
                rgb = img if img.mode in ("RGB", "RGBA") else img.convert("RGBA")
                factor = -(-max(rgb.size) // KEPT_TEXTURE_SIDE)
                return np.asarray(rgb.reduce(factor) if factor > 1 else rgb)
        except Exception:  # noqa: BLE001 -- decoders fail in many ways; an unreadable texture is drawn grey
            return None

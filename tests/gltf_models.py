"""Rigged models written the way other tools write them, for the character tests: an FBX-style
centimetre armature turned Z-up, rest rotations on every joint, VRM 0.x turned to face -Z, VRM 1.0,
external buffers or data URIs -- not by our exporter."""

from __future__ import annotations

import base64

import numpy as np
from scipy.spatial.transform import Rotation

from dancesynth.kinematics import fk
from dancesynth.retarget.character import Mesh
from dancesynth.retarget.rigs import rig_skeleton
from dancesynth.rotations import IDENTITY

MANNEQUIN, MANNEQUIN_BONES = rig_skeleton("mannequin")
TURN = Rotation.from_euler("y", 180, degrees=True)     # VRM 0.x models face -Z


def rest_positions(skeleton, rest_rot=None, rest_root=None) -> np.ndarray:
    rest_rot = np.tile(IDENTITY, (skeleton.n_joints, 1)) if rest_rot is None else rest_rot
    rest_root = skeleton.offsets[0] if rest_root is None else rest_root
    return fk(rest_rot, rest_root, skeleton.offsets, skeleton.parents)[1]


def stick_mesh(skeleton) -> Mesh:
    """A box round every bone (and End Site), each rigidly bound to the bone's top joint: a tiny test body."""
    p = rest_positions(skeleton)
    segments = [(skeleton.parents[j], p[skeleton.parents[j]], p[j]) for j in range(1, skeleton.n_joints)]
    segments += [(j, p[j], p[j] + tip) for j, tip in skeleton.end_sites.items()]
    positions, indices, joints = [], [], []
    for owner, a, b in segments:
        d = b - a
        u = np.cross(d, [0.0, 0.0, 1.0] if abs(d[2]) < 0.9 * np.linalg.norm(d) else [1.0, 0.0, 0.0])
        u = 0.03 * u / np.linalg.norm(u)
        v = 0.03 * np.cross(d, u) / np.linalg.norm(np.cross(d, u))
        corners = [a + e * d + s * u + t * v for e in (0, 1) for s in (-1, 1) for t in (-1, 1)]
        centre = (a + b) / 2
        base = len(positions)
        for quad in ((0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)):
            for tri in ((quad[0], quad[1], quad[2]), (quad[0], quad[2], quad[3])):
                x = [corners[k] for k in tri]
                if np.dot(np.cross(x[1] - x[0], x[2] - x[0]), np.mean(x, axis=0) - centre) < 0:
                    tri = tri[::-1]   # counter-clockwise seen from outside
                indices.append([base + k for k in tri])
        positions += corners
        joints += [owner] * 8
    positions = np.array(positions, np.float32)
    centres = np.repeat(np.array([(a + b) / 2 for _, a, b in segments]), 8, axis=0)
    normals = (positions - centres) / np.linalg.norm(positions - centres, axis=1, keepdims=True)
    joints = np.array(joints)
    colours = np.stack([0.3 + 0.6 * (joints % 3 == 0), 0.3 + 0.6 * (joints % 3 == 1), 0.3 + 0.6 * (joints % 3 == 2)],
                       axis=1)
    return Mesh(positions, normals.astype(np.float32), np.array(indices, np.uint32),
                np.stack([joints, 0 * joints, 0 * joints, 0 * joints], axis=1).astype(np.uint16),
                np.tile([1.0, 0.0, 0.0, 0.0], (len(joints), 1)).astype(np.float32), colours.astype(np.float32))


def write_model(path, skeleton, mesh, *, turn=False, armature=None, twist=False, names=None, extensions=None,
                buffers="glb", mesh_in_armature=False, skin=True) -> list[int]:
    """Write ``skeleton`` (standing in its T-pose) with ``mesh`` skinned to it as another tool would, and
    return each joint's node index.

    ``turn``: face -Z (VRM 0.x); ``armature``: (rotation, scale) of an "Armature" node above the hips (the
    joints' translations are then in its units, as FBX conversions have them); ``twist``: give every joint
    a rest rotation of its own (the world rest pose stays the T-pose); ``names``: node names (None: none);
    ``extensions``: a function of the joint -> node list returning the glTF extensions (VRM tables);
    ``buffers``: "glb", "external" (.gltf + .bin) or "datauri" (.gltf, base64 buffer); ``mesh_in_armature``:
    the mesh node hangs from the armature with its vertices in the armature's frame and units, and the
    inverse bind matrices take them there (as Blender writes an FBX conversion); ``skin``: False writes no
    skin but hangs each joint's part of the (rigid) mesh from the joint as a mesh of its own, on a node
    squashed by a non-uniform scale (as VRM samples made without a skin have them)."""
    import pygltflib as g

    turned = TURN if turn else Rotation.identity()
    x = turned.apply(rest_positions(skeleton))
    n = skeleton.n_joints
    world = Rotation.random(n, random_state=7) if twist else Rotation.from_quat(np.tile(IDENTITY, (n, 1)))
    arm_rot, arm_scale = armature if armature else (Rotation.identity(), 1.0)
    scale = np.atleast_1d(arm_scale).astype(float)
    first = 2 if armature else 1
    node_of = list(range(first, first + n))
    nodes = [g.Node(name="Body", mesh=0, skin=0) if skin else g.Node(name="Body")]
    if armature:
        nodes.append(g.Node(name="Armature", rotation=arm_rot.as_quat().tolist(),
                            scale=(scale if len(scale) == 3 else np.repeat(scale, 3)).tolist(),
                            children=[2, 0] if mesh_in_armature else [2]))
    mesh_rot, mesh_scale = (arm_rot, scale[0]) if mesh_in_armature else (Rotation.identity(), 1.0)
    to_mesh = np.eye(4)   # the mesh's frame in the world
    to_mesh[:3, :3] = mesh_rot.as_matrix() * mesh_scale
    for j in range(n):
        p = skeleton.parents[j]
        parent_rot, parent_pos = (arm_rot, np.zeros(3)) if p < 0 else (world[p], x[p])
        t = parent_rot.inv().apply(x[j] - parent_pos) / scale[0]
        nodes.append(g.Node(name=None if names is None else names[j], translation=t.tolist(),
                            rotation=(parent_rot.inv() * world[j]).as_quat().tolist(),
                            children=[node_of[c] for c in skeleton.children(j)]))
    joint_world = np.tile(np.eye(4), (n, 1, 1))   # each joint's world transform
    joint_world[:, :3, :3], joint_world[:, :3, 3] = world.as_matrix() * scale[0], x

    blob, views, accessors = bytearray(), [], []

    def accessor(array, kind, component, target=None, bounds=False):
        data = np.ascontiguousarray(array)
        views.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=data.nbytes, target=target))
        blob.extend(data.tobytes())
        blob.extend(b"\0" * (-len(blob) % 4))
        extra = {"min": data.min(axis=0).tolist(), "max": data.max(axis=0).tolist()} if bounds else {}
        accessors.append(g.Accessor(bufferView=len(views) - 1, componentType=component, count=len(data), type=kind,
                                    **extra))
        return len(accessors) - 1

    def primitive(keep, frame):
        """A primitive of ``mesh``'s vertices where ``keep`` (and the triangles among them) on a node whose
        world transform is ``frame``."""
        at = np.flatnonzero(keep)
        tris = (np.cumsum(keep) - 1)[mesh.indices[keep[mesh.indices].all(axis=1)]]
        pos = np.linalg.solve(frame[:3, :3], (turned.apply(mesh.positions[at]) - frame[:3, 3]).T).T
        nrm = turned.apply(mesh.normals[at]) @ frame[:3, :3]     # the inverse transpose's inverse
        nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
        attributes = g.Attributes(POSITION=accessor(pos.astype(np.float32), g.VEC3, g.FLOAT, g.ARRAY_BUFFER,
                                                    bounds=True),
                                  NORMAL=accessor(nrm.astype(np.float32), g.VEC3, g.FLOAT, g.ARRAY_BUFFER),
                                  COLOR_0=accessor(mesh.colours[at], g.VEC3, g.FLOAT, g.ARRAY_BUFFER))
        if skin:
            attributes.JOINTS_0 = accessor(mesh.joints[at].astype(np.uint16), g.VEC4, g.UNSIGNED_SHORT,
                                           g.ARRAY_BUFFER)
            attributes.WEIGHTS_0 = accessor(mesh.weights[at], g.VEC4, g.FLOAT, g.ARRAY_BUFFER)
        tris = accessor(tris.reshape(-1).astype(np.uint32), g.SCALAR, g.UNSIGNED_INT, g.ELEMENT_ARRAY_BUFFER)
        return g.Mesh(primitives=[g.Primitive(attributes=attributes, indices=tris, material=0)])

    if skin:
        meshes = [primitive(np.ones(len(mesh.positions), bool), to_mesh)]
        ibm = (np.linalg.inv(joint_world) @ to_mesh).transpose(0, 2, 1)   # column-major
        skins = [g.Skin(joints=node_of, inverseBindMatrices=accessor(ibm.reshape(n, 16).astype(np.float32),
                                                                     g.MAT4, g.FLOAT))]
    else:
        assert (mesh.weights[:, 0] == 1).all(), "a mesh hung from bones is rigid"
        meshes, skins, squash = [], [], np.array([1.0, 2.0, 0.5])
        for j in np.unique(mesh.joints[:, 0]):
            meshes.append(primitive(mesh.joints[:, 0] == j, joint_world[j] @ np.diag([*squash, 1.0])))
            nodes[node_of[j]].children.append(len(nodes))
            nodes.append(g.Node(name=f"{nodes[node_of[j]].name or 'joint'} mesh", mesh=len(meshes) - 1,
                                scale=squash.tolist()))
    extensions = extensions(node_of) if extensions else {}
    gltf = g.GLTF2(asset=g.Asset(version="2.0", generator="dancesynth tests"), scene=0,
                   scenes=[g.Scene(nodes=[1] if mesh_in_armature else [0, 1])], nodes=nodes, skins=skins, meshes=meshes,
                   materials=[g.Material(pbrMetallicRoughness=g.PbrMetallicRoughness(metallicFactor=0.0))],
                   accessors=accessors, bufferViews=views, buffers=[g.Buffer(byteLength=len(blob))],
                   extensions=extensions, extensionsUsed=list(extensions))
    if buffers == "glb":
        gltf.set_binary_blob(bytes(blob))
        path.write_bytes(b"".join(gltf.save_to_bytes()))
    else:
        if buffers == "external":
            path.with_suffix(".bin").write_bytes(bytes(blob))
            gltf.buffers[0].uri = path.with_suffix(".bin").name
        else:
            gltf.buffers[0].uri = "data:application/octet-stream;base64," + base64.b64encode(bytes(blob)).decode()
        path.write_text(gltf.gltf_to_json())
    return node_of


def vrm0_extension(bones: dict[str, int]):
    """A VRM 0.x extension (meta and humanoid) for ``bones`` (bone -> joint)."""
    def make(node_of):
        return {"VRM": {"exporterVersion": "dancesynth-tests", "specVersion": "0.0",
                        "meta": {"title": "mannequin 0.x", "version": "1", "author": "dancesynth",
                                 "allowedUserName": "Everyone", "violentUssageName": "Disallow",
                                 "sexualUssageName": "Disallow", "commercialUssageName": "Allow",
                                 "licenseName": "CC0"},
                        "humanoid": {"humanBones": [{"bone": b, "node": node_of[j], "useDefaultValues": True}
                                                    for b, j in bones.items()]},
                        "blendShapeMaster": {"blendShapeGroups": []},
                        "secondaryAnimation": {"boneGroups": [], "colliderGroups": []},
                        "materialProperties": []}}
    return make


def vrm1_extension(bones: dict[str, int], name: str = "mannequin 1.0"):
    """A VRM 1.0 extension (meta name and humanoid) for ``bones`` (bone -> joint)."""
    def make(node_of):
        return {"VRMC_vrm": {"specVersion": "1.0", "meta": {"name": name},
                             "humanoid": {"humanBones": {b: {"node": node_of[j]} for b, j in bones.items()}}}}
    return make


def write_vrm0_mannequin(path) -> list[int]:
    """The mannequin (its mesh and rig) as a VRM 0.x avatar: identity rest rotations, turned to face -Z,
    extension "VRM"."""
    from dancesynth.retarget.mannequin import mannequin_character

    return write_model(path, MANNEQUIN, mannequin_character().mesh, turn=True, names=MANNEQUIN.names,
                       extensions=vrm0_extension(MANNEQUIN_BONES))


def write_skinless_vrm(path, version="1.0") -> list[int]:
    """The mannequin as a VRM avatar (``version`` "1.0" or "0.x", facing -Z; None: a plain glTF) made
    without a skin: a box round each bone, hung from the bone's node as a mesh of its own (on a squashed
    child node), rest rotations on every joint."""
    extensions = {"1.0": vrm1_extension(MANNEQUIN_BONES, "skinless"), "0.x": vrm0_extension(MANNEQUIN_BONES),
                  None: None}[version]
    return write_model(path, MANNEQUIN, stick_mesh(MANNEQUIN), turn=version == "0.x", twist=True,
                       names=MANNEQUIN.names, extensions=extensions, skin=False)


def fbx_style_model(path, buffers="glb", names=None, mesh_in_armature=False) -> list[int]:
    """The Mixamo layout as an FBX conversion writes it: a Z-up "Armature" at 0.01 (joints in centimetres),
    a rest rotation on every joint; ``mesh_in_armature``: see ``write_model``."""
    mixamo, _ = rig_skeleton("mixamo")
    return write_model(path, mixamo, stick_mesh(mixamo), armature=(Rotation.from_euler("x", 90, degrees=True), 0.01),
                       twist=True, names=mixamo.names if names is None else names, buffers=buffers,
                       mesh_in_armature=mesh_in_armature)

"""A user's own rigged model (issue 14): glTF, GLB and VRM 0.x / 1.0 files load as characters with the
skeleton, rest pose and humanoid bones they hold, in metres whatever units and armature they use; broken
files fail in one clear line; and our dance added to such a file (``onto_model``) plays back, in an
independent reader and in three.js, with every joint where our forward kinematics puts it.

The models are written here the way other tools write them (an FBX-style centimetre armature turned
Z-up, rest rotations on every joint, VRM 0.x turned to face -Z, external buffers), not by our exporter.
"""

from __future__ import annotations

import base64
import io
import json
import shutil
import subprocess

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import REPO
from dancesynth.errors import InputError
from dancesynth.export.onto_model import onto_model_bytes
from dancesynth.kinematics import fk
from dancesynth.retarget.character import Mesh
from dancesynth.retarget.gltf_character import load_gltf_character
from dancesynth.retarget.gltf_file import open_gltf
from dancesynth.retarget.rigs import rig_skeleton
from dancesynth.rotations import IDENTITY, about_y, exp, mul
from dancesynth.types import MotionClip

CLIENTS = REPO / "tests" / "clients"
MANNEQUIN, MANNEQUIN_BONES = rig_skeleton("mannequin")
TURN = Rotation.from_euler("y", 180, degrees=True)     # VRM 0.x models face -Z
needs_node = pytest.mark.skipif(shutil.which("node") is None or not (CLIENTS / "node_modules" / "three").is_dir(),
                                reason="needs node and the npm clients (bash scripts/setup.sh --test installs them)")
has_validator = shutil.which("node") is not None and (CLIENTS / "node_modules" / "gltf-validator").is_dir()
needs_validator = pytest.mark.skipif(not has_validator, reason="needs node and the npm gltf-validator (bash "
                                     "scripts/setup.sh --test installs them)")


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


def assert_same_rest(character, skeleton, turn=False):
    """``character`` holds ``skeleton``'s joints, standing as it does (turned to -Z if ``turn``)."""
    assert character.skeleton.names == skeleton.names
    assert list(character.skeleton.parents) == list(skeleton.parents)
    ours = rest_positions(character.skeleton, character.rest_rot, character.rest_root)
    expected = rest_positions(skeleton)
    expected = TURN.apply(expected) if turn else expected
    assert np.abs(ours - expected).max() < 1e-5


def test_a_vrm0_avatar_loads_with_its_humanoid_bones_facing_minus_z(tmp_path):
    path = tmp_path / "avatar.vrm"
    node_of = write_vrm0_mannequin(path)
    character = load_gltf_character(path)
    assert character.kind == "vrm0" and character.name == "mannequin 0.x" and character.source == path
    assert character.bones == MANNEQUIN_BONES
    assert character.nodes == tuple(node_of)
    assert_same_rest(character, MANNEQUIN, turn=True)
    assert np.allclose(character.rest_rot, IDENTITY) and np.allclose(character.armature, np.eye(4))


def test_a_vrm1_avatar_with_rest_rotations_on_its_joints_loads_its_rest_pose(tmp_path):
    path = tmp_path / "avatar.vrm"
    write_model(path, MANNEQUIN, stick_mesh(MANNEQUIN), twist=True, names=MANNEQUIN.names,
                extensions=vrm1_extension(MANNEQUIN_BONES, "twisted"))
    character = load_gltf_character(path)
    assert character.kind == "vrm1" and character.name == "twisted"
    assert character.bones == MANNEQUIN_BONES
    assert_same_rest(character, MANNEQUIN)
    assert not np.allclose(character.rest_rot, IDENTITY)


@pytest.mark.parametrize("version, kind", [("1.0", "vrm1"), ("0.x", "vrm0")])
def test_a_vrm_avatar_without_a_skin_has_its_humanoid_bones_as_its_skeleton(tmp_path, version, kind):
    path = tmp_path / "skinless.vrm"
    node_of = write_skinless_vrm(path, version)
    character = load_gltf_character(path)
    assert character.kind == kind
    assert character.bones == MANNEQUIN_BONES and character.nodes == tuple(node_of)
    assert_same_rest(character, MANNEQUIN, turn=version == "0.x")
    assert character.mesh is not None     # its boxes, each on its bone (test_user_mesh checks where)


def test_an_fbx_style_model_in_centimetres_under_a_turned_armature_comes_out_in_metres(tmp_path):
    from dancesynth.retarget.character import load_character

    path = tmp_path / "mixamo.glb"
    fbx_style_model(path)
    character = load_gltf_character(path)
    mixamo, mixamo_bones = rig_skeleton("mixamo")
    assert character.kind == "gltf" and character.bones == {} and character.name == "mixamo"
    assert_same_rest(character, mixamo)
    expected = np.eye(4)
    expected[:3, :3] = 0.01 * Rotation.from_euler("x", 90, degrees=True).as_matrix()
    assert np.allclose(character.armature, expected)
    # The caller finds the bones by the joints' names.
    assert load_character(path).bones == mixamo_bones


@pytest.mark.parametrize("buffers", ["external", "datauri"])
def test_a_gltf_with_its_buffer_in_a_file_or_a_data_uri_loads(tmp_path, buffers):
    path = tmp_path / "model.gltf"
    fbx_style_model(path, buffers=buffers)
    assert_same_rest(load_gltf_character(path), rig_skeleton("mixamo")[0])


def test_missing_and_repeated_node_names_become_unique_joint_names(tmp_path):
    path = tmp_path / "names.glb"
    mixamo, _ = rig_skeleton("mixamo")
    names = [None if j % 5 == 1 else "Bone" if j % 5 == 2 else nm for j, nm in enumerate(mixamo.names)]
    node_of = fbx_style_model(path, names=names)
    got = load_gltf_character(path).skeleton.names
    assert len(set(got)) == len(got) == mixamo.n_joints
    for j, (name, node) in enumerate(zip(got, node_of)):
        assert name == {1: f"node{node}", 2: f"Bone_node{node}"}.get(j % 5, mixamo.names[j])


def _skinless(path):
    from dancesynth.export.gltf import glb_bytes

    path.write_bytes(glb_bytes(wiggle(MANNEQUIN, np.tile(IDENTITY, (MANNEQUIN.n_joints, 1)), MANNEQUIN.offsets[0])))


def _truncated(path):
    write_vrm0_mannequin(path)
    path.write_bytes(path.read_bytes()[:3000])


def _json_edit(edit):
    def make(path):
        fbx_style_model(path.with_suffix(".gltf"), buffers="datauri")
        doc = json.loads(path.with_suffix(".gltf").read_text())
        edit(doc)
        path.write_text(json.dumps(doc))
    return make


def _non_uniform(doc):
    doc["nodes"][1]["scale"] = [0.01, 0.02, 0.01]


def _joint_out_of_range(doc):
    doc["skins"][0]["joints"][3] = 999


def _cycle(doc):
    doc["nodes"][5]["children"].append(2)


def _mesh_edit(edit):
    """A ``_json_edit`` of the mesh's first primitive's attributes."""
    return _json_edit(lambda doc: edit(doc, doc["meshes"][0]["primitives"][0]["attributes"]))


BROKEN = {
    "skinless.glb": (_skinless, ["no skin", "rigged"]),
    "meshes-on-nodes.glb": (lambda p: write_skinless_vrm(p, version=None), ["no skin", "rigged"]),
    "truncated.vrm": (_truncated, ["truncated"]),
    "random.glb": (lambda p: p.write_bytes(np.random.default_rng(1).bytes(5000)), ["not a glTF"]),
    "hello.gltf": (lambda p: p.write_text('{"hello": [1, 2]}'), ["not a glTF 2.0"]),
    "empty.glb": (lambda p: p.write_bytes(b""), ["not a glTF"]),
    "short.glb": (lambda p: p.write_bytes(b"glTF\x02\0\0\0"), ["truncated"]),
    "squashed.gltf": (_json_edit(_non_uniform), ["non-uniform", "Armature", "apply"]),
    "dangling.gltf": (_json_edit(_joint_out_of_range), ["corrupt", "999"]),
    "cycle.gltf": (_json_edit(_cycle), ["corrupt"]),
    "wrongtype.gltf": (_json_edit(lambda d: d["nodes"][3].update(translation="up")), ["not a valid glTF"]),
    "badindices.gltf": (_json_edit(lambda d: d["meshes"][0]["primitives"][0].update(indices=999)),
                       ["corrupt", "indices", "accessor 999"]),
    "shortview.gltf": (_mesh_edit(lambda d, a: d["bufferViews"][d["accessors"][a["NORMAL"]]["bufferView"]].update(
        byteLength=100)), ["corrupt", "NORMAL", "past the end"]),
    "floatjoints.gltf": (_mesh_edit(lambda d, a: a.update(JOINTS_0=a["WEIGHTS_0"])),
                         ["corrupt", "JOINTS_0", "floats"]),
    "vec2normals.gltf": (_mesh_edit(lambda d, a: d["accessors"][a["NORMAL"]].update(type="VEC2")),
                         ["corrupt", "NORMAL", "VEC3"]),
}


@pytest.mark.parametrize("name", BROKEN)
def test_a_broken_or_unrigged_file_is_one_clear_line(tmp_path, name):
    make, words = BROKEN[name]
    path = tmp_path / name
    make(path)
    with pytest.raises(InputError) as err:
        load_gltf_character(path)
    message = str(err.value)
    assert "\n" not in message and name in message, message
    for w in words:
        assert w.lower() in message.lower(), message


def test_a_missing_buffer_file_is_a_clear_error_when_the_dance_is_added(tmp_path):
    path = tmp_path / "model.gltf"
    fbx_style_model(path, buffers="external")
    character = load_gltf_character(path)
    path.with_suffix(".bin").unlink()
    with pytest.raises(InputError, match="model.bin"):
        onto_model_bytes(character, wiggle(character.skeleton, character.rest_rot, character.rest_root))


# --- the dance on the user's own model ---------------------------------------------------------------

def wiggle(skeleton, rest_rot, rest_root, n_frames=45, fps=30.0) -> MotionClip:
    """Every joint swinging about its own axis on top of its rest rotation; the root turning and travelling."""
    t = np.arange(n_frames) / fps
    rng = np.random.default_rng(3)
    axes = rng.normal(size=(skeleton.n_joints, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    swing = exp(0.5 * np.sin(2 * np.pi * 1.3 * t)[:, None, None] * axes[None])
    local = mul(np.broadcast_to(rest_rot, swing.shape), swing)
    local[:, 0] = mul(about_y(0.8 * t), local[:, 0])
    root = rest_root + np.stack([0.3 * np.sin(t), 0.05 * np.sin(4 * t), 0.2 * t], axis=1)
    return MotionClip(skeleton, fps, root, local)


def node_world_poses(path, animation="dance") -> dict[str, tuple[Rotation, np.ndarray]]:
    """Every named node's world rotation (F) and position (F, 3) at each key of ``animation``, from the
    file alone (pygltflib's arrays, SciPy's rotations, node scales applied)."""
    import pygltflib

    gltf = pygltflib.GLTF2.load_from_bytes(path.read_bytes())
    blob = gltf.binary_blob()

    def values(index):
        acc = gltf.accessors[index]
        view = gltf.bufferViews[acc.bufferView]
        width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[acc.type]
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        return np.frombuffer(blob, np.float32, acc.count * width, start).reshape(acc.count, width)

    anim = next(a for a in gltf.animations if a.name == animation)
    n = len(values(anim.samplers[0].input))
    trs = [[np.tile(nd.translation or [0, 0, 0], (n, 1)), np.tile(nd.rotation or [0, 0, 0, 1], (n, 1)),
            np.tile(nd.scale or [1, 1, 1], (n, 1))] for nd in gltf.nodes]
    for ch in anim.channels:
        trs[ch.target.node][{"translation": 0, "rotation": 1}[ch.target.path]] = \
            values(anim.samplers[ch.sampler].output).astype(np.float64)
    out = {}

    def walk(i, rot, pos, scale):
        t, q, s = trs[i]
        pos = pos + rot.apply(scale * t)
        rot, scale = rot * Rotation.from_quat(q), scale * s
        out[gltf.nodes[i].name] = rot, pos
        for c in gltf.nodes[i].children or []:
            walk(c, rot, pos, scale)

    for root in gltf.scenes[gltf.scene].nodes:
        walk(root, Rotation.from_quat(np.tile(IDENTITY, (n, 1))), np.zeros((n, 3)), np.ones((n, 3)))
    return out


USERS_MODELS = {"fbx.gltf": lambda path: fbx_style_model(path, buffers="external"),
                "avatar.vrm": write_vrm0_mannequin, "skinless.vrm": write_skinless_vrm}


@pytest.fixture(params=USERS_MODELS)
def users_model(request, tmp_path):
    """A user's model (an FBX-style glTF with an external buffer, a VRM 0.x avatar, a VRM 1.0 one without a
    skin), its character and a dance."""
    path = tmp_path / request.param
    USERS_MODELS[request.param](path)
    character = load_gltf_character(path)
    clip = wiggle(character.skeleton, character.rest_rot, character.rest_root)
    out = tmp_path / "danced.glb"
    out.write_bytes(onto_model_bytes(character, clip))
    return path, character, clip, out


def test_the_dance_added_to_a_users_model_puts_every_joint_where_we_do(users_model):
    import pygltflib

    path, character, clip, out = users_model
    assert_joints_where_we_have_them(out, character, clip)
    source, before, after = open_gltf(path), load_gltf_character(path), pygltflib.GLTF2.load(str(out))
    assert [a.name for a in after.animations] == ["dance"] and len(after.buffers) == 1
    assert after.buffers[0].uri is None
    assert len(after.meshes) == len(source.meshes) and len(after.skins) == len(source.skins or [])
    assert after.extensions == source.extensions     # the VRM table is kept
    assert load_gltf_character(out).skeleton.names == before.skeleton.names


def assert_joints_where_we_have_them(out, character, clip):
    """Every joint of the dance in ``out`` is where our forward kinematics of ``clip`` puts it."""
    _, ours = fk(clip.local_rot, clip.root_pos, character.skeleton.offsets, character.skeleton.parents)
    got = node_world_poses(out)
    theirs = np.stack([got[character.skeleton.names[j]][1] for j in range(character.skeleton.n_joints)], axis=1)
    assert theirs.shape == ours.shape
    assert np.abs(theirs - ours).max() < 1e-4      # metres, every joint, every frame


@needs_validator
def test_the_khronos_validator_finds_no_error_in_a_model_with_our_dance(users_model):
    report = validate(users_model[3])
    assert report["numErrors"] == 0, report["messages"][:5]


def test_a_dance_retargeted_onto_a_vrm_without_a_skin_plays_on_the_avatar_itself(tmp_path):
    from dancesynth.retarget import on_character

    path, out = tmp_path / "skinless.vrm", tmp_path / "danced.glb"
    write_skinless_vrm(path)
    source = wiggle(MANNEQUIN, np.tile(IDENTITY, (MANNEQUIN.n_joints, 1)), MANNEQUIN.offsets[0])
    clip, character = on_character(source, str(path))
    assert character.kind == "vrm1" and character.bones == MANNEQUIN_BONES
    out.write_bytes(onto_model_bytes(character, clip))
    assert_joints_where_we_have_them(out, character, clip)
    if has_validator:
        report = validate(out)
        assert report["numErrors"] == 0, report["messages"][:5]


def test_a_gltf_with_its_buffer_and_texture_in_files_becomes_one_self_contained_glb(tmp_path):
    from PIL import Image

    path = tmp_path / "model.gltf"
    fbx_style_model(path, buffers="external")
    Image.new("RGB", (4, 4), (200, 30, 30)).save(tmp_path / "skin texture.png")
    doc = json.loads(path.read_text())
    doc.update(images=[{"uri": "skin%20texture.png"}], textures=[{"source": 0}])
    path.write_text(json.dumps(doc))
    character = load_gltf_character(path)
    out = tmp_path / "danced.glb"
    out.write_bytes(onto_model_bytes(character, wiggle(character.skeleton, character.rest_rot, character.rest_root)))
    (tmp_path / "model.bin").unlink()
    (tmp_path / "skin texture.png").unlink()
    gltf = open_gltf(out)
    image = gltf.images[0]
    assert image.uri is None and image.mimeType == "image/png"
    view = gltf.bufferViews[image.bufferView]
    Image.open(io.BytesIO(gltf.binary_blob()[view.byteOffset:view.byteOffset + view.byteLength])).verify()
    assert_same_rest(load_gltf_character(out), rig_skeleton("mixamo")[0])
    if has_validator:
        assert validate(out)["numErrors"] == 0


def validate(path) -> dict:
    """The Khronos glTF validator's issues for ``path``."""
    out = subprocess.run(["node", str(CLIENTS / "validate_gltf.mjs"), str(path)], capture_output=True, text=True,
                         cwd=CLIENTS, timeout=120, check=True)
    return json.loads(out.stdout)["issues"]


@needs_node
def test_three_js_plays_our_dance_on_the_users_model_with_every_joint_where_we_have_it(users_model):
    _, character, clip, out = users_model
    frames = (0, clip.n_frames // 2, clip.n_frames - 1)
    proc = subprocess.run(["node", str(CLIENTS / "three_gltf_import.mjs"), str(out), str(clip.fps),
                           ",".join(map(str, frames))], capture_output=True, text=True, cwd=CLIENTS, timeout=120,
                          check=True)
    report = json.loads(proc.stdout)
    assert report["errors"] == [] and report["animations"] == 1
    _, ours = fk(clip.local_rot, clip.root_pos, character.skeleton.offsets, character.skeleton.parents)
    names = [n.replace(":", "") for n in character.skeleton.names]   # three.js drops ':' from node names
    for f in frames:
        got = np.array([report["positions"][str(f)][n] for n in names])
        assert np.abs(got - ours[f]).max() < 1e-4, f

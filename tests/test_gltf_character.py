"""A user's own rigged model (issue 14): glTF, GLB and VRM 0.x / 1.0 files load as characters with the
skeleton, rest pose and humanoid bones they hold, in metres whatever units and armature they use; broken
files fail in one clear line; and our dance added to such a file (``onto_model``) plays back, in an
independent reader and in three.js, with every joint where our forward kinematics puts it.

The models are written (``gltf_models``) the way other tools write them (an FBX-style centimetre armature turned
Z-up, rest rotations on every joint, VRM 0.x turned to face -Z, external buffers), not by our exporter.
"""

from __future__ import annotations

import io
import json
import shutil
import subprocess

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import REPO
from gltf_models import (MANNEQUIN, MANNEQUIN_BONES, TURN, fbx_style_model, rest_positions, stick_mesh,
                         vrm1_extension, write_model, write_skinless_vrm, write_vrm0_mannequin)
from dancesynth.errors import InputError
from dancesynth.export.onto_model import onto_model_bytes
from dancesynth.kinematics import fk
from dancesynth.retarget.gltf_character import load_gltf_character
from dancesynth.retarget.gltf_file import open_gltf
from dancesynth.retarget.rigs import rig_skeleton
from dancesynth.rotations import IDENTITY, about_y, exp, mul
from dancesynth.types import MotionClip

CLIENTS = REPO / "tests" / "clients"
needs_node = pytest.mark.skipif(shutil.which("node") is None or not (CLIENTS / "node_modules" / "three").is_dir(),
                                reason="needs node and the npm clients (bash scripts/setup.sh --test installs them)")
has_validator = shutil.which("node") is not None and (CLIENTS / "node_modules" / "gltf-validator").is_dir()
needs_validator = pytest.mark.skipif(not has_validator, reason="needs node and the npm gltf-validator (bash "
                                     "scripts/setup.sh --test installs them)")


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

"""A user's own model drawn as itself (issue 14): ``load_gltf_character`` brings the model's skinned mesh
into ``Character.mesh``, in the rest pose in the skeleton's frame and metres, with its skin weights on our
joints and its colours (factor x vertex colour x texture) in linear RGB, so videos draw the user's avatar.

The models come from the writers of ``test_gltf_character`` (other tools' layouts) and from our VRM
exporter; here they are edited the ways real files differ: textures, compact accessors, sparse data,
see-through and double-sided materials, a mesh hanging from a bone.
"""

from __future__ import annotations

import base64
import io
import json

import numpy as np
import pytest
from PIL import Image

from scipy.spatial.transform import Rotation

from gltf_models import (MANNEQUIN, MANNEQUIN_BONES, TURN, fbx_style_model, stick_mesh, vrm1_extension, write_model,
                         write_skinless_vrm, write_vrm0_mannequin)
from test_render_character import frame, needs_ffmpeg, shaded, waving_dance
from dancesynth.export import render_video
from dancesynth.export.vrm import vrm_bytes
from dancesynth.kinematics import fk
from dancesynth.retarget import on_character
from dancesynth.retarget.character import builtin_character
from dancesynth.retarget.gltf_character import load_gltf_character
from dancesynth.retarget.mannequin import PALETTE
from dancesynth.retarget.rigs import rig_skeleton

FLOAT, UBYTE, USHORT = 5126, 5121, 5123
MIXAMO, _ = rig_skeleton("mixamo")
STICKS = stick_mesh(MIXAMO)          # the mesh fbx_style_model writes
FACTOR = [0.8, 0.9, 0.5, 1.0]        # a base colour factor
TEXELS = [(200, 30, 30, 255), (30, 60, 200, 0)]   # sRGB: red on the left half, see-through blue on the right


@pytest.fixture(scope="module")
def mannequin():
    return builtin_character("mannequin")


def linear(srgb) -> np.ndarray:
    c = np.asarray(srgb, float) / 255
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def dense_weights(mesh, names) -> dict[str, np.ndarray]:
    """Each joint's weight on every vertex, by joint name."""
    out = {}
    for k in range(mesh.joints.shape[1]):
        for j in np.unique(mesh.joints[:, k]):
            out.setdefault(names[j], np.zeros(len(mesh.joints)))
            out[names[j]] += np.where(mesh.joints[:, k] == j, mesh.weights[:, k], 0.0)
    return out


class Gltf:
    """A .gltf whose one buffer is a data: URI, open for editing: its JSON (``doc``) and buffer (``blob``)."""

    def __init__(self, path):
        self.doc = json.loads(path.read_text())
        self.blob = bytearray(base64.b64decode(self.doc["buffers"][0]["uri"].partition(",")[2]))

    @property
    def primitive(self) -> dict:
        return self.doc["meshes"][0]["primitives"][0]

    def array(self, accessor: int) -> np.ndarray:
        """A tightly packed accessor as ``write_model`` writes them."""
        acc = self.doc["accessors"][accessor]
        dtype = {FLOAT: np.float32, USHORT: np.uint16, 5125: np.uint32}[acc["componentType"]]
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}[acc["type"]]
        start = self.doc["bufferViews"][acc["bufferView"]].get("byteOffset", 0) + acc.get("byteOffset", 0)
        return np.frombuffer(bytes(self.blob), dtype, acc["count"] * width, start).reshape(acc["count"], width)

    def view(self, data: bytes, **fields) -> int:
        self.blob.extend(b"\0" * (-len(self.blob) % 4))
        self.doc["bufferViews"].append({"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data), **fields})
        self.blob.extend(data)
        return len(self.doc["bufferViews"]) - 1

    def accessor(self, view: int, count: int, kind: str, component: int, **fields) -> int:
        self.doc["accessors"].append({"bufferView": view, "componentType": component, "count": count, "type": kind,
                                      **fields})
        return len(self.doc["accessors"]) - 1

    def add(self, array: np.ndarray, kind: str, component: int, **fields) -> int:
        return self.accessor(self.view(np.ascontiguousarray(array).tobytes()), len(array), kind, component, **fields)

    def save(self, path) -> None:
        self.doc["buffers"] = [{"byteLength": len(self.blob),
                                "uri": "data:application/octet-stream;base64," + base64.b64encode(self.blob).decode()}]
        path.write_text(json.dumps(self.doc))


def fbx_gltf(path) -> Gltf:
    fbx_style_model(path, buffers="datauri")
    return Gltf(path)


# --------------------------------------------------------------------------- where the mesh is

def _our_vrm1(path, mannequin):
    path.write_bytes(vrm_bytes(mannequin))


def _twisted_vrm1(path, mannequin):
    write_model(path, MANNEQUIN, mannequin.mesh, twist=True, names=MANNEQUIN.names,
                extensions=vrm1_extension(MANNEQUIN_BONES))


AVATARS = {"our VRM 1.0": (_our_vrm1, False), "VRM 1.0 with rest rotations": (_twisted_vrm1, False),
           "VRM 0.x facing -Z": (lambda path, _: write_vrm0_mannequin(path), True)}


@pytest.mark.parametrize("avatar", AVATARS)
def test_an_avatars_mesh_loads_in_its_rest_pose_with_its_weights_and_colours(tmp_path, mannequin, avatar):
    write, turned = AVATARS[avatar]
    path = tmp_path / "avatar.vrm"
    write(path, mannequin)
    character = load_gltf_character(path)
    ours, theirs = character.mesh, mannequin.mesh
    turn = TURN.apply if turned else (lambda x: x)
    assert ours.positions.shape == theirs.positions.shape and ours.positions.dtype == np.float32
    assert np.abs(ours.positions - turn(theirs.positions)).max() < 1e-4      # metres
    assert np.abs(ours.normals - turn(theirs.normals)).max() < 1e-4
    np.testing.assert_array_equal(ours.indices, theirs.indices)
    assert np.abs(ours.weights.sum(axis=1) - 1).max() < 1e-6
    assert np.abs(ours.colours - theirs.colours).max() < 1e-4
    mine, original = dense_weights(ours, character.skeleton.names), dense_weights(theirs, MANNEQUIN.names)
    assert all(np.abs(mine.get(name, 0) - w).max() < 1e-5 for name, w in original.items())


@pytest.mark.parametrize("mesh_in_armature", [False, True])
def test_an_fbx_style_mesh_in_centimetres_comes_out_in_metres_on_its_bones(tmp_path, mesh_in_armature):
    path = tmp_path / "mixamo.glb"
    fbx_style_model(path, mesh_in_armature=mesh_in_armature)
    character = load_gltf_character(path)
    mesh = character.mesh
    assert np.abs(mesh.positions - STICKS.positions).max() < 1e-4
    assert np.abs(mesh.normals - STICKS.normals).max() < 1e-4
    assert 1.6 < np.ptp(mesh.positions[:, 1]) < 1.9        # a person's height, Y up
    names = np.array(character.skeleton.names)
    np.testing.assert_array_equal(names[mesh.joints[:, 0]], np.array(MIXAMO.names)[STICKS.joints[:, 0]])


def test_compact_accessors_load_as_the_plain_ones(tmp_path, mannequin):
    """Unsigned-byte joints, normalized unsigned-byte weights, POSITION and COLOR_0 interleaved in one strided
    view, a sparse accessor putting back part of POSITION, no indices, no normals."""
    path = tmp_path / "compact.gltf"
    write_model(path, MANNEQUIN, mannequin.mesh, names=MANNEQUIN.names, extensions=vrm1_extension(MANNEQUIN_BONES),
                buffers="datauri")
    g = Gltf(path)
    corners = g.array(g.primitive["indices"]).reshape(-1)          # unrolled: each triangle its own vertices
    plain = {k: g.array(i)[corners] for k, i in g.primitive["attributes"].items()}
    n = len(corners)
    interleaved = np.concatenate([plain["POSITION"], plain["COLOR_0"]], axis=1)
    interleaved[:7, :3] = 0.0                                       # wrong until the sparse values replace them
    view = g.view(interleaved.tobytes(), byteStride=24)
    sparse = {"count": 7, "indices": {"bufferView": g.view(np.arange(7, dtype=np.uint16).tobytes()),
                                      "componentType": USHORT},
              "values": {"bufferView": g.view(plain["POSITION"][:7].tobytes())}}
    g.primitive["attributes"] = {
        "POSITION": g.accessor(view, n, "VEC3", FLOAT, sparse=sparse),
        "COLOR_0": g.accessor(view, n, "VEC3", FLOAT, byteOffset=12),
        "JOINTS_0": g.add(plain["JOINTS_0"].astype(np.uint8), "VEC4", UBYTE),
        "WEIGHTS_0": g.add(np.rint(plain["WEIGHTS_0"] * 255).astype(np.uint8), "VEC4", UBYTE, normalized=True)}
    del g.primitive["indices"]
    g.save(path)

    character = load_gltf_character(path)
    mesh, theirs = character.mesh, mannequin.mesh
    expected = theirs.positions[theirs.indices].reshape(-1, 3)
    assert np.abs(mesh.positions - expected).max() < 1e-5
    np.testing.assert_array_equal(mesh.indices, np.arange(n).reshape(-1, 3))
    corner = expected.reshape(-1, 3, 3)
    face = np.cross(corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0])
    big = np.linalg.norm(face, axis=1) > 1e-8       # flat: each vertex its own triangle's normal
    face = np.repeat(face / np.maximum(np.linalg.norm(face, axis=1, keepdims=True), 1e-12), 3, axis=0)
    assert np.abs(mesh.normals - face)[np.repeat(big, 3)].max() < 1e-3
    assert np.abs(mesh.colours - theirs.colours[theirs.indices].reshape(-1, 3)).max() < 1e-6
    assert np.abs(mesh.weights.sum(axis=1) - 1).max() < 1e-6
    mine = dense_weights(mesh, character.skeleton.names)
    for name, w in dense_weights(theirs, MANNEQUIN.names).items():
        assert np.abs(mine.get(name, 0) - w[theirs.indices].reshape(-1)).max() < 0.01, name


# --------------------------------------------------------------------------- colours

def textured(path, source: str, *, factor=FACTOR, image_ok=True, **material) -> np.ndarray:
    """The FBX-style model with a 2x1 texture (``TEXELS``) on its base colour, held in ``source``: a
    bufferView, a file beside it, a data: URI, as a VRM 0.x MToon's ``_MainTex``, or a bufferView with a
    KHR_texture_transform that moves the UVs by half the texture ("shifted"). The left side's UVs fall in
    the left texel and the rest in the right one (before a shift), from outside 0..1 (they wrap).
    Returns which vertices are on the left."""
    g = fbx_gltf(path)
    left = np.char.find(np.array(MIXAMO.names)[STICKS.joints[:, 0]], "Left") >= 0
    uv = np.stack([np.where(left, 1.25, -0.25), np.full(len(left), 0.5)], axis=1).astype(np.float32)
    g.primitive["attributes"]["TEXCOORD_0"] = g.add(uv, "VEC2", FLOAT)
    png = io.BytesIO()
    Image.frombytes("RGBA", (2, 1), bytes(sum(TEXELS, ()))).save(png, "PNG")
    png = png.getvalue()
    if not image_ok:
        image = {"uri": "gone.png"}
    elif source == "file":
        (path.parent / "skin texture.png").write_bytes(png)
        image = {"uri": "skin%20texture.png"}
    elif source == "data-uri":
        image = {"uri": "data:image/png;base64," + base64.b64encode(png).decode()}
    else:
        image = {"bufferView": g.view(png), "mimeType": "image/png"}
    g.doc.update(images=[image], textures=[{"source": 0}])
    mat = g.doc["materials"][0]
    mat.update(name="skin", **material)
    mat["pbrMetallicRoughness"]["baseColorFactor"] = factor
    if source == "vrm0":
        g.doc["extensions"] = {"VRM": {"materialProperties": [{"name": "skin", "shader": "VRM/MToon",
                                                               "textureProperties": {"_MainTex": 0}}]}}
    else:
        shift = {"KHR_texture_transform": {"offset": [0.5, 0.0]}} if source == "shifted" else {}
        mat["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0, "extensions": shift}
    g.save(path)
    return left


@pytest.mark.parametrize("source", ["bufferView", "file", "data-uri", "vrm0", "shifted"])
def test_a_textured_model_takes_each_vertexs_colour_from_its_texel(tmp_path, source):
    path = tmp_path / "textured.gltf"
    left = textured(path, source) != (source == "shifted")
    colours = load_gltf_character(path).mesh.colours
    texel = np.where(left[:, None], linear(TEXELS[0][:3]), linear(TEXELS[1][:3]))
    expected = np.asarray(FACTOR[:3]) * STICKS.colours * texel      # factor x COLOR_0 x texture
    assert np.abs(colours - expected).max() < 1e-5


@pytest.mark.parametrize("factor, stand_in", [([1.0, 1.0, 1.0, 1.0], linear([128] * 3)), (FACTOR, 1.0)])
def test_a_texture_that_cannot_be_read_leaves_the_factor_or_grey(tmp_path, factor, stand_in):
    path = tmp_path / "textured.gltf"
    textured(path, "file", factor=factor, image_ok=False)
    colours = load_gltf_character(path).mesh.colours
    assert np.abs(colours - np.asarray(factor[:3]) * STICKS.colours * stand_in).max() < 1e-5


def test_see_through_triangles_are_dropped_and_double_sided_ones_get_a_back(tmp_path):
    path = tmp_path / "textured.gltf"
    left = textured(path, "bufferView", alphaMode="MASK", doubleSided=True)
    mesh = load_gltf_character(path).mesh
    front = STICKS.indices[left[STICKS.indices].all(axis=1)]      # the right texel is see-through
    n = len(STICKS.positions)
    np.testing.assert_array_equal(mesh.indices, np.concatenate([front, front[:, ::-1] + n]))
    np.testing.assert_allclose(mesh.positions[n:], mesh.positions[:n])
    np.testing.assert_allclose(mesh.normals[n:], -mesh.normals[:n])


# --------------------------------------------------------------------------- which meshes

def test_an_unskinned_mesh_hanging_from_a_bone_moves_with_it_and_one_outside_the_rig_is_left_out(tmp_path):
    path = tmp_path / "hat.gltf"
    g = fbx_gltf(path)
    nodes = g.doc["nodes"]
    head = next(i for i, nd in enumerate(nodes) if nd.get("name") == "mixamorig:Head")
    nodes += [{"name": "Hat", "mesh": 0, "translation": [0, 10, 0]},    # in the head's centimetres
              {"name": "Prop", "mesh": 0}]                              # beside the rig
    nodes[head]["children"] = nodes[head].get("children", []) + [len(nodes) - 2]
    g.doc["scenes"][0]["nodes"].append(len(nodes) - 1)
    g.save(path)
    character = load_gltf_character(path)
    mesh, sk, n = character.mesh, character.skeleton, len(STICKS.positions)
    assert len(mesh.positions) == 2 * n
    j = sk.index("mixamorig:Head")
    g_rot, g_pos = fk(character.rest_rot, character.rest_root, sk.offsets, sk.parents)
    hat = g_pos[j] + Rotation.from_quat(g_rot[j]).apply(0.01 * (STICKS.positions + [0, 10, 0]))
    assert np.abs(mesh.positions[n:] - hat).max() < 1e-5
    assert (mesh.joints[n:, 0] == j).all() and (mesh.weights[n:, 0] == 1).all()


def test_a_vrm_without_a_skin_has_each_bones_mesh_rigidly_on_that_bone(tmp_path):
    path = tmp_path / "skinless.vrm"
    write_skinless_vrm(path)     # each bone's box a mesh of its own, squashed by its node's scale
    character = load_gltf_character(path)
    mesh, sticks = character.mesh, stick_mesh(MANNEQUIN)
    assert character.skeleton.names == MANNEQUIN.names
    by_bone = np.argsort(sticks.joints[:, 0], kind="stable")    # the file holds them bone by bone
    assert np.abs(mesh.positions - sticks.positions[by_bone]).max() < 1e-5
    assert np.abs(mesh.normals - sticks.normals[by_bone]).max() < 1e-5
    np.testing.assert_array_equal(mesh.joints[:, 0], sticks.joints[by_bone, 0])
    assert (mesh.weights[:, 0] == 1).all() and len(mesh.indices) == len(sticks.indices)


def test_a_skin_that_no_mesh_uses_gives_no_mesh(tmp_path):
    path = tmp_path / "bare.gltf"
    g = fbx_gltf(path)
    del g.doc["nodes"][0]["mesh"]
    g.save(path)
    character = load_gltf_character(path)
    assert character.mesh is None and character.skeleton.n_joints == MIXAMO.n_joints


# --------------------------------------------------------------------------- in a video

@needs_ffmpeg
def test_a_video_of_the_users_avatar_draws_its_own_mesh(tmp_path, mannequin):
    path = tmp_path / "avatar.vrm"
    path.write_bytes(vrm_bytes(mannequin))
    dance, character = on_character(waving_dance(mannequin, seconds=1.0), load_gltf_character(path))
    out = tmp_path / "avatar.mp4"
    info = render_video(dance, None, out, width=320, height=180, character=character)
    assert info["figure"] == "character"
    for n in (5, 20):
        img = frame(out, n)
        seen = {part: int(shaded(img, PALETTE[part], tol=10).sum()) for part in ("top", "trousers", "skin")}
        assert min(seen.values()) > 80, seen

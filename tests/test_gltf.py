"""A dance as glTF (issue 14): read back by an independent reader (pygltflib's arrays, SciPy's
rotations, a forward kinematics written here) it puts every joint where ours does, and the Khronos
validator finds nothing wrong with it. With the mannequin's skinned body, the file's own skin moves
every vertex where our skinning does, Blender imports it as an armature deforming a mesh, and
three.js draws the dancing figure in a browser."""

from __future__ import annotations

import functools
import json
import shutil
import subprocess

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from conftest import REPO
from test_cli import TRUMPET, assert_clean_failure, cli
from test_mannequin import skinned_positions
from dancesynth.errors import InputError
from dancesynth.export.gltf import glb_bytes, write_glb
from dancesynth.kinematics import clip_fk
from dancesynth.retarget.character import Mesh
from dancesynth.retarget.mannequin import mannequin_character
from dancesynth.retarget.solve import retarget
from dancesynth.types import MotionClip

CLIENTS = REPO / "tests" / "clients"


@pytest.fixture(scope="module")
def salsa(bundled_db, bundled_song):
    from dancesynth.api import dance

    return dance(bundled_song, database=bundled_db, style="salsa-133-150bpm", seed=2)


@pytest.fixture(scope="module")
def mannequin_salsa(salsa):
    """The salsa danced by the mannequin, the character with a skinned body."""
    return retarget(salsa, mannequin_character())


def accessor_values(gltf, index: int) -> np.ndarray:
    """An accessor's elements (count, width), from the file's binary chunk."""
    acc = gltf.accessors[index]
    view = gltf.bufferViews[acc.bufferView]
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[acc.type]
    dtype = {5126: np.float32, 5121: np.uint8, 5123: np.uint16, 5125: np.uint32}[acc.componentType]
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    return np.frombuffer(gltf.binary_blob(), dtype, acc.count * width, start).reshape(acc.count, width)


def read_joint_positions(path) -> tuple[list[str], np.ndarray]:
    """Every node's world position at every key time, from the file alone."""
    names, _, world_pos = read_nodes(path)
    return names, world_pos


def read_nodes(path) -> tuple[list[str], list[Rotation], np.ndarray]:
    """Every node's name, and its world rotation and position (frames, nodes, 3) at every key time."""
    import pygltflib

    gltf = pygltflib.GLTF2.load(str(path))
    values = functools.partial(accessor_values, gltf)
    anim = gltf.animations[0]
    times = values(anim.samplers[0].input)[:, 0]
    n, nodes = len(times), gltf.nodes
    trans = np.array([np.tile(nd.translation or [0, 0, 0], (n, 1)) for nd in nodes], dtype=np.float64)
    quats = np.array([np.tile(nd.rotation or [0, 0, 0, 1], (n, 1)) for nd in nodes], dtype=np.float64)
    for ch in anim.channels:
        data = values(anim.samplers[ch.sampler].output)
        (trans if ch.target.path == "translation" else quats)[ch.target.node] = data
    parent = {c: i for i, nd in enumerate(nodes) for c in (nd.children or [])}
    world_rot, world_pos = [None] * len(nodes), np.zeros((len(nodes), n, 3))
    for i in range(len(nodes)):  # parents come first: the exporter writes them so
        local = Rotation.from_quat(quats[i])
        if i in parent:
            p = parent[i]
            world_pos[i] = world_pos[p] + world_rot[p].apply(trans[i])
            world_rot[i] = world_rot[p] * local
        else:
            world_pos[i], world_rot[i] = trans[i], local
    return [nd.name for nd in nodes], world_rot, world_pos.transpose(1, 0, 2)


def test_a_glb_read_back_puts_every_joint_where_the_dance_has_it(salsa, tmp_path):
    path = write_glb(tmp_path / "dance.glb", salsa)
    names, pos = read_joint_positions(path)
    _, ours = clip_fk(salsa)
    j = salsa.skeleton.n_joints
    assert names[:j] == list(salsa.skeleton.names)
    assert pos.shape[0] == salsa.n_frames
    assert np.max(np.abs(pos[:, :j] - ours)) < 1e-4    # metres, every joint, every frame
    assert len(names) == j + len(salsa.skeleton.end_sites)


@pytest.mark.skipif(shutil.which("node") is None or not (CLIENTS / "node_modules" / "gltf-validator").is_dir(),
                    reason="needs node and the npm gltf-validator (bash scripts/setup.sh --test installs them)")
def test_the_khronos_validator_finds_no_error_or_warning(salsa, tmp_path):
    path = write_glb(tmp_path / "dance.glb", salsa)
    out = subprocess.run(["node", str(CLIENTS / "validate_gltf.mjs"), str(path)], capture_output=True, text=True,
                         cwd=CLIENTS, timeout=120, check=True)
    issues = json.loads(out.stdout)["issues"]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"][:5]


def test_dance_writes_glb_when_asked_and_refuses_formats_it_does_not_write(tmp_path):
    out = tmp_path / "dance.glb"
    proc = cli("dance", TRUMPET, "-o", out, "-q")
    assert proc.returncode == 0, proc.stderr
    assert out.read_bytes()[:4] == b"glTF"
    names, pos = read_joint_positions(out)
    assert len(names) > 10 and np.all(np.isfinite(pos))
    bad = tmp_path / "dance.obj"
    assert_clean_failure(cli("dance", TRUMPET, "-o", bad), bad, ".bvh", ".glb")


def _blender_has_numpy() -> bool:
    """Debian's Blender runs on the system Python, whose glTF importer needs python3-numpy."""
    if shutil.which("blender") is None:
        return False
    probe = subprocess.run(["blender", "-b", "--factory-startup", "--python-expr", "import numpy"],
                           capture_output=True, text=True, timeout=120)
    return "ModuleNotFoundError" not in probe.stdout + probe.stderr


@pytest.mark.blender
def test_blender_imports_the_glb_and_poses_every_joint_as_we_do(salsa, tmp_path):
    if not _blender_has_numpy():
        pytest.skip("needs blender with numpy for its glTF importer (bash scripts/setup.sh --test installs "
                    "python3-numpy)")
    path = write_glb(tmp_path / "dance.glb", salsa)
    frames = (0, salsa.n_frames // 2, salsa.n_frames - 1)
    report_file = tmp_path / "blender.json"
    subprocess.run(["blender", "-b", "--factory-startup", "--python", str(CLIENTS / "blender_gltf_import.py"), "--",
                    str(path), str(salsa.fps), str(report_file), ",".join(map(str, frames))],
                   capture_output=True, text=True, timeout=300)
    report = json.loads(report_file.read_text())
    assert report["errors"] == []
    assert report["actions"] > 0 and set(salsa.skeleton.names) <= set(report["objects"])
    _, ours = clip_fk(salsa)
    for f in frames:
        got = np.array([report["positions"][str(f)][n] for n in salsa.skeleton.names])
        expected = np.stack([ours[f, :, 0], -ours[f, :, 2], ours[f, :, 1]], axis=1)  # Y-up to Blender's Z-up
        assert np.abs(got - expected).max() < 1e-4, f


@pytest.mark.skipif(shutil.which("node") is None or not (CLIENTS / "node_modules" / "three").is_dir(),
                    reason="needs node and three.js (bash scripts/setup.sh --test installs them)")
def test_three_js_plays_the_glb_with_every_joint_where_we_have_it(salsa, tmp_path):
    path = write_glb(tmp_path / "dance.glb", salsa)
    frames = (0, salsa.n_frames // 2, salsa.n_frames - 1)
    out = subprocess.run(["node", str(CLIENTS / "three_gltf_import.mjs"), str(path), str(salsa.fps),
                          ",".join(map(str, frames))], capture_output=True, text=True, cwd=CLIENTS, timeout=120,
                         check=True)
    report = json.loads(out.stdout)
    assert report["errors"] == [] and report["animations"] == 1
    assert report["duration"] == pytest.approx(salsa.duration_s, abs=1e-4)
    _, ours = clip_fk(salsa)
    for f in frames:
        got = np.array([report["positions"][str(f)][n] for n in salsa.skeleton.names])
        assert np.abs(got - ours[f]).max() < 1e-4, f


def skinned_from_file(path, frames) -> dict[int, np.ndarray]:
    """The body's vertices at ``frames`` as a glTF player skins them, from the file alone: each
    vertex carried by its joints' animated world matrices times the skin's inverse bind matrices."""
    import pygltflib

    gltf = pygltflib.GLTF2.load(str(path))
    node = next(n for n in gltf.nodes if n.mesh is not None)
    attributes = gltf.meshes[node.mesh].primitives[0].attributes
    skin = gltf.skins[node.skin]
    positions = accessor_values(gltf, attributes.POSITION).astype(np.float64)
    joints = accessor_values(gltf, attributes.JOINTS_0).astype(np.int64)
    weights = accessor_values(gltf, attributes.WEIGHTS_0).astype(np.float64)
    inverse_bind = accessor_values(gltf, skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
    _, world_rot, world_pos = read_nodes(path)
    homogeneous = np.concatenate([positions, np.ones((len(positions), 1))], axis=1)
    out = {}
    for f in frames:
        world = np.zeros((len(skin.joints), 4, 4))
        for k, n in enumerate(skin.joints):
            world[k, :3, :3] = world_rot[n][f].as_matrix()
            world[k, :3, 3] = world_pos[f, n]
            world[k, 3, 3] = 1.0
        skinning = np.einsum("vk,vkab->vab", weights, (world @ inverse_bind)[joints])
        out[f] = np.einsum("vab,vb->va", skinning, homogeneous)[:, :3]
    return out


def synthetic_mannequin_dance(n_frames: int, fps: float = 30.0) -> MotionClip:
    """Arms swinging, elbows and knees bending, hips turning, the root swaying and bobbing."""
    sk, b = mannequin_character().skeleton, mannequin_character().bones
    phase = 2 * np.pi * 0.5 * np.arange(n_frames) / fps
    turn = np.zeros((n_frames, sk.n_joints, 3))
    for side, s in (("left", 1.0), ("right", -1.0)):
        swing = np.sin(phase + (0.0 if s > 0 else np.pi))
        turn[:, b[side + "UpperArm"], 2] = s * (-1.0 + 0.9 * swing)
        turn[:, b[side + "LowerArm"], 1] = s * (-0.8 - 0.6 * np.sin(2 * phase))
        turn[:, b[side + "UpperLeg"], 0] = -0.25 * (1 + swing)
        turn[:, b[side + "LowerLeg"], 0] = 0.5 * (1 + swing)
    turn[:, b["hips"], 1] = 0.4 * np.sin(phase)
    root = np.tile(sk.offsets[0], (n_frames, 1))
    root[:, 0] += 0.2 * np.sin(phase)
    root[:, 1] -= 0.05 * (1 - np.cos(2 * phase))
    local_rot = Rotation.from_rotvec(turn.reshape(-1, 3)).as_quat().reshape(n_frames, sk.n_joints, 4)
    return MotionClip(sk, fps, root, local_rot)


def test_the_mannequins_skinned_body_moves_in_the_file_as_our_skinning_moves_it(mannequin_salsa, tmp_path):
    character = mannequin_character()
    path = write_glb(tmp_path / "dance.glb", mannequin_salsa, character.mesh)
    import pygltflib

    gltf = pygltflib.GLTF2.load(str(path))
    (skin,), (mesh,) = gltf.skins, gltf.meshes
    body = next(i for i, n in enumerate(gltf.nodes) if n.mesh is not None)
    assert [gltf.nodes[j].name for j in skin.joints] == list(character.skeleton.names)
    assert gltf.scenes[0].nodes == [0, body]            # the body beside the skeleton's root, untransformed
    assert not (gltf.nodes[body].translation or gltf.nodes[body].rotation or gltf.nodes[body].matrix)
    material = gltf.materials[mesh.primitives[0].material].pbrMetallicRoughness
    assert material.baseColorFactor == [1.0, 1.0, 1.0, 1.0] and material.metallicFactor == 0.0
    assert 0.6 <= material.roughnessFactor <= 0.9
    colours = accessor_values(gltf, mesh.primitives[0].attributes.COLOR_0)
    assert np.allclose(colours, character.mesh.colours)
    frames = (0, mannequin_salsa.n_frames // 2, mannequin_salsa.n_frames - 1)
    from_file = skinned_from_file(path, frames)
    for f in frames:
        ours = skinned_positions(character, mannequin_salsa.local_rot[f], mannequin_salsa.root_pos[f])
        assert np.abs(from_file[f] - ours).max() < 1e-4, f   # metres, every vertex
        assert from_file[f][:, 1].min() > -0.05            # dancing on the floor, not through it


def test_a_rest_pose_other_than_identity_binds_the_body_where_it_was_modelled(tmp_path):
    """A character modelled with bent rest rotations: the inverse bind matrices undo that pose, so
    a dance frame in that same pose leaves every vertex where it was modelled."""
    character = mannequin_character()
    sk = character.skeleton
    rest_rot = Rotation.from_rotvec(np.tile([0.0, 0.3, 0.1], (sk.n_joints, 1))).as_quat()
    rest_root = sk.offsets[0] + [0.5, 0.0, -0.2]
    clip = MotionClip(sk, 30.0, np.tile(rest_root, (2, 1)), np.tile(rest_rot, (2, 1, 1)))
    path = tmp_path / "bent.glb"
    path.write_bytes(glb_bytes(clip, character.mesh, rest_rot=rest_rot, rest_root=rest_root))
    assert np.abs(skinned_from_file(path, (1,))[1] - character.mesh.positions).max() < 1e-5


def test_a_three_minute_dance_with_the_body_is_a_file_of_a_few_megabytes():
    # (its export time is measured by benchmarks/retarget_bench.py, not asserted here)
    data = glb_bytes(synthetic_mannequin_dance(5400), mannequin_character().mesh)
    assert data[:4] == b"glTF" and len(data) < 5_000_000


def test_a_mesh_that_does_not_fit_the_skeleton_is_refused():
    clip = synthetic_mannequin_dance(3)
    mesh = mannequin_character().mesh
    beyond = Mesh(mesh.positions, mesh.normals, mesh.indices, mesh.joints + 1, mesh.weights, mesh.colours)
    with pytest.raises(InputError, match="joint"):
        glb_bytes(clip, beyond)
    with pytest.raises(InputError, match="rest pose"):
        glb_bytes(clip, mesh, rest_rot=np.zeros((3, 4)))
    weightless = Mesh(mesh.positions, mesh.normals, mesh.indices, mesh.joints, mesh.weights * 0, mesh.colours)
    with pytest.raises(InputError, match="weight"):
        glb_bytes(clip, weightless)


@pytest.mark.skipif(shutil.which("node") is None or not (CLIENTS / "node_modules" / "gltf-validator").is_dir(),
                    reason="needs node and the npm gltf-validator (bash scripts/setup.sh --test installs them)")
def test_the_khronos_validator_finds_no_error_or_warning_in_the_skinned_mannequin(mannequin_salsa, tmp_path):
    path = write_glb(tmp_path / "dance.glb", mannequin_salsa, mannequin_character().mesh)
    out = subprocess.run(["node", str(CLIENTS / "validate_gltf.mjs"), str(path)], capture_output=True, text=True,
                         cwd=CLIENTS, timeout=120, check=True)
    report = json.loads(out.stdout)
    issues = report["issues"]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"][:5]
    info = report["info"]
    assert info["animationCount"] == 1 and info["hasSkins"] and info["materialCount"] == 1
    assert info["totalTriangleCount"] == len(mannequin_character().mesh.indices) and info["maxInfluences"] == 4


@pytest.mark.blender
def test_blender_imports_the_mannequin_as_an_armature_deforming_its_body(mannequin_salsa, tmp_path):
    if not _blender_has_numpy():
        pytest.skip("needs blender with numpy for its glTF importer (bash scripts/setup.sh --test installs "
                    "python3-numpy)")
    character = mannequin_character()
    path = write_glb(tmp_path / "dance.glb", mannequin_salsa, character.mesh)
    frames = (0, mannequin_salsa.n_frames // 2)
    report_file = tmp_path / "blender.json"
    subprocess.run(["blender", "-b", "--factory-startup", "--python", str(CLIENTS / "blender_gltf_import.py"), "--",
                    str(path), str(mannequin_salsa.fps), str(report_file), ",".join(map(str, frames))],
                   capture_output=True, text=True, timeout=300)
    report = json.loads(report_file.read_text())
    assert report["errors"] == []
    names = list(character.skeleton.names)
    (mesh_name, mesh), = report["meshes"].items()
    assert sorted(mesh["vertex_groups"]) == sorted(names) and mesh["modifiers"] == ["ARMATURE"]
    assert mesh["polygons"] == len(character.mesh.indices)
    (bones,) = report["armatures"].values()
    assert set(names) <= set(bones)
    (frame_range,) = report["frame_ranges"].values()
    assert frame_range == [0.0, float(mannequin_salsa.n_frames - 1)]
    for f in frames:   # Blender's armature deforms the body where our skinning puts it
        got = np.array(report["deformed"][str(f)][mesh_name])
        got = np.stack([got[:, 0], got[:, 2], -got[:, 1]], axis=1)   # Blender's Z-up back to Y-up
        ours = skinned_positions(character, mannequin_salsa.local_rot[f], mannequin_salsa.root_pos[f])
        assert got.shape == ours.shape
        assert cKDTree(got).query(ours)[0].max() < 1e-4, f


def figure_mask(rgb: np.ndarray) -> np.ndarray:
    """Pixels of the figure: the background and floor are neutral greys, the figure is coloured."""
    top, low = rgb.max(axis=2), rgb.min(axis=2)
    return (top > 0.06) & ((top - low) / np.maximum(top, 1e-6) > 0.2)


@pytest.mark.skipif(shutil.which("node") is None or not (CLIENTS / "node_modules" / "playwright-core").is_dir()
                    or not shutil.which("chromium"),
                    reason="needs node, playwright-core, three.js and chromium (bash scripts/setup.sh --test)")
def test_three_js_draws_the_mannequin_dancing_in_a_browser(mannequin_salsa, tmp_path):
    from PIL import Image

    path = write_glb(tmp_path / "dance.glb", mannequin_salsa, mannequin_character().mesh)
    t1 = round(mannequin_salsa.duration_s / 3, 2)
    out = subprocess.run(["node", str(CLIENTS / "three_gltf_browser.mjs"), str(path), str(tmp_path),
                          f"a:{t1}:0,b:{t1 + 0.8}:0", shutil.which("chromium")], capture_output=True, text=True,
                         cwd=CLIENTS, timeout=180)
    report = json.loads(out.stdout)
    assert report["ok"] and report["errors"] == [], (report["errors"], out.stderr[-2000:])
    model = report["model"]
    assert model["skinnedMeshes"] == 1 and model["vertexColors"]
    assert model["bones"] == list(mannequin_salsa.skeleton.names)
    assert model["duration"] == pytest.approx(mannequin_salsa.duration_s, abs=1e-3)
    shots = []
    for shot in report["shots"]:
        print(shot["path"])
        low, high = np.array(shot["box"]["min"]), np.array(shot["box"]["max"])
        assert 1.3 < high[1] - low[1] < 1.85 and low[1] > -0.05   # three.js skins a full-size figure on the floor
        rgb = np.asarray(Image.open(shot["path"]).convert("RGB"), dtype=np.float64) / 255.0
        assert rgb.shape == (480, 640, 3)
        mask = figure_mask(rgb)
        assert mask.sum() > 8000                                  # the figure is drawn, a good part of the view
        r, g, b = (rgb[..., k] for k in range(3))
        shirt = mask & (r > 1.6 * g) & (r > 1.6 * b)              # the coral top
        trousers = mask & (b > r) & (b > g)                       # navy trousers
        skin = mask & (r > g) & (g > b) & (g > 0.6 * r)           # face, arms, hands
        assert shirt.sum() > 1000 and trousers.sum() > 1000 and skin.sum() > 300, (shirt.sum(), trousers.sum())
        shots.append((rgb, mask))
    (a, mask_a), (b, mask_b) = shots
    union = mask_a | mask_b
    changed = union & (np.abs(a - b).max(axis=2) > 0.15)
    assert changed.sum() > 0.25 * union.sum()                     # the figure moved between the two times


@pytest.mark.blender
def test_the_readme_workaround_lets_debians_blender_import_a_skinned_glb(mannequin_salsa, tmp_path):
    """Issue 31: Debian's Blender 3.4 cannot import a .glb with normals from its menu (numpy.bool is gone); the
    README says so and gives a one-line workaround, which must work."""
    import re

    if not _blender_has_numpy():
        pytest.skip("needs blender with numpy for its glTF importer")
    workaround = re.search(r"run `(import numpy; numpy\.bool = bool)`", (REPO / "README.md").read_text()).group(1)
    path = write_glb(tmp_path / "dance.glb", mannequin_salsa, mannequin_character().mesh)
    results = {}
    for shim in ("", workaround + "; "):
        expr = (f"{shim}import bpy\ntry:\n    bpy.ops.import_scene.gltf(filepath={str(path)!r})\n"
                "    print('IMPORTED', len(bpy.data.meshes))\nexcept Exception as e:\n    print('FAILED', e)\n")
        proc = subprocess.run(["blender", "-b", "--factory-startup", "--python-expr", expr],
                              capture_output=True, text=True, timeout=300)
        results[bool(shim)] = proc.stdout + proc.stderr
    if "IMPORTED" in results[False]:
        pytest.skip("this Blender's glTF importer does not need the workaround")
    assert "numpy" in results[False] and "bool" in results[False]        # the failure the README names
    assert re.search(r"IMPORTED [1-9]", results[True]), results[True][-2000:]

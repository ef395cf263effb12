"""Character files are hostile input (issue 29): a downloaded model may read only files inside its own
folder (or data: URIs), every read is bounded, and a rig a dance cannot be put on is refused when it
is loaded, before any dance is made, in one line.

The models are the mannequin written by our exporter and then edited as an attacker would.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap

import pytest

from conftest import BUNDLED_MUSIC, REPO
from dancesynth.errors import InputError
from dancesynth.export.formats import encode_dance
from dancesynth.io.bvh import read_bvh
from dancesynth.retarget import on_character
from dancesynth.retarget.character import load_character
from fuzz.character_target import MARKER, glb_container, make_seeds, split_glb

SONG = BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg"
FORMATS = (".bvh", ".glb", ".vrma", ".mp4", ".fbx")


@pytest.fixture(scope="module")
def seeds(tmp_path_factory):
    folder = tmp_path_factory.mktemp("character_seeds")
    make_seeds(folder)
    return folder


@pytest.fixture
def planted(tmp_path):
    """A model folder beside a folder of secrets, the secrets holding ``MARKER``."""
    outside = tmp_path / "outside"
    outside.mkdir()
    for name in ("secret.png", "secret.bin"):
        (outside / name).write_bytes(MARKER * 100)
    model = tmp_path / "model"
    model.mkdir()
    return model, outside


def gltf_with(seeds, folder, *, image=None, buffer=None, edit=None):
    """The textured .gltf seed in ``folder`` with its image's and/or buffer's URI replaced."""
    doc = json.loads((seeds / "model.gltf").read_text())
    (folder / "model.bin").write_bytes((seeds / "model.bin").read_bytes())
    (folder / "skin.png").write_bytes((seeds / "skin.png").read_bytes())
    if image is not None:
        doc["images"][0]["uri"] = image
    if buffer is not None:
        doc["buffers"][0]["uri"] = buffer
    if edit is not None:
        edit(doc)
    path = folder / "model.gltf"
    path.write_text(json.dumps(doc))
    return path


def dance_clip():
    return read_bvh(REPO / "tests" / "data" / "mocap" / "cmu_daz_salsa" / "60_01_scaled.bvh").frames(0, 10)


def all_outputs(character) -> bytes:
    moved, character = on_character(dance_clip(), character)
    return b"".join(encode_dance(s, moved, character) for s in (".bvh", ".glb", ".vrma"))


# ----------------------------------------------------------------------------- no file outside the folder


OUTSIDE_URIS = ["{abs}/secret.png", "../outside/secret.png", "%2e%2e/outside/secret.png",
                "..%2Foutside%2Fsecret.png", "sub/../../outside/secret.png", "..\\outside\\secret.png",
                "file://{abs}/secret.png", "/etc/passwd", "/proc/self/environ", "link.png", "linkdir/secret.png"]


@pytest.mark.parametrize("kind", ["image", "buffer"])
@pytest.mark.parametrize("uri", OUTSIDE_URIS)
def test_a_uri_outside_the_models_folder_is_refused_when_the_model_is_opened(seeds, planted, uri, kind):
    model, outside = planted
    os.symlink(outside / "secret.png", model / "link.png")
    os.symlink(outside, model / "linkdir")
    uri = uri.format(abs=outside)
    path = gltf_with(seeds, model, **{kind: uri})
    with pytest.raises(InputError) as err:
        load_character(path)
    message = str(err.value)
    assert "\n" not in message and "model.gltf" in message and "own folder" in message, message


def test_files_inside_the_folder_are_read_and_copied_into_the_dance(seeds, planted):
    model, _ = planted
    (model / "textures").mkdir()
    (model / "textures" / "skin one.png").write_bytes((seeds / "skin.png").read_bytes())
    path = gltf_with(seeds, model, image="textures/skin%20one.png", buffer="./model.bin")
    glb = all_outputs(load_character(path))
    assert (seeds / "skin.png").read_bytes() in glb    # the user's own texture travels with their model


@pytest.mark.parametrize("suffix", FORMATS)
def test_no_output_format_carries_a_planted_file(seeds, planted, suffix, tmp_path):
    """The CLI, as a user runs it on a downloaded model that names a file outside its folder: refused
    before any dance is made, in one line, and nothing written."""
    model, outside = planted
    path = gltf_with(seeds, model, image=str(outside / "secret.png"))
    out = tmp_path / f"shared{suffix}"
    proc = subprocess.run([sys.executable, "-m", "dancesynth.cli", "dance", str(SONG), "--character", str(path),
                           "-o", str(out), "-q"], capture_output=True, text=True, timeout=120,
                          env={**os.environ, "NUMBA_CACHE_DIR": str(REPO / ".cache" / "numba")})
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1 and "own folder" in proc.stderr and "Traceback" not in proc.stderr
    assert not out.exists() and not list(tmp_path.glob(f".{out.name}*"))


# ----------------------------------------------------------------------------- bounded reads


def load_in_child(path, bone_map=None, timeout=60) -> tuple[str, float]:
    """(what loading ``path`` said, peak memory in MB) in a fresh process that may not block."""
    code = textwrap.dedent(f"""
        import sys
        from dancesynth.errors import InputError
        from dancesynth.retarget.character import load_character
        try:
            load_character({str(path)!r}, bone_map={None if bone_map is None else str(bone_map)!r})
            print("loaded")
        except InputError as e:
            print("error:", e)
        # VmHWM, not ru_maxrss: ru_maxrss survives exec, so it would report pytest's own peak
        print(next(int(ln.split()[1]) / 1024 for ln in open("/proc/self/status") if ln.startswith("VmHWM:")))
    """)
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout,
                          stdin=subprocess.PIPE)
    assert proc.returncode == 0 and not proc.stderr, proc.stderr
    said, peak = proc.stdout.strip().splitlines()
    return said, float(peak)


@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom", "/dev/stdin", "fifo"])
@pytest.mark.parametrize("kind", ["image", "buffer", "bone map"])
def test_devices_and_pipes_are_never_read(seeds, planted, device, kind):
    model, _ = planted
    if device == "fifo":
        os.mkfifo(model / "pipe")
    else:
        os.symlink(device, model / "pipe")
    if kind == "bone map":
        said, peak = load_in_child(gltf_with(seeds, model), bone_map=model / "pipe")
    else:
        said, peak = load_in_child(gltf_with(seeds, model, **{kind.split()[0]: "pipe"}))
    # A symlink to a device leads out of the folder; a FIFO inside it is no regular file. A texture that
    # cannot be read is drawn grey (the model still dances); a buffer or bone map cannot be done without.
    refused = said.startswith("error:") and ("regular file" in said or "own folder" in said)
    assert refused or (kind == "image" and device == "fifo" and said == "loaded"), said
    assert peak < 600, f"{peak:.0f} MB"


def test_a_texture_bomb_is_not_decoded(seeds, planted):
    """Six textures of one 13,000 x 13,000 PNG (170 kB): it peaked at 7 GB; now it is drawn grey."""
    model, _ = planted
    (model / "bomb.png").write_bytes((seeds / "bomb.png").read_bytes())

    def six(doc):
        doc["images"] = [{"uri": "bomb.png"}] * 6
        doc["textures"] = [{"source": k} for k in range(6)]
        doc["materials"] = (doc["materials"] * 6)[:6]
        for k, m in enumerate(doc["materials"]):
            m["pbrMetallicRoughness"] = {"baseColorTexture": {"index": k}}

    said, peak = load_in_child(gltf_with(seeds, model, edit=six))
    assert said == "loaded" and peak < 600, (said, peak)


def test_a_huge_bone_map_or_model_is_refused_by_its_size(seeds, planted):
    model, _ = planted
    big = model / "map.toml"
    with open(big, "wb") as fh:
        fh.truncate(2 ** 30)   # sparse: no disk, a gigabyte to read
    with pytest.raises(InputError, match="at most 1 MB"):
        load_character(seeds / "model.glb", bone_map=big)
    doc = json.loads((seeds / "model.gltf").read_text())
    doc["buffers"][0]["byteLength"] = 2 ** 40
    (model / "model.gltf").write_text(json.dumps(doc))
    with pytest.raises(InputError, match="too large"):
        load_character(model / "model.gltf")


# ----------------------------------------------------------------------------- checked at load


def vrm_edit(seeds, tmp_path, edit, name="avatar1.vrm"):
    doc, blob = split_glb((seeds / name).read_bytes())
    edit(doc)
    path = tmp_path / name
    path.write_bytes(glb_container(doc, blob))
    return path


def test_a_vrm_table_missing_a_leg_is_completed_from_the_rig_or_refused_at_load(seeds, tmp_path):
    path = vrm_edit(seeds, tmp_path, lambda d: d["extensions"]["VRMC_vrm"]["humanoid"]["humanBones"].pop("leftFoot"))
    character = load_character(path)          # the mannequin's joint names say where the foot is
    assert character.skeleton.names[character.bones["leftFoot"]] == "leftFoot"
    assert all_outputs(character)

    def anonymous(doc):   # no table entry and no name that says "foot"
        doc["extensions"]["VRMC_vrm"]["humanoid"]["humanBones"].pop("leftFoot")
        for k, node in enumerate(doc["nodes"]):
            node["name"] = f"bone{k}"
    with pytest.raises(InputError, match="leftFoot"):
        load_character(vrm_edit(seeds, tmp_path, anonymous))


def test_the_cli_refuses_a_broken_character_before_making_the_dance(seeds, tmp_path):
    def head_on_hips(doc):
        table = doc["extensions"]["VRMC_vrm"]["humanoid"]["humanBones"]
        table["head"] = dict(table["hips"])
    path = vrm_edit(seeds, tmp_path, head_on_hips)
    out = tmp_path / "dance.glb"
    proc = subprocess.run([sys.executable, "-m", "dancesynth.cli", "dance", str(SONG), "--character", str(path),
                           "-o", str(out)], capture_output=True, text=True, timeout=120,
                          env={**os.environ, "NUMBA_CACHE_DIR": str(REPO / ".cache" / "numba")})
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and "one joint" in proc.stderr, proc.stderr
    assert "tempo" not in proc.stdout and not out.exists()   # refused before any music was analysed


def _move_node(name, translation):
    def edit(doc):
        for node in doc["nodes"]:
            if node.get("name") in name:
                node["translation"] = translation
    return edit


@pytest.mark.parametrize("edit, words", [
    (_move_node(("leftUpperLeg", "rightUpperLeg"), [0.0, -0.05, 0.0]), "one point"),
    (_move_node(("leftLowerLeg",), [0.0, 0.0, 0.0]), "collapsed"),
    (_move_node(("leftFoot", "leftLowerLeg", "rightFoot", "rightLowerLeg"), [0.0, 0.0, 0.0]), "legs are 0.0 cm"),
    (_move_node(("leftFoot",), [1e30, 0.0, 0.0]), "not finite"),
])
def test_degenerate_rig_geometry_is_refused_at_load(seeds, tmp_path, edit, words):
    with pytest.raises(InputError, match=words):
        load_character(vrm_edit(seeds, tmp_path, edit))


def test_a_bone_map_putting_the_head_on_the_hips_is_refused(seeds, tmp_path):
    bone_map = tmp_path / "map.toml"
    bone_map.write_text('[bones]\nhead = "mixamorig:Hips"\n')
    with pytest.raises(InputError, match="one joint|hang below"):
        load_character(seeds / "rig_mixamo.bvh", bone_map=bone_map)


@pytest.mark.parametrize("text", ["[bones]\nhips = " + "[" * 3000 + "]" * 3000 + "\n", "[bones]\nhips = \"\xff\"\n"])
def test_a_bone_map_nested_deep_or_not_utf8_is_one_line(seeds, tmp_path, text):
    bone_map = tmp_path / "map.toml"
    bone_map.write_bytes(text.encode("latin-1"))
    with pytest.raises(InputError) as err:
        load_character(seeds / "rig_mixamo.bvh", bone_map=bone_map)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("edit, words", [
    (lambda text: re.sub(r"(?<=[\[,: ])0\.0(?=[,\]}])", "NaN", text, count=1), "NaN"),
    (lambda text: text.replace('"asset"', '"extras": ' + "[" * 2000 + "]" * 2000 + ', "asset"', 1), "nests"),
    (lambda text: text.replace('"uri": "skin.png"', '"uri": "skin.png\\u0000.png"'), "relative path"),
])
def test_hostile_json_is_one_line(seeds, tmp_path, edit, words):
    (tmp_path / "model.bin").write_bytes((seeds / "model.bin").read_bytes())
    path = tmp_path / "model.gltf"
    path.write_text(edit((seeds / "model.gltf").read_text()))
    with pytest.raises(InputError, match=words):
        load_character(path)


def test_null_extensions_still_dance_onto_the_users_model(seeds, tmp_path):
    doc, blob = split_glb((seeds / "model.glb").read_bytes())
    doc["extensions"] = None
    path = tmp_path / "odd.glb"
    path.write_bytes(glb_container(doc, blob))
    assert all_outputs(load_character(path))


def test_an_image_in_a_buffer_view_of_a_model_without_any_is_one_line(seeds, tmp_path):
    doc = json.loads((seeds / "model.gltf").read_text())
    (tmp_path / "model.bin").write_bytes((seeds / "model.bin").read_bytes())
    doc["images"] = [{"bufferView": 0, "mimeType": "image/png"}]
    views = doc.pop("bufferViews")
    for onto in (False, True):   # loading (the texture is grey) and adding the dance to the model
        doc["bufferViews"] = views if onto else None
        path = tmp_path / "model.gltf"
        path.write_text(json.dumps(doc))
        try:
            all_outputs(load_character(path))
        except InputError as err:
            assert "\n" not in str(err)


@pytest.mark.parametrize("depth", [300, 1000])
def test_a_joint_chain_too_deep_for_any_rig_is_refused(seeds, tmp_path, depth):
    def chain(doc):
        first = len(doc["nodes"])
        doc["nodes"] += [{"name": f"c{k}", "translation": [0, 0.01, 0], "children": [first + k + 1]}
                         for k in range(depth - 1)] + [{"name": "end", "translation": [0, 0.01, 0]}]
        doc["nodes"][0].setdefault("children", []).append(first)
        doc["skins"][0]["joints"] += list(range(first, first + depth))
    with pytest.raises(InputError, match="deep|joints"):
        load_character(vrm_edit(seeds, tmp_path, chain, "model.glb"))


def test_a_bvh_rig_at_the_origin_writes_every_format(seeds, tmp_path):
    """A BVH rig whose root OFFSET is 0 0 0: its .glb and .vrma are written (the .vrma refused it)."""
    assert all_outputs(load_character(seeds / "rig_mixamo.bvh"))

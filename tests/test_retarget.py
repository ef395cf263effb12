"""Retargeting (issue 14): any bundled style danced by any character, bones pointing where the source's
point, feet planted, root height in proportion; rigs a user brings mapped automatically or by a TOML."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import SHARED_MOCAP
from user_rigs import apose_mixamo_bvh, blender_style_bvh
from test_cli import TRUMPET, assert_clean_failure, cli
from dancesynth import rotations as rot
from dancesynth.errors import InputError
from dancesynth.eval.retarget import retarget_quality
from dancesynth.io.bvh import format_bvh, read_bvh
from dancesynth.kinematics import clip_fk
from dancesynth.retarget.character import builtin_character, load_character
from dancesynth.retarget.humanoid import find_bones
from dancesynth.retarget.rigs import LAYOUTS, rig_skeleton
from dancesynth.retarget.solve import retarget
from dancesynth.types import MotionClip, Skeleton

CC_RIG = SHARED_MOCAP / "cmu_iclone_cc" / "002_01.bvh"


@pytest.fixture(scope="module")
def dances(bundled_db, perfume_db, bundled_song):
    """A dance of each distinct skeleton layout: Daz (salsa), CMU (mj, whirl), G1 read as a humanoid (pop),
    Perfume (jpop, from the shared folder)."""
    from dancesynth.api import dance

    out = {s: dance(bundled_song, database=bundled_db, style=s, seed=3)
           for s in ("salsa-133-150bpm", "mj", "whirl", "pop-82-103bpm")}
    out["jpop"] = dance(bundled_song, database=perfume_db, style="jpop", seed=3)
    return out


def assert_faithful(source, target, bones):
    q = retarget_quality(source, target, find_bones(source.skeleton), bones)
    assert q["bone_direction_median_deg"] < 5.0, q
    assert q["skate_target"] <= q["skate_source"] * 1.1 + 1e-9, q
    assert q["penetration_target_m"] <= 0.02, q
    assert abs(q["root_height_target"] / q["root_height_source"] - 1) < 0.05, q
    return q


def test_every_bundled_skeleton_maps_its_humanoid_bones_by_name_and_hierarchy(bundled_db):
    expected = {"salsa-133-150bpm": {"leftUpperArm": "lShldr", "leftShoulder": "lCollar", "spine": "abdomen"},
                "mj": {"leftUpperArm": "LeftShoulder", "leftShoulder": "LeftCollar", "leftHand": "LeftWrist"},
                "whirl": {"leftUpperArm": "LeftArm", "leftShoulder": "LeftShoulder", "upperChest": "Spine1"},
                "pop-82-103bpm": {"leftUpperArm": "leftUpperArm", "leftFoot": "leftFoot", "head": "head"}}
    for style, want in expected.items():
        sk = bundled_db.styles[style].skeleton
        bones = find_bones(sk)
        assert {b: sk.names[bones[b]] for b in want} == want


@pytest.mark.parametrize("name", list(LAYOUTS))
def test_each_builtin_rig_maps_to_the_bones_it_was_built_with(name):
    sk, bones = rig_skeleton(name)
    assert find_bones(sk) == bones


def test_a_character_creator_rig_with_twist_helpers_maps_to_its_main_bones():
    if not CC_RIG.is_file():
        pytest.skip(f"{CC_RIG} (shared mocap data) is not on this machine")
    ch = load_character(CC_RIG)
    names = {b: ch.skeleton.names[j] for b, j in ch.bones.items()}
    assert names["hips"] == "CC_Base_Hip" and names["leftLowerArm"] == "CC_Base_L_Forearm"
    assert names["leftToes"] == "CC_Base_L_ToeBase" and names["spine"] == "CC_Base_Waist"


@pytest.mark.parametrize("style", ["salsa-133-150bpm", "mj", "whirl", "pop-82-103bpm", "jpop"])
@pytest.mark.parametrize("name", ["mixamo", "smpl", "cmu"])
def test_every_style_dances_faithfully_on_every_builtin_rig(dances, style, name):
    ch = builtin_character(name)
    out = retarget(dances[style], ch)
    assert out.skeleton is ch.skeleton and out.n_frames == dances[style].n_frames
    assert_faithful(dances[style], out, ch.bones)


def test_a_mixamo_named_apose_rig_in_centimetres_dances_with_its_own_names_and_proportions(dances, tmp_path):
    path = apose_mixamo_bvh(tmp_path)
    ch = load_character(path)
    src = dances["salsa-133-150bpm"]
    out = retarget(src, ch)
    assert_faithful(src, out, ch.bones)
    # In the A-pose rest the forearm hangs 40 degrees down; dancing, it points where the source's does.
    rest_arm = ch.skeleton.offsets[ch.bones["leftHand"]]
    assert rest_arm[1] < -0.1 * np.linalg.norm(rest_arm)


def test_dance_cli_writes_the_users_rig_with_its_joint_names_and_offsets(tmp_path, bundled_song):
    rig = apose_mixamo_bvh(tmp_path)
    out = tmp_path / "mine.bvh"
    r = cli(*["dance", TRUMPET, "--character", str(rig), "-o", str(out), "-q"])
    assert r.returncode == 0, (r.stdout + r.stderr)
    got, want = read_bvh(out), read_bvh(rig)
    assert got.skeleton.names == want.skeleton.names
    assert np.allclose(got.skeleton.offsets[1:], want.skeleton.offsets[1:], atol=1e-5)
    _, pos = clip_fk(got)
    _, rig_pos = clip_fk(want)
    assert pos[:, :, 1].min() > rig_pos[:, :, 1].min() - 0.02   # feet stay above its floor


def test_default_rig_is_the_same_whatever_the_style(tmp_path, bundled_song):
    rigs = set()
    for style in ("salsa-133-150bpm", "pop-82-103bpm"):
        out = tmp_path / f"{style}.bvh"
        assert cli(*["dance", TRUMPET, "--style", style, "-o", str(out), "-q"]).returncode == 0
        rigs.add(read_bvh(out).skeleton.names)
    assert rigs == {rig_skeleton("mannequin")[0].names}
    out = tmp_path / "source.bvh"
    assert cli(*["dance", TRUMPET, "--style", "pop-82-103bpm", "--character", "source", "-o", str(out),
                "-q"]).returncode == 0
    assert read_bvh(out).skeleton.n_joints == 19    # the G1 read as a humanoid, kept on request


def test_a_rig_without_the_required_bones_is_refused_with_the_toml_that_fixes_it(tmp_path, bundled_song):
    sk, _ = rig_skeleton("mannequin")
    names = tuple(f"bone_{i:02d}" for i in range(sk.n_joints))
    odd = Skeleton(names, sk.parents, sk.offsets, sk.channels, sk.end_sites)
    rig = tmp_path / "odd.bvh"
    rig.write_text(format_bvh(MotionClip(odd, 30.0, sk.offsets[:1], np.tile(rot.IDENTITY, (1, sk.n_joints, 1)))))
    out = tmp_path / "out.glb"
    r = cli("dance", TRUMPET, "--character", rig, "-o", out)
    assert_clean_failure(r, out)
    assert "hips" in (r.stdout + r.stderr) and "leftHand" in (r.stdout + r.stderr) and "[bones]" in (r.stdout + r.stderr) and "--bone-map" in (r.stdout + r.stderr)

    # The TOML the message shows makes the same rig dance.
    canonical = rig_skeleton("mannequin")[0].names
    toml = tmp_path / "bones.toml"
    toml.write_text("[bones]\n" + "".join(f'{canonical[i]} = "{n}"\n' for i, n in enumerate(names)))
    r = cli(*["dance", TRUMPET, "--character", str(rig), "--bone-map", str(toml), "-o",
             str(tmp_path / "odd_dance.bvh"), "-q"])
    assert r.returncode == 0, (r.stdout + r.stderr)
    assert set(read_bvh(tmp_path / "odd_dance.bvh").skeleton.names) == set(names)


@pytest.mark.parametrize("character, message", [
    ("robot", "unknown character 'robot'"),
    ("missing.glb", "does not exist"),
    ("rig.obj", "cannot read .obj"),
    ("skeleton_only.glb", "no skin"),
    ("corrupt.vrm", "corrupt.vrm"),
    ("empty.bvh", "empty.bvh"),
])
def test_bad_characters_get_one_line_errors_and_no_file(tmp_path, character, message):
    from dancesynth.export.gltf import glb_bytes

    sk, _ = rig_skeleton("mannequin")
    (tmp_path / "rig.obj").write_text("o cube\n")
    (tmp_path / "skeleton_only.glb").write_bytes(glb_bytes(MotionClip(sk, 30.0, sk.offsets[:1],
                                                                      np.tile(rot.IDENTITY, (1, sk.n_joints, 1)))))
    (tmp_path / "corrupt.vrm").write_bytes(b"glTF" + bytes(range(60)))
    (tmp_path / "empty.bvh").write_text("")
    out = tmp_path / "out.glb"
    spec = character if character == "robot" else tmp_path / character
    assert_clean_failure(cli("dance", TRUMPET, "-o", out, "--character", spec), out, message)


def test_an_output_extension_we_do_not_write_is_refused_before_dancing(tmp_path, bundled_song):
    out = tmp_path / "dance.obj"
    assert_clean_failure(cli("dance", TRUMPET, "-o", out), out, ".glb", ".vrma")


def test_bone_map_errors_name_the_bad_entry(tmp_path):
    toml = tmp_path / "bones.toml"
    toml.write_text('[bones]\nelbow = "x"\n')
    with pytest.raises(InputError, match="unknown humanoid bone 'elbow'"):
        load_character("mixamo", bone_map=toml)
    toml.write_text('[bones]\nhips = "nope"\n')
    with pytest.raises(InputError, match="is not a joint of mixamo"):
        load_character("mixamo", bone_map=toml)
    toml.write_text('[bones\n')
    with pytest.raises(InputError, match="not valid TOML"):
        load_character("mixamo", bone_map=toml)


def test_characters_lists_the_builtins():
    r = cli(*["characters"])
    assert r.returncode == 0
    for name in LAYOUTS:
        assert name in (r.stdout + r.stderr)
    assert "(default)" in (r.stdout + r.stderr) and ".vrm" in (r.stdout + r.stderr)


def test_fingers_follow_the_source_when_both_rigs_have_them(dances):
    """Daz's two-joint fingers drive a Character Creator rig's three-joint fingers; a rig without
    fingers (the mannequin's mitten hands) simply has none to move."""
    if not CC_RIG.is_file():
        pytest.skip(f"{CC_RIG} (shared mocap data) is not on this machine")
    src = dances["salsa-133-150bpm"]
    ch = load_character(CC_RIG)
    out = retarget(src, ch)
    sb = find_bones(src.skeleton)
    _, ps = clip_fk(src)
    _, pt = clip_fk(out)
    for finger in ("leftIndex", "rightMiddle", "leftThumb"):
        a, b = ("Metacarpal", "Proximal") if finger.endswith("Thumb") else ("Proximal", "Intermediate")
        want = ps[:, sb[finger + b]] - ps[:, sb[finger + a]]
        got = pt[:, ch.bones[finger + b]] - pt[:, ch.bones[finger + a]]
        cos = np.sum(want * got, -1) / np.linalg.norm(want, axis=-1) / np.linalg.norm(got, axis=-1)
        assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 1.0, finger
    assert not any("Index" in b for b in builtin_character("mannequin").bones)


def _blender_positions(bvh, frames, tmp_path) -> dict:
    """Bone heads in Blender's own BVH importer at ``frames``: {frame: {bone: (x, y, z)}}, Z up, file units."""
    import json
    import shutil
    import subprocess

    from conftest import REPO

    if shutil.which("blender") is None:
        pytest.skip("needs blender (bash scripts/setup.sh --test installs it)")
    report = tmp_path / "blender.json"
    subprocess.run(["blender", "-b", "--factory-startup", "--python", str(REPO / "tests" / "clients" /
                    "blender_import.py"), "--", str(bvh), str(read_bvh(bvh).n_frames), str(report),
                    ",".join(map(str, frames))], capture_output=True, text=True, timeout=300)
    data = json.loads(report.read_text())
    assert data["errors"] == [], data["errors"]
    return {int(f): v for f, v in data["head_positions"].items()}


@pytest.mark.blender
def test_a_blender_style_rig_in_centimetres_dances_on_its_floor_in_its_own_units(tmp_path):
    """Issue 31: a rig whose root OFFSET is its rest position and whose position channels are absolute (Blender,
    Mixamo) was read with its hips at twice their height, and its dance came back in metres with the feet
    0.95 m above the floor in Blender. Read as Blender reads it, it dances on its floor, in centimetres."""
    rig = blender_style_bvh(tmp_path)
    read = read_bvh(rig)
    assert read.meta["root_channels"] == "absolute" and read.meta["source_units"] == "cm"
    assert read.root_pos[0, 1] == pytest.approx(0.96, abs=1e-6)          # not 1.92
    out = tmp_path / "mine.bvh"
    r = cli(*["dance", TRUMPET, "--character", str(rig), "-o", str(out), "-q"])
    assert r.returncode == 0, (r.stdout + r.stderr)
    text = out.read_text()
    assert read_bvh(out).meta["source_units"] == "cm"
    raw_rig, raw_out = (read_bvh(p, to_metres=False) for p in (rig, out))
    assert raw_out.skeleton.names == raw_rig.skeleton.names and "mixamorig:Hips" in text
    assert np.allclose(raw_out.skeleton.offsets[1:], raw_rig.skeleton.offsets[1:], atol=1e-4)   # its own cm
    # Feet on the floor and the hips at a standing height, in our reading and in Blender's.
    _, rest = clip_fk(read)
    floor = rest[0, :, 1].min()                                   # the rig's one frame stands on its floor
    leg = rest[0, 0, 1] - floor                                   # hips above it, standing straight
    dance = read_bvh(out)
    _, pos = clip_fk(dance)
    feet = [dance.skeleton.index(f"mixamorig:{s}Foot") for s in ("Left", "Right")]
    assert pos[:, feet, 1].min() >= floor - 0.02 - 0.1            # ankles: the toes reach 10 cm lower at most
    assert 0.8 <= np.median(pos[:, 0, 1] - floor) / leg <= 1.0
    frames = [0, dance.n_frames // 2, dance.n_frames - 1]
    blender = _blender_positions(out, frames, tmp_path)
    for f in frames:   # Blender keeps the file's centimetres (global_scale 1), Z up
        assert blender[f]["mixamorig:Hips"][2] / 100.0 == pytest.approx(pos[f, 0, 1], abs=0.01), f
        for s, j in zip(("Left", "Right"), feet):
            assert blender[f][f"mixamorig:{s}Foot"][2] / 100.0 == pytest.approx(pos[f, j, 1], abs=0.01), f


def test_a_root_channel_added_to_its_offset_is_read_so(tmp_path):
    """iClone writes the root's position channels relative to its OFFSET (three.js adds the two): such a file
    keeps that reading, so the dancer is not sunk into the floor."""
    text = blender_style_bvh(tmp_path).read_text().splitlines()
    values = text[-1].split()
    values[1] = "0.500000"                                    # 0.5 cm above the rest position
    (tmp_path / "added.bvh").write_text("\n".join(text[:-1] + [" ".join(values)]) + "\n")
    clip = read_bvh(tmp_path / "added.bvh")
    assert clip.meta["root_channels"] == "added to the OFFSET"
    assert clip.root_pos[0, 1] == pytest.approx(0.965, abs=1e-6)

"""The mannequin's body (issue 14, a skinned character): a closed, outward-facing, person-sized
dancer with smooth skin weights, so that it bends at elbows and knees without tearing or spiking,
dressed in a few colours, the same every time and quick to make."""

from __future__ import annotations


import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from dancesynth.errors import InputError
from dancesynth.kinematics import fk
from dancesynth.retarget.mannequin import PALETTE, mannequin_character, mannequin_mesh
from dancesynth.retarget.rigs import rig_skeleton


@pytest.fixture(scope="module")
def mannequin():
    return mannequin_character()


def rest_positions(character) -> np.ndarray:
    return fk(character.rest_rot, character.rest_root, character.skeleton.offsets, character.skeleton.parents)[1]


def skinned_positions(character, local_rot, root_pos) -> np.ndarray:
    """The mesh's vertices (V, 3) in a pose, by linear blend skinning written out here: each joint
    carries its vertices from where it stands in the rest pose to where it stands in the pose."""
    mesh, sk = character.mesh, character.skeleton
    g_rot, g_pos = fk(local_rot, root_pos, sk.offsets, sk.parents)
    rest = rest_positions(character)
    turn = Rotation.from_quat(g_rot).as_matrix()
    p = mesh.positions.astype(np.float64)
    out = np.zeros_like(p)
    for k in range(4):
        j = mesh.joints[:, k]
        out += mesh.weights[:, k, None] * (np.einsum("vab,vb->va", turn[j], p - rest[j]) + g_pos[j])
    return out


def welded(mesh) -> tuple[np.ndarray, np.ndarray]:
    """(positions, triangles) with vertices at one place merged: colour seams are duplicated vertices."""
    points, index = np.unique(np.round(mesh.positions.astype(np.float64), 6), axis=0, return_inverse=True)
    return points, index.reshape(-1)[mesh.indices.astype(np.int64)]


def edges(triangles) -> np.ndarray:
    return np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])


def bone_segments(character) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """(joint, start, end) of each bone in the rest pose: to each child, or to the End Site."""
    sk, rest = character.skeleton, rest_positions(character)
    segments = [(sk.parents[c], rest[sk.parents[c]], rest[c]) for c in range(1, sk.n_joints)]
    return segments + [(j, rest[j], rest[j] + tip) for j, tip in sk.end_sites.items()]


def test_the_body_stands_a_dancers_height_on_the_floor_in_the_rigs_t_pose(mannequin):
    p = mannequin.mesh.positions
    assert 1.70 <= p[:, 1].max() <= 1.80                       # height, metres
    assert -0.002 <= p[:, 1].min() <= 0.005                    # shoes on the floor, not through it
    assert 1.6 <= np.ptp(p[:, 0]) <= 1.9                       # arm span in the T-pose
    assert np.ptp(p[:, 2]) < 0.45                              # front to back: heel/bun to toes
    assert 3000 <= len(mannequin.mesh.indices) <= 8000         # low-poly
    mirrored = p * np.array([-1.0, 1.0, 1.0])                  # left and right are one body, mirrored
    assert cKDTree(p).query(mirrored)[0].max() < 1e-5
    feet = p[p[:, 1] < 0.02]
    assert len(feet) > 10 and np.all(np.abs(np.abs(feet[:, 0]) - 0.10) < 0.06)   # the soles, under the legs


def test_the_body_is_closed_with_every_face_turned_outwards(mannequin):
    points, tris = welded(mannequin.mesh)
    e = edges(tris)
    key = e[:, 0] * len(points) + e[:, 1]
    assert len(np.unique(key)) == len(key)                     # no edge twice the same way: consistent winding
    assert np.all(np.isin(e[:, 1] * len(points) + e[:, 0], key))   # ... and each has its twin: no holes
    n_parts, part = connected_components(coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])),
                                                    shape=(len(points),) * 2))
    corners = points[tris]
    volume = np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])) / 6.0
    part_volume = np.bincount(part[tris[:, 0]], volume, n_parts)
    assert n_parts >= 10 and np.all(part_volume > 0)           # each part encloses space: faces point out
    assert 0.045 < part_volume.sum() < 0.09                    # m^3: about a person's 60-70 litres

    mesh = mannequin.mesh
    p = mesh.positions.astype(np.float64)
    t = mesh.indices.astype(np.int64)
    face = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    assert np.mean(np.sum(face * mesh.normals[t].sum(axis=1), axis=1) > 0) > 0.995   # normals agree with faces
    assert np.allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-5)
    # Faces point away from the bone they move with (the head and hands are bulkier than their bone).
    centre = p[t].mean(axis=1)
    best = np.full(len(t), np.inf)
    away = np.zeros(len(t), dtype=bool)
    owner = mesh.joints[t[:, 0], 0]
    for j, a, b in bone_segments(mannequin):
        mine = owner == j
        s = np.clip((centre[mine] - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
        out = centre[mine] - (a + s[:, None] * (b - a))
        dist = np.linalg.norm(out, axis=1)
        closer = dist < best[mine]
        idx = np.flatnonzero(mine)[closer]
        best[idx], away[idx] = dist[closer], np.sum(face[idx] * out[closer], axis=1) > 0
    assert away.mean() > 0.97


def test_skin_weights_are_normalised_and_blend_across_each_bending_joint(mannequin):
    mesh, bones = mannequin.mesh, mannequin.bones
    assert mesh.joints.shape == mesh.weights.shape == (len(mesh.positions), 4)
    assert np.all(mesh.weights >= 0) and np.allclose(mesh.weights.sum(axis=1), 1.0, atol=1e-6)
    assert mesh.joints.max() < 22 and mesh.joints.dtype == np.uint16
    assert set(np.unique(mesh.joints[mesh.weights > 0])) == set(range(22))   # every joint moves some of the body
    dense = np.zeros((len(mesh.positions), 22))
    np.add.at(dense, (np.arange(len(dense))[:, None], mesh.joints.astype(np.int64)), mesh.weights)  # unused slots: 0
    for upper, lower in [("leftUpperArm", "leftLowerArm"), ("rightUpperLeg", "rightLowerLeg"),
                         ("leftShoulder", "leftUpperArm"), ("hips", "spine"), ("rightLowerLeg", "rightFoot")]:
        shared = (dense[:, bones[upper]] > 0.2) & (dense[:, bones[lower]] > 0.2)
        assert shared.sum() >= 16, (upper, lower)              # at least one ring eases from one bone to the next


def test_bending_every_joint_hard_tears_and_spikes_nothing(mannequin):
    sk, b = mannequin.skeleton, mannequin.bones
    turn = np.zeros((sk.n_joints, 3))
    for side, s in (("left", 1.0), ("right", -1.0)):
        turn[b[side + "LowerArm"], 1] = -s * 2.1               # elbows bent 120 degrees
        turn[b[side + "UpperArm"], 2] = -s * 1.2               # arms down
        turn[b[side + "Hand"], 2] = -s * 1.0
        turn[b[side + "UpperLeg"], 0] = -1.5                   # thighs up ...
        turn[b[side + "LowerLeg"], 0] = 2.1                    # ... knees bent 120 degrees: a deep squat
        turn[b[side + "Foot"], 0] = 0.7
        turn[b[side + "Shoulder"], 2] = s * 0.3                # a shrug
    turn[b["spine"], 1], turn[b["chest"], 0], turn[b["neck"], 0], turn[b["head"], 1] = 0.5, 0.3, 0.5, 0.6
    posed = skinned_positions(mannequin, Rotation.from_rotvec(turn).as_quat(), mannequin.rest_root)
    rest = mannequin.mesh.positions.astype(np.float64)
    e = edges(mannequin.mesh.indices.astype(np.int64))
    before = np.linalg.norm(rest[e[:, 0]] - rest[e[:, 1]], axis=1)
    after = np.linalg.norm(posed[e[:, 0]] - posed[e[:, 1]], axis=1)
    assert np.max(after[before > 0] / before[before > 0]) < 2.5   # no triangle drawn out into a spike
    assert after.max() < 0.1

    def off_bones(points, joint_pos):
        segments = [(joint_pos[sk.parents[c]], joint_pos[c]) for c in range(1, sk.n_joints)]
        d = np.full(len(points), np.inf)
        for a, z in segments:
            s = np.clip((points - a) @ (z - a) / ((z - a) @ (z - a)), 0.0, 1.0)
            d = np.minimum(d, np.linalg.norm(points - (a + s[:, None] * (z - a)), axis=1))
        return d

    _, joints_posed = fk(Rotation.from_rotvec(turn).as_quat(), mannequin.rest_root, sk.offsets, sk.parents)
    drift = off_bones(posed, joints_posed) - off_bones(rest, rest_positions(mannequin))
    assert drift.max() < 0.08                                  # no vertex flung away from the skeleton


def test_the_outfit_has_a_top_trousers_shoes_and_skin_in_linear_rgb(mannequin):
    mesh = mannequin.mesh
    assert mesh.colours.shape == mesh.positions.shape and mesh.colours.min() >= 0 and mesh.colours.max() <= 1
    tree = cKDTree(mesh.positions)

    def colour_at(point):
        return mesh.colours[tree.query(point)[1]]

    chest, thigh, toe = colour_at([0.0, 1.25, 0.2]), colour_at([0.2, 0.75, 0.0]), colour_at([0.1, 0.03, 0.25])
    hand, face = colour_at([0.8, 1.42, 0.0]), colour_at([0.0, 1.58, 0.2])
    assert np.allclose(chest, PALETTE["top"]) and np.allclose(thigh, PALETTE["trousers"])
    assert np.allclose(toe, PALETTE["shoes"]) and np.allclose(hand, PALETTE["skin"]) and np.allclose(face, hand)
    assert len({tuple(c) for c in (chest, thigh, toe, hand)}) == 4
    assert np.allclose(colour_at([0.0, 1.8, -0.05]), PALETTE["hair"])
    assert PALETTE["trousers"].sum() < PALETTE["top"].sum() < PALETTE["shoes"].sum()   # dark legs, light shoes


def test_the_body_is_the_same_every_time(mannequin):
    skeleton, bones = rig_skeleton("mannequin")
    first = mannequin_mesh(skeleton, bones)
    again = mannequin_mesh(skeleton, bones)
    for name in ("positions", "normals", "indices", "joints", "weights", "colours"):
        assert np.array_equal(getattr(first, name), getattr(again, name)), name
    assert first.positions.dtype == np.float32 and first.indices.dtype == np.uint32


def test_the_mannequin_character_is_the_canonical_rig_with_its_body(mannequin):
    skeleton, bones = rig_skeleton("mannequin")
    assert mannequin is mannequin_character()                  # made once
    assert mannequin.name == "mannequin" and mannequin.kind == "builtin" and mannequin.bones == bones
    assert mannequin.skeleton.names == skeleton.names and np.array_equal(mannequin.skeleton.offsets, skeleton.offsets)
    assert np.array_equal(mannequin.rest_rot, np.tile([0.0, 0.0, 0.0, 1.0], (22, 1)))
    assert np.array_equal(mannequin.rest_root, skeleton.offsets[0])
    assert np.array_equal(mannequin.mesh.positions, mannequin_mesh(skeleton, bones).positions)


def test_a_rig_without_the_humanoid_bones_is_refused():
    skeleton, bones = rig_skeleton("mannequin")
    with pytest.raises(InputError, match="leftHand"):
        mannequin_mesh(skeleton, {k: v for k, v in bones.items() if k != "leftHand"})


def test_a_taller_rig_gets_a_taller_body_on_the_same_floor():
    skeleton, bones = rig_skeleton("mannequin")
    tall = mannequin_mesh(skeleton.scaled(1.1), bones).positions
    assert tall[:, 1].max() == pytest.approx(1.1 * mannequin_mesh(skeleton, bones).positions[:, 1].max(), rel=1e-5)
    assert abs(tall[:, 1].min()) < 0.005

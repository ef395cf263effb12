"""Left-right mirroring of motion, on the bundled salsa capture."""

from __future__ import annotations

import numpy as np
import pytest

from dancesynth.errors import InputError
from dancesynth.kinematics import fk
from dancesynth.motion.mirror import mirror_motion, mirror_pairs, symmetry_error
from dancesynth.motion.roles import find_roles
from dancesynth.types import Skeleton

M = np.array([-1.0, 1.0, 1.0])


@pytest.fixture(scope="module")
def salsa(bundled_db):
    return bundled_db.styles_of("salsa")[0].clip(0)


def _symmetrised(skeleton: Skeleton) -> Skeleton:
    """The skeleton with each pair's offsets averaged after reflection (centre joints get x = 0)."""
    pairs = mirror_pairs(skeleton)
    off = 0.5 * (skeleton.offsets + skeleton.offsets[pairs] * M)
    return Skeleton(skeleton.names, skeleton.parents, off, skeleton.channels, dict(skeleton.end_sites))


def _depth(parents) -> int:
    depth = np.zeros(len(parents), dtype=int)
    for j in range(1, len(parents)):
        depth[j] = depth[parents[j]] + 1
    return int(depth.max())


def _mirror_positions_error(skeleton, clip) -> float:
    """Largest distance between the mirrored motion's joints and the reflected original's counterparts."""
    rot_m, pos_m, _ = mirror_motion(skeleton, clip.local_rot, clip.root_pos)
    _, p = fk(clip.local_rot, clip.root_pos, skeleton.offsets, skeleton.parents)
    _, p_m = fk(rot_m, pos_m, skeleton.offsets, skeleton.parents)
    expected = (p * M)[:, mirror_pairs(skeleton)]
    return float(np.linalg.norm(p_m - expected, axis=-1).max())


def test_mirroring_twice_gives_the_input(salsa):
    rot_m, pos_m, con_m = mirror_motion(salsa.skeleton, salsa.local_rot, salsa.root_pos, salsa.contacts)
    assert not np.allclose(rot_m, salsa.local_rot)
    rot_2, pos_2, con_2 = mirror_motion(salsa.skeleton, rot_m, pos_m, con_m)
    sign = np.where(np.sum(rot_2 * salsa.local_rot, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    np.testing.assert_allclose(rot_2 * sign, salsa.local_rot, atol=1e-12)
    np.testing.assert_allclose(pos_2, salsa.root_pos, atol=1e-12)
    np.testing.assert_array_equal(con_2, salsa.contacts)
    np.testing.assert_array_equal(con_m, salsa.contacts[:, ::-1])
    np.testing.assert_array_equal(pos_m[:, 0], -salsa.root_pos[:, 0])


def test_mirrored_positions_are_the_reflected_original(salsa):
    sk = salsa.skeleton
    err = symmetry_error(sk)
    # The salsa skeleton is nearly symmetric (its head and eyes sit a few mm off centre).
    assert 0.0 < err < 0.01, err
    # Each offset error is rotated, not grown, so it adds at most once per bone along a chain.
    assert _mirror_positions_error(sk, salsa) <= _depth(sk.parents) * err + 1e-9

    sym = _symmetrised(sk)
    assert symmetry_error(sym) < 1e-12
    assert _mirror_positions_error(sym, salsa) < 1e-9


def test_pairs_are_an_involution_that_swaps_sides(salsa):
    sk = salsa.skeleton
    pairs = mirror_pairs(sk)
    np.testing.assert_array_equal(pairs[pairs], np.arange(sk.n_joints))
    roles = find_roles(sk)
    for left, right in (roles.wrists, roles.ankles, roles.knees, roles.shoulders):
        assert (pairs[left], pairs[right]) == (right, left)
    assert pairs[roles.root] == roles.root and pairs[roles.head] == roles.head
    assert np.count_nonzero(pairs != np.arange(sk.n_joints)) == 2 * 19   # 19 pairs, 5 centre joints


def test_names_in_other_conventions_pair_up():
    names = ("mixamorig:Hips", "mixamorig:LeftUpLeg", "mixamorig:RightUpLeg", "thigh_l", "thigh_r", "Spine")
    sk = Skeleton(names, [-1, 0, 0, 0, 0, 0], np.zeros((6, 3)), (("Xrotation",),) * 6)
    np.testing.assert_array_equal(mirror_pairs(sk), [0, 2, 1, 4, 3, 5])


def test_a_skeleton_without_sides_cannot_be_mirrored():
    names = ("hips", "spine", "neck", "head")
    sk = Skeleton(names, [-1, 0, 1, 2], np.array([[0, 0, 0], [0, 0.2, 0], [0, 0.3, 0], [0, 0.1, 0]]),
                  (("Xrotation",),) * 4)
    np.testing.assert_array_equal(mirror_pairs(sk), np.arange(4))
    q = np.tile([0.0, 0.0, 0.0, 1.0], (3, 4, 1))
    with pytest.raises(InputError, match="no left/right joint pairs"):
        mirror_motion(sk, q, np.zeros((3, 3)))


def test_sides_with_different_hierarchies_cannot_be_mirrored():
    names = ("hips", "lThigh", "rThigh", "lShin", "rShin")
    sk = Skeleton(names, [-1, 0, 0, 1, 1], np.zeros((5, 3)), (("Xrotation",),) * 5)   # rShin hangs off lThigh
    with pytest.raises(InputError, match="same hierarchy"):
        mirror_motion(sk, np.tile([0.0, 0.0, 0.0, 1.0], (2, 5, 1)), np.zeros((2, 3)))


def test_the_g1_robot_faces_x_and_is_mirrored_across_its_own_sagittal_plane(bundled_db):
    """The G1 rig's left and right lie along Z (it faces +X): mirroring reflects Z, not X."""
    from dancesynth.motion.mirror import lateral_axis

    pop = bundled_db.styles_of("pop")[0]
    salsa = bundled_db.styles_of("salsa")[0]
    assert lateral_axis(pop.skeleton) == 2 and lateral_axis(salsa.skeleton) == 0
    sk, clip = pop.skeleton, pop.clip(0).frames(0, 300)
    err = symmetry_error(sk)
    assert err < 0.01, err                     # 6 mm: the robot is built symmetric
    rot_m, pos_m, _ = mirror_motion(sk, clip.local_rot, clip.root_pos)
    _, p = fk(clip.local_rot, clip.root_pos, sk.offsets, sk.parents)
    _, p_m = fk(rot_m, pos_m, sk.offsets, sk.parents)
    expected = (p * np.array([1.0, 1.0, -1.0]))[:, mirror_pairs(sk)]
    assert np.linalg.norm(p_m - expected, axis=-1).max() <= _depth(sk.parents) * err + 1e-9

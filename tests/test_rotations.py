"""Our numpy quaternion algebra gives SciPy's numbers (it replaced SciPy's ``Rotation`` for speed)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dancesynth import rotations as rot


@pytest.mark.parametrize("shape", [(), (7,), (5, 3)])
def test_the_algebra_matches_scipy(shape):
    rng = np.random.default_rng(len(shape))
    a, b = rng.normal(size=shape + (4,)), rng.normal(size=shape + (4,))
    v = rng.normal(size=shape + (3,))
    ra, rb = Rotation.from_quat(a.reshape(-1, 4)), Rotation.from_quat(b.reshape(-1, 4))
    assert np.allclose(rot.mul(a, b).reshape(-1, 4), (ra * rb).as_quat(canonical=False), atol=1e-12)
    assert np.allclose(rot.apply(a, v).reshape(-1, 3), ra.apply(v.reshape(-1, 3)), atol=1e-12)
    assert np.allclose(rot.log(a).reshape(-1, 3), ra.as_rotvec(), atol=1e-12)
    assert np.allclose(rot.exp(v).reshape(-1, 4), Rotation.from_rotvec(v.reshape(-1, 3)).as_quat(canonical=False),
                       atol=1e-12)


def test_broadcasting_and_the_edge_cases():
    rng = np.random.default_rng(9)
    one, many, v = rng.normal(size=4), rng.normal(size=(6, 4)), rng.normal(size=(6, 3))
    assert np.allclose(rot.mul(one, many), (Rotation.from_quat(one) * Rotation.from_quat(many)).as_quat(canonical=False))
    assert np.allclose(rot.apply(one, v), Rotation.from_quat(one).apply(v))
    # the identity, tiny and half-turn rotations, and a quaternion on the far hemisphere
    q = np.array([[0, 0, 0, 1.0], [1e-9, 0, 0, 1], [0, 1, 0, 0], [0, 0, 1e-5, -1], [1, 0, 0, 1e-12]])
    assert np.allclose(rot.log(q), Rotation.from_quat(q).as_rotvec(), atol=1e-12)
    w = np.array([[0, 0, 0.0], [1e-9, 0, 0], [0, np.pi, 0], [1e-4, 2e-4, 0]])
    assert np.allclose(rot.exp(w), Rotation.from_rotvec(w).as_quat(canonical=False), atol=1e-12)
    u = rng.normal(size=(4, 3))
    assert np.allclose(rot.apply(rot.exp(w), u), Rotation.from_rotvec(w).apply(u), atol=1e-12)


def test_euler_angles_in_pieces_are_those_of_the_whole(monkeypatch):
    """A long dance's Euler angles are converted a few thousand frames at a time (memory); the
    angles, continuous across the pieces, are those of one conversion."""
    rng = np.random.default_rng(3)
    q = np.cumsum(rng.normal(size=(500, 4, 4)) * 0.1, axis=0) + np.array([0, 0, 0, 2.0])
    whole = rot.to_euler(q, "ZXY")
    monkeypatch.setattr(rot, "EULER_CHUNK", 37)
    assert np.array_equal(rot.to_euler(q, "ZXY"), whole)
    assert np.array_equal(rot.to_euler(q[250:], "ZXY", prev=whole[249]), whole[250:])
    assert np.all(np.abs(np.diff(whole, axis=0)) < 90)   # continuous: no 360-degree flips

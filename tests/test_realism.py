"""FID_k / FID_g / Div_k / Div_g (eval.realism): analytic cases, real mocap, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from dancesynth import rotations as rot
from dancesynth.errors import InputError
from dancesynth.eval import realism as R
from dancesynth.motion.resample import resample_clip_arrays
from dancesynth.types import MotionClip

LARGEST = "salsa-97-124bpm"  # the bench's realism style: the salsa style with the most takes (Daz skeleton, 43 joints)


@pytest.fixture(scope="module")
def db():
    from dancesynth.motion.database import open_database

    return open_database()


@pytest.fixture(scope="module")
def split(db):
    """The largest style with 20 % of its clips held out (seed 0), and the clips left."""
    reduced, held = R.held_out_split(db.styles[LARGEST], seed=0)
    return reduced, held, [reduced.clip(i) for i in range(reduced.n_clips)]


def frozen(clip: MotionClip, seconds: float, fps: float = 30.0) -> MotionClip:
    """The middle pose of ``clip`` held still."""
    n, mid = int(seconds * fps) + 1, clip.n_frames // 2
    return MotionClip(clip.skeleton, fps, np.repeat(clip.root_pos[mid:mid + 1], n, axis=0),
                      np.repeat(clip.local_rot[mid:mid + 1], n, axis=0))


def swaying(skeleton, rest_rot, *, seed: int, amplitude: float, hz: float, seconds: float = 12.0,
            fps: float = 30.0) -> MotionClip:
    """Every joint swinging about random axes: sines of random phase, amplitude ~ ``amplitude`` rad at ~ ``hz``."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * fps) + 1)[:, None, None] / fps
    j = skeleton.n_joints
    amp = amplitude * rng.uniform(0.5, 1.5, (1, j, 3))
    freq = hz * rng.uniform(0.7, 1.3, (1, j, 3))
    rotvec = amp * np.sin(2 * np.pi * freq * t + rng.uniform(0, 2 * np.pi, (1, j, 3)))
    local = rot.mul(np.broadcast_to(rest_rot, rotvec.shape[:2] + (4,)), rot.exp(rotvec))
    sway, bounce = amplitude * rng.uniform(0.1, 0.3), amplitude * rng.uniform(0.2, 0.4)
    root = np.zeros((len(t), 3))
    root[:, 1] = 0.9 + bounce * np.sin(2 * np.pi * freq[0, 0, 0] * t[:, 0, 0])
    root[:, 0] = sway * np.sin(np.pi * freq[0, 0, 1] * t[:, 0, 0])
    return MotionClip(skeleton, fps, root, local)


# ---------------------------------------------------------------------------------------------
# FID and diversity on numbers


def test_fid_of_gaussians_matches_the_closed_form():
    rng = np.random.default_rng(0)
    d, n = 4, 20000
    m = np.array([1.0, -2.0, 0.5, 0.0])
    a = rng.normal(size=(n, d))
    b = m + 2.0 * rng.normal(size=(n, d))
    # N(0, I) vs N(m, 4 I): |m|^2 + tr(I + 4I - 2 * 2I) = |m|^2 + d
    assert R.fid(a, b) == pytest.approx(m @ m + d, rel=0.03)
    same = R.fid(a, rng.normal(size=(n, d)))
    assert same < 0.01
    assert R.fid(a, a) == pytest.approx(0.0, abs=1e-9)


def test_fid_stays_finite_with_fewer_samples_than_dimensions():
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(5, 40)), rng.normal(size=(7, 40)) + 3.0
    value = R.fid(a, b)
    assert np.isfinite(value) and value > 40 * 9 * 0.5  # the mean shift alone is 40 * 3^2
    assert R.fid(a, a) == pytest.approx(0.0, abs=1e-6)
    assert R.fid(np.ones((4, 3)), np.ones((6, 3))) == pytest.approx(0.0, abs=1e-12)  # constant sets


def test_diversity_is_the_mean_pairwise_distance():
    assert R.diversity(np.tile([1.0, 2.0, 3.0], (6, 1))) == 0.0
    pts = np.array([[0.0, 0.0], [3.0, 4.0], [0.0, 8.0]])
    assert R.diversity(pts) == pytest.approx((5.0 + 8.0 + 5.0) / 3)
    assert np.isnan(R.diversity(pts[:1]))


def test_normalise_features_uses_the_reference_scale():
    ref = np.array([[0.0, 1.0], [2.0, 1.0]])
    gen = np.array([[4.0, 1.5]])
    r, g = R.normalise_features(ref, gen, min_std=0.5)
    np.testing.assert_allclose(r, [[-1.0, 0.0], [1.0, 0.0]])
    np.testing.assert_allclose(g, [[3.0, 1.0]])  # the constant column is counted in units of min_std
    r, g = R.normalise_features(ref, gen, mode="combined")
    both = np.vstack([ref, gen])
    np.testing.assert_allclose(g, (gen - both.mean(0)) / both.std(0))


# ---------------------------------------------------------------------------------------------
# Features of bundled skeletons


@pytest.mark.parametrize("style, joints", [(LARGEST, 21), ("mj", 24), ("pop-82-103bpm", 19)])
def test_feature_dimensions(db, style, joints):
    clip = db.styles[style].clip(0)
    mapping = R.smpl_joint_map(clip.skeleton)
    assert len(mapping) == joints and list(mapping) == [n for n in R.SMPL_JOINTS if n in mapping]
    k, g = R.kinetic_features(clip), R.geometric_features(clip)
    assert k.shape == (3 * joints,) and g.shape == (len(R.GEOMETRIC_FEATURES),) == (32,)
    assert np.all(np.isfinite(k)) and np.all(k >= 0)
    assert np.all((g >= 0) & (g <= 1))


def test_joint_map_of_the_daz_salsa_skeleton(db):
    sk = db.styles[LARGEST].skeleton
    named = {k: sk.names[v] for k, v in R.smpl_joint_map(sk).items()}
    assert named["pelvis"] == "hip" and named["spine3"] == "chest" and named["neck"] == "neck"
    assert named["left_shoulder"] == "lShldr" and named["left_collar"] == "lCollar"
    assert named["left_wrist"] == "lHand" and named["left_hand"] == "lMid1"
    assert "spine2" not in named and "left_foot" not in named  # no such joints: left out


def test_features_barely_depend_on_the_frame_rate(db):
    clip = db.styles[LARGEST].clip(0)
    k60, g60 = R.kinetic_features(clip), R.geometric_features(clip)
    for fps in (30.0, 24.0):
        rot_, pos, _ = resample_clip_arrays(clip.local_rot, clip.root_pos, None, clip.fps, fps)
        low = MotionClip(clip.skeleton, fps, pos, rot_)
        k, g = R.kinetic_features(low).reshape(-1, 3), R.geometric_features(low)
        rel = np.abs(k - k60.reshape(-1, 3)) / k60.reshape(-1, 3)
        assert rel[:, :2].max() < 0.05     # kinetic energies
        assert rel[:, 2].max() < 0.2       # energy expenditure: resampling removes capture noise
        assert np.abs(g - g60).max() < 0.02


def test_kinetic_features_of_a_frozen_pose_are_zero(db):
    k = R.kinetic_features(frozen(db.styles["mj"].clip(0), 3.0))
    np.testing.assert_allclose(k, 0.0, atol=1e-9)


# ---------------------------------------------------------------------------------------------
# realism() on motions


def test_same_distribution_scores_near_zero_and_far_below_another(db):
    sk = db.styles["mj"].skeleton
    rest = db.styles["mj"].clip(0).local_rot[0]

    def family(seeds, **kw):
        return [swaying(sk, rest, seed=s, **kw) for s in seeds]

    a = family(range(0, 12), amplitude=0.15, hz=1.0)
    b = family(range(100, 112), amplitude=0.15, hz=1.0)
    c = family(range(200, 212), amplitude=0.2, hz=1.25)
    same, other = R.realism(b, a, window_s=4.0), R.realism(c, a, window_s=4.0)
    assert same["n_generated"] == same["n_reference"] == 12 * 5
    assert other["fid_k"] > 20 * same["fid_k"] and other["fid_g"] > 5 * same["fid_g"]
    # "near 0": within the sampling noise of 60 windows in 72 dimensions, far below the other family
    assert same["fid_k"] < 0.05 * other["fid_k"]


def test_frozen_pose_is_far_worse_than_real_mocap(split):
    reduced, held, rest = split
    mocap = R.realism(rest, held)
    still = R.realism([frozen(rest[0], 60.0)], held)
    assert still["fid_k"] > 4 * mocap["fid_k"]
    assert still["fid_g"] > 4 * mocap["fid_g"]
    assert still["div_k"] == 0.0 and still["div_g"] == 0.0
    assert mocap["div_k"] > 0.5 * mocap["div_k_ref"]
    # the reference's own diversity does not depend on what it is compared with
    assert still["div_k_ref"] == pytest.approx(mocap["div_k_ref"])
    assert still["div_g_ref"] == pytest.approx(mocap["div_g_ref"])
    assert mocap["dim_k"] == 63 and mocap["dim_g"] == 32 and len(mocap["joints"]) == 21
    assert mocap["n_reference"] > 20 and mocap["skipped_reference"] == 0


def test_realism_scores_several_sets_as_realism_does_one_by_one(split):
    _, held, rest = split
    sets = {"a": rest[:2], "still": [frozen(rest[0], 20.0)]}
    table = R.realism_scores(sets, held)
    assert list(table) == ["a", "still"]
    for name, motions in sets.items():
        assert table[name] == R.realism(motions, held)  # the shared reference features change nothing
    with pytest.raises(InputError, match=r"generated\['short'\]"):
        R.realism_scores({"a": rest[:2], "short": [rest[0].frames(0, 120)]}, held)
    with pytest.raises(InputError, match="dict"):
        R.realism_scores([rest[:2]], held)


def test_features_live_in_their_own_module_and_stay_importable_from_realism():
    from dancesynth.eval import realism_features as F

    assert all(hasattr(R, name) for name in R.__all__)
    for name in ("kinetic_features", "geometric_features", "smpl_joint_map", "SMPL_JOINTS", "GEOMETRIC_FEATURES",
                 "FEATURE_FPS", "MIN_DURATION_S"):
        assert getattr(R, name) is getattr(F, name)


def test_identical_copies_have_no_diversity(db):
    mj = db.styles["mj"]
    clip = mj.clip(1)
    out = R.realism([clip, clip], [mj.clip(0), mj.clip(2)], window_s=8.0, stride_s=8.0)
    assert out["n_generated"] == 2 and out["div_k"] == 0.0 and out["div_g"] == 0.0


# ---------------------------------------------------------------------------------------------
# held_out_split


def test_held_out_split_is_deterministic_and_keeps_partners_together(db):
    style = db.styles[LARGEST]
    reduced, held = R.held_out_split(style, seed=0)
    again, held2 = R.held_out_split(style, seed=0)
    names = [c.meta["name"] for c in held]
    assert names == [c.meta["name"] for c in held2] and reduced.fingerprint == again.fingerprint
    assert 3 <= len(held) <= 4 and reduced.n_clips == style.n_clips - len(held)
    assert not set(names) & set(reduced.clip_names)
    assert reduced.n_frames == style.n_frames - sum(c.n_frames for c in held)
    length = {n: style.clip(i).n_frames for i, n in enumerate(style.clip_names)}
    partner = {n: m for n in style.clip_names for m in style.clip_names
               if m != n and m.split("_")[1] == n.split("_")[1] and length[m] == length[n]}
    assert len(partner) == 4  # takes 04 and 05 have both dancers in this style
    for seed in range(6):  # partners of one take (60_xx / 61_xx) never straddle the split
        out = {c.meta["name"] for c in R.held_out_split(style, seed=seed)[1]}
        assert all(partner[n] in out for n in out if n in partner)
    _, one = R.held_out_split(style, n_clips=1, seed=3, by_take=False)
    assert len(one) == 1


def test_held_out_split_refuses_too_small_styles(db):
    with pytest.raises(InputError, match="to dance on"):
        R.held_out_split(db.styles["indian"])
    with pytest.raises(InputError, match="to dance on"):
        R.held_out_split(db.styles["mj"], n_clips=2)
    with pytest.raises(InputError, match="fraction"):
        R.held_out_split(db.styles[LARGEST], fraction=1.5)


# ---------------------------------------------------------------------------------------------
# Bad input


def test_bad_input_raises_input_error(db, split):
    _, held, rest = split
    pop = db.styles["pop-82-103bpm"].clip(0)   # another skeleton: the G1 read as a humanoid
    with pytest.raises(InputError, match="empty"):
        R.realism([], held)
    with pytest.raises(InputError, match="empty"):
        R.realism(rest[:1], [])
    with pytest.raises(InputError, match="list"):
        R.realism(rest[0], held)
    with pytest.raises(InputError, match="skeleton"):
        R.realism([pop], held)
    with pytest.raises(InputError, match="window"):
        R.realism([rest[0].frames(0, 120)], held)  # 2 s: shorter than one 5 s window
    first = rest[0]
    root = first.root_pos[:600].copy()  # a copy: the fixture's clips are shared
    root[10, 1] = np.nan
    bad = MotionClip(first.skeleton, first.fps, root, first.local_rot[:600])
    with pytest.raises(InputError, match="NaN"):
        R.realism([bad], held)
    with pytest.raises(InputError, match="NaN"):
        R.kinetic_features(bad)
    with pytest.raises(InputError, match="too short"):
        R.geometric_features(rest[0].frames(0, 3))
    with pytest.raises(InputError, match="window_s"):
        R.realism(rest, held, window_s=0.0)
    with pytest.raises(InputError, match="normalisation"):
        R.realism(rest, held, normalise="zscore")
    with pytest.raises(InputError, match="dimension"):
        R.fid(np.zeros((3, 4)), np.zeros((3, 5)))
    with pytest.raises(InputError, match="at least 2"):
        R.fid(np.zeros((1, 4)), np.zeros((3, 4)))
    with pytest.raises(InputError, match="NaN"):
        R.fid(np.full((3, 2), np.nan), np.zeros((3, 2)))
    with pytest.raises(InputError, match="matrix"):
        R.diversity(np.zeros(5))

"""The learned pose generator's pieces: pose encoding, torch FK, windowed AdaIN, losses, overfitting."""

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from dancesynth import rotations as rot  # noqa: E402
from dancesynth.engines.neural.data import (TRAIN_FPS, beat_phase, decode_pose, encode_pose,  # noqa: E402
                                            hamming_weights, pose_dims, restore_spread)
from dancesynth.engines.neural.engine import motif_plan  # noqa: E402
from dancesynth.engines.neural.losses import Body, PoseLoss, fk as torch_fk, geodesic  # noqa: E402
from dancesynth.engines.neural.model import NeuralConfig, PoseGenerator, WindowedAdaIN  # noqa: E402
from dancesynth.engines.neural.train import make_batch, training_set  # noqa: E402
from dancesynth.kinematics import fk  # noqa: E402
from dancesynth.motion.database import open_database  # noqa: E402
from dancesynth.motion.resample import resample_clip_arrays  # noqa: E402


@pytest.fixture(scope="module")
def style():
    return open_database().styles["salsa-97-124bpm"]


@pytest.fixture(scope="module")
def clip30(style):
    c = style.clip(0)
    return resample_clip_arrays(c.local_rot, c.root_pos, c.contacts, style.fps, TRAIN_FPS)


def test_pose_vectors_round_trip_a_real_dance(style, clip30):
    local, root, contacts = clip30
    poses = encode_pose(local, root, contacts, TRAIN_FPS)
    assert poses.shape == (len(local), pose_dims(style.skeleton.n_joints))
    back_rot, back_root, back_contacts = decode_pose(poses, TRAIN_FPS, yaw0=rot.heading(local[0, 0]),
                                                     xz0=root[0, [0, 2]])
    assert np.degrees(rot.angle(back_rot, local)).max() < 0.01
    assert np.abs(back_root - root).max() < 1e-4        # the trajectory is integrated back to the millimetre
    assert (back_contacts == contacts).all()


def test_torch_fk_equals_numpy_fk(style, clip30):
    local, root, _ = clip30
    rng = np.random.default_rng(1)
    local = rot.mul(local[:40], rot.exp(rng.normal(0, 0.3, (40, local.shape[1], 3))))  # off the mocap manifold too
    from scipy.spatial.transform import Rotation

    mats = torch.as_tensor(Rotation.from_quat(local.reshape(-1, 4)).as_matrix().reshape(40, -1, 3, 3))
    sk = style.skeleton
    g_mats, g_pos = torch_fk(mats, torch.as_tensor(root[:40]), torch.as_tensor(sk.offsets), list(sk.parents))
    ref_rot, ref_pos = fk(local, root[:40], sk.offsets, sk.parents)
    assert np.abs(g_pos.numpy() - ref_pos).max() < 1e-9
    ref_mats = Rotation.from_quat(ref_rot.reshape(-1, 4)).as_matrix().reshape(g_mats.shape)
    assert np.abs(g_mats.numpy() - ref_mats).max() < 1e-9


def test_world_positions_integrate_the_trajectory_like_decode(style, clip30):
    local, root, contacts = clip30
    poses = encode_pose(local[:90], root[:90], contacts[:90], TRAIN_FPS).astype(np.float64)
    body = Body(style.skeleton, TRAIN_FPS)
    body.offsets = body.offsets.double()
    mats, r, _ = body.split(torch.as_tensor(poses))
    _, pos = body.world_positions(mats, r)
    q, rp, _ = decode_pose(poses, TRAIN_FPS)
    _, ref = fk(q, rp, style.skeleton.offsets, style.skeleton.parents)
    assert np.abs(pos.numpy() - ref).max() < 1e-6


def test_geodesic_loss_is_the_rotation_angle():
    from scipy.spatial.transform import Rotation

    a = Rotation.from_rotvec([[0, 0.3, 0], [0.2, 0, 0]])
    b = Rotation.from_rotvec([[0, 0.8, 0], [0.2, 0, 0]])
    ang = geodesic(torch.as_tensor(a.as_matrix()), torch.as_tensor(b.as_matrix())).numpy()
    assert ang == pytest.approx([0.5, 0.0], abs=2e-3)


def test_kinetic_term_wants_the_real_energy_where_frame_wise_losses_prefer_a_damped_copy(style, clip30):
    """Why the term exists: frame by frame, a blurred copy of a dance is nearer the real one
    than the same dance four frames late, so a generator unsure of the timing learns to blur.
    The kinetic term (each joint's kinetic energy and acceleration over the sequence)
    ranks them the other way round."""
    from dataclasses import replace

    local, root, contacts = clip30
    poses = encode_pose(local, root, contacts, TRAIN_FPS).astype(np.float32)
    a, n = 200, 60
    kernel = np.full(9, 1 / 9, dtype=np.float32)
    blurred = np.stack([np.convolve(poses[:, d], kernel, mode="same") for d in range(poses.shape[1])], axis=1)
    mean, std = poses.mean(0), (poses.std(0) + 1e-3).astype(np.float32)
    loss = PoseLoss(Body(style.skeleton, TRAIN_FPS), mean, std, replace(NeuralConfig.named("small"), w_kinetic=1.0))
    real = torch.as_tensor((poses[a:a + n] - mean) / std)[None]

    def terms(x):
        out = torch.as_tensor((x - mean) / std)[None]
        out[..., -2:] = 0.0   # contact logits: not what is compared here
        return {k: v.item() for k, v in loss(out, real)[1].items()}

    same, late, blur = terms(poses[a:a + n]), terms(poses[a - 4:a + n - 4]), terms(blurred[a:a + n])
    assert same["kinetic"] < 1e-9
    assert blur["pos"] < late["pos"] / 2                 # frame-wise: the blurred copy looks better ...
    assert blur["kinetic"] > 10 * late["kinetic"]        # ... the kinetic term sees it has lost the energy


def test_spread_filter_gives_a_damped_dance_its_amplitude_back_and_nothing_else(clip30):
    """What a network regressing to the mean makes: the real dance, damped about its own average pose.
    The post-filter widens it again, by at most its cap, keeping the posture and the timing."""
    poses = encode_pose(*clip30, TRAIN_FPS)
    std = poses.std(axis=0)
    z = (poses - poses.mean(axis=0)) / np.where(std < 1e-4, 1.0, std) + 0.3     # off-centre: a posture to keep
    spread = z.std(axis=0)
    damped = z.mean(axis=0) + 0.7 * (z - z.mean(axis=0))
    channels = z.shape[1] - 2                                                    # not the foot contacts
    live = spread[:channels] > 0.05
    capped = restore_spread(damped, spread, channels, cap=1.2)
    assert np.allclose(capped[:, :channels].std(axis=0)[live], 0.84 * spread[:channels][live], rtol=1e-3)
    assert np.allclose(capped.mean(axis=0), damped.mean(axis=0), atol=1e-5)      # the same average pose
    assert np.array_equal(capped[:, channels:], damped[:, channels:])
    assert np.allclose(restore_spread(damped, spread, channels, cap=2.0)[:, :channels], z[:, :channels], atol=1e-4)
    assert np.allclose(restore_spread(z * 1.5, spread, channels, cap=2.0), z * 1.5, atol=1e-5)   # never narrows


def test_adain_leaves_word_boundaries_unchanged():
    torch.manual_seed(0)
    layer = WindowedAdaIN(16, 8)
    torch.nn.init.normal_(layer.mlp[-1].weight)        # a trained-looking layer, not the identity start
    beats = np.array([0.0, 13.0, 27.0, 40.0])            # three words of uneven length
    _, phase, _ = beat_phase(41, beats, TRAIN_FPS)
    w = torch.as_tensor(hamming_weights(phase))
    h = torch.randn(41, 16)
    music = torch.randn(41, 3)
    out = layer(h, music, w)
    bounds = [0, 13, 27]
    assert torch.equal(out[bounds], h[bounds])
    middle = [6, 20, 33]
    assert (out[middle] - h[middle]).abs().mean() > 0.1   # the music does restyle the word's middle
    assert w.max() == pytest.approx(1.0, abs=0.01) and w.min() >= 0


def test_tiny_model_overfits_a_short_clip(style):
    """acLSTM with half its inputs self-fed learns one 1-second clip: the loss falls at least 10x."""
    ts = training_set(style.name, motifs=False)
    cfg = NeuralConfig.named("tiny")
    torch.manual_seed(0)
    gen = PoseGenerator(pose_dims(ts.skeleton.n_joints), 0, cfg)
    loss_fn = PoseLoss(Body(ts.skeleton, TRAIN_FPS), ts.mean, ts.std, cfg)
    batch = make_batch(ts, ts.train, [(0, ts.train[0].first + 5)], 30)
    opt = torch.optim.Adam(gen.parameters(), lr=1e-2)
    losses = []
    for _ in range(60):
        out = gen(batch["first"], batch["cond"], batch["music"], batch["window"], target=batch["target"])
        total, _ = loss_fn(out, batch["target"])
        opt.zero_grad()
        total.backward()
        opt.step()
        losses.append(total.item())
    assert losses[-1] < losses[0] / 10


def test_motif_plan_follows_the_genre_template():
    """Eq. (5): the signature of a long plan approaches the template even with a biased transition matrix."""
    template = np.array([0.5, 0.3, 0.2])
    trans = np.array([[0.9, 0.05, 0.05], [0.1, 0.8, 0.1], [0.1, 0.1, 0.8]])
    plan = motif_plan(400, template, trans, np.random.default_rng(3))
    sig = np.bincount(plan, minlength=3) / 400
    assert np.abs(sig - template).max() < 0.02
    assert (plan == motif_plan(400, template, trans, np.random.default_rng(3))).all()
    assert (motif_plan(5, None, None, np.random.default_rng(3)) == -1).all()   # a model without motifs


def test_torch_word_features_match_motion_words(style, clip30):
    """The perceptual loss sees the same word features as the motif model (motion/words.py)."""
    from dancesynth.engines.neural.losses import Perceptual
    from dancesynth.motion import words
    from dancesynth.types import MotionClip

    local, root, contacts = clip30
    clip = MotionClip(style.skeleton, TRAIN_FPS, root[:200], local[:200])
    beats = np.array([3, 17, 30, 46, 61, 75])
    ref = words.clip_words(clip, beats).features
    poses = encode_pose(local[:200], root[:200], contacts[:200], TRAIN_FPS).astype(np.float64)
    body = Body(style.skeleton, TRAIN_FPS)
    body.offsets = body.offsets.double()
    percept = Perceptual(body, words.landmark_indices(style.skeleton), torch.nn.Identity(), np.zeros((1, 1)))
    cut = torch.as_tensor([[0, a, b] for a, b in zip(beats[:-1], beats[1:])], dtype=torch.float64)
    ours = percept.features(torch.as_tensor(poses)[None], cut).numpy()
    assert ours.shape == ref.shape
    assert np.abs(ours - ref).max() < 1e-3        # float32 reference; velocities are in m/s


def test_beat_warp_moves_generated_beats_onto_music_beats():
    from dancesynth.engines.neural.engine import _warp_positions, beat_warp

    music = np.arange(0.0, 10.0, 0.5)
    rng = np.random.default_rng(0)
    motion = music + rng.uniform(-0.08, 0.08, len(music))
    motion = np.delete(motion, 7)                   # one beat the generator skipped
    motion = np.r_[motion, 6.27]                    # and an accent off the beat
    motion.sort()
    am, ag = beat_warp(motion, music)
    assert 7 * 0.5 not in am                        # the skipped beat has no partner ...
    assert len(am) >= len(music) - 3
    src = _warp_positions(am, (am, ag))
    assert np.allclose(src, ag)                     # ... the others are shown exactly at their music beat
    rates = np.diff(ag) / np.diff(am)
    assert rates.min() >= 0.67 and rates.max() <= 1.5
    t = np.linspace(-1, 12, 500)
    assert np.all(np.diff(_warp_positions(t, (am, ag))) > 0)   # time never runs backwards


def test_the_beat_warp_speeds_motion_up_only_within_the_styles_speed():
    """Issue 31 item 5: a generated beat that comes late is caught up by playing the stretch before it
    faster; where that stretch already moves near the style's fastest, the beat is let go instead (the
    next one takes the anchor), and slowing down is always allowed."""
    from dancesynth.engines.neural.engine import beat_warp

    music = np.arange(0.0, 4.01, 0.5)
    motion = music.copy()
    motion[4] += 0.1                                  # a beat generated 0.1 s late: 1.2x to catch up
    motion[6] -= 0.1                                  # one 0.1 s early: 0.8x
    t = np.linspace(0.0, 4.5, 451)
    calm = (t, np.full(t.size, 1.0))
    fast = (t, np.where((t > 1.5) & (t < 2.85), 2.6, 1.0))   # 2.6 m/s from 1.5 s to 2.85 s
    am, ag = beat_warp(motion, music, speed=calm, speed_limit=3.0)
    np.testing.assert_array_equal(am, music)          # every beat anchored
    am, ag = beat_warp(motion, music, speed=fast, speed_limit=3.0)
    assert 2.0 not in am                               # 2.6 m/s x 1.2 would pass 3 m/s: let go ...
    assert {1.5, 2.5, 3.0, 3.5} <= set(am)             # ... its neighbours kept, the early one slowed
    rates = np.diff(ag) / np.diff(am)
    assert rates[am[:-1] < 2.9].max() == pytest.approx(1.0)   # nothing sped up in the fast stretch
    assert beat_warp(motion, music)[0].tolist() == music.tolist()   # no speed given: as before


def test_each_frame_sees_its_motif_word_and_half_a_word_ahead_the_next_one():
    from dancesynth.engines.neural.data import LOOKAHEAD, exemplar_samples
    from dancesynth.motion.words import FEATURE_DIM, WORD_FRAMES

    words = np.random.default_rng(0).normal(size=(3, WORD_FRAMES, FEATURE_DIM)).astype(np.float32)
    k = np.array([0, 0, 0, 1, 2, 2])
    phase = np.array([0.0, 0.25, 0.75, 0.5, 0.0, 0.9])
    now, ahead = np.split(exemplar_samples(words, k, phase), 2, axis=1)
    assert np.allclose(now[0], words[0, 0]) and np.allclose(now[1], words[0, 3])     # 0.25 of 12 intervals
    assert np.allclose(now[3], words[1, 6])
    assert LOOKAHEAD == 0.5
    assert np.allclose(ahead[0], words[0, 6])                  # still in its own word
    assert np.allclose(ahead[2], words[1, 3])                  # 0.75 + 0.5: a quarter into the next motif word
    assert np.allclose(ahead[5], words[2, -1])                 # the last word looks at its own end


def test_training_is_reproducible_on_the_tiny_config(tmp_path):
    """Same data, config and seed -> the same weights; another seed -> other weights."""
    from dancesynth.engines.neural.train import train

    runs = [train("salsa", "tiny", steps=12, out=tmp_path / name, seed=seed)
            for name, seed in (("a", 0), ("b", 0), ("c", 1))]
    blobs = [torch.load(r["path"], weights_only=True)["state_dict"] for r in runs]
    assert all(torch.equal(blobs[0][k], blobs[1][k]) for k in blobs[0])
    assert not all(torch.equal(blobs[0][k], blobs[2][k]) for k in blobs[0])
    assert [p["loss"] for p in runs[0]["curve"]] == [p["loss"] for p in runs[1]["curve"]]
    assert Path(runs[0]["plot"]).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"     # the loss curve, as a picture


def test_stored_motif_words_are_the_least_ambiguous_of_their_motif():
    """The words shown at inference lie deep inside their motif, so what the network redraws
    from them is found again as that motif rather than its neighbour."""
    from dancesynth.engines.neural.train import motif_words_store

    ts = training_set("salsa")
    words, ids = motif_words_store(ts, per_motif=24, keep=6)
    drawn, drawn_ids = motif_words_store(ts, per_motif=24, keep=24)     # the same random draw, unfiltered
    assert np.bincount(ids).max() <= 6 and set(ids) == set(drawn_ids)   # every motif keeps words

    def margin(w):
        z = ts.embedder.embed(w.astype(np.float32))
        d = np.sort(((z[:, None, :] - ts.centroids[None]) ** 2).sum(-1), axis=1)
        return d[:, 1] - d[:, 0]

    assert (margin(words) > 0).all()                                    # each nearest its own motif's centroid
    for m in np.unique(ids):   # the kept are the deepest of the drawn
        # float32 embeddings of a batch of 6 and of 24 round differently on some CPUs: compare to 1e-5
        kept, best = margin(words[ids == m]).min(), np.sort(margin(drawn[drawn_ids == m]))[::-1][:6].min()
        assert kept >= best - 1e-5 * max(1.0, abs(best))

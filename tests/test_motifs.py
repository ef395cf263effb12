"""Motifs, signatures, templates, transitions, chi2 and the shipped embeddings."""

from __future__ import annotations


import numpy as np
import pytest

from dancesynth.errors import InputError, ModelError
from dancesynth.eval.beat_metrics import signature_chi2
from dancesynth.motion import embedding_train as T
from dancesynth.motion.database import MotionDatabase
from dancesynth.motion.embedding import FORMAT_VERSION, load_embedder, read_embedder, save_embedder
from dancesynth.motion.motifs import (DEFAULT_K, MotifModel, build_motif_model, chi2, load_motif_model,
                                      parse_motif_id, read_motif_model, save_motif_model)
from dancesynth.motion.words import style_words


def test_chi2_on_hand_made_histograms():
    assert chi2([1, 2, 3], [2, 4, 6]) == 0.0                     # proportional counts: the same signature
    assert chi2([1, 0], [0, 1]) == 1.0                            # nothing in common
    assert chi2([1, 1, 2, 0], [1, 3, 0, 0]) == pytest.approx(0.375)  # 1/2 (0 + .25/1 + .25/.5)
    assert chi2([0.2, 0.8], [0.5, 0.5]) == chi2([0.5, 0.5], [0.2, 0.8]) == pytest.approx(0.5 * (0.09 / 0.7 + 0.09 / 1.3))
    rng = np.random.default_rng(0)
    a, b = rng.random(10), rng.random(10)
    assert signature_chi2(a, b) == chi2(a, b)                     # the metric is this very function
    for bad, words in ((([1, 2], [1, 2, 3]), "same motifs"), (([1, -2], [1, 2]), "negative"),
                       (([0, 0], [1, 2]), "all zeros"), (([1, np.nan], [1, 2]), "non-finite")):
        with pytest.raises(InputError, match=words):
            chi2(*bad)


@pytest.fixture(scope="module")
def shipped():
    return load_motif_model()


def test_signature_is_the_normalised_motif_histogram(shipped):
    k = shipped.k
    sig = shipped.signature([0, 0, 1, 3])
    assert sig.shape == (k,) and sig[:4].tolist() == [0.5, 0.25, 0.0, 0.25] and sig.sum() == 1.0
    assert shipped.signature([]).sum() == 0.0
    with pytest.raises(InputError, match="motif ids"):
        shipped.signature([k])
    assert parse_motif_id("M17", k) == 17 and parse_motif_id("3", k) == 3
    for bad in ("M999", "X3", "", "M-1"):
        with pytest.raises(InputError, match="unknown motif"):
            parse_motif_id(bad, k)


def _never_built(*args, **kwargs):
    raise AssertionError("the motif model was rebuilt instead of read")


def test_shipped_model_is_read_not_rebuilt_and_matches_the_bundled_database(shipped, bundled_db, monkeypatch):
    monkeypatch.setattr("dancesynth.motion.motifs.build_motif_model", _never_built)
    load_motif_model(bundled_db)
    assert shipped.k == DEFAULT_K and shipped.embedder.kind == "learned"
    assert set(shipped.genres) == set(bundled_db.genres())
    # The template of a genre is the average signature of its dances, recomputed here from scratch.
    style = bundled_db.styles["mj"]
    words = style_words(style)
    ids = shipped.assign(words.features)
    sigs = [shipped.signature(ids[words.clip == c]) for c in range(style.n_clips)]
    np.testing.assert_allclose(shipped.templates["mj"], np.mean(sigs, axis=0), atol=1e-6)
    for g in shipped.genres:
        t = shipped.transitions[g]
        np.testing.assert_allclose(t.sum(axis=1), 1.0, atol=1e-9)
        assert np.all(t[:, shipped.templates[g] == 0] == 0)   # motifs foreign to a genre are never entered
    # each motif is a real word of the database, and that word belongs to its own motif
    all_feats = np.concatenate([style_words(s).features for s in bundled_db.styles.values()])
    for m in range(shipped.k):
        assert np.any(np.all(np.abs(all_feats - shipped.motif_features[m]) < 1e-6, axis=(1, 2)))
    assert np.mean(shipped.assign(shipped.motif_features) == np.arange(shipped.k)) > 0.95


def test_a_dance_is_closest_to_its_own_genre_template(shipped, bundled_db):
    for genre in ("salsa", "pop"):
        style = bundled_db.styles_of(genre)[0]
        words = style_words(style)
        sig = shipped.signature(shipped.assign(words.features[words.clip == 0]))
        assert shipped.nearest_genre(sig) == genre


def small_db(bundled_db, source="elsewhere"):
    return MotionDatabase({n: bundled_db.styles[n] for n in ("mj", "whirl", "indian")}, source=source)


def test_kmeans_is_reproducible_under_a_seed(bundled_db):
    db = small_db(bundled_db)
    a = build_motif_model(db, k=8, seed=3)
    b = build_motif_model(db, k=8, seed=3)
    c = build_motif_model(db, k=8, seed=4)
    np.testing.assert_array_equal(a.centroids, b.centroids)
    np.testing.assert_array_equal(a.transitions["mj"], b.transitions["mj"])
    assert not np.array_equal(a.centroids, c.centroids)
    assert a.genres == ("indian", "mj", "whirl")
    with pytest.raises(InputError, match="motifs from"):
        build_motif_model(db, k=10_000)


def test_another_database_gets_its_own_model_built_once_and_cached(bundled_db, tmp_path, monkeypatch):
    monkeypatch.setenv("DANCESYNTH_CACHE", str(tmp_path))
    db = small_db(bundled_db)
    first = load_motif_model(db, k=6)
    assert len(list((tmp_path / "motifs").glob("*.npz"))) == 1
    monkeypatch.setattr("dancesynth.motion.motifs.build_motif_model", _never_built)
    again = load_motif_model(db, k=6)
    np.testing.assert_array_equal(first.centroids, again.centroids)
    assert again.k == 6 and again.genres == first.genres


def test_saved_models_round_trip(bundled_db, tmp_path):
    model = build_motif_model(small_db(bundled_db), k=5, seed=0)
    save_motif_model(model, tmp_path / "m.npz")
    back = read_motif_model(tmp_path / "m.npz")
    assert isinstance(back, MotifModel) and back.k == 5 and back.genres == model.genres
    np.testing.assert_array_equal(back.templates["mj"], model.templates["mj"])


@pytest.mark.parametrize("damage", ["missing", "garbage", "truncated", "wrong shape"])
def test_missing_or_corrupt_weights_are_a_model_error(tmp_path, damage):
    good = tmp_path / "good.npz"
    save_embedder(load_embedder("learned"), good)
    path = tmp_path / "bad.npz"
    if damage == "garbage":
        path.write_bytes(b"these are not weights")
    elif damage == "truncated":
        path.write_bytes(good.read_bytes()[:2000])
    elif damage == "wrong shape":
        with np.load(good) as z:
            arrays = {k: z[k] for k in z.files}
        arrays["w3"] = arrays["w3"][:, :10]
        np.savez(path, **arrays)
    with pytest.raises(ModelError, match="embedding weights"):
        read_embedder(path)
    if damage != "missing":
        with pytest.raises(ModelError, match="motif model"):
            read_motif_model(path)
    with pytest.raises(ModelError, match="unknown embedding"):
        load_embedder("bert")
    assert FORMAT_VERSION == 1


def test_torch_module_computes_the_same_embedding():
    torch = pytest.importorskip("torch")
    x = load_motif_model().motif_features
    for kind in ("learned", "pca"):
        emb = load_embedder(kind)
        module = emb.torch_module()
        inp = torch.as_tensor(x, dtype=torch.float32).requires_grad_(True)
        out = module(inp)
        np.testing.assert_allclose(out.detach().numpy(), emb.embed(x), atol=1e-4)
        out.sum().backward()                                  # differentiable with respect to the words
        assert inp.grad is not None and not any(p.requires_grad for p in module.parameters())


def test_learned_embedding_finds_retimed_words_better_than_pca(bundled_db):
    """Held-out clips: a word re-cut with its beats moved and its timing warped must find itself."""
    train, held_out = T.split_sources(T.database_sources(bundled_db), T.TrainConfig.holdout)
    acc = T.evaluate_retrieval({"pca": load_embedder("pca"), "learned": load_embedder("learned")},
                               held_out, others=train, jitter=6, warp=0.8, repeats=2)
    assert acc["learned"] > acc["pca"]
    assert acc["learned"] > 0.9

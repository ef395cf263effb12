"""Training and evaluating the word embedding (torch is imported lazily, only here).

Objective: NT-Xent (SimCLR's normalised-temperature cross entropy). A batch holds B
words of the database, each seen twice through a random *view*; each view must pick
out the other view of its own word among the 2B - 1 others. A view re-cuts the word
from the raw clip with

- each of its two beats moved by up to +-``jitter`` frames (beat detection is never
  exact to the frame),
- a smooth monotone time warp ``u + a sin(pi u) / pi`` of the 13 sample times,
  ``|a| <= warp`` (the dancer hurries then lingers inside one beat),
- Gaussian noise of ``noise`` standard deviations on the standardised features.

No mirroring: a left-hand step and a right-hand step are different words.
NT-Xent alone (at a low temperature) spreads all words evenly over the sphere, and
K-means then finds no stable motifs; so we train at temperature 0.5 and add a
*structure* term (``_stress``) that keeps the relative pairwise distances of the PCA
space: the embedding is PCA's geometry with the timing differences taken out.
Clips are split for evaluation: every ``holdout``-th clip (in database order) is
left out of training and the retrieval number in docs/motifs.md is measured on them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .embedding import Embedder, channel_stats, fit_pca
from .words import WORD_FRAMES, clip_landmarks, features_at


@dataclass(frozen=True)
class TrainConfig:
    dim: int = 32
    hidden: int = 64
    epochs: int = 100
    batch: int = 256
    lr: float = 2e-3
    temperature: float = 0.5   # a low temperature (0.1) spreads words evenly and K-means finds no stable motifs
    structure: float = 3.0     # weight of the distance-preservation term (see _stress)
    jitter: int = 5
    warp: float = 0.8
    noise: float = 0.05
    views: int = 24        # pre-computed views per word (the epochs draw pairs among them)
    holdout: int = 5       # every 5th clip is held out (0: train on everything)
    seed: int = 0


@dataclass
class WordSource:
    """The words of one clip with the raw landmarks they are cut from."""

    pos: np.ndarray        # (F, 14, 3)
    root_rot: np.ndarray   # (F, 4)
    fps: float
    starts: np.ndarray     # (W,) clip frames
    ends: np.ndarray       # (W,)
    genre: str


def database_sources(database) -> list[WordSource]:
    """One ``WordSource`` per clip of every style (clips with fewer than two beats are skipped)."""
    out = []
    for st in database.styles.values():
        for c in range(st.n_clips):
            clip = st.clip(c)
            beats = np.unique(clip.meta["beat_frames"])
            if len(beats) < 2:
                continue
            pos, root_rot = clip_landmarks(clip)
            out.append(WordSource(pos, root_rot, st.fps, beats[:-1], beats[1:], st.genre))
    return out


def split_sources(sources: list[WordSource], holdout: int) -> tuple[list[WordSource], list[WordSource]]:
    if holdout <= 0:
        return sources, []
    return ([s for i, s in enumerate(sources) if i % holdout != holdout - 1],
            [s for i, s in enumerate(sources) if i % holdout == holdout - 1])


def warped_times(starts, ends, n_frames: int, rng: np.random.Generator, *, jitter: int = 2,
                 warp: float = 0.3) -> np.ndarray:
    """Sample times (W, 13) of re-cut words: beats jittered by +-``jitter`` frames, time warped."""
    s = np.asarray(starts) + rng.integers(-jitter, jitter + 1, len(starts))
    e = np.asarray(ends) + rng.integers(-jitter, jitter + 1, len(ends))
    s = np.clip(s, 0, n_frames - 2)
    e = np.clip(np.maximum(e, s + 2), 0, n_frames - 1)
    u = np.linspace(0.0, 1.0, WORD_FRAMES)
    a = rng.uniform(-warp, warp, (len(s), 1))
    u = u + a * np.sin(np.pi * u) / np.pi   # monotone for |a| < 1, ends fixed
    return s[:, None] + (e - s)[:, None] * u


def source_features(sources: list[WordSource], rng: np.random.Generator | None = None, **warp) -> np.ndarray:
    """Features of every word of ``sources``: exact cuts (``rng=None``) or one random view each."""
    out = []
    for src in sources:
        if rng is None:
            times = src.starts[:, None] + (src.ends - src.starts)[:, None] * np.linspace(0, 1, WORD_FRAMES)
        else:
            times = warped_times(src.starts, src.ends, len(src.pos), rng, **warp)
        out.append(features_at(src.pos, src.root_rot, src.fps, times))
    return np.concatenate(out).astype(np.float32)


def retrieval_accuracy(embedder: Embedder, exact: np.ndarray, views: np.ndarray) -> float:
    """Share of re-cut views whose nearest exact word (Euclidean, in the embedding) is their own word."""
    g = embedder.embed(exact)
    q = embedder.embed(views)
    d = (q ** 2).sum(1)[:, None] - 2 * q @ g.T + (g ** 2).sum(1)[None]
    return float(np.mean(np.argmin(d, axis=1) == np.arange(len(q))))


def evaluate_retrieval(embedders: dict, sources: list[WordSource], *, others: list[WordSource] = (),
                       seed: int = 1, repeats: int = 3, jitter: int = 2, warp: float = 0.3) -> dict:
    """Mean retrieval accuracy of each embedder over ``repeats`` seeded sets of re-cut views.

    Queries are views of the words of ``sources``; the gallery is their exact cuts plus
    the exact words of ``others`` (distractors, e.g. the training words).
    """
    exact = source_features(sources)
    gallery = np.concatenate([exact, source_features(list(others))]) if others else exact
    rng = np.random.default_rng(seed)
    sets = [source_features(sources, rng, jitter=jitter, warp=warp) for _ in range(repeats)]
    return {name: float(np.mean([retrieval_accuracy(e, gallery, v) for v in sets])) for name, e in embedders.items()}


def train_learned(sources: list[WordSource], config: TrainConfig = TrainConfig(), *,
                  progress=None) -> Embedder:
    """Train the convolutional word encoder on ``sources`` (seeded, CPU, under a minute).

    One thread: multi-threaded reductions add in a different order run to run, and
    600 Adam steps grow those last bits into different weights, hence different motifs.
    """
    import torch

    from .embedding import _torch_module

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return _train(sources, config, progress, torch, _torch_module)
    finally:
        torch.set_num_threads(threads)


def _train(sources, config: TrainConfig, progress, torch, _torch_module) -> Embedder:
    torch.manual_seed(config.seed)
    rng = np.random.default_rng(config.seed)
    exact = source_features(sources)
    mean, std = channel_stats(exact)
    views = np.stack([source_features(sources, rng, jitter=config.jitter, warp=config.warp)
                      for _ in range(config.views)])                      # (V, W, 13, D)
    views = torch.as_tensor((views - mean) / std)
    n_words = views.shape[1]
    reference = torch.as_tensor(fit_pca(exact).embed(exact))   # what "similar movement" means before training

    params = {"mean": mean, "std": std, "w1": np.zeros((config.hidden, exact.shape[2], 3)),
              "b1": np.zeros(config.hidden), "w2": np.zeros((config.hidden, config.hidden, 3)),
              "b2": np.zeros(config.hidden), "w3": np.zeros((config.dim, config.hidden * WORD_FRAMES)),
              "b3": np.zeros(config.dim)}
    model = _torch_module(Embedder("learned", params), torch)
    net = torch.nn.ModuleList([model.conv1, model.conv2, model.out])
    for layer in net:  # fresh, seeded initialisation
        layer.reset_parameters()
        for p in layer.parameters():
            p.requires_grad_(True)
    model.mean.zero_()
    model.std.fill_(1.0)   # the views are standardised already
    model.train()
    opt = torch.optim.Adam(net.parameters(), lr=config.lr)
    steps = config.epochs * max(1, n_words // config.batch)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, steps)
    gen = torch.Generator().manual_seed(config.seed)
    step = 0
    for epoch in range(config.epochs):
        order = torch.randperm(n_words, generator=gen)
        for b in range(max(1, n_words // config.batch)):
            idx = order[b * config.batch:(b + 1) * config.batch]
            pick = torch.randint(0, config.views, (2, len(idx)), generator=gen)
            x = torch.cat([views[pick[0], idx], views[pick[1], idx]])
            x = x + config.noise * torch.randn(x.shape, generator=gen)
            z = model(x)
            loss = _nt_xent(z, config.temperature, torch)
            if config.structure > 0:
                loss = loss + config.structure * _stress(z[:len(idx)], reference[idx], torch)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            step += 1
        if progress and (epoch % 50 == 0 or epoch == config.epochs - 1):
            progress(f"epoch {epoch + 1}/{config.epochs} loss {loss.item():.4f}")
    state = {k: v.detach().numpy().astype(np.float32) for k, v in net.state_dict().items()}
    names = {"0.weight": "w1", "0.bias": "b1", "1.weight": "w2", "1.bias": "b2", "2.weight": "w3", "2.bias": "b3"}
    learned = {names[k]: v for k, v in state.items()}
    info = {"objective": "NT-Xent", "words": int(n_words), "steps": step, "final_loss": round(float(loss.detach()), 4),
            **{k: v for k, v in vars(config).items()}}
    return Embedder("learned", {"mean": mean, "std": std, **learned}, info)


def _nt_xent(z, temperature: float, torch):
    """NT-Xent loss of 2B unit vectors where row i and row i + B are the two views of one word."""
    n = z.shape[0] // 2
    sim = z @ z.T / temperature
    sim = sim - 1e9 * torch.eye(2 * n)
    target = torch.cat([torch.arange(n, 2 * n), torch.arange(0, n)])
    return torch.nn.functional.cross_entropy(sim, target)


def _stress(z, ref, torch):
    """Scale-free mismatch between the batch's pairwise distances in the embedding and in ``ref``.

    Contrastive learning alone spreads all words evenly over the sphere and forgets
    which movements resemble each other, so K-means finds no stable clusters; this term
    keeps the PCA space's geometry (relative distances) while NT-Xent removes timing.
    """
    d_z = torch.cdist(z, z)
    d_r = torch.cdist(ref, ref)
    return torch.mean((d_z / d_z.mean() - d_r / d_r.mean()) ** 2)


def fit_baseline(sources: list[WordSource], dim: int = 32) -> Embedder:
    """The PCA baseline on the exact words of ``sources``."""
    return fit_pca(source_features(sources), dim)

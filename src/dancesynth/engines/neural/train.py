"""Training the pose generator on one genre of the database (``dancesynth train``).

Sequences of ``seq_frames`` frames are cut at random from the genre's clips, each
also played faster and slower and mirrored (one take -- both dancers of it -- is
held out to measure generalisation); every word is given a motif word, its own or
another real word of its motif; the generator runs the acLSTM schedule over them
and the §4.4 losses are minimised with Adam for a fixed number of steps at a fixed
thread count, so the same data and seed give the same weights. The result is
written atomically with its config, loss curve and a plot of it
(``store.save_model``).
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from ...errors import InputError
from ...motion.database import MotionDatabase, open_database
from .data import TRAIN_FPS, Sequence, conditioning, normaliser, pose_dims, pose_spread, style_sequences
from .losses import Body, Perceptual, PoseLoss
from .model import NeuralConfig, PoseGenerator
from .store import save_model, user_dir


@dataclass
class TrainingSet:
    genre: str
    skeleton: object
    train: list[Sequence]
    held_out: list[Sequence]
    mean: np.ndarray
    std: np.ndarray
    n_motifs: int
    motif_source: str
    template: np.ndarray | None = None     # the genre's motif signature (K,) ...
    transitions: np.ndarray | None = None  # ... and motif transitions (K, K), kept with the weights
    centroids: np.ndarray | None = None    # (K, dim) the motifs in the embedding (perceptual loss)
    medoids: np.ndarray | None = None      # (K, 13, D) the real word nearest each motif
    embedder: object = None

    def pool(self) -> tuple[np.ndarray, np.ndarray]:
        """Every training word (N, 13, D) and its motif (N,): where other words of a motif come from."""
        return (np.concatenate([s.words for s in self.train]), np.concatenate([s.motifs for s in self.train]))


def _take(name: str) -> str:
    """The take of a CMU clip name ('60_09_scaled' -> '09_scaled': subjects 60 and 61 danced it together)."""
    m = re.match(r"^\d+_(.+)$", name)
    return m.group(1) if m else name


def training_set(genre: str = "salsa", database: MotionDatabase | str | Path | None = None,
                 *, motifs: bool = True, rates=(1.0,), mirror: bool = False) -> TrainingSet:
    """The sequences of a style or genre (all its styles on the first one's skeleton), augmented."""
    db = database if isinstance(database, MotionDatabase) else open_database(database)
    styles = db.styles_of(genre)
    skeleton = styles[0].skeleton
    styles = [s for s in styles if s.skeleton.names == skeleton.names]
    model = None
    if motifs:
        from ...motion.motifs import load_motif_model

        model = load_motif_model(db)
        model = model if styles[0].genre in model.templates else None
    names = [n for s in styles for n in s.clip_names]
    held_take = _take(names[len(names) // 2]) if len(names) > 2 else None
    train_, held = [], []
    for st in styles:
        out = [c for c in range(st.n_clips) if _take(st.clip_names[c]) == held_take]
        held += style_sequences(st, model, clips=out)   # the held-out take only as it was danced
        train_ += style_sequences(st, model, clips=[c for c in range(st.n_clips) if c not in out], rates=rates,
                                  mirror=mirror)
    if not train_:
        raise InputError(f"style '{genre}' has no clip with enough motion beats to train on")
    mean, std = normaliser(train_)
    name = styles[0].genre if len(styles) > 1 else genre
    if model is None:
        return TrainingSet(name, skeleton, train_, held, mean, std, 0, "none")
    g = styles[0].genre
    f32 = [np.asarray(a, dtype=np.float32) for a in (model.templates[g], model.transitions[g], model.centroids,
                                                     model.motif_features)]
    return TrainingSet(name, skeleton, train_, held, mean, std, int(model.k),
                       f"k-means K={model.k} ({model.embedder.kind} embedding)", *f32, model.embedder)


def _windows(seqs: list[Sequence], length: int) -> list[tuple[int, int, int]]:
    """(sequence, first start, last start) of each sequence long enough for a window."""
    out = []
    for i, s in enumerate(seqs):
        lo, hi = max(s.first, 1), s.last - length
        if hi > lo:
            out.append((i, lo, hi))
    return out


class MotifWords:
    """Draws, for a word of motif m, another real word of m (its own when m has no other)."""

    def __init__(self, features: np.ndarray, motifs: np.ndarray):
        self.features = features
        order = np.argsort(motifs, kind="stable")
        bounds = np.searchsorted(motifs[order], np.arange(int(motifs.max(initial=-1)) + 2))
        self.members = {m: order[bounds[m]:bounds[m + 1]] for m in range(len(bounds) - 1)
                        if bounds[m + 1] > bounds[m]}

    def choose(self, own: np.ndarray, motifs: np.ndarray, keep_own: np.ndarray, rng) -> np.ndarray:
        out = own.copy()
        for i, m in enumerate(motifs):
            if not keep_own[i] and m in self.members:
                out[i] = self.features[self.members[m][rng.integers(len(self.members[m]))]]
        return out


def make_batch(ts: TrainingSet, seqs: list[Sequence], starts: list[tuple[int, int]], length: int, *,
               words: MotifWords | None = None, own_word: float = 1.0, rng=None) -> dict:
    """Tensors for windows ``(sequence, start)``: first pose, targets, conditioning, music, window, words.

    Each word of a window is conditioned on its own features with probability
    ``own_word``, else on another word of its motif drawn from ``words``.
    """
    rng = rng if rng is not None else np.random.default_rng(0)
    first, target, cond, music, window, cut = [], [], [], [], [], []
    for i, a in starts:
        s, sl = seqs[i], slice(a, a + length)
        norm = (s.poses[a - 1:a + length] - ts.mean) / ts.std
        first.append(norm[0])
        target.append(norm[1:])
        k0, k1 = int(s.word[a]), min(int(s.word[a + length - 1]) + 2, len(s.words))
        own = s.words[k0:k1]
        ex = own if words is None else words.choose(own, s.motifs[k0:k1], rng.random(k1 - k0) < own_word, rng)
        cond.append(conditioning(s.phase[sl], s.length_s[sl], ex, s.word[sl] - k0))
        music.append(s.music[s.word[sl]])
        window.append(s.window[sl])
        inside = np.nonzero((s.beat_frames >= a) & (s.beat_frames <= a + length - 1))[0]
        cut += [(len(first) - 1, s.beat_frames[j] - a, s.beat_frames[j + 1] - a, s.motifs[j])
                for j in inside[:-1] if j + 1 in inside]   # words inside the window, with their motif
    batch = {k: torch.as_tensor(np.stack(v).astype(np.float32)) for k, v in
             (("first", first), ("target", target), ("cond", cond), ("music", music), ("window", window))}
    batch["words"] = torch.as_tensor(np.array(cut, dtype=np.float32).reshape(-1, 4))
    return batch


def _perceptual(body: Body, skeleton, ts: TrainingSet):
    """The motion perceptual loss through the motif model's frozen embedding (None without motifs)."""
    if ts.centroids is None:
        return None, "none"
    from ...motion.words import landmark_indices

    return Perceptual(body, landmark_indices(skeleton), ts.embedder.torch_module(), ts.centroids), ts.embedder.kind


def motif_words_store(ts: TrainingSet, per_motif: int = 24, keep: int = 12,
                      seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Up to ``keep`` training words of each motif, as danced (no tempo change), for inference.

    ``per_motif`` words of a motif are drawn at random; of those, the ``keep`` deepest inside
    the motif are stored: the largest margin, in the motif model's embedding, between the
    nearest other centroid and their own. The network redraws a word a little differently, and
    a word near a border comes out as the neighbouring motif: with these, the planned motif was
    found again on 60 % of beats instead of 48 %, at the same realism (docs/neural.md).
    """
    rng = np.random.default_rng(seed)
    plain = [s for s in ts.train if s.rate == 1.0]
    feats = np.concatenate([s.words for s in plain])
    ids = np.concatenate([s.motifs for s in plain])
    drawn = [rng.permutation(np.nonzero(ids == m)[0])[:per_motif] for m in np.unique(ids)]
    if ts.embedder is not None and ts.centroids is not None:
        z = ts.embedder.embed(feats.astype(np.float32))
        d = np.sort(((z[:, None, :] - ts.centroids[None]) ** 2).sum(-1), axis=1)
        margin = d[:, 1] - d[:, 0]
        drawn = [w[np.argsort(-margin[w], kind="stable")[:keep]] for w in drawn]
    chosen = np.sort(np.concatenate(drawn))
    return feats[chosen], ids[chosen]


def start_poses(seqs: list[Sequence], per_sequence: int = 8) -> np.ndarray:
    """Real poses at motion beats (normalised later), where generated dances begin."""
    out = []
    for s in seqs:
        beats = np.round(s.beat_frames[1:-1]).astype(int)
        out += [s.poses[b] for b in beats[:: max(1, len(beats) // per_sequence)]]
    return np.stack(out)


def train(genre: str = "salsa", config: str | NeuralConfig = "small", *, device: str = "cpu",
          minutes: float | None = None, steps: int | None = None, out: str | Path | None = None,
          seed: int = 0, database=None, progress: Callable[[int, int, float], None] | None = None) -> dict:
    """Train a generator for ``genre``; returns the JSON summary that is written beside the weights.

    Training runs ``steps`` (default: the config's) Adam steps at the config's thread
    count: the same data, config and seed give the same weights on the same machine.
    ``minutes`` caps the time (then how far it gets depends on the machine).
    ``progress(step, steps, loss)`` is called after every step.
    """
    cfg = config if isinstance(config, NeuralConfig) else NeuralConfig.named(config)
    if steps is not None:
        cfg = replace(cfg, steps=int(steps))
    cap_s = 60.0 * (cfg.minutes if minutes is None else float(minutes))
    if cap_s < 0 or cfg.steps <= 0 or (minutes is not None and cap_s <= 0):
        raise InputError("the training budget must be positive: give --steps > 0 and --minutes > 0")
    if device not in ("cpu", "cuda"):
        raise InputError(f"unknown device '{device}': use cpu or cuda")
    if device == "cuda" and not torch.cuda.is_available():
        raise InputError("--device cuda asked for, but torch sees no CUDA GPU here; use --device cpu")
    t_start = time.perf_counter()
    ts = training_set(genre, database, rates=cfg.rates, mirror=cfg.mirror)
    path = Path(out) if out is not None else user_dir()
    path = path / f"{ts.genre}.pt" if path.suffix != ".pt" else path
    try:  # before training, not after: a bad --out must not cost the training time
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot write the model to {path}: {exc.strerror}; give --out a folder you can write to") \
            from None
    torch.set_num_threads(cfg.threads)   # reductions, so results, depend on the thread count
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    windows = _windows(ts.train, cfg.seq_frames)
    if not windows:
        raise InputError(f"the clips of '{genre}' are shorter than a {cfg.seq_frames}-frame training sequence")
    weights = np.array([hi - lo for _, lo, hi in windows], dtype=float)
    gen = PoseGenerator(pose_dims(ts.skeleton.n_joints), ts.n_motifs, cfg).to(device)
    body = Body(ts.skeleton, TRAIN_FPS)
    perceptual, embedding = _perceptual(body, ts.skeleton, ts)
    loss_fn = PoseLoss(body, ts.mean, ts.std, cfg, perceptual).to(device)
    opt = torch.optim.Adam(gen.parameters(), lr=cfg.lr)
    pool = MotifWords(*ts.pool())
    held = _windows(ts.held_out, cfg.seq_frames)
    # Held out as at inference: every word conditioned on another word of its motif, from the training set.
    held_batch = (make_batch(ts, ts.held_out, [(i, lo + (hi - lo) * k // 16) for i, lo, hi in held for k in range(16)],
                             cfg.seq_frames, words=pool, own_word=0.0, rng=np.random.default_rng(1))
                  if held else None)

    def run(batch):
        b = {k: v.to(device) for k, v in batch.items()}
        out_ = gen(b["first"], b["cond"], b["music"], b["window"], target=b["target"])
        return loss_fn(out_, b["target"], b["words"] if len(b["words"]) else None)

    curve, recent, first_loss = [], [], None
    log_every = max(cfg.steps // 24, 1)
    t0 = time.perf_counter()
    step = 0
    while step < cfg.steps and not (cap_s > 0 and time.perf_counter() - t0 >= cap_s):
        pick = rng.choice(len(windows), size=cfg.batch, p=weights / weights.sum())
        starts = [(windows[q][0], int(rng.integers(windows[q][1], windows[q][2]))) for q in pick]
        gen.train()
        total, terms = run(make_batch(ts, ts.train, starts, cfg.seq_frames, words=pool, own_word=cfg.own_word,
                                      rng=rng))
        opt.zero_grad()
        total.backward()
        torch.nn.utils.clip_grad_norm_(gen.parameters(), 1.0)
        for group in opt.param_groups:  # linear decay to 10 % over the steps
            group["lr"] = cfg.lr * (1.0 - 0.9 * step / cfg.steps)
        opt.step()
        step += 1
        recent.append({"loss": total.item(), **{k: v.item() for k, v in terms.items()}})
        first_loss = first_loss if first_loss is not None else recent[-1]["loss"]
        if progress:
            progress(step, cfg.steps, recent[-1]["loss"])
        if step % log_every == 0 or step == 1:
            curve.append(_log_point(step, time.perf_counter() - t0, recent, gen, run, held_batch))
            recent = []
    if recent:
        curve.append(_log_point(step, time.perf_counter() - t0, recent, gen, run, held_batch))
    info = {"config": cfg.to_dict(), "steps": step, "train_s": round(time.perf_counter() - t0, 1),
            "total_s": round(time.perf_counter() - t_start, 1), "device": device, "seed": seed,
            "threads": cfg.threads, "clips": len({s.name for s in ts.train}),
            "sequences": len(ts.train), "held_out_clips": [s.name for s in ts.held_out],
            "frames": int(sum(len(s.poses) for s in ts.train)), "fps": TRAIN_FPS,
            "motifs": ts.n_motifs, "motif_source": ts.motif_source, "perceptual_embedding": embedding,
            "first_loss": first_loss, "final_loss": curve[-1]["loss"] if curve else None, "curve": curve}
    gen.cpu().eval()
    words, word_motifs = motif_words_store(ts, seed=seed)
    save_model(path, gen, ts.skeleton, ts.mean, ts.std, ts.genre, info,
               start_poses([s for s in ts.train if s.rate == 1.0]), ts.template, ts.transitions,
               motif_words=words, word_motifs=word_motifs, medoids=ts.medoids,
               spread=pose_spread(ts.train, ts.mean, ts.std))
    info["path"] = str(path)
    info["plot"] = str(plot_curve(info, path.with_suffix(".png")))
    return info


def plot_curve(info: dict, path: Path) -> Path:
    """The training and held-out loss against steps, as a PNG beside the weights."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curve = info["curve"]
    steps = [p["step"] for p in curve]
    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.plot(steps, [p["loss"] for p in curve], label="training loss (mean since the last point)")
    if curve and "held_out_loss" in curve[0]:
        ax.plot(steps, [p["held_out_loss"] for p in curve], label=f"held out: {', '.join(info['held_out_clips'])}")
    ax.set_xlabel("step")
    ax.set_ylabel("loss (§4.4, weighted sum)")
    ax.set_yscale("log")
    ax.set_title(f"{info['config']['name']} model, {info['steps']} steps in {info['train_s'] / 60:.1f} min "
                 f"on {info['device']}")
    ax.legend(fontsize=8)
    fig.tight_layout()
    from ...io.files import atomic_output

    with atomic_output(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=100)
    plt.close(fig)
    return path


def _log_point(step, elapsed, recent, gen, run, held_batch) -> dict:
    point = {"step": step, "elapsed_s": round(elapsed, 1)}
    for name in recent[-1]:
        point[name] = round(float(np.mean([r[name] for r in recent if name in r])), 4)
    if held_batch is not None:
        gen.eval()
        with torch.no_grad():
            total, terms = run(held_batch)
        point["held_out_loss"] = round(float(total), 4)
        point["held_out_rot_deg"] = round(float(np.degrees(float(terms["rot"]))), 2)
        point["held_out_pos_cm"] = round(100 * float(terms["pos"]), 2)
    return point

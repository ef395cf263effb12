"""Training the pose generator on one genre of the database (``dancesynth train``).

Sequences of ``seq_frames`` frames are cut at random from the genre's clips (one
clip is held out to measure generalisation); the generator runs the acLSTM
schedule over them and the §4.4 losses are minimised with Adam until the step or
time budget is spent. The result is written atomically with its config and loss
curve (``store.save_model``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from ...errors import InputError
from ...motion.database import MotionDatabase, Style, open_database
from .data import TRAIN_FPS, Sequence, normaliser, pose_dims, style_sequences
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


def _motif_ids(db: MotionDatabase, styles: list[Style]):
    """Motif ids of every word of each style, and the motif model (None when there is none)."""
    try:
        from ...motion.motifs import load_motif_model, style_motifs
    except ImportError:
        return [None] * len(styles), None
    model = load_motif_model(db)
    return [style_motifs(s, model)[1] for s in styles], model


def training_set(genre: str = "salsa", database: MotionDatabase | str | Path | None = None,
                 *, motifs: bool = True) -> TrainingSet:
    """The sequences of a style or genre (all its styles on the first one's skeleton)."""
    db = database if isinstance(database, MotionDatabase) else open_database(database)
    styles = db.styles_of(genre)
    skeleton = styles[0].skeleton
    styles = [s for s in styles if s.skeleton.names == skeleton.names]
    ids, model = _motif_ids(db, styles) if motifs else ([None] * len(styles), None)
    seqs = [q for s, i in zip(styles, ids) for q in style_sequences(s, i)]
    if not seqs:
        raise InputError(f"style '{genre}' has no clip with enough motion beats to train on")
    held = [seqs.pop(len(seqs) // 2)] if len(seqs) > 2 else []
    mean, std = normaliser(seqs)
    name = styles[0].genre if len(styles) > 1 else genre
    if model is None or styles[0].genre not in model.templates:
        return TrainingSet(name, skeleton, seqs, held, mean, std, 0, "none")
    return TrainingSet(name, skeleton, seqs, held, mean, std, int(model.k),
                       f"k-means K={model.k} ({model.embedder.kind} embedding)",
                       np.asarray(model.templates[styles[0].genre], dtype=np.float32),
                       np.asarray(model.transitions[styles[0].genre], dtype=np.float32))


def _windows(seqs: list[Sequence], length: int) -> list[tuple[int, int, int]]:
    """(sequence, first start, last start) of each sequence long enough for a window."""
    out = []
    for i, s in enumerate(seqs):
        lo, hi = max(s.first, 1), s.last - length
        if hi > lo:
            out.append((i, lo, hi))
    return out


def make_batch(ts: TrainingSet, seqs: list[Sequence], starts: list[tuple[int, int]], length: int) -> dict:
    """Tensors for windows ``(sequence, start)``: first pose, targets, conditioning, music, window."""
    first, target, cond, music, window, words = [], [], [], [], [], []
    eye = np.eye(max(ts.n_motifs, 1), dtype=np.float32)[:, :ts.n_motifs]
    for i, a in starts:
        s, sl = seqs[i], slice(a, a + length)
        norm = (s.poses[a - 1:a + length] - ts.mean) / ts.std
        first.append(norm[0])
        target.append(norm[1:])
        motif = eye[np.maximum(s.motif[sl], 0)] * (s.motif[sl] >= 0)[:, None]
        cond.append(np.concatenate([s.beat[sl], motif], axis=1))
        music.append(s.music[s.word[sl]])
        window.append(s.window[sl])
        b = s.beat_frames[(s.beat_frames >= a) & (s.beat_frames <= a + length - 1)] - a
        words += [(len(first) - 1, b0, b1) for b0, b1 in zip(b[:-1], b[1:])]   # words inside the window
    batch = {k: torch.as_tensor(np.stack(v)) for k, v in
             (("first", first), ("target", target), ("cond", cond), ("music", music), ("window", window))}
    batch["words"] = torch.as_tensor(np.array(words, dtype=np.float32).reshape(-1, 3))
    return batch


def _perceptual(body: Body, skeleton):
    """The motion perceptual loss through the frozen word embedding, if the embedding is available."""
    try:
        from ...motion.embedding import load_embedder
        from ...motion.words import landmark_indices
    except ImportError:
        return None, "none"
    embedder = load_embedder()
    return Perceptual(body, landmark_indices(skeleton), embedder.torch_module()), embedder.kind


def start_poses(seqs: list[Sequence], per_sequence: int = 8) -> np.ndarray:
    """Real poses at motion beats (normalised later), where generated dances begin."""
    out = []
    for s in seqs:
        beats = np.round(s.beat_frames[1:-1]).astype(int)
        out += [s.poses[b] for b in beats[:: max(1, len(beats) // per_sequence)]]
    return np.stack(out)


def train(genre: str = "salsa", config: str | NeuralConfig = "small", *, device: str = "cpu",
          minutes: float | None = None, steps: int | None = None, out: str | Path | None = None,
          seed: int = 0, database=None, progress: Callable[[float, float, float], None] | None = None) -> dict:
    """Train a generator for ``genre``; returns the JSON summary that is written beside the weights.

    ``progress(elapsed_s, budget_s, loss)`` is called after every step.
    """
    cfg = config if isinstance(config, NeuralConfig) else NeuralConfig.named(config)
    if steps is not None:
        cfg = replace(cfg, steps=int(steps))
    budget_s = 60.0 * (cfg.minutes if minutes is None else float(minutes))
    if budget_s <= 0 or cfg.steps <= 0:
        raise InputError("the training budget must be positive: give --minutes > 0")
    if device not in ("cpu", "cuda"):
        raise InputError(f"unknown device '{device}': use cpu or cuda")
    if device == "cuda" and not torch.cuda.is_available():
        raise InputError("--device cuda asked for, but torch sees no CUDA GPU here; use --device cpu")
    t_start = time.perf_counter()
    ts = training_set(genre, database)
    path = Path(out) if out is not None else user_dir()
    path = path / f"{ts.genre}.pt" if path.suffix != ".pt" else path
    try:  # before training, not after: a bad --out must not cost the training time
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot write the model to {path}: {exc.strerror}; give --out a folder you can write to") \
            from None
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    windows = _windows(ts.train, cfg.seq_frames)
    if not windows:
        raise InputError(f"the clips of '{genre}' are shorter than a {cfg.seq_frames}-frame training sequence")
    weights = np.array([hi - lo for _, lo, hi in windows], dtype=float)
    n_pose = pose_dims(ts.skeleton.n_joints)
    gen = PoseGenerator(n_pose, ts.n_motifs, cfg).to(device)
    body = Body(ts.skeleton, TRAIN_FPS)
    perceptual, embedding = _perceptual(body, ts.skeleton)
    loss_fn = PoseLoss(body, ts.mean, ts.std, cfg, perceptual).to(device)
    opt = torch.optim.Adam(gen.parameters(), lr=cfg.lr)
    held = _windows(ts.held_out, cfg.seq_frames)
    held_batch = (make_batch(ts, ts.held_out, [(i, lo + (hi - lo) * k // 16) for i, lo, hi in held
                                               for k in range(16)], cfg.seq_frames) if held else None)

    def run(batch):
        b = {k: v.to(device) for k, v in batch.items()}
        out_ = gen(b["first"], b["cond"], b["music"], b["window"], target=b["target"])
        return loss_fn(out_, b["target"], b["words"] if len(b["words"]) else None)

    curve, step, log_every_s, next_log, recent = [], 0, max(budget_s / 12.0, 1.0), 0.0, []
    first_loss = None
    t0 = time.perf_counter()
    while step < cfg.steps:
        elapsed = time.perf_counter() - t0
        if elapsed >= budget_s:
            break
        pick = rng.choice(len(windows), size=cfg.batch, p=weights / weights.sum())
        starts = [(windows[p][0], int(rng.integers(windows[p][1], windows[p][2]))) for p in pick]
        gen.train()
        total, terms = run(make_batch(ts, ts.train, starts, cfg.seq_frames))
        opt.zero_grad()
        total.backward()
        torch.nn.utils.clip_grad_norm_(gen.parameters(), 1.0)
        for group in opt.param_groups:  # linear decay to 10 % over the time budget
            group["lr"] = cfg.lr * (1.0 - 0.9 * min(elapsed / budget_s, 1.0))
        opt.step()
        step += 1
        recent.append({"loss": total.item(), **{k: v.item() for k, v in terms.items()}})
        first_loss = first_loss if first_loss is not None else recent[-1]["loss"]
        if progress:
            progress(time.perf_counter() - t0, budget_s, recent[-1]["loss"])
        if time.perf_counter() - t0 >= next_log:
            curve.append(_log_point(step, time.perf_counter() - t0, recent, gen, run, held_batch))
            next_log += log_every_s
            recent = []
    if recent:
        curve.append(_log_point(step, time.perf_counter() - t0, recent, gen, run, held_batch))
    info = {"config": cfg.to_dict(), "steps": step, "train_s": round(time.perf_counter() - t0, 1),
            "total_s": round(time.perf_counter() - t_start, 1), "device": device, "seed": seed,
            "clips": len(ts.train), "held_out_clips": [s.name for s in ts.held_out],
            "frames": int(sum(len(s.poses) for s in ts.train)), "fps": TRAIN_FPS,
            "motifs": ts.n_motifs, "motif_source": ts.motif_source, "perceptual_embedding": embedding,
            "first_loss": first_loss, "final_loss": curve[-1]["loss"] if curve else None, "curve": curve}
    gen.cpu().eval()
    save_model(path, gen, ts.skeleton, ts.mean, ts.std, ts.genre, info, start_poses(ts.train),
               ts.template, ts.transitions)
    info["path"] = str(path)
    return info


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

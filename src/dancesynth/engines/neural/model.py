"""The pose generator: an auto-conditioned LSTM with windowed AdaIN (Aristidou et al. §4.2-4.3).

Each step reads the previous pose and this frame's conditioning (beat phase and
length, target motif) and predicts the next pose. *Auto-conditioning* (Li et al.,
acLSTM): in training the previous pose is alternately the ground truth for
``gt_frames`` steps and the network's own output for ``self_frames`` steps, so it
learns to recover from its own errors and can run for minutes at inference.

*AdaIN*: the music of each motion word (``data.music_vectors``) sets a scale and
shift of the normalised LSTM features. The parameters are tiled over the word and
faded in and out with a Hamming-shaped window (``data.hamming_weights``) that is 0
at the word's boundaries, so the music restyles the middle of a word while the
joins between words stay what the LSTM predicts.

torch is imported only here and by the other modules of this package.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn

from .data import BEAT_DIMS, MUSIC_DIMS


@dataclass(frozen=True)
class NeuralConfig:
    """Sizes and training schedule; one source of defaults per named configuration."""

    name: str = "small"
    hidden: int = 320           # LSTM units per layer
    layers: int = 3
    adain_hidden: int = 64
    seq_frames: int = 60        # frames per training sequence (at data.TRAIN_FPS)
    batch: int = 32
    gt_frames: int = 5          # acLSTM: ground-truth inputs ...
    self_frames: int = 5        # ... then self-fed inputs, alternating
    lr: float = 1e-3
    steps: int = 100_000        # upper bound; training also stops at its time budget
    minutes: float = 25.0       # default time budget
    w_rot: float = 1.0          # eq. (6): geodesic rotation loss ...
    w_pos: float = 4.0          # ... plus FK positions (metres)
    w_root: float = 0.5         # root speeds and height (normalised units)
    w_contact: float = 0.2      # contact classification + foot skating
    w_percept: float = 0.1      # motion perceptual loss through the word embedding

    @staticmethod
    def named(name: str) -> "NeuralConfig":
        if name not in CONFIGS:
            from ...errors import InputError

            raise InputError(f"unknown config '{name}': use one of {', '.join(CONFIGS)}")
        return CONFIGS[name]

    def to_dict(self) -> dict:
        return asdict(self)


CONFIGS = {
    "tiny": NeuralConfig(name="tiny", hidden=48, layers=1, adain_hidden=16, seq_frames=30, batch=8,
                         minutes=0.5, steps=400, lr=3e-3),
    "small": NeuralConfig(),
    # Aristidou et al. build on acLSTM's three layers of 1024 units and 100-frame sequences.
    "paper": NeuralConfig(name="paper", hidden=1024, layers=3, adain_hidden=256, seq_frames=100, batch=32,
                          minutes=24 * 60.0),
}


class WindowedAdaIN(nn.Module):
    """``h' = (1 - w) h + w (gamma * norm(h) + beta)``, gamma and beta from the word's music vector.

    ``norm`` is a per-frame layer norm (causal, so it streams); ``w`` is the window
    weight of the frame within its word, 0 at the word's boundaries.
    """

    def __init__(self, channels: int, hidden: int):
        super().__init__()
        self.norm = nn.LayerNorm(channels, elementwise_affine=False)
        self.mlp = nn.Sequential(nn.Linear(MUSIC_DIMS, hidden), nn.ReLU(), nn.Linear(hidden, 2 * channels))
        nn.init.zeros_(self.mlp[-1].weight)
        nn.init.zeros_(self.mlp[-1].bias)

    def forward(self, h, music, window):
        gamma, beta = self.mlp(music).chunk(2, dim=-1)
        styled = (1.0 + gamma) * self.norm(h) + beta
        w = window.unsqueeze(-1)
        return (1.0 - w) * h + w * styled


class PoseGenerator(nn.Module):
    """acLSTM over pose vectors; the last two outputs are contact logits."""

    def __init__(self, pose_dims: int, n_motifs: int, config: NeuralConfig):
        super().__init__()
        self.config, self.pose_dims, self.n_motifs = config, pose_dims, n_motifs
        cond = BEAT_DIMS + n_motifs
        self.cells = nn.ModuleList(nn.LSTMCell(pose_dims + cond if i == 0 else config.hidden, config.hidden)
                                   for i in range(config.layers))
        self.adain = WindowedAdaIN(config.hidden, config.adain_hidden)
        self.out = nn.Linear(config.hidden, pose_dims)

    def initial_state(self, batch: int, device=None):
        z = torch.zeros(batch, self.config.hidden, device=device)
        return [(z, z) for _ in self.cells]

    def step(self, prev, cond, music, window, state):
        """One frame: previous pose (B, P), conditioning (B, C), music (B, M), window (B,)."""
        x, new = torch.cat([prev, cond], dim=-1), []
        for cell, s in zip(self.cells, state):
            h, c = cell(x, s)
            new.append((h, c))
            x = h
        return self.out(self.adain(x, music, window)), new

    @staticmethod
    def feedback(output):
        """The pose fed to the next step: contacts as probabilities."""
        return torch.cat([output[..., :-2], torch.sigmoid(output[..., -2:])], dim=-1)

    def forward(self, first, cond, music, window, target=None):
        """Generate ``T`` frames after the pose ``first`` (B, P); cond (B, T, C), music (B, T, M), window (B, T).

        With ``target`` (B, T, P) the inputs follow the acLSTM schedule (ground truth
        for ``gt_frames``, then own output for ``self_frames``); without it every
        input is the previous output (inference).
        """
        b, t = cond.shape[:2]
        state, prev, outs = self.initial_state(b, cond.device), first, []
        period = self.config.gt_frames + self.config.self_frames
        for i in range(t):
            if target is not None and i > 0 and (i % period) < self.config.gt_frames:
                prev = target[:, i - 1]
            y, state = self.step(prev, cond[:, i], music[:, i], window[:, i], state)
            outs.append(y)
            prev = self.feedback(y)
        return torch.stack(outs, dim=1)

"""The pose generator: an auto-conditioned LSTM with windowed AdaIN (Aristidou et al. §4.2-4.3).

Each step reads the previous pose and this frame's conditioning (beat phase and
length, the target motif as samples of a motif word, ``data.conditioning``) and
predicts the next pose. *Auto-conditioning* (Li et al., acLSTM): in training the
previous pose is alternately the ground truth for ``gt_frames`` steps and the
network's own output for ``self_frames`` steps, so it learns to recover from its
own errors and can run for minutes at inference.

*AdaIN* (§4.2.1): the music of each motion word (``data.music_vectors``) sets a
scale and shift of every joint-rotation channel of the generated motion word,
constant over the word (temporally invariant); the rotations are already
normalised channel by channel (by the training data's statistics rather than the
word's own, which a frame-by-frame generator cannot see in advance). The
modulation fades in and out with a Hann-shaped window (``data.hamming_weights``)
that is 0 at the word's boundaries, so the joins between words stay what the LSTM
predicts. The modulated pose is the output and is fed back.

torch is imported only here and by the other modules of this package.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
from torch import nn

from .data import COND_DIMS, MUSIC_DIMS, ROOT_DIMS


@dataclass(frozen=True)
class NeuralConfig:
    """Sizes and training schedule; one source of defaults per named configuration."""

    name: str = "small"
    hidden: int = 256           # LSTM units per layer
    layers: int = 2
    adain_hidden: int = 64
    seq_frames: int = 60        # frames per training sequence (at data.TRAIN_FPS)
    batch: int = 32
    gt_frames: int = 1          # acLSTM: ground-truth inputs ...
    self_frames: int = 9        # ... then self-fed inputs, alternating
    lr: float = 1e-3            # decays linearly to 10 % over ``steps``
    steps: int = 800            # training length: same data, seed and steps -> same weights
    minutes: float = 0.0        # an optional time cap (0: none); a cap makes training depend on the machine
    threads: int = 2            # torch threads in training (results depend on it, so it is fixed)
    rates: tuple = (0.85, 1.0, 1.18)   # tempo augmentation: each clip also played this much faster
    mirror: bool = True         # ... and left-right mirrored
    own_word: float = 1.0       # share of words whose motif word is the word itself (else another of its motif)
    w_rot: float = 1.0          # eq. (6): geodesic rotation loss ...
    w_pos: float = 4.0          # ... plus FK positions (metres)
    w_root: float = 0.5         # root speeds and height (normalised units)
    w_contact: float = 0.2      # contact classification + foot skating
    w_percept: float = 0.5      # eq. (9): motion perceptual loss against the motif
    w_head: float = 10.0        # hands kept out of the head (metres of penetration)
    w_kinetic: float = 1.0      # each joint's kinetic energy and acceleration over a sequence, as the real's

    @staticmethod
    def named(name: str) -> "NeuralConfig":
        if name not in CONFIGS:
            from ...errors import InputError

            raise InputError(f"unknown config '{name}': use one of {', '.join(CONFIGS)}")
        return CONFIGS[name]

    def to_dict(self) -> dict:
        return asdict(self)

    @staticmethod
    def from_dict(d: dict) -> "NeuralConfig":
        fields = NeuralConfig.__dataclass_fields__
        known = {k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items() if k in fields}
        return NeuralConfig(**known)


CONFIGS = {
    "tiny": NeuralConfig(name="tiny", hidden=48, layers=1, adain_hidden=16, seq_frames=30, batch=8, gt_frames=5,
                         self_frames=5, steps=60, lr=3e-3, rates=(1.0,), mirror=False),
    "small": NeuralConfig(),
    # Aristidou et al. build on acLSTM's three layers of 1024 units and 100-frame sequences; Adam at 1e-4.
    "paper": NeuralConfig(name="paper", hidden=1024, layers=3, adain_hidden=256, seq_frames=100, batch=32,
                          lr=1e-4, steps=500_000),
}


class WindowedAdaIN(nn.Module):
    """``y' = y + w (gamma * y + beta)`` on the rotation channels; gamma, beta from the word's music vector.

    ``y`` is the normalised generated pose, ``w`` the window weight of the frame
    within its word (0 at the word's boundaries). gamma and beta start at 0: an
    untrained AdaIN changes nothing.
    """

    def __init__(self, channels: int, hidden: int):
        super().__init__()
        self.channels = channels
        self.mlp = nn.Sequential(nn.Linear(MUSIC_DIMS, hidden), nn.ReLU(), nn.Linear(hidden, 2 * channels))
        nn.init.zeros_(self.mlp[-1].weight)
        nn.init.zeros_(self.mlp[-1].bias)

    def forward(self, y, music, window):
        gamma, beta = self.mlp(music).chunk(2, dim=-1)
        rot = y[..., :self.channels]
        styled = rot + window.unsqueeze(-1) * (gamma * rot + beta)
        return torch.cat([styled, y[..., self.channels:]], dim=-1)


class PoseGenerator(nn.Module):
    """acLSTM over pose vectors; the last two outputs are contact logits."""

    def __init__(self, pose_dims: int, n_motifs: int, config: NeuralConfig):
        super().__init__()
        self.config, self.pose_dims, self.n_motifs = config, pose_dims, n_motifs
        self.cells = nn.ModuleList(nn.LSTMCell(pose_dims + COND_DIMS if i == 0 else config.hidden, config.hidden)
                                   for i in range(config.layers))
        self.out = nn.Linear(config.hidden, pose_dims)
        self.adain = WindowedAdaIN(pose_dims - ROOT_DIMS - 2, config.adain_hidden)

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
        return self.adain(self.out(x), music, window), new
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

"""An embedding of motion words where similar movements lie close together.

Aristidou et al. embed their words with the pretrained network of Aristidou et al.
(2018), which we do not have. We ship two embedders, both plain numpy at run time:

- ``"pca"``: the words' features, standardised per channel, flattened and projected
  on their first principal components -- the baseline.
- ``"learned"``: a small 1-D convolutional encoder over the 13 frames, trained by us
  on the bundled database with a contrastive (NT-Xent) objective whose positives are
  the same word cut with its beats moved by up to +-2 frames and its time warped
  (see ``embedding_train.py`` and docs/motifs.md); output on the unit sphere.

``Embedder.torch_module()`` gives the same function as a frozen, differentiable torch
module, for the neural generator's motion perceptual loss.
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ModelError, InputError
from .words import FEATURE_DIM, WORD_FRAMES

MODELS_DIR = Path(__file__).resolve().parents[1] / "data" / "models"
KINDS = ("pca", "learned")
FORMAT_VERSION = 1

# The arrays each kind stores (besides mean/std of the 45 feature channels).
_PARAMS = {"pca": ("components", "center"), "learned": ("w1", "b1", "w2", "b2", "w3", "b3")}


def embedder_path(kind: str) -> Path:
    return MODELS_DIR / f"embedding_{kind}.npz"


def _conv1d(x: np.ndarray, w: np.ndarray, b: np.ndarray) -> np.ndarray:
    """'Same' 1-D convolution over the frame axis: x (N, T, Cin), w (Cout, Cin, K) as torch stores it."""
    k = w.shape[2]
    pad = k // 2
    xp = np.pad(x, ((0, 0), (pad, pad), (0, 0)))
    t = x.shape[1]
    out = np.zeros((x.shape[0], t, w.shape[0]), dtype=x.dtype) + b
    for i in range(k):  # torch's Conv1d is a cross-correlation: tap i reads frame t + i - pad
        out += xp[:, i:i + t] @ w[:, :, i].T
    return out


@dataclass(eq=False)
class Embedder:
    """A function from motion words (W, 13, 45) to points (W, dim)."""

    kind: str
    params: dict = field(repr=False)
    info: dict = field(default_factory=dict)

    @property
    def dim(self) -> int:
        key = "components" if self.kind == "pca" else "b3"
        return int(self.params[key].shape[0])

    def _normalise(self, features: np.ndarray) -> np.ndarray:
        f = np.asarray(features, dtype=np.float32)
        if f.ndim != 3 or f.shape[1:] != (WORD_FRAMES, FEATURE_DIM):
            raise InputError(f"features must be (words, {WORD_FRAMES}, {FEATURE_DIM}), got {f.shape}")
        return (f - self.params["mean"]) / self.params["std"]

    def embed(self, features: np.ndarray) -> np.ndarray:
        """Embed words (W, 13, 45) -> (W, dim) float32."""
        x = self._normalise(features)
        p = self.params
        if self.kind == "pca":
            return (x.reshape(len(x), -1) - p["center"]) @ p["components"].T
        h = np.maximum(_conv1d(x, p["w1"], p["b1"]), 0.0)
        h = np.maximum(_conv1d(h, p["w2"], p["b2"]), 0.0)
        z = h.reshape(len(h), -1) @ p["w3"].T + p["b3"]
        return z / np.maximum(np.linalg.norm(z, axis=1, keepdims=True), 1e-8)

    def torch_module(self):
        """A frozen ``torch.nn.Module`` (N, 13, 45) -> (N, dim) computing ``embed``, differentiable."""
        import torch

        return _torch_module(self, torch)


def _torch_module(emb: Embedder, torch):
    nn = torch.nn
    hidden = emb.params["w1"].shape[0] if emb.kind == "learned" else 0

    class WordEncoder(nn.Module):
        def __init__(self):
            super().__init__()
            self.register_buffer("mean", torch.zeros(FEATURE_DIM))
            self.register_buffer("std", torch.ones(FEATURE_DIM))
            if emb.kind == "pca":
                self.register_buffer("center", torch.zeros(WORD_FRAMES * FEATURE_DIM))
                self.register_buffer("components", torch.zeros(emb.dim, WORD_FRAMES * FEATURE_DIM))
            else:
                self.conv1 = nn.Conv1d(FEATURE_DIM, hidden, 3, padding=1)
                self.conv2 = nn.Conv1d(hidden, hidden, 3, padding=1)
                self.out = nn.Linear(hidden * WORD_FRAMES, emb.dim)

        def forward(self, x):
            x = (x - self.mean) / self.std
            if emb.kind == "pca":
                return (x.flatten(1) - self.center) @ self.components.T
            h = torch.relu(self.conv1(x.transpose(1, 2)))
            h = torch.relu(self.conv2(h))
            # flatten frame-major, as the numpy code does: (N, T, C) -> (N, T*C)
            z = self.out(h.transpose(1, 2).flatten(1))
            return torch.nn.functional.normalize(z, dim=1, eps=1e-8)

    m = WordEncoder()
    names = {"w1": "conv1.weight", "b1": "conv1.bias", "w2": "conv2.weight", "b2": "conv2.bias",
             "w3": "out.weight", "b3": "out.bias"}
    state = {names.get(k, k): torch.as_tensor(np.asarray(v, dtype=np.float32)) for k, v in emb.params.items()}
    m.load_state_dict(state)
    m.eval()
    for p in m.parameters():
        p.requires_grad_(False)
    return m


def save_embedder(emb: Embedder, path: Path) -> None:
    """Write an embedder's arrays (float32) and its info to an ``.npz`` file, atomically."""
    import json

    from ..io.files import atomic_output

    arrays = {k: np.asarray(v, dtype=np.float32) for k, v in emb.params.items()}
    with atomic_output(Path(path), "wb") as fh:
        np.savez_compressed(fh, kind=np.array(emb.kind), format=np.array(FORMAT_VERSION),
                            info=np.array(json.dumps(emb.info)), **arrays)


def read_embedder(path: Path) -> Embedder:
    """Load an embedder file; ``ModelError`` when it is missing, corrupt or of the wrong shape."""
    import json

    path = Path(path)
    fix = "reinstall dancesynth or rebuild it with 'python scripts/build_motifs.py'"
    try:
        with np.load(path, allow_pickle=False) as z:
            arr = {k: z[k] for k in z.files}
        kind = str(arr.pop("kind"))
        version = int(arr.pop("format"))
        info = json.loads(str(arr.pop("info")))
    except FileNotFoundError:
        raise ModelError(f"embedding weights {path} are missing: {fix}") from None
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, TypeError) as exc:
        raise ModelError(f"embedding weights {path} are corrupt ({exc}): {fix}") from None
    if version != FORMAT_VERSION or kind not in KINDS:
        raise ModelError(f"embedding weights {path} are of another version or kind ({kind!r}): {fix}")
    need = ("mean", "std") + _PARAMS[kind]
    if set(arr) != set(need):
        raise ModelError(f"embedding weights {path} lack {sorted(set(need) - set(arr))}: {fix}")
    emb = Embedder(kind, arr, info)
    try:
        probe = emb.embed(np.zeros((2, WORD_FRAMES, FEATURE_DIM), np.float32))
    except (ValueError, IndexError, InputError) as exc:
        raise ModelError(f"embedding weights {path} have inconsistent shapes ({exc}): {fix}") from None
    if not np.all(np.isfinite(probe)) or not np.all(arr["std"] > 0):
        raise ModelError(f"embedding weights {path} hold non-finite numbers: {fix}")
    return emb


def load_embedder(kind: str = "learned") -> Embedder:
    """The shipped embedder of ``kind`` ("learned" or "pca")."""
    if kind not in KINDS:
        raise ModelError(f"unknown embedding '{kind}': use one of {', '.join(KINDS)}")
    return read_embedder(embedder_path(kind))


# ---------------------------------------------------------------------------------------------
# Fitting the PCA baseline


def channel_stats(features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation of each of the 45 feature channels over all words and frames."""
    flat = np.asarray(features, dtype=np.float64).reshape(-1, FEATURE_DIM)
    return flat.mean(axis=0).astype(np.float32), np.maximum(flat.std(axis=0), 1e-3).astype(np.float32)


def fit_pca(features: np.ndarray, dim: int = 32) -> Embedder:
    """The PCA baseline fitted on words (W, 13, 45)."""
    mean, std = channel_stats(features)
    x = ((np.asarray(features, np.float32) - mean) / std).reshape(len(features), -1).astype(np.float64)
    center = x.mean(axis=0)
    _, s, vt = np.linalg.svd(x - center, full_matrices=False)
    # A deterministic sign: the largest entry of each component is positive.
    signs = np.sign(vt[np.arange(len(vt)), np.argmax(np.abs(vt), axis=1)])
    comps = vt[:dim] * signs[:dim, None]
    explained = float((s[:dim] ** 2).sum() / (s ** 2).sum())
    return Embedder("pca", {"mean": mean, "std": std, "center": center.astype(np.float32),
                            "components": comps.astype(np.float32)},
                    {"words": int(len(features)), "explained_variance": round(explained, 4)})

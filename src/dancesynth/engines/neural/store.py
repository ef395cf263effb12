"""Saving and finding trained pose generators.

A model is one ``<genre>.pt`` file (torch's zip format, loaded with
``weights_only=True``: tensors and plain values, never pickled code) with a
``<genre>.json`` beside it saying how it was trained (config, data, loss curve).
``dance --engine neural`` uses the model shipped in ``dancesynth/data/models/neural``
unless the user names another (``dance --model PATH``): training one (``dancesynth
train``, by default into the user cache) never silently changes later dances. Every
dance records which weights made it (``model_id``: name and content hash).
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import ModelError
from ...io.files import atomic_output
from ...motion.database import _skeleton_from_json, _skeleton_to_json, cache_dir
from ...types import Skeleton

SHIPPED = Path(__file__).resolve().parents[2] / "data" / "models" / "neural"
FORMAT = 2   # 2: conditioned on motif words, AdaIN on the output rotations


def user_dir() -> Path:
    return cache_dir() / "models" / "neural"


def shipped_genres() -> list[str]:
    """The genres a model is shipped for: what ``dance --engine neural`` can dance without ``--model``."""
    return sorted(p.stem for p in SHIPPED.glob("*.pt"))


def find_model(genre: str) -> Path:
    """The shipped model file for ``genre``."""
    if (SHIPPED / f"{genre}.pt").is_file():
        return SHIPPED / f"{genre}.pt"
    shipped = shipped_genres()
    raise ModelError(f"no neural model is shipped for genre '{genre}' (shipped: {', '.join(shipped) or 'none'}); "
                     f"train one with 'dancesynth train --style {genre}' and dance with --model, or dance another "
                     "style")


def model_id(model: "StoredModel") -> dict:
    """Which weights made a dance: where they are, a readable name and a hash of the file's bytes."""
    import hashlib

    digest = hashlib.sha256(Path(model.path).read_bytes()).hexdigest()[:16]
    config = model.info.get("config", {}).get("name", "?")
    where = "shipped" if Path(model.path).resolve().parent == SHIPPED.resolve() else "yours"
    return {"model": str(model.path), "model_name": f"{model.genre}-{config} ({where})", "model_sha256": digest}


@dataclass
class StoredModel:
    generator: object            # model.PoseGenerator, in eval mode
    skeleton: Skeleton
    mean: np.ndarray
    std: np.ndarray
    genre: str
    info: dict                   # config, motif source, metrics
    start_poses: np.ndarray      # (S, P) real poses at motion beats to start a dance from
    path: Path
    template: np.ndarray | None = None      # (K,) the genre's motif signature when trained ...
    transitions: np.ndarray | None = None   # (K, K) ... and its motif transitions
    motif_words: np.ndarray | None = None   # (N, 13, D) real words of the genre, the motif words to dance ...
    word_motifs: np.ndarray | None = None   # (N,) ... and their motifs
    medoids: np.ndarray | None = None       # (K, 13, D) the word nearest each motif (for a motif without words)
    spread: np.ndarray | None = None        # (P,) the training data's spread per channel (data.pose_spread)

    def motif_words_for(self, plan, rng: np.random.Generator) -> np.ndarray:
        """One real word (13, D) of each planned motif, drawn at random (its medoid word where none is stored).

        So a motif is danced a little differently each time. The stored words are the least ambiguous of
        their motif (``train.motif_words_store``). (Choosing the word that best continues the last, as the
        choreography engine does, was tried: the plan was followed on 47.7 % of beats instead of 50.0 %;
        docs/neural.md.)
        """
        out = []
        for m in np.asarray(plan, dtype=np.int64):
            members = np.nonzero(self.word_motifs == m)[0]
            out.append(self.motif_words[members[rng.integers(len(members))]] if len(members) else self.medoids[m])
        return np.stack(out)


def save_model(path: Path, generator, skeleton: Skeleton, mean, std, genre: str, info: dict,
               start_poses: np.ndarray, template=None, transitions=None, *, motif_words=None, word_motifs=None,
               medoids=None, spread=None) -> None:
    """Write ``path`` (.pt) and its .json summary atomically."""
    import torch

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    blob = {"format": FORMAT, "state_dict": {k: v.detach().cpu() for k, v in generator.state_dict().items()},
            "config": generator.config.to_dict(), "pose_dims": generator.pose_dims, "n_motifs": generator.n_motifs,
            "skeleton": json.dumps(_skeleton_to_json(skeleton)), "mean": torch.as_tensor(mean),
            "std": torch.as_tensor(std), "genre": genre, "info": json.dumps(info),
            "start_poses": torch.as_tensor(start_poses, dtype=torch.float16)}
    if template is not None:  # the model's motifs travel with it: a rebuilt motif model cannot confuse it
        blob["template"], blob["transitions"] = torch.as_tensor(template), torch.as_tensor(transitions)
        blob["medoids"] = torch.as_tensor(medoids, dtype=torch.float16)
    blob["motif_words"] = torch.as_tensor(motif_words, dtype=torch.float16)   # what the network is conditioned on
    blob["word_motifs"] = torch.as_tensor(word_motifs, dtype=torch.int16)
    if spread is not None:
        blob["spread"] = torch.as_tensor(spread)
    with atomic_output(path, "wb") as fh:
        torch.save(blob, fh)
    with atomic_output(path.with_suffix(".json"), "w") as fh:
        json.dump({"genre": genre, **info}, fh, indent=1)


def load_model(path: Path) -> StoredModel:
    """Load a model file; a missing, corrupt or foreign file is a ``ModelError``."""
    import torch

    from .model import NeuralConfig, PoseGenerator

    path = Path(path)
    if not path.is_file():
        raise ModelError(f"neural model {path} does not exist; train one with 'dancesynth train'")
    try:
        blob = torch.load(path, map_location="cpu", weights_only=True)
        if not isinstance(blob, dict) or blob.get("format") != FORMAT:
            raise ValueError("not a dancesynth neural model of this version")
        config = NeuralConfig.from_dict(blob["config"])
        gen = PoseGenerator(int(blob["pose_dims"]), int(blob["n_motifs"]), config)
        gen.load_state_dict(blob["state_dict"])
        skeleton = _skeleton_from_json(json.loads(blob["skeleton"]))
        info = json.loads(blob["info"])
        start = blob["start_poses"].float().numpy()
        motifs = [blob[k].numpy() if k in blob else None for k in ("template", "transitions")]
        words = [blob[k].float().numpy() if k in blob else None for k in ("motif_words", "word_motifs", "medoids")]
        spread = blob["spread"].numpy() if "spread" in blob else None
        if words[1] is not None:
            words[1] = words[1].astype(np.int64)
        if words[0] is None or (motifs[0] is None) != (gen.n_motifs == 0) or \
                (motifs[0] is not None and motifs[0].shape != (gen.n_motifs,)):
            raise ValueError("its motif template does not fit the network")
    except (OSError, RuntimeError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile,
            json.JSONDecodeError, __import__("pickle").UnpicklingError) as exc:
        raise ModelError(f"neural model {path} is corrupt or from another version ({str(exc).splitlines()[0]}); "
                         "retrain it with 'dancesynth train' or reinstall dancesynth") from None
    gen.eval()
    return StoredModel(gen, skeleton, blob["mean"].numpy(), blob["std"].numpy(), str(blob["genre"]), info,
                       start, path, *motifs, *words, spread)

"""Motion motifs, signatures, genre templates and motif transitions (Aristidou et al. §3).

Every motion word of the database is embedded (``embedding.py``) and the points are
clustered by K-means; a *motif* is a cluster, represented by the real word nearest
its centroid. A dance's *signature* is the normalised histogram of its words'
motifs; a genre's *template* is the average signature of its dances (one dance = one
clip of the database); its *transition matrix* counts which motif follows which on
consecutive beats of its dances. Motif ids are shown to users as ``M0`` .. ``M{K-1}``.

Transitions are smoothed towards the template, ``T[a] = (C[a] + template) / (n_a + 1)``:
one pseudo-observation per row spread as the genre's own motif distribution, so every
row is a distribution, a motif never seen followed in this genre continues like the
genre in general, and motifs foreign to the genre stay at probability 0.
"""

from __future__ import annotations

import hashlib
import json
import re
import zipfile
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import InputError, ModelError
from .embedding import MODELS_DIR, Embedder, load_embedder
from .words import MotionWords, style_words

DEFAULT_K = 48          # see docs/motifs.md for why
DEFAULT_SEED = 0
TRANSITION_PRIOR = 1.0  # pseudo-counts per row, spread as the genre template
FORMAT_VERSION = 1
MOTIFS_PATH = MODELS_DIR / "motifs.npz"


def chi2(s1, s2) -> float:
    """Chi-square distance of eq. (11): ``1/2 sum_i (S1_i - S2_i)^2 / (S1_i + S2_i)``.

    Both histograms are normalised first (counts are fine); bins empty in both add 0.
    0 for proportional histograms, 1 for histograms with no bin in common.
    ``InputError`` for NaN, negative entries, all-zero histograms, different lengths.
    """
    p, q = (np.asarray(s, dtype=np.float64) for s in (s1, s2))
    if p.ndim != 1 or q.ndim != 1:
        raise InputError("signatures must be 1-D histograms of motif counts or shares")
    if p.size != q.size:
        raise InputError(f"the signatures have {p.size} and {q.size} bins; histogram both over the same motifs")
    for s in (p, q):
        if not np.all(np.isfinite(s)):
            raise InputError("a signature has a non-finite (NaN or infinite) entry")
        if np.any(s < 0):
            raise InputError("a signature has negative entries; a signature is a histogram of motif counts or shares")
        if not s.sum() > 0:
            raise InputError("a signature is empty (all zeros); a signature needs at least one motif occurrence")
    p, q = p / p.sum(), q / q.sum()
    num, den = (p - q) ** 2, p + q
    return float(0.5 * np.sum(np.divide(num, den, out=np.zeros_like(num), where=den > 0)))


def parse_motif_id(text: str, k: int) -> int:
    """``"M17"`` (or ``"17"``) -> 17, checked against ``k`` motifs; ``InputError`` otherwise."""
    m = re.fullmatch(r"[Mm]?(\d+)", str(text).strip())
    if not m or int(m.group(1)) >= k:
        raise InputError(f"unknown motif '{text}': motif ids are M0 .. M{k - 1}")
    return int(m.group(1))


@dataclass(frozen=True)
class MotifModel:
    """K motifs in an embedding, with each genre's template signature and transitions."""

    k: int
    embedder: Embedder
    centroids: np.ndarray        # (K, dim)
    motif_features: np.ndarray   # (K, 13, D) the real word nearest each centroid
    genres: tuple[str, ...]
    templates: dict              # genre -> (K,) normalised signature (average over the genre's dances)
    transitions: dict            # genre -> (K, K) row-stochastic motif transition matrix
    info: dict = field(default_factory=dict)   # provenance: seed, words, the source of each motif word

    def assign(self, features) -> np.ndarray:
        """Motif id (W,) of each word (W, 13, D): the nearest centroid in the embedding."""
        z = self.embedder.embed(features)
        if len(z) == 0:
            return np.zeros(0, dtype=np.int64)
        d = ((z[:, None, :] - self.centroids[None]) ** 2).sum(-1)
        return np.argmin(d, axis=1).astype(np.int64)

    def signature(self, ids) -> np.ndarray:
        """Normalised histogram (K,) of motif ids (all zeros when there are none)."""
        ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        if ids.size and (ids.min() < 0 or ids.max() >= self.k):
            raise InputError(f"motif ids must lie in 0 .. {self.k - 1}")
        h = np.bincount(ids, minlength=self.k).astype(np.float64)
        return h / h.sum() if h.sum() > 0 else h

    def nearest_genre(self, signature) -> str:
        """The genre whose template is nearest ``signature`` in chi2."""
        return min(self.genres, key=lambda g: chi2(self.templates[g], signature))

    def fingerprint(self) -> str:
        """A short hash of the centroids: store it with anything trained on these motif ids."""
        return hashlib.blake2b(np.ascontiguousarray(self.centroids, np.float32).tobytes(), digest_size=8).hexdigest()

    def check_genre(self, genre: str) -> str:
        if genre not in self.templates:
            raise InputError(f"unknown genre '{genre}': the motif model knows {', '.join(self.genres)}")
        return genre


def motif_name(i: int) -> str:
    return f"M{int(i)}"


_STYLE_MOTIFS: dict = {}  # cutting and embedding a style's words takes about a second: once per process


def style_motifs(style, model: MotifModel) -> tuple[MotionWords, np.ndarray]:
    """Every word of a database ``Style`` (``style_words``) and the motif of each."""
    key = (style.name, style.fingerprint, style.n_frames, model.k, model.fingerprint())
    if key not in _STYLE_MOTIFS:
        if len(_STYLE_MOTIFS) >= 4:
            _STYLE_MOTIFS.clear()
        words = style_words(style)
        _STYLE_MOTIFS[key] = (words, model.assign(words.features))
    return _STYLE_MOTIFS[key]


def beat_frames_at(clip, times_s) -> np.ndarray:
    """The clip's frames nearest ``times_s`` (beats in seconds), inside the clip, once each."""
    f = np.rint(np.asarray(times_s, dtype=np.float64) * clip.fps).astype(np.int64)
    return np.unique(np.clip(f, 0, clip.n_frames - 1))


def dance_motifs(clip, model: MotifModel, *, genre: str | None = None, beat_frames=None) -> dict:
    """A dance's motif sequence and signature against a genre template (plain JSON-able data).

    Beats are the clip's kinematic beats unless ``beat_frames`` are given (e.g. the
    music beats it dances to, ``beat_frames_at(clip, beat_times_s)``); the genre is
    the one whose template is nearest the dance's signature unless named.
    """
    from .words import clip_words, kinematic_beat_frames

    if genre is not None:
        model.check_genre(genre)
    if beat_frames is None:
        beat_frames = kinematic_beat_frames(clip)
    words = clip_words(clip, beat_frames)
    ids = model.assign(words.features)
    sig = model.signature(ids)
    by_genre = {g: round(chi2(model.templates[g], sig), 4) for g in model.genres}
    chosen = genre or min(by_genre, key=by_genre.get)
    return {
        "fps": float(clip.fps), "duration_s": round(clip.duration_s, 3), "k": model.k,
        "genre": chosen, "genre_guessed": genre is None, "chi2": by_genre[chosen], "chi2_by_genre": by_genre,
        "words": [{"start_s": round(s / clip.fps, 3), "end_s": round(e / clip.fps, 3), "motif": motif_name(i)}
                  for s, e, i in zip(words.start, words.end, ids)],
        "signature": [round(float(x), 5) for x in sig],
        "template": [round(float(x), 5) for x in model.templates[chosen]],
    }


# ---------------------------------------------------------------------------------------------
# Building


def _transition_counts(ids: np.ndarray, words: MotionWords, k: int) -> np.ndarray:
    """Counts of motif a followed by motif b on consecutive beats of the same clip."""
    c = np.zeros((k, k))
    follows = (words.clip[1:] == words.clip[:-1]) & (words.start[1:] == words.end[:-1])
    np.add.at(c, (ids[:-1][follows], ids[1:][follows]), 1.0)
    return c


def build_motif_model(database, embedder: Embedder | None = None, *, k: int = DEFAULT_K,
                      seed: int = DEFAULT_SEED) -> MotifModel:
    """Cluster every word of ``database`` into ``k`` motifs (K-means, seeded) and summarise each genre."""
    from sklearn.cluster import KMeans  # only needed when building

    embedder = embedder or load_embedder("learned")
    all_words = [style_words(s) for s in database.styles.values()]
    all_words = [w for w in all_words if len(w)]
    n = sum(len(w) for w in all_words)
    if k < 2 or n < k:
        raise InputError(f"cannot make {k} motifs from {n} motion words: choose 2 <= K <= {n}")
    feats = np.concatenate([w.features for w in all_words])
    z = embedder.embed(feats).astype(np.float64)
    km = KMeans(n_clusters=k, random_state=seed, n_init=10).fit(z)
    centroids = km.cluster_centers_
    labels = km.labels_.astype(np.int64)
    nearest = np.argmin(((z[:, None, :] - centroids[None]) ** 2).sum(-1), axis=0)
    origin = [(w.style, int(c), int(s), int(e)) for w in all_words for c, s, e in zip(w.clip, w.start, w.end)]

    templates, transitions, per_genre = {}, {}, {}
    offset = 0
    for w in all_words:
        ids = labels[offset:offset + len(w)]
        offset += len(w)
        g = per_genre.setdefault(w.genre, {"sigs": [], "counts": np.zeros((k, k))})
        for c in np.unique(w.clip):
            g["sigs"].append(np.bincount(ids[w.clip == c], minlength=k) / np.sum(w.clip == c))
        g["counts"] += _transition_counts(ids, w, k)
    for genre, g in per_genre.items():
        t = np.mean(g["sigs"], axis=0)
        templates[genre] = t / t.sum()
        counts = g["counts"] + TRANSITION_PRIOR * templates[genre]
        transitions[genre] = counts / counts.sum(axis=1, keepdims=True)
    info = {"seed": seed, "words": n, "embedding": embedder.kind, "inertia": float(km.inertia_),
            "motif_words": [list(origin[i]) for i in nearest], "dances": {g: len(v["sigs"]) for g, v in per_genre.items()}}
    return MotifModel(k, embedder, centroids.astype(np.float32), feats[nearest].astype(np.float32),
                      tuple(sorted(templates)), templates, transitions, info)


# ---------------------------------------------------------------------------------------------
# Storage


def refresh_motif_words(model: MotifModel, database) -> MotifModel:
    """``model`` with each motif's real word re-picked, nearest its centroid, from ``database`` as it is now.

    The clean-up at ``build-db`` may change a few frames of a word (a mended snap); the motifs, their
    centroids, templates and transitions stay, so dances and the neural model keep their meaning, and
    each motif is again a word the database has."""
    words = [w for w in (style_words(s) for s in database.styles.values()) if len(w)]
    feats = np.concatenate([w.features for w in words])
    z = model.embedder.embed(feats).astype(np.float64)
    nearest = np.argmin(((z[:, None, :] - model.centroids[None].astype(np.float64)) ** 2).sum(-1), axis=0)
    origin = [(w.style, int(c), int(s), int(e)) for w in words for c, s, e in zip(w.clip, w.start, w.end)]
    info = {**model.info, "motif_words": [list(origin[i]) for i in nearest]}
    return replace(model, motif_features=feats[nearest].astype(np.float32), info=info)


def save_motif_model(model: MotifModel, path: Path) -> None:
    """Write ``model`` (without its embedder, which is stored on its own) atomically."""
    from ..io.files import atomic_output

    g = model.genres
    with atomic_output(Path(path), "wb") as fh:
        np.savez_compressed(
            fh, format=np.array(FORMAT_VERSION), k=np.array(model.k), embedding=np.array(model.embedder.kind),
            centroids=model.centroids, motif_features=model.motif_features, genres=np.array(g, dtype=str),
            templates=np.array([model.templates[x] for x in g]),
            transitions=np.array([model.transitions[x] for x in g]), info=np.array(json.dumps(model.info)))


def read_motif_model(path: Path, embedder: Embedder | None = None) -> MotifModel:
    """Load a motif model file; ``ModelError`` when it is missing or corrupt."""
    path = Path(path)
    fix = "reinstall dancesynth or rebuild it with 'python scripts/build_motifs.py'"
    try:
        with np.load(path, allow_pickle=False) as z:
            a = {key: z[key] for key in z.files}
        k, kind = int(a["k"]), str(a["embedding"])
        genres = tuple(str(x) for x in a["genres"])
        info = json.loads(str(a["info"]))
        version = int(a["format"])
    except FileNotFoundError:
        raise ModelError(f"motif model {path} is missing: {fix}") from None
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, TypeError) as exc:
        raise ModelError(f"motif model {path} is corrupt ({exc}): {fix}") from None
    embedder = embedder or load_embedder(kind)
    shapes_ok = (version == FORMAT_VERSION and a["centroids"].shape == (k, embedder.dim)
                 and a["motif_features"].shape[0] == k and a["templates"].shape == (len(genres), k)
                 and a["transitions"].shape == (len(genres), k, k))
    if not shapes_ok or not all(np.all(np.isfinite(a[x])) for x in ("centroids", "templates", "transitions")):
        raise ModelError(f"motif model {path} is inconsistent (version or shapes) or holds non-finite numbers: {fix}")
    return MotifModel(k, embedder, a["centroids"], a["motif_features"], genres,
                      dict(zip(genres, a["templates"])), dict(zip(genres, a["transitions"])), info)


def _database_key(database, embedder: Embedder, k: int, seed: int) -> str:
    h = hashlib.blake2b(repr((FORMAT_VERSION, k, seed, embedder.kind)).encode(), digest_size=16)
    for name in sorted(database.styles):
        st = database.styles[name]
        h.update(f"{name}|{st.genre}|{st.fingerprint}|{st.n_frames}".encode())
    for arr in embedder.params.values():
        h.update(np.ascontiguousarray(arr).tobytes())
    here = Path(__file__).resolve().parent
    for code in ("words.py", "embedding.py", "motifs.py"):  # changing the method rebuilds cached models
        h.update((here / code).read_bytes())
    return h.hexdigest()


def load_motif_model(database=None, *, k: int = DEFAULT_K, seed: int = DEFAULT_SEED) -> MotifModel:
    """The shipped model for the bundled database; built once and cached for another database."""
    from .database import BUNDLED_DATABASE, cache_dir

    if database is None or (Path(database.source).resolve() == BUNDLED_DATABASE.resolve()
                            and k == DEFAULT_K and seed == DEFAULT_SEED):
        return read_motif_model(MOTIFS_PATH)
    embedder = load_embedder("learned")
    cached = cache_dir() / "motifs" / f"{_database_key(database, embedder, k, seed)}.npz"
    if cached.is_file():
        try:
            return read_motif_model(cached, embedder)
        except ModelError:
            pass  # a damaged cache entry is rebuilt below
    model = build_motif_model(database, embedder, k=k, seed=seed)
    cached.parent.mkdir(parents=True, exist_ok=True)
    save_motif_model(model, cached)
    return model

"""Rebuild the shipped word embeddings and motif model from the bundled database.

    python scripts/build_motifs.py [--k 48] [--seed 0] [--epochs 100] [--skip-training]
    python scripts/build_motifs.py --evaluate          # only print the retrieval table of docs/motifs.md
    python scripts/build_motifs.py --choose-k          # the table behind the default K (docs/motifs.md)
    python scripts/build_motifs.py --refresh-words     # after build-db mended some frames: same motifs

Writes src/dancesynth/data/models/embedding_pca.npz, embedding_learned.npz and
motifs.npz. Everything is seeded, so a rebuild on the same machine gives the same
files (torch's CPU kernels may differ in the last bits across machines).
The learned embedding is trained on 4 of every 5 clips; the fifth is held out for
the retrieval evaluation printed at the end (see docs/motifs.md).
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from dancesynth.motion import embedding_train as T
from dancesynth.motion.database import open_database
from dancesynth.motion.embedding import embedder_path, load_embedder, save_embedder
from dancesynth.motion.motifs import (DEFAULT_K, DEFAULT_SEED, MOTIFS_PATH, build_motif_model, chi2,
                                      load_motif_model, refresh_motif_words, save_motif_model)
from dancesynth.motion.words import style_words


def retrieval_table(embedders: dict, held_out, train) -> str:
    rows = ["| timing perturbation of the query | " + " | ".join(embedders) + " |",
            "|---|" + "---|" * len(embedders)]
    for jitter, warp in ((2, 0.3), (4, 0.5), (6, 0.8), (8, 0.95)):
        acc = T.evaluate_retrieval(embedders, held_out, others=train, jitter=jitter, warp=warp)
        rows.append(f"| beats +-{jitter} frames, warp {warp} | " + " | ".join(f"{acc[k]:.3f}" for k in embedders) + " |")
    return "\n".join(rows)


def k_table(db, embedder, ks=(12, 24, 32, 48, 64, 96)) -> str:
    """For each K: words per motif, spread inside motifs, seed stability, and leave-one-dance-out genre
    identification (a dance's signature against templates built without it)."""
    from sklearn.metrics import adjusted_rand_score

    words = [w for w in (style_words(s) for s in db.styles.values()) if len(w)]
    feats = np.concatenate([w.features for w in words])
    dance = np.concatenate([[f"{w.style}/{c}" for c in w.clip] for w in words])
    genre = np.concatenate([[w.genre] * len(w) for w in words])
    rows = ["| K | words per motif | distance to centroid / between words | ARI seed 0 vs 1 | genre of held-out dance |",
            "|---|---|---|---|---|"]
    for k in ks:
        model = build_motif_model(db, embedder, k=k, seed=0)
        ids = model.assign(feats)
        other = build_motif_model(db, embedder, k=k, seed=1).assign(feats)
        z = model.embedder.embed(feats)
        # spread relative to the typical distance between two words, so embeddings compare
        scale = float(np.mean(np.linalg.norm(z - z[np.random.default_rng(0).permutation(len(z))], axis=1)))
        spread = float(np.mean(np.linalg.norm(z - model.centroids[ids], axis=1))) / scale
        dances = sorted(set(dance))
        sigs = {d: model.signature(ids[dance == d]) for d in dances}
        g_of = {d: genre[dance == d][0] for d in dances}
        hits = tried = 0
        for d in dances:
            templates = {}
            for g in set(g_of.values()):
                members = [sigs[e] for e in dances if g_of[e] == g and e != d]
                if members:
                    templates[g] = np.mean(members, axis=0)
            if g_of[d] not in templates:
                continue   # the only dance of its genre
            tried += 1
            hits += min(templates, key=lambda g: chi2(templates[g], sigs[d])) == g_of[d]
        rows.append(f"| {k} | {len(feats) / k:.0f} | {spread:.3f} | {adjusted_rand_score(ids, other):.2f} "
                    f"| {hits}/{tried} |")
    return "\n".join(rows)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--k", type=int, default=DEFAULT_K)
    ap.add_argument("--seed", type=int, default=DEFAULT_SEED)
    ap.add_argument("--epochs", type=int, default=T.TrainConfig.epochs)
    ap.add_argument("--skip-training", action="store_true", help="keep the shipped embeddings, rebuild motifs only")
    ap.add_argument("--evaluate", action="store_true", help="only evaluate the shipped embeddings")
    ap.add_argument("--choose-k", action="store_true", help="only print the table for choosing K")
    ap.add_argument("--refresh-words", action="store_true",
                    help="keep the shipped motifs; re-pick each one's real word from the database as rebuilt")
    args = ap.parse_args()
    db = open_database()
    if args.refresh_words:
        save_motif_model(refresh_motif_words(load_motif_model(db), db), MOTIFS_PATH)
        print(f"wrote {MOTIFS_PATH}", file=sys.stderr)
        return 0
    if args.choose_k:
        for kind in ("learned", "pca"):
            print(f"{kind} embedding\n" + k_table(db, load_embedder(kind)))
        return 0
    train, held_out = T.split_sources(T.database_sources(db), T.TrainConfig.holdout)
    print(f"{sum(len(s.starts) for s in train)} training words, {sum(len(s.starts) for s in held_out)} held out",
          file=sys.stderr)
    if not (args.skip_training or args.evaluate):
        t0 = time.time()
        save_embedder(T.fit_baseline(train), embedder_path("pca"))
        learned = T.train_learned(train, T.TrainConfig(epochs=args.epochs, seed=args.seed),
                                  progress=lambda m: print(m, file=sys.stderr))
        save_embedder(learned, embedder_path("learned"))
        print(f"trained in {time.time() - t0:.0f} s", file=sys.stderr)
    if not args.evaluate:
        model = build_motif_model(db, load_embedder("learned"), k=args.k, seed=args.seed)
        save_motif_model(model, MOTIFS_PATH)
        print(f"{model.k} motifs over {model.info['words']} words, genres {', '.join(model.genres)}", file=sys.stderr)
    print(retrieval_table({"pca": load_embedder("pca"), "learned": load_embedder("learned")}, held_out, train))
    return 0


if __name__ == "__main__":
    sys.exit(main())

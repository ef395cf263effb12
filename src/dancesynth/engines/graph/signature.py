"""Signature-aware streaming (beyond both papers): the graph engine keeps a genre's global structure.

Xu et al.'s segment DP matches beats and intensity but knows nothing of the dance's
global structure; Aristidou et al. keep it by drawing each next motif in proportion
to the signature *deficit*, ``max(S_target - S_now, 0)`` (eq. 5). Here the same
idea becomes a cost in the DP: every step of the graph dances one real motion word
(the mono edge ``prev(v) -> v``, so the word is known from the node it arrives at),
and a word whose motif the dance still *owes* the genre template is cheap.

After ``n`` danced words with signature ``p`` (motif counts / n), arriving by a
word of motif ``m`` costs

    weight * (p_m - q_m) / (p_m + q_m + eps)          (q = the genre's template)

which has the sign and, up to a positive factor, the shape of eq. (11)'s derivative
with respect to ``p_m``: dancing an over-represented motif raises the chi-square
distance to the template and costs up to ``+weight``; dancing one the dance still
owes lowers it and earns up to ``-weight``; a motif foreign to the genre costs the
full weight once danced. The counts are the engine's state, updated after each
segment, so over segments the signature converges to the template (the DP cannot
see its own counts change inside a segment; segments are short). Only costs change:
beats still land exactly and the end-of-segment capacity constraint (THC) is
untouched, so no Xu guarantee is lost. The weight trades the signature against the
intensity match (docs/choreography.md has the measured trade-off).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...motion.database import Style
from ...motion.motifs import MotifModel, style_motifs
from .meta_graph import MetaMotionGraph

DEFAULT_WEIGHT = 8.0  # on the scale of the DP's weighted intensity deviations (EngineConfig.intensity_weight 8;
                      # a jump costs 0.25): chi2 0.10, 0.24 at weight 1 (0.12 when the intensity weight was 1)
_EPS = 1e-3          # keeps the ratio finite for motifs neither danced nor in the template


@dataclass(frozen=True)
class SignatureTarget:
    """What the DP needs: the motif of the word that arrives at each node, and the genre's template."""

    node_motif: np.ndarray   # (N,) motif of the word prev(v) -> v; -1 where no word arrives
    template: np.ndarray     # (K,) the genre's signature
    weight: float            # 0: only count motifs (for measuring), no effect on the dance
    genre: str

    def arrival_cost(self, counts: np.ndarray) -> np.ndarray | None:
        """(N,) cost of arriving at each node after the motif ``counts`` danced so far."""
        if self.weight <= 0:
            return None
        p = counts / counts.sum() if counts.sum() > 0 else np.zeros_like(self.template)
        q = self.template
        per_motif = self.weight * (p - q) / (p + q + _EPS)
        return np.where(self.node_motif >= 0, per_motif[np.maximum(self.node_motif, 0)], self.weight)

    def count(self, counts: np.ndarray, arrived: np.ndarray) -> np.ndarray:
        """``counts`` plus the motifs of the words that arrived at nodes ``arrived``."""
        m = self.node_motif[np.asarray(arrived, dtype=np.int64)]
        return counts + np.bincount(m[m >= 0], minlength=len(self.template))


def signature_target(style: Style, graph: MetaMotionGraph, model: MotifModel,
                     weight: float = DEFAULT_WEIGHT) -> SignatureTarget:
    """The motif of every graph step's word (the style's words, assigned by ``model``) and the
    template of the style's genre."""
    words, ids = style_motifs(style, model)
    node_motif = np.full(graph.n_nodes, -1, dtype=np.int64)
    has_prev = np.flatnonzero(graph.prev_node >= 0)
    start = graph.node_frame[graph.prev_node[has_prev]]
    end = graph.node_frame[has_prev]
    # A word is identified by its two beat frames (words never cross clips, nor do mono edges).
    order = np.lexsort((words.end, words.start))
    ws, we = words.start[order], words.end[order]
    i = np.clip(np.searchsorted(ws, start), 0, max(len(ws) - 1, 0))
    if len(ws):
        hit = (ws[i] == start) & (we[i] == end)
        node_motif[has_prev[hit]] = ids[order][i[hit]]
    return SignatureTarget(node_motif, np.asarray(model.templates[model.check_genre(style.genre)], dtype=np.float64),
                           float(weight), style.genre)


def database_signature(style: Style, graph: MetaMotionGraph, database, weight: float = DEFAULT_WEIGHT) -> SignatureTarget:
    """``signature_target`` with the motif model of ``database`` (the shipped one for the bundled database)."""
    from ...motion.motifs import load_motif_model

    return signature_target(style, graph, load_motif_model(database), weight)

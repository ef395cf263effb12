"""The path search of §3.3: a dynamic program over beat intervals, eq. (4)-(9).

For beat interval k of the music (normalised intensity ``I[k]``) a step from node i
either follows the mono-directional edge i -> next(i), costing

    intCost = |w1_z(i) - I[k]|                                  (eq. 4-5, mono)

or jumps along a bi-directional edge i ~ j and then follows j -> next(j), costing

    s * w2(i, j) * |w1_z(j) - I[k]|                              (eq. 4-5, jump)

where s >= 1 (eq. 6) is the ratio of the time-warp rates before and after the jump.
``P(v, k) = min_i P(i, k-1) + edgeCost`` (eq. 7-8) and the segment ends at the best
node whose synchronization capacity is at least THC (eq. 9). The same function with
the whole song as one segment is the global-DP baseline.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import SynthesisError
from ...motion.accents import AccentCosts
from .meta_graph import MetaMotionGraph


@dataclass
class Path:
    """A walk through the graph, one step per beat interval.

    ``nodes[k]`` is the beat frame shown at beat k (K+1 of them); ``via[k]`` is the
    node whose mono edge fills interval k (``== nodes[k]`` unless step k jumps).
    """

    nodes: np.ndarray
    via: np.ndarray
    jump: np.ndarray
    cost: float

    @property
    def n_steps(self) -> int:
        return len(self.via)

    def first(self, k: int) -> "Path":
        """The first ``k`` steps (a receding horizon commits these and searches the rest again)."""
        return Path(self.nodes[:k + 1], self.via[:k], self.jump[:k], self.cost)


def _rate_factor(rho: np.ndarray, prev_duration: float | None, duration: float) -> np.ndarray:
    """Eq. (6): s = max(r1/r2, r2/r1) with r1/r2 = rho * duration / prev_duration."""
    if prev_duration is None or not prev_duration > 0:  # also NaN: no previous interval
        return np.ones_like(rho)
    x = rho * (duration / prev_duration)
    s = np.maximum(x, 1.0 / x)
    return np.where(np.isfinite(s), s, 1.0)


def search(graph: MetaMotionGraph, intensity_z: np.ndarray, durations_s: np.ndarray, *,
           start_nodes: np.ndarray, prev_duration_s: float | None = None, thc: float = np.inf,
           node_penalty: np.ndarray | None = None, jump_cost: float = 0.0,
           accent: AccentCosts | None = None, beat_class: np.ndarray | None = None,
           class_cost: np.ndarray | None = None, steps: "StepCosts | None" = None,
           intensity_weight: float = 1.0, beat_target: np.ndarray | None = None,
           target_reward: float = 0.0, entry: np.ndarray | None = None, entry_cost: float = 0.0,
           shown_intensity: bool = False, beat_penalty: tuple | None = None) -> Path:
    """Best path for K beat intervals (eq. 7-9).

    ``intensity_z`` (K,) are the normalised music intensities, ``durations_s`` (K,)
    the beat intervals. The path starts at one of ``start_nodes`` (the previous
    segment's last node, or InitS) and ends at a node with capacity >= ``thc``.
    ``node_penalty`` (N,), if given, is added whenever a step arrives at a node (the
    streaming engine uses it to discourage replaying recent beats; not in the paper).
    ``jump_cost`` is added to every jump (0 in the paper, where a jump to a beat of
    exactly the music's intensity is free). ``accent`` adds the costs of ``AccentCosts``
    where the graph knows its accents. ``class_cost`` (C, N) is added on arriving at a node
    on beat ``k`` (0..K) of class ``beat_class[k]`` (-1: none), e.g. the downbeats.
    ``steps``: the graph's ``StepCosts`` for this ``jump_cost`` and ``accent``, built once and
    reused across segments (built here when not given). ``intensity_weight`` scales eq. (8)'s
    intensity deviation against the costs added beyond the paper (1 = as printed).
    ``beat_target`` (K+1,): a node to be at on beat k (-1: none), worth ``target_reward`` when the
    path arrives there (the song's form: a repeated section replays its first occurrence's path).
    On a beat where ``entry`` (K+1,) is set, the path may also cut into that beat's target from
    wherever it is, for ``entry_cost`` (a jump along no edge of the graph: the render blends it),
    so that a replay starts on its section's first beat however far the dance is from it.
    ``shown_intensity``: match the intensity each node's piece shows in its beat against the style's own
    (``MetaMotionGraph.shown_intensity_z``) instead of eq. (5)'s ``w1_z``.
    ``beat_penalty`` ``(beats, nodes, costs)``: a cost for arriving at a node on one beat (1..K) only
    (the global DP charges a node on the beats after it was first danced, ``engine.revisit_penalty``).

    On a large graph only the steps leaving a node the path can be at (a finite cost) are
    relaxed: a streaming segment starts at one node, and within a segment's few beats the path
    reaches a small part of the graph (about 2 % of a large style's beats after 11 beats), so
    most of the graph's steps would only add infinity. The result is the same as relaxing every
    step (``BeatTerms``).
    """
    intensity_z = np.asarray(intensity_z, dtype=np.float64)
    durations_s = np.asarray(durations_s, dtype=np.float64)
    n, k_steps = graph.n_nodes, len(intensity_z)
    costs = np.full((k_steps + 1, n), np.inf)
    costs[0, np.asarray(start_nodes)] = 0.0
    if steps is None:
        steps = StepCosts(graph, jump_cost, accent)
    # Costs that depend only on the node arrived at are added after the minimum over the ways
    # in: the same result, fewer operations, and backtracking is unaffected.
    penalty = None if node_penalty is None else np.asarray(node_penalty, dtype=np.float64)
    prev = np.r_[np.nan if prev_duration_s is None else prev_duration_s, durations_s[:-1]]
    w1_z = graph.shown_intensity_z(durations_s) if shown_intensity else graph.w1_z
    terms = BeatTerms(steps, intensity_weight * np.abs(w1_z - intensity_z[:, None]), durations_s, prev)
    reached = np.flatnonzero(np.isfinite(costs[0]))
    if beat_penalty is not None:
        at, on, cost = (np.asarray(x) for x in beat_penalty)
        order = np.argsort(at, kind="stable")
        at, on, cost = at[order], on[order], np.asarray(cost, dtype=np.float64)[order]
        bounds = np.searchsorted(at, np.arange(k_steps + 2))

    for k in range(k_steps):
        # Eq. (8) for every destination at once. A node has one mono step in; jumps are sorted by
        # destination, so a reduceat takes each destination's best when every jump is relaxed,
        # and minimum.at when only those leaving the reached nodes are.
        row = costs[k + 1]
        m_sel, j_sel = (slice(None), slice(None)) if terms.every_step else steps.leaving(reached)
        row[steps.m_dst[m_sel]] = terms.mono(k, costs[k], m_sel)
        arrive = terms.jump(k, costs[k], j_sel)
        if isinstance(j_sel, slice):
            if steps.j_nodes.size:
                row[steps.j_nodes] = np.minimum(row[steps.j_nodes], np.minimum.reduceat(arrive, steps.j_starts))
        else:
            np.minimum.at(row, steps.j_dst[j_sel], arrive)
        cut = _entry(graph, costs[k], terms, k, beat_target, entry, entry_cost)
        if cut is not None and cut[1] < row[cut[2]]:
            row[cut[2]] = cut[1]
        if penalty is not None:
            row += penalty
        if beat_penalty is not None and bounds[k + 2] > bounds[k + 1]:
            part = slice(bounds[k + 1], bounds[k + 2])
            np.add.at(row, on[part], cost[part])
        if beat_class is not None and beat_class[k + 1] >= 0:
            row += class_cost[beat_class[k + 1]]
        if beat_target is not None and beat_target[k + 1] >= 0:
            row[beat_target[k + 1]] -= target_reward
        if not terms.every_step:
            reached = np.flatnonzero(np.isfinite(row))

    ok = (graph.capacity >= thc) & np.isfinite(costs[k_steps])
    if not ok.any():
        raise SynthesisError(
            f"no path through the '{graph.style}' graph for {k_steps} beats ending with capacity "
            f">= {thc}: the style's database is too small for this music; try another style")
    end = int(np.flatnonzero(ok)[np.argmin(costs[k_steps][ok])])
    # Backtrack: re-evaluate only the steps into each chosen node.
    nodes = np.empty(k_steps + 1, dtype=np.int64)
    vias = np.empty(k_steps, dtype=np.int64)
    jumped = np.empty(k_steps, dtype=bool)
    nodes[k_steps] = end
    for k in range(k_steps - 1, -1, -1):
        v = nodes[k + 1]
        m_sel = steps.mono_into[v:v + 1] if steps.mono_into[v] >= 0 else np.zeros(0, dtype=np.int64)
        j_sel = np.arange(steps.j_first[v], steps.j_last[v])
        cand = np.concatenate([terms.mono(k, costs[k], m_sel), terms.jump(k, costs[k], j_sel)])
        i = int(np.argmin(cand)) if cand.size else -1
        cut = _entry(graph, costs[k], terms, k, beat_target, entry, entry_cost)
        if cut is not None and cut[2] == v and (i < 0 or cut[1] < cand[i]):
            nodes[k], vias[k], jumped[k] = cut[0], graph.prev_node[v], True
        elif i < len(m_sel):
            nodes[k] = vias[k] = steps.m_src[m_sel[i]]
            jumped[k] = False
        else:
            e = j_sel[i - len(m_sel)]
            nodes[k], vias[k], jumped[k] = steps.j_src[e], steps.j_via[e], True
    return Path(nodes, vias, jumped, float(costs[k_steps][end]))


def _entry(graph: MetaMotionGraph, prev_cost: np.ndarray, terms: "BeatTerms", k: int, target, entry,
           entry_cost: float) -> tuple[int, float, int] | None:
    """The cut into beat ``k + 1``'s target, if allowed there: (from the cheapest node, at cost, into
    the target) by the target's own mono edge in."""
    if entry is None or not entry[k + 1] or target[k + 1] < 0:
        return None
    t = int(target[k + 1])
    via = int(graph.prev_node[t])
    src = int(np.argmin(prev_cost))
    if via < 0 or not np.isfinite(prev_cost[src]):
        return None
    return src, float(prev_cost[src] + terms.deviation[k][via] + entry_cost), t


class StepCosts:
    """The graph's steps split into mono steps and jumps, with the cost terms that do not depend
    on the music, and the steps into and out of each node. Built once per graph and
    configuration; a search's beats are priced by ``BeatTerms`` (no cache: a tracked song's
    beats all differ in length).
    """

    #: Relax every jump (reduceat over all) once the reached nodes' jumps are this share of them:
    #: the per-jump gather and minimum.at cost more than the dense pass from there on.
    DENSE_SHARE = 0.25
    #: Price every step of every beat at once (``BeatTerms``) up to this many (beats x jumps).
    EVERY_STEP_MAX = 1 << 18

    def __init__(self, graph: MetaMotionGraph, jump_cost: float = 0.0, accent: AccentCosts | None = None):
        jump = graph.step_jump
        m, j = np.flatnonzero(~jump), np.flatnonzero(jump)
        arrive = np.zeros(graph.n_nodes)
        played = np.zeros(graph.n_nodes)  # cost of playing the mono edge leaving a node
        self.warp = None
        if accent is not None and graph.node_accent is not None:
            arrive, played = accent.beat_costs(graph.node_accent, graph.edge_offbeat, graph.edge_slide)
            self.warp = accent.warp_cost
            self.log_s = np.log(np.maximum(graph.frames_to_next(), 1.0) / graph.fps)  # seconds each edge plays
        self.m_src, self.m_dst = graph.step_src[m], graph.step_dst[m]
        self.m_add = arrive[self.m_dst] + played[self.m_src]
        self.j_src, self.j_via, self.j_dst = graph.step_src[j], graph.step_via[j], graph.step_dst[j]
        self.j_rho, self.j_w2 = graph.step_rho[j], graph.step_w2[j]
        self.j_add = jump_cost + arrive[self.j_dst] + played[self.j_via]
        first = np.r_[True, self.j_dst[1:] != self.j_dst[:-1]] if j.size else np.zeros(0, bool)
        self.j_starts = np.flatnonzero(first)
        self.j_nodes = self.j_dst[self.j_starts]
        # Per node: its incoming mono step (or -1) and its run of incoming jumps.
        self.mono_into = np.full(graph.n_nodes, -1)
        self.mono_into[self.m_dst] = np.arange(len(self.m_dst))
        self.j_first = np.zeros(graph.n_nodes, dtype=np.int64)
        self.j_last = np.zeros(graph.n_nodes, dtype=np.int64)
        self.j_first[self.j_nodes] = self.j_starts
        self.j_last[self.j_nodes] = np.r_[self.j_starts[1:], len(self.j_dst)]
        # ... and its outgoing mono step (or -1) and jumps: the jumps by source, with each node's range.
        self.mono_from = np.full(graph.n_nodes, -1)
        self.mono_from[self.m_src] = np.arange(len(self.m_src))
        self.j_by_src = np.argsort(self.j_src, kind="stable")
        self.j_out = np.r_[0, np.cumsum(np.bincount(self.j_src, minlength=graph.n_nodes))]

    def leaving(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray | slice]:
        """The mono steps and jumps out of ``nodes`` (sorted, unique); all jumps (a slice) when that
        is most of them."""
        mono = self.mono_from[nodes]
        mono = mono[mono >= 0]
        first, count = self.j_out[nodes], self.j_out[nodes + 1] - self.j_out[nodes]
        total = int(count.sum())
        if total > self.DENSE_SHARE * len(self.j_src):
            return mono, slice(None)
        # The concatenated ranges first[i] .. first[i] + count[i] of the jumps by source.
        at = np.arange(total) + np.repeat(first - (np.cumsum(count) - count), count)
        return mono, self.j_by_src[at]


class BeatTerms:
    """What each step costs on each beat of one search, but for the cost of the path that reaches
    its source: eq. (4)'s intensity deviation (``deviation`` (K, N), per node's mono edge) with eq.
    (6)'s rate factor times w2 for a jump, the time warp of playing the edge in the beat's length,
    and the fixed costs of ``StepCosts``.

    On a small graph (K x jumps up to ``StepCosts.EVERY_STEP_MAX``) every step's terms for every
    beat are found at once, a few large array operations instead of many small ones a beat, and
    every step is relaxed. Else each beat's are found for the steps asked for. Forward pass and
    backtracking both take costs from ``mono`` and ``jump``, element by element the same
    operations either way, so backtracking reproduces the forward minimum exactly.
    """

    def __init__(self, steps: StepCosts, deviation: np.ndarray, durations_s: np.ndarray,
                 prev_durations_s: np.ndarray):
        self.steps, self.deviation = steps, deviation
        k_beats, n = deviation.shape
        # Eq. (6)'s ratio of each beat's length to the previous one's (-1: no previous beat).
        ratio = [d / p if p > 0 else np.nan for d, p in zip(durations_s, prev_durations_s)]
        self.ratio = np.array([-1.0 if not np.isfinite(r) else float(r) for r in ratio])
        if steps.warp is None:
            self.warp = np.zeros((k_beats, n))
        else:
            # ln of each beat's length, one by one (np.log of a scalar), against every edge's.
            self.warp = steps.warp(steps.log_s - np.array([[float(np.log(d))] for d in durations_s]))
        self.every_step = k_beats * len(steps.j_src) <= steps.EVERY_STEP_MAX
        if self.every_step:
            self._mono = steps.m_add + np.take(self.warp, steps.m_src, axis=1)
            self._jump = self._jump_terms(None, slice(None))

    def mono(self, k: int, prev_cost: np.ndarray, sel) -> np.ndarray:
        """Cost of arriving by mono steps ``sel`` on beat ``k``: eq. (4), first case."""
        s = self.steps
        src = s.m_src[sel]
        fixed = self._mono[k][sel] if self.every_step else s.m_add[sel] + self.warp[k][src]
        return (prev_cost[src] + self.deviation[k][src]) + fixed

    def jump(self, k: int, prev_cost: np.ndarray, sel) -> np.ndarray:
        """Cost of arriving by jumps ``sel`` and their mono edge on beat ``k``: eq. (4), second case."""
        terms = self._jump[k][sel] if self.every_step else self._jump_terms(k, sel)
        return prev_cost[self.steps.j_src[sel]] + terms

    def _jump_terms(self, k: int | None, sel) -> np.ndarray:
        """The terms of jumps ``sel`` on beat ``k`` (None: on every beat, (K, jumps))."""
        s = self.steps
        via, rho, w2 = s.j_via[sel], s.j_rho[sel], s.j_w2[sel]
        rows, ratio = (slice(None), self.ratio[:, None]) if k is None else (k, self.ratio[k])
        deviation, warp = np.take(self.deviation[rows], via, axis=-1), np.take(self.warp[rows], via, axis=-1)
        # s * w2, with s = 1 where there is no previous beat.
        factor = np.where(ratio < 0, w2, _rate_factor(rho, 1.0, np.where(ratio < 0, 1.0, ratio)) * w2)
        return deviation * factor + (s.j_add[sel] + warp)


def path_cost(graph: MetaMotionGraph, path: Path, intensity_z, durations_s, prev_duration_s=None) -> float:
    """Cost of a given path under eq. (4)-(6) (for tests and brute-force checks)."""
    total = 0.0
    prev_d = prev_duration_s
    f_next = graph.frames_to_next()
    for k in range(path.n_steps):
        i, j = path.nodes[k], path.via[k]
        c = abs(graph.w1_z[j] - intensity_z[k])
        if path.jump[k]:
            e = np.flatnonzero((graph.bi_src == i) & (graph.bi_dst == j))[0]
            p = graph.prev_node[i]
            rho = f_next[p] / f_next[j] if p >= 0 else np.nan
            s = _rate_factor(np.array([rho]), prev_d, durations_s[k])[0]
            c *= s * max(graph.bi_rd[e], graph.thr)
        total += c
        prev_d = durations_s[k]
    return total


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
           intensity_weight: float = 1.0) -> Path:
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

    for k in range(k_steps):
        # Eq. (8) for every destination at once. Mono steps have one destination each;
        # jumps are sorted by destination, so a reduceat takes each destination's best.
        dev = intensity_weight * np.abs(graph.w1_z - intensity_z[k])
        row = costs[k + 1]
        row[steps.m_dst] = steps.mono(costs[k], dev, durations_s[k])
        if steps.j_nodes.size:
            best = np.minimum.reduceat(steps.jump(costs[k], dev, prev[k], durations_s[k]), steps.j_starts)
            row[steps.j_nodes] = np.minimum(row[steps.j_nodes], best)
        if penalty is not None:
            row += penalty
        if beat_class is not None and beat_class[k + 1] >= 0:
            row += class_cost[beat_class[k + 1]]

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
        dev = intensity_weight * np.abs(graph.w1_z - intensity_z[k])
        v = nodes[k + 1]
        m_sel = steps.mono_into[v:v + 1] if steps.mono_into[v] >= 0 else np.zeros(0, dtype=np.int64)
        j_sel = np.arange(steps.j_first[v], steps.j_last[v])
        cand = np.r_[steps.mono(costs[k], dev, durations_s[k], m_sel),
                     steps.jump(costs[k], dev, prev[k], durations_s[k], j_sel)]
        i = int(np.argmin(cand))
        if i < len(m_sel):
            nodes[k] = vias[k] = steps.m_src[m_sel[i]]
            jumped[k] = False
        else:
            e = j_sel[i - len(m_sel)]
            nodes[k], vias[k], jumped[k] = steps.j_src[e], steps.j_via[e], True
    return Path(nodes, vias, jumped, float(costs[k_steps][end]))


class StepCosts:
    """The graph's steps split into mono steps and jumps, with their cost terms.

    Forward pass and backtracking evaluate costs through the same two methods, so the
    step chosen when backtracking reproduces the forward minimum exactly. The terms that
    depend only on the beat's length (time warp, eq. 6's rate factor) are computed once
    per distinct length and kept: a song's beat grid has few of them.
    """

    _KEEP = 256  # distinct beat lengths (or length ratios) remembered

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
        self._fixed: dict[float, tuple[np.ndarray, np.ndarray]] = {}
        self._factor: dict[float, np.ndarray] = {}

    def _fixed_terms(self, duration: float) -> tuple[np.ndarray, np.ndarray]:
        """Per mono step and per jump: the static costs plus the time warp of a beat this long."""
        got = self._fixed.get(duration)
        if got is None:
            if len(self._fixed) >= self._KEEP:
                self._fixed.clear()
            warp = np.zeros(len(self.mono_into))
            if self.warp is not None:
                warp = self.warp(self.log_s - np.log(duration))
            got = self._fixed[duration] = (self.m_add + warp[self.m_src], self.j_add + warp[self.j_via])
        return got

    def _rate_factors(self, prev_duration, duration) -> np.ndarray:
        """Eq. (6)'s s times the jump's w2, per jump."""
        ratio = duration / prev_duration if prev_duration is not None and prev_duration > 0 else np.nan
        key = -1.0 if not np.isfinite(ratio) else float(ratio)
        got = self._factor.get(key)
        if got is None:
            if len(self._factor) >= self._KEEP:
                self._factor.clear()
            got = self._factor[key] = _rate_factor(self.j_rho, None if key < 0 else 1.0, key) * self.j_w2
        return got

    def mono(self, prev_cost, dev, duration, sel=slice(None)):
        """Cost of arriving by mono steps ``sel``: eq. (4), first case."""
        return (prev_cost + dev)[self.m_src[sel]] + self._fixed_terms(duration)[0][sel]

    def jump(self, prev_cost, dev, prev_duration, duration, sel=slice(None)):
        """Cost of arriving by jumps ``sel`` and their mono edge: eq. (4), second case."""
        return prev_cost[self.j_src[sel]] + (dev[self.j_via[sel]] * self._rate_factors(prev_duration, duration)[sel]
                                             + self._fixed_terms(duration)[1][sel])


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


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


def _rate_factor(rho: np.ndarray, prev_duration: float | None, duration: float) -> np.ndarray:
    """Eq. (6): s = max(r1/r2, r2/r1) with r1/r2 = rho * duration / prev_duration."""
    if prev_duration is None or not prev_duration > 0:
        return np.ones_like(rho)
    x = rho * (duration / prev_duration)
    s = np.maximum(x, 1.0 / x)
    return np.where(np.isfinite(s), s, 1.0)


def search(graph: MetaMotionGraph, intensity_z: np.ndarray, durations_s: np.ndarray, *,
           start_nodes: np.ndarray, prev_duration_s: float | None = None, thc: float = np.inf,
           node_penalty: np.ndarray | None = None, jump_cost: float = 0.0) -> Path:
    """Best path for K beat intervals (eq. 7-9).

    ``intensity_z`` (K,) are the normalised music intensities, ``durations_s`` (K,)
    the beat intervals. The path starts at one of ``start_nodes`` (the previous
    segment's last node, or InitS) and ends at a node with capacity >= ``thc``.
    ``node_penalty`` (N,), if given, is added whenever a step arrives at a node (the
    streaming engine uses it to discourage replaying recent beats; not in the paper).
    ``jump_cost`` is added to every jump (0 in the paper, where a jump to a beat of
    exactly the music's intensity is free).
    """
    intensity_z = np.asarray(intensity_z, dtype=np.float64)
    durations_s = np.asarray(durations_s, dtype=np.float64)
    n, k_steps = graph.n_nodes, len(intensity_z)
    costs = np.full((k_steps + 1, n), np.inf)
    costs[0, np.asarray(start_nodes)] = 0.0
    src, via = graph.step_src, graph.step_via
    starts, dest = graph.group_starts, graph.group_nodes
    jumps = np.flatnonzero(graph.step_jump)
    rho_j, w2_j = graph.step_rho[jumps], graph.step_w2[jumps]
    arrive = None if node_penalty is None else np.asarray(node_penalty, dtype=np.float64)[graph.step_dst]
    prev = np.r_[np.nan if prev_duration_s is None else prev_duration_s, durations_s[:-1]]

    def step_terms(k: int, sel=slice(None)):
        """Eq. (4)-(6) edge costs of step k (for the steps ``sel``)."""
        term = np.abs(graph.w1_z - intensity_z[k])[via[sel]]
        is_jump = graph.step_jump[sel]
        if is_jump.any():
            j = np.searchsorted(jumps, np.arange(len(src))[sel][is_jump])
            term[is_jump] *= _rate_factor(rho_j[j], prev[k], durations_s[k]) * w2_j[j]
            term[is_jump] += jump_cost
        if arrive is not None:
            term += arrive[sel]
        return term

    for k in range(k_steps):
        # Eq. (8) for every destination at once: the steps are sorted by destination.
        term = np.abs(graph.w1_z - intensity_z[k])[via]
        term[jumps] *= _rate_factor(rho_j, prev[k], durations_s[k]) * w2_j
        term[jumps] += jump_cost
        if arrive is not None:
            term += arrive
        term += costs[k][src]
        if len(starts):
            costs[k + 1][dest] = np.minimum.reduceat(term, starts)

    ok = (graph.capacity >= thc) & np.isfinite(costs[k_steps])
    if not ok.any():
        raise SynthesisError(
            f"no path through the '{graph.style}' graph for {k_steps} beats ending with capacity "
            f">= {thc}: the style's database is too small for this music; try another style")
    end = int(np.flatnonzero(ok)[np.argmin(costs[k_steps][ok])])
    # Backtrack: re-evaluate only the steps into the chosen node (the first minimum wins,
    # as it would in a forward argmin).
    group_of_node = np.full(n, -1)
    group_of_node[dest] = np.arange(len(dest))
    ends = np.r_[starts[1:], len(src)]
    nodes = np.empty(k_steps + 1, dtype=np.int64)
    vias = np.empty(k_steps, dtype=np.int64)
    jumped = np.empty(k_steps, dtype=bool)
    nodes[k_steps] = end
    for k in range(k_steps - 1, -1, -1):
        g = group_of_node[nodes[k + 1]]
        sel = slice(starts[g], ends[g])
        e = starts[g] + int(np.argmin(costs[k][src[sel]] + step_terms(k, sel)))
        nodes[k], vias[k], jumped[k] = src[e], via[e], graph.step_jump[e]
    return Path(nodes, vias, jumped, float(costs[k_steps][end]))


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


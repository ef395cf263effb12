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
           node_penalty: np.ndarray | None = None) -> Path:
    """Best path for K beat intervals (eq. 7-9).

    ``intensity_z`` (K,) are the normalised music intensities, ``durations_s`` (K,)
    the beat intervals. The path starts at one of ``start_nodes`` (the previous
    segment's last node, or InitS) and ends at a node with capacity >= ``thc``.
    ``node_penalty`` (N,), if given, is added whenever a step arrives at a node (the
    streaming engine uses it to discourage replaying recent beats; not in the paper).
    """
    intensity_z = np.asarray(intensity_z, dtype=np.float64)
    durations_s = np.asarray(durations_s, dtype=np.float64)
    n, k_steps = graph.n_nodes, len(intensity_z)
    cost = np.full(n, np.inf)
    cost[np.asarray(start_nodes)] = 0.0
    back = np.full((k_steps, n), -1, dtype=np.int32)

    src, via = graph.step_src, graph.step_via
    w2, jump, rho = graph.step_w2, graph.step_jump, graph.step_rho
    starts, dest = graph.group_starts, graph.group_nodes
    group_of_step = np.repeat(np.arange(len(starts)), np.diff(np.r_[starts, len(src)]))
    w1z_via = graph.w1_z[via]
    arrive = 0.0 if node_penalty is None else np.asarray(node_penalty, dtype=np.float64)[graph.step_dst]
    prev_d = prev_duration_s
    for k in range(k_steps):
        factor = np.where(jump, _rate_factor(rho, prev_d, durations_s[k]) * w2, 1.0)
        step_cost = cost[src] + factor * np.abs(w1z_via - intensity_z[k]) + arrive
        best = np.minimum.reduceat(step_cost, starts) if len(starts) else np.zeros(0)
        # First step per destination reaching the minimum = the argmin of eq. (8).
        hit = np.flatnonzero(step_cost <= best[group_of_step])
        first = hit[np.r_[True, group_of_step[hit[1:]] != group_of_step[hit[:-1]]]] if hit.size else hit
        cost = np.full(n, np.inf)
        cost[dest] = best
        back[k, dest[group_of_step[first]]] = first
        prev_d = durations_s[k]

    ok = (graph.capacity >= thc) & np.isfinite(cost)
    if not ok.any():
        raise SynthesisError(
            f"no path through the '{graph.style}' graph for {k_steps} beats ending with capacity "
            f">= {thc}: the style's database is too small for this music; try another style")
    end = int(np.flatnonzero(ok)[np.argmin(cost[ok])])
    total = float(cost[end])
    nodes = np.empty(k_steps + 1, dtype=np.int64)
    vias = np.empty(k_steps, dtype=np.int64)
    jumps = np.empty(k_steps, dtype=bool)
    nodes[k_steps] = end
    for k in range(k_steps - 1, -1, -1):
        e = back[k, nodes[k + 1]]
        nodes[k], vias[k], jumps[k] = src[e], via[e], jump[e]
    return Path(nodes, vias, jumps, total)


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


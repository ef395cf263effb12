"""Meta motion graphs (Xu, Takagi & Kawada, §3.2).

Nodes are the beat frames of one style. Two successive beat frames of a clip are
joined by a *mono-directional* edge weighted by the motion intensity between them
(total kinetic energy). Two similar beat frames are joined by a *bi-directional*
edge when, by eq. (1),

    rd = d(i, j) / (d(i-1, i+1) + d(j-1, j+1)) < THS,

with the frame distance of eq. (3), ``d = sum_m w_m ||log(q_j,m^-1 q_i,m)||^2``; its
weight is ``w2 = max(rd, THR)`` (eq. 2). A bi-directional edge takes no time and is
always followed by a mono-directional edge, so the graph the search walks has one
*step* per music beat: a mono edge, or a jump plus the mono edge after it.

Each node carries its *synchronization capacity* (node weight): 0 for an end node,
infinite for a node that can reach a cycle, otherwise 1 + the best successor, in
beats.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components

from ... import rotations as rot
from ...motion.accents import cached_accent_beats, fast_beats, limb_turns
from ...motion.database import Style
from ...errors import InputError

GRAPH_FORMAT_VERSION = 1


@dataclass(frozen=True)
class GraphConfig:
    """Parameters of graph construction; paper values where the paper gives them."""

    ths: float = 3.0            # eq. (1): bi-directional edge when rd < THS (paper: 3.0)
    neighbour_s: float = 1 / 30  # eq. (1)'s "t-1, t+1": neighbouring frames at 30 fps, the rate motion
                                 # graphs are usually built at (the paper does not state its rate)
    thr: float = 1.5            # eq. (2): floor of the bi-directional weight, must be > 1
    max_jumps_per_beat: int = 32  # keep a beat's most similar partners only (mutual nearest
                                  # neighbours; 0 = no limit, the paper)
    min_jump_beats: int = 4     # no jump between beats of one clip closer than this (0 = paper);
                                # stops the search looping on one beat
    close_dead_ends: bool = True  # if no start node can go on forever, give every end node
                                  # its most similar beat as an extra edge (see build_graph)
    max_joint_speed_deg_s: float = 1500.0  # beat intervals where a limb turns faster than this
                                           # hold capture glitches (wrist flips) and are not played
    calm_jumps: float = 99.0        # no jump at a beat where a joint turns faster than this percentile of
                                    # the style's fastest-joint speeds (0 = off, the paper): no blend can
                                    # carry a velocity like that within its limits, so it shows as a pop
    prune_trap_cycles: bool = True  # drop steps into small cycles the main cycle cannot be reached
                                    # from (a dance that enters one loops there forever; see derive_steps)
    accent_window: float = 0.0      # render each beat at its most visible stop within this fraction of a
                                    # beat (motion.accents; 0 = the motion beats themselves, the paper).
                                    # Off: with the renderer's accent timing (timing.ease) it added no
                                    # accents, and its uneven pieces cost playback rates and transitions.

    @classmethod
    def paper(cls) -> "GraphConfig":
        """Eq. (1)-(3) as printed: literal neighbouring frames, no limits on jumps."""
        return cls(neighbour_s=0.0, max_jumps_per_beat=0, min_jump_beats=0, prune_trap_cycles=False,
                   accent_window=0.0, calm_jumps=0.0)

    def __post_init__(self):
        if not self.thr > 1.0:
            raise InputError("THR must be larger than 1")
        if not self.ths > 0:
            raise InputError("THS must be positive")

    def key(self) -> str:
        return repr(sorted(asdict(self).items()))


@dataclass(eq=False)
class MetaMotionGraph:
    """Arrays of one meta motion graph. Node ``i`` is the beat at flat frame ``node_frame[i]``."""

    style: str
    fps: float
    node_frame: np.ndarray      # (N,) int64
    node_clip: np.ndarray       # (N,) int64
    next_node: np.ndarray       # (N,) successor beat in the same clip, -1 at a clip's last beat
    prev_node: np.ndarray       # (N,) predecessor beat, -1 at a clip's first beat
    w1: np.ndarray              # (N,) intensity of the mono edge leaving the node (nan if none)
    w1_z: np.ndarray            # (N,) standard score of w1 (0 if none)
    bi_src: np.ndarray          # (E2,) directed bi-directional edges (both directions stored)
    bi_dst: np.ndarray
    bi_rd: np.ndarray           # (E2,) eq. (1) ratio
    capacity: np.ndarray        # (N,) float, np.inf for "can go on forever"
    init_nodes: np.ndarray      # first beat of every clip (InitS)
    thr: float = 1.5            # THR the graph was built with
    n_forced: int = 0           # bi-directional edges added by close_dead_ends
    n_trapped: int = 0          # beats of trap cycles no step leads into any more (prune_trap_cycles)
    # One step = optional jump + mono edge, sorted by destination for the search.
    step_src: np.ndarray = None
    step_via: np.ndarray = None
    step_dst: np.ndarray = None
    step_w2: np.ndarray = None     # 1 for a plain mono step, w2 for a jump
    step_jump: np.ndarray = None   # bool
    step_rho: np.ndarray = None    # frames(prev(src)->src) / frames(via->dst); nan if src starts a clip
    group_starts: np.ndarray = None  # start of each destination's run of steps
    group_nodes: np.ndarray = None   # destination node of each run
    # Visible accents (motion.accents): the frame each beat is rendered at, how clearly the
    # motion stops there (1 = the style's median stop, 0 = none), and how much it stops between
    # the node and its successor. None in hand-made graphs: render node_frame, no accent costs.
    node_accent_frame: np.ndarray = None
    node_accent: np.ndarray = None
    edge_offbeat: np.ndarray = None
    edge_slide: np.ndarray = None   # how much the piece to the successor slides its feet (1 = the style's mean)

    @property
    def n_nodes(self) -> int:
        return len(self.node_frame)

    @property
    def n_bi_edges(self) -> int:
        """Undirected bi-directional edges."""
        return len(self.bi_src) // 2

    @property
    def mean_in_degree(self) -> float:
        """D of the paper: mean number of steps entering a node."""
        return len(self.step_dst) / max(self.n_nodes, 1)

    @property
    def render_frame(self) -> np.ndarray:
        """(N,) the source frame shown on the music beat: the beat's visible stop."""
        return self.node_frame if self.node_accent_frame is None else self.node_accent_frame

    def frames_to_next(self) -> np.ndarray:
        """(N,) source frames the mono edge leaving each node plays (0 at a clip's last beat)."""
        nxt = self.next_node
        out = np.zeros(self.n_nodes)
        ok = nxt >= 0
        out[ok] = self.render_frame[nxt[ok]] - self.render_frame[ok]
        return out

    def shown_intensity_z(self, durations_s) -> np.ndarray:
        """(K, N) each node's mono-edge intensity as shown in beats of ``durations_s``, standardised
        against the style's own: each piece at its captured speed.

        A piece of L source seconds played in a beat of d seconds moves L / d times as fast, so it shows
        the kinetic power ``(w1 / L) (L / d)^2``. ``w1_z`` standardises against the pieces' own spread
        only, so on a song faster than the style the whole range of the style's moves shows up faster
        than captured (a 160 bpm song in a 141 bpm style: every move at 1.13x, the style's fastest
        ones faster than the mocap ever is); standardised against the power each piece shows at its
        own tempo, the intensity match picks calmer pieces there and livelier ones on a slow song,
        so the dance shows the style's own range of power."""
        d = np.asarray(durations_s, dtype=np.float64)[:, None]
        length = self.frames_to_next() / self.fps
        has = (length > 0) & np.isfinite(self.w1)
        own = self.w1[has] / length[has]   # the power each piece shows at its own tempo
        if own.size < 2 or not own.std() > 0:
            return np.tile(self.w1_z, (d.shape[0], 1))
        out = np.zeros((d.shape[0], self.n_nodes))
        out[:, has] = (self.w1[has] * length[has] / np.maximum(d, 1e-6) ** 2 - own.mean()) / own.std()
        return out

    def arrays(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if isinstance(v, np.ndarray)}


def joint_weights(style: Style) -> np.ndarray:
    """w(m) of eq. (3), normalised: a joint weighs the bone length of its subtree (the bone into
    the joint included), and the root as much as all the other joints together.

    A hip or spine rotation moves most of the body, a finger almost nothing. The root's
    rotation (its heading removed: how the body leans and tilts) is half of the distance,
    so two beats whose limbs match but whose bodies lean differently are far apart: a jump
    between them would swing the whole body. (The paper leaves w(m) to its reference [9].)
    Joints that never move get weight 0 and are skipped.
    """
    sk = style.skeleton
    subtree = np.linalg.norm(sk.offsets, axis=1)
    for j in range(sk.n_joints - 1, 0, -1):
        subtree[sk.parents[j]] += subtree[j]
    subtree[0] = subtree[1:].sum()
    moving = np.any(np.abs(style.local_rot - style.local_rot[:1]) > 1e-5, axis=(0, 2))
    w = np.where(moving, subtree, 0.0)
    return w / max(w.sum(), 1e-12)


def rotation_glitches(style: Style, limit_deg_s: float, turns: np.ndarray | None = None) -> np.ndarray:
    """(F-1,) True where some joint that moves a limb turns faster than ``limit_deg_s``
    between frame f and f+1 (a capture glitch such as a wrist flip, not a movement).
    ``turns``: ``limb_turns(style)`` if the caller has it already."""
    return (limb_turns(style) if turns is None else turns) > np.radians(limit_deg_s) / style.fps


def _poses(style: Style, frames: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """Local joint rotations at ``frames``, the root's heading removed (jumps re-align it)."""
    q = style.local_rot[frames][:, joints].astype(np.float64)
    if joints[0] == 0:
        root = q[:, 0]
        q[:, 0] = rot.mul(rot.about_y(-rot.heading(root)), root)
    return q


def _distance(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Eq. (3) between paired poses: sum_m w_m * (geodesic angle)^2."""
    return np.sum(w * rot.angle(a, b) ** 2, axis=-1)


class _SimilarityRows:
    """Eq. (1) ratios ``rd`` for a block of rows at a time, so memory stays O(rows x N)."""

    def __init__(self, style: Style, frames: np.ndarray, clip: np.ndarray, config: GraphConfig):
        w = joint_weights(style)
        joints = np.flatnonzero(w > 0)
        if joints.size == 0:
            joints, w = np.array([0]), np.ones(1)
        self.w = w[joints]
        lo = style.clip_starts[clip]
        hi = style.clip_starts[clip + 1] - 1
        step = max(1, int(round(config.neighbour_s * style.fps)))  # 0 s: the adjacent frames
        before = _poses(style, np.clip(frames - step, lo, hi), joints)
        after = _poses(style, np.clip(frames + step, lo, hi), joints)
        self.local = _distance(before, after, self.w)
        self.q = _poses(style, frames, joints)
        self.q32 = self.q.astype(np.float32)
        self.clip = clip
        self.min_gap = max(config.min_jump_beats, 1)

    def block_rows(self, budget_bytes: float = 64e6) -> int:
        """Rows per block so that one block's temporaries stay near ``budget_bytes``."""
        per_row = len(self.q) * self.q.shape[1] * 4 * 3
        return int(max(1, min(1024, budget_bytes // max(per_row, 1))))

    def __call__(self, rows: np.ndarray, *, allow_near: bool = False) -> np.ndarray:
        dots = np.abs(np.einsum("ajk,bjk->abj", self.q32[rows], self.q32))
        np.minimum(dots, 1.0, out=dots)
        ang = np.arccos(dots, out=dots)
        np.square(ang, out=ang)
        d = (ang @ (4.0 * self.w).astype(np.float32)).astype(np.float64)
        rd = d / np.maximum(self.local[rows, None] + self.local[None, :], 1e-12)
        idx = np.arange(len(self.q))
        gap = 1 if allow_near else self.min_gap
        near = (self.clip[rows, None] == self.clip[None, :]) & (np.abs(rows[:, None] - idx[None, :]) < gap)
        rd[near] = np.inf
        return rd


def build_graph(style: Style, config: GraphConfig = GraphConfig()) -> MetaMotionGraph:
    """Build the meta motion graph of one style (nodes, edges, weights, capacities)."""
    frames = np.asarray(style.beat_frames, dtype=np.int64)
    clip = style.clip_of_frame(frames)
    n = len(frames)
    # Everything below is measured where the dance is cut and shown: at each beat's visible stop
    # (the beat frame itself when accent_window is 0).
    accents = cached_accent_beats(style, window=config.accent_window)
    shown = np.asarray(accents.frame, dtype=np.int64)
    same_next = np.r_[clip[1:] == clip[:-1], False]
    turns = limb_turns(style)  # the glitch filter and the calm jumps both need it: measured once
    if n > 1 and np.isfinite(config.max_joint_speed_deg_s):
        glitch = np.r_[rotation_glitches(style, config.max_joint_speed_deg_s, turns), False]
        cum_glitch = np.concatenate([[0], np.cumsum(glitch)])
        same_next[:-1] &= cum_glitch[shown[1:]] == cum_glitch[shown[:-1]]
    next_node = np.where(same_next, np.arange(n) + 1, -1)
    prev_node = np.full(n, -1)
    prev_node[next_node[next_node >= 0]] = np.flatnonzero(next_node >= 0)

    # Mono-directional edges: total kinetic energy between successive beats (J*s), as rendered:
    # from one visible stop to the next.
    cum = np.concatenate([[0.0], np.cumsum(style.energy, dtype=np.float64)])
    w1 = np.full(n, np.nan)
    has = next_node >= 0
    w1[has] = (cum[shown[next_node[has]]] - cum[shown[has]]) / style.fps
    # What the search matches with the music is the energy a viewer sees on the beat. A piece of L
    # source seconds played in a beat of d seconds shows w1 * L / d (speeds scale by L / d, time by
    # d / L); d is the music's and the same for every node, so nodes rank by w1 * L. (The paper's
    # pieces all last about a beat; pieces between visible stops vary more.)
    shown_w1 = w1 * (np.r_[shown[1:] - shown[:-1], 0] / style.fps)
    w1_z = np.zeros(n)
    if has.sum() > 1 and np.std(shown_w1[has]) > 0:
        w1_z[has] = (shown_w1[has] - shown_w1[has].mean()) / shown_w1[has].std()

    # Bi-directional edges, eq. (1)-(3), a block of rows at a time.
    rd_rows = _SimilarityRows(style, shown, clip, config)
    src_l, dst_l, rd_l = [], [], []
    block = rd_rows.block_rows()
    m = config.max_jumps_per_beat
    for s in range(0, n, block):
        rows = np.arange(s, min(s + block, n))
        rd = rd_rows(rows)
        if 0 < m < n:
            # Keep each beat's m most similar candidates (then only mutual pairs, below).
            cut = np.partition(rd, m - 1, axis=1)[:, m - 1:m]
            rd[rd > cut] = np.inf
        r, c = np.nonzero(rd < config.ths)
        src_l.append(rows[r])
        dst_l.append(c)
        rd_l.append(rd[r, c])
    src, dst, rd_e = np.concatenate(src_l), np.concatenate(dst_l), np.concatenate(rd_l)
    if 0 < m < n:
        # An edge is bi-directional: keep it when each end is among the other's m best.
        # This also stops one beat with a large local motion (a small eq. (1) ratio to
        # everything) from joining the whole graph.
        mutual = np.isin(dst * n + src, src * n + dst)
        src, dst, rd_e = src[mutual], dst[mutual], rd_e[mutual]
    if config.calm_jumps > 0:
        fast = fast_beats(style, shown, config.calm_jumps, turns)
        calm = ~(fast[src] | fast[dst])
        src, dst, rd_e = src[calm], dst[calm], rd_e[calm]

    graph = MetaMotionGraph(
        style=style.name, fps=style.fps, node_frame=frames, node_clip=clip, next_node=next_node,
        prev_node=prev_node, w1=w1, w1_z=w1_z, bi_src=src, bi_dst=dst, bi_rd=rd_e.astype(np.float64),
        capacity=np.zeros(n), init_nodes=np.flatnonzero(np.r_[True, clip[1:] != clip[:-1]]), thr=config.thr)
    graph.node_accent_frame, graph.node_accent, graph.edge_offbeat = accents.frame, accents.strength, accents.offbeat
    graph.edge_slide = accents.slide
    derive_steps(graph, config.prune_trap_cycles)

    if config.close_dead_ends and not np.isinf(graph.capacity[graph.init_nodes]).any():
        # No start can go on forever (a tiny database without cycles): link every dead end
        # to its most similar beat that has a successor, so long songs still find a path.
        ends = np.flatnonzero(next_node < 0)
        if has.any() and len(ends):
            rd = rd_rows(ends, allow_near=True)[:, has]
            best = np.flatnonzero(has)[np.argmin(rd, axis=1)]
            ok = np.isfinite(rd.min(axis=1))
            ends, best, best_rd = ends[ok], best[ok], rd.min(axis=1)[ok]
            graph.bi_src = np.r_[graph.bi_src, ends, best]
            graph.bi_dst = np.r_[graph.bi_dst, best, ends]
            graph.bi_rd = np.r_[graph.bi_rd, best_rd, best_rd]
            graph.n_forced = len(ends)
            derive_steps(graph, config.prune_trap_cycles)
    return graph


def derive_steps(g: MetaMotionGraph, prune_traps: bool = False) -> None:
    """Derive the step list (sorted by destination) and the capacities from nodes and edges.

    With ``prune_traps``, steps into *trap cycles* are dropped: strongly connected
    beats from which the graph's main cycle (its largest strongly connected
    component) cannot be reached. Xu's capacity calls every node that reaches some
    cycle infinite, so the search may enter a 4-beat loop and, with no way out,
    dance it for the rest of the song. Motion graphs are usually cut to their
    largest strongly connected component (Kovar et al. 2002); we keep every beat
    that can still reach it, so dead-end tails stay usable near a song's end.
    """
    n = g.n_nodes
    mono = np.flatnonzero(g.next_node >= 0)
    usable = g.next_node[g.bi_dst] >= 0  # a jump must be followed by a mono edge
    jsrc, jvia = g.bi_src[usable], g.bi_dst[usable]
    src = np.r_[mono, jsrc]
    via = np.r_[mono, jvia]
    dst = g.next_node[via]
    w2 = np.r_[np.ones(len(mono)), np.maximum(g.bi_rd[usable], g.thr)]
    jump = np.r_[np.zeros(len(mono), bool), np.ones(len(jsrc), bool)]
    g.n_trapped = 0
    if prune_traps:
        trapped = trap_nodes(n, src, dst)
        keep = ~trapped[dst]
        src, via, dst, w2, jump = src[keep], via[keep], dst[keep], w2[keep], jump[keep]
        g.n_trapped = int(trapped.sum())
    f_next = g.frames_to_next()
    prev = g.prev_node[src]
    rho = np.full(len(src), np.nan)
    okp = prev >= 0
    rho[okp] = f_next[prev[okp]] / f_next[via[okp]]
    order = np.argsort(dst, kind="stable")
    g.step_src, g.step_via, g.step_dst = src[order], via[order], dst[order]
    g.step_w2, g.step_jump, g.step_rho = w2[order], jump[order], rho[order]
    starts = np.flatnonzero(np.r_[True, g.step_dst[1:] != g.step_dst[:-1]]) if len(dst) else np.zeros(0, int)
    g.group_starts = starts
    g.group_nodes = g.step_dst[starts] if len(dst) else np.zeros(0, int)
    g.capacity = synchronization_capacity(n, g.step_src, g.step_dst)


def _cyclic(n_nodes: int, src: np.ndarray, dst: np.ndarray):
    """Strong components of a step graph: (csr adjacency, label per node, whether each node is on a cycle)."""
    adj = coo_matrix((np.ones(len(src)), (src, dst)), shape=(n_nodes, n_nodes)).tocsr()
    n_comp, label = connected_components(adj, directed=True, connection="strong")
    cyclic = np.bincount(label, minlength=n_comp)[label] > 1
    cyclic[src[src == dst]] = True
    return adj, label, cyclic


def _reaching(adj, n_nodes: int, seeds: np.ndarray) -> np.ndarray:
    """(N,) True for every node from which one of ``seeds`` can be reached (seeds included)."""
    out = np.zeros(n_nodes, bool)
    if not len(seeds):
        return out
    radj = adj.T.tocoo()
    super_src = n_nodes  # a virtual node pointing to every seed
    aug = coo_matrix((np.ones(len(seeds) + radj.nnz), (np.r_[np.full(len(seeds), super_src), radj.row],
                                                       np.r_[seeds, radj.col])),
                     shape=(n_nodes + 1, n_nodes + 1)).tocsr()
    reached = breadth_first_order(aug, super_src, directed=True, return_predecessors=False)
    out[reached[reached < n_nodes]] = True
    return out


def trap_nodes(n_nodes: int, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """(N,) True for nodes on a cycle from which the largest strongly connected component is out of reach."""
    src = np.asarray(src, dtype=np.int64)
    dst = np.asarray(dst, dtype=np.int64)
    if n_nodes == 0 or not len(src):
        return np.zeros(n_nodes, bool)
    adj, label, cyclic = _cyclic(n_nodes, src, dst)
    if not cyclic.any():
        return np.zeros(n_nodes, bool)
    sizes = np.bincount(label[cyclic])
    main = np.flatnonzero(label == int(np.argmax(sizes)))
    return cyclic & ~_reaching(adj, n_nodes, main)


def synchronization_capacity(n_nodes: int, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Capacity of every node of a step graph (edges ``src -> dst``), in beats.

    Properties (1)-(4) of §3.2: an end node has 0; a node that can reach a cycle has
    infinity; otherwise a node has 1 + the largest capacity among its successors.
    """
    src = np.asarray(src, dtype=np.int64)
    dst = np.asarray(dst, dtype=np.int64)
    cap = np.zeros(n_nodes)
    if n_nodes == 0:
        return cap
    adj, _, cyclic = _cyclic(n_nodes, src, dst)
    # Everything that can reach a cyclic node can go on forever.
    forever = _reaching(adj, n_nodes, np.flatnonzero(cyclic))
    cap[forever] = np.inf
    # The rest is a DAG: relax longest-path-to-a-sink until nothing changes.
    finite_edges = ~forever[src]
    fs, fd = src[finite_edges], dst[finite_edges]
    for _ in range(n_nodes + 1):
        new = cap.copy()
        np.maximum.at(new, fs, cap[fd] + 1)
        if np.array_equal(new, cap):
            break
        cap = new
    return cap

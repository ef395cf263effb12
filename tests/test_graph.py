"""Meta motion graph: capacity on hand-made graphs, the DP against brute force, construction."""

from __future__ import annotations


import numpy as np
import pytest

from dancesynth.engines.graph.meta_graph import (GraphConfig, MetaMotionGraph, build_graph, derive_steps,
                                                 synchronization_capacity, trap_nodes)
from dancesynth.engines.graph.search import Path, path_cost, search
from dancesynth.errors import SynthesisError

INF = np.inf


# --- synchronization capacity on step graphs with known answers -------------------------------

@pytest.mark.parametrize("n, edges, expected", [
    (3, [(0, 1), (1, 2)], [2, 1, 0]),                                 # a chain ending in a dead end
    (1, [], [0]),                                                     # a lone end node
    (4, [(0, 1), (1, 2), (2, 0), (3, 0)], [INF, INF, INF, INF]),      # a cycle and a node leading into it
    (4, [(0, 1), (1, 2), (1, 3), (3, 1)], [INF, INF, 0, INF]),        # a dead-end branch beside a cycle
    (3, [(0, 0), (1, 0), (2, 1)], [INF, INF, INF]),                   # a self-loop is a cycle
    (5, [(0, 1), (0, 2), (2, 3), (3, 4)], [3, 0, 2, 1, 0]),           # the longer branch counts
    (6, [(0, 1), (1, 2), (3, 4), (4, 3), (5, 0), (5, 3)], [2, 1, 0, INF, INF, INF]),
])
def test_capacity_on_hand_made_graphs(n, edges, expected):
    src = np.array([e[0] for e in edges], dtype=int)
    dst = np.array([e[1] for e in edges], dtype=int)
    assert synchronization_capacity(n, src, dst).tolist() == expected


def tiny_graph(clips: list[int], bi: list[tuple[int, int, float]], w1_z, thr: float = 1.5) -> MetaMotionGraph:
    """A graph from clip lengths (in beats), undirected bi-edges (i, j, rd) and mono-edge intensities."""
    clip = np.concatenate([np.full(n, c) for c, n in enumerate(clips)])
    n = len(clip)
    frames = np.arange(n) * 10 + clip * 1000
    nxt = np.where(np.r_[clip[1:] == clip[:-1], False], np.arange(n) + 1, -1)
    prev = np.full(n, -1)
    prev[nxt[nxt >= 0]] = np.flatnonzero(nxt >= 0)
    src = np.array([b[0] for b in bi] + [b[1] for b in bi], dtype=int)
    dst = np.array([b[1] for b in bi] + [b[0] for b in bi], dtype=int)
    rd = np.array([b[2] for b in bi] * 2, dtype=float)
    w1 = np.asarray(w1_z, dtype=float)
    g = MetaMotionGraph(style="tiny", fps=30.0, node_frame=frames, node_clip=clip, next_node=nxt, prev_node=prev,
                        w1=w1, w1_z=np.where(nxt >= 0, w1, 0.0), bi_src=src, bi_dst=dst, bi_rd=rd,
                        capacity=np.zeros(n), init_nodes=np.flatnonzero(np.r_[True, clip[1:] != clip[:-1]]), thr=thr)
    derive_steps(g)
    return g


def test_capacity_counts_a_jump_and_its_mono_edge_as_one_beat():
    # Clip A: 0 -> 1 -> 2 (end). Clip B: 3 -> 4 (end). Jump 2 ~ 3 then mono 3 -> 4.
    g = tiny_graph([3, 2], [(2, 3, 1.0)], [0, 0, 0, 0, 0])
    # From 2: jump to 3 and walk to 4 = 1 beat; from 4 there is no mono edge and no usable jump.
    assert g.capacity.tolist() == [3, 2, 1, 1, 0]


def test_capacity_of_a_loop_through_a_jump_is_infinite():
    # Clip 0..3; jump from the end (3) back to 0 closes a loop.
    g = tiny_graph([4], [(3, 0, 1.0)], [0, 0, 0, 0])
    assert np.isinf(g.capacity).all()


@pytest.mark.parametrize("n, edges, trapped", [
    (6, [(0, 1), (1, 2), (2, 0), (2, 3), (3, 4), (4, 3)], [3, 4]),    # a 2-beat loop with no way back
    (6, [(0, 1), (1, 2), (2, 0), (2, 3), (3, 4), (4, 3), (4, 0)], []),  # ... with a way back: not a trap
    (5, [(0, 1), (1, 2), (2, 0), (2, 3), (3, 3), (1, 4)], [3]),       # a self-loop off the main cycle
    (3, [(0, 1), (1, 2)], []),                                        # no cycle at all
])
def test_trap_cycles_are_the_loops_that_never_lead_back(n, edges, trapped):
    src, dst = np.array(edges).T
    assert np.flatnonzero(trap_nodes(n, src, dst)).tolist() == trapped


def test_a_search_never_enters_a_trap_cycle():
    # Clip 0..5 loops (5 ~ 0); beat 2 jumps to clip 6..7, whose end jumps back to its start: the
    # step 7 -> (6) -> 7 is a one-beat trap. Its low intensity matches the music (0) better than the
    # main loop's (1), so an unpruned search dives in and stays.
    bi = [(5, 0, 1.0), (2, 6, 1.0), (7, 6, 1.0)]
    w1 = [1, 1, 1, 1, 1, 1, 0, 0]
    free = tiny_graph([6, 2], bi, w1)
    free_path = search(free, np.zeros(12), np.full(12, 0.5), start_nodes=np.array([0]), thc=INF)
    assert set(free_path.nodes[-4:].tolist()) <= {6, 7}
    g = tiny_graph([6, 2], bi, w1)
    derive_steps(g, prune_traps=True)
    assert g.n_trapped == 1 and np.isinf(g.capacity[:6]).all()
    path = search(g, np.zeros(12), np.full(12, 0.5), start_nodes=np.array([0]), thc=INF)
    assert not set(path.nodes.tolist()) & {6, 7}


def test_bundled_graphs_have_no_trap_left(bundled_db):
    trapped = nodes = 0
    for style in bundled_db.styles.values():
        g = build_graph(style)
        assert not trap_nodes(g.n_nodes, g.step_src, g.step_dst).any(), style.name
        trapped, nodes = trapped + g.n_trapped, nodes + g.n_nodes
        assert build_graph(style, GraphConfig.paper()).n_trapped == 0     # the paper's graph keeps them
    assert trapped < 0.05 * nodes  # pruning loses a few beats of small loops, never a real part of a style


# --- the DP against brute force ----------------------------------------------------------------

def brute_force(g: MetaMotionGraph, intensity, durations, start_nodes, thc, prev_d=None):
    best = (np.inf, None)
    steps = list(zip(g.step_src, g.step_via, g.step_dst, g.step_jump))
    by_src = {}
    for s in steps:
        by_src.setdefault(int(s[0]), []).append(s)
    k_steps = len(intensity)

    def walk(nodes, vias, jumps):
        nonlocal best
        if len(vias) == k_steps:
            if g.capacity[nodes[-1]] >= thc:
                p = Path(np.array(nodes), np.array(vias), np.array(jumps, bool), 0.0)
                c = path_cost(g, p, intensity, durations, prev_d)
                if c < best[0] - 1e-12:
                    best = (c, p)
            return
        for _, via, dst, jump in by_src.get(nodes[-1], []):
            walk(nodes + [int(dst)], vias + [int(via)], jumps + [bool(jump)])

    for s in start_nodes:
        walk([int(s)], [], [])
    return best


@pytest.mark.parametrize("seed", range(12))
def test_dp_matches_brute_force_on_tiny_graphs(seed):
    rng = np.random.default_rng(seed)
    clips = list(rng.integers(2, 5, size=rng.integers(2, 4)))
    n = sum(clips)
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)]
    chosen = rng.choice(len(pairs), size=min(len(pairs), rng.integers(2, 7)), replace=False)
    bi = [(pairs[c][0], pairs[c][1], float(rng.uniform(0.2, 3.0))) for c in chosen]
    g = tiny_graph(clips, bi, rng.normal(size=n))
    k_steps = int(rng.integers(2, 6))
    inten = rng.normal(size=k_steps)
    durs = rng.uniform(0.4, 0.6, size=k_steps)
    prev_d = float(rng.uniform(0.4, 0.6))
    for start, thc in [(g.init_nodes, 0.0), (g.init_nodes, np.inf), (np.array([int(rng.integers(n))]), 1.0)]:
        expected, exp_path = brute_force(g, inten, durs, start, thc, prev_d)
        if exp_path is None:
            with pytest.raises(SynthesisError):
                search(g, inten, durs, start_nodes=start, prev_duration_s=prev_d, thc=thc)
            continue
        got = search(g, inten, durs, start_nodes=start, prev_duration_s=prev_d, thc=thc)
        assert got.cost == pytest.approx(expected, abs=1e-9)
        assert path_cost(g, got, inten, durs, prev_d) == pytest.approx(expected, abs=1e-9)
        assert g.capacity[got.nodes[-1]] >= thc
        assert got.nodes[0] in set(start.tolist())


def test_dp_prefers_the_mono_edge_whose_intensity_matches_the_music():
    # Two clips of 3 beats: clip 0 is calm, clip 1 energetic, connected at their starts.
    g = tiny_graph([3, 3], [(0, 3, 1.0)], [-1.0, -1.0, 0.0, 1.0, 1.0, 0.0])
    loud = search(g, np.array([1.0, 1.0]), np.array([0.5, 0.5]), start_nodes=np.array([0]), thc=0)
    quiet = search(g, np.array([-1.0, -1.0]), np.array([0.5, 0.5]), start_nodes=np.array([0]), thc=0)
    assert loud.jump[0] and loud.nodes.tolist() == [0, 4, 5]
    assert not quiet.jump.any() and quiet.nodes.tolist() == [0, 1, 2]


def test_dp_reports_no_path_clearly():
    g = tiny_graph([2], [], [0.0, 0.0])
    with pytest.raises(SynthesisError, match="no path"):
        search(g, np.zeros(3), np.full(3, 0.5), start_nodes=g.init_nodes)


def test_rate_change_factor_penalises_jumps_between_different_tempi():
    # Node 1 is reached after a 10-frame interval; the jump target's interval has 20 frames.
    g = tiny_graph([3, 3], [(1, 3, 1.0)], [0.5, 0.5, 0.0, 0.5, 0.5, 0.0])
    g.node_frame[3:] = 1000 + np.arange(3) * 20
    derive_steps(g)
    p = Path(np.array([1, 4]), np.array([3]), np.array([True]), 0.0)
    # r1 = 10 frames / 0.5 s, r2 = 20 frames / 0.5 s -> s = 2; cost = s * max(rd, THR) * |0.5 - 0|
    assert path_cost(g, p, np.array([0.0]), np.array([0.5]), 0.5) == pytest.approx(2 * 1.5 * 0.5)


# --- construction on real data ------------------------------------------------------------------

def test_graph_of_the_bundled_styles_keeps_every_start_alive(bundled_db):
    for style in bundled_db.styles.values():
        g = build_graph(style)
        assert g.n_nodes == len(style.beat_frames)
        assert np.isinf(g.capacity[g.init_nodes]).any(), style.name
        # Every mono edge joins successive beats of one clip.
        ok = g.next_node >= 0
        assert np.all(g.node_clip[g.next_node[ok]] == g.node_clip[ok])
        assert np.all(g.node_frame[g.next_node[ok]] > g.node_frame[ok])
        # Bi-directional edges satisfy eq. (1) unless added to close dead ends.
        assert (g.bi_rd < GraphConfig().ths).sum() >= len(g.bi_rd) - 2 * g.n_forced


def test_ths_controls_the_number_of_edges(perfume_db, bundled_db):
    style = perfume_db.styles["jpop"]
    few = build_graph(style, GraphConfig(ths=2.0, close_dead_ends=False))
    many = build_graph(style, GraphConfig(ths=8.0, close_dead_ends=False))
    assert many.n_bi_edges > few.n_bi_edges
    assert set(zip(few.bi_src, few.bi_dst)) <= set(zip(many.bi_src, many.bi_dst))


def test_no_jump_leaves_or_lands_on_a_beat_where_a_limb_whips_round(perfume_db, bundled_db):
    # jpop's elbow turns at ~1,400 deg/s into its beat at frame 1841 (a hit): a jump there had to
    # carry that speed into the next motion and showed as a pop 1.08x the mocap's roughest 1 %.
    from dancesynth.motion.accents import fast_beats

    style = perfume_db.styles["jpop"]
    calm = build_graph(style, GraphConfig(close_dead_ends=False))
    fast = fast_beats(style, calm.node_frame, GraphConfig().calm_jumps)
    assert fast[np.flatnonzero(style.beat_frames == 1841)].all()
    assert 0 < fast.mean() < 0.05                       # few beats: the graph keeps its jumps
    assert not fast[calm.bi_src].any() and not fast[calm.bi_dst].any()
    every = build_graph(style, GraphConfig(calm_jumps=0.0, close_dead_ends=False))
    assert fast[every.bi_src].any()
    assert calm.n_bi_edges >= 0.8 * every.n_bi_edges    # most jumps are kept


# Eq. (1)-(3) on a hand-made pose

def arm_style(turns_deg: np.ndarray) -> "Style":
    """A three-joint arm: root -> shoulder (1 m up) -> elbow (2 m further), a 0.5 m forearm
    to the End Site. ``turns_deg[f]`` = (root, shoulder, elbow) rotation about x in frame f."""
    from dancesynth import rotations as rot
    from dancesynth.motion.database import Style
    from dancesynth.types import Skeleton
    channels = (("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"),
                ("Zrotation", "Xrotation", "Yrotation"), ("Zrotation", "Xrotation", "Yrotation"))
    sk = Skeleton(("root", "shoulder", "elbow"), np.array([-1, 0, 1]),
                  np.array([[0.0, 0.9, 0.0], [0.0, 1.0, 0.0], [0.0, 2.0, 0.0]]), channels,
                  {2: np.array([0.0, 0.5, 0.0])})
    f = len(turns_deg)
    q = rot.exp(np.radians(np.asarray(turns_deg, float))[..., None] * np.array([1.0, 0.0, 0.0]))
    return Style("arm", "test", sk, 30.0, ("a",), ("a.bvh",), np.array([0, f]), q.astype(np.float32),
                 np.zeros((f, 3), np.float32), np.zeros((f, 2), bool), np.ones(f, np.float32),
                 np.arange(f, dtype=np.int64), np.array([120.0]), "")


def test_joint_weights_are_the_bone_length_each_joint_moves():
    from dancesynth.engines.graph.meta_graph import joint_weights
    style = arm_style(np.array([[0, 0, 0], [10, 20, 30]]))
    # the shoulder: its subtree, 1 + 2 m; the elbow its 2 m bone; the root as much as both together
    assert np.allclose(joint_weights(style), np.array([5.0, 3.0, 2.0]) / 10.0)
    still_root = arm_style(np.array([[0, 0, 0], [0, 20, 30]]))
    assert np.allclose(joint_weights(still_root), np.array([0.0, 3.0, 2.0]) / 5.0)


def test_frame_distance_is_eq_3_and_the_ratio_eq_1():
    from dancesynth.engines.graph.meta_graph import _SimilarityRows
    # frame 1 and frame 4 are poses; 0, 2, 3, 5 their neighbours
    turns = np.array([[0, 0, 0], [0, 30, 0], [0, 40, 10], [0, 0, 60], [0, 30, 90], [0, 0, 0]], float)
    style = arm_style(turns)
    rows = _SimilarityRows(style, np.arange(6), np.zeros(6, np.int64),
                           GraphConfig(neighbour_s=0.0, min_jump_beats=0))
    w = np.array([3.0, 2.0]) / 5.0                    # the root never turns: skipped

    def d(a, b):                                      # eq. (3) by hand: sum_m w_m |angle_m|^2
        return float(np.sum(w * np.radians(turns[a, 1:] - turns[b, 1:]) ** 2))

    assert d(1, 4) == pytest.approx(w[1] * np.radians(90) ** 2)
    expected = d(1, 4) / (d(0, 2) + d(3, 5))          # eq. (1)
    assert rows(np.array([1]))[0, 4] == pytest.approx(expected, rel=1e-4)
    assert rows(np.array([4]))[0, 1] == pytest.approx(expected, rel=1e-4)  # symmetric


def test_the_frame_distance_ignores_which_way_the_dancer_faces():
    from dancesynth import rotations as rot
    from dancesynth.engines.graph.meta_graph import _distance, _poses
    style = arm_style(np.array([[0, 10, 20], [0, 10, 20]]))
    style.local_rot[1, 0] = rot.about_y(np.radians(120.0))  # same pose, turned to face elsewhere
    q = _poses(style, np.array([0, 1]), np.arange(3))
    assert _distance(q[0], q[1], np.ones(3) / 3) == pytest.approx(0.0, abs=1e-9)

"""The random-walk baseline: seeded, lands on the music's beats, survives dead ends."""

from __future__ import annotations

import numpy as np
import pytest

from dancesynth.api import DanceConfig, synthesise
from dancesynth.engines.beatgrid import beat_grid
from dancesynth.engines.graph.cache import load_graph
from dancesynth.engines.graph.meta_graph import GraphConfig, build_graph
from dancesynth.engines.graph.random_walk import OutSteps, RandomWalkEngine, random_walk
from dancesynth.types import MusicFeatures

FPS = 30.0


def music(duration_s: float, bpm: float, *, offset_s: float = 16 / FPS) -> MusicFeatures:
    beats = np.arange(offset_s, duration_s, 60.0 / bpm)
    loud = -20 + 6 * np.sin(np.arange(len(beats) - 1) / 5.0)
    return MusicFeatures(duration_s, beats, loud, bpm, source=f"synthetic {bpm} bpm")


def walk(style, graph, song: MusicFeatures, seed: int, segment_s: float = 5.0):
    grid = beat_grid(song)
    segments, _ = synthesise(RandomWalkEngine(style, graph, fps=FPS), grid, song.duration_s,
                             DanceConfig(segment_s=segment_s, fps=FPS, seed=seed))
    return segments


@pytest.fixture(scope="module")
def salsa(bundled_db):
    style = bundled_db.styles["salsa-133-150bpm"]
    return style, load_graph(style)[0]


def test_same_seed_same_dance_other_seed_other_dance(salsa):
    style, graph = salsa
    song = music(20.0, 112.5)
    a, b, c = (walk(style, graph, song, seed) for seed in (3, 3, 4))
    rot = [np.concatenate([s.local_rot for s in x]) for x in (a, b, c)]
    assert np.array_equal(rot[0], rot[1])
    assert np.array_equal(np.concatenate([s.path.nodes for s in a]), np.concatenate([s.path.nodes for s in b]))
    assert rot[0].shape == rot[2].shape and not np.allclose(rot[0], rot[2])


def test_segment_length_does_not_change_the_walk(salsa):
    """The generator's state travels with the stream: segments cut differently, same path."""
    style, graph = salsa
    song = music(20.0, 112.5)
    a, b = walk(style, graph, song, 7, segment_s=3.0), walk(style, graph, song, 7, segment_s=8.0)
    va, vb = (np.concatenate([s.path.via for s in x]) for x in (a, b))
    assert np.array_equal(va, vb)


def test_every_music_beat_shows_a_motion_beat_frame(salsa):
    style, graph = salsa
    # 112.5 bpm puts every beat on the 30 fps frame grid (16 frames per beat).
    song = music(30.0, 112.5)
    segments = walk(style, graph, song, 1)
    src = np.concatenate([s.source_pos for s in segments])
    jumps = sum(int(s.pieces.jump.sum()) for s in segments)
    assert jumps > 5, "a random walk on this graph jumps often"
    beat_frames = set(graph.render_frame.tolist())  # each beat's visible stop (motion.accents)
    for t in song.beat_times_s:
        f = int(round(t * FPS))
        assert abs(src[f] - round(src[f])) < 1e-6, f"beat at {t:.3f} s shows a fractional source frame"
        assert int(round(src[f])) in beat_frames


def test_steps_are_graph_steps_and_dead_ends_restart(bundled_db):
    """A tiny style without jumps: one chain that ends; the walk restarts instead of failing."""
    style = bundled_db.styles["whirl"]
    graph = build_graph(style, GraphConfig(ths=1e-9, close_dead_ends=False))
    assert graph.n_bi_edges == 0 and np.any(graph.next_node < 0)
    out = OutSteps.of(graph)
    path, restarts = random_walk(graph, 200, np.random.default_rng(0), start=int(graph.init_nodes[0]), out=out)
    chain = len(out.restart)
    assert restarts >= 200 // (chain + 1) - 1
    for k in range(path.n_steps):
        u, v, w = path.nodes[k], path.via[k], path.nodes[k + 1]
        assert graph.next_node[v] == w
        if out.count[u] == 0:
            assert path.jump[k]
        else:
            ok = (graph.step_src == u) & (graph.step_via == v) & (graph.step_dst == w)
            assert ok.any() and path.jump[k] == (u != v)


def test_dead_ends_render_a_whole_song(bundled_db):
    style = bundled_db.styles["whirl"]
    graph = build_graph(style, GraphConfig(ths=1e-9, close_dead_ends=False))
    song = music(40.0, 80.0)  # far longer than the style's 15 s chain
    segments = walk(style, graph, song, 0)
    rot = np.concatenate([s.local_rot for s in segments])
    assert len(rot) == int(40.0 * FPS) + 1
    assert np.all(np.isfinite(rot)) and np.allclose(np.linalg.norm(rot, axis=-1), 1.0, atol=1e-6)

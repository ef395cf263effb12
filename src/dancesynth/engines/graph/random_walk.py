"""A random walk on the meta motion graph: the baseline that shows what the search adds.

At every music beat the walk takes one *step* of the graph chosen uniformly at random
among the steps leaving the current node -- the mono-directional edge to the next
beat of the clip, or a jump along a bi-directional edge followed by that beat's mono
edge -- exactly the moves the search of eq. (4)-(9) chooses from. At a dead end (a
node with no step) it restarts at a node drawn uniformly among those with a mono
edge. It ignores the music's intensity and the synchronization capacity.

The path is rendered by the same renderer as the streaming engine (time-warping,
re-placement and blending at jumps, foot locking), so the walk still lands a motion
beat on every music beat: comparing it with the streaming engine isolates what the
dynamic program adds over the graph itself.

``RandomWalkEngine`` has the streaming engine's interface (``initial_state``,
``step``), so ``dancesynth.api.synthesise`` runs it like any engine; it is seeded
and pure (the generator's state travels in ``WalkState``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from ...errors import SynthesisError
from ...types import DEFAULT_FPS
from ...motion.database import Style
from ...motion.roles import find_roles
from ..footlock import FootLockState, lock_feet
from ..stitch import StitchState, render
from ..timing import speed_room
from .engine import EngineConfig, MusicSegment, SegmentFrames, pieces_from_path
from .meta_graph import MetaMotionGraph
from .search import Path

DEFAULT_SEED = 0


@dataclass(frozen=True)
class OutSteps:
    """The graph's steps grouped by their *source* node (the search groups them by destination)."""

    via: np.ndarray     # (S,) node whose mono edge the step plays
    dst: np.ndarray     # (S,) node the step arrives at
    jump: np.ndarray    # (S,) the step starts with a jump
    first: np.ndarray   # (N,) first step leaving each node
    count: np.ndarray   # (N,) number of steps leaving each node
    restart: np.ndarray  # nodes with a mono edge: where a dead end restarts

    @classmethod
    def of(cls, graph: MetaMotionGraph) -> "OutSteps":
        order = np.argsort(graph.step_src, kind="stable")
        src = graph.step_src[order]
        nodes = np.arange(graph.n_nodes)
        first = np.searchsorted(src, nodes, side="left")
        count = np.searchsorted(src, nodes, side="right") - first
        return cls(graph.step_via[order], graph.step_dst[order], graph.step_jump[order].astype(bool),
                   first, count, np.flatnonzero(graph.next_node >= 0))


def random_walk(graph: MetaMotionGraph, n_steps: int, rng: np.random.Generator, *, start: int,
                out: OutSteps | None = None) -> tuple[Path, int]:
    """A uniformly random walk of ``n_steps`` steps from node ``start``.

    Returns ``(path, restarts)``; a restart (at a dead end) is marked as a jump in
    ``path.jump``, since the motion changes source there. ``path.cost`` is NaN: the
    walk has no objective.
    """
    out = OutSteps.of(graph) if out is None else out
    if n_steps > 0 and not len(out.restart):
        raise SynthesisError(f"the '{graph.style}' graph has no mono-directional edge: nothing to dance")
    nodes = np.empty(n_steps + 1, dtype=np.int64)
    via = np.empty(n_steps, dtype=np.int64)
    jump = np.empty(n_steps, dtype=bool)
    nodes[0] = start
    restarts = 0
    # One uniform draw per beat; a restart draws a second number for the new node.
    u = rng.random(n_steps)
    for k in range(n_steps):
        node = nodes[k]
        c = out.count[node]
        if c:
            s = out.first[node] + min(int(u[k] * c), c - 1)
            via[k], nodes[k + 1], jump[k] = out.via[s], out.dst[s], out.jump[s]
        else:
            r = int(out.restart[rng.integers(len(out.restart))])
            via[k], nodes[k + 1], jump[k] = r, graph.next_node[r], True
            restarts += 1
    return Path(nodes, via, jump, float("nan")), restarts


@dataclass(frozen=True)
class WalkState:
    """What the walk carries from one segment to the next."""

    node: int
    rng_state: dict                      # the generator's state (PCG64), so ``step`` stays pure
    stitch: StitchState = field(default_factory=StitchState)
    feet: FootLockState = field(default_factory=FootLockState)
    segments: int = 0
    restarts: int = 0


@dataclass(frozen=True)
class RandomWalkEngine:
    """Random walk + the streaming engine's renderer; same interface as ``GraphEngine``."""

    style: Style
    graph: MetaMotionGraph
    config: EngineConfig = EngineConfig()
    fps: float = DEFAULT_FPS

    @cached_property
    def speed_room(self):
        """As ``GraphEngine.speed_room``: the walk is rendered with the streaming engine's timing."""
        return speed_room(self.style, self.config)

    def initial_state(self, seed: int | None = None) -> WalkState:
        """Start at a clip's first beat (InitS) drawn by ``seed`` (``None``: seed 0)."""
        rng = np.random.Generator(np.random.PCG64(DEFAULT_SEED if seed is None else seed))
        start = int(rng.choice(self.graph.init_nodes))
        return WalkState(node=start, rng_state=rng.bit_generator.state)

    def step(self, state: WalkState, segment: MusicSegment) -> tuple[WalkState, SegmentFrames]:
        """Walk and render one music segment (the music's intensity is ignored)."""
        beats = np.asarray(segment.beat_times_s, dtype=np.float64)
        rng = np.random.Generator(np.random.PCG64())
        rng.bit_generator.state = state.rng_state
        t0 = time.perf_counter()
        path, restarts = random_walk(self.graph, len(beats) - 1, rng, start=state.node, out=self._out)
        t1 = time.perf_counter()
        ease = self.config.beat_ease(len(beats), segment.bar_position, segment.beats_per_bar)
        pieces = pieces_from_path(self.graph, path, beats, segment.beat_count, ease, self.config.ease_max_rate,
                                  self.speed_room)
        last = segment.end_s is not None
        stitch, frames = render(self.style, pieces, state.stitch, fps=self.fps,
                                end_s=segment.end_s if last else float(beats[-1]),
                                blend_s=self.config.blend_s, inclusive_end=last)
        t2 = time.perf_counter()
        local, feet = frames.local_rot, state.feet
        if self.config.foot_lock:
            local, feet = lock_feet(self.style.skeleton, find_roles(self.style.skeleton), frames, feet, fps=self.fps)
        new = replace(state, node=int(path.nodes[-1]), rng_state=rng.bit_generator.state, stitch=stitch,
                      feet=feet, segments=state.segments + 1, restarts=state.restarts + restarts)
        t3 = time.perf_counter()
        return new, SegmentFrames.of(frames, local, path, pieces, t1 - t0, t3 - t1, foot_lock_s=t3 - t2)

    @property
    def _out(self) -> OutSteps:
        cached = self.__dict__.get("_out_steps")
        if cached is None:
            cached = OutSteps.of(self.graph)
            object.__setattr__(self, "_out_steps", cached)
        return cached

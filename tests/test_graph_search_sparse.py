"""However the path search prices and relaxes the steps (all beats at once, or beat by beat only the
steps leaving reached nodes), the same path and cost, to the bit."""

from __future__ import annotations

import numpy as np
import pytest

from dancesynth.engines.graph.cache import load_graph
from dancesynth.engines.graph.search import StepCosts, search
from dancesynth.errors import SynthesisError
from dancesynth.motion.accents import AccentCosts


def _cases(graph, rng):
    n = graph.n_nodes
    for trial in range(8):
        k = int(rng.integers(1, 20))
        durations = np.full(k, 0.5) if trial % 3 == 0 else rng.uniform(0.3, 0.7, size=k)
        one = np.array([int(rng.choice(np.flatnonzero(graph.next_node >= 0)))])
        start = graph.init_nodes if trial % 4 == 0 else one
        kw = dict(start_nodes=start, prev_duration_s=None if trial % 5 == 0 else float(rng.uniform(0.3, 0.7)),
                  thc=[np.inf, 0.0, 4.0][trial % 3], intensity_weight=8.0,
                  node_penalty=rng.uniform(0, 1, n) if trial % 2 else None)
        if trial % 3 == 1:
            classes = rng.integers(-1, 2, size=k + 1)
            classes[0] = -1
            kw.update(beat_class=classes, class_cost=rng.normal(size=(2, n)))
        yield rng.normal(size=k), durations, kw


@pytest.mark.parametrize("accent", [None, AccentCosts(warp=16.0, far_warp=30.0, slide=1.0)])
def test_relaxing_only_reached_nodes_changes_nothing(bundled_db, monkeypatch, accent):
    rng = np.random.default_rng(0)
    for style in sorted(bundled_db.styles.values(), key=lambda s: s.name)[:4]:
        graph, _ = load_graph(style)
        steps = StepCosts(graph, 0.25, accent)
        for intensity, durations, kw in _cases(graph, rng):
            found = []
            # Every step of every beat priced at once (a small graph); beat by beat, every step; beat
            # by beat, the default share; beat by beat, only the reached nodes' steps.
            for every, share in ((1 << 30, 0.25), (0, -1.0), (0, 0.25), (0, 2.0)):
                monkeypatch.setattr(StepCosts, "EVERY_STEP_MAX", every)
                monkeypatch.setattr(StepCosts, "DENSE_SHARE", share)
                try:
                    path = search(graph, intensity, durations, steps=steps, **kw)
                    found.append((path.nodes.tolist(), path.via.tolist(), path.jump.tolist(), path.cost))
                except SynthesisError as exc:  # no path: the same error either way
                    found.append(str(exc))
            assert found[1:] == found[:-1]

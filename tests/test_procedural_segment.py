"""Loi & Li's music segmentation (Fig. 2, eq. 1-5): optimal, fast, and it turns on beats."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from dancesynth.engines.procedural.config import ProceduralConfig
from dancesynth.engines.procedural.segment import (segment, segment_costs, segment_fig2, segment_prefix,
                                                    segmentation_cost)
from dancesynth.music.notes import note_sequence


def random_melody(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    dur = rng.choice([1, 2, 2, 4, 4, 4, 8], n).astype(float)
    onset = np.concatenate(([0.0], np.cumsum(dur)[:-1])) * 0.125
    return note_sequence(onset, 60 + rng.integers(-9, 10, n), dur * 0.125 * rng.choice([0.3, 0.9], n),
                         rng.integers(30, 127, n), sixteenth_s=0.125, beat_times_s=np.arange(0, onset[-1] + 1, 0.5),
                         duration_s=onset[-1] + 1.0, tempo_bpm=120.0, is_beat=rng.random(n) < 0.35)


def brute_force(costs, n, lmax):
    best = np.inf
    for r in range(n):
        for cut in itertools.combinations(range(1, n), r):
            bounds = list(zip((0,) + cut, cut + (n,)))
            if all(b - a <= lmax for a, b in bounds):
                best = min(best, segmentation_cost(costs, bounds))
    return best


@pytest.mark.parametrize("seed", range(12))
def test_dp_matches_brute_force_on_short_melodies(seed):
    n = 9 + seed % 4
    weights = [(1, 0.5, 0.3, 1), (1, 1, 1, 1), (0, 1, 0, 0.2), (2, 0, 1, 0.5)][seed % 4]
    cfg = ProceduralConfig(w1=weights[0], w2=weights[1], w3=weights[2], w4=weights[3], max_segment_notes=6,
                           ideal_duration=8.0 + seed)
    notes = random_melody(n, seed)
    costs = segment_costs(notes, cfg)
    best = brute_force(costs, n, 6)
    for method in (segment_prefix, segment_fig2):
        bounds = method(costs)
        assert bounds[0][0] == 0 and bounds[-1][1] == n
        assert all(a < b and b - a <= 6 for a, b in bounds)
        assert all(b1 == a2 for (_, b1), (a2, _) in zip(bounds[:-1], bounds[1:]))
        assert segmentation_cost(costs, bounds) == pytest.approx(best, abs=1e-12)


def test_fig2_table_and_prefix_dp_agree_on_a_song():
    notes = random_melody(400, seed=5)
    costs = segment_costs(notes, ProceduralConfig())
    a, b = segment_prefix(costs), segment_fig2(costs)
    assert segmentation_cost(costs, a) == pytest.approx(segmentation_cost(costs, b), abs=1e-12)


def test_costs_follow_equations_one_to_four():
    cfg = ProceduralConfig(w1=1, w2=0, w3=0, w4=0)
    notes = random_melody(30, seed=2)
    f1 = segment_costs(notes, cfg)[0]  # one-note segments: f1 only
    assert np.array_equal(f1 == 0, notes.is_beat | notes.rest_after)
    cfg = ProceduralConfig(w1=0, w2=0, w3=0, w4=1, ideal_duration=8.0)
    f4 = segment_costs(notes, cfg)
    total = notes.duration_16[3:3 + 5].sum()
    assert f4[4, 3] == pytest.approx(min(abs(total - 8.0) / 8.0, 1.0))


def test_segments_turn_on_beats_and_have_the_ideal_length():
    notes = random_melody(600, seed=9)
    cfg = ProceduralConfig()
    bounds = segment(notes, cfg)
    last = np.array([b - 1 for _, b in bounds])
    ends_well = (notes.is_beat | notes.rest_after)[last]
    assert ends_well.mean() > 0.9 > (notes.is_beat | notes.rest_after).mean()
    dur = np.array([notes.duration_16[a:b].sum() for a, b in bounds])
    assert abs(np.median(dur) - cfg.ideal_duration) <= 4


def test_two_thousand_notes_are_all_segmented():
    # (how fast: benchmarks/procedural_bench.py)
    notes = random_melody(2000, seed=1)
    bounds = segment(notes, ProceduralConfig())
    assert bounds[0][0] == 0 and bounds[-1][1] == 2000
    assert all(a[1] == b[0] for a, b in zip(bounds, bounds[1:]))


def test_segment_longer_than_the_bound_is_impossible():
    costs = segment_costs(random_melody(10), ProceduralConfig(max_segment_notes=2))
    assert max(b - a for a, b in segment_prefix(costs)) <= 2

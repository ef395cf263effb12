"""The choreography level (eq. 5) and its constraints, on the shipped motif model and on hand-made chains."""

from __future__ import annotations

import numpy as np
import pytest

from dancesynth.engines.choreography.level import (
    constraint_beats, eq5_probabilities, parse_motif_at, plan_motifs, recreate_plan)
from dancesynth.errors import InputError
from dancesynth.motion.motifs import chi2, load_motif_model


@pytest.fixture(scope="module")
def salsa():
    model = load_motif_model()
    return model, model.templates["salsa"], model.transitions["salsa"]


def _markov(template, transitions, n, rng):
    """The transition matrix alone, for comparison."""
    cur, out = int(rng.choice(len(template), p=template)), []
    for _ in range(n):
        out.append(cur)
        cur = int(rng.choice(len(template), p=transitions[cur]))
    return out


def test_eq5_converges_to_the_genre_template(salsa):
    model, template, transitions = salsa
    for n, bound in ((100, 0.03), (500, 0.002)):
        for seed in range(5):
            sig = model.signature(plan_motifs(n, template, transitions, np.random.default_rng(seed)))
            assert chi2(template, sig) < bound, (n, seed)
    # Measured: chi2 after 100 beats is ~0.011 by eq. (5) and ~0.15 following T alone.
    eq5 = [chi2(template, model.signature(plan_motifs(100, template, transitions, np.random.default_rng(s))))
           for s in range(5)]
    chain = [chi2(template, model.signature(_markov(template, transitions, 100, np.random.default_rng(s))))
             for s in range(5)]
    assert max(eq5) < 0.3 * min(chain)


def test_eq5_is_transition_times_deficit():
    t = np.array([[0.0, 0.5, 0.5], [0.2, 0.0, 0.8], [1.0, 0.0, 0.0]])
    template = np.array([0.2, 0.3, 0.5])
    p = eq5_probabilities(t, template, np.array([1.0, 0.0, 0.0]), current=0)
    np.testing.assert_allclose(p, [0.0, 0.5 * 0.3, 0.5 * 0.5])
    # No reachable motif in deficit: T alone decides.
    p = eq5_probabilities(t, template, np.array([3.0, 0.0, 7.0]), current=1)   # only motif 1 is in deficit
    np.testing.assert_allclose(p, t[1])


def test_plans_are_reproducible_under_a_seed(salsa):
    _, template, transitions = salsa
    a = plan_motifs(200, template, transitions, np.random.default_rng(7))
    b = plan_motifs(200, template, transitions, np.random.default_rng(7))
    c = plan_motifs(200, template, transitions, np.random.default_rng(8))
    np.testing.assert_array_equal(a, b)
    assert np.mean(a != c) > 0.5


def test_plan_only_uses_allowed_transitions(salsa):
    _, template, transitions = salsa
    plan = plan_motifs(300, template, transitions, np.random.default_rng(1))
    assert np.all(transitions[plan[:-1], plan[1:]] > 0)


def test_constraints_are_reached_through_allowed_transitions():
    # A cycle 0 -> 1 -> 2 -> 3 -> 0 with a side step 0 -> 4 -> 0: reaching motif 2 at beat 10
    # and motif 4 at beat 17 needs planning several beats ahead.
    t = np.zeros((5, 5))
    for a, b in ((0, 1), (1, 2), (2, 3), (3, 0), (4, 0)):
        t[a, b] = 1.0
    t[0] = [0, 0.5, 0, 0, 0.5]
    template = np.full(5, 0.2)
    fixed = {10: 2, 17: 4, 29: 3}
    for seed in range(20):
        plan = plan_motifs(30, template, t, np.random.default_rng(seed), fixed=fixed)
        assert all(plan[b] == m for b, m in fixed.items())
        assert np.all(t[plan[:-1], plan[1:]] > 0), plan


def test_an_unreachable_constraint_is_still_honoured():
    t = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])   # 2 cannot be entered
    plan = plan_motifs(12, np.array([0.5, 0.5, 0.0]), t, np.random.default_rng(0), fixed={6: 2})
    assert plan[6] == 2
    assert np.all(t[plan[:5], plan[1:6]] > 0)


def test_constraint_times_map_to_the_beat_containing_them():
    beats = np.array([-0.2, 0.3, 0.8, 1.3, 1.8, 2.3])
    assert constraint_beats([(0.0, 3), (1.3, 4), (2.0, 5)], beats, 2.1) == {0: 3, 3: 4, 4: 5}


def test_parse_motif_at():
    assert parse_motif_at("12.0=M17", 48) == (12.0, 17)
    assert parse_motif_at(" 3 = m4 ", 48) == (3.0, 4)


@pytest.mark.parametrize("text, needle", [("12.0=M999", "M0 .. M47"), ("12.0=X3", "M0 .. M47"),
                                          ("M3", "TIME=MOTIF"), ("abc=M3", "TIME=MOTIF"), ("nan=M3", "TIME=MOTIF")])
def test_bad_motif_at_says_what_to_write(text, needle):
    with pytest.raises(InputError, match=needle.replace(".", r"\.")):
        parse_motif_at(text, 48)


@pytest.mark.parametrize("t", [-1.0, 2.5])
def test_constraint_outside_the_song_is_refused(t):
    with pytest.raises(InputError, match=r"outside the song \(0 to 2\.1 s\)"):
        constraint_beats([(t, 3)], np.array([-0.2, 0.3, 0.8, 1.3, 1.8, 2.3]), 2.1)


def test_two_motifs_on_one_beat_are_refused():
    with pytest.raises(InputError, match="both M3 and M4"):
        constraint_beats([(0.4, 3), (0.5, 4)], np.array([0.0, 0.3, 0.8, 1.3]), 1.2)


def test_recreate_plan_loops_and_crops():
    np.testing.assert_array_equal(recreate_plan([1, 2, 3], 7), [1, 2, 3, 1, 2, 3, 1])
    np.testing.assert_array_equal(recreate_plan([1, 2, 3, 4, 5], 2), [1, 2])
    with pytest.raises(InputError, match="no motion word"):
        recreate_plan([], 5)

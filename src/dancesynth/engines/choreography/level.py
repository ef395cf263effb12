"""The choreography level (Aristidou et al. §5.2.4, eq. 5): which motif to dance on each beat.

A genre is a *signature*, the histogram of its motifs (the template). The dance so
far has its own signature; the next motif is drawn with probability

    P(m | current) ∝ T[current, m] · max(S_target[m] − S_current[m], 0)          (5)

so motifs the dance has danced less than the genre does are preferred, but only
among those that follow the current motif in the genre's dances (``T``). When no
motif is both reachable and in deficit, ``T`` alone decides (DESIGN.md).

User constraints (§5.5): a motif fixed at some beats (``--motif-at``) -- the gaps
are planned so that the sequence reaches each fixed motif through transitions of
``T`` where that is possible -- or a whole motif sequence taken from a reference
dance (``--recreate``).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from ...errors import InputError
from ...motion.motifs import parse_motif_id


def parse_motif_at(text: str, k: int) -> tuple[float, int]:
    """``"12.0=M17"`` -> ``(12.0, 17)``: the motif to dance at that time (seconds)."""
    time_s, sep, motif = str(text).partition("=")
    try:
        t = float(time_s)
    except ValueError:
        t = float("nan")
    if not sep or not np.isfinite(t):
        raise InputError(f"'{text}' is not TIME=MOTIF: write e.g. --motif-at 12.0=M17 (seconds = motif id)")
    return t, parse_motif_id(motif, k)


def constraint_beats(constraints, beat_times_s: np.ndarray, duration_s: float) -> dict[int, int]:
    """``{beat interval: motif}`` for ``(time_s, motif)`` constraints on a beat grid.

    The interval containing the time gets the motif. Raises ``InputError`` for a time
    outside the song or two different motifs asked for the same beat.
    """
    times = np.asarray(beat_times_s, dtype=float)
    fixed: dict[int, int] = {}
    for t, m in constraints:
        if not 0.0 <= t <= duration_s:
            raise InputError(f"--motif-at {t:g}=M{m}: {t:g} s is outside the song (0 to {duration_s:.1f} s)")
        b = int(np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2))
        if fixed.get(b, m) != m:
            raise InputError(f"--motif-at asks for both M{fixed[b]} and M{m} on the beat at "
                             f"{times[b]:.2f}-{times[b + 1]:.2f} s: move one of them to another beat")
        fixed[b] = m
    return fixed


def _reach(allowed: np.ndarray, target: int, steps: int) -> list[np.ndarray]:
    """``out[d]``: motifs from which ``target`` can be reached in exactly ``d`` transitions (d ≤ steps)."""
    cur = np.zeros(len(allowed), dtype=bool)
    cur[target] = True
    out = [cur]
    for _ in range(steps):
        cur = (allowed & cur[None, :]).any(axis=1)
        out.append(cur)
    return out


def eq5_probabilities(transitions: np.ndarray, template: np.ndarray, counts: np.ndarray,
                      current: int | None) -> np.ndarray:
    """Eq. (5) for the next motif (unnormalised): transition × signature deficit, ``T`` alone
    when nothing reachable is in deficit, the template alone at the very start."""
    if current is None:
        return template.copy()
    now = counts / counts.sum() if counts.sum() > 0 else np.zeros_like(template)
    p = transitions[current] * np.maximum(template - now, 0.0)
    return p if p.sum() > 0 else transitions[current].copy()


def plan_motifs(n_beats: int, template, transitions, rng: np.random.Generator, *,
                fixed: Mapping[int, int] | None = None) -> np.ndarray:
    """One motif per beat interval (``n_beats``,), drawn by eq. (5); ``fixed`` beats get their motif.

    Before a fixed beat, each draw is restricted to motifs from which the fixed motif
    can still be reached through transitions of ``T`` in the beats left -- so the
    sequence arrives there naturally. If no such motif exists (the constraint cannot
    be reached through ``T``), the draw is unrestricted and the fixed beat is a jump.
    """
    template = np.asarray(template, dtype=float)
    transitions = np.asarray(transitions, dtype=float)
    k = len(template)
    if transitions.shape != (k, k):
        raise InputError(f"transitions must be ({k}, {k}) for {k} motifs, got {transitions.shape}")
    fixed = dict(fixed or {})
    allowed = transitions > 0
    targets = sorted(b for b in fixed if 0 <= b < n_beats)
    # Only the gap since the previous fixed beat needs planning towards each fixed beat.
    reach = {b: _reach(allowed, fixed[b], b - a) for a, b in zip([0] + targets[:-1], targets)}
    counts = np.zeros(k)
    out = np.empty(n_beats, dtype=np.int64)
    current = None
    nxt = 0  # index into targets of the next fixed beat
    for i in range(n_beats):
        while nxt < len(targets) and targets[nxt] < i:
            nxt += 1
        if i in fixed:
            m = fixed[i]
        else:
            p = eq5_probabilities(transitions, template, counts, current)
            if nxt < len(targets):
                ok = reach[targets[nxt]][targets[nxt] - i]
                # Draw among motifs that can still reach the fixed one: eq. (5) weights if any
                # is positive, else T, else any reachable motif.
                for cand in (p, None if current is None else transitions[current], np.ones(k)):
                    if cand is not None and (cand * ok).sum() > 0:
                        p = cand * ok
                        break
            if p.sum() <= 0:
                p = template if template.sum() > 0 else np.ones(k)
            m = int(rng.choice(k, p=p / p.sum()))
        out[i] = m
        counts[m] += 1
        current = m
    return out


def recreate_plan(reference_ids, n_beats: int) -> np.ndarray:
    """§5.5.1: the reference dance's motif sequence, one per beat, looped or cropped to ``n_beats``."""
    ref = np.asarray(reference_ids, dtype=np.int64).reshape(-1)
    if ref.size == 0:
        raise InputError("the reference dance has no motion word: use a dance with at least two motion beats")
    return np.resize(ref, n_beats)

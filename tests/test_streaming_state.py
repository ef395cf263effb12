"""What one streaming segment hands the next (Xu et al. §3.3): the end node and the running
statistics of the music's intensity."""

from __future__ import annotations

import numpy as np
import pytest

from dancesynth import rotations as rot
from dancesynth.engines.graph.cache import load_graph
from dancesynth.engines.graph.engine import GraphEngine, MusicSegment

STYLE = "salsa-133-150bpm"


@pytest.fixture(scope="module")
def engine(bundled_db):
    style = bundled_db.styles[STYLE]
    return GraphEngine(style, load_graph(style)[0])


def segments(loudness_db: list[np.ndarray], beat_s: float = 0.46):
    """Consecutive segments of beats every ``beat_s``, one interval per loudness value."""
    start = 0.3
    for k, loud in enumerate(loudness_db):
        beats = start + beat_s * np.arange(len(loud) + 1)
        last = k == len(loudness_db) - 1
        yield MusicSegment(beats, loud, end_s=beats[-1] + 0.2 if last else None)
        start = beats[-1]


def test_each_segment_starts_where_the_last_one_ended(engine):
    rng = np.random.default_rng(4)
    state, frames = engine.initial_state(seed=0), []
    for seg in segments([rng.normal(-20, 3, 11) for _ in range(4)]):
        before = state.node
        state, out = engine.step(state, seg)
        if before is not None:
            assert out.path.nodes[0] == before      # the path goes on from the previous segment's end node
        assert state.node == out.path.nodes[-1]
        frames.append(out)
    # ... and the motion goes on without a jump where segments meet: no joint turns further in
    # that frame than the dance's own fastest 1 % of frames
    steps = [np.degrees(rot.angle(f.local_rot[1:], f.local_rot[:-1])).max(axis=1) for f in frames]
    limit = np.percentile(np.concatenate(steps), 99)
    for a, b in zip(frames, frames[1:]):
        seam = np.degrees(rot.angle(b.local_rot[0], a.local_rot[-1])).max()
        assert seam <= limit
        assert np.linalg.norm(b.root_pos[0] - a.root_pos[-1]) < 0.1


def test_intensity_is_standardised_by_everything_heard_so_far(engine):
    quiet, loud = np.full(10, -30.0), np.full(10, -10.0)
    state = engine.initial_state(seed=0)
    state, _ = engine.step(state, next(segments([quiet, loud])))
    assert state.n_heard == 10 and state.mean_db == pytest.approx(-30.0) and state.m2_db == pytest.approx(0.0)
    # The loud segment is judged against the quiet one heard before it: it is loud, so the
    # search asks for the style's liveliest pieces there.
    seg2 = list(segments([quiet, loud]))[1]
    state2, _ = engine.step(state, seg2)
    heard = np.r_[quiet, loud]
    assert state2.n_heard == 20
    assert state2.mean_db == pytest.approx(heard.mean())
    assert np.sqrt(state2.m2_db / state2.n_heard) == pytest.approx(heard.std())
    # The same loud music after a loud start is ordinary there: the dance is calmer than after quiet, by
    # the intensity its pieces show (measured 0.29 z on average; from one start the few beats reachable in
    # a segment may leave both on one path: 0.0 from seed 0, 0.48 from seed 1).
    shown = engine.graph.shown_intensity_z(np.diff(seg2.beat_times_s))[0]
    calmer = []
    for seed in range(6):
        after_quiet, _ = engine.step(engine.initial_state(seed=seed), next(segments([quiet, loud])))
        _, lively = engine.step(after_quiet, seg2)
        after_loud, _ = engine.step(engine.initial_state(seed=seed), next(segments([loud, loud])))
        _, same = engine.step(after_loud, list(segments([loud, loud]))[1])
        calmer.append(np.mean(shown[lively.path.nodes[:-1]]) - np.mean(shown[same.path.nodes[:-1]]))
    assert np.mean(calmer) > 0.15 and min(calmer) >= 0, calmer
    # Looked-ahead intervals are searched, not heard: they do not enter the statistics.
    ahead = MusicSegment(seg2.beat_times_s, seg2.intensity_db, ahead=4)
    assert engine.step(state, ahead)[0].n_heard == 16


def test_a_report_is_enough_to_make_the_same_dance_again(bundled_db, bundled_song):
    import json

    from dancesynth.api import analyse, config_from_report, dance

    music = analyse(bundled_song)
    first = dance(music, database=bundled_db, seed=7, segment_s=4.0, follow_signature=True)
    report = json.loads(json.dumps(first.provenance.report()))   # as written to disk and read back
    assert report["config"]["seed"] == 7 and report["style"] == first.provenance.style
    again = dance(music, database=bundled_db, config=config_from_report(report))
    np.testing.assert_array_equal(again.local_rot, first.local_rot)
    np.testing.assert_array_equal(again.root_pos, first.root_pos)

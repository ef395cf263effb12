"""Re-dancing a span of a dance (``dancesynth.edit``): the rest stays frame for frame, the span changes,
the joins do not pop, and a bad span or motif gets a clear error."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import BUNDLED_MUSIC
from dancesynth.api import analyse, dance
from dancesynth.edit import BLEND_S, redance_span, span_beats
from dancesynth.errors import InputError
from dancesynth.eval import motion_metrics as mm
from dancesynth.eval.artefacts import one_frame_steps
from dancesynth.eval.evaluate import mocap_reference
from dancesynth.motion.database import open_database

SONG = BUNDLED_MUSIC / "Kevin_MacLeod_-_Vibe_Ace.ogg"


@pytest.fixture(scope="module")
def made():
    db = open_database(None)
    music = analyse(SONG, structure=False)
    return music, db, dance(music, database=db, seed=1)


def frames(clip, start_s, end_s):
    return round(start_s * clip.fps), round(end_s * clip.fps)


def test_only_the_span_changes_and_it_is_snapped_to_beats(made):
    music, db, clip = made
    edited, record = redance_span(clip, music, 20.0, 27.5, database=db, seed=5)
    a, b = record["beats"]
    assert record["start_s"] == music.beat_times_s[a] and record["end_s"] == music.beat_times_s[b]
    assert abs(record["start_s"] - 20.0) < 0.3 and abs(record["end_s"] - 27.5) < 0.3
    fa, fb = frames(clip, record["start_s"], record["end_s"])
    assert edited.n_frames == clip.n_frames
    for x, y in ((edited.local_rot, clip.local_rot), (edited.root_pos, clip.root_pos)):
        assert np.array_equal(x[:fa], y[:fa]) and np.array_equal(x[fb + 1:], y[fb + 1:])
    middle = slice(fa + 15, fb - 15)
    assert np.abs(edited.local_rot[middle] - clip.local_rot[middle]).max() > 0.3, "the span was not re-danced"
    assert edited.provenance.summary["edits"] == [record] and clip.provenance.summary.get("edits") is None


def test_the_joins_stay_within_the_mocaps_jumps_and_the_dancer_does_not_teleport(made):
    music, db, clip = made
    style = db.styles[clip.provenance.style]
    p99 = np.percentile(mocap_reference([style.clip(i) for i in range(style.n_clips)], clip.fps).jumps_deg_s, 99)
    before = {tuple(s) for s in one_frame_steps(clip).tolist()}
    for seed, (start, end) in enumerate([(10.0, 17.4), (33.0, 40.4), (48.0, 55.4)]):
        edited, record = redance_span(clip, music, start, end, database=db, seed=seed)
        fa, fb = frames(clip, record["start_s"], record["end_s"])
        jumps = mm.angular_velocity_jumps(edited)
        width = round(BLEND_S * clip.fps)   # the cross-fades, and two frames each side
        assert jumps[fa - 2:fa + width + 3].max() < p99 and jumps[fb - width - 2:fb + 3].max() < p99, seed
        assert {tuple(s) for s in one_frame_steps(edited).tolist()} <= before
        # The root moves on at its own pace through the joins: no step bigger than the dance's own.
        step = np.linalg.norm(np.diff(edited.root_pos[:, [0, 2]], axis=0), axis=1)
        assert step[fa - 2:fb + 2].max() <= 1.5 * np.linalg.norm(np.diff(clip.root_pos[:, [0, 2]], axis=0), axis=1).max()


def test_the_same_seed_gives_the_same_edit_and_another_seed_another(made):
    music, db, clip = made
    one, _ = redance_span(clip, music, 30.0, 37.0, database=db, seed=9)
    again, _ = redance_span(clip, music, 30.0, 37.0, database=db, seed=9)
    other, _ = redance_span(clip, music, 30.0, 37.0, database=db, seed=10)
    assert np.array_equal(one.local_rot, again.local_rot)
    assert not np.array_equal(one.local_rot, other.local_rot)


def test_a_motif_is_danced_by_the_choreography_engine_and_edits_add_up(made):
    music, db, clip = made
    edited, record = redance_span(clip, music, 30.0, 37.0, database=db, seed=3, motif="M3")
    assert record["engine"] == "choreography" and record["motif"] == "M3"
    twice, second = redance_span(edited, music, 45.0, 50.0, database=db, seed=4)
    assert twice.provenance.summary["edits"] == [record, second] and second["engine"] == "streaming"
    with pytest.raises(InputError, match="M0 .. M"):
        redance_span(clip, music, 30.0, 37.0, database=db, motif="M9999")


@pytest.mark.parametrize("start, end, words", [
    (20.0, 20.2, "fewer than two beats"),
    (30.0, 20.0, "start before its end"),
    (float("nan"), 20.0, "start before its end"),
])
def test_a_bad_span_is_a_clear_error(made, start, end, words):
    music, db, clip = made
    with pytest.raises(InputError, match=words):
        redance_span(clip, music, start, end, database=db)


def test_a_dance_without_its_record_cannot_be_edited(made):
    music, db, clip = made
    from dataclasses import replace

    with pytest.raises(InputError, match="provenance"):
        redance_span(replace(clip, provenance=None), music, 20.0, 27.0, database=db)


def test_span_beats_snaps_to_the_nearest_beats(made):
    music = made[0]
    beats = music.beat_times_s
    assert span_beats(music, beats[10] + 0.01, beats[18] - 0.01) == (10, 18)

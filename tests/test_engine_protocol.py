"""Every engine is called one way (engines/protocol.py, issue 32 item 2): music, database and the
config in; the motion and the engine's account out, with its own stages timed under their own names."""

import inspect

import numpy as np
import pytest

from dancesynth.api import DanceConfig, dance
from dancesynth.engines.form import FormPlan
from dancesynth.engines.protocol import ENGINES, engine
from dancesynth.provenance import EngineRun
from dancesynth.types import MotionClip, MusicFeatures

STAGES = {"streaming": "graph", "global": "graph", "choreography": "motifs", "neural": "model"}


def _music(bpm: float = 120.0, beats: int = 40) -> MusicFeatures:
    times = 0.3 + np.arange(beats) * 60.0 / bpm
    loud = -20.0 + 4.0 * np.sin(np.arange(beats - 1) / 5.0)
    return MusicFeatures(times[-1] + 0.3, times, loud, bpm, beats_per_bar=4, beat_in_bar=np.arange(beats) % 4,
                         source=f"synthetic {bpm} bpm")


def test_every_engine_has_the_same_entry():
    assert set(ENGINES) == set(STAGES)
    for name in ENGINES:
        params = list(inspect.signature(engine(name)).parameters)
        assert params == ["music", "db", "config", "timings", "progress"], name


@pytest.mark.parametrize("name", sorted(STAGES))
def test_each_engine_dances_through_the_protocol_and_times_its_own_stages(name, bundled_db):
    if name == "neural":
        pytest.importorskip("torch")
    music, timings = _music(), {}
    clip, run = engine(name)(music, bundled_db, DanceConfig(engine=name, seed=1), timings)
    assert isinstance(clip, MotionClip) and isinstance(run, EngineRun)
    assert clip.duration_s == pytest.approx(music.duration_s, abs=0.05)
    assert run.style in bundled_db.styles and isinstance(run.form, FormPlan)
    assert set(timings) == {"prepare_s", "synthesis_s"} and all(v >= 0 for v in timings.values())
    assert run.extra["prepare_stage"] == STAGES[name]
    # What the CLI prints and the report keeps: the engine's own stage, no other engine's name for it.
    summary = dance(music, database=bundled_db, engine=name, seed=1).provenance.summary
    assert summary["prepare_stage"] == STAGES[name] and "graph_s" not in summary["timings_s"]
    assert ("graph_cached" in summary) == (STAGES[name] == "graph")

"""One way to call every dance engine (issue 32 item 2).

An engine is a function::

    dance(music, db, config, timings, progress=None) -> (MotionClip, EngineRun)

``music`` is the song's ``MusicFeatures`` (its form included, ``music.structure``), ``db`` the
``MotionDatabase``, ``config`` the ``api.DanceConfig`` -- each engine reads its own fields, and the
config refuses fields that do not fit its engine -- ``timings`` a dict the engine fills with the
seconds of its two stages, ``prepare_s`` (what it loads or builds before dancing: the graph, the
motif bank, the network; ``EngineRun.extra["prepare_stage"]`` names it) and ``synthesis_s``, and
``progress`` an optional ``(stage, done, total)`` callback. The ``EngineRun`` is what the engine
reports beyond the motion: style, beat grid, transitions, the form it followed. ``api.dance``
analyses the song, opens the database, calls the engine ``config.engine`` names and makes the
provenance record of the run. The song's form reaches every engine the same way, as an
``engines.form.FormPlan`` on the engine's own beat grid.
"""

from __future__ import annotations

from importlib import import_module
from typing import Callable

Progress = Callable[[str, int, int], None]

#: Each engine's module (imported when first danced: the neural one imports torch).
ENGINES = {"streaming": "graph.dance", "global": "graph.dance", "neural": "neural.engine",
           "choreography": "choreography.engine"}


def engine(name: str) -> Callable:
    """The ``dance`` function of engine ``name`` (one of ``ENGINES``)."""
    return import_module(f"{__package__}.{ENGINES[name]}").dance

"""Command line, the options of a dance: the same on ``dance`` and ``batch``, made into a
``DanceConfig`` in one place."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import click

from .defaults import DEFAULT_FPS, MAX_SONG_S, SEGMENT_S
from .errors import InputError

_OPTIONS = [
    click.option("--style", help="Style or genre to dance (see 'dancesynth styles'); default: best tempo match."),
    click.option("--engine", type=click.Choice(["streaming", "global", "neural", "choreography"]), default=None,
                 help="streaming (default): segment by segment as music arrives (Xu et al.); global: whole-song "
                      "DP baseline; choreography: motifs by eq. (5) danced with mocap words (Aristidou et al.)."),
    click.option("--recreate", type=click.Path(dir_okay=False, path_type=Path),
                 help="Re-create this BVH dance's motif sequence on SONG (implies --engine choreography)."),
    click.option("--motif-at", "motif_at", multiple=True, metavar="SECONDS=MOTIF",
                 help="Dance MOTIF (e.g. M17) on the beat at SECONDS; repeatable (implies --engine choreography)."),
    click.option("--follow-signature", is_flag=True,
                 help="Streaming engine: also keep the genre's motif signature (Aristidou et al.'s global "
                      "structure)."),
    click.option("--repeat", type=click.Choice(["same", "mirror", "vary", "off"]), default="off",
                 show_default=True,
                 help="The song's form: a returning section or phrase replays the moves danced the first time "
                      "(same), their mirror image (mirror), its first bars with the rest new (vary, see --vary), "
                      "or is danced afresh (off, the default until its costs are mended: docs/form.md). With same, "
                      "mirror or vary, sections heard for the first time prefer new moves."),
    click.option("--vary", type=float, default=0.5, show_default=True, metavar="SHARE",
                 help="With --repeat vary: the share of each replayed phrase's bars danced anew (0 = same, 1 = new)."),
    click.option("--segment-seconds", type=float, default=SEGMENT_S, show_default=True,
                 help="Streaming segment length."),
    click.option("--lookahead", "lookahead", type=float, default=0.0, show_default=True, metavar="SECONDS",
                 help="Streaming: choose each segment seeing this much of the music after it; the dance follows "
                      "the music's loudness more closely, its feet slide a little more (docs/accents.md)."),
    click.option("--fps", type=float, default=DEFAULT_FPS, show_default=True, help="Frame rate of the output."),
    click.option("--seed", type=int, default=None, help="Vary the dance between runs (default: deterministic)."),
    click.option("--model", type=click.Path(dir_okay=False, path_type=Path),
                 help="Neural engine: dance with these weights (a .pt from 'dancesynth train'; implies --engine "
                      "neural). Default: the model shipped for the style's genre."),
    click.option("--database", type=click.Path(file_okay=False, path_type=Path),
                 help="A database folder or a folder of BVH files (default: the bundled database)."),
    click.option("--max-minutes", type=float, default=MAX_SONG_S / 60, show_default=True,
                 help="Refuse longer songs."),
    click.option("--ths", type=float, default=None, help="Eq. (1) threshold for transitions (default 3.0)."),
    click.option("--thr", type=float, default=None, help="Eq. (2) floor of a transition's weight, > 1 (default 1.5)."),
    click.option("--paper", is_flag=True,
                 help="Xu et al.'s graph and objective as printed: no repeat memory, jump cost, jump limits, "
                      "accent timing or accent costs, literal eq. (1). Still on: style and level choice, glitch "
                      "skipping, dead-end closing, the database's beats as built (snapped to the nearest stop), "
                      "loudness standardised by what has been heard, blends and foot lock (README: 'Where we "
                      "depart from or add to the paper'). With --engine neural: the network's motion without the "
                      "spread post-filter; its beat warp, foot lock and hand clearance stay on (docs/neural.md). "
                      "The song's form is not followed (--repeat off). "
                      "Not for --engine choreography, which has no paper preset."),
]

def dance_options(command):
    """Every option that shapes a dance (``--style`` ... ``--paper``, and ``--database``)."""
    for option in reversed(_OPTIONS):
        command = option(command)
    return command


def dance_config(*, style, engine, recreate, motif_at, follow_signature, segment_seconds, lookahead, fps, seed,
                 max_minutes, ths, thr, paper, model, repeat="off", vary=0.5):
    """The ``DanceConfig`` the options of ``dance_options`` ask for."""
    from .api import DanceConfig

    config = DanceConfig(style=style, engine=engine, segment_s=segment_seconds, lookahead_s=lookahead, fps=fps,
                         seed=seed, max_duration_s=max_minutes * 60.0, motif_at=motif_at, recreate=recreate,
                         follow_signature=follow_signature, model=model, repeat=repeat, vary=vary)
    from .engines.graph.engine import EngineConfig
    from .engines.graph.meta_graph import GraphConfig

    if paper:
        if config.engine == "choreography":
            raise InputError("--paper has no preset for the choreography engine (its mixer is Aristidou et al.'s "
                             "with the additions docs/choreography.md lists, which have no switch back): leave out "
                             "--paper, or use it with --engine streaming, global or neural")
        config = replace(config, graph=GraphConfig.paper(), render=EngineConfig.paper(), restore_spread=False,
                         repeat="off")
    if ths is not None or thr is not None:
        try:
            graph = replace(config.graph, **{k: v for k, v in (("ths", ths), ("thr", thr)) if v is not None})
        except InputError as exc:
            raise InputError(f"{exc}: check --ths and --thr") from None
        config = replace(config, graph=graph)
    return config


def form_line(form: dict) -> str:
    """The summary's line on the song's form: its sections, and what the dance replayed of them."""
    names = " ".join(f"{s['label']}:{s['name']}" for s in form["sections"])
    if form["repeat"] == "off":
        return f"{names}; --repeat off: danced without replaying"
    bars = sum(s.get("bars_replayed", 0) for s in form["sections"])
    total = sum(s["bars"] for s in form["sections"])
    line = f"{names}; --repeat {form['repeat']}: {bars} of {total} bars replay an earlier one"
    if form.get("replayed_share") is not None:
        line += f", {form['replayed_share']:.0%} of their beats danced as it was"
    return line + (f" ({form['note']})" if form.get("note") else "")

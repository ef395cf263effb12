"""Command line, characters: who dances (``dance --character``), the built-ins (``characters``), and
``dance -o dance.mp4``'s video."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from .cli_support import Progress, write_json


def character_options(command):
    """``--character`` and ``--bone-map``, the same on every command that writes or draws a dance."""
    command = click.option(
        "--bone-map", type=click.Path(dir_okay=False, path_type=Path),
        help="TOML file naming your character's humanoid bones ([bones] hips = \"pelvis\", ...) where the "
             "automatic mapping cannot.")(command)
    return click.option(
        "--character", default=None, metavar="NAME|FILE",
        help="Who dances: a built-in (see 'dancesynth characters'; default mannequin) or your rig/model as "
             ".bvh, .glb, .gltf or .vrm; 'source' keeps the skeleton the motion was made on.")(command)


def on_dance_character(clip, target):
    """``(clip on the character, the Character)`` for ``export.formats.output_character``'s choice."""
    from .retarget import SOURCE, on_character

    return on_character(clip, SOURCE if target is None else target)


def write_on_character(clip, target, output, *, song, report_path=None, report=None, quiet=False):
    """Write ``clip`` put on ``target`` (``export.formats.output_character``'s choice) in ``output``'s
    format, with the report if asked: both or neither. Returns ``(the clip on the character, the Character)``."""
    moved, target = on_dance_character(clip, target)
    write_moved(moved, target, output, song=song, report_path=report_path, report=report, quiet=quiet)
    return moved, target


def write_moved(moved, target, output, *, song, report_path=None, report=None, quiet=False) -> None:
    """``write_on_character`` for a clip already on its character."""
    from .export.formats import write_dance

    progress = Progress(enabled=not quiet and sys.stderr.isatty() and output.suffix.lower() == ".mp4")
    try:
        write_dance(output, moved, target, song=song, progress=lambda done, total: progress("render", done, total))
    finally:
        progress.close()
    if report is not None:
        try:   # the dance and the report both or neither
            write_json(report_path, report)
        except BaseException:
            output.unlink(missing_ok=True)
            raise


@click.command()
def characters():
    """List the built-in characters and rigs a dance can be put on (dance --character NAME)."""
    from .retarget.character import DEFAULT_CHARACTER, FILE_KINDS
    from .retarget.rigs import DESCRIPTIONS, rig_skeleton

    w = max(len(n) for n in DESCRIPTIONS) + 2
    click.echo(f"{'character':<{w}}{'joints':>7}  description")
    for name, text in DESCRIPTIONS.items():
        default = " (default)" if name == DEFAULT_CHARACTER else ""
        click.echo(f"{name:<{w}}{rig_skeleton(name)[0].n_joints:>7}  {text}{default}")
    click.echo(f"{'source':<{w}}{'':>7}  the skeleton the chosen style was captured on")
    click.echo("your own: --character FILE, one of " + ", ".join(f"{s} ({k})" for s, k in FILE_KINDS.items())
               + "; --bone-map FILE.toml names bones the automatic mapping misses")

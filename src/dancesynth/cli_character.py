"""Command line, characters: who dances (``dance --character``), the built-ins (``characters``), and
``dance -o dance.mp4``'s video."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from .cli_support import Progress, write_json
from .errors import InputError


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


def dance_character(spec, bone_map, suffix):
    """The character to dance (None: the source skeleton), checked before any work (a missing Blender, too)."""
    from .retarget import SOURCE
    from .retarget.character import DEFAULT_CHARACTER, load_character

    if suffix == ".fbx":
        from .export.fbx import find_blender

        find_blender()
    spec = spec or DEFAULT_CHARACTER
    if spec == SOURCE:
        if bone_map is not None:
            raise InputError("--bone-map names the bones of your own --character; it does not apply to 'source'")
        if suffix == ".vrma":
            raise InputError("a .vrma is made on a humanoid rig: leave out --character source")
        return None
    return load_character(spec, bone_map=bone_map)


def on_dance_character(clip, target):
    """``(clip on the character, the Character)`` for ``dance_character``'s choice."""
    from .retarget import SOURCE, on_character

    return on_character(clip, SOURCE if target is None else target)


def write_on_character(clip, target, output, *, song, report_path=None, report=None, quiet=False):
    """Write ``clip`` put on ``target`` (``dance_character``'s choice) in ``output``'s format, with the
    report if asked: both or neither. Returns ``(the clip on the character, the Character)``."""
    from .export.formats import encode_dance
    from .io.files import atomic_output

    moved, target = on_dance_character(clip, target)
    if output.suffix.lower() == ".mp4":
        _video(moved, target, song, output, report_path, report, quiet)
        return moved, target
    data = encode_dance(output.suffix.lower(), moved, target)
    with atomic_output(output, "wb") as fh:
        fh.write(data)
        if report is not None:
            write_json(report_path, report)
    return moved, target


def _video(clip, character, song, output, report_path, report, quiet):
    """``-o dance.mp4``: the dance rendered with the song, in one step."""
    from .export.video import render_video

    progress = Progress(enabled=not quiet and sys.stderr.isatty())
    try:
        render_video(clip, song, output, character=character,
                     progress=lambda done, total: progress("render", done, total))
    finally:
        progress.close()
    if report is not None:
        try:   # the video and the report both or neither
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

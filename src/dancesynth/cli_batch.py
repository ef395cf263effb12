"""Command line, ``batch``: dance a music library into a folder on a process pool or a Ray cluster."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from .cli_character import character_options
from .cli_dance import dance_config, dance_options
from .defaults import AUDIO_SUFFIXES
from .errors import InputError
from .export.formats import FORMATS

#: Exit code when the batch ran but some songs failed (their reasons are in the manifest).
SOME_FAILED = 1


@click.command()
@click.argument("songs", nargs=-1, type=click.Path(dir_okay=False, path_type=Path))
@click.option("--list", "list_file", type=click.Path(dir_okay=False, path_type=Path),
              help="A text file naming one song per line (relative paths: from the file's folder).")
@click.option("--folder", type=click.Path(path_type=Path), help="A music folder: every audio file in it and below.")
@click.option("-o", "--output", "out_dir", type=click.Path(path_type=Path), required=True,
              help="Folder for the dances (created) and manifest.jsonl; a folder's sub-folders are kept.")
@click.option("--format", "fmt", type=click.Choice([s.lstrip(".") for s in FORMATS]), default="bvh",
              show_default=True, help="What to write for each song (as 'dance -o' by extension).")
@click.option("--workers", type=click.IntRange(1, 4096), default=None,
              help="Worker processes (default: this machine's cores) or, with --ray, Ray actors (default: the "
                   "cluster's CPUs).")
@click.option("--ray", "ray", is_flag=False, flag_value="auto", default=None, metavar="[ADDRESS]",
              help="Run on a Ray cluster (pip install 'dancesynth[ray]'): the one started here with "
                   "'ray start --head', or the one at ADDRESS (HOST:PORT).")
@click.option("--threads", type=click.IntRange(1, 1024), default=None,
              help="torch and BLAS threads per worker (default: $DANCESYNTH_THREADS or 1).")
@character_options
@dance_options
@click.option("--eval", "evaluate", is_flag=True, help="Add each dance's metrics ('dancesynth eval') to the manifest.")
@click.option("--report", is_flag=True, help="Also write NAME.report.json (for 'dancesynth eval --report') beside "
                                              "each dance.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar and no summary; failures are still reported.")
def batch(songs, list_file, folder, out_dir, fmt, workers, ray, threads, character, bone_map, database, evaluate, report,
          quiet, **options):
    """Dance many songs into OUT_DIR: resumable (a re-run skips the songs already danced), one line per song in
    OUT_DIR/manifest.jsonl; a song that fails is recorded and the others go on (exit code 1 if any failed)."""
    from .batching import batch as run_batch

    if ray is not None and (Path(ray).suffix.lower() in AUDIO_SUFFIXES or Path(ray).is_file()):
        raise InputError(f"--ray took {ray!r} as the cluster's address: put --ray after the songs, or give the "
                         "address (--ray HOST:PORT)")
    show = not quiet and sys.stderr.isatty()
    bar = None

    def progress(record, finished, total):
        nonlocal bar
        if record["status"] == "failed":
            msg = f"failed: {record['song']}: {record.get('error', '')}"
            (bar.write(msg, file=sys.stderr) if bar is not None else click.echo(msg, err=True))
        if show:
            if bar is None:
                from tqdm import tqdm

                bar = tqdm(total=total, desc="dancing", unit="song", file=sys.stderr, dynamic_ncols=True)
            rate = 60.0 * bar.format_dict["n"] / max(bar.format_dict["elapsed"], 1e-9)
            bar.set_postfix_str(f"{rate:.1f} songs/min", refresh=False)
            bar.update(1)

    try:
        result = run_batch(songs, out_dir, list_file=list_file, folder=folder, format=fmt, character=character,
                           bone_map=bone_map, database=database, evaluate=evaluate, report=report, workers=workers,
                           ray=ray, threads=threads, config=dance_config(**options), progress=progress)
    finally:
        if bar is not None:
            bar.close()
    if not quiet:
        click.echo(f"danced    {result.done} song(s)" + (f", {result.failed} failed" if result.failed else "")
                   + (f", {result.skipped} already done (skipped)" if result.skipped else "")
                   + (f" in {result.seconds:.1f} s: {result.songs_per_min:.1f} songs/min" if result.seconds else ""))
        click.echo(f"wrote     {result.out_dir}/ (manifest: {result.manifest})")
    if result.failed:
        click.echo(f"error: {result.failed} song(s) failed; their reasons are above and in {result.manifest}",
                   err=True)
        raise click.exceptions.Exit(SOME_FAILED)

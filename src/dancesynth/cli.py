"""Command line: thin wrappers that parse, call one library function and report."""

from __future__ import annotations

import errno
import os
import sys
import time
from pathlib import Path

import click

from .cli_batch import batch
from .cli_character import character_options, characters, on_dance_character, write_moved, write_on_character
from .cli_dance import dance_config, dance_options, form_line
from .cli_live import render, serve, stream, vmc_listen
from .cli_support import Progress, writable, write_json
from .defaults import DEFAULT_FPS
from .errors import DanceSynthError, InputError


def _setup_env() -> None:
    from .io.files import stop_cleanly_on_sigterm, use_numba_cache
    from .threads import limit_threads

    use_numba_cache()
    limit_threads()  # before numpy loads: torch and BLAS at DANCESYNTH_THREADS (1) threads
    stop_cleanly_on_sigterm()


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="dancesynth")
def cli():
    """Make a 3D character dance to music."""


@cli.command()
@click.argument("song", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="File to write, by extension: .bvh, .glb (glTF, skinned character), .vrma (VRM Animation), "
                   ".fbx (needs Blender), .mp4 (video with the song). Default: the song's name with .bvh, here.")
@character_options
@dance_options
@click.option("--report", "report_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Also write a JSON report (beats, transitions, time warps) for 'dancesynth eval --report'.")
@click.option("-q", "--quiet", is_flag=True, help="No summary and no progress bar.")
def dance(song, output, character, bone_map, database, report_path, quiet, **options):
    """Make a beat-synchronised dance for SONG (wav, ogg, flac, mp3, ...) and write it for your character."""
    from .api import dance as make_dance
    from .export.formats import check_format, output_character

    output = output or Path(song.stem + ".bvh")
    suffix = check_format(output)
    writable(output, report_path)
    target = output_character(character, bone_map, suffix)
    config = dance_config(**options)
    progress = Progress(enabled=not quiet and sys.stderr.isatty())
    t0 = time.perf_counter()
    try:
        clip = make_dance(song, config=config, database=database, progress=progress)
    finally:
        progress.close()
    t = time.perf_counter()
    provenance = clip.provenance
    report = provenance.report() if report_path is not None else None
    moved, target = on_dance_character(clip, target)
    del clip   # the source motion (74 MB for 30 minutes) is not kept while the file is written
    write_moved(moved, target, output, song=song, report_path=report_path, report=report, quiet=quiet)
    s = provenance.summary
    write_s = time.perf_counter() - t
    for warning in s.get("warnings", ()):  # also with --quiet: the dance is not what the user may expect
        click.echo(f"warning: {warning}", err=True)
    if quiet:
        return
    tm = {**s["timings_s"], "write_s": write_s}
    note = " (no clear beat: dancing at a steady default tempo)" if s["default_tempo"] else ""
    click.echo(f"song      {song}  {s['duration_s']:.1f} s")
    click.echo(f"tempo     {s['tempo_bpm']:.1f} bpm, {s['beats']} beats{note}")
    level = s.get("level", "beat")
    warp = ""
    if s.get("in_range_expected") is not None:  # beat pieces played within the natural range of speeds
        lo, hi = s["rate_range"]
        done = f", {s['in_range_actual']:.0%} danced" if s.get("in_range_actual") is not None else ""
        warp = f"; beat pieces at {lo:g}-{hi:g}x their captured speed: {s['in_range_expected']:.0%} expected{done}"
    click.echo(f"style     {s['style']}, " + ("on the beat" if level == "beat" else f"at {level}") + warp)
    if s.get("style_reason"):
        click.echo(f"chosen    {s['style_reason']}")
    rep = s.get("repetition")
    if rep:
        mirrored = f" (+ {rep['mirrored_minutes']:.1f} mirrored)" if rep.get("mirrored_minutes") else ""
        form = f", the form's {rep['form_replays']} replayed beats aside" if rep.get("form_replays") else ""
        click.echo(f"material  {rep['material_minutes']:.1f} min captured{mirrored}; {rep['replayed_share']:.0%} of the "
                   f"beats replay a move danced in the previous {rep['window_s']:g} s{form} (longest run "
                   f"{rep['longest_repeat_beats']} beats)")
    if s.get("beats_per_bar"):
        period = s.get("dance_period_beats")
        click.echo(f"metre     {s['beats_per_bar']} beats per bar"
                   + (f"; the dance's energy repeats every {period} beats" if period else "")
                   + (f" (styles tried for it: {', '.join(s['styles_tried_for_metre'])})"
                      if s.get("styles_tried_for_metre") else ""))
    form = s.get("form")
    if form and form.get("sections"):
        click.echo("form      " + form_line(form))
    if s["engine"] == "streaming":
        ahead = f" (each chosen seeing {s['lookahead_s']:g} s ahead)" if s.get("lookahead_s") else ""
        click.echo(f"engine    streaming: {s['segments']} segment(s) of {s['segment_s']:g} s{ahead}, "
                   f"{s['transitions']} transitions, median {s['step_s_median'] * 1e3:.1f} ms per segment")
    else:  # the other engines see the whole song at once
        click.echo(f"engine    {s['engine']}: the whole song at once, {s['transitions']} transitions, "
                   f"{s['step_s_median'] * 1e3:.1f} ms")
    if s.get("motif_chi2") is not None:
        click.echo(f"motifs    chi2 to the {s['genre']} template {s['motif_chi2']:.3f}"
                   + (f", {s['plan_followed']:.0%} of beats as planned" if s.get("plan_followed") is not None else "")
                   + (f", {s['constraints']} constraint(s)" if s.get("constraints") else "")
                   + (f", re-creating {s['recreate']}" if s.get("recreate") else ""))
    if s.get("model_sha256"):
        spread = (f"spread post-filter up to {s['spread_cap']:g}x" if s.get("spread_cap", 1.0) > 1.0
                  else "the network alone")
        click.echo(f"model     {s['model_name']}, sha256 {s['model_sha256']}, {spread}: {s['model']}")
    # What the engine loaded or built before dancing: the graph, the motif bank, the network (engines/protocol.py).
    stage = s.get("prepare_stage", "preparation")
    cached = " (cached)" if s.get("graph_cached") else ""
    click.echo(f"time      music {tm['music_s']:.2f} s, database {tm['database_s']:.2f} s, {stage} "
               f"{tm['prepare_s']:.2f} s{cached}, synthesis "
               f"{tm['synthesis_s']:.2f} s, write {tm['write_s']:.2f} s; total {time.perf_counter() - t0:.2f} s")
    click.echo(f"wrote     {output} ({s['frames']} frames at {s['fps']:g} fps, on {target.name}"
               + (f", {moved.skeleton.n_joints} joints" if suffix != ".mp4" else "") + ")")


@cli.command()
@click.option("--database", type=click.Path(file_okay=False, path_type=Path),
              help="A database folder or a folder of BVH files (default: the bundled database).")
@click.option("--tempo-map", is_flag=True,
              help="For each tempo from 60 to 180 bpm: the styles that can dance it, at which level, with how many "
                   "minutes of material within 0.8-1.25x of their captured speed.")
@click.option("--step", type=click.IntRange(1, 60), default=5, show_default=True, help="Tempo step of --tempo-map.")
def styles(database, tempo_map, step):
    """List the styles of a dance database: tempo ranges, sizes and licences."""
    from .motion.catalog import list_styles

    if tempo_map:
        return print_tempo_map(database, step)
    rows = list_styles(database)
    ws = max(len("style"), *(len(r["name"]) for r in rows)) + 2
    wg = max(len("genre"), *(len(r["genre"]) for r in rows)) + 2
    click.echo(f"{'style':<{ws}}{'genre':<{wg}}{'tempo (bpm)':>12}{'clips':>7}{'minutes':>9}{'mirrored':>10}"
               f"{'beats':>7}{'joints':>8}  licence")
    for r in rows:
        tempo = f"{r['tempo_min_bpm']:.0f}-{r['tempo_max_bpm']:.0f}"
        click.echo(f"{r['name']:<{ws}}{r['genre']:<{wg}}{tempo:>12}{r['clips']:>7}{r['minutes']:>9.1f}"
                   f"{r['mirrored_minutes']:>10.1f}{r['beats']:>7}{r['joints']:>8}  {r['licence']}")
    total, mirrored = sum(r["minutes"] for r in rows), sum(r["mirrored_minutes"] for r in rows)
    click.echo(f"{len(rows)} styles, {total:.1f} minutes of captured dance"
               + (f" (and {mirrored:.1f} minutes of its mirrored takes)" if mirrored else ""))


def print_tempo_map(database, step: int) -> None:
    from .engines.beatgrid import MIN_MATERIAL_MINUTES, tempo_map
    from .motion.database import open_database

    rows = tempo_map(open_database(database), range(60, 181, step))
    click.echo(f"tempo  chosen (level, captured minutes of material)  styles with at least {MIN_MATERIAL_MINUTES:g} "
               "captured min there (+m: also danced mirrored)")
    for r in rows:
        chosen = f"{r['chosen']} ({r['chosen_level']}, {r['chosen_minutes']:.1f})"
        others = ", ".join(f"{x['style']} {x['level']} {x['minutes']:.1f}{'+m' if x['mirrored'] else ''}"
                           for x in r["styles"]) or "none"
        click.echo(f"{r['tempo_bpm']:>5.0f}  {chosen:<40} {others}")


@cli.command("build-db")
@click.argument("source", type=click.Path(file_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(file_okay=False, path_type=Path), required=True,
              help="Folder to write the database to.")
@click.option("--beats", type=click.Choice(["pca", "kinematic"]), default="pca", show_default=True,
              help="Motion beats by short-term PCA (Xu et al.) or by speed minima.")
@click.option("--snap", type=click.FloatRange(0.0, 0.5), default=0.15, show_default=True,
              help="Move PCA beats to a speed minimum within this fraction of a beat (0: regular PCA beats).")
@click.option("--manifest", type=click.Path(dir_okay=False, path_type=Path),
              help="A genres.toml mapping genres to file patterns (default: SOURCE/genres.toml or sub-folders).")
def build_db(source, output, beats, snap, manifest):
    """Analyse a folder of BVH files (one sub-folder per genre, or a genres.toml) into a database."""
    from .motion.database import AnalysisConfig, build_database, save_database
    from .motion.sources import collect_sources, manifest_options

    sources = collect_sources(source, manifest)
    options = manifest_options(source, manifest)
    with click.progressbar(length=len(sources), label="analysing", file=sys.stderr) as bar:
        db = build_database(sources, AnalysisConfig(beat_method=beats, snap_beats=snap),
                            progress=lambda _: bar.update(1), **options)
    db.source = str(source)
    save_database(db, output)
    click.echo(f"wrote {output}: {len(db.styles)} styles from {len(sources)} files")


@cli.command()
@click.argument("dance_path", metavar="DANCE.bvh", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--genre", help="Compare with this genre's template (default: the nearest template).")
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Write the motif sequence, signature and template as JSON.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Draw the motif sequence and the signature vs. the template to a PNG/PDF/SVG.")
@click.option("--database", type=click.Path(file_okay=False, path_type=Path),
              help="Motifs of this database (built once and cached; default: the shipped motifs).")
def motifs(dance_path, genre, json_path, plot_path, database):
    """Print a dance's motif sequence (at its kinematic beats) and its signature vs. its genre template."""
    from .eval.rigs import genre_motifs
    from .io.bvh import read_bvh
    from .motion.database import open_database
    from .motion.motifs import load_motif_model

    writable(json_path, plot_path)
    db = open_database(database)
    # Read on each genre's own skeleton, so the answer does not depend on the rig the dance was written on.
    result = genre_motifs(read_bvh(dance_path), load_motif_model(None if database is None else db), db, genre=genre)
    guess = " (nearest template; --genre to choose)" if result["genre_guessed"] else ""
    click.echo(f"{dance_path}: {result['duration_s']:.1f} s, {len(result['words'])} motion words, "
               f"{result['k']} motifs")
    click.echo(f"{'time (s)':>9}  motif")
    for w in result["words"]:
        click.echo(f"{w['start_s']:>9.2f}  {w['motif']}")
    click.echo(f"genre  {result['genre']}{guess}")
    click.echo(f"chi2 to the {result['genre']} template: {result['chi2']:.3f} "
               f"(others: {', '.join(f'{g} {v:.3f}' for g, v in result['chi2_by_genre'].items() if g != result['genre'])})")
    if json_path is not None:
        write_json(json_path, {"file": str(dance_path), **result})
        click.echo(f"wrote  {json_path}")
    if plot_path is not None:
        from .motion.motif_plot import plot_motifs

        plot_motifs(result, plot_path, title=f"{dance_path.name}: motif sequence")
        click.echo(f"wrote  {plot_path}")


@cli.command()
@click.argument("song", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Write the beats as JSON: {\"beats\": [seconds...], \"tempo\": bpm, \"downbeats\": [seconds...], "
                   "\"beats_per_bar\": 3 or 4, \"beat_in_bar\": [0 = downbeat...], \"bar\": [1...], "
                   "\"sections\": [{start_s, end_s, label, name, first_bar, bars}...], \"phrases\": {\"4\": [...], "
                   "\"8\": [...]}, ...}.")
@click.option("--tracker", default=None, help="Beat tracker (default: the product's, 'varying').")
def beats(song, json_path, tracker):
    """Print the beats and bars dancesynth hears in SONG (the beats `dance` lands motion beats on).

    Bars are numbered from 1 on the first beat; a new bar starts on every downbeat
    (so the beats of a pickup before the first downbeat are bar 1). Sections (verse,
    chorus, ...: the same letter plays the same music) start on downbeats.
    """
    from .music import DEFAULT_TRACKER, TRACKERS, analyze_music

    tracker = tracker or DEFAULT_TRACKER
    if tracker not in TRACKERS:
        raise InputError(f"unknown tracker {tracker!r}; choose one of {', '.join(sorted(TRACKERS))}")
    music = analyze_music(path=song, tracker=tracker, structure=True)
    downbeat = [int(p) == 0 for p in music.beat_in_bar]
    bar, number = [], 0 if downbeat[:1] == [True] else 1
    for d in downbeat:
        number += d
        bar.append(number)
    data = {"beats": [round(float(b), 4) for b in music.beat_times_s], "tempo": round(music.tempo_bpm, 2),
            "duration_s": round(music.duration_s, 3), "confidence": round(music.beat_confidence, 3),
            "default_tempo": bool(music.default_tempo), "tracker": tracker,
            "intensity_db": [round(float(v), 2) for v in music.intensity_db],
            "downbeats": [round(float(b), 4) for b in music.downbeat_times_s], "beats_per_bar": music.beats_per_bar,
            "beat_in_bar": music.beat_in_bar.tolist(), "bar": bar,
            "metre_confidence": round(float(music.meta["metre_confidence"]), 3)}
    first_bar = bar[downbeat.index(True)] if True in downbeat else 1
    data.update(music.structure.report(first_bar))
    if json_path is not None:
        write_json(json_path, data)
    note = " (no clear beat: a steady default tempo)" if music.default_tempo else ""
    click.echo(f"{song}: {music.duration_s:.1f} s, {music.tempo_bpm:.1f} bpm, {len(music.beat_times_s)} beats, "
               f"confidence {music.beat_confidence:.2f}{note}")
    click.echo(f"metre {music.beats_per_bar}/4 (confidence {music.meta['metre_confidence']:.2f}), "
               f"{bar[-1] if bar else 0} bars; '|' marks a downbeat")
    click.echo(" ".join(("| " if d else "") + f"{b:.3f}" for b, d in zip(music.beat_times_s, downbeat)))
    click.echo("sections: " + ", ".join(f"{x['label']} {x['name']} {x['start_s']:.1f} s ({x['bars']} bars)"
                                        for x in data["sections"]))


@cli.command("eval")
@click.argument("dance_path", metavar="DANCE.bvh", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("song", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--json", "json_path", type=click.Path(dir_okay=False, path_type=Path), help="Write every metric as JSON.")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Draw speed, kinematic beats and music beats (Aristidou et al. Fig. 7) to a PNG/PDF/SVG.")
@click.option("--plot-from", type=float, default=0.0, show_default=True,
              help="Start of the plotted window (seconds); the beats are unreadable over a whole song.")
@click.option("--plot-length", type=float, default=20.0, show_default=True,
              help="Length of the plotted window (seconds).")
@click.option("--reference", "reference_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Also evaluate this motion (e.g. real mocap) against the song, by the same code.")
@click.option("--style", help="Compare smoothness with this style's mocap (default: the report's or best match).")
@click.option("--report", "report_path", type=click.Path(dir_okay=False, path_type=Path),
              help="The dance's JSON from 'dancesynth dance --report' (adds transition and time-warp metrics).")
@click.option("--database", type=click.Path(file_okay=False, path_type=Path),
              help="The database the style comes from (default: the bundled one).")
def eval_(dance_path, song, json_path, plot_path, plot_from, plot_length, reference_path, style, report_path,
          database):
    """Measure a dance against its song: beat alignment, intensity, smoothness, foot contact, time warp."""
    from .eval.evaluate import format_table
    from .eval.report import beat_plot_data, evaluate_files, plot_beats

    writable(json_path, plot_path)
    if not (plot_from >= 0 and plot_length > 0):  # NaN too
        raise InputError(f"the plot window needs --plot-from >= 0 and --plot-length > 0 seconds, got "
                         f"{plot_from} and {plot_length}")
    result = evaluate_files(dance_path, song, reference_path=reference_path, report_path=report_path,
                            style=style, database=database)
    columns = {"dance": result["dance"]}
    if "reference" in result:
        columns["reference"] = result["reference"]
    s = result["song"]
    click.echo(f"song   {song}: {s['duration_s']:.1f} s, {s['tempo_bpm']:.1f} bpm, {s['beats']} beats")
    click.echo(f"mocap  {result['mocap_style'] or 'none with this skeleton (use --style)'}")
    click.echo(format_table(columns))
    if json_path is not None:
        write_json(json_path, result)
    if plot_path is not None:
        from .io.bvh import read_bvh
        from .music import analyze_music

        music = analyze_music(path=song)
        data = beat_plot_data(read_bvh(dance_path), music.beat_times_s)
        if plot_from >= music.duration_s:
            raise InputError(f"--plot-from {plot_from:g} s is past the song's end ({music.duration_s:.1f} s)")
        window = (plot_from, min(plot_from + plot_length, music.duration_s))
        plot_beats(data, plot_path, title=f"{dance_path.name}: speed, kinematic beats, music beats",
                   window_s=window)
        click.echo(f"wrote  {plot_path} ({window[0]:.1f}-{window[1]:.1f} s of {music.duration_s:.1f} s; "
                   "--plot-from and --plot-length choose the window)")


@cli.command()
@click.option("--quick", is_flag=True, help="A smaller run (under 2 minutes).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), default=Path("bench-results"),
              show_default=True, help="Folder for bench.json.")
def bench(quick, out_dir):
    """Benchmarks: synthesis time (Xu Fig. 4), scaling, quality table, beat tracking on generated songs."""
    from .bench.run import format_bench, run_bench
    from .io.files import output_folder

    output_folder(out_dir, "bench.json")
    result = run_bench(quick=quick, out_dir=out_dir, progress=lambda msg: click.echo(msg, err=True))
    click.echo(format_bench(result))
    click.echo(f"wrote {out_dir / 'bench.json'}")


MIN_TRAIN_MINUTES, MAX_TRAIN_MINUTES = 0.1, 7 * 24 * 60.0


@cli.command()
@click.option("--style", default="salsa", show_default=True, help="Style or genre to learn (see 'dancesynth styles').")
@click.option("--config", "config_name", type=click.Choice(["tiny", "small", "paper"]), default="small",
              show_default=True, help="Model size: small (the shipped model) trains on a 2-core laptop CPU in about "
              "7 minutes, paper is Aristidou et al.'s (a GPU).")
@click.option("--device", type=click.Choice(["cpu", "cuda"]), default="cpu", show_default=True)
@click.option("--steps", type=click.IntRange(min=1, max=10_000_000), default=None,
              help="Training steps (default: the config's). Same data, steps and seed give the same weights.")
@click.option("--minutes", type=float, default=None,
              help="Stop after this many minutes even if steps remain (then the result depends on the machine).")
@click.option("--out", "out_dir", type=click.Path(path_type=Path),
              help="Folder (or .pt file) for the weights (default: the user cache). Dance with them: --model PATH.")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True)
@click.option("--database", type=click.Path(file_okay=False, path_type=Path),
              help="A database folder or a folder of BVH files (default: the bundled database).")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar.")
def train(style, config_name, device, steps, minutes, out_dir, seed, database, quiet):
    """Train the learned pose generator of '--engine neural' (Aristidou et al. §4) on one genre.

    Writes the weights (.pt), a summary (.json) and the training and held-out loss curve (.png).
    """
    from .engines.neural.train import train as run_training

    if minutes is not None and not MIN_TRAIN_MINUTES <= minutes <= MAX_TRAIN_MINUTES:  # NaN too
        raise InputError(f"--minutes must be from {MIN_TRAIN_MINUTES:g} (a few steps) to {MAX_TRAIN_MINUTES:g} "
                         f"(a week), got {minutes:g}")
    bar = None
    if not quiet and sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=None, desc="training", unit="step", leave=False, file=sys.stderr, dynamic_ncols=True)

    def progress(step, total, loss):
        if bar is not None:
            bar.total = total
            bar.update(step - bar.n)
            bar.set_postfix(loss=f"{loss:.3f}")

    try:
        info = run_training(style, config_name, device=device, steps=steps, minutes=minutes, out=out_dir, seed=seed,
                            database=database, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    last = info["curve"][-1]
    held = f", held-out {last['held_out_loss']:.3f}" if "held_out_loss" in last else ""
    click.echo(f"trained   {info['config']['name']} on {info['clips']} clips ({info['sequences']} sequences with "
               f"speed and mirror copies, {info['frames']} frames), {info['steps']} steps in {info['train_s']:.0f} s "
               f"on {info['device']}")
    click.echo(f"loss      {info['first_loss']:.3f} -> {info['final_loss']:.3f}{held}")
    click.echo(f"wrote     {info['path']}")
    click.echo(f"curve     {info['plot']}")
    click.echo(f"dance     with it: dancesynth dance SONG --model {info['path']} (the shipped model stays the default)")


@cli.command()
@click.argument("song", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="File to write, as for 'dance': .bvh, .glb, .vrma, .fbx or .mp4 (default: SONG.bvh).")
@character_options
@click.option("--melody-track", type=int, help="MIDI part that carries the melody (see --list-tracks).")
@click.option("--rhythm-track", type=int, help="MIDI part that gives the beats (default: drums, else the bass).")
@click.option("--style", help="A look: default, e1, e2, calm, lively.")
@click.option("--config", "config_path", type=click.Path(dir_okay=False, path_type=Path),
              help="TOML file of parameters (style = \"calm\", l1 = 0.3, ...); see docs/procedural.md.")
@click.option("--param", "params", multiple=True, metavar="NAME=VALUE", help="Override one parameter (repeatable).")
@click.option("--fps", type=float, default=None, help=f"Frame rate of the output (default {DEFAULT_FPS:g}).")
@click.option("--list-tracks", is_flag=True, help="List the MIDI parts and the ones chosen, then stop.")
@click.option("-q", "--quiet", is_flag=True, help="No summary.")
def conduct(song, output, character, bone_map, melody_track, rhythm_track, style, config_path, params, fps,
            list_tracks, quiet):
    """Upper-body motion drawing SONG's melody and marking its beats (Loi & Li); SONG: MIDI or a recording."""
    from .api import conduct as make_motion
    from .engines.procedural import make_config
    from .engines.procedural.report import parts_lines, summary_lines
    from .export.formats import check_format, output_character

    if list_tracks:
        return click.echo("\n".join(parts_lines(song)))
    output = output or Path(song.stem + ".bvh")
    suffix = check_format(output)
    writable(output)
    target = output_character(character, bone_map, suffix)
    cfg = make_config(style=style, config_path=config_path, params=params, fps=fps)
    clip = make_motion(song, config=cfg, melody_track=melody_track, rhythm_track=rhythm_track)
    write_on_character(clip, target, output, song=song, quiet=quiet)
    if not quiet:
        click.echo("\n".join(summary_lines(clip.provenance.summary, output)))


for _command in (stream, render, serve, vmc_listen, characters, batch):  # in cli_live.py, cli_character.py, cli_batch.py
    cli.add_command(_command)


def main(argv=None) -> int:
    try:
        _setup_env()
        code = cli.main(args=argv, prog_name="dancesynth", standalone_mode=False)
        if isinstance(code, int) and not isinstance(code, bool):  # click.exceptions.Exit(code), e.g. batch's
            return code
    except click.exceptions.Abort:
        click.echo("interrupted", err=True)
        return 130
    except click.ClickException as exc:
        exc.show()
        return exc.exit_code
    except InputError as exc:
        click.echo(f"error: {exc}", err=True)
        return 2
    except DanceSynthError as exc:
        click.echo(f"error: {exc}", err=True)
        return 1
    except KeyboardInterrupt:
        click.echo("interrupted", err=True)
        return 130
    except OSError as exc:
        if exc.errno not in _FULL_DISK:
            return _internal_error(exc)
        # A full disk met outside our own outputs (a library's cache, a temporary file): the same to a user.
        what = exc.filename or "a cache or temporary file (DANCESYNTH_DEBUG=1 shows which)"
        click.echo(f"error: cannot write {what}: {exc.strerror}; free some disk space", err=True)
        return 2
    except Exception as exc:
        return _internal_error(exc)
    return 0


_FULL_DISK = {errno.ENOSPC, errno.EFBIG, errno.EDQUOT}


def _internal_error(exc: Exception) -> int:
    """Never a traceback for users; one line, and how to get more."""
    if os.environ.get("DANCESYNTH_DEBUG"):
        raise exc
    click.echo(f"internal error: {type(exc).__name__}: {exc} (please report it; set DANCESYNTH_DEBUG=1 "
               "for the traceback)", err=True)
    return 70


if __name__ == "__main__":
    sys.exit(main())

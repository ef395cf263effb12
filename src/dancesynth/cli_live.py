"""Command line, live and viewing: ``stream`` (a dance as music arrives), ``render`` (MP4), ``serve`` (web page)."""

from __future__ import annotations

import signal
import sys
import threading
from pathlib import Path

import click

from .cli_character import character_options
from .cli_support import Progress, bvh_output
from .errors import InputError
from .defaults import DEFAULT_FPS, SEGMENT_S


@click.command()
@click.argument("source")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="BVH file that grows as the dance goes (a valid BVH after every segment); default live.bvh, "
                   "none with --vmc unless given.")
@click.option("--vmc", metavar="HOST:PORT",
              help="Also send the dance live over the VMC protocol to an avatar app (VSeeFace, VNyan, Warudo, "
                   "3tene, VirtualMotionCapture, EVMC4U...): usually 127.0.0.1:39539.")
@click.option("--segment-seconds", type=float, default=None, help=f"Length of a segment (default {SEGMENT_S:g}).")
@click.option("--latency", type=float, default=None, metavar="SECONDS",
              help="The longest wait from a beat heard to its move (plus the few ms of its synthesis), at least 1 s: "
                   "the segment length, so a shorter wait sees less music ahead when the moves are chosen "
                   f"(they follow its loudness less). Default: {SEGMENT_S:g} s.")
@click.option("--style", help="Style or genre to dance (default: chosen from the first segment's tempo).")
@click.option("--fps", type=float, default=DEFAULT_FPS, show_default=True, help="Frame rate of the output.")
@click.option("--seed", type=int, default=None, help="Vary the dance between runs.")
@click.option("--database", type=click.Path(file_okay=False, path_type=Path),
              help="A database folder or a folder of BVH files (default: the bundled database).")
@click.option("--follow-signature", is_flag=True, help="Also keep the genre's motif signature as the dance goes.")
@click.option("--repeat", type=click.Choice(["same", "mirror", "vary", "off"]), default="off", show_default=True,
              help="When the music repeats what was heard (two bars like two earlier ones), dance again what was "
                   "danced then: the same moves, their mirror image, its phrases' first bars (vary), or not (off).")
@click.option("--vary", type=float, default=0.5, show_default=True, metavar="SHARE",
              help="With --repeat vary: the share of each replayed phrase's bars danced anew.")
@click.option("--fast", is_flag=True, help="Read a file as fast as it decodes instead of at real-time pace.")
@character_options
@click.option("-q", "--quiet", is_flag=True, help="Only the summary, no line per segment.")
def stream(source, output, vmc, segment_seconds, latency, style, fps, seed, database, follow_signature, repeat, vary,
           fast, character, bone_map, quiet):
    """Dance to SOURCE as it arrives: an audio file (played at real-time pace), '-' for standard input,
    an http(s) URL of an audio stream, 'system' (what this computer plays), 'mic' (its default input), or
    pulse:NAME / alsa:NAME (a named sound source). Motion is synthesised segment by segment (Xu et al.'s
    double buffer) and appended to the BVH as it goes, and with --vmc sent to an avatar app as it plays.
    Ctrl-C ends the dance with the segment being heard (twice: at once)."""
    from .live.output import LiveSinks
    from .live.runtime import LiveConfig, run_live
    from .live.sources import AudioSource, broke_off

    from .retarget import SOURCE, SegmentRetargeter
    from .retarget.character import DEFAULT_CHARACTER, load_character

    segment_seconds = segment_length(segment_seconds, latency)
    if output is None and vmc is None:
        output = Path("live.bvh")
    if output is not None:
        bvh_output(output)
    address = None
    if vmc is not None:
        from .live.vmc import parse_address

        address = parse_address(vmc)
        if (character or DEFAULT_CHARACTER) == SOURCE:
            raise InputError("--vmc sends a humanoid avatar's bones: leave out --character source")
    if (character or DEFAULT_CHARACTER) == SOURCE:
        on_character = None
    else:
        on_character = SegmentRetargeter(load_character(character or DEFAULT_CHARACTER, bone_map=bone_map))

    def report(r):
        sinks.on_report(r)
        if not quiet:
            click.echo(f"segment {r.index + 1:3d}  heard {r.audio_end_s:7.2f} s  {r.beats:3d} beats  motion "
                       f"{r.motion_start_s:6.2f}-{r.motion_end_s:6.2f} s  step {r.process_s * 1e3:6.1f} ms "
                       f"({100 * r.process_s / r.segment_s:4.1f}% of {r.segment_s:g} s)"
                       f"{'  LATE' if r.late else ''}  ready at {r.ready_s:6.2f} s")

    config = LiveConfig(segment_s=segment_seconds, style=style, fps=fps, seed=seed, database=database,
                        follow_signature=follow_signature, repeat=repeat, vary=vary)
    stop = threading.Event()

    def on_interrupt(signum, frame):   # the first Ctrl-C ends the dance as the source's end would
        if stop.is_set():
            raise KeyboardInterrupt
        stop.set()
        click.echo("stopping: the dance ends with this segment (Ctrl-C again to quit at once)", err=True)

    previous = signal.signal(signal.SIGINT, on_interrupt)
    try:
        with AudioSource(source, realtime=not fast) as src, LiveSinks(output, address, on_character, fps,
                                                                               segment_seconds) as sinks:
            summary = run_live(src, sinks.append, config=config, on_report=report, realtime=not fast, stop=stop)
    finally:
        signal.signal(signal.SIGINT, previous)
    if summary["frames"] == 0:
        raise InputError(f"{source}: the stream ended before a single segment could be danced")
    died = broke_off(src)
    click.echo(f"style     {summary['style']}, {summary['tempo_bpm']:.1f} bpm")
    click.echo(f"segments  {summary['segments']} of {segment_seconds:g} s, step median "
               f"{summary['step_s_median'] * 1e3:.1f} ms, max {summary['step_s_max'] * 1e3:.1f} ms, "
               f"{summary['late_segments']} late")
    delays = (f"; a beat's move ready {summary['beat_delay_s_median']:.2f} s after the beat (median), at most "
              f"{summary['beat_delay_s_max']:.2f} s" if summary["beat_delay_s_max"] is not None else "")
    click.echo(f"latency   first motion ready {summary['first_motion_ready_s']:.2f} s after start "
               f"({summary['first_audio_s']:.2f} s of audio heard){delays}"
               + (f"; {summary['silence_s']:.1f} s of stalls bridged" if summary["silence_s"] > 0 else ""))
    if summary["motif_chi2"] is not None:
        click.echo(f"motifs    chi2 to the genre template {summary['motif_chi2']:.3f}")
    form = summary["form"]
    if form["repeat"] != "off":
        heard = ", ".join(f"bar {b + 1} repeats bar {a + 1}" for b, a in form["repeats"]) or "no repeat heard"
        share = f", {form['replayed_share']:.0%} of them as first danced" if form.get("replayed_share") is not None \
            else ""
        click.echo(f"form      {heard}; {form['replay_beats']} beats replayed{share}; sections heard at bars "
                   + " ".join(str(b + 1) for b in form["section_bars"]))
    if sinks.vmc is not None:
        v = sinks.vmc.stats()
        behind = f"{sinks.vmc.delay_s:.2f} s (whole bars) behind" if sinks.vmc.delay_s is not None else "behind"
        click.echo(f"vmc       the avatar danced {behind} the music; "
                   f"{v['bundles']} frames sent to {vmc} ({v['on_time']:.1%} within a frame of their time, "
                   f"{v['held']} held while a segment was late, {v['lost']} lost by the socket"
                   + (f", {v['skipped']} skipped while the sender was held up" if v["skipped"] else "") + ")")
    if output is not None:
        click.echo(f"wrote     {output} ({summary['frames']} frames at {fps:g} fps)")
    if died:  # the BVH is complete up to there; the user must still learn that the source died
        raise InputError(f"{died}" + (f"; {output} holds the dance up to then" if output is not None else ""))


@click.command("vmc-listen")
@click.option("--port", type=click.IntRange(1, 65535), default=39539, show_default=True,
              help="UDP port to listen on (127.0.0.1).")
@click.option("--seconds", type=click.FloatRange(min=0.1), default=None,
              help="Stop after this long (default: at Ctrl-C).")
def vmc_listen(port, seconds):
    """Listen for VMC messages on 127.0.0.1:PORT and say, once a second, what arrives: a check of what
    `stream --vmc` (or any VMC sender) sends, without an avatar app."""
    import time

    from .live.vmc_receiver import VmcReceiver

    try:
        rx = VmcReceiver(port)
    except OSError as exc:
        raise InputError(f"cannot listen on 127.0.0.1:{port} ({exc.strerror or exc}); is an app using it?") from None
    click.echo(f"listening on 127.0.0.1:{rx.port}; Ctrl-C to stop")
    end = None if seconds is None else time.monotonic() + seconds
    seen = 0
    try:
        while end is None or time.monotonic() < end:
            time.sleep(1.0 if end is None else max(0.0, min(1.0, end - time.monotonic())))
            n = len(rx.frames)
            if n > seen:
                last = rx.frames[-1]
                click.echo(f"{n - seen} frames in the last second; t = {last.t:.2f} s, {len(last.bones)} bones, "
                           f"e.g. {', '.join(list(last.bones)[:3])}")
                seen = n
    except KeyboardInterrupt:
        pass
    finally:
        rx.close()
    click.echo(f"{seen} frames in all")


def segment_length(segment_seconds: float | None, latency: float | None) -> float:
    """The segment length ``stream`` dances with: given, or made from ``--latency``, or the default."""
    if latency is None:
        return SEGMENT_S if segment_seconds is None else segment_seconds
    if segment_seconds is not None:
        raise InputError("give --latency or --segment-seconds, not both (--latency sets the segment length)")
    if not latency >= 1.0:   # NaN too
        raise InputError(f"--latency {latency:g}: at least 1 s (a segment of 1 s)")
    return latency


@click.command()
@click.argument("dance_path", metavar="DANCE.bvh", type=click.Path(dir_okay=False, path_type=Path))
@click.argument("song", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              help="MP4 to write (default: the dance's name with .mp4, here).")
@click.option("--width", type=int, default=960, show_default=True)
@click.option("--height", type=int, default=540, show_default=True)
@click.option("--fps", type=float, default=None, help="Video frame rate (default: the dance's).")
@character_options
@click.option("--figure", type=click.Choice(["character", "stick"]), default="character", show_default=True,
              help="Draw the character's skinned mesh, or a stick figure of the dance's own skeleton.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar.")
def render(dance_path, song, output, width, height, fps, character, bone_map, figure, quiet):
    """Render DANCE.bvh as an MP4 video (H.264) with SONG muxed in sync (AAC)."""
    from .export.video import render_video_files
    from .retarget import on_character
    from .retarget.character import DEFAULT_CHARACTER, load_character

    output = output or Path(dance_path.stem + ".mp4")
    target = None
    if figure == "character" or character is not None:   # loaded first: a bad character fails before work
        target = load_character(character or DEFAULT_CHARACTER, bone_map=bone_map)

    def dress(clip):
        if target is None:
            return clip, None
        try:
            return on_character(clip, target)
        except InputError:
            if character is not None:
                raise
            return clip, None   # a dance with no humanoid skeleton (no legs, say): drawn as it is

    progress = Progress(enabled=not quiet and sys.stderr.isatty())
    try:
        info = render_video_files(dance_path, song, output, width=width, height=height, fps=fps, dress=dress,
                                  figure=figure, progress=lambda done, total: progress("render", done, total))
    finally:
        progress.close()
    drawn = f"the {target.name}" if info.get("figure") == "character" and target is not None else "a stick figure"
    click.echo(f"wrote {output}: {drawn}, {info['frames']} frames at {info['fps']:g} fps, {info['duration_s']:.1f} s, "
               f"rendered in {info['seconds']:.1f} s")


@click.command()
@click.option("--host", default="127.0.0.1", show_default=True,
              help="Address to listen on (127.0.0.1: this machine only; 0.0.0.0: every network).")
@click.option("--port", type=click.IntRange(1, 65535), default=8000, show_default=True, help="Port to listen on.")
@click.option("--database", type=click.Path(file_okay=False, path_type=Path),
              help="A database folder or a folder of BVH files (default: the bundled database).")
@click.option("--max-upload-mb", type=click.FloatRange(min=0.1), default=50.0, show_default=True,
              help="Refuse uploaded songs larger than this.")
def serve(host, port, database, max_upload_mb):
    """A web page to watch the character dance: open http://HOST:PORT/ in a browser."""
    from .web.server import serve as run_server

    run_server(host=host, port=port, database=database, max_upload_mb=max_upload_mb)

"""Benchmark of `dancesynth render`: MP4 frames per second with the stick figure and the skinned mannequin.

    .venv/bin/python benchmarks/render_speed.py [--seconds 20] [--sizes 960x540,1920x1080] [--repeat 1]
                                                [--out benchmarks/results]

A fixed dance: the first ``--seconds`` of a bundled song, danced from the bundled
database with a fixed seed and retargeted onto the built-in mannequin. Each size and
figure is rendered once, end to end as ``render_video`` does it (camera planning,
skinning, drawing, H.264 + AAC encoding by ffmpeg with the song excerpt muxed in).
The table gives frames rendered per second of wall time and the multiple of real time
(video seconds per wall second; 1.0 = real time), plus the CPU seconds of Python (the
renderer) and of ffmpeg (running beside it): on a busy machine the wall time suffers
and the CPU times say where the work went. The load average is recorded for that reason,
and ``--repeat N`` renders each row N times, interleaved, and keeps the fastest.

Prints a table and writes ``render_speed.json`` into the output folder.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SONG = REPO / "src" / "dancesynth" / "data" / "music" / "Kevin_MacLeod_-_Vibe_Ace.ogg"
SEED = 7
FIGURES = ("stick", "character")


def make_dance(seconds: float, tmp: Path):
    """The song's first ``seconds`` as a WAV, and the mannequin dancing to it."""
    import soundfile as sf

    import dancesynth
    from dancesynth.retarget.mannequin import mannequin_character
    from dancesynth.retarget.solve import retarget

    sr = sf.info(str(SONG)).samplerate
    y, sr = sf.read(str(SONG), frames=int(seconds * sr))
    excerpt = tmp / "excerpt.wav"
    sf.write(excerpt, y, sr)
    character = mannequin_character()
    return excerpt, retarget(dancesynth.dance(excerpt, seed=SEED), character), character


def children_cpu() -> float:
    use = resource.getrusage(resource.RUSAGE_CHILDREN)
    return use.ru_utime + use.ru_stime


def bench(clip, song: Path, character, figure: str, width: int, height: int, out: Path) -> dict:
    from dancesynth.export import render_video

    cpu, ffmpeg = time.process_time(), children_cpu()
    info = render_video(clip, song, out, width=width, height=height, character=character, figure=figure)
    return {"figure": info["figure"], "width": width, "height": height, "frames": info["frames"],
            "video_s": info["duration_s"], "wall_s": info["seconds"], "fps": info["frames"] / info["seconds"],
            "x_realtime": info["duration_s"] / info["seconds"], "python_cpu_s": time.process_time() - cpu,
            "ffmpeg_cpu_s": children_cpu() - ffmpeg, "mp4_bytes": out.stat().st_size}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=20.0, help="length of the dance (default 20)")
    ap.add_argument("--sizes", default="960x540,1920x1080", help="comma-separated WIDTHxHEIGHT (default %(default)s)")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    ap.add_argument("--repeat", type=int, default=1, help="render each row this many times, keep the fastest")
    ap.add_argument("--keep", type=Path, help="also keep the videos in this folder")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(REPO / "src"))
    from dancesynth.export import video
    from dancesynth.io.files import atomic_output

    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    load_before = os.getloadavg()
    best = {}
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        song, clip, character = make_dance(args.seconds, tmp)
        for _ in range(max(1, args.repeat)):
            for width, height in sizes:
                for figure in FIGURES:
                    folder = args.keep or tmp
                    folder.mkdir(parents=True, exist_ok=True)
                    row = bench(clip, song, character, figure, width, height,
                                folder / f"{figure}_{width}x{height}.mp4")
                    key = (figure, width, height)
                    if key not in best or row["wall_s"] < best[key]["wall_s"]:
                        best[key] = row
                    print(f"  {figure} {width}x{height}: {row['fps']:.1f} fps", file=sys.stderr)
    rows = list(best.values())
    load_after = os.getloadavg()

    print(f"render speed: {clip.n_frames} frames ({clip.duration_s:.1f} s at {clip.fps:g} fps), "
          f"{os.cpu_count()} CPUs, load average {load_before[0]:.2f} before, {load_after[0]:.2f} after"
          + (f", fastest of {args.repeat}" if args.repeat > 1 else ""))
    print(f"{'figure':<10} {'size':>10} {'frames':>7} {'wall s':>7} {'fps':>6} {'x real time':>12} "
          f"{'python cpu s':>13} {'ffmpeg cpu s':>13}")
    for r in rows:
        print(f"{r['figure']:<10} {r['width']:>5}x{r['height']:<4} {r['frames']:>7} {r['wall_s']:>7.1f} "
              f"{r['fps']:>6.1f} {r['x_realtime']:>12.2f} {r['python_cpu_s']:>13.1f} {r['ffmpeg_cpu_s']:>13.1f}")
    args.out.mkdir(parents=True, exist_ok=True)
    result = {"machine": {"python": platform.python_version(), "processor": platform.processor(),
                          "system": platform.platform(), "cpus": os.cpu_count(),
                          "load_average_before": load_before, "load_average_after": load_after},
              "dance": {"song": SONG.name, "seconds": clip.duration_s, "frames": clip.n_frames, "fps": clip.fps,
                        "seed": SEED, "character": character.name,
                        "mesh_triangles": int(len(character.mesh.indices))},
              "encoder": {"codec": "libx264", "preset": video.X264_PRESET, "params": video.X264_PARAMS,
                          "crf": video.X264_CRF, "input_pix_fmt": "yuv420p"},
              "repeat": max(1, args.repeat), "runs": rows}
    with atomic_output(args.out / "render_speed.json") as fh:
        json.dump(result, fh, indent=1)
        fh.write("\n")
    print(f"\nwrote {args.out / 'render_speed.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

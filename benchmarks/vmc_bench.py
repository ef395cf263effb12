"""The live dance over VMC, measured as an avatar app receives it.

    .venv/bin/python benchmarks/vmc_bench.py [--seconds 60] [--out benchmarks/results]

A song streamed at real-time pace (the bundled *Vibe Ace*, as ``dancesynth stream SONG --vmc``
plays it: the same runtime, the default character) to a VMC receiver on 127.0.0.1 written from
the protocol's specification (``dancesynth.live.vmc_receiver``). Prints and writes to
``vmc_bench.json``:

- frames sent and received, in order, held while a segment was late, lost by the socket;
- on time: the share of frames that reached the receiver within one frame period of the time
  the sender's clock gave them, and the lateness's median, 99th percentile and maximum;
- agreement: the receiver's rebuilt pose (every humanoid bone's position, from the local
  transforms it was sent) against our forward kinematics of the frame shown, the largest
  difference over every frame not blended out of a hold.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
SONG = REPO / "src" / "dancesynth" / "data" / "music" / "Kevin_MacLeod_-_Vibe_Ace.ogg"


def measure(seconds: float) -> dict:
    from dancesynth.live.output import LiveSinks
    from dancesynth.live.runtime import LiveConfig, run_live
    from dancesynth.live.sources import AudioSource
    from dancesynth.live.vmc import VmcFrames
    from dancesynth.live.vmc_receiver import VmcReceiver, expected_positions, world_positions
    from dancesynth.retarget import SegmentRetargeter
    from dancesynth.retarget.character import load_character

    character = load_character("mannequin")
    with tempfile.TemporaryDirectory() as tmp:
        song = Path(tmp) / "song.wav"
        subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-t", str(seconds), "-i", str(SONG), "-ac", "1",
                        str(song)], check=True)
        dressed = []
        retarget = SegmentRetargeter(character)

        class Kept:   # the sinks' retargeter, keeping the clips it dresses for the agreement check
            character = retarget.character

            def __call__(self, clip):
                dressed.append(retarget(clip))
                return dressed[-1]

        with VmcReceiver() as rx:
            t0 = time.perf_counter()
            with AudioSource(str(song), realtime=True) as src, \
                    LiveSinks(None, ("127.0.0.1", rx.port), Kept(), 30.0, 5.0) as sinks:
                summary = run_live(src, sinks.append, config=LiveConfig(), realtime=True, on_report=sinks.on_report)
            rx.wait_for(len(sinks.vmc.log), 5.0)
            wall = time.perf_counter() - t0
        tx = sinks.vmc
    log = tx.log
    got = rx.frames
    # Frames pair with the log by their clock time (/VMC/Ext/T = tick / fps).
    tick_of = {round(f.t * tx.fps): f for f in got}
    late = np.array([tick_of[k].arrived - due for k, (_, due, _) in enumerate(log) if k in tick_of])
    shown = [s for s, *_ in log]
    # Agreement, away from the blends out of a hold.
    from dancesynth.types import MotionClip

    whole = MotionClip(dressed[0].skeleton, dressed[0].fps, np.concatenate([c.root_pos for c in dressed]),
                       np.concatenate([c.local_rot for c in dressed]))
    truth, parent = expected_positions(whole, character.bones)
    names = VmcFrames.of(whole.frames(0, 1), character.bones).names
    err, since_hold = 0.0, tx.blend + 1
    for k, s in enumerate(shown):
        since_hold = 0 if s < 0 else since_hold + 1
        if s >= 0 and since_hold > tx.blend and k in tick_of:
            err = max(err, float(np.abs(world_positions(tick_of[k], names, parent) - truth[s]).max()))
    ordered = [s for s in shown if s >= 0]
    return {"song": SONG.name, "seconds": seconds, "fps": tx.fps, "wall_s": wall,
            "first_motion_ready_s": summary["first_motion_ready_s"],
            "frames_danced": summary["frames"], "bundles_sent": len(log), "bundles_received": len(got),
            "frames_shown": len(ordered), "in_order": ordered == sorted(set(ordered)),
            "held": tx.held, "lost_by_socket": tx.dropped, "skipped": tx.skipped,
            "on_time_share": float(np.mean(late < 1.0 / tx.fps)) if late.size else None,
            "lateness_ms": {"median": float(np.median(late) * 1e3), "p99": float(np.percentile(late, 99) * 1e3),
                            "max": float(late.max() * 1e3)} if late.size else None,
            "agreement_max_m": err, "bones": len(names),
            "avatar_delay_s": tx.delay_s,   # how far behind the music heard the avatar dances (whole bars)
            "tempo_bpm": summary["tempo_bpm"], "beats_per_bar": summary["beats_per_bar"],
            "machine": {"cpus": os.cpu_count(), "processor": platform.processor() or platform.machine()}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    args = parser.parse_args()
    r = measure(args.seconds)
    lat = r["lateness_ms"] or {}
    print(f"VMC to a receiver on 127.0.0.1: {r['song']}, {r['seconds']:g} s at real-time pace, {r['fps']:g} fps, "
          f"{r['bones']} bones a frame")
    print(f"  frames danced {r['frames_danced']}, bundles sent {r['bundles_sent']}, received {r['bundles_received']}, "
          f"in order {r['in_order']}")
    print(f"  held while a segment was late {r['held']}, lost by the socket {r['lost_by_socket']}, skipped while the "
          f"sender was held up {r['skipped']}")
    print(f"  on time (within one frame period) {r['on_time_share']:.2%}; lateness median {lat.get('median', 0):.2f} ms, "
          f"p99 {lat.get('p99', 0):.2f} ms, max {lat.get('max', 0):.2f} ms")
    print(f"  receiver's pose against our forward kinematics: largest difference {r['agreement_max_m']:.2e} m")
    bar = 60.0 / r["tempo_bpm"] * r["beats_per_bar"]
    print(f"  first motion ready {r['first_motion_ready_s']:.2f} s after the first audio; the avatar dances "
          f"{r['avatar_delay_s']:.2f} s behind the music ({r['avatar_delay_s'] / bar:.2f} bars of {bar:.2f} s)")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "vmc_bench.json").write_text(json.dumps(r, indent=1))


if __name__ == "__main__":
    main()

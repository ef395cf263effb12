"""The page's "Dance to a tab" / "Dance to the microphone", measured end to end.

    .venv/bin/python benchmarks/capture_bench.py [--seconds 60] [--segment 2] [--out benchmarks/results]

A real ``serve`` in a subprocess (``serve_load.server_process``) and the page in headless Chromium
(``tests/clients/viewer_check.mjs``), whose fake capture device plays the bundled *Vibe Ace* (48 kHz
stereo, as a sound card gives it): the page captures it with its AudioWorklet and sends it over the
live WebSocket at real-time pace; after ``--seconds`` it presses Stop and the server dances to the end
of what it heard. Prints and writes ``capture_bench.json``: for the tab and the microphone, the
server's first motion after the first audio, a beat's move after the beat (median, largest; the target:
a segment), the step, late segments, how long the page waited for motion it should have had (starved),
audio sent against audio the server heard, and the tempo heard against the song's.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SONG = REPO / "src" / "dancesynth" / "data" / "music" / "Kevin_MacLeod_-_Vibe_Ace.ogg"
CLIENTS = REPO / "tests" / "clients"
sys.path.insert(0, str(REPO / "benchmarks"))
from serve_load import server_process  # noqa: E402


def measure(kind: str, seconds: float, segment_s: float, tmp: Path) -> dict:
    song = tmp / "song.wav"
    if not song.exists():
        subprocess.run(["ffmpeg", "-loglevel", "error", "-y", "-i", str(SONG), "-ar", "48000", "-ac", "2",
                        str(song)], check=True)
    work = tmp / kind
    work.mkdir()
    with server_process(work, {}) as (address, _, _):
        chromium = shutil.which("chromium") or "/usr/bin/chromium"
        options = {"audio_file": str(song), "capture_s": seconds, "segment": segment_s}
        proc = subprocess.run(["node", str(CLIENTS / "viewer_check.mjs"), f"http://{address[0]}:{address[1]}/",
                               str(work), "capture", kind, chromium, json.dumps(options)],
                              capture_output=True, text=True, timeout=seconds + 240, cwd=CLIENTS)
    report = json.loads(proc.stdout or "{}")
    if not report.get("ok") or report["page"]["live"].get("state") != "ended":
        raise RuntimeError(f"the capture failed: {report.get('errors') or proc.stderr[-2000:]}")
    live = report["page"]["live"]
    s = live["summary"]
    return {"kind": kind, "segment_s": s["segment_s"], "sent_s": round(live["capture"]["sent_s"], 2),
            "capture_rate_hz": live["capture"]["rate"], "heard_s": round(s["heard_s"], 2),
            "silence_fed_s": round(s["silence_s"], 2), "first_motion_ready_s": round(s["first_motion_ready_s"], 3),
            "first_motion_target_s": 2.0, "beat_delay_s_median": round(s["beat_delay_s_median"], 3),
            "beat_delay_s_max": round(s["beat_delay_s_max"], 3), "beat_delay_target_s": s["segment_s"],
            "step_ms_median": round(1000 * s["step_s_median"], 1), "step_ms_max": round(1000 * s["step_s_max"], 1),
            "late_segments": s["late_segments"], "page_delay_s": live["delay_s"],
            "page_starved_s": round(live["starved_s"], 3), "page_playing_s": round(live["playing_s"], 2),
            "tempo_bpm": round(s["tempo_bpm"], 2), "style": s["style"]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="how long the page captures")
    parser.add_argument("--segment", type=float, default=2.0, help="the page's segment length, s")
    parser.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results")
    args = parser.parse_args()
    os.environ.setdefault("NUMBA_CACHE_DIR", str(REPO / ".cache" / "numba"))
    from dancesynth.api import analyse

    with tempfile.TemporaryDirectory(prefix="capture-bench-") as tmp:
        rows = [measure(kind, args.seconds, args.segment, Path(tmp)) for kind in ("tab", "mic")]
    song_tempo = analyse(SONG, structure=False).tempo_bpm
    result = {"song": SONG.name, "song_tempo_bpm": round(song_tempo, 2), "seconds": args.seconds, "rows": rows}
    print(f"Page capture of {SONG.stem} ({song_tempo:.1f} bpm offline), {args.seconds:g} s, "
          f"{args.segment:g} s segments, headless Chromium's fake capture device")
    print(f"{'':5} {'sent s':>7} {'heard s':>7} {'first motion':>12} {'beat delay med/max':>19} {'step ms':>8} "
          f"{'late':>4} {'starved s':>9} {'tempo':>7}")
    for r in rows:
        print(f"{r['kind']:5} {r['sent_s']:7.2f} {r['heard_s']:7.2f} {r['first_motion_ready_s']:10.2f} s "
              f"{r['beat_delay_s_median']:8.2f} / {r['beat_delay_s_max']:4.2f} s {r['step_ms_median']:8.1f} "
              f"{r['late_segments']:4d} {r['page_starved_s']:9.3f} {r['tempo_bpm']:7.2f}")
    print(f"targets: first motion <= 2 s; a beat's move within a segment ({args.segment:g} s)")
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "capture_bench.json"
    path.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()

"""Every option of every ``dancesynth`` command with hostile values, run in-process through ``cli.main``.

Mutates: one or two options (or the positional argument) of a command that
otherwise runs on small real inputs (a 5 s song, a short MIDI tune, a dance made
from them): negative, zero, nan, inf, huge, empty and non-numeric numbers;
missing, unwritable, folder-instead-of-file and device paths; unknown names.
``serve`` runs against a port that is already taken, so that a run never starts a
server; ``bench`` gets only output folders it cannot use.

Sane: exit 0 with every BVH written readable and sane and every JSON strict; or
exit 1/2 with a one-line ``error: ...`` (click's own usage errors: an
``Error: ...`` line); never exit 70 (internal error), another code, or a traceback.
"""

from __future__ import annotations

import json
import os
import random
import shutil
import socket
import subprocess
from pathlib import Path

from .harness import Case, Failed, Target, rng_for

REPO = Path(__file__).resolve().parents[2]
SONG = REPO / "src" / "dancesynth" / "data" / "music" / "Kevin_MacLeod_-_Vibe_Ace.ogg"

FLOAT = ["-1", "0", "nan", "inf", "-inf", "1e308", "1e-300", "", "abc", "1e999", "-0", "0.5", "30"]
INT = ["-1", "0", "--5", "9" * 30, "", "1.5", "abc", "-" + "9" * 25, "3", "65536"]
OUT = ["", "/nonexistent/dir/out.bvh", "/proc/out.bvh", "{dir}", "/dev/full", "{file_as_dir}/x.bvh", "x" * 300]
IN = ["", "/nonexistent.bvh", "{dir}", "/dev/null", "{junk}", "{empty}", "{song}", "{dance}"]
DIR = ["", "/nonexistent", "{junk}", "{dir}", "/proc", "/dev/null"]
TEXT = ["", "nonexistent", "../../etc/passwd", "a" * 5000, "-1", "salsa", "jpop", "\t"]
CHOICE = ["", "bogus"]
PARAM = ["l1=nan", "l1", "=", "max_segment_notes=inf", "max_segment_notes=nan", "fps=0", "bogus=1", "l1=1e308",
         "l1=0.2"]
MOTIF = ["1=M17", "nan=M1", "-5=M1", "1e308=M2", "x=y", "=", "1=M99999", "inf=M3"]

# command -> (base arguments, {option: hostile values}); "{...}" are files made by prepare.
COMMANDS = {
    "beats": (["{song}"], {"--json": OUT, "--tracker": TEXT}),
    "dance": (["{song}", "-o", "out.bvh", "-q"],
              {"-o": OUT, "--style": TEXT, "--engine": CHOICE + ["global"], "--recreate": IN, "--motif-at": MOTIF,
               "--segment-seconds": FLOAT, "--lookahead": FLOAT, "--fps": FLOAT, "--seed": INT, "--database": DIR,
               "--max-minutes": FLOAT, "--ths": FLOAT, "--thr": FLOAT, "--report": OUT}),
    "conduct": (["{midi}", "-o", "out.bvh", "-q"],
                {"-o": OUT, "--melody-track": INT, "--rhythm-track": INT, "--style": TEXT, "--config": IN,
                 "--param": PARAM, "--fps": FLOAT}),
    "eval": (["{dance}", "{song}"], {"--json": OUT, "--plot": OUT, "--plot-from": FLOAT, "--plot-length": FLOAT,
                                     "--reference": IN, "--style": TEXT, "--report": IN, "--database": DIR}),
    "motifs": (["{dance}"], {"--genre": TEXT, "--json": OUT, "--plot": OUT, "--database": DIR}),
    "render": (["{dance}", "{song}", "-o", "out.mp4", "-q", "--width", "64", "--height", "48", "--fps", "5"],
               {"-o": OUT, "--width": INT, "--height": INT, "--fps": FLOAT}),
    "styles": ([], {"--database": DIR}),
    "build-db": (["{bvh_dir}", "-o", "db"], {"-o": OUT, "--beats": CHOICE, "--snap": FLOAT, "--manifest": IN}),
    "stream": (["{song}", "-o", "out.bvh", "--fast", "-q"],
               {"-o": OUT, "--segment-seconds": FLOAT, "--style": TEXT, "--fps": FLOAT, "--seed": INT,
                "--database": DIR}),
    "train": (["--config", "tiny", "--minutes", "0.01", "--out", "w.pt", "-q"],
              {"--style": TEXT, "--config": CHOICE, "--device": ["cuda", ""], "--minutes": FLOAT, "--out": OUT,
               "--seed": INT, "--database": DIR}),
    "bench": (["--quick"], {"--out": ["/proc/x", "{junk}", "/dev/null"]}),
    "serve": (["--port", "{busy_port}"], {"--host": ["", "nonexistent.invalid", "999.1.1.1", "::1x"],
                                          "--port": ["0", "-1", "65536", "abc", ""], "--database": DIR,
                                          "--max-upload-mb": FLOAT}),
}
# How often each command is drawn: the slow ones (a whole dance or render) less often.
WEIGHTS = {"beats": 2, "dance": 3, "conduct": 3, "eval": 2, "motifs": 2, "render": 1, "styles": 2, "build-db": 1,
           "stream": 2, "train": 1, "bench": 1, "serve": 2}


class CliTarget(Target):
    name = "cli"
    mutates = "one or two options (or the argument) of each command set to hostile values"
    sane = "exit 0 with readable outputs, or exit 1/2 with one error line; never 70 or a traceback"

    def __init__(self):
        self._busy = None

    def prepare(self, workdir: Path) -> None:
        files = workdir / "cli_files"
        if self._busy is None:  # a port that stays taken while this process lives
            self._busy = socket.create_server(("127.0.0.1", 0))
        if (files / "dance.bvh").is_file():
            return
        files.mkdir(parents=True, exist_ok=True)
        subprocess.run(["ffmpeg", "-nostdin", "-v", "error", "-y", "-ss", "20", "-t", "5", "-i", str(SONG),
                        "-map", "0:a", "-ac", "1", "-ar", "22050", str(files / "song.wav")], check=True)
        from .midi_target import _seed_songs

        (files / "tune.mid").write_bytes(_seed_songs()["type1.mid"])
        (files / "junk").write_bytes(os.urandom(2000))
        (files / "empty").write_bytes(b"")
        (files / "dir").mkdir(exist_ok=True)
        (files / "file_as_dir").write_text("a file")
        bvh_dir = files / "bvh_dir" / "jpop"
        bvh_dir.mkdir(parents=True, exist_ok=True)
        from .database_target import DatabaseTarget

        DatabaseTarget().prepare(workdir)
        shutil.copy(workdir / "db_seeds" / "clips" / "clip0.bvh", bvh_dir / "clip0.bvh")
        from dancesynth.cli import main

        code = main(["dance", str(files / "song.wav"), "-o", str(files / "dance.bvh"), "-q"])
        if code != 0:
            raise RuntimeError(f"could not make the seed dance (exit {code})")

    def cases(self, n: int, seed: int, workdir: Path) -> list[Case]:
        rng = rng_for(seed, "cli")
        names = list(COMMANDS)
        out = []
        for _ in range(n):
            command = rng.choices(names, [WEIGHTS[c] for c in names])[0]
            args, how = _hostile_args(rng, command)
            out.append(Case(f"{command}: {how}", [command] + args))
        return out

    def run(self, case: Case, workdir: Path) -> None:
        from click.testing import CliRunner

        from dancesynth.cli import main

        files = workdir / "cli_files"
        here = workdir / "cli_case"
        shutil.rmtree(here, ignore_errors=True)
        here.mkdir()
        names = {"song": files / "song.wav", "midi": files / "tune.mid", "dance": files / "dance.bvh",
                 "junk": files / "junk", "empty": files / "empty", "dir": files / "dir",
                 "file_as_dir": files / "file_as_dir", "bvh_dir": files / "bvh_dir",
                 "busy_port": self._busy.getsockname()[1]}
        argv = [a.format(**names) for a in case.data]
        os.environ["DANCESYNTH_CACHE"] = str(workdir / "cache")
        os.chdir(here)
        runner = CliRunner()
        with runner.isolation() as (out, err, *_):
            try:
                code = main(argv)
            except SystemExit as exc:  # main returns its code; a SystemExit is a bug of its own
                code = f"SystemExit({exc.code})"
            stdout, stderr = out.getvalue().decode(errors="replace"), err.getvalue().decode(errors="replace")
        check_exit(code, stdout, stderr)
        if code == 0:
            check_outputs(here)


def check_exit(code, stdout: str, stderr: str) -> None:
    from dancesynth.errors import InputError

    text = stdout + stderr
    if "Traceback" in text:
        raise Failed("a traceback", text[-300:])
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    if code == 0:
        return
    if code == 70:
        raise Failed(f"exit 70: {lines[-1].split(':')[:2] if lines else ''}", lines[-1] if lines else "")
    if code not in (1, 2):
        raise Failed(f"exit {code}", text[-300:])
    if lines and lines[-1].startswith("Error: "):  # click's usage errors (usage and hint lines above)
        raise InputError(lines[-1])
    if len(lines) == 1 and lines[0].startswith("error: ") and len(lines[0]) > len("error: "):
        raise InputError(lines[0])
    raise Failed(f"exit {code} without a one-line error", text[-300:])


def check_outputs(folder: Path) -> None:
    from dancesynth.io.bvh import read_bvh

    from .bvh_target import check_clip

    for path in folder.rglob("*"):
        if path.suffix == ".bvh" and path.is_file():
            check_clip(read_bvh(path))
        elif path.suffix == ".json" and path.is_file():
            json.loads(path.read_text(), parse_constant=_no_constant)


def _no_constant(name):
    from .harness import Insane

    raise Insane(f"JSON output holds {name}")


def _hostile_args(rng: random.Random, command: str) -> tuple[list[str], str]:
    base, options = COMMANDS[command]
    args = list(base)
    done = []
    if base and not base[0].startswith("-") and rng.random() < 0.1:
        args[0] = rng.choice(IN + TEXT)
        done.append(f"argument={args[0][:30]!r}")
    for option in rng.sample(sorted(options), min(len(options), rng.choice((1, 1, 2)))):
        value = rng.choice(options[option])
        if option in args:  # replace a base value
            args[args.index(option) + 1] = value
        else:
            args += [option, value]
        done.append(f"{option}={value[:30]!r}")
    return args, " ".join(done)


TARGET = CliTarget()

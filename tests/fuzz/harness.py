"""The fuzzing harness: run a target's cases in a watched child process and sort the outcomes.

A *target* (one module per parser in this folder) makes a deterministic list of
cases for a seed and runs one case: it calls dancesynth and checks that what came
back is sane, raising ``Insane`` otherwise. The harness runs the cases in a child
process that a watchdog kills and restarts when one case runs past ``hang_s``
seconds (a *hang*) or when the child and its own children (ffmpeg) hold more than
``memory_mb`` of resident memory (*memory*). Every case ends in one class:

- ``ok``: success with sane output;
- ``input_error``: a ``DanceSynthError`` with a one-line, non-empty message;
- failures: ``other_exception`` (any other exception, or our error with a bad
  message), ``insane_output``, ``hang``, ``memory``.

The child imports ``dancesynth`` from wherever the parent's ``sys.path`` and
``PYTHONPATH`` find it, so the same cases can be run against an older source tree.
"""

from __future__ import annotations

import importlib
import multiprocessing
import os
import random
import resource
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path

OK, INPUT_ERROR = "ok", "input_error"
FAILURES = ("other_exception", "insane_output", "hang", "memory")
CLASSES = (OK, INPUT_ERROR) + FAILURES
HANG_S = 10.0
MEMORY_MB = 2048.0
_POLL_S = 0.02  # watchdog sampling: a process grows at most a few hundred MB between two looks


class Insane(Exception):
    """A call succeeded but what it returned is not sane (NaN, negative frame rate, ...)."""


class Failed(Exception):
    """A failure seen from outside the code (a CLI exit 70, an HTTP 500); ``key`` deduplicates it."""

    def __init__(self, key: str, message: str):
        super().__init__(message)
        self.key = key


class Target:
    """What a target module defines: a name, seeds, cases and how to run (and save) one case."""

    name = "?"
    mutates = ""   # one line for the table's notes: what the cases are
    sane = ""      # one line: what an ``ok`` outcome was checked for
    suffix = ".bin"  # of a saved reproducer

    def prepare(self, workdir: Path) -> None:
        """Make the seed files under ``workdir`` (called in the parent and in each child)."""

    def cases(self, n: int, seed: int, workdir: Path) -> list[Case]:
        raise NotImplementedError

    def run(self, case: Case, workdir: Path) -> None:
        raise NotImplementedError

    def save(self, case: Case, folder: Path, stem: str) -> Path:
        """Write ``case`` so that a developer can replay it; returns the file."""
        data = case.data
        if isinstance(data, (bytes, str)):
            return write_file(folder, f"{stem}{self.suffix}",
                              data if isinstance(data, bytes) else data.encode("utf-8", "surrogateescape"))
        return write_file(folder, f"{stem}.txt", (repr(data) + "\n").encode("utf-8"))


def write_file(folder: Path, name: str, data: bytes) -> Path:
    """A reproducer's bytes in ``folder`` (made if needed); returns the file."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_bytes(data)
    return path


@dataclass
class Case:
    """One input: ``label`` says how it was made (for the table's failure list), ``data`` is
    what the target's ``run`` needs (bytes, text, argument lists; anything picklable)."""

    label: str
    data: object


@dataclass
class Failure:
    kind: str
    key: str          # what deduplicates it: class, exception type and where it was raised
    message: str
    count: int = 0
    examples: list = field(default_factory=list)  # case indices (the first few)


@dataclass
class TargetResult:
    name: str
    cases: int = 0
    counts: dict = field(default_factory=lambda: {c: 0 for c in CLASSES})
    slowest_s: float = 0.0
    slowest_case: str = ""
    peak_rss_mb: float = 0.0
    wall_s: float = 0.0
    failures: dict = field(default_factory=dict)  # key -> Failure
    note: str = ""

    def record(self, index: int, kind: str, key: str, message: str) -> None:
        self.counts[kind] += 1
        if kind in FAILURES:
            f = self.failures.setdefault(key, Failure(kind, key, message))
            f.count += 1
            if len(f.examples) < 5:
                f.examples.append(index)

    def as_json(self) -> dict:
        return {"target": self.name, "cases": self.cases, **self.counts, "slowest_s": round(self.slowest_s, 3),
                "slowest_case": self.slowest_case, "peak_rss_mb": round(self.peak_rss_mb, 1),
                "wall_s": round(self.wall_s, 1), "note": self.note,
                "failures": [vars(f) for f in self.failures.values()]}


# ----------------------------------------------------------------------------- classifying one case


def classify(exc: BaseException | None) -> tuple[str, str, str]:
    """(class, dedup key, message) of a case that raised ``exc`` (None: it returned sanely)."""
    from dancesynth.errors import DanceSynthError

    if exc is None:
        return OK, OK, ""
    if isinstance(exc, Failed):
        return "other_exception", exc.key, str(exc)[:300]
    if isinstance(exc, Insane):
        return "insane_output", f"insane: {str(exc).split(':')[0]}", str(exc)
    if isinstance(exc, MemoryError):
        return "memory", f"MemoryError at {_where(exc)}", "MemoryError"
    text = str(exc)
    if isinstance(exc, DanceSynthError):
        if text.strip() and "\n" not in text.strip():
            return INPUT_ERROR, INPUT_ERROR, text
        what = "empty" if not text.strip() else "multi-line"
        return "other_exception", f"{type(exc).__name__} with a {what} message at {_where(exc)}", text[:300]
    first = text.strip().splitlines()[0][:200] if text.strip() else ""
    return "other_exception", f"{type(exc).__name__} at {_where(exc)}", f"{type(exc).__name__}: {first}"


def _where(exc: BaseException) -> str:
    """The innermost frame of dancesynth's own code (else the innermost frame) as file:line."""
    frames = traceback.extract_tb(exc.__traceback__)
    ours = [f for f in frames if "dancesynth" in f.filename and "/tests/" not in f.filename]
    f = (ours or frames or [None])[-1]
    if f is None:
        return "?"
    path = f.filename
    if "dancesynth/" in path:
        path = "dancesynth/" + path.rsplit("dancesynth/", 1)[1]
    return f"{path}:{f.lineno} ({f.name})"


def load_target(spec: str):
    """``"module:ATTRIBUTE"`` -> the target object."""
    module, _, attr = spec.partition(":")
    return getattr(importlib.import_module(module), attr or "TARGET")


# ----------------------------------------------------------------------------- the child process


def _worker(conn, spec: str, workdir: str) -> None:
    # Decoders write to the terminal (mpg123's "Trying to resync"); the table must stay readable.
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    os.dup2(devnull, 2)
    target = load_target(spec)
    target.prepare(Path(workdir))
    conn.send(("ready", None))
    while True:
        msg = conn.recv()
        if msg is None:
            return
        index, case = msg
        try:
            target.run(case, Path(workdir))
            result = classify(None)
        except KeyboardInterrupt:
            raise
        except BaseException as exc:  # everything else is an outcome (SystemExit from a CLI included)
            result = classify(exc)
        rss = max(_own_peak_rss_mb(), resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0)
        conn.send((index, result, rss))


def _own_peak_rss_mb() -> float:
    # VmHWM, not ru_maxrss: ru_maxrss survives exec, so a child spawned by a big parent would report the parent's.
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    return 0.0


def tree_rss_mb(pid: int) -> float:
    """Resident memory of ``pid`` and its descendants (ffmpeg, ffprobe), in MB; 0 once it is gone."""
    total, todo, seen = 0.0, [pid], set()
    while todo:
        p = todo.pop()
        if p in seen:
            continue
        seen.add(p)
        try:
            with open(f"/proc/{p}/status") as fh:
                for line in fh:
                    if line.startswith("VmRSS:"):
                        total += int(line.split()[1]) / 1024.0
                        break
            for task in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{task}/children") as fh:
                    todo += [int(c) for c in fh.read().split()]
        except (OSError, ValueError):
            continue
    return total


def _kill_tree(proc) -> None:
    pids = []
    todo = [proc.pid]
    while todo:  # the child's own children first, so that no ffmpeg is left behind
        p = todo.pop()
        pids.append(p)
        try:
            for task in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{task}/children") as fh:
                    todo += [int(c) for c in fh.read().split()]
        except (OSError, ValueError):
            pass
    for p in reversed(pids):
        try:
            os.kill(p, 9)
        except OSError:
            pass
    proc.join(5)


class _Child:
    """The watched worker: started on demand, killed and forgotten after a hang or a blow-up."""

    def __init__(self, spec: str, workdir: Path, start_timeout_s: float):
        self.spec, self.workdir, self.start_timeout_s = spec, workdir, start_timeout_s
        self.proc = self.conn = None

    def ensure(self) -> None:
        if self.proc is not None and self.proc.is_alive():
            return
        ctx = multiprocessing.get_context("spawn")
        parent, child = ctx.Pipe()
        self.proc = ctx.Process(target=_worker, args=(child, self.spec, str(self.workdir)), daemon=True)
        self.proc.start()
        child.close()
        self.conn = parent
        if not parent.poll(self.start_timeout_s):
            self.kill()
            raise RuntimeError(f"the fuzz worker for {self.spec} did not start in {self.start_timeout_s:.0f} s")
        try:
            parent.recv()
        except EOFError:
            self.kill()
            raise RuntimeError(f"the fuzz worker for {self.spec} died while preparing its seeds") from None

    def kill(self) -> None:
        if self.proc is not None:
            _kill_tree(self.proc)
        self.proc = self.conn = None

    def close(self) -> None:
        if self.proc is not None and self.proc.is_alive():
            try:
                self.conn.send(None)
                self.proc.join(5)
            except OSError:
                pass
        self.kill()


def run_cases(name: str, spec: str, cases: list[Case], workdir: Path, *, hang_s: float = HANG_S,
              memory_mb: float = MEMORY_MB, start_timeout_s: float = 120.0, progress=None) -> TargetResult:
    """Run ``cases`` of the target ``spec`` one by one in a watched child process."""
    result = TargetResult(name)
    workdir.mkdir(parents=True, exist_ok=True)
    child = _Child(spec, workdir, start_timeout_s)
    t_start = time.monotonic()
    try:
        for index, case in enumerate(cases):
            child.ensure()
            child.conn.send((index, case))
            t0 = time.monotonic()
            kind = None
            while kind is None:
                if child.conn.poll(_POLL_S):
                    try:
                        _, (kind, key, message), rss = child.conn.recv()
                    except EOFError:  # the child died without a word (a segfault, the OOM killer)
                        code = child.proc.exitcode if child.proc else None
                        kind, key, message = "other_exception", f"worker died (exit {code})", case.label
                        rss = 0.0
                        child.kill()
                    result.peak_rss_mb = max(result.peak_rss_mb, rss)
                    break
                elapsed = time.monotonic() - t0
                rss_now = tree_rss_mb(child.proc.pid)
                result.peak_rss_mb = max(result.peak_rss_mb, rss_now)
                if rss_now > memory_mb:
                    kind, key, message = "memory", f"over {memory_mb:.0f} MB", f"{case.label}: {rss_now:.0f} MB"
                    child.kill()
                elif elapsed > hang_s:
                    kind, key, message = "hang", f"over {hang_s:g} s", f"{case.label}: killed after {elapsed:.1f} s"
                    child.kill()
            took = time.monotonic() - t0
            if took > result.slowest_s:
                result.slowest_s, result.slowest_case = took, case.label
            result.cases += 1
            result.record(index, kind, key, message)
            if progress:
                progress(result)
    finally:
        child.close()
    result.wall_s = time.monotonic() - t_start
    return result


# ----------------------------------------------------------------------------- generating cases


def rng_for(seed: int, *parts) -> random.Random:
    """A random generator for one target (and one kind of case) that depends only on the seed."""
    return random.Random("/".join(map(str, (seed, *parts))))


def hypothesis_examples(strategy, n: int, seed: int) -> list:
    """``n`` values drawn from a hypothesis strategy, the same for the same seed.

    The examples are collected from a ``@given`` run limited to the generate phase
    (no shrinking, no example database); a run that stops early is continued with
    the next seed.
    """
    from hypothesis import HealthCheck, Phase, given, settings
    from hypothesis import seed as with_seed

    out: list = []
    round_ = 0
    while len(out) < n and round_ < 20:
        @with_seed(seed * 1000 + round_)
        @settings(max_examples=n - len(out), database=None, phases=[Phase.generate], deadline=None,
                  suppress_health_check=list(HealthCheck))
        @given(strategy)
        def collect(value):
            out.append(value)

        collect()
        round_ += 1
    return out[:n]


# Values that break parsers: signs, zero, NaN, infinities, overflowing floats and integers.
HOSTILE_NUMBERS = ["0", "-0", "-1", "1e308", "-1e308", "1e309", "nan", "NaN", "inf", "-inf", "Infinity",
                   "9" * 40, "-" + "9" * 40, "18446744073709551616", "4294967296", "1e-320", "0x10", "1_000",
                   "", "1,5", "+", ".", "e5", "1e", "--5"]


def mutate_bytes(rng: random.Random, data: bytes, n_edits: int | None = None) -> tuple[bytes, str]:
    """Classic mutations of a byte string (bit flips, interesting bytes, cuts, copies, junk); and what was done."""
    buf = bytearray(data)
    done = []
    for _ in range(n_edits or rng.choice((1, 1, 2, 3, 8))):
        op = rng.choice(("flip", "byte", "word", "cut", "truncate", "insert", "dup", "delete", "junk"))
        pos = rng.randrange(len(buf)) if buf else 0
        if op == "flip" and buf:
            buf[pos] ^= 1 << rng.randrange(8)
        elif op == "byte" and buf:
            buf[pos] = rng.choice((0, 1, 0x7F, 0x80, 0xFF))
        elif op == "word" and len(buf) > 4:
            pos = min(pos, len(buf) - 4)
            buf[pos:pos + 4] = rng.choice((b"\xff\xff\xff\xff", b"\x00\x00\x00\x00", b"\xff\xff\xff\x7f",
                                           b"\x00\x00\x00\x80", b"\x01\x00\x00\x00"))
        elif op == "cut" and buf:
            del buf[pos:pos + rng.randrange(1, 64)]
        elif op == "truncate":
            del buf[rng.randrange(len(buf) + 1):]
        elif op == "insert":
            buf[pos:pos] = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 32)))
        elif op == "dup" and buf:
            chunk = buf[pos:pos + rng.randrange(1, 256)]
            buf[rng.randrange(len(buf) + 1):0] = chunk
        elif op == "delete" and buf:
            del buf[pos]
        elif op == "junk":
            junk = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 4096)))
            buf = bytearray(junk) + buf if rng.random() < 0.5 else buf + junk
        done.append(op)
    return bytes(buf), "+".join(done)


# ----------------------------------------------------------------------------- running targets

# Target name -> module; the CLI and web targets run whole commands, so their case counts are smaller.
TARGETS = {
    "bvh": "fuzz.bvh_target",
    "audio": "fuzz.audio_target",
    "midi": "fuzz.midi_target",
    "toml": "fuzz.toml_target",
    "database": "fuzz.database_target",
    "cli": "fuzz.cli_target",
    "web": "fuzz.web_target",
    "character_gltf": "fuzz.character_target:GLTF",
    "character_vrm": "fuzz.character_target:VRM",
    "character_bvh": "fuzz.rig_target:BVH_RIG",
    "character_bonemap": "fuzz.rig_target:BONE_MAP",
}


def run_target(name: str, n: int, seed: int, workdir: Path, *, failures_dir: Path | None = None,
               hang_s: float = HANG_S, memory_mb: float = MEMORY_MB, progress=None) -> TargetResult:
    """Make ``n`` cases of target ``name`` for ``seed``, run them, and save every failing input."""
    spec = TARGETS[name] if ":" in TARGETS[name] else TARGETS[name] + ":TARGET"
    target = load_target(spec)
    target.prepare(workdir)
    cases = target.cases(n, seed, workdir)
    result = run_cases(name, spec, cases, workdir, hang_s=hang_s, memory_mb=memory_mb,
                       progress=progress)
    if failures_dir is not None:
        for f in result.failures.values():
            f.examples = [{"case": i, "label": cases[i].label,
                           "file": str(target.save(cases[i], failures_dir / name, f"case{i:05d}"))}
                          for i in f.examples]
    else:
        for f in result.failures.values():
            f.examples = [{"case": i, "label": cases[i].label} for i in f.examples]
    return result


COLUMNS = ("target", "cases", "ok", "input_error", "other_exception", "insane_output", "hang", "memory",
           "slowest_s", "peak_rss_mb", "wall_s")


def table(results: list[TargetResult]) -> str:
    """The fixed-format outcome table."""
    head = "| " + " | ".join(COLUMNS) + " |"
    lines = [head, "|" + "|".join("---" for _ in COLUMNS) + "|"]
    for r in results:
        j = r.as_json()
        cells = [r.name] + [str(j[c]) for c in COLUMNS[1:8]] + [f"{r.slowest_s:.2f}", f"{r.peak_rss_mb:.0f}",
                                                                 f"{r.wall_s:.0f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def failure_lines(results: list[TargetResult]) -> str:
    out = []
    for r in results:
        for f in r.failures.values():
            ex = f.examples[0] if f.examples else {}
            where = ex.get("file") or ex.get("label", "")
            out.append(f"{r.name}: {f.kind} x{f.count}: {f.key}: {f.message[:160]!r} (e.g. {where})")
    return "\n".join(out)

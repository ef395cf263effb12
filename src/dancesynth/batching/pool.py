"""Run a batch on local worker processes, one song at a time each.

Not ``concurrent.futures``: when one of its workers dies, the whole pool breaks and no one knows
which song killed it. Here each worker has its own pipe, so a worker that dies (killed, out of
memory) costs only its own song: that song is retried once on a fresh worker, then reported failed,
and the half-written file it left is removed.
"""

from __future__ import annotations

import multiprocessing
from collections import deque
from dataclasses import dataclass
from multiprocessing.connection import wait
from pathlib import Path
from typing import Iterator

from ..errors import SynthesisError
from .songs import Job
from .worker import BatchSettings

#: A song whose worker died is tried this many more times before it is reported failed.
RETRIES = 1


def failed_record(job: Job, error: str, attempts: int) -> dict:
    return {"name": job.name, "song": str(job.song), "status": "failed", "error": error, "attempts": attempts}


def remove_partial(out_dir: Path, job: Job) -> None:
    """Remove what a worker killed while writing ``job`` left: the hidden temporary files of
    ``io.files.atomic_path`` (``.<name>.<random>.part``)."""
    out = Path(out_dir) / job.name
    for part in out.parent.glob(f".{out.name}.*.part"):
        part.unlink(missing_ok=True)


def _serve(settings: BatchSettings, conn) -> None:
    """A worker process: load once, then dance what the pipe sends until it sends ``None``."""
    import signal

    from ..errors import DanceSynthError
    from ..io.files import stop_cleanly_on_sigterm
    from .worker import Worker

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the parent's to handle: it stops us
    stop_cleanly_on_sigterm()  # a terminated worker removes its half-written file itself
    try:
        worker = Worker(settings)
    except Exception as exc:
        conn.send(("failed", str(exc) if isinstance(exc, DanceSynthError) else f"{type(exc).__name__}: {exc}"))
        return
    try:
        while (msg := conn.recv()) is not None:
            conn.send(("done", worker.run(*msg)))
    except (EOFError, BrokenPipeError):
        pass  # the batch is gone


@dataclass
class _Slot:
    """A worker process and the song it is dancing (its first song is sent as it starts: a worker that
    dies while loading has cost that song an attempt, as one dying mid-song has)."""

    process: multiprocessing.Process
    conn: object
    job: Job | None = None


def run_local(jobs: list[Job], settings: BatchSettings, out_dir: Path, workers: int) -> Iterator[dict]:
    """Dance ``jobs`` on ``workers`` processes; yields each song's record as it finishes."""
    ctx = multiprocessing.get_context("spawn")  # a fresh interpreter: no locks or threads inherited
    pending = deque(jobs)
    attempts = {job.name: 0 for job in jobs}
    slots: list[_Slot] = []

    def assign(slot: _Slot) -> None:
        slot.job = pending.popleft()
        attempts[slot.job.name] += 1
        slot.conn.send((slot.job, str(out_dir)))

    try:
        while pending or slots:
            while pending and len(slots) < workers:
                parent, child = ctx.Pipe()
                p = ctx.Process(target=_serve, args=(settings, child), daemon=True, name="dancesynth-batch-worker")
                p.start()
                child.close()
                slots.append(_Slot(p, parent))
                assign(slots[-1])
            ready = wait([s.conn for s in slots] + [s.process.sentinel for s in slots])
            for slot in list(slots):
                if slot.conn not in ready and slot.process.sentinel not in ready:
                    continue
                try:
                    kind, value = slot.conn.recv() if slot.conn in ready else ("died", None)
                except (EOFError, OSError):
                    kind, value = "died", None
                if kind == "failed":
                    raise SynthesisError(f"a batch worker could not start: {value}")
                if kind == "died":
                    yield from _died(slot, slots, pending, attempts, out_dir)
                    continue
                slot.job = None
                yield {**value, "attempts": attempts[value["name"]]}
                if pending:
                    assign(slot)
                else:
                    _stop(slot)
                    slots.remove(slot)
    finally:
        for slot in slots:
            _stop(slot)
            if slot.job is not None:
                remove_partial(out_dir, slot.job)


def _died(slot: _Slot, slots: list, pending: deque, attempts: dict, out_dir: Path) -> Iterator[dict]:
    """A worker ended without answering: retry its song once, else report it failed."""
    slot.process.join(1.0)
    slots.remove(slot)
    slot.conn.close()
    job = slot.job
    remove_partial(out_dir, job)
    code = slot.process.exitcode
    how = f"killed by signal {-code}" if code is not None and code < 0 else f"exit code {code}"
    if attempts[job.name] <= RETRIES:
        pending.appendleft(job)
    else:
        yield failed_record(job, f"the worker dancing this song died ({how}), {attempts[job.name]} times",
                            attempts[job.name])


def _stop(slot: _Slot) -> None:
    """Ask a worker to finish; terminate it if it does not (it is busy: the batch is being stopped)."""
    try:
        if slot.job is None and slot.process.is_alive():
            slot.conn.send(None)
            slot.process.join(2.0)
    except (OSError, ValueError):
        pass
    if slot.process.is_alive():
        slot.process.terminate()
        slot.process.join(5.0)
    if slot.process.is_alive():
        slot.process.kill()
        slot.process.join()
    slot.conn.close()

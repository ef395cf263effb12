"""Run a batch on a Ray cluster: the same ``Worker`` as a Ray actor per CPU.

The database goes into Ray's object store once (``ray.put``); every actor on a node maps that one
copy (numpy arrays are read zero-copy), so a song costs its own work only. Songs and the output
folder are paths: on a cluster of several machines they must be on a file system every node
sees at the same path. An actor that dies mid-song costs that song one retry, as in ``pool``.
"""

from __future__ import annotations

import logging
import socket
import threading
from collections import deque
from pathlib import Path
from typing import Iterator

from ..errors import InputError
from .pool import RETRIES, failed_record, remove_partial
from .songs import Job
from .worker import BatchSettings, Worker

CONNECT_TIMEOUT_S = 25.0   # a cluster that does not answer is an error well within 30 s
AUTO = "auto"              # the cluster started on this machine with `ray start --head`


def import_ray():
    try:
        import ray
    except ImportError:
        raise InputError("--ray needs Ray, an optional extra: pip install 'dancesynth[ray]' "
                         "(or leave out --ray to use this machine's cores)") from None
    return ray


def connect(address: str = AUTO):
    """Connect to the Ray cluster at ``address``; a clear ``InputError`` within 30 s when none answers."""
    ray = import_ray()
    if address != AUTO and not address.startswith("ray://"):
        host, _, port = address.rpartition(":")
        if not host or not port.isdigit():
            raise InputError(f"Ray address {address!r} is not HOST:PORT (e.g. 127.0.0.1:6379)")
        try:
            socket.create_connection((host, int(port)), timeout=5.0).close()
        except OSError as exc:
            raise InputError(f"no Ray cluster answers at {address} ({exc.strerror or exc}): start one with "
                             "'ray start --head' or check the address") from None
    result: dict = {}

    def init():
        try:
            result["context"] = ray.init(address=address, logging_level="error", log_to_driver=False,
                                         configure_logging=False)
        except Exception as exc:  # Ray raises ConnectionError, RuntimeError, ValueError...
            result["error"] = exc

    # In a thread, so a cluster that never answers cannot hang us (and Ray leaves our SIGTERM handler
    # alone there; the warning it logs about that is expected).
    logging.getLogger("ray._private.worker").setLevel(logging.ERROR)
    thread = threading.Thread(target=init, daemon=True, name="ray-connect")
    thread.start()
    thread.join(CONNECT_TIMEOUT_S)
    if thread.is_alive():
        raise InputError(f"the Ray cluster at {address} did not answer within {CONNECT_TIMEOUT_S:.0f} s")
    if "error" in result:
        exc = result["error"]
        if address == AUTO:
            raise InputError("no Ray cluster is running on this machine: start one with 'ray start --head', "
                             f"or give its address with --ray ADDRESS ({type(exc).__name__})") from None
        raise InputError(f"cannot join the Ray cluster at {address}: {str(exc).splitlines()[0][:300]}") from None
    return ray


class _Actor:
    def __init__(self, settings: BatchSettings, database):
        self.worker = Worker(settings, database=database)

    def run(self, job: Job, out_dir: str) -> dict:
        return self.worker.run(job, out_dir)


def run_ray(jobs: list[Job], settings: BatchSettings, out_dir: Path, workers: int | None,
            address: str = AUTO) -> Iterator[dict]:
    """Dance ``jobs`` on a Ray cluster, one actor per CPU (or ``workers``); yields records as songs finish."""
    ray = connect(address)
    try:
        from ..motion.database import open_database

        database = ray.put(open_database(settings.database))  # once, for every actor on every node
        n = workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
        actor_class = ray.remote(num_cpus=1)(_Actor)
        idle = [actor_class.remote(settings, database) for _ in range(min(n, len(jobs)))]
        pending, running = deque(jobs), {}
        attempts = {job.name: 0 for job in jobs}
        while pending or running:
            while idle and pending:
                actor, job = idle.pop(), pending.popleft()
                attempts[job.name] += 1
                running[actor.run.remote(job, str(out_dir))] = (actor, job)
            done, _ = ray.wait(list(running), num_returns=1)
            for ref in done:
                actor, job = running.pop(ref)
                try:
                    record = ray.get(ref)
                except ray.exceptions.RayActorError as exc:  # the actor's process died
                    remove_partial(out_dir, job)
                    ray.kill(actor)
                    idle.append(actor_class.remote(settings, database))
                    if attempts[job.name] <= RETRIES:
                        pending.appendleft(job)
                    else:
                        why = str(exc).splitlines()[0][:200]
                        yield failed_record(job, f"the Ray worker dancing this song died, {attempts[job.name]} "
                                                 f"times ({why})", attempts[job.name])
                    continue
                idle.append(actor)
                yield {**record, "attempts": attempts[job.name]}
    finally:
        ray.shutdown()  # leaves the cluster running; its actors end with our job

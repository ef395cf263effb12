"""Dance a music library: many songs, one output folder, resumable.

    >>> import dancesynth
    >>> result = dancesynth.batch(folder="music/", out_dir="dances/", format="glb")
    >>> result.done, result.failed, result.songs_per_min

Songs are danced on local worker processes (``workers``, default: the machine's cores) or, with
``ray``, as Ray actors on a running Ray cluster. Each worker loads the database, the graphs and
the character once. Every song gets a line in ``OUT_DIR/manifest.jsonl`` (``manifest``); outputs
are written whole or not at all, a re-run skips the songs already danced, and a song that fails
is recorded and never stops the others.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

from ..errors import InputError
from ..io.files import output_folder, use_numba_cache
from .manifest import Manifest, settings_key
from .songs import Job, collect_songs, plan_jobs
from .worker import BatchSettings

__all__ = ["batch", "BatchResult", "BatchSettings"]


@dataclass
class BatchResult:
    out_dir: Path
    manifest: Path
    done: int = 0            # danced in this run
    failed: int = 0
    skipped: int = 0         # danced by an earlier run, left as they were
    seconds: float = 0.0
    records: list = field(default_factory=list)   # this run's manifest records, in finishing order

    @property
    def songs_per_min(self) -> float:
        return 60.0 * (self.done + self.failed) / self.seconds if self.seconds > 0 else 0.0

    @property
    def errors(self) -> list[tuple[str, str]]:
        return [(r["song"], r.get("error", "")) for r in self.records if r["status"] == "failed"]


#: ``progress(record, finished, total)`` after each song of this run.
BatchProgress = Callable[[dict, int, int], None]


def batch(songs=(), out_dir="dances", *, list_file=None, folder=None, format: str = "bvh", character=None,
          bone_map=None, database=None, evaluate: bool = False, report: bool = False, workers: int | None = None,
          ray: str | bool | None = None, threads: int | None = None, config=None,
          progress: BatchProgress | None = None, **overrides) -> BatchResult:
    """Dance every song (paths in ``songs``, the lines of ``list_file``, the audio files under ``folder``)
    into ``out_dir`` as ``format`` (bvh, glb, vrma, fbx, mp4) on ``character``.

    ``config`` is a ``DanceConfig`` and keyword ``overrides`` its fields, as for ``dance()``.
    ``workers``: local processes (default: the cores) or, with ``ray``, actors (default: the
    cluster's CPUs); ``ray=True`` joins the cluster started on this machine, a string is its
    address. ``threads``: torch and BLAS threads per worker (default ``DANCESYNTH_THREADS`` or 1).
    """
    from ..api import DanceConfig
    from ..export.formats import check_format
    from ..threads import thread_count

    config = config or DanceConfig()
    if overrides:
        config = replace(config, **overrides)
    if config.model is not None:   # a worker, a Ray actor above all, may run in another folder
        config = replace(config, model=os.path.abspath(config.model))
    suffix = check_format(Path("x." + str(format).lstrip(".")))
    if workers is not None and not (isinstance(workers, int) and 1 <= workers <= 4096):
        raise InputError(f"--workers {workers!r}: give a whole number of worker processes from 1 to 4096")
    settings = BatchSettings(config=config, suffix=suffix, database=None if database is None else str(database),
                             character=None if character is None else str(character),
                             bone_map=None if bone_map is None else str(bone_map), evaluate=evaluate, report=report,
                             threads=thread_count() if threads is None else int(threads))
    out_dir = output_folder(os.path.abspath(out_dir), "the dances")
    jobs = plan_jobs(collect_songs(songs, list_file=list_file, folder=folder), suffix)
    manifest = Manifest(out_dir)
    key = settings_key(settings.key_fields())
    last = manifest.last_records()
    todo = [j for j in jobs if not manifest.is_done(last.get(j.name), j.song, key, out_dir)]
    result = BatchResult(out_dir, manifest.path, skipped=len(jobs) - len(todo))
    if not todo:   # decided from the manifest alone: no character, database or worker is touched
        return result
    _check_settings(settings)
    use_numba_cache()  # the workers inherit it
    t0 = time.perf_counter()
    try:
        for record in _records(todo, settings, out_dir, workers, ray):
            record["settings"] = key
            manifest.append(record)
            result.records.append(record)
            if record["status"] == "done":
                result.done += 1
            else:
                result.failed += 1
            result.seconds = time.perf_counter() - t0
            if progress is not None:
                progress(record, result.done + result.failed, len(todo))
    finally:
        manifest.close()
        result.seconds = time.perf_counter() - t0
    return result


def _records(jobs: list[Job], settings: BatchSettings, out_dir: Path, workers, ray):
    if ray is None or ray is False:
        from .pool import run_local

        return run_local(jobs, settings, out_dir, workers or os.cpu_count() or 1)
    from .ray_runner import AUTO, run_ray

    return run_ray(jobs, settings, out_dir, workers, AUTO if ray is True else str(ray))


def _check_settings(settings: BatchSettings) -> None:
    """What would fail every song, found before any worker starts: the database, the character,
    a missing Blender for .fbx."""
    from ..export.formats import output_character
    from ..motion.catalog import list_styles

    output_character(settings.character, settings.bone_map, settings.suffix)
    list_styles(settings.database)

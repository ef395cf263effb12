"""One batch worker: loads the database and the character once, then dances song after song.

The same ``Worker`` runs in a local process (``pool``) and as a Ray actor (``ray_runner``). A
song that fails becomes a ``failed`` record with the reason; it never stops the worker.
"""

from __future__ import annotations

import os
import resource
import socket
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from ..errors import DanceSynthError
from .manifest import song_stamp
from .songs import Job

# The parts of a dance's report that grow with the song; the manifest keeps the rest (the per-song
# report file, ``--report``, keeps everything).
_PER_BEAT = ("music_beat_times_s", "grid_times_s", "transition_times_s", "segment_times_s", "warp_rates", "motifs")


@dataclass(frozen=True)
class BatchSettings:
    """What every song of a batch is danced with (picklable: it travels to the workers)."""

    config: object                    # api.DanceConfig
    suffix: str = ".bvh"              # the output format, by extension
    database: str | None = None       # a database folder; None: the bundled one
    character: str | None = None      # a built-in name, a file, "source"; None: the default (mannequin)
    bone_map: str | None = None
    evaluate: bool = False            # add ``dancesynth eval``'s metrics to each record
    report: bool = False              # also write NAME.report.json beside each dance
    threads: int = 1                  # torch and BLAS threads per worker

    def key_fields(self) -> dict:
        """What the dances depend on (a change re-dances finished songs on a re-run)."""
        from dataclasses import asdict

        return {"config": asdict(self.config), "suffix": self.suffix, "database": self.database,
                "character": self.character, "bone_map": self.bone_map, "evaluate": self.evaluate,
                "report": self.report}


class Worker:
    """Dances jobs one at a time with everything loaded once (``database``: an already-open
    ``MotionDatabase``, e.g. from Ray's object store)."""

    def __init__(self, settings: BatchSettings, database=None):
        from ..threads import limit_threads

        limit_threads(settings.threads)
        from ..export.formats import output_character
        from ..motion.database import open_database
        from ..retarget import SOURCE

        self.settings = settings
        self.database = database if database is not None else open_database(settings.database)
        self.character = output_character(settings.character, settings.bone_map, settings.suffix) or SOURCE
        self.where = f"{socket.gethostname()}:{os.getpid()}"

    def run(self, job: Job, out_dir: str | Path) -> dict:
        """Dance ``job`` into ``out_dir``; returns its manifest record (``status`` done or failed)."""
        t0, cpu0 = time.perf_counter(), time.process_time()
        record = {"name": job.name, "song": str(job.song), "worker": self.where}
        try:
            record.update(song_stamp(Path(job.song)))
            record.update(self._dance(job, Path(out_dir)))
            record["status"] = "done"
        except DanceSynthError as exc:
            record.update(status="failed", error=str(exc))
        except MemoryError:
            record.update(status="failed", error="out of memory dancing this song")
        except OSError as exc:
            record.update(status="failed", error=f"{exc.strerror or exc}" + (f": {exc.filename}" if exc.filename
                                                                             else ""))
        except Exception as exc:  # a bug met on one song must not stop the other 99,999
            record.update(status="failed", error=f"internal error: {type(exc).__name__}: {exc}")
        record.update(seconds=time.perf_counter() - t0, cpu_seconds=time.process_time() - cpu0,
                      peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
                      finished_at=datetime.now(timezone.utc).isoformat(timespec="seconds"))
        return record

    def _dance(self, job: Job, out_dir: Path) -> dict:
        from ..api import analyse, dance
        from ..export.formats import write_dance
        from ..retarget import on_character

        s = self.settings
        t = time.perf_counter()
        music = analyse(job.song, s.config.max_duration_s)
        analysed_s = time.perf_counter() - t
        clip = dance(music, config=s.config, database=self.database)
        t = time.perf_counter()
        moved, target = on_character(clip, self.character)
        output = out_dir / job.name
        output.parent.mkdir(parents=True, exist_ok=True)
        report = clip.provenance.report()
        write_dance(output, moved, target, song=Path(job.song))
        if s.report:
            from ..io.files import write_json

            write_json(output.with_name(output.name + ".report.json"), report)
        summary = dict(clip.provenance.summary)
        timings = {**summary.pop("timings_s", {}), "music_s": analysed_s, "write_s": time.perf_counter() - t}
        out = {"summary": summary, "timings_s": timings,
               "provenance": {k: v for k, v in report.items() if k not in _PER_BEAT + ("summary",)}}
        if s.evaluate:
            from ..eval.report import evaluate_dance

            out["eval"] = evaluate_dance(clip, music, report=report, database=self.database)["dance"]
        return out

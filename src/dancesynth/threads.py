"""Thread pools set on purpose.

torch and BLAS start one thread per core by default. Our matrices are small, so extra threads
only spin: torch inference ran 3.5-5.6x slower with them, BLAS spent 1.3-1.5x the CPU for no gain,
and two batch workers each starting a thread per core fight over the cores. So every process
runs them at ``DANCESYNTH_THREADS`` threads (default 1); set it higher for one big job alone on a
machine with cores to spare.
"""

from __future__ import annotations

import os
import sys

ENV = "DANCESYNTH_THREADS"
_BLAS_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS")


def thread_count() -> int:
    """Threads per process for torch and BLAS: ``DANCESYNTH_THREADS``, else 1."""
    from .errors import InputError

    raw = os.environ.get(ENV, "1")
    try:
        n = int(raw)
    except ValueError:
        n = 0
    if not 1 <= n <= 1024:
        raise InputError(f"{ENV}={raw!r} is not a thread count: use a whole number from 1 to 1024")
    return n


def limit_threads(n: int | None = None) -> int:
    """Run torch and BLAS at ``n`` threads (default ``thread_count()``) in this process; returns ``n``.

    Before numpy loads, the environment variables do it for free; afterwards threadpoolctl
    changes the loaded BLAS and OpenMP pools. torch is only touched if it is already loaded
    (it is heavy; ``torch_threads`` is called where it is used)."""
    n = thread_count() if n is None else int(n)
    for var in _BLAS_ENV:
        os.environ[var] = str(n)
    os.environ[ENV] = str(n)
    if "numpy" in sys.modules:
        from threadpoolctl import threadpool_limits

        threadpool_limits(n)
    if "torch" in sys.modules:
        torch_threads()
    return n


def torch_threads() -> None:
    """torch at ``thread_count()`` threads (call after importing torch, before running a model)."""
    import torch

    n = thread_count()
    if torch.get_num_threads() != n:
        torch.set_num_threads(n)

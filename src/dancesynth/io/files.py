"""User files at the boundary: read only what they may be read for (regular files, bounded sizes,
nothing outside a folder they name), and written so that a failure never leaves a partial output
behind."""

from __future__ import annotations

import contextlib
import dataclasses
import os
import shutil
import stat
import tempfile
from pathlib import Path

from ..errors import InputError


def read_user_file(path, *, limit: int, what: str, prefix: int | None = None) -> bytes:
    """The bytes of a regular file of at most ``limit`` bytes (``prefix``: only its first that many,
    and it must have them). A device, pipe or folder is refused: ``/dev/zero`` would fill memory and
    ``/dev/stdin`` block. ``what`` names the file in the error (``"bone map x.toml"``)."""
    try:
        with open(path, "rb", buffering=0, opener=_nonblocking) as fh:
            info = os.fstat(fh.fileno())
            if not stat.S_ISREG(info.st_mode):
                raise InputError(f"{what} is not a regular file (a device, pipe or folder); give a file")
            want = info.st_size if prefix is None else prefix
            if want > limit:
                raise InputError(f"{what} is {info.st_size / 2**20:.1f} MB; at most {limit / 2**20:g} MB is read")
            data = fh.read(want + (prefix is None))   # one more: a file that grew past its size
    except OSError as exc:
        raise InputError(f"cannot read {what}: {str(exc.strerror or exc).lower()}") from None
    except ValueError:   # a NUL byte in the path
        raise InputError(f"cannot read {what}: its name holds a NUL byte") from None
    if prefix is not None and len(data) < prefix:
        raise InputError(f"{what} is truncated: {len(data)} of the {prefix} bytes it should hold")
    if prefix is None and len(data) > limit:
        raise InputError(f"{what} is over {limit / 2**20:g} MB, the most that is read")
    return data


def decode_text(data: bytes, *, empty: str, binary: str) -> str:
    """A text file's bytes as text: ``InputError(empty)`` when blank, ``InputError(binary)`` when it holds
    NUL bytes; UTF-8 (a BOM dropped), else Latin-1 (old exporters write names in it; numbers and
    keywords are ASCII either way)."""
    if not data.strip():
        raise InputError(empty)
    if b"\x00" in data[:65536]:
        raise InputError(binary)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def _nonblocking(path, flags):
    # A FIFO opened for reading would block until a writer appears; O_NONBLOCK lets the check above see it.
    return os.open(path, flags | os.O_NONBLOCK)


def inside_folder(folder, relative: str) -> Path | None:
    """``folder / relative`` resolved (symlinks followed), or None when it lies outside ``folder``."""
    root = Path(folder).resolve()
    try:
        target = (root / relative).resolve()
    except (OSError, ValueError, RuntimeError):   # a NUL byte, a symlink loop
        return None
    return target if root in target.parents else None


@contextlib.contextmanager
def atomic_path(path):
    """A temporary path next to ``path`` (for a tool such as ffmpeg to write); moved into place only
    if the block succeeds, removed otherwise."""
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"cannot write {path}: folder {parent} does not exist (create it first)")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=parent)
    except OSError as exc:
        raise InputError(f"cannot write {path}: {exc.strerror} in folder {parent}; check its permissions") from None
    os.close(fd)
    try:
        yield Path(tmp)
        # mkstemp makes the file private (0600); give it the permissions a plain open() would.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.strerror:  # a full disk, a quota, a folder gone read-only
            raise InputError(f"cannot write {path}: {exc.strerror}; nothing was written") from None
        raise


@contextlib.contextmanager
def atomic_output(path, mode: str = "w", **open_kwargs):
    """Open a temporary file next to ``path``; move it into place only if the block succeeds."""
    with atomic_path(path) as tmp, open(tmp, mode, **open_kwargs) as fh:
        yield fh


@contextlib.contextmanager
def atomic_folder(path):
    """A temporary folder next to ``path`` to write a set of files into; they are moved into ``path``
    (created, or its files of the same names replaced) only if the block succeeds, removed otherwise."""
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if path.exists() and not path.is_dir():
        raise InputError(f"cannot write {path}: it is a file; give a folder")
    try:
        parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".part", dir=parent))
    except OSError as exc:
        raise InputError(f"cannot write {path}: {exc.strerror or exc}") from None
    try:
        yield tmp
        if path.is_dir():
            for f in tmp.iterdir():
                os.replace(f, path / f.name)
            tmp.rmdir()
        else:
            os.rename(tmp, path)
    except BaseException as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        if isinstance(exc, OSError) and exc.strerror:  # a full disk, a quota, a folder gone read-only
            raise InputError(f"cannot write {path}: {exc.strerror}; nothing was written") from None
        raise


def output_folder(path, what: str) -> Path:
    """``path`` as a folder to write ``what`` into, created if needed; a clear error if it is a file,
    cannot be created or cannot be written to."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputError(f"output folder {path} is a file; give a folder for {what}")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot write {path}: cannot create output folder ({exc.strerror or exc})") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise InputError(f"cannot write to output folder {path}: permission denied")
    return path


def stop_cleanly_on_sigterm() -> None:
    """SIGTERM (``kill``, a service manager, a container stopping) ends the process as an exception
    would, so half-written outputs are removed on the way out (by default it kills outright and
    leaves a hidden ``.part`` file behind). The exit code is the usual 128 + 15."""
    import signal

    def terminate(signum, frame):
        raise SystemExit(128 + signum)

    signal.signal(signal.SIGTERM, terminate)


def write_json(path, data) -> None:
    """``data`` as indented JSON at ``path``, whole or not at all (NaN refused: JSON has none)."""
    import json

    with atomic_output(path) as fh:
        json.dump(data, fh, indent=1, allow_nan=False)
        fh.write("\n")


def jsonable(x):
    """Plain JSON types: numpy scalars and arrays, paths, tuples, non-finite floats (as null)."""
    import numpy as np  # here, not at the top: the command line's start-up reads this module

    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if np.isfinite(x) else None
    if x is None or isinstance(x, str):
        return x
    if hasattr(x, "__dataclass_fields__"):
        return jsonable(dataclasses.asdict(x))
    return str(x)


def use_numba_cache() -> None:
    """librosa JIT-compiles with numba; a persistent cache (``NUMBA_CACHE_DIR``, unless set) saves
    seconds on every later run, in this process and in the workers it starts."""
    os.environ.setdefault("NUMBA_CACHE_DIR", str(cache_dir() / "numba"))


def cache_dir() -> Path:
    """Where built graphs and databases are cached (``$DANCESYNTH_CACHE`` or the user cache).
    Here, in a light module, so the command line finds it without loading the motion analysis."""
    root = os.environ.get("DANCESYNTH_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "dancesynth")
    return Path(root)

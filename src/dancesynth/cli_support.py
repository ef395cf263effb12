"""What the command-line modules share: progress bars, checked output paths, JSON files."""

from __future__ import annotations

import sys
from pathlib import Path

from .errors import InputError
from .io.files import write_json  # noqa: F401  (the CLI modules import it from here)


class Progress:
    """A tqdm bar per stage on stderr (quiet when asked or when stderr is not a terminal)."""

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.bars = {}

    def __call__(self, stage: str, done: int, total: int):
        if not self.enabled:
            return
        from tqdm import tqdm

        bar = self.bars.get(stage)
        if bar is None:
            bar = self.bars[stage] = tqdm(total=total, desc=stage, unit="seg", leave=False, file=sys.stderr)
        bar.update(done - bar.n)
        if done >= total:
            bar.close()

    def close(self):
        for bar in self.bars.values():
            bar.close()


def bvh_output(path: Path) -> Path:
    """``path``, refused unless it names a .bvh file."""
    if path.suffix.lower() != ".bvh":
        raise InputError(f"output {path} must end in .bvh")
    return path


def writable(*paths: Path | None) -> None:
    """Refuse, before any work, output files whose folder does not exist (``None``: not asked for)."""
    for out in paths:
        if out is not None and not out.parent.is_dir():
            raise InputError(f"cannot write {out}: folder {out.parent} does not exist")

"""A fixed-capacity ring of recent rows (audio samples, spectra) for the streaming analysis."""

from __future__ import annotations

import numpy as np


class Ring:
    """A fixed-capacity buffer of rows that keeps the last ``keep`` rows (amortised O(1) append)."""

    def __init__(self, keep: int, row_shape: tuple = (), dtype=np.float32, start: int = 0):
        self.keep, self.data = keep, np.zeros((2 * keep,) + row_shape, dtype=dtype)
        self.size, self.start = 0, start    # rows held; global index of data[0]

    def append(self, rows: np.ndarray, on_drop=None) -> None:
        if self.size + len(rows) > len(self.data):
            drop = max(self.size - self.keep, self.size + len(rows) - len(self.data), 0)
            if on_drop is not None:
                on_drop(self.data[:drop], self.start)
            self.data[:self.size - drop] = self.data[drop:self.size]
            self.size, self.start = self.size - drop, self.start + drop
        self.data[self.size:self.size + len(rows)] = rows
        self.size += len(rows)

    def view(self) -> np.ndarray:
        return self.data[:self.size]

    @property
    def end(self) -> int:
        return self.start + self.size

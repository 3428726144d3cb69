"""A series of rows kept within a fixed memory, spanning the whole run however long it is."""
from __future__ import annotations

import numpy as np

__all__ = ["BoundedSeries"]


class BoundedSeries:
    """Rows of floats kept up to ``capacity``; when full, every other row is dropped and only
    every ``stride``-th new row is kept (so the series always spans the whole run)."""

    def __init__(self, names: tuple[str, ...], capacity: int):
        self.names = names
        self.capacity = int(capacity)
        self._data = np.empty((self.capacity, len(names)))
        self._n = 0
        self._seen = 0
        self.stride = 1

    def __len__(self) -> int:
        return self._n

    def extend(self, rows: np.ndarray) -> None:
        rows = np.asarray(rows, dtype=float).reshape(-1, len(self.names))
        idx = self._seen + np.arange(len(rows))
        self._seen += len(rows)
        while True:
            keep = rows[idx % self.stride == 0]
            if self._n + len(keep) <= self.capacity:
                self._data[self._n:self._n + len(keep)] = keep
                self._n += len(keep)
                return
            half = self._data[:self._n:2].copy()     # kept rows are multiples of stride: keep 2·stride
            self._n = len(half)
            self._data[:self._n] = half
            self.stride *= 2

    def array(self) -> np.ndarray:
        return self._data[:self._n].copy()

    def column(self, name: str) -> np.ndarray:
        return self._data[:self._n, self.names.index(name)].copy()

    def clear(self) -> None:
        self._n = 0
        self._seen = 0
        self.stride = 1

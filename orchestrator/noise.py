"""Measurement noise: reproducible Gaussian errors added to the written values only.

Draw order (so anyone can regenerate the noise): ``numpy.random.default_rng(seed)``,
``standard_normal`` row by row, one draw per output listed in ``std`` (even with std 0),
in the order of the case's outputs; the draw times ``std`` is added to the FMU's value.
Drawing a block of rows at once gives the same numbers as drawing them one row at a
time, so the noise does not depend on the flush interval.
"""
from __future__ import annotations

from typing import Sequence

from .case import Noise

__all__ = ["NoiseSource"]


class NoiseSource:
    """Adds the noise of ``noise`` to rows whose columns are ``outputs``."""

    def __init__(self, noise: Noise, outputs: Sequence[str]):
        import numpy as np

        self._columns = [i for i, name in enumerate(outputs) if name in noise.std]
        self._std = np.array([noise.std[outputs[i]] for i in self._columns], dtype=float)
        self._rng = np.random.default_rng(noise.seed)

    def apply(self, rows: list[list]) -> list[list]:
        """Add one draw per noisy column to each row, in place; returns ``rows``."""
        if not rows or not self._columns:
            return rows
        draws = (self._rng.standard_normal((len(rows), len(self._columns))) * self._std).tolist()
        columns = self._columns
        for row, row_draws in zip(rows, draws):
            for column, draw in zip(columns, row_draws):
                row[column] = row[column] + draw
        return rows

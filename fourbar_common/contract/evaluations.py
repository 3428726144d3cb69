"""The monitor's ``evaluations.csv``: every evaluation of the detector, written as it happens.

Header ``time,statistic,threshold,state``; one row per evaluation: ``time`` (simulated s, the
end of the evaluated interval), ``statistic`` (cusum: the largest CUSUM statistic of the
interval; mae: the window's MAE) and ``threshold`` (its limit) as floats written with ``repr``
(they read back to the same double; ``inf``/``nan`` where the detector gives them), ``state``
the detector's state after it (``training``, ``monitoring``, ``alarm``, ...).  The monitor
flushes each row, so a reader sees complete lines except, while it writes, the last one.

:func:`read_evaluations` reads a finished file strictly (every complete line a valid row, or
a :class:`~.problems.ContractError` listing each problem); :class:`EvaluationsTail` reads a
growing one, skipping rows without a valid time and counting them.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from .exchange import TableRow, TableTail, read_table
from .problems import ContractError, Problem

__all__ = ["COLUMNS", "Evaluation", "Evaluations", "EvaluationsTail", "HEADER", "format_row", "read_evaluations",
           "write_evaluations"]

#: The columns, in the file's order.
COLUMNS = ("time", "statistic", "threshold", "state")
#: The header line.
HEADER = ",".join(COLUMNS) + "\n"


@dataclass(frozen=True)
class Evaluation:
    """One row."""

    time: float          # s
    statistic: float
    threshold: float
    state: str


def format_row(time: float, statistic: float, threshold: float, state: str) -> str:
    """One row's line, ``\\n``-terminated (floats as ``repr``: they read back exactly)."""
    return f"{float(time)!r},{float(statistic)!r},{float(threshold)!r},{state}\n"


@dataclass(frozen=True)
class Evaluations:
    """Rows as columns: ``time``, ``statistic``, ``threshold`` float64 arrays and ``state``, of one length."""

    time: np.ndarray
    statistic: np.ndarray
    threshold: np.ndarray
    state: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.time)

    @classmethod
    def from_rows(cls, rows: Iterable[Evaluation]) -> "Evaluations":
        rows = list(rows)
        return cls(np.array([r.time for r in rows], dtype=float), np.array([r.statistic for r in rows], dtype=float),
                   np.array([r.threshold for r in rows], dtype=float), tuple(r.state for r in rows))

    def rows(self) -> list[Evaluation]:
        return [Evaluation(float(t), float(s), float(h), st)
                for t, s, h, st in zip(self.time, self.statistic, self.threshold, self.state)]


def _float(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def _parse(rows: Sequence[TableRow], strict: bool) -> tuple[list[Evaluation], list[Problem]]:
    """Typed rows and, for each row that is not valid, a problem (strict: a statistic or a
    threshold that is not a number, or an empty state, makes a row invalid too; else NaN)."""
    out, problems = [], []
    for row in rows:
        t, statistic, threshold, state = row.fields
        time = _float(t)
        values = (_float(statistic), _float(threshold))
        state = state.strip()
        wrong = []
        if time is None or not math.isfinite(time):
            wrong.append(f"time {t.strip()[:40]!r} is not a finite number")
        if strict:
            wrong += [f"{name} {text.strip()[:40]!r} is not a number"
                      for name, text, v in zip(COLUMNS[1:3], (statistic, threshold), values) if v is None]
            if not state:
                wrong.append("state is empty")
        if wrong:
            problems.append(Problem(f"line {row.line}", "; ".join(wrong)))
            continue
        out.append(Evaluation(time, *(math.nan if v is None else v for v in values), state))
    return out, problems


def read_evaluations(path: str | os.PathLike[str]) -> Evaluations:
    """Every row of a finished evaluations.csv (module docstring).  Raises ``FileNotFoundError``
    when there is none and :class:`~.problems.ContractError` listing every problem otherwise."""
    rows, malformed = read_table(path, COLUMNS)
    out, problems = _parse(rows, strict=True)
    if malformed or problems:          # in line order, the first 20
        found = sorted(malformed + problems, key=lambda p: int(p.field.split()[-1]))
        raise ContractError(str(path), found[:20])
    return Evaluations.from_rows(out)


def write_evaluations(path: str | os.PathLike[str], rows: Iterable[Evaluation]) -> None:
    """Write a whole evaluations.csv (the monitor streams the same lines: :data:`HEADER`, :func:`format_row`)."""
    with open(Path(path), "w", encoding="utf-8", newline="") as fh:
        fh.write(HEADER)
        fh.writelines(format_row(r.time, r.statistic, r.threshold, r.state) for r in rows)


class EvaluationsTail:
    """The rows appended to a growing evaluations.csv since the last poll.

    :meth:`poll` gives (new rows, restarted): rows without a valid time are skipped and
    counted in :attr:`skipped`; a statistic or threshold that is not a number reads as NaN.
    A header other than :data:`HEADER` raises :class:`~.problems.ContractError`.
    """

    def __init__(self, path: str | os.PathLike[str], *, max_chunk_bytes: int = 4 << 20):
        self._tail = TableTail(path, COLUMNS, max_chunk_bytes=max_chunk_bytes)
        self.path = self._tail.path
        self.skipped = 0

    def poll(self) -> tuple[Evaluations, bool]:
        rows, bad, restarted = self._tail.poll()
        out, problems = _parse(rows, strict=False)
        self.skipped += len(bad) + len(problems)
        return Evaluations.from_rows(out), restarted

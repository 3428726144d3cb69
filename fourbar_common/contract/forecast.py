"""The monitor's ``forecast.csv``: each judged sample beside what the detector compared it with.

Header ``time,signal,value,forecast``, long format: one row per monitored column per judged
sample (the training window's samples, then every later one), the signals of one sample
together in the monitored order.  ``value`` is the sample as read, ``forecast`` what the
detector compared it with when it judged it, empty for the training samples (read as NaN).
Floats are written with ``repr`` (the shortest text that reads back to the same double).

:func:`read_forecast` reads a finished file strictly (every complete line a valid row, or a
:class:`~.problems.ContractError` listing each problem); :class:`ForecastTail` reads a growing
one, skipping rows without a valid time and counting them.
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

__all__ = ["COLUMNS", "Forecast", "ForecastRow", "ForecastTail", "HEADER", "format_row", "format_rows", "read_forecast",
           "write_forecast"]

#: The columns, in the file's order: long format, one row per monitored column per judged sample.
COLUMNS = ("time", "signal", "value", "forecast")
#: The header line: the monitor writes it when it starts, before any row.
HEADER = ",".join(COLUMNS) + "\n"


@dataclass(frozen=True)
class ForecastRow:
    """One row: ``forecast`` is NaN for a training sample (written empty)."""

    time: float          # s
    signal: str
    value: float
    forecast: float


def format_row(row: ForecastRow) -> str:
    """One row's line, ``\\n``-terminated (floats as ``repr``; NaN forecast: empty)."""
    forecast = "" if row.forecast != row.forecast else repr(float(row.forecast))
    return f"{float(row.time)!r},{row.signal},{float(row.value)!r},{forecast}\n"


def format_rows(signals: Sequence[str], t: np.ndarray, x: np.ndarray, f: np.ndarray) -> str:
    """The lines of judged samples: times ``t``, values ``x`` and forecasts ``f`` (one column per
    signal of ``signals``; NaN: no forecast), sample by sample, each sample's signals together."""
    names = tuple(signals)
    if x.shape[1] != len(names) or f.shape != x.shape:
        raise ValueError(f"forecast rows: {x.shape[1]} value and {f.shape} forecast columns for "
                         f"{len(names)} signals")
    # repr of a Python float is the shortest text that reads back to the same double
    tt = [repr(v) for v in np.asarray(t, dtype=float).tolist()]
    lines = []
    for j, name in enumerate(names):
        xs = [repr(v) for v in x[:, j].tolist()]
        fs = ["" if v != v else repr(v) for v in f[:, j].tolist()]     # NaN (v != v): no forecast
        lines.append([f"{a},{name},{b},{c}\n" for a, b, c in zip(tt, xs, fs)])
    return "".join(lines[0]) if len(lines) == 1 else "".join(map("".join, zip(*lines)))


@dataclass(frozen=True)
class Forecast:
    """Rows as columns: ``time``, ``value``, ``forecast`` float64 arrays and ``signal``, of one length."""

    time: np.ndarray
    signal: tuple[str, ...]
    value: np.ndarray
    forecast: np.ndarray

    def __len__(self) -> int:
        return len(self.time)

    @classmethod
    def from_rows(cls, rows: Iterable[ForecastRow]) -> "Forecast":
        rows = list(rows)
        return cls(np.array([r.time for r in rows], dtype=float), tuple(r.signal for r in rows),
                   np.array([r.value for r in rows], dtype=float), np.array([r.forecast for r in rows], dtype=float))

    def rows(self) -> list[ForecastRow]:
        return [ForecastRow(float(t), s, float(v), float(f))
                for t, s, v, f in zip(self.time, self.signal, self.value, self.forecast)]


def _float(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def _parse(rows: Sequence[TableRow], strict: bool) -> tuple[list[ForecastRow], list[Problem]]:
    """Typed rows and, for each row that is not valid, a problem (strict: an empty signal, a value
    that is not a number or a forecast that is neither empty nor a number make a row invalid
    too; else NaN)."""
    out, problems = [], []
    for row in rows:
        t, signal, value, forecast = row.fields
        time, v = _float(t), _float(value)
        f = math.nan if not forecast.strip() else _float(forecast)
        signal = signal.strip()
        wrong = []
        if time is None or not math.isfinite(time):
            wrong.append(f"time {t.strip()[:40]!r} is not a finite number")
        if strict:
            if not signal:
                wrong.append("signal is empty")
            if v is None:
                wrong.append(f"value {value.strip()[:40]!r} is not a number")
            if f is None:
                wrong.append(f"forecast {forecast.strip()[:40]!r} is neither empty nor a number")
        if wrong:
            problems.append(Problem(f"line {row.line}", "; ".join(wrong)))
            continue
        out.append(ForecastRow(time, signal, math.nan if v is None else v, math.nan if f is None else f))
    return out, problems


def read_forecast(path: str | os.PathLike[str]) -> Forecast:
    """Every row of a finished forecast.csv (module docstring).  Raises ``FileNotFoundError``
    when there is none and :class:`~.problems.ContractError` listing every problem otherwise."""
    rows, malformed = read_table(path, COLUMNS)
    out, problems = _parse(rows, strict=True)
    if malformed or problems:          # in line order, the first 20
        found = sorted(malformed + problems, key=lambda p: int(p.field.split()[-1]))
        raise ContractError(str(path), found[:20])
    return Forecast.from_rows(out)


def write_forecast(path: str | os.PathLike[str], table: Forecast) -> None:
    """Write a whole forecast.csv (the monitor streams the same lines: :data:`HEADER`, :func:`format_rows`)."""
    with open(Path(path), "w", encoding="utf-8", newline="") as fh:
        fh.write(HEADER)
        fh.writelines(map(format_row, table.rows()))


class ForecastTail:
    """The rows appended to a growing forecast.csv since the last poll.

    :meth:`poll` gives (new rows, restarted): rows without a valid time are skipped and
    counted in :attr:`skipped`; a value or forecast that is not a number reads as NaN.  A
    header other than :data:`HEADER` raises :class:`~.problems.ContractError`.
    """

    def __init__(self, path: str | os.PathLike[str], *, max_chunk_bytes: int = 4 << 20):
        self._tail = TableTail(path, COLUMNS, max_chunk_bytes=max_chunk_bytes)
        self.path = self._tail.path
        self.skipped = 0

    def poll(self) -> tuple[Forecast, bool]:
        rows, bad, restarted = self._tail.poll()
        out, problems = _parse(rows, strict=False)
        self.skipped += len(bad) + len(problems)
        return Forecast.from_rows(out), restarted

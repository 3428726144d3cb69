"""Everything read from a run folder so far, indexed by simulated time.

:class:`Timeline` takes the :class:`~view.sources.Update` of each poll and keeps the run in
numpy arrays that grow by doubling, so a page can ask for any instant: the row at ``t`` (the
mechanism), the rows in ``(t0, t1]`` (what to stream), the recent window at full resolution,
and the whole run as min/max per bin (the long view: an hour at 100 Hz is 360,000 rows, 3,600
bins).  Memory is the rows kept, ``8 * (1 + columns)`` bytes each: 43 MB for an hour of the
four-bar's 14 columns at 100 Hz.  Pure numpy/pandas: no page code here.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from fourbar_common.contract.run_record import RunRecord

from .components import ComponentSignals, component_signals
from .sources import Diagnosis, MonitorEvent, Update

__all__ = ["Series", "Timeline", "StateAt"]


class Series:
    """Rows of named float columns, appended in time order; ``time`` is the first column."""

    def __init__(self, columns: tuple[str, ...]):
        self.columns = tuple(columns)
        self._data = np.empty((1024, len(self.columns)))
        self.n = 0

    def append(self, frame: pd.DataFrame) -> int:
        """Append the rows of ``frame`` (missing columns as NaN) later than the last kept; returns
        how many were added."""
        block = np.full((len(frame), len(self.columns)), np.nan)
        for i, c in enumerate(self.columns):
            if c in frame:
                block[:, i] = pd.to_numeric(frame[c], errors="coerce").to_numpy(float)
        if self.n:
            block = block[block[:, 0] > self._data[self.n - 1, 0]]
        block = block[np.isfinite(block[:, 0])]
        if not len(block):
            return 0
        need = self.n + len(block)
        if need > len(self._data):
            grown = np.empty((max(need, 2 * len(self._data)), len(self.columns)))
            grown[:self.n] = self._data[:self.n]
            self._data = grown
        self._data[self.n:need] = block
        self.n = need
        return len(block)

    @property
    def time(self) -> np.ndarray:
        return self._data[:self.n, 0]

    def column(self, name: str) -> np.ndarray:
        return self._data[:self.n, self.columns.index(name)]

    @property
    def last_time(self) -> float | None:
        return float(self._data[self.n - 1, 0]) if self.n else None

    def index_at(self, t: float) -> int:
        """Index of the last row at or before ``t`` (-1: none)."""
        return int(np.searchsorted(self.time, t, side="right")) - 1

    def between(self, t0: float, t1: float, names) -> dict[str, np.ndarray]:
        """Columns ``names`` (and ``time``) of the rows with t0 < time <= t1."""
        time = self.time
        i0, i1 = np.searchsorted(time, t0, side="right"), np.searchsorted(time, t1, side="right")
        return {"time": time[i0:i1].copy(), **{n: self.column(n)[i0:i1].copy() for n in names}}

    def envelope(self, name: str, t1: float, bin_s: float) -> dict[str, np.ndarray]:
        """Per bin of ``bin_s`` seconds up to ``t1``: the bin's centre, min and max of ``name``."""
        time = self.time
        end = np.searchsorted(time, t1, side="right")
        if end == 0:
            return {"time": np.empty(0), "low": np.empty(0), "high": np.empty(0)}
        t, v = time[:end], self.column(name)[:end]
        bins = np.floor((t - t[0]) / bin_s).astype(np.int64)
        starts = np.flatnonzero(np.r_[True, bins[1:] != bins[:-1]])
        ok = np.isfinite(v)
        safe_low, safe_high = np.where(ok, v, np.inf), np.where(ok, v, -np.inf)
        low, high = np.minimum.reduceat(safe_low, starts), np.maximum.reduceat(safe_high, starts)
        centre = t[0] + (bins[starts] + 0.5) * bin_s
        good = np.isfinite(low) & np.isfinite(high)
        return {"time": centre[good], "low": low[good], "high": high[good]}

    @property
    def nbytes(self) -> int:
        return int(self._data.nbytes)


@dataclass
class StateAt:
    """What the monitor said up to a time."""

    state: str                         # WAITING | TRAINING | STABLE | ALARM
    message: str = ""
    alarm_time: float | None = None
    train: tuple[float, float] | None = None


@dataclass
class Timeline:
    """The run so far; feed it every :class:`Update`."""

    record: RunRecord | None = None
    record_problem: str | None = None
    rows: Series | None = None
    evaluations: Series = field(default_factory=lambda: Series(("time", "statistic", "threshold")))
    forecasts: dict[str, Series] = field(default_factory=dict)     # per monitored signal
    events: list[MonitorEvent] = field(default_factory=list)
    diagnosis: Diagnosis | None = None
    writer_gone: bool = False
    warnings: list[str] = field(default_factory=list)
    generation: int = 0                # +1 whenever what was shown must be dropped (a new run)

    def feed(self, update: Update) -> None:
        if update.restarted:
            self.rows = None
            self.diagnosis = None
        if update.restarted or update.monitor_restarted:
            self.evaluations = Series(("time", "statistic", "threshold"))
            self.forecasts = {}
            self.events = []
            self.generation += 1
        if update.record is not None:
            self.record = update.record
            self.record_problem = None
        if update.record_problem is not None:
            self.record_problem = update.record_problem
        if update.rows is not None:
            if self.rows is None:
                self.rows = Series(("time", *[c for c in update.rows.columns if c != "time"]))
            self.rows.append(update.rows)
        if update.evaluations is not None:
            self.evaluations.append(update.evaluations)
        if update.forecast is not None and {"signal", "time"} <= set(update.forecast.columns):
            for name, part in update.forecast.groupby("signal", sort=False):
                series = self.forecasts.setdefault(str(name), Series(("time", "value", "forecast")))
                series.append(part)
        self.events.extend(update.events)
        if update.diagnosis is not None:
            self.diagnosis = update.diagnosis
        self.writer_gone = update.writer_gone
        self.warnings.extend(update.warnings)

    # -- questions a page asks ----------------------------------------------------------
    @property
    def last_time(self) -> float | None:
        return self.rows.last_time if self.rows is not None else None

    @property
    def first_time(self) -> float | None:
        return float(self.rows.time[0]) if self.rows is not None and self.rows.n else None

    @property
    def signals(self) -> tuple[str, ...]:
        """The monitored signals (forecast.csv's), else the first recorded output."""
        if self.forecasts:
            return tuple(self.forecasts)
        if self.rows is not None and len(self.rows.columns) > 1:
            return (self.rows.columns[1],)
        return ()

    @property
    def components(self) -> tuple[ComponentSignals, ...]:
        """A system run's recorded signals per component (:func:`view.components.component_signals`)."""
        return component_signals(self.record, self.rows.columns if self.rows is not None else ())

    def state_at(self, t: float) -> StateAt:
        state = StateAt("WAITING" if not self.events else "TRAINING")
        for e in self.events:
            if e.time > t:
                break
            if e.event in ("trained", "refit") and e.train_start is not None and e.train_end is not None:
                state.train = (e.train_start, e.train_end)
            if e.event == "alarm":
                state.state, state.message = "ALARM", e.message
                state.alarm_time = state.alarm_time if state.alarm_time is not None else e.time
            elif e.event in ("trained", "stable", "clear", "refit"):
                state.state = "ALARM" if e.state.upper() == "ALARM" else "STABLE"
        return state

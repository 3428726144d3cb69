"""The exchange file's time grid, checked row by row: missing rows, time jumps, rows off the grid.

fourbar-run writes one row per communication point ``start + k*step`` (run.json's
``experiment``), so the times of a healthy file are that grid with every ``k`` present.
:class:`GridChecker` sits between the reader and the monitor and compares each accepted
row with it:

``grid``
    run.json's ``experiment.start`` and ``experiment.step`` (rows after ``experiment.stop``
    are off the grid).  Without run.json (or with one that records no experiment) the
    file's own dominant step: the median of the first :data:`LEARN_ROWS` steps, with the
    first row as origin; the rows are held until that many have come (or the data end).
``off_grid``
    a row whose time is farther than :data:`GRID_TOLERANCE` steps from the nearest grid
    time (non-uniform steps, 1e-9 s steps, rows before the start or after the stop) is
    dropped; each run of consecutive such rows is one :class:`GridIssue`.
``missing``
    two consecutive on-grid rows more than one step apart: the rows between are missing
    (a time jump is a long run of missing rows).  A gap longer than the monitor's
    evaluation interval is *skipped*: the session tells the monitor, which advances its
    evaluation clock past it instead of evaluating the empty span point by point, so the
    work is bounded by the number of rows, not by the time span.
``duplicate``
    a row whose time repeats (or goes back before) an earlier row's; the reader drops it
    (:mod:`monitor.reader`), the session records it here so it counts as a grid problem.

Every issue names its span (from, to, how many rows).  The session decides from them
whether the verdict is indeterminate (:mod:`monitor.session`).

Memory: a bounded list of example issues (:data:`MAX_ISSUES`) and counters; the rows are
processed with numpy, so 10 million rows at 1e-9 s steps cost a few seconds.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fourbar_common.contract.layout import RUN_RECORD

__all__ = ["GRID_TOLERANCE", "Grid", "GridChecker", "GridIssue", "GridPiece", "GridStats", "LEARN_ROWS",
           "MAX_ISSUES", "grid_of"]

#: A row is on the grid when its time is within this many steps of ``start + k*step`` (times
#: are written with 17 significant digits, so a healthy file is within 1e-12 steps).
GRID_TOLERANCE = 1e-6
#: Rows whose steps give the dominant step of a file without run.json.
LEARN_ROWS = 32
#: Example issues kept (the counters count all).
MAX_ISSUES = 100


@dataclass(frozen=True)
class Grid:
    """The expected times ``start + k*step`` (s), up to ``stop`` (None: open-ended);
    ``source`` says where it comes from (for messages)."""

    start: float
    step: float
    stop: float | None
    source: str

    def describe(self) -> str:
        return f"the {self.step:g} s grid ({self.source})"


@dataclass(frozen=True)
class GridIssue:
    """One problem of the grid: ``rows`` rows missing, off the grid or duplicated in the span
    ``start``–``end`` (s).  For ``missing`` the span is between the rows around the gap."""

    kind: str
    start: float
    end: float
    rows: int
    message: str

    def affects(self, from_time: float) -> bool:
        """True when the span reaches ``from_time`` (s) or later (e.g. the training start)."""
        return self.end >= from_time

    def as_dict(self) -> dict:
        return {"kind": self.kind, "from": self.start, "to": self.end, "rows": self.rows, "message": self.message}


@dataclass
class GridStats:
    """Counters of the grid problems found (reset when the file is replaced)."""

    missing_rows: int = 0
    gaps: int = 0
    skipped_gaps: int = 0
    off_grid_rows: int = 0
    duplicate_rows: int = 0
    issues: list[GridIssue] = field(default_factory=list)
    issue_count: int = 0
    #: issues whose span reaches the watched time (the training start) or later, and the first
    watched: int = 0
    first_watched: GridIssue | None = None

    @property
    def problems(self) -> int:
        return self.missing_rows + self.off_grid_rows + self.duplicate_rows

    def as_dict(self) -> dict:
        return {"missing_rows": self.missing_rows, "gaps": self.gaps, "skipped_gaps": self.skipped_gaps,
                "off_grid_rows": self.off_grid_rows, "duplicate_rows": self.duplicate_rows,
                "issues": self.issue_count, "issues_in_window": self.watched, "examples": [i.as_dict() for i in self.issues]}


@dataclass(frozen=True)
class GridPiece:
    """Rows on the grid with no missing row between them; ``gap_before`` is the gap that
    precedes them (None for the first piece of the data, or none)."""

    time: np.ndarray
    values: np.ndarray
    gap_before: GridIssue | None = None


class GridChecker:
    """Splits accepted rows into :class:`GridPiece` s on the grid (module docstring).

    ``source`` names the file in messages; ``grid`` None learns the file's dominant step.
    New issues are collected in :attr:`new_issues` by each call (the session warns with them).
    """

    def __init__(self, source: str, grid: Grid | None, *, watch_from: float = -math.inf):
        self.source = source
        self.fixed_grid = grid
        self.watch_from = float(watch_from)
        self.reset()

    def reset(self) -> None:
        """Forget the file (it was replaced): the grid is learnt again if it was learnt."""
        self.grid = self.fixed_grid
        self.stats = GridStats()
        self.new_issues: list[GridIssue] = []
        self._last_k: float | None = None
        self._last_t: float | None = None
        self._held_t = np.empty(0)
        self._held_x: np.ndarray | None = None
        self._off_run: list | None = None      # [first time, last time, rows] of the current off-grid run

    # -- issues -----------------------------------------------------------------------------
    def _issue(self, kind: str, start: float, end: float, rows: int, message: str, *, said: bool = False
               ) -> GridIssue:
        issue = GridIssue(kind, float(start), float(end), int(rows), f"{self.source}: {message}")
        self.stats.issue_count += 1
        if issue.affects(self.watch_from):
            self.stats.watched += 1
            if self.stats.first_watched is None:
                self.stats.first_watched = issue
        if len(self.stats.issues) < MAX_ISSUES:
            self.stats.issues.append(issue)
        if not said:
            self.new_issues.append(issue)
        return issue

    def duplicate(self, time: float, rows: int, message: str) -> None:
        """The reader dropped ``rows`` rows whose time repeats or goes back, the first at
        ``time`` (the reader has warned with ``message`` already: not in :attr:`new_issues`)."""
        self.stats.duplicate_rows += rows
        self._issue("duplicate", time, time, rows, message, said=True)

    def _close_off_run(self) -> None:
        if self._off_run is None:
            return
        a, b, n = self._off_run
        self._off_run = None
        where = f"at t = {a:.12g} s" if n == 1 else f"from t = {a:.12g} s to t = {b:.12g} s"
        self._issue("off_grid", a, b, n, f"{n} row(s) {where} are off {self.grid.describe()}; skipped")

    # -- rows ---------------------------------------------------------------------------------
    def split(self, t: np.ndarray, x: np.ndarray) -> list[GridPiece]:
        """The on-grid rows of a batch (strictly increasing times), cut at every gap."""
        self.new_issues = []
        t = np.asarray(t, dtype=float)
        if t.size == 0:
            return []
        x = np.asarray(x, dtype=float).reshape(t.size, -1)
        if self.grid is None:
            self._held_t = np.concatenate([self._held_t, t])
            self._held_x = x if self._held_x is None else np.vstack([self._held_x, x])
            if self._held_t.size <= LEARN_ROWS:
                return []
            return self._learn_and_release()
        return self._pieces(t, x)

    def flush(self) -> list[GridPiece]:
        """The data ended: release held rows (a grid learnt from what there is) and close spans."""
        self.new_issues = []
        pieces: list[GridPiece] = []
        if self.grid is None and self._held_t.size:
            if self._held_t.size >= 2:
                pieces = self._learn_and_release()
            else:                           # one row: nothing to check it against
                pieces = [GridPiece(self._held_t, self._held_x)]
                self._held_t, self._held_x = np.empty(0), None
        self._close_off_run()
        return pieces

    def _learn_and_release(self) -> list[GridPiece]:
        t, x = self._held_t, self._held_x
        self._held_t, self._held_x = np.empty(0), None
        steps = np.diff(t[:LEARN_ROWS + 1])
        step = float(np.median(steps))
        n = steps.size
        if np.all(np.abs(steps - step) <= GRID_TOLERANCE * step):   # a clean start: the mean is exact
            step = float((t[n] - t[0]) / n)
        self.grid = Grid(float(t[0]), step, None, "the file's dominant step; no run.json")
        return self._pieces(t, x)

    def _pieces(self, t: np.ndarray, x: np.ndarray) -> list[GridPiece]:
        g = self.grid
        u = (t - g.start) / g.step
        k = np.rint(u)
        on = np.abs(u - k) <= GRID_TOLERANCE
        on &= k >= 0
        if g.stop is not None:
            on &= t <= g.stop + GRID_TOLERANCE * g.step
        # a second row at a grid point already taken (steps far below the grid's) is off it too
        idx = np.flatnonzero(on)
        if idx.size:
            kk = k[idx]
            prev = np.concatenate([[self._last_k if self._last_k is not None else -np.inf], kk[:-1]])
            taken = kk <= prev
            if taken.any():
                kk_max = np.maximum.accumulate(np.concatenate([[prev[0]], kk]))[:-1]
                on[idx[kk <= kk_max]] = False
        self._off_runs(t, on)
        t, x, k = t[on], x[on], k[on]
        if t.size == 0:
            return []
        prev_k = np.concatenate([[self._last_k if self._last_k is not None else k[0] - 1], k[:-1]])
        prev_t = np.concatenate([[self._last_t if self._last_t is not None else -math.inf], t[:-1]])
        jump = np.flatnonzero(k - prev_k > 1)
        self._last_k, self._last_t = float(k[-1]), float(t[-1])
        cuts = [0, *jump.tolist(), t.size]
        gaps_at = set(jump.tolist())
        pieces = []
        for a, b in zip(cuts[:-1], cuts[1:]):
            if a == b:
                continue
            gap = None
            if a in gaps_at:         # a gap precedes the row at a
                rows = int(k[a] - prev_k[a] - 1)
                t0, t1 = float(prev_t[a]), float(t[a])
                self.stats.missing_rows += rows
                self.stats.gaps += 1
                gap = self._issue("missing", t0, t1, rows,
                                  f"time jumps from t = {t0:.12g} s to t = {t1:.12g} s: {rows} row(s) of "
                                  f"{g.describe()} are missing")
            pieces.append(GridPiece(t[a:b], x[a:b], gap))
        return pieces

    def _off_runs(self, t: np.ndarray, on: np.ndarray) -> None:
        """Count the off-grid rows of a batch, one issue per run of consecutive ones."""
        off = ~on
        if not off.any():
            if on.size:
                self._close_off_run()
            return
        self.stats.off_grid_rows += int(off.sum())
        edges = np.flatnonzero(np.diff(off.astype(np.int8))) + 1
        bounds = [0, *edges.tolist(), off.size]
        for a, b in zip(bounds[:-1], bounds[1:]):
            if not off[a]:
                self._close_off_run()
                continue
            if self._off_run is None:
                self._off_run = [float(t[a]), float(t[b - 1]), b - a]
            else:
                self._off_run[1] = float(t[b - 1])
                self._off_run[2] += b - a

    def missing_after(self, last_time: float) -> None:
        """The data end at ``last_time`` (s) although the run recorded a later row: the rows
        between are missing (an issue when any is)."""
        if self.grid is None or self._last_t is None:
            return
        rows = int(round((last_time - self._last_t) / self.grid.step))
        if rows >= 1:
            t0 = self._last_t
            self.stats.missing_rows += rows
            self.stats.gaps += 1
            self.new_issues = []
            self._issue("missing", t0, float(last_time), rows,
                        f"the file ends at t = {t0:.12g} s but run.json records rows up to t = {last_time:.12g} s: "
                        f"{rows} row(s) of {self.grid.describe()} are missing")


def grid_of(experiment: object | None) -> Grid | None:
    """The grid of run.json's ``experiment`` (a :class:`~fourbar_common.RecordedExperiment`), or None."""
    if experiment is None:
        return None
    start, step, stop = (getattr(experiment, name, None) for name in ("start", "step", "stop"))
    if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in (start, step, stop)) or step <= 0:
        return None
    return Grid(float(start), float(step), float(stop), RUN_RECORD)

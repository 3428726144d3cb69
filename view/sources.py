"""The files of one run folder, read as they grow: what the view shows, and nothing else.

A run folder (``fourbar-run --out DIR``) holds ``exchange.csv`` and ``run.json``; the monitor
adds ``monitor/`` (``events.jsonl``, ``evaluations.csv``, ``forecast.csv``, ``summary.json``)
and ``fourbar-diagnose`` adds ``diagnosis/diagnosis.json``.  :class:`RunFolder` polls them:
each :meth:`RunFolder.poll` returns only what is new since the last one (:class:`Update`), so a
page streams rows instead of re-sending the run.  Complete lines only: a writer appends whole
lines, and a last line without its newline is read at the next poll (a torn last line left by a
killed writer is never read).  A FIFO, device or folder in place of a file is refused by
:func:`check_run_folder` and never opened by a poll; JSON nested too deeply or too large is a
warning naming the file, not a traceback.  A file replaced by a new
run (shorter, or another ``run_id``) starts again from its top, and the update says so.

The formats are the contracts of docs/contracts.md; this module reads them with the contract
package (:mod:`fourbar_common.contract`: the one tail reader of exchange.csv, the monitor's
tables) and the shared run record, not with the monitor's or the orchestrator's code.
"""
from __future__ import annotations

import math
import os
import stat
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from fourbar_common.contract.diagnosis import read_diagnosis
from fourbar_common.contract.evaluations import EvaluationsTail
from fourbar_common.contract.exchange import TIME_COLUMN, ExchangeTail, LineTail
from fourbar_common.contract.forecast import ForecastTail
from fourbar_common.contract.json_files import JsonFileError
from fourbar_common.contract.layout import EXCHANGE, RUN_RECORD
from fourbar_common.contract.layout import RunFolder as RunPaths
from fourbar_common.contract.monitor_events import MonitorEvent, read_growing_events
from fourbar_common.contract.problems import ContractError
from fourbar_common.contract.run_record import RunRecord, RunRecordError, read_run_record
from fourbar_common.files import file_kind

__all__ = ["Diagnosis", "MonitorEvent", "RunFolder", "RunFolderError", "Update", "check_run_folder"]

#: Most bytes of one file read by one poll (the rest comes at the next polls).
MAX_READ_BYTES = 16 << 20
#: A writer that has not touched run.json for this many heartbeats is taken as stopped.
STALE_HEARTBEATS = 5.0


class RunFolderError(ValueError):
    """Not a run folder, or one the view cannot read; the message says which file and why."""


def check_run_folder(path: str | os.PathLike[str]) -> Path:
    """``path`` as a run folder, or :class:`RunFolderError` saying what is missing."""
    folder = Path(path)
    paths = RunPaths(folder)
    if not folder.exists():
        raise RunFolderError(f"{folder}: no such folder; expected a run folder written by fourbar-run "
                             f"(e.g. out/case2_fault_L2)")
    if not folder.is_dir():
        raise RunFolderError(f"{folder}: is a file; expected the run folder that holds {EXCHANGE} and {RUN_RECORD}")
    if not paths.run_record.exists() and not paths.exchange.exists():
        raise RunFolderError(f"{folder}: not a run folder: it holds neither {RUN_RECORD} nor {EXCHANGE} "
                             f"(fourbar-run writes both; run one with `fourbar-run CASE --out {folder}`)")
    if not paths.run_record.exists():
        raise RunFolderError(f"{folder}: has {EXCHANGE} but no {RUN_RECORD}; the view needs the run's record "
                             f"(written by fourbar-run beside the exchange file)")
    for file in (paths.run_record, paths.exchange, paths.events, paths.evaluations, paths.forecast, paths.diagnosis):
        try:
            mode = file.stat().st_mode
        except OSError:
            continue
        if not stat.S_ISREG(mode):
            raise RunFolderError(f"{file}: {file_kind(mode)}, not a regular file; a run folder holds "
                                 "the files fourbar-run, fourbar-monitor and fourbar-diagnose write")
    return folder


@dataclass(frozen=True)
class Diagnosis:
    """What diagnosis.json says, as a view shows it: the verdict and the best explanation of the
    contract's :class:`~fourbar_common.contract.diagnosis.DiagnosisRecord`."""

    verdict: str                   # explained | ambiguous | unexplained | no_change
    message: str
    parameter: str | None = None
    before: float | None = None
    value: float | None = None
    change_time: float | None = None


@dataclass
class Update:
    """What is new in the folder since the previous poll."""

    record: RunRecord | None = None            # run.json when it changed
    record_problem: str | None = None          # why run.json could not be read (when it could not)
    rows: pd.DataFrame | None = None           # new exchange rows (all columns)
    evaluations: pd.DataFrame | None = None    # new rows of evaluations.csv
    forecast: pd.DataFrame | None = None       # new rows of forecast.csv
    events: list[MonitorEvent] = field(default_factory=list)
    diagnosis: Diagnosis | None = None         # diagnosis.json when it changed
    restarted: bool = False                    # the run was replaced: drop what was shown
    monitor_restarted: bool = False            # a new monitor session: drop the monitor's outputs only
    writer_gone: bool = False                  # run.json says running, but nobody writes it
    warnings: list[str] = field(default_factory=list)



def _number(value: Any) -> float | None:
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value) else None


class RunFolder:
    """Poll one run folder (:func:`check_run_folder` first)."""

    def __init__(self, folder: str | os.PathLike[str]):
        self.folder = check_run_folder(folder)
        paths = RunPaths(self.folder)
        # time decides whether a row is read; the other columns are NaN where they do not parse
        self.exchange = ExchangeTail(paths.exchange, (), others=True, max_chunk_bytes=MAX_READ_BYTES,
                                     refuse_other_files=False)
        self.evaluations = EvaluationsTail(paths.evaluations, max_chunk_bytes=MAX_READ_BYTES)
        self.forecast = ForecastTail(paths.forecast, max_chunk_bytes=MAX_READ_BYTES)
        self.events = LineTail(paths.events, max_chunk_bytes=MAX_READ_BYTES, refuse_other_files=False)  # JSON lines
        self.record: RunRecord | None = None
        self._stamps: dict[Path, tuple[int, int]] = {}
        self._skipped = 0                  # exchange rows skipped, over every file read
        self._warned_skips = 0
        self._warned: dict[Path, str] = {}         # the last problem said of a file (said once)

    def _changed(self, path: Path) -> bool | None:
        """Whether ``path`` changed since the last call that saw it (None: there is no such file)."""
        try:
            st = path.stat()
        except FileNotFoundError:
            self._stamps.pop(path, None)
            return None
        stamp = (st.st_mtime_ns, st.st_size)
        if self._stamps.get(path) == stamp:
            return False
        self._stamps[path] = stamp
        return True

    # -- run.json -----------------------------------------------------------------------
    def _read_record(self, update: Update) -> None:
        path = RunPaths(self.folder).run_record
        changed = self._changed(path)
        if changed is None:
            update.record_problem = f"{path}: missing (the run folder was emptied)"
            return
        if not changed:
            return
        try:
            record = read_run_record(path)
        except (RunRecordError, FileNotFoundError) as exc:
            update.record_problem = str(exc)
            return
        if self.record is not None and record.run_id != self.record.run_id:
            update.restarted = True
            self.exchange.reset()
        self.record = record
        update.record = record

    def writer_gone(self) -> bool:
        """run.json says running, but its writer is gone (or silent for STALE_HEARTBEATS beats)."""
        r = self.record
        if r is None or r.ended or r.writer is None:
            return False
        alive = r.writer.alive()
        if alive is False:
            return True
        try:
            age = max(0.0, time.time() - RunPaths(self.folder).run_record.stat().st_mtime)
        except FileNotFoundError:
            return True
        return alive is None and age > STALE_HEARTBEATS * r.writer.heartbeat_s

    # -- the monitor and the diagnosis ---------------------------------------------------
    def _read_events(self, update: Update) -> None:
        chunk = self.events.read()
        update.monitor_restarted = update.monitor_restarted or chunk.restarted
        events, warnings = read_growing_events(chunk.data.decode("utf-8", errors="replace"), str(self.events.path))
        update.events += events
        update.warnings += warnings

    def _read_diagnosis(self, update: Update) -> None:
        path = RunPaths(self.folder).diagnosis
        if not self._changed(path):
            return
        try:
            record = read_diagnosis(path)
        except (OSError, JsonFileError, ContractError) as exc:
            update.warnings.append(f"{path}: cannot be read ({exc}); the diagnosis is not shown")
            return
        best = record.best
        update.diagnosis = Diagnosis(verdict=record.verdict, message=record.message,
                                     parameter=best.parameter if best is not None else None,
                                     before=best.before if best is not None else None,
                                     value=best.value if best is not None else None,
                                     change_time=best.change_time if best is not None else None)

    # -- the CSV files ------------------------------------------------------------------
    def _problem(self, update: Update, path: Path, exc: ContractError, what: str) -> None:
        """Say a file's problem once (not at every poll while it lasts)."""
        text = f"{exc}; {what}"
        if self._warned.get(path) != text:
            self._warned[path] = text
            update.warnings.append(text)

    def _read_rows(self, update: Update) -> None:
        before = self.exchange.stats.skipped
        try:
            batch = self.exchange.poll()
        except ContractError as exc:           # a header that is not an exchange file's
            self._problem(update, self.exchange.path, exc, "its rows are not shown")
            return
        self._warned.pop(self.exchange.path, None)
        self._skipped += self.exchange.stats.skipped - (0 if batch.restarted else before)
        update.restarted = update.restarted or batch.restarted
        if len(batch):
            update.rows = pd.DataFrame({TIME_COLUMN: batch.time, **batch.values})

    def _read_tables(self, update: Update) -> None:
        try:
            evaluations, again = self.evaluations.poll()
            if len(evaluations):
                update.evaluations = pd.DataFrame({"time": evaluations.time, "statistic": evaluations.statistic,
                                                   "threshold": evaluations.threshold,
                                                   "state": list(evaluations.state)})
        except ContractError as exc:
            self._problem(update, self.evaluations.path, exc, "the detector statistic is not shown")
            again = False
        try:
            forecast, again2 = self.forecast.poll()
            if len(forecast):
                update.forecast = pd.DataFrame({"time": forecast.time, "signal": list(forecast.signal),
                                                "value": forecast.value, "forecast": forecast.forecast})
        except ContractError as exc:
            self._problem(update, self.forecast.path, exc, "the forecast is not shown")
            again2 = False
        update.monitor_restarted = update.monitor_restarted or again or again2

    # -- one poll -----------------------------------------------------------------------
    def poll(self) -> Update:
        """Everything new since the previous poll."""
        update = Update()
        self._read_record(update)
        self._read_rows(update)
        self._read_tables(update)
        self._read_events(update)
        self._read_diagnosis(update)
        if self._skipped > self._warned_skips:
            update.warnings.append(f"{self.exchange.path}: {self._skipped - self._warned_skips} row(s) that "
                                   f"do not parse were skipped")
            self._warned_skips = self._skipped
        update.writer_gone = self.writer_gone()
        return update


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

The formats are the contracts of docs/contracts.md; this module reads them with pandas and
the shared run record (:mod:`fourbar_common`), not with the monitor's or the orchestrator's
code.
"""
from __future__ import annotations

import io
import math
import os
import stat
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from fourbar_common.contract.diagnosis import read_diagnosis
from fourbar_common.contract.json_files import JsonFileError, parse_json
from fourbar_common.contract.layout import RunFolder as RunFolderLayout
from fourbar_common.contract.problems import ContractError
from fourbar_common.contract.run_record import RunRecord, RunRecordError, read_run_record
from fourbar_common.files import NotRegularFileError, file_kind, open_regular

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
    layout = RunFolderLayout(folder)
    record = layout.run_record
    if not folder.exists():
        raise RunFolderError(f"{folder}: no such folder; expected a run folder written by fourbar-run "
                             f"(e.g. out/case2_fault_L2)")
    if not folder.is_dir():
        raise RunFolderError(f"{folder}: is a file; expected the run folder that holds exchange.csv and run.json")
    if not record.exists() and not (folder / "exchange.csv").exists():
        raise RunFolderError(f"{folder}: not a run folder: it holds neither run.json nor exchange.csv "
                             f"(fourbar-run writes both; run one with `fourbar-run CASE --out {folder}`)")
    if not record.exists():
        raise RunFolderError(f"{folder}: has exchange.csv but no run.json; the view needs the run's record "
                             f"(written by fourbar-run beside the exchange file)")
    for file in (layout.run_record, layout.exchange, layout.events, layout.evaluations, layout.forecast,
                 layout.diagnosis):
        try:
            mode = file.stat().st_mode
        except OSError:
            continue
        if not stat.S_ISREG(mode):
            raise RunFolderError(f"{file}: {file_kind(mode)}, not a regular file; a run folder holds "
                                 "the files fourbar-run, fourbar-monitor and fourbar-diagnose write")
    return folder


@dataclass(frozen=True)
class MonitorEvent:
    """One line of the monitor's events.jsonl."""

    time: float
    event: str                     # trained | stable | refit | alarm | clear
    state: str
    statistic: float | None
    threshold: float | None
    message: str
    train_start: float | None = None
    train_end: float | None = None


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



class _LineTail:
    """The complete lines appended to a text file since the last read; notices a file that
    was replaced (shorter than what was read, or another inode) and starts it again."""

    def __init__(self, path: Path, has_header: bool = True):
        self.path = path
        self.has_header = has_header
        self.offset = 0
        self.inode: int | None = None
        self.header: str | None = None

    def reset(self) -> None:
        self.offset, self.inode, self.header = 0, None, None

    def read(self) -> tuple[list[str], bool]:
        """(new complete lines without the header, whether the file started again)."""
        try:
            st = self.path.stat()
        except FileNotFoundError:
            restarted = self.offset > 0
            self.reset()
            return [], restarted
        if not stat.S_ISREG(st.st_mode):       # a FIFO or a folder put in its place: never opened
            restarted = self.offset > 0
            self.reset()
            return [], restarted
        restarted = False
        if (self.inode is not None and st.st_ino != self.inode) or st.st_size < self.offset:
            self.reset()
            restarted = True
        self.inode = st.st_ino
        if st.st_size == self.offset:
            return [], restarted
        try:
            f = open_regular(self.path)
        except (FileNotFoundError, NotRegularFileError):
            return [], restarted
        with f:
            f.seek(self.offset)
            # only up to the size seen: bytes appended since are read at the next poll
            chunk = f.read(min(st.st_size - self.offset, MAX_READ_BYTES))
        end = chunk.rfind(b"\n")
        if end < 0:
            return [], restarted
        self.offset += end + 1
        lines = chunk[:end].decode("utf-8", errors="replace").split("\n")
        if self.has_header and self.header is None and lines:
            self.header = lines.pop(0).strip()
        return [line for line in lines if line.strip()], restarted


class _CsvTail(_LineTail):
    """New rows of a CSV file with a header, as a DataFrame (rows that do not parse are skipped
    and counted)."""

    def __init__(self, path: Path, numeric: tuple[str, ...] | None = None):
        super().__init__(path)
        self.numeric = numeric
        self.skipped = 0

    def frame(self) -> tuple[pd.DataFrame | None, bool]:
        lines, restarted = self.read()
        if not lines or not self.header:
            return None, restarted
        names = self.header.split(",")
        frame = pd.read_csv(io.StringIO("\n".join(lines)), header=None, names=names, on_bad_lines="skip",
                            engine="c", dtype=str)
        columns = [c for c in names if self.numeric is None or c in self.numeric]
        for c in columns:
            frame[c] = pd.to_numeric(frame[c], errors="coerce")
        bad = frame[columns].isna().all(axis=1) if "time" not in columns else frame["time"].isna()
        self.skipped += int(bad.sum()) + max(0, len(lines) - len(frame))
        frame = frame[~bad]
        return (frame if len(frame) else None), restarted


def _number(value: Any) -> float | None:
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value) else None


class RunFolder:
    """Poll one run folder (:func:`check_run_folder` first)."""

    def __init__(self, folder: str | os.PathLike[str]):
        self.folder = check_run_folder(folder)
        self.exchange = _CsvTail(self.folder / "exchange.csv")
        monitor = self.folder / "monitor"
        self.evaluations = _CsvTail(monitor / "evaluations.csv", ("time", "statistic", "threshold"))
        self.forecast = _CsvTail(monitor / "forecast.csv", ("time", "value", "forecast"))
        self.events = _LineTail(monitor / "events.jsonl", has_header=False)       # JSON lines
        self.record: RunRecord | None = None
        self._stamps: dict[Path, tuple[int, int]] = {}
        self._warned_skips = 0

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
        path = RunFolderLayout(self.folder).run_record
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
            age = max(0.0, time.time() - RunFolderLayout(self.folder).run_record.stat().st_mtime)
        except FileNotFoundError:
            return True
        return alive is None and age > STALE_HEARTBEATS * r.writer.heartbeat_s

    # -- the monitor and the diagnosis ---------------------------------------------------
    def _read_events(self, update: Update) -> None:
        lines, restarted = self.events.read()
        update.monitor_restarted = update.monitor_restarted or restarted
        for line in lines:
            try:
                data = parse_json(line, str(self.events.path))
            except JsonFileError as exc:     # not JSON, or nested too deeply
                update.warnings.append(f"{exc}; the line was skipped")
                continue
            if not isinstance(data, dict) or _number(data.get("time")) is None:
                continue
            update.events.append(MonitorEvent(
                time=float(data["time"]), event=str(data.get("event", "")), state=str(data.get("state", "")),
                statistic=_number(data.get("statistic")), threshold=_number(data.get("threshold")),
                message=str(data.get("message") or ""), train_start=_number(data.get("train_start")),
                train_end=_number(data.get("train_end"))))

    def _read_diagnosis(self, update: Update) -> None:
        path = RunFolderLayout(self.folder).diagnosis
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

    # -- one poll -----------------------------------------------------------------------
    def poll(self) -> Update:
        """Everything new since the previous poll."""
        update = Update()
        self._read_record(update)
        rows, restarted = self.exchange.frame()
        update.restarted = update.restarted or restarted
        update.rows = rows
        update.evaluations, again = self.evaluations.frame()
        update.forecast, again2 = self.forecast.frame()
        update.monitor_restarted = again or again2
        self._read_events(update)
        self._read_diagnosis(update)
        if self.exchange.skipped > self._warned_skips:
            update.warnings.append(f"{self.exchange.path}: {self.exchange.skipped - self._warned_skips} row(s) that "
                                   f"do not parse were skipped")
            self._warned_skips = self.exchange.skipped
        update.writer_gone = self.writer_gone()
        return update


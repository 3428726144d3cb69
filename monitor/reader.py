"""Reading the exchange file (``time,x2,y2,...``) and its ``run.json``.

The exchange file grows while the orchestrator runs: complete lines are appended in blocks
and a last line without ``\\n`` is not yet written.  :class:`ExchangeReader` follows it by
byte offset and returns only the new complete rows at each :meth:`~ExchangeReader.poll`;
it keeps no history (memory stays bounded however long the run), only the offset, the
header and counters.

Row rules (each skipped row is counted by kind and, for the first ``max_issues``, kept as a
:class:`RowIssue` naming the file, line, column and value):

- ``malformed``: blank line, wrong number of fields, or not UTF-8;
- ``non_numeric``: a requested column does not parse as a float;
- ``non_finite``: a requested column is NaN or ±inf;
- ``duplicate_time`` / ``decreasing_time``: time not strictly greater than the last
  accepted row's time.

Only the columns asked for (``time`` and, e.g., ``x2``) decide whether a row is valid; the
other fields are not parsed.

File replacement: when the path's inode changes, the file becomes shorter than the offset
already read, or the bytes just before the offset change (truncated and rewritten), the
reader starts again from the beginning of the new file and flags the batch ``restarted``.

Header problems (missing column, duplicate column name, undecodable header) raise
:class:`~monitor.errors.ExchangeFormatError`; so do an empty or header-only file in
:func:`read_exchange` (a finished file).
"""
from __future__ import annotations

import math
import os
import stat
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from fourbar_common import Event
from fourbar_common.contract.layout import EXCHANGE as EXCHANGE_NAME, RUN_RECORD
from fourbar_common.contract.run_record import RunRecord, RunRecordError, read_run_record
from fourbar_common.files import NotRegularFileError, file_kind, open_regular

from .errors import ExchangeFormatError, ExchangeMissingError

__all__ = [
    "ExchangeReader",
    "ExchangeWarning",
    "ReadBatch",
    "ReaderStats",
    "RowIssue",
    "RunInfo",
    "read_exchange",
    "read_run_info",
    "TIME_COLUMN",
]

#: Name of the time column (first column of the contract's header).
TIME_COLUMN = "time"
#: Bytes kept before the offset to notice a file truncated and rewritten past the offset.
_SIGNATURE_BYTES = 64
_SKIP_KINDS = ("malformed", "non_numeric", "non_finite", "duplicate_time", "decreasing_time")


class ExchangeWarning(UserWarning):
    """Rows of an exchange file were skipped (see the counts in the message)."""


@dataclass(frozen=True)
class RowIssue:
    """One skipped row: ``kind`` is one of the :class:`ReaderStats` counters."""

    kind: str
    line: int
    message: str
    column: str | None = None
    value: str | None = None


@dataclass
class ReaderStats:
    """Counters of the current file (reset on restart, except ``restarts``)."""

    lines: int = 0
    rows: int = 0
    malformed: int = 0
    non_numeric: int = 0
    non_finite: int = 0
    duplicate_time: int = 0
    decreasing_time: int = 0
    restarts: int = 0

    @property
    def skipped(self) -> int:
        return sum(getattr(self, k) for k in _SKIP_KINDS)

    def as_dict(self) -> dict[str, int]:
        d = asdict(self)
        d["skipped"] = self.skipped
        return d


@dataclass
class ReadBatch:
    """New complete rows from one poll.

    ``time`` and ``values[column]`` are float64 arrays of equal length (possibly empty).
    ``restarted`` is true when the file was replaced or truncated before these rows:
    the consumer must forget everything it had from the old file.  ``missing`` is true
    when the file does not exist (yet, or any more).
    """

    time: np.ndarray
    values: dict[str, np.ndarray]
    issues: list[RowIssue] = field(default_factory=list)
    restarted: bool = False
    missing: bool = False

    def __len__(self) -> int:
        return len(self.time)


def _empty_batch(columns: Sequence[str], **flags: bool) -> ReadBatch:
    return ReadBatch(np.empty(0), {c: np.empty(0) for c in columns}, **flags)


class ExchangeReader:
    """Incremental reader of one exchange file.

    Parameters
    ----------
    path:
        The exchange CSV file.  It need not exist yet: :meth:`poll` reports ``missing``.
    columns:
        Columns to return besides ``time`` (default: every column of the header).
    max_chunk_bytes:
        Largest number of bytes read by one poll (bounds memory per batch).
    max_issues:
        Number of :class:`RowIssue` examples kept; further skipped rows are only counted.
    """

    def __init__(self, path: str | os.PathLike[str], columns: Sequence[str] | None = None, *,
                 max_chunk_bytes: int = 4 << 20, max_issues: int = 100):
        self.path = Path(path)
        self._requested = None if columns is None else tuple(c for c in columns if c != TIME_COLUMN)
        if max_chunk_bytes < 1024:
            raise ValueError(f"max_chunk_bytes must be at least 1024, got {max_chunk_bytes}")
        self.max_chunk_bytes = int(max_chunk_bytes)
        self.max_issues = int(max_issues)
        self.stats = ReaderStats()
        self.issues: list[RowIssue] = []
        self._fh: Any = None
        self._ino: tuple[int, int] | None = None
        self._reset_file_state()

    # -- state ------------------------------------------------------------------------
    def _reset_file_state(self) -> None:
        self._offset = 0
        self._signature = b""
        self.header: tuple[str, ...] | None = None
        self._index: tuple[int, ...] = ()
        self._ncols = 0
        self._last_time = -math.inf
        self._line_no = 0
        self._discarding_long_line = False
        self.pending_bytes = 0

    @property
    def columns(self) -> tuple[str, ...]:
        """Returned value columns (known once the header has been read)."""
        if self._requested is not None:
            return self._requested
        if self.header is None:
            return ()
        return tuple(c for c in self.header if c != TIME_COLUMN)

    @property
    def offset(self) -> int:
        """Bytes consumed so far (header and complete lines)."""
        return self._offset

    @property
    def last_time(self) -> float:
        return self._last_time

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def __enter__(self) -> "ExchangeReader":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _restart(self) -> None:
        self.close()
        self._ino = None
        restarts = self.stats.restarts + 1
        self.stats = ReaderStats(restarts=restarts)
        self.issues = []
        self._reset_file_state()

    # -- polling ------------------------------------------------------------------------
    def poll(self) -> ReadBatch:
        """Read the complete lines appended since the last poll (at most ``max_chunk_bytes``)."""
        restarted = False
        try:
            st = os.stat(self.path)
        except FileNotFoundError:
            if self._fh is not None:          # the file went away: start afresh when it is back
                self._restart()
                return _empty_batch(self.columns, missing=True, restarted=True)
            return _empty_batch(self.columns, missing=True)
        if not stat.S_ISREG(st.st_mode):
            raise ExchangeFormatError(f"{self.path}: {file_kind(st.st_mode)}, not a regular file; the exchange file "
                                      "must be a file written by fourbar-run")
        ino = (st.st_dev, st.st_ino)
        if self._fh is not None and (ino != self._ino or st.st_size < self._offset or not self._signature_ok()):
            self._restart()
            restarted = True
        if self._fh is None:
            try:
                self._fh = open_regular(self.path)
            except FileNotFoundError:
                return _empty_batch(self.columns, missing=True, restarted=restarted)
            except NotRegularFileError as exc:
                raise ExchangeFormatError(f"{exc}; the exchange file must be a file written by fourbar-run") from None
            except OSError as exc:
                raise ExchangeMissingError(f"{self.path}: cannot open exchange file: {exc.strerror}") from exc
            self._ino = (os.fstat(self._fh.fileno()).st_dev, os.fstat(self._fh.fileno()).st_ino)
        self._fh.seek(self._offset)
        data = self._fh.read(self.max_chunk_bytes)
        self._new_issues: list[RowIssue] = []
        batch = self._consume(data)
        batch.issues = self._new_issues
        batch.restarted = restarted
        return batch

    def _signature_ok(self) -> bool:
        if not self._signature:
            return True
        n = len(self._signature)
        # A replaced file has a new inode; a truncated-and-rewritten one keeps its inode and
        # may have grown past the offset again, and then only these bytes tell.
        self._fh.seek(self._offset - n)
        return self._fh.read(n) == self._signature

    def _consume(self, data: bytes) -> ReadBatch:
        if self._discarding_long_line:        # the rest of an over-long line: drop it
            nl = data.find(b"\n")
            cut = len(data) if nl < 0 else nl + 1
            self._advance(data, cut)
            if nl < 0:
                return _empty_batch(self.columns)
            self._discarding_long_line = False
            data = data[cut:]
        end = data.rfind(b"\n") + 1
        if end == 0:
            self.pending_bytes = len(data)
            if len(data) == self.max_chunk_bytes:
                if self.header is None:
                    raise ExchangeFormatError(f"{self.path}: no newline in the first {len(data)} bytes; "
                                              "expected a header line 'time,x2,y2,x3,y3,x4,y4'")
                self._line_no += 1
                self._skip("malformed", self._line_no, f"line longer than {len(data)} bytes; row skipped")
                self._discarding_long_line = True
                self._advance(data, len(data))
                self.pending_bytes = 0
            return _empty_batch(self.columns)
        body = data[:end]
        self._advance(data, end)
        self.pending_bytes = len(data) - end
        if self.header is None:
            nl = body.index(b"\n")
            self._line_no += 1
            self._parse_header(body[:nl])
            body = body[nl + 1:]
        if not body:
            return _empty_batch(self.columns)
        if len(body) > 2048:
            fast = self._parse_clean(body)
            if fast is not None:
                return fast
        return self._parse_each(body.split(b"\n")[:-1])

    def _advance(self, data: bytes, end: int) -> None:
        self._offset += end
        tail = data[max(0, end - _SIGNATURE_BYTES):end]
        if len(tail) < _SIGNATURE_BYTES and self._offset > len(tail):
            tail = (self._signature + tail)[-_SIGNATURE_BYTES:]
        self._signature = tail

    def _parse_header(self, raw: bytes) -> None:
        try:
            text = raw.decode("utf-8-sig").rstrip("\r")
        except UnicodeDecodeError as exc:
            raise ExchangeFormatError(f"{self.path}: line 1 (header) is not UTF-8 text: {exc.reason}") from exc
        names = tuple(name.strip() for name in text.split(","))
        if not text.strip():
            raise ExchangeFormatError(f"{self.path}: line 1 (header) is empty; expected column names "
                                      f"like 'time,x2,y2,x3,y3,x4,y4'")
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise ExchangeFormatError(f"{self.path}: header names column(s) {', '.join(map(repr, dupes))} "
                                      f"more than once: {text!r}")
        wanted = (TIME_COLUMN,) + (self._requested if self._requested is not None
                                   else tuple(n for n in names if n != TIME_COLUMN))
        missing = [c for c in wanted if c not in names]
        if missing:
            # the file's own columns are the answer (any mechanism's); the four-bar's header is
            # only an example of the format, for a file without a time column
            hint = (" (expected a header like 'time,x2,y2,x3,y3,x4,y4')" if TIME_COLUMN in missing
                    else "; choose the column(s) to read among them")
            raise ExchangeFormatError(
                f"{self.path}: header has no column {', '.join(map(repr, missing))}; "
                f"columns are {', '.join(names)}{hint}")
        self.header = names
        self._ncols = len(names)
        self._index = tuple(names.index(c) for c in wanted)

    def _skip(self, kind: str, line: int, message: str, column: str | None = None,
              value: str | None = None) -> None:
        setattr(self.stats, kind, getattr(self.stats, kind) + 1)
        if len(self.issues) < self.max_issues:
            issue = RowIssue(kind, line, f"{self.path.name} line {line}: {message}", column, value)
            self.issues.append(issue)
            self._new_issues.append(issue)

    def _parse_clean(self, body: bytes) -> ReadBatch | None:
        """Fast path (pandas' C parser) for a block with no bad row; None means 'use the slow path'.

        It accepts the block only when every line has the right number of numeric fields,
        the requested columns are finite and time increases strictly from the last row, so
        the result is the same as the row-by-row path (pandas 3 parses floats exactly).
        """
        import csv
        import io

        import pandas as pd

        try:
            arr = pd.read_csv(io.BytesIO(body), header=None, dtype=float, engine="c",
                              skip_blank_lines=False, quoting=csv.QUOTE_NONE, na_filter=True).to_numpy()
        except (ValueError, pd.errors.ParserError, pd.errors.EmptyDataError):
            return None
        n = body.count(b"\n")
        # pandas pads a row with too few fields with NaN (and refuses one with too many): a
        # short row whose time and signal survived would pass the checks below; count commas
        if arr.shape != (n, self._ncols) or body.count(b",") != n * (self._ncols - 1):
            return None
        sub = arr[:, list(self._index)]
        t = sub[:, 0]
        if not np.isfinite(sub).all() or not t[0] > self._last_time or not (np.diff(t) > 0).all():
            return None
        self._line_no += n
        self.stats.lines += n
        self.stats.rows += n
        self._last_time = float(t[-1])
        cols = [self.header[i] for i in self._index[1:]]
        return ReadBatch(t.copy(), {c: sub[:, j + 1].copy() for j, c in enumerate(cols)})

    def _parse_each(self, lines: list[bytes]) -> ReadBatch:
        names = self.header
        index = self._index
        ncols = self._ncols
        width = len(index)
        out = np.empty((len(lines), width))
        n = 0
        last = self._last_time
        line_no = self._line_no
        for raw in lines:
            line_no += 1
            self.stats.lines += 1
            try:
                text = raw.decode("utf-8").rstrip("\r")
            except UnicodeDecodeError:
                self._skip("malformed", line_no, "not UTF-8 text; row skipped")
                continue
            fields = text.split(",")
            if len(fields) != ncols:
                what = "blank line" if not text.strip() else f"{len(fields)} fields, expected {ncols}"
                self._skip("malformed", line_no, f"{what}; row skipped")
                continue
            row = out[n]
            ok = True
            for j, i in enumerate(index):
                s = fields[i]
                try:
                    v = float(s)
                except ValueError:
                    shown = s.strip()[:40]
                    self._skip("non_numeric", line_no, f"column {names[i]}: value {shown!r} is not a number; "
                               "row skipped", names[i], shown)
                    ok = False
                    break
                if not math.isfinite(v):
                    self._skip("non_finite", line_no, f"column {names[i]}: value {s.strip()!r} is not finite; "
                               "row skipped", names[i], s.strip())
                    ok = False
                    break
                row[j] = v
            if not ok:
                continue
            t = row[0]
            if t <= last:
                kind = "duplicate_time" if t == last else "decreasing_time"
                self._skip(kind, line_no, f"column time: value {fields[index[0]].strip()!r} is "
                           f"{'equal to' if t == last else 'before'} the previous row's time {float(last)!r}; "
                           "row skipped", TIME_COLUMN, fields[index[0]].strip())
                continue
            last = t
            n += 1
        self._line_no = line_no
        self._last_time = last
        self.stats.rows += n
        out = out[:n]
        cols = [names[i] for i in index[1:]]
        return ReadBatch(out[:, 0].copy(), {c: out[:, j + 1].copy() for j, c in enumerate(cols)})

    def read_to_end(self) -> ReadBatch:
        """Poll until the file gives nothing more; return all rows read (a finished file)."""
        batches = []
        issues: list[RowIssue] = []
        restarted = False
        missing = False
        while True:
            before = self._offset
            batch = self.poll()
            restarted |= batch.restarted
            missing |= batch.missing
            issues.extend(batch.issues)
            if len(batch):
                batches.append(batch)
            if batch.missing or self._offset == before:
                break
        cols = self.columns
        if not batches:
            return ReadBatch(np.empty(0), {c: np.empty(0) for c in cols}, issues, restarted, missing)
        return ReadBatch(np.concatenate([b.time for b in batches]),
                         {c: np.concatenate([b.values[c] for b in batches]) for c in cols},
                         issues, restarted, missing)

    def check_finished(self) -> None:
        """Raise :class:`ExchangeFormatError` if a finished file has no header or no valid row."""
        if self.header is None:
            if self.pending_bytes:
                raise ExchangeFormatError(f"{self.path}: the header line is not terminated by a newline "
                                          f"(file of {self.pending_bytes} bytes); expected "
                                          "'time,x2,y2,x3,y3,x4,y4\\n' then data rows")
            raise ExchangeFormatError(f"{self.path}: file is empty; expected a header line "
                                      "'time,x2,y2,x3,y3,x4,y4' then data rows")
        if self.stats.rows == 0:
            if self.stats.lines == 0:
                raise ExchangeFormatError(f"{self.path}: file has a header but no data rows")
            raise ExchangeFormatError(f"{self.path}: none of the {self.stats.lines} data rows is valid "
                                      f"({self._skip_text()})")

    def _skip_text(self) -> str:
        return ", ".join(f"{getattr(self.stats, k)} {k.replace('_', ' ')}" for k in _SKIP_KINDS
                         if getattr(self.stats, k))

    def skip_summary(self) -> str:
        """One line: how many rows were skipped and why ('' when none)."""
        if not self.stats.skipped and not self.pending_bytes:
            return ""
        parts = []
        if self.stats.skipped:
            parts.append(f"skipped {self.stats.skipped} of {self.stats.lines} data rows ({self._skip_text()})")
        if self.pending_bytes:
            parts.append(f"ignored an incomplete last line ({self.pending_bytes} bytes without newline)")
        return f"{self.path}: " + "; ".join(parts)


def exchange_file(path: str | Path, *, later: bool = False) -> Path:
    """The exchange file ``path`` names: itself, or a run folder's exchange.csv (which, with
    ``later``, may not exist yet).  A folder without one raises :class:`ExchangeMissingError`.

    With ``later`` a path that does not exist yet is a run folder to come (its exchange.csv
    is followed) unless its name ends in ``.csv``."""
    p = Path(path)
    if p.is_dir():
        if later or os.path.lexists(p / EXCHANGE_NAME):      # not a file: the reader says what it is
            return p / EXCHANGE_NAME
        raise ExchangeMissingError(f"{p}: is a directory with no {EXCHANGE_NAME} in it: give an exchange file or "
                                   f"a run folder")
    if later and not p.exists() and p.suffix.lower() != ".csv":
        return p / EXCHANGE_NAME        # a run folder still to come (a file to come ends in .csv)
    return p


def regular_or_absent(path: Path) -> None:
    """Raise :class:`ExchangeFormatError` when ``path`` exists and is not a regular file (a
    FIFO, a device, a folder): checked with ``stat``, never opened, so nothing blocks."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return
    if not stat.S_ISREG(mode):
        raise ExchangeFormatError(f"{path}: {file_kind(mode)}, not a regular file; the exchange file must be a "
                                  "file written by fourbar-run")


def read_exchange(path: str | os.PathLike[str], columns: Sequence[str] | None = None) -> "pd.DataFrame":
    """Read a finished exchange file into a DataFrame (``time`` first, then ``columns``).

    Invalid rows are skipped under the rules of this module; when any were skipped (or the
    last line is incomplete) an :class:`ExchangeWarning` is issued and the counts are in
    ``df.attrs["reader_stats"]``, the examples in ``df.attrs["issues"]``.

    Raises :class:`ExchangeMissingError` if the file does not exist and
    :class:`ExchangeFormatError` if it is empty, has only a header, lacks a column, or has
    no valid row.
    """
    import pandas as pd

    p = exchange_file(path)
    if not p.exists():
        raise ExchangeMissingError(f"{p}: exchange file not found")
    with ExchangeReader(p, columns) as reader:
        batch = reader.read_to_end()
        reader.check_finished()
        df = pd.DataFrame({TIME_COLUMN: batch.time, **batch.values})
        df.attrs["reader_stats"] = reader.stats.as_dict()
        df.attrs["issues"] = [asdict(i) for i in reader.issues]
        note = reader.skip_summary()
    if note:
        warnings.warn(note, ExchangeWarning, stacklevel=2)
    return df


@dataclass(frozen=True)
class RunInfo:
    """What the monitor uses from ``run.json`` (the orchestrator's run record).

    ``record`` is the checked record (:class:`fourbar_common.RunRecord`, the one reader of
    run.json's schema); it is None when run.json could not be read or is not a valid record,
    and ``problem`` then says why (the status is ``"unreadable"``).  The properties read the
    record: ``run_id`` tells runs in the same folder apart; ``writer_pid``/``writer_host``
    name the process that writes the record and ``updated_at`` is its last heartbeat.
    """

    path: Path
    record: RunRecord | None
    problem: str | None = None

    @property
    def status(self) -> str:
        return self.record.status if self.record is not None else "unreadable"

    @property
    def error(self) -> str | None:
        return self.problem if self.record is None else self.record.error

    @property
    def fault_time(self) -> float | None:
        return self.record.fault_time if self.record is not None else None

    @property
    def events(self) -> tuple[Event, ...]:
        return self.record.events if self.record is not None else ()

    @property
    def case(self) -> str | None:
        return self.record.case if self.record is not None else None

    @property
    def rows_written(self) -> int | None:
        return self.record.rows_written if self.record is not None else None

    @property
    def last_time(self) -> float | None:
        return self.record.last_time if self.record is not None else None

    @property
    def run_id(self) -> str | None:
        return self.record.run_id if self.record is not None else None

    @property
    def started_at(self) -> str | None:
        return self.record.started_at if self.record is not None else None

    @property
    def updated_at(self) -> str | None:
        return self.record.updated_at if self.record is not None else None

    @property
    def writer_pid(self) -> int | None:
        writer = self.record.writer if self.record is not None else None
        return writer.pid if writer is not None else None

    @property
    def writer_host(self) -> str | None:
        writer = self.record.writer if self.record is not None else None
        return writer.host if writer is not None else None

    @property
    def units(self) -> dict[str, str]:
        return dict(self.record.units) if self.record is not None else {}

    @property
    def ended(self) -> bool:
        """True when run.json says the run will not append any more rows."""
        return self.record is not None and self.record.ended

    @property
    def identity(self) -> str | None:
        """What tells this run from another one in the same folder."""
        return self.run_id or self.started_at

    def describe(self) -> str:
        """``run 3f2a… of case2_fault_L2, started 2026-…`` for messages."""
        what = f"run {self.run_id}" if self.run_id else "the run"
        if self.case:
            what += f" of {self.case}"
        if self.started_at:
            what += f", started {self.started_at}"
        return what

    def writer_alive(self) -> bool | None:
        """Whether the writing process still exists: None when it cannot be checked from here
        (another host, or a run.json without writer); a pid reused within a run is not detected."""
        writer = self.record.writer if self.record is not None else None
        return writer.alive() if writer is not None else None


def read_run_info(exchange_path: str | os.PathLike[str]) -> RunInfo | None:
    """Read ``run.json`` beside the exchange file; None when there is none.

    A run.json that cannot be read, is not JSON or is not a valid run record gives status
    ``"unreadable"`` with the reason (naming the field) in ``error``; it is replaced
    atomically, so this means a foreign or damaged file.
    """
    path = Path(exchange_path).parent / RUN_RECORD
    try:
        return RunInfo(path, read_run_record(path))
    except FileNotFoundError:
        return None
    except RunRecordError as exc:
        return RunInfo(path, None, problem=str(exc))

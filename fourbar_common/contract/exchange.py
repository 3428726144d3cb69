"""exchange.csv: its header, its rows, its writer's format and *the* tail reader of a growing CSV.

The format (docs/contracts.md): one header line naming the columns, ``time`` first, then the
outputs (any mechanism's: ``time,x2,y2,...`` for the four-bar); then one line per
communication point, every field a float written with ``repr`` (the shortest text that reads
back to the same double), ``.`` decimal point, ``\\n`` line ends.  The orchestrator appends
complete lines in blocks, so a reader sees a last line without ``\\n`` only while it is being
written.

:class:`LineTail` follows any text file that grows by whole lines (the exchange file, the
monitor's CSV tables, events.jsonl) by byte offset: each :meth:`~LineTail.read` returns only
the complete lines appended since the last one, at most ``max_chunk_bytes`` of them, and keeps
no history (memory stays bounded however long the run), only the offset and the bytes just
before it.  File replacement: when the file at the path is another one (device and inode),
is shorter than the offset already read, or the bytes just before the offset changed
(truncated and rewritten), the tail starts again from the new file's top and says
``restarted``.  A line longer than ``max_chunk_bytes`` is dropped (and said).

:class:`ExchangeTail` reads exchange.csv on top of it, the one reader the monitor, the view
and the diagnosis use.  Row rules (each skipped row is counted by kind in :class:`ReaderStats`
and, for the first ``max_issues``, kept as a :class:`RowIssue` naming the file, line, column
and value):

- ``malformed``: blank line, wrong number of fields, or not UTF-8;
- ``non_numeric``: a required column does not parse as a float;
- ``non_finite``: a required column is NaN or +-inf;
- ``duplicate_time`` / ``decreasing_time``: time not strictly greater than the last
  accepted row's time.

Only the required columns (``time`` and the columns asked for) decide whether a row is valid;
with ``others`` the remaining columns are returned too, NaN where a field is not a number.
Header problems (no ``time`` column or a requested one missing, a column named twice, an
empty or undecodable header) raise :class:`ExchangeFormatError`.
"""
from __future__ import annotations

import errno
import io
import math
import os
import stat
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterable, Sequence

if TYPE_CHECKING:             # numpy is imported where rows are read: fourbar-run's writer needs none
    import numpy as np

from fourbar_common.files import NotRegularFileError, file_kind, open_regular

from .layout import EXCHANGE
from .problems import ContractError, Problem

__all__ = ["BlockParser", "ExchangeData", "ExchangeFormatError", "ExchangeTail", "HEADER_EXAMPLE", "LineTail",
           "Lines", "ReadBatch", "ReaderStats", "RowIssue", "SKIP_KINDS", "TIME_COLUMN", "TableRow", "TableTail",
           "format_header", "format_row", "header_problems", "numpy_block", "read_exchange", "read_table"]

#: Name of the time column (the header's first column).
TIME_COLUMN = "time"
#: The header's shape, as messages show it (the columns after time are the FMU's outputs).
HEADER_EXAMPLE = "time,<output>,..."
#: The kinds of skipped rows, as :class:`ReaderStats` counts them.
SKIP_KINDS = ("malformed", "non_numeric", "non_finite", "duplicate_time", "decreasing_time")
#: Bytes kept before the offset to notice a file truncated and rewritten past the offset.
_SIGNATURE_BYTES = 64


class ExchangeFormatError(ContractError):
    """An exchange file cannot be used: its header (missing, empty, not UTF-8, a column missing
    or named twice), no valid row in a finished file, or not a regular file."""


# -- writing ----------------------------------------------------------------------------------------------
def header_problems(columns: Sequence[str]) -> list[Problem]:
    """What is wrong with ``columns`` as an exchange header (empty list: nothing)."""
    problems = []
    if not columns or columns[0] != TIME_COLUMN:
        problems.append(Problem("header", f"the first column must be {TIME_COLUMN!r}, got "
                                          f"{columns[0] if columns else 'no column'!r}"))
    for i, name in enumerate(columns):
        if not name.strip() or name != name.strip() or any(c in name for c in ',\n\r"'):
            problems.append(Problem(f"header[{i}]", f"column name {name!r} is empty, padded or holds a comma, "
                                                    "quote or line break"))
    dupes = sorted({n for n in columns if list(columns).count(n) > 1})
    if dupes:
        problems.append(Problem("header", f"column(s) {', '.join(map(repr, dupes))} named more than once"))
    return problems


def format_header(columns: Iterable[str]) -> str:
    """The header line (``\\n``-terminated); :class:`ExchangeFormatError` when ``columns`` is not one."""
    columns = tuple(columns)
    problems = header_problems(columns)
    if problems:
        raise ExchangeFormatError(EXCHANGE, problems)
    return ",".join(columns) + "\n"


def format_row(values: Sequence[float | int]) -> str:
    """One data line, ``\\n``-terminated; floats round-trip exactly (``repr``)."""
    return ",".join(map(repr, values)) + "\n"


# -- the tail of a growing file ---------------------------------------------------------------------------
@dataclass(frozen=True)
class Lines:
    """What one :meth:`LineTail.read` gives.

    ``data`` holds complete lines, each ending in ``\\n`` (``b""`` when none); ``first_line`` is
    the 1-based number of its first line in the file.  ``restarted``: the file was replaced
    or truncated before these lines (forget what came from the old one); ``missing``: there is
    no file at the path (yet, or any more).  ``overlong``: the number of a line longer than
    ``max_chunk_bytes`` that is being dropped (0 when none).
    """

    data: bytes
    first_line: int
    restarted: bool = False
    missing: bool = False
    overlong: int = 0


class LineTail:
    """The complete lines appended to a growing text file since the last :meth:`read` (module docstring).

    The file is opened at each read and closed again, never followed through a replacement.
    What is not a regular file (a FIFO, a folder) is never opened: :meth:`read` raises
    :class:`~fourbar_common.files.NotRegularFileError`, or with ``refuse_other_files=False``
    treats it as no file.
    """

    def __init__(self, path: str | os.PathLike[str], *, max_chunk_bytes: int = 4 << 20,
                 refuse_other_files: bool = True):
        self.path = Path(path)
        self.max_chunk_bytes = int(max_chunk_bytes)
        self.refuse_other_files = refuse_other_files
        self.restarts = 0
        self.reset()

    def reset(self) -> None:
        """Forget the file: the next read starts from its top (not counted as a restart)."""
        self._identity: tuple[int, int] | None = None
        self._offset = 0
        self._signature = b""
        self._line_no = 0
        self._discarding = False
        self.pending_bytes = 0

    @property
    def offset(self) -> int:
        """Bytes consumed so far (complete lines only)."""
        return self._offset

    @property
    def lines_read(self) -> int:
        return self._line_no

    def _restart(self) -> None:
        self.reset()
        self.restarts += 1

    def _gone(self, restarted: bool = False) -> Lines:
        if self._identity is not None:
            self._restart()
            restarted = True
        return Lines(b"", 1, restarted=restarted, missing=True)

    def _other_file(self, mode: int) -> Lines:
        if self.refuse_other_files:
            raise NotRegularFileError(errno.EINVAL, f"{self.path}: {file_kind(mode)}, not a regular file")
        return self._gone()

    def read(self) -> Lines:
        try:
            st = os.stat(self.path)
        except FileNotFoundError:
            return self._gone()
        if not stat.S_ISREG(st.st_mode):
            return self._other_file(st.st_mode)
        restarted = False
        if self._identity is not None and ((st.st_dev, st.st_ino) != self._identity or st.st_size < self._offset):
            self._restart()
            restarted = True
        try:
            fh = open_regular(self.path)
        except FileNotFoundError:
            return self._gone(restarted)
        except NotRegularFileError:
            if self.refuse_other_files:
                raise
            return self._gone(restarted)
        with fh:
            info = os.fstat(fh.fileno())
            # A replaced file has a new inode; a truncated-and-rewritten one keeps its inode and
            # may have grown past the offset again, and then only the bytes before the offset tell.
            if self._identity is not None and ((info.st_dev, info.st_ino) != self._identity
                                               or not self._signature_ok(fh)):
                self._restart()
                restarted = True
            self._identity = (info.st_dev, info.st_ino)
            fh.seek(self._offset)
            data = fh.read(self.max_chunk_bytes)
        return self._consume(data, restarted)

    def _signature_ok(self, fh) -> bool:
        if not self._signature:
            return True
        n = len(self._signature)
        fh.seek(self._offset - n)
        return fh.read(n) == self._signature

    def _consume(self, data: bytes, restarted: bool) -> Lines:
        if self._discarding:                    # the rest of an over-long line: drop it
            nl = data.find(b"\n")
            cut = len(data) if nl < 0 else nl + 1
            self._advance(data, cut)
            if nl < 0:
                return Lines(b"", self._line_no + 1, restarted)
            self._discarding = False
            data = data[cut:]
        first = self._line_no + 1
        end = data.rfind(b"\n") + 1
        if end == 0:
            self.pending_bytes = len(data)
            if len(data) == self.max_chunk_bytes:
                self._line_no += 1
                self._discarding = True
                self._advance(data, len(data))
                self.pending_bytes = 0
                return Lines(b"", first, restarted, overlong=self._line_no)
            return Lines(b"", first, restarted)
        self._advance(data, end)
        self.pending_bytes = len(data) - end
        body = data[:end]
        self._line_no += body.count(b"\n")
        return Lines(body, first, restarted)

    def _advance(self, data: bytes, end: int) -> None:
        self._offset += end
        tail = data[max(0, end - _SIGNATURE_BYTES):end]
        if len(tail) < _SIGNATURE_BYTES and self._offset > len(tail):
            tail = (self._signature + tail)[-_SIGNATURE_BYTES:]
        self._signature = tail


# -- exchange.csv's rows ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class RowIssue:
    """One skipped row: ``kind`` is one of :data:`SKIP_KINDS`."""

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
        return sum(getattr(self, k) for k in SKIP_KINDS)

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


#: Parses a block of complete data lines (``ncols`` fields each) into a float array of shape
#: (lines, ncols), or returns None when any field is not a plain float (the rows are then read
#: one by one under the row rules).  It must parse floats exactly (as ``float()`` does).
BlockParser = Callable[[bytes, int], "np.ndarray | None"]


def numpy_block(body: bytes, ncols: int) -> np.ndarray | None:
    """The default :data:`BlockParser` (numpy's C reader; pandas' is about 5x faster and is
    what the monitor passes, as the contract package may not use pandas)."""
    import numpy as np
    try:
        return np.loadtxt(io.BytesIO(body), delimiter=",", dtype=float, ndmin=2, comments=None, encoding=None)
    except ValueError:
        return None


def _empty_batch(columns: Sequence[str], **flags: bool) -> ReadBatch:
    import numpy as np
    return ReadBatch(np.empty(0), {c: np.empty(0) for c in columns}, **flags)


class ExchangeTail:
    """Incremental reader of one exchange file (module docstring).

    Parameters
    ----------
    path:
        The exchange CSV file.  It need not exist yet: :meth:`poll` reports ``missing``.
    columns:
        Required columns besides ``time`` (default: every column of the header).
    others:
        Also return the header's other columns (NaN where a field is not a number); they do
        not decide whether a row is valid.
    max_chunk_bytes:
        Largest number of bytes read by one poll (bounds memory per batch).
    max_issues:
        Number of :class:`RowIssue` examples kept; further skipped rows are only counted.
    parse_block:
        The fast reader of a clean block (:data:`BlockParser`; default :func:`numpy_block`).
    refuse_other_files:
        A FIFO or folder at the path raises :class:`ExchangeFormatError` (default) or reads as
        no file.
    """

    def __init__(self, path: str | os.PathLike[str], columns: Sequence[str] | None = None, *, others: bool = False,
                 max_chunk_bytes: int = 4 << 20, max_issues: int = 100, parse_block: BlockParser | None = None,
                 refuse_other_files: bool = True):
        self.path = Path(path)
        self._requested = None if columns is None else tuple(c for c in columns if c != TIME_COLUMN)
        if max_chunk_bytes < 1024:
            raise ValueError(f"max_chunk_bytes must be at least 1024, got {max_chunk_bytes}")
        self.max_chunk_bytes = int(max_chunk_bytes)
        self.max_issues = int(max_issues)
        self.others = others
        self.parse_block = parse_block or numpy_block
        self._tail = LineTail(self.path, max_chunk_bytes=self.max_chunk_bytes, refuse_other_files=refuse_other_files)
        self.stats = ReaderStats()
        self.issues: list[RowIssue] = []
        self._new_issues: list[RowIssue] = []
        self._reset_file_state()

    # -- state ------------------------------------------------------------------------
    def _reset_file_state(self) -> None:
        self.header: tuple[str, ...] | None = None
        self._index: tuple[int, ...] = ()      # required columns' positions, time first
        self._extra: tuple[int, ...] = ()      # the other returned columns' positions
        self._ncols = 0
        self._last_time = -math.inf
        self._header_error: ExchangeFormatError | None = None   # said again until the file is replaced

    @property
    def columns(self) -> tuple[str, ...]:
        """Returned value columns (required first; known once the header has been read)."""
        if self.header is None:
            return self._requested if self._requested is not None and not self.others else ()
        return tuple(self.header[i] for i in self._index[1:] + self._extra)

    @property
    def offset(self) -> int:
        """Bytes consumed so far (header and complete lines)."""
        return self._tail.offset

    @property
    def pending_bytes(self) -> int:
        """Bytes after the last complete line at the last poll (a line still being written)."""
        return self._tail.pending_bytes

    @property
    def last_time(self) -> float:
        return self._last_time

    def close(self) -> None:
        """Nothing stays open between polls; kept so that a reader is a context manager."""

    def __enter__(self) -> "ExchangeTail":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def reset(self) -> None:
        """Forget the file (a new run is known to have replaced it): the next poll reads it from its top."""
        self._tail.reset()
        self.stats = ReaderStats(restarts=self.stats.restarts)
        self.issues = []
        self._reset_file_state()

    def _error(self, message: str) -> ExchangeFormatError:
        return ExchangeFormatError(str(self.path), [Problem("", message)])

    def _restart(self) -> None:
        self.stats = ReaderStats(restarts=self.stats.restarts + 1)
        self.issues = []
        self._reset_file_state()

    # -- polling ------------------------------------------------------------------------
    def poll(self) -> ReadBatch:
        """Read the complete lines appended since the last poll (at most ``max_chunk_bytes``)."""
        try:
            lines = self._tail.read()
        except NotRegularFileError as exc:
            what = str(exc).removeprefix(f"{self.path}: ")
            raise self._error(f"{what}; the exchange file must be a file written by fourbar-run") from None
        if lines.restarted:
            self._restart()
        if self._header_error is not None:
            raise self._header_error
        self._new_issues = []
        if lines.missing:
            return _empty_batch(self.columns, missing=True, restarted=lines.restarted)
        batch = self._parse(lines)
        batch.issues = self._new_issues
        batch.restarted = lines.restarted
        return batch

    def _parse(self, lines: Lines) -> ReadBatch:
        if lines.overlong:
            if self.header is None:
                self._header_error = self._error(f"no newline in the first {self.max_chunk_bytes} bytes; "
                                                 f"expected a header line {HEADER_EXAMPLE!r}")
                raise self._header_error
            self._skip("malformed", lines.overlong, f"line longer than {self.max_chunk_bytes} bytes; row skipped")
        body = lines.data
        line_no = lines.first_line - 1
        if self.header is None and body:
            nl = body.index(b"\n")
            try:
                self._parse_header(body[:nl])
            except ExchangeFormatError as exc:
                self._header_error = exc
                raise
            body = body[nl + 1:]
            line_no += 1
        if not body:
            return _empty_batch(self.columns)
        if len(body) > 2048:
            fast = self._parse_clean(body)
            if fast is not None:
                return fast
        return self._parse_each(body.split(b"\n")[:-1], line_no)

    def _parse_header(self, raw: bytes) -> None:
        try:
            text = raw.decode("utf-8-sig").rstrip("\r")
        except UnicodeDecodeError as exc:
            raise self._error(f"line 1 (header) is not UTF-8 text: {exc.reason}") from None
        names = tuple(name.strip() for name in text.split(","))
        if not text.strip():
            raise self._error(f"line 1 (header) is empty; expected column names like {HEADER_EXAMPLE!r}")
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise self._error(f"header names column(s) {', '.join(map(repr, dupes))} more than once: {text!r}")
        wanted = (TIME_COLUMN,) + (self._requested if self._requested is not None
                                   else tuple(n for n in names if n != TIME_COLUMN))
        missing = [c for c in wanted if c not in names]
        if missing:
            # the file's own columns are the answer (any mechanism's); the header's shape is
            # only said for a file without a time column
            hint = (f" (expected a header like {HEADER_EXAMPLE!r})" if TIME_COLUMN in missing
                    else "; choose the column(s) to read among them")
            raise self._error(f"header has no column {', '.join(map(repr, missing))}; "
                              f"columns are {', '.join(names)}{hint}")
        self.header = names
        self._ncols = len(names)
        self._index = tuple(names.index(c) for c in wanted)
        self._extra = tuple(i for i in range(len(names)) if i not in self._index) if self.others else ()

    def _skip(self, kind: str, line: int, message: str, column: str | None = None,
              value: str | None = None) -> None:
        setattr(self.stats, kind, getattr(self.stats, kind) + 1)
        if len(self.issues) < self.max_issues:
            issue = RowIssue(kind, line, f"{self.path.name} line {line}: {message}", column, value)
            self.issues.append(issue)
            self._new_issues.append(issue)

    def _batch(self, time: np.ndarray, required: np.ndarray, extra: np.ndarray) -> ReadBatch:
        names = self.header
        values = {names[i]: required[:, j + 1].copy() for j, i in enumerate(self._index[1:])}
        values.update({names[i]: extra[:, j].copy() for j, i in enumerate(self._extra)})
        return ReadBatch(time.copy(), values)

    def _parse_clean(self, body: bytes) -> ReadBatch | None:
        """Fast path for a block with no bad row; None means 'use the slow path'.

        It accepts the block only when every line has the right number of numeric fields,
        the required columns are finite and time increases strictly from the last row, so
        the result is the same as the row-by-row path.
        """
        import numpy as np
        arr = self.parse_block(body, self._ncols)
        if arr is None:
            return None
        n = body.count(b"\n")
        # a parser may pad a row with too few fields with NaN: a short row whose time and
        # signal survived would pass the checks below; count commas
        if arr.shape != (n, self._ncols) or body.count(b",") != n * (self._ncols - 1):
            return None
        sub = arr[:, list(self._index)]
        t = sub[:, 0]
        if not np.isfinite(sub).all() or not t[0] > self._last_time or not (np.diff(t) > 0).all():
            return None
        self.stats.lines += n
        self.stats.rows += n
        self._last_time = float(t[-1])
        return self._batch(t, sub, arr[:, list(self._extra)])

    def _parse_each(self, lines: list[bytes], line_no: int) -> ReadBatch:
        import numpy as np
        names = self.header
        index = self._index
        extra = self._extra
        ncols = self._ncols
        out = np.empty((len(lines), len(index)))
        more = np.empty((len(lines), len(extra)))
        n = 0
        last = self._last_time
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
            for j, i in enumerate(extra):
                try:
                    more[n, j] = float(fields[i])
                except ValueError:
                    more[n, j] = math.nan
            last = t
            n += 1
        self._last_time = last
        self.stats.rows += n
        return self._batch(out[:n, 0], out[:n], more[:n])

    def read_to_end(self) -> ReadBatch:
        """Poll until the file gives nothing more; return all rows read (a finished file)."""
        import numpy as np
        batches = []
        issues: list[RowIssue] = []
        restarted = False
        missing = False
        while True:
            before = self.offset
            batch = self.poll()
            restarted |= batch.restarted
            missing |= batch.missing
            issues.extend(batch.issues)
            if len(batch):
                batches.append(batch)
            if batch.missing or self.offset == before:
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
                raise self._error(f"the header line is not terminated by a newline (file of {self.pending_bytes} "
                                  f"bytes); expected '{HEADER_EXAMPLE}\\n' then data rows")
            raise self._error(f"file is empty; expected a header line {HEADER_EXAMPLE!r} then data rows")
        if self.stats.rows == 0:
            if self.stats.lines == 0:
                raise self._error("file has a header but no data rows")
            raise self._error(f"none of the {self.stats.lines} data rows is valid ({self._skip_text()})")

    def _skip_text(self) -> str:
        return ", ".join(f"{getattr(self.stats, k)} {k.replace('_', ' ')}" for k in SKIP_KINDS
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


@dataclass(frozen=True)
class ExchangeData:
    """A finished exchange file as :func:`read_exchange` reads it: ``time`` and each column's
    values (float64 arrays of one length), the counters, the kept examples of skipped rows,
    and ``note``, one line saying what was skipped ('' when nothing)."""

    time: np.ndarray
    values: dict[str, np.ndarray]
    stats: ReaderStats
    issues: tuple[RowIssue, ...]
    note: str


def read_exchange(path: str | os.PathLike[str], columns: Sequence[str] | None = None, *,
                  parse_block: BlockParser | None = None) -> ExchangeData:
    """Read a finished exchange file: ``time`` and ``columns`` (default: all), rows under the
    module's rules.

    Raises ``FileNotFoundError`` when there is no file and :class:`ExchangeFormatError` when
    it is empty, has only a header, lacks a column, or has no valid row.
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(errno.ENOENT, "exchange file not found", str(p))
    with ExchangeTail(p, columns, parse_block=parse_block) as reader:
        batch = reader.read_to_end()
        reader.check_finished()
        return ExchangeData(batch.time, batch.values, reader.stats, tuple(reader.issues), reader.skip_summary())


# -- a CSV table with a fixed header (the monitor's evaluations.csv and forecast.csv) --------------------
@dataclass(frozen=True)
class TableRow:
    """One complete line of a table: its 1-based number in the file and its fields."""

    line: int
    fields: tuple[str, ...]


def _header_problem(columns: Sequence[str], raw: bytes) -> Problem | None:
    text = raw.decode("utf-8-sig", errors="replace").rstrip("\r")
    if tuple(name.strip() for name in text.split(",")) == tuple(columns):
        return None
    return Problem("header", f"expected {','.join(columns)!r}, got {text[:200]!r}")


def _table_rows(data: bytes, first_line: int, width: int) -> tuple[list[TableRow], list[int]]:
    """The rows of complete lines ``data`` (numbered from ``first_line``) and the numbers of the
    lines that are not rows: not UTF-8, or not ``width`` fields (a blank line is neither)."""
    rows, bad = [], []
    for k, raw in enumerate(data.split(b"\n")[:-1]):
        try:
            text = raw.decode("utf-8").rstrip("\r")
        except UnicodeDecodeError:
            bad.append(first_line + k)
            continue
        if not text.strip():
            continue
        fields = tuple(text.split(","))
        if len(fields) == width:
            rows.append(TableRow(first_line + k, fields))
        else:
            bad.append(first_line + k)
    return rows, bad


class TableTail:
    """The new rows of a growing CSV table whose header is ``columns`` (:class:`LineTail` below).

    :meth:`poll` returns (rows, numbers of the lines that are not rows, restarted); a header
    other than ``columns`` raises :class:`~.problems.ContractError` naming the file.  A FIFO or
    folder at the path reads as no file unless ``refuse_other_files``.
    """

    def __init__(self, path: str | os.PathLike[str], columns: Sequence[str], *, max_chunk_bytes: int = 4 << 20,
                 refuse_other_files: bool = False):
        self.path = Path(path)
        self.columns = tuple(columns)
        self._tail = LineTail(self.path, max_chunk_bytes=max_chunk_bytes, refuse_other_files=refuse_other_files)
        self._header_seen = False
        self._header_error: ContractError | None = None     # said again until the file is replaced

    def reset(self) -> None:
        self._tail.reset()
        self._header_seen = False
        self._header_error = None

    def poll(self) -> tuple[list[TableRow], list[int], bool]:
        lines = self._tail.read()
        if lines.restarted or lines.missing:
            self._header_seen = False
            self._header_error = None
        if self._header_error is not None:
            raise self._header_error
        data, first = lines.data, lines.first_line
        bad = [lines.overlong] if lines.overlong and self._header_seen else []
        if data and not self._header_seen:
            nl = data.index(b"\n")
            problem = _header_problem(self.columns, data[:nl])
            if problem is not None:
                self._header_error = ContractError(str(self.path), [problem])
                raise self._header_error
            self._header_seen = True
            data, first = data[nl + 1:], first + 1
        rows, more = _table_rows(data, first, len(self.columns))
        return rows, bad + more, lines.restarted


def read_table(path: str | os.PathLike[str], columns: Sequence[str]) -> tuple[list[TableRow], list[Problem]]:
    """Every row of a finished table whose header is ``columns``, and a problem for each complete
    line that is not a row; a last line without its newline (a writer stopped mid-line) is not
    a row.  Raises ``FileNotFoundError`` when there is no file and
    :class:`~.problems.ContractError` when the header is missing or another."""
    p = Path(path)
    try:
        fh = open_regular(p)
    except NotRegularFileError as exc:
        raise ContractError(str(p), [Problem("", str(exc).removeprefix(f"{p}: "))]) from None
    with fh:
        data = fh.read()
    end = data.rfind(b"\n") + 1
    if end == 0:
        raise ContractError(str(p), [Problem("header", f"missing; expected {','.join(columns)!r}")])
    nl = data.index(b"\n")
    problem = _header_problem(columns, data[:nl])
    if problem is not None:
        raise ContractError(str(p), [problem])
    rows, bad = _table_rows(data[nl + 1:end], 2, len(columns))
    return rows, [Problem(f"line {n}", f"not {len(columns)} comma-separated fields of UTF-8 text") for n in bad]

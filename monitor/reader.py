"""Reading the exchange file (``time,<output>,...``) and its ``run.json``.

The exchange file grows while the orchestrator runs.  :class:`ExchangeReader` follows it with
the contract's one tail reader (:class:`fourbar_common.contract.exchange.ExchangeTail`: complete
lines only, by byte offset, bounded memory, a replaced or truncated file read again from its
top, the row rules and their counters), with pandas' C parser for clean blocks and the
monitor's exceptions: header problems (missing column, duplicate column name, undecodable
header) raise :class:`~monitor.errors.ExchangeFormatError`; so do an empty or header-only file
in :func:`read_exchange` (a finished file).
"""
from __future__ import annotations

import os
import stat
import warnings
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np

from fourbar_common import Event
from fourbar_common.contract import exchange as contract
from fourbar_common.contract.exchange import TIME_COLUMN, ReadBatch, ReaderStats, RowIssue
from fourbar_common.contract.layout import EXCHANGE, RUN_RECORD
from fourbar_common.contract.run_record import RunRecord, RunRecordError, read_run_record
from fourbar_common.files import file_kind

from .errors import ExchangeFormatError, ExchangeMissingError

if TYPE_CHECKING:
    import pandas as pd

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


class ExchangeWarning(UserWarning):
    """Rows of an exchange file were skipped (see the counts in the message)."""


def _pandas_block(body: bytes, ncols: int) -> np.ndarray | None:
    """The contract's :data:`~fourbar_common.contract.exchange.BlockParser` with pandas' C parser
    (about 5x numpy's; pandas 3 parses floats exactly); None when the block does not parse."""
    import csv
    import io

    import pandas as pd

    try:
        return pd.read_csv(io.BytesIO(body), header=None, dtype=float, engine="c",
                           skip_blank_lines=False, quoting=csv.QUOTE_NONE, na_filter=True).to_numpy()
    except (ValueError, pd.errors.ParserError, pd.errors.EmptyDataError):
        return None


class ExchangeReader(contract.ExchangeTail):
    """Incremental reader of one exchange file: the contract's :class:`~fourbar_common.contract.
    exchange.ExchangeTail` raising the monitor's errors.

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
        super().__init__(path, columns, max_chunk_bytes=max_chunk_bytes, max_issues=max_issues,
                         parse_block=_pandas_block)

    def __enter__(self) -> "ExchangeReader":
        return self

    def poll(self) -> ReadBatch:
        try:
            return super().poll()
        except contract.ExchangeFormatError as exc:
            raise ExchangeFormatError(str(exc)) from None
        except (ExchangeMissingError, FileNotFoundError):
            raise
        except OSError as exc:
            raise ExchangeMissingError(f"{self.path}: cannot open exchange file: {exc.strerror}") from exc

    def check_finished(self) -> None:
        try:
            super().check_finished()
        except contract.ExchangeFormatError as exc:
            raise ExchangeFormatError(str(exc)) from None


def exchange_file(path: str | Path, *, later: bool = False) -> Path:
    """The exchange file ``path`` names: itself, or a run folder's exchange.csv (which, with
    ``later``, may not exist yet).  A folder without one raises :class:`ExchangeMissingError`.

    With ``later`` a path that does not exist yet is a run folder to come (its exchange.csv
    is followed) unless its name ends in ``.csv``."""
    p = Path(path)
    if p.is_dir():
        if later or os.path.lexists(p / EXCHANGE):      # not a file: the reader says what it is
            return p / EXCHANGE
        raise ExchangeMissingError(f"{p}: is a directory with no {EXCHANGE} in it: give an exchange file or "
                                   f"a run folder")
    if later and not p.exists() and p.suffix.lower() != ".csv":
        return p / EXCHANGE        # a run folder still to come (a file to come ends in .csv)
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

"""The results table: one row per scenario, appended as scenarios finish, kept when interrupted.

Files in the sweep's output directory:

``results.csv``      the journal: a header, then one line per finished scenario, appended
                     (and flushed) as each one finishes -- in completion order while the
                     sweep runs, rewritten in plan order when it ends.  Floats are written
                     with ``repr`` (17 significant digits at most) and read back exactly.
``results.parquet``  the same table in plan order, rewritten (atomically) while the sweep
                     runs (every 30 s) and at the end.
``stale.csv``        rows moved out of the table: scenarios no longer in the sweep file,
                     rows made with another build of the FMU (GUID), failed rows given
                     again with ``--retry-failed``.  Nothing is deleted.

A last line without ``\\n`` (the sweep was killed while writing it) is dropped on reading.
"""
from __future__ import annotations

import io
import math
from pathlib import Path
from typing import Any, Iterable, Sequence

from fourbar_common import output_folder_problem, replace_atomically
from fourbar_common.contract.layout import SWEEP_RESULTS, SWEEP_SUMMARY, SweepFolder
from fourbar_common.contract.sweep_results import (RESULT_COLUMNS, RUNTIME_COLUMNS, format_cell, format_row,
                                                   results_header)

from .scenario import RESULT_FIELDS

__all__ = ["COLUMNS", "RUNTIME_COLUMNS", "ResultsError", "ResultsStore", "table_from_rows"]

#: Every column of the table and its type: str, float, int (nullable), bool (nullable) (the contract's).
COLUMNS: dict[str, str] = RESULT_COLUMNS
_DTYPES = {"str": "str", "float": "float64", "int": "Int64", "bool": "boolean"}

assert set(RESULT_FIELDS) <= set(COLUMNS), "scenario fields missing from the table schema"


class ResultsError(RuntimeError):
    """An existing results file cannot be used (other columns, unreadable)."""


def table_from_rows(rows: Iterable[dict[str, Any]]) -> "Any":
    """A DataFrame with the table's columns and types (missing values: NaN / <NA>)."""
    import pandas as pd

    rows = list(rows)
    data = {}
    for name, kind in COLUMNS.items():
        values = [r.get(name) for r in rows]
        values = [None if (v is None or v is pd.NA or (isinstance(v, float) and math.isnan(v))) else v
                  for v in values]
        if kind == "float":
            values = [math.nan if v is None else float(v) for v in values]
        data[name] = pd.array(values, dtype=_DTYPES[kind])
    return pd.DataFrame(data)


class ResultsStore:
    """The results files of one sweep output directory."""

    def __init__(self, out_dir: str | Path):
        self.out_dir = Path(out_dir)
        self.csv_path = SweepFolder(self.out_dir).results
        self.parquet_path = self.out_dir / "results.parquet"
        self.stale_path = self.out_dir / "stale.csv"
        self._fh = None

    # -- reading --------------------------------------------------------------------------
    def load(self) -> list[dict[str, Any]]:
        """Rows already in ``results.csv`` (none if it does not exist)."""
        import pandas as pd

        if not self.csv_path.exists():
            return []
        data = self.csv_path.read_bytes()
        if not data.strip():
            return []
        complete = data[:data.rfind(b"\n") + 1] if not data.endswith(b"\n") else data
        header = complete.split(b"\n", 1)[0].decode("utf-8", "replace").strip()
        if header.split(",") != list(COLUMNS):
            raise ResultsError(f"{self.csv_path}: its columns are not those of this version of fourbar-sweep "
                               f"(header {header[:80]!r}...); move it away or choose another --out")
        # pandas >= 3 parses floats exactly by default (and deprecates float_precision)
        exact = {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}
        try:
            df = pd.read_csv(io.BytesIO(complete), dtype={k: _DTYPES[v] for k, v in COLUMNS.items()},
                             keep_default_na=False, na_values={k: [""] for k in COLUMNS}, **exact)
        except (ValueError, pd.errors.ParserError) as exc:
            raise ResultsError(f"{self.csv_path}: cannot be read back ({exc}); move it away or choose "
                               f"another --out") from None
        return [_plain(r) for r in df.to_dict("records")]

    # -- writing --------------------------------------------------------------------------
    def rewrite(self, rows: Sequence[dict[str, Any]]) -> None:
        """Replace ``results.csv`` with ``rows`` (atomically), then keep it open for appends."""
        self.close()
        self.out_dir.mkdir(parents=True, exist_ok=True)

        def write(tmp: Path) -> None:
            with open(tmp, "w", encoding="utf-8", newline="") as fh:
                fh.write(results_header())
                fh.writelines(format_row(r) for r in rows)

        replace_atomically(self.csv_path, write)

    def append(self, row: dict[str, Any]) -> None:
        """Append one row to ``results.csv`` and flush it to the OS."""
        if self._fh is None:
            self._fh = open(self.csv_path, "a", encoding="utf-8", newline="")
        self._fh.write(format_row(row))
        self._fh.flush()

    def move_to_stale(self, rows: Sequence[dict[str, Any]], reason: str) -> None:
        """Append ``rows`` to ``stale.csv`` with a ``reason`` column."""
        if not rows:
            return
        new = not self.stale_path.exists()
        with open(self.stale_path, "a", encoding="utf-8", newline="") as fh:
            if new:
                fh.write(results_header(("stale_reason",)))
            for r in rows:
                fh.write(format_row(r)[:-1] + "," + format_cell(reason) + "\n")

    def write_parquet(self, table) -> None:
        replace_atomically(self.parquet_path, lambda tmp: table.to_parquet(tmp, index=False))

    def close(self) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def check_dir(self) -> None:
        """Raise :class:`ResultsError` naming the path when the output directory cannot be
        used: it (or a parent) is a file, or it cannot be created or written.  Creates nothing."""
        problem = output_folder_problem(self.out_dir, f"{SWEEP_RESULTS}, results.parquet, {SWEEP_SUMMARY}, plots/ and "
                                                      "runs/")
        if problem is not None:
            raise ResultsError(f"--out {self.out_dir}: {problem}")

    def lock(self) -> None:
        """Claim the directory (:class:`fourbar_common.folder_lock.FolderLock` on ``.lock``,
        held until :meth:`unlock` or the process's end); ResultsError naming the holder if
        another process holds it, or if the directory cannot be used (:meth:`check_dir`).
        A lock left by a dead process is no lock (the kernel released it)."""
        from fourbar_common.folder_lock import FolderLock, FolderLocked

        self.check_dir()
        try:
            self.out_dir.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ResultsError(f"--out {self.out_dir}: cannot create the folder: {exc.strerror or exc}") from None
        try:
            self._lock = FolderLock(self.out_dir, "fourbar-sweep").acquire()
        except FolderLocked as exc:
            if exc.holder is not None:
                raise ResultsError(f"{self.out_dir}: another {exc.holder.describe()} is writing here; "
                                   f"wait for it, or choose another --out") from None
            raise ResultsError(f"--out {self.out_dir}: cannot write there: {exc}") from None

    def unlock(self) -> None:
        lock, self._lock = getattr(self, "_lock", None), None
        if lock is not None:
            lock.release()

    def __enter__(self) -> "ResultsStore":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
        self.unlock()


def _plain(record: dict[str, Any]) -> dict[str, Any]:
    """pandas scalars -> Python values (None for missing)."""
    import pandas as pd

    out = {}
    for k, v in record.items():
        if v is pd.NA or v is None or (isinstance(v, float) and math.isnan(v)):
            out[k] = None
        elif hasattr(v, "item"):
            out[k] = v.item()
        else:
            out[k] = v
    return out

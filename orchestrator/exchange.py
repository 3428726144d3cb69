"""The exchange file (CSV rows) and run.json, written so that a concurrent reader is safe.

exchange.csv: one header line, then one line per communication point; floats written with
``repr`` (the shortest text that reads back to the same double, at most 17 significant
digits), ``.`` decimal point, ``\\n`` line ends.  Lines are appended in blocks of complete
lines; if an append fails part-way (disk full), the file is cut back to the end of the last
complete block, so it never ends in a half row that would later be completed.

run.json is replaced atomically (:func:`fourbar_common.write_json_atomic`), so a reader
sees either the previous or the new document, never a mixture.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable, Sequence

__all__ = ["ExchangeWriter", "format_row"]


def format_row(values: Sequence[float | int]) -> str:
    """One CSV line, ``\\n``-terminated; floats round-trip exactly."""
    return ",".join(map(repr, values)) + "\n"


class ExchangeWriter:
    """Append-only writer of complete CSV lines (use as a context manager).

    ``append`` writes all given lines with as few ``write`` calls as the OS allows; the
    size after the last complete append is remembered and restored on failure.
    """

    def __init__(self, path: str | Path, columns: Iterable[str]):
        self.path = Path(path)
        self.rows_written = 0
        self._size = 0
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        try:
            self._append_text(",".join(columns) + "\n")
        except BaseException:
            self.close()
            raise

    def __enter__(self) -> "ExchangeWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def append(self, lines: Sequence[str]) -> None:
        """Append complete lines (each ending in ``\\n``); all or nothing, as far as a reader sees."""
        if not lines:
            return
        self._append_text("".join(lines))
        self.rows_written += len(lines)

    def _append_text(self, text: str) -> None:
        data = memoryview(text.encode("utf-8"))
        try:
            written = 0
            while written < len(data):
                written += self._write(data[written:])
        except OSError as exc:
            self._cut_back()
            if exc.filename is None:   # os.write does not say which file
                raise OSError(exc.errno, exc.strerror, str(self.path)) from exc
            raise
        except BaseException:
            self._cut_back()
            raise
        self._size += len(data)

    def _write(self, data: memoryview) -> int:
        return os.write(self._fd, data)

    def _cut_back(self) -> None:
        """Remove a partial block after a failed append (best effort: the disk may be full)."""
        try:
            os.ftruncate(self._fd, self._size)
            os.lseek(self._fd, self._size, os.SEEK_SET)
        except OSError:
            pass

    def close(self) -> None:
        if self._fd is not None:
            fd, self._fd = self._fd, None
            os.close(fd)


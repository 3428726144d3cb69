"""The exchange file (CSV rows) and run.json, written so that a concurrent reader is safe.

exchange.csv: the format is the contract's (:mod:`fourbar_common.contract.exchange`: the
header, ``time`` first, and each row's text, floats that round-trip exactly, come from
there); this module owns how the file is written safely.  Lines are appended in blocks of complete
lines; if an append fails part-way (disk full), the file is cut back to the end of the last
complete block, so it never ends in a half row that would later be completed.

The file is opened without following a symbolic link (``O_NOFOLLOW``) and only if it is a
regular file (or absent): a link or a FIFO named exchange.csv raises
:class:`ExchangeRefused` before anything is truncated.  :meth:`ExchangeWriter.verify` checks
at the end that the file at the path is still the one written (same device and inode) and
holds exactly the lines written.

run.json is replaced atomically (:func:`fourbar_common.write_json_atomic`), so a reader
sees either the previous or the new document, never a mixture.
"""
from __future__ import annotations

import errno
import os
import stat
from pathlib import Path
from typing import Iterable, Sequence

from fourbar_common.contract.exchange import format_header, format_row

__all__ = ["ExchangeRefused", "ExchangeWriter", "format_row"]


class ExchangeRefused(OSError):
    """The path exchange.csv is to be written at holds something else than a regular file
    (a symbolic link, a FIFO, a folder): nothing was opened for writing or truncated."""


class ExchangeWriter:
    """Append-only writer of complete CSV lines (use as a context manager).

    ``append`` writes all given lines with as few ``write`` calls as the OS allows; the
    size after the last complete append is remembered and restored on failure.
    """

    def __init__(self, path: str | Path, columns: Iterable[str]):
        header = format_header(columns)      # checked before anything is opened or truncated
        self.path = Path(path)
        self.rows_written = 0
        self._size = 0
        self._fd = None
        flags = os.O_WRONLY | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW | os.O_NONBLOCK   # NONBLOCK: a FIFO
        try:
            fd = os.open(self.path, flags, 0o644)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                raise ExchangeRefused(exc.errno, "is a symbolic link; refusing to follow it (its target is left "
                                                 "untouched): remove the link or choose another --out",
                                      str(self.path)) from None
            if exc.errno in (errno.ENXIO, errno.EISDIR):
                raise ExchangeRefused(exc.errno, "is not a regular file (a FIFO or a folder); remove it or choose "
                                                 "another --out", str(self.path)) from None
            raise
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            os.close(fd)
            raise ExchangeRefused(errno.EINVAL, "is not a regular file; remove it or choose another --out",
                                  str(self.path))
        os.set_blocking(fd, True)
        self._fd = fd
        self.identity = (info.st_dev, info.st_ino)
        try:
            os.ftruncate(fd, 0)
            self._append_text(header)
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

    def verify(self) -> str | None:
        """None when the file at the path is the one written and holds exactly what was
        appended (its size, and one header plus ``rows_written`` lines); else why not."""
        try:
            info = os.stat(self.path, follow_symlinks=False)
        except FileNotFoundError:
            return f"{self.path} was removed during the run; the {self.rows_written} rows written are lost"
        except OSError as exc:
            return f"{self.path} cannot be checked: {exc.strerror or exc}"
        if (info.st_dev, info.st_ino) != self.identity:
            return (f"{self.path} was replaced during the run (another file is at the path now); the "
                    f"{self.rows_written} rows this run wrote went to the replaced file")
        if info.st_size != self._size:
            return (f"{self.path} holds {info.st_size} bytes, but this run wrote {self._size}: something else "
                    f"changed the file during the run")
        lines = 0
        try:
            with open(self.path, "rb") as fh:
                while chunk := fh.read(1 << 20):
                    lines += chunk.count(b"\n")
        except OSError as exc:
            return f"{self.path} cannot be read back: {exc.strerror or exc}"
        if lines != self.rows_written + 1:
            return (f"{self.path} holds {lines - 1} complete rows, but this run wrote {self.rows_written}: "
                    f"something else changed the file during the run")
        return None

    def close(self) -> None:
        if self._fd is not None:
            fd, self._fd = self._fd, None
            os.close(fd)


"""A command's standard output piped into a reader that stops early (``| head``).

Writing to a pipe whose reader has gone raises ``BrokenPipeError``.  A command's console
lines are a report of its work, not the work: the files it writes (a monitor's summary, a
diagnosis) must still be written, and nothing should print a traceback or an error about
the console.  :func:`closed_stdout_tolerated` makes ``sys.stdout`` drop what cannot be
delivered once the reader has gone, so the command finishes as if nobody read it; its exit
status is what the work says.
"""
from __future__ import annotations

import io
import os
import sys
from contextlib import contextmanager
from typing import Iterator, TextIO

__all__ = ["closed_stdout_tolerated"]


class _TolerantStream(io.TextIOBase):
    """Passes text to ``stream`` until its reader has gone, then drops it."""

    def __init__(self, stream: TextIO):
        super().__init__()
        self._stream = stream
        self.reader_gone = False

    def _gone(self) -> None:
        self.reader_gone = True
        try:        # the interpreter flushes the real stdout at exit: point it at /dev/null
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self._stream.fileno())
            os.close(devnull)
        except (OSError, ValueError, io.UnsupportedOperation):
            pass

    def write(self, text: str) -> int:
        if not self.reader_gone:
            try:
                self._stream.write(text)
            except BrokenPipeError:
                self._gone()
        return len(text)

    def flush(self) -> None:
        if not self.reader_gone:
            try:
                self._stream.flush()
            except BrokenPipeError:
                self._gone()

    def isatty(self) -> bool:
        return not self.reader_gone and self._stream.isatty()

    def fileno(self) -> int:
        return self._stream.fileno()

    @property
    def encoding(self) -> str:          # type: ignore[override]
        return getattr(self._stream, "encoding", "utf-8")

    def writable(self) -> bool:
        return True


@contextmanager
def closed_stdout_tolerated() -> Iterator[None]:
    """Inside the block, ``sys.stdout`` survives its reader going away (module docstring)."""
    previous = sys.stdout
    if previous is None or isinstance(previous, _TolerantStream):
        yield
        return
    sys.stdout = _TolerantStream(previous)
    try:
        yield
    finally:
        try:
            sys.stdout.flush()
        finally:
            sys.stdout = previous

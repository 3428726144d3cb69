"""Ctrl-C (SIGINT) and SIGTERM: one orderly way to stop a command, whatever it is doing.

A command runs its work inside :class:`StopSignals`.  Either signal then raises
:class:`Stopped`, a ``KeyboardInterrupt`` that carries the signal's number, so every
``except KeyboardInterrupt`` that keeps what was written also does so on SIGTERM, and the
command ends with one line and the shell's status for that signal, ``128 + number``
(:func:`exit_code`: 130 for Ctrl-C, 143 for SIGTERM).

Code that calls into an FMU that runs Python in this interpreter (a pythonfmu FMU) wraps
those calls in :func:`deferred`: a signal that arrives inside the block is only recorded,
and raised when the block ends or at the next :func:`checkpoint`.  An exception raised in
the FMU's own Python code would make the FMU report a fatal error, after which its
instance may not even be freed; deferred, the signal always lands between two FMU calls.
Without an active :class:`StopSignals` (a library caller), :func:`deferred` does the same
for Ctrl-C alone, while its block runs.

Signal handlers run in the main thread only: elsewhere these are no-ops.  A signal the
process inherited as ignored (a background job's SIGINT) stays ignored.
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from typing import Any, Iterator

__all__ = ["STOP_SIGNALS", "StopSignals", "Stopped", "checkpoint", "deferred", "exit_code", "signal_of",
           "stop_reason"]

#: The signals that stop a command in order: Ctrl-C and a service manager's (or `kill`'s) SIGTERM.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Stopped(KeyboardInterrupt):
    """A stop signal, raised where Ctrl-C raises ``KeyboardInterrupt``; ``signum`` says which."""

    def __init__(self, signum: int = signal.SIGINT):
        super().__init__(stop_reason(signum))
        self.signum = int(signum)


def signal_of(exc: BaseException) -> int:
    """The signal behind a ``KeyboardInterrupt``: its ``signum`` if it carries one, else SIGINT."""
    return int(getattr(exc, "signum", signal.SIGINT))


def exit_code(signum: int) -> int:
    """The exit status of a command stopped by ``signum``: 128 + its number (SIGINT 130, SIGTERM 143)."""
    return 128 + int(signum)


def stop_reason(signum: int) -> str:
    """'interrupted by Ctrl-C' or 'terminated by SIGTERM' (other signals by name)."""
    if signum == signal.SIGINT:
        return "interrupted by Ctrl-C"
    try:
        return f"terminated by {signal.Signals(signum).name}"
    except ValueError:
        return f"terminated by signal {signum}"


_active: "StopSignals | None" = None


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


class StopSignals:
    """Context manager: while active, SIGINT and SIGTERM raise :class:`Stopped` (see the module docstring).

    ``received`` is the first signal's number (None until one came); :attr:`exit_code` the
    status to end with.  Handlers are restored on exit.
    """

    def __init__(self, signals: tuple[int, ...] = STOP_SIGNALS):
        self.signals = tuple(signals)
        self.received: int | None = None
        self._previous: dict[int, Any] = {}
        self._depth = 0            # nesting of deferred() blocks
        self._pending: int | None = None
        self._outer: StopSignals | None = None
        self._entered = False

    def __enter__(self) -> "StopSignals":
        global _active
        if _main_thread():
            for signum in self.signals:
                current = signal.getsignal(signum)
                if current is signal.SIG_IGN:       # ignored by whoever started us: keep it so
                    continue
                self._previous[signum] = signal.signal(signum, self._handle)
            self._outer, _active = _active, self
            self._entered = True
        return self

    def __exit__(self, *exc: Any) -> None:
        global _active
        for signum, previous in self._previous.items():
            signal.signal(signum, previous if previous is not None else signal.SIG_DFL)
        self._previous.clear()
        if self._entered and _active is self:
            _active = self._outer
        self._entered = False

    def _handle(self, signum: int, frame: Any) -> None:
        if self.received is None:
            self.received = signum
        if self._depth:
            self._pending = signum
            return
        raise Stopped(signum)

    @property
    def exit_code(self) -> int:
        """128 + the signal received (130 when none was: a plain ``KeyboardInterrupt``)."""
        return exit_code(self.received if self.received is not None else signal.SIGINT)

    @property
    def reason(self) -> str:
        return stop_reason(self.received if self.received is not None else signal.SIGINT)

    def _raise_pending(self) -> None:
        if self._pending is not None:
            signum, self._pending = self._pending, None
            raise Stopped(signum)


@contextmanager
def deferred() -> Iterator[None]:
    """Hold stop signals back while the block runs; raise the one that came when it ends."""
    if not _main_thread():
        yield
        return
    stop, own = _active, None
    if stop is None:
        if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
            yield                     # someone else handles Ctrl-C: leave it to them
            return
        own = stop = StopSignals((signal.SIGINT,)).__enter__()
    stop._depth += 1
    try:
        yield
    finally:
        stop._depth -= 1
        if own is not None:
            own.__exit__()
        if stop._depth == 0:
            stop._raise_pending()


def checkpoint() -> None:
    """Inside :func:`deferred`: raise the stop signal that came since the block began, if any."""
    stop = _active
    if stop is not None and _main_thread():
        stop._raise_pending()

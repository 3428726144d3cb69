"""Real-time pacing and signal handling (Ctrl-C, SIGTERM) for the run loop.

:class:`RealtimePacer` holds each block of rows back until its simulated time has come on
the wall clock: the block ending at ``t`` is released at
``wall_start + (t - start)/factor`` (factor 1: real time, 20: twenty times faster).

:class:`InterruptFlag` turns Ctrl-C (SIGINT) and SIGTERM into a flag the loop checks
between steps, so the signal never lands inside the FMU's own code (a pythonfmu FMU runs
Python in this interpreter); a second signal raises at once.  What is raised is
:class:`fourbar_common.signals.Stopped`, a ``KeyboardInterrupt`` that carries the signal's
number, so every ``except KeyboardInterrupt`` that keeps rows also keeps them on SIGTERM,
and a command ends with :func:`fourbar_common.signals.exit_code` (130 or 143).
"""
from __future__ import annotations

import signal
import threading
import time

from fourbar_common.signals import STOP_SIGNALS, StopSignals, Stopped

__all__ = ["InterruptFlag", "RealtimePacer"]

_SLICE = 0.05   # s: longest single sleep, so a signal is noticed quickly while waiting


def _default_stop(signum: int, handler) -> bool:
    """``handler`` stops the program at once on ``signum``: Python's own Ctrl-C handler,
    SIGTERM's default (termination), or a command's :class:`StopSignals` (what every CLI
    of this project runs under).  A handler someone else installed is left alone, and so
    is a signal the process inherited as ignored."""
    if signum == signal.SIGINT and handler is signal.default_int_handler:
        return True
    if signum == signal.SIGTERM and handler in (signal.SIG_DFL, None):
        return True
    return isinstance(getattr(handler, "__self__", None), StopSignals)


class InterruptFlag:
    """Context manager: while active (main thread only), SIGINT and SIGTERM set ``requested``
    and ``signum`` instead of stopping the program at once (:func:`_default_stop` says when
    a signal is taken over)."""

    def __init__(self):
        self.requested = False
        self.signum: int | None = None
        self._previous: dict[int, object] = {}

    def __enter__(self) -> "InterruptFlag":
        if threading.current_thread() is threading.main_thread():
            for signum in STOP_SIGNALS:
                current = signal.getsignal(signum)
                if _default_stop(signum, current):
                    self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        for signum, previous in self._previous.items():
            signal.signal(signum, previous if previous is not None else signal.SIG_DFL)
        self._previous = {}

    def _handle(self, signum, frame) -> None:
        if self.requested:
            raise Stopped(signum)
        self.requested = True
        self.signum = signum

    def check(self) -> None:
        """Raise :class:`~fourbar_common.signals.Stopped` if a signal came."""
        if self.requested:
            raise Stopped(self.signum)


class RealtimePacer:
    """Waits until simulated time ``t`` is due on the wall clock (no-op for factor 0)."""

    def __init__(self, factor: float, start_time: float, interrupt: InterruptFlag | None = None):
        self.factor = factor
        self.start_time = start_time
        self.interrupt = interrupt
        self.wall_start = time.monotonic()

    def start(self) -> None:
        """Anchor simulated ``start_time`` to now."""
        self.wall_start = time.monotonic()

    def due(self, t: float) -> float:
        """Wall-clock (monotonic) instant at which simulated time ``t`` is due."""
        return self.wall_start + (t - self.start_time) / self.factor

    def wait_until(self, t: float) -> None:
        if self.factor <= 0.0:
            return
        target = self.due(t)
        while True:
            if self.interrupt is not None:
                self.interrupt.check()
            remaining = target - time.monotonic()
            if remaining <= 0.0:
                return
            time.sleep(min(remaining, _SLICE))

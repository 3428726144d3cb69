"""Real-time pacing and signal handling (Ctrl-C, SIGTERM) for the run loop.

:class:`RealtimePacer` holds each block of rows back until its simulated time has come on
the wall clock: the block ending at ``t`` is released at
``wall_start + (t - start)/factor`` (factor 1: real time, 20: twenty times faster).

:class:`InterruptFlag` turns Ctrl-C (SIGINT) and SIGTERM into a flag the loop checks
between steps, so the signal never lands inside the FMU's own code (a pythonfmu FMU runs
Python in this interpreter); a second signal raises at once.  SIGTERM is handled like
Ctrl-C: it raises :class:`Terminated`, a ``KeyboardInterrupt`` that carries its signal
number, so every ``except KeyboardInterrupt`` that keeps rows also keeps them on SIGTERM.
"""
from __future__ import annotations

import signal
import threading
import time

__all__ = ["InterruptFlag", "RealtimePacer", "Terminated", "raise_on_sigterm", "signal_of", "stop_reason"]

_SLICE = 0.05   # s: longest single sleep, so a signal is noticed quickly while waiting


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where Ctrl-C raises ``KeyboardInterrupt``."""

    signum = signal.SIGTERM


def signal_of(exc: BaseException) -> int:
    """The signal behind a ``KeyboardInterrupt``: SIGTERM for :class:`Terminated`, else SIGINT."""
    return int(getattr(exc, "signum", signal.SIGINT))


def stop_reason(signum: int) -> str:
    """'interrupted by Ctrl-C' or 'terminated by SIGTERM': what run.json and messages say."""
    return "terminated by SIGTERM" if signum == signal.SIGTERM else "interrupted by Ctrl-C"


def _raise_terminated(signum, frame) -> None:
    raise Terminated


def raise_on_sigterm() -> None:
    """Make SIGTERM raise :class:`Terminated` in the main thread (for a CLI's whole life:
    outside a run's loop it stops the program like Ctrl-C does, without a traceback when
    the CLI catches ``KeyboardInterrupt``).  Leaves a handler someone else installed alone."""
    if threading.current_thread() is threading.main_thread() \
            and signal.getsignal(signal.SIGTERM) in (signal.SIG_DFL, None):
        signal.signal(signal.SIGTERM, _raise_terminated)


class InterruptFlag:
    """Context manager: while active (main thread only), SIGINT and SIGTERM set ``requested``
    and ``signum``.

    A signal is taken over only while it has its default behaviour (Python's
    ``KeyboardInterrupt`` for SIGINT; termination, or :func:`raise_on_sigterm`'s handler,
    for SIGTERM), so a program that handles the signal itself keeps doing so.
    """

    def __init__(self):
        self.requested = False
        self.signum: int | None = None
        self._previous: dict[int, object] = {}

    def __enter__(self) -> "InterruptFlag":
        if threading.current_thread() is threading.main_thread():
            defaults = {signal.SIGINT: (signal.default_int_handler,),
                        signal.SIGTERM: (signal.SIG_DFL, _raise_terminated)}
            for signum, default in defaults.items():
                if signal.getsignal(signum) in default:
                    self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        for signum, previous in self._previous.items():
            signal.signal(signum, previous)
        self._previous = {}

    def _handle(self, signum, frame) -> None:
        if self.requested:
            raise Terminated if signum == signal.SIGTERM else KeyboardInterrupt
        self.requested = True
        self.signum = signum

    def check(self) -> None:
        """Raise ``KeyboardInterrupt`` (:class:`Terminated` for SIGTERM) if a signal came."""
        if self.requested:
            raise Terminated if self.signum == signal.SIGTERM else KeyboardInterrupt


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

"""Real-time pacing and Ctrl-C handling for the run loop.

:class:`RealtimePacer` holds each block of rows back until its simulated time has come on
the wall clock: the block ending at ``t`` is released at
``wall_start + (t - start)/factor`` (factor 1: real time, 20: twenty times faster).

:class:`InterruptFlag` turns Ctrl-C into a flag the loop checks between steps, so the
interrupt never lands inside the FMU's own code (a pythonfmu FMU runs Python in this
interpreter); a second Ctrl-C raises ``KeyboardInterrupt`` at once.
"""
from __future__ import annotations

import signal
import threading
import time

__all__ = ["InterruptFlag", "RealtimePacer"]

_SLICE = 0.05   # s: longest single sleep, so Ctrl-C is noticed quickly while waiting


class InterruptFlag:
    """Context manager: while active (main thread only), SIGINT sets ``requested``."""

    def __init__(self):
        self.requested = False
        self._previous = None

    def __enter__(self) -> "InterruptFlag":
        if threading.current_thread() is threading.main_thread() \
                and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
            self._previous = None

    def _handle(self, signum, frame) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True

    def check(self) -> None:
        """Raise ``KeyboardInterrupt`` if Ctrl-C was pressed."""
        if self.requested:
            raise KeyboardInterrupt


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

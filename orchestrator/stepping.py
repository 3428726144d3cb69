"""The run loop in a worker thread, so that a signal is handled even while a doStep never returns.

A Python signal handler runs only in the main thread, and only between two bytecodes: while
the main thread is inside one foreign call (an FMU's ``fmi2DoStep`` that integrates a
1e15 rad/s crank for days) Ctrl-C and SIGTERM wait with it.  So :func:`run_in_worker` runs
the loop in a worker thread (ctypes releases the GIL during a foreign call; a pythonfmu
FMU's Python code takes it back in turns) while the main thread only waits, in slices of
:data:`_SLICE` s, and watches the :class:`~orchestrator.pacing.InterruptFlag`:

- the loop checks the flag between steps (``flag.check()``) and ends with
  :class:`~fourbar_common.signals.Stopped` as before; the main thread re-raises whatever the
  worker raised, so the run ends as it always did;
- if the worker has not ended :data:`GRACE` s after the signal (a doStep that does not
  return), or at a second signal, the main thread calls ``take_over()`` (the run stops the
  worker from touching its files and frees nothing the worker still uses) and raises
  :class:`WorkerAbandoned`, a ``Stopped``: the run records ``interrupted`` and the command
  exits without waiting for the worker (``os._exit`` in the CLI: the thread is still inside
  the FMU's C code, and neither the FMU instance nor the interpreter can be torn down under it).

Measured by ``benchmarks/stop_latency.py``: the time from the signal to the exit.
"""
from __future__ import annotations

import threading
import time
from typing import Callable

from fourbar_common.signals import Stopped

from .pacing import InterruptFlag

__all__ = ["GRACE", "WorkerAbandoned", "run_in_worker"]

#: s: how long after a signal the worker may take to end its step before it is abandoned.
#: A doStep of the shipped FMUs at 0.01 s takes well under 10 ms on a normal case; 0.5 s
#: leaves room on a loaded machine and keeps the exit within 2 s of the signal.
GRACE = 0.5
_SLICE = 0.05   # s: longest single wait of the main thread, so a signal is seen quickly


class WorkerAbandoned(Stopped):
    """A stop signal came and the loop's worker thread did not end within :data:`GRACE` s
    (it is inside a foreign call).  The process must exit without freeing the FMU."""


def run_in_worker(loop: Callable[[], None], flag: InterruptFlag, take_over: Callable[[], None], *,
                  grace: float = GRACE, name: str = "fmu loop") -> None:
    """Run ``loop()`` in a daemon thread; return when it returns, re-raise what it raised.

    After a stop signal (``flag.requested``) the worker gets ``grace`` s to end (it sees the
    flag between steps); then, or at once on a second signal, ``take_over()`` is called in
    this thread and :class:`WorkerAbandoned` is raised while the worker may still run.
    """
    outcome: list[BaseException] = []

    def work() -> None:
        try:
            loop()
        except BaseException as exc:     # handed to the main thread, which decides
            outcome.append(exc)

    worker = threading.Thread(target=work, name=name, daemon=True)
    worker.start()
    deadline: float | None = None
    hurry = False
    while True:
        try:
            worker.join(_SLICE)
        except KeyboardInterrupt:        # a second signal (InterruptFlag raises on it): do not wait
            hurry = True
        if not worker.is_alive():
            break
        if flag.requested and deadline is None:
            deadline = time.monotonic() + grace
        if hurry or (deadline is not None and time.monotonic() >= deadline):
            take_over()
            raise WorkerAbandoned(flag.signum if flag.signum is not None else 2)
    if outcome:
        raise outcome[0]

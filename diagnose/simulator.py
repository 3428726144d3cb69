"""The model side of a diagnosis: the healthy trajectory and "what if this parameter changed here".

:class:`Simulator` runs the run's FMU once with the run's start values up to the end of
the diagnosis window, keeping the healthy outputs at every communication point of the
window.  :meth:`Simulator.branch` then answers "what would the outputs have been had
``name`` taken these values from grid point ``c`` on": the change is applied exactly as
the orchestrator applies a fault (``fmi2SetReal`` between two steps, so row ``c`` still
shows the old state and row ``c + 1`` the new one).

Two ways to start a branch at grid point ``c``:

``snapshot``     ``fmi2GetFMUstate`` at every grid point of the window during the healthy
                 pass, ``fmi2SetFMUstate`` to branch (the native FMU: a branch costs only
                 its own steps);
``resimulate``   ``fmi2Reset`` and a new run from the start with the healthy values up to
                 ``c`` (any FMI 2.0 FMU, e.g. the pythonfmu one, which cannot save its state;
                 much slower).

Grid point ``k`` is the time ``start + k*step`` (the orchestrator's grid).  Before the
window the FMU takes one-second communication steps (an FMU integrates each step to its
tolerance, so this changes the result by less than that tolerance and makes hour-long
runs cheap to replay).

A system run (``master`` given: run.json's ``system`` record) is replayed by the
orchestrator's :class:`~orchestrator.system.SystemInstance` with the run's master algorithm,
names ``component.variable``; it takes the run's macro step everywhere (the coupling error
depends on the macro step, so a longer one would not replay the run), and snapshots when
every component can save its state.

Every FMU call runs inside :func:`fourbar_common.signals.deferred`: Ctrl-C or SIGTERM is
raised between two calls (at the latest at the end of a branch), never inside a pythonfmu
FMU's own Python code, where it would make the FMU fail fatally and crash the process.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from fourbar_common.signals import checkpoint, deferred

__all__ = ["BranchFailed", "Grid", "Simulator"]

#: s: communication step used to reach the window (see the module docstring).
_FAST_STEP = 1.0


class BranchFailed(RuntimeError):
    """The FMU refused a branch (e.g. a length at which the linkage cannot be assembled)."""


@dataclass(frozen=True)
class Grid:
    """The run's communication points ``t_k = start + k*step``."""

    start: float
    step: float

    def time(self, k: int | np.ndarray) -> float | np.ndarray:
        return self.start + np.asarray(k) * self.step if isinstance(k, np.ndarray) else self.start + k * self.step

    def index(self, t: float) -> int:
        return int(round((t - self.start) / self.step))


class Simulator:
    """One FMU instance replaying a run between grid points ``first`` and ``last``.

    ``healthy`` holds the outputs ``columns`` at grid points ``first .. last`` (rows), with
    the run's ``parameters``.  Use as a context manager (the instance is freed on exit).
    """

    def __init__(self, description, parameters: Mapping[str, float], columns: Sequence[str], grid: Grid,
                 tolerance: float | None, first: int, last: int, method: str = "auto", master=None):
        if method not in ("auto", "snapshot", "resimulate"):
            raise ValueError(f"method: expected auto, snapshot or resimulate, got {method!r}")
        can_save = bool(getattr(description.model.coSimulation, "canGetAndSetFMUstate", False))
        if method == "snapshot" and not can_save:
            raise ValueError(f"{description.path.name} cannot save its state (canGetAndSetFMUstate is false)")
        self.method = ("snapshot" if can_save else "resimulate") if method == "auto" else method
        self.description = description
        self.master = master
        self.parameters = dict(parameters)
        self.columns = tuple(columns)
        self.grid = grid
        self.tolerance = tolerance
        self.first, self.last = int(first), int(last)
        if not 0 <= self.first < self.last:
            raise ValueError(f"window: expected 0 <= first < last, got {first}, {last}")
        self.healthy = np.empty((self.last - self.first + 1, len(self.columns)))
        self.branches = 0          # branches simulated (for the timing report)
        self._fmu = None
        self._states: list = []

    # -- life cycle ---------------------------------------------------------------------
    def __enter__(self) -> "Simulator":
        with deferred():
            self._fmu = self._instance().__enter__()
            try:
                self._read = self._fmu.reader(self.columns)
                self._initialise()
                self._healthy_pass()
            except BaseException:
                self.__exit__(None, None, None)
                raise
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        fmu, self._fmu = self._fmu, None
        if fmu is None:
            return
        with deferred():
            for state in self._states:
                try:
                    fmu.free_state(state)
                except Exception:    # freeing must not hide the diagnosis' own result
                    pass
            self._states = []
            fmu.__exit__(exc_type, exc, tb)

    # -- the FMU ------------------------------------------------------------------------
    def _instance(self):
        if self.master is not None:
            from orchestrator.system import SystemInstance

            return SystemInstance(self.description, self.master, "fourbar-diagnose")
        from orchestrator.instance import instance_for

        return instance_for(self.description, "fourbar-diagnose")

    def _initialise(self) -> None:
        fmu = self._fmu
        stop = self.grid.time(self.last)
        fmu.setup_experiment(self.grid.start, stop, self.tolerance)
        fmu.set_values(self.parameters.items())
        fmu.enter_initialization_mode()
        fmu.exit_initialization_mode()

    def _advance(self, k_from: int, k_to: int) -> None:
        """Healthy steps from grid point ``k_from`` to ``k_to`` in steps of about ``_FAST_STEP``."""
        per = 1 if self.master is not None else max(1, int(round(_FAST_STEP / self.grid.step)))
        k = k_from
        while k < k_to:
            checkpoint()
            k_next = min(k + per, k_to)
            t = self.grid.time(k)
            self._fmu.do_step(t, self.grid.time(k_next) - t)
            k = k_next

    def _times(self, k_from: int, k_to: int) -> list[float]:
        return [self.grid.time(k) for k in range(k_from, k_to + 1)]

    def _healthy_pass(self) -> None:
        self._advance(0, self.first)
        fmu = self._fmu
        self.healthy[0] = self._read()
        if self.method == "resimulate":
            fmu.step_through(self._times(self.first, self.last), self.columns, self.healthy[1:])
            return
        self._states.append(fmu.get_state())
        for k in range(self.first, self.last):
            checkpoint()
            fmu.step_through(self._times(k, k + 1), self.columns, self.healthy[k - self.first + 1:])
            self._states.append(fmu.get_state())

    def _restart_at(self, c: int) -> None:
        if self.method == "snapshot":
            self._fmu.set_state(self._states[c - self.first])
            return
        self._fmu.reset()
        self._initialise()
        self._advance(0, self.first)
        if c > self.first:
            self._fmu.step_through(self._times(self.first, c), (), np.empty((c - self.first, 0)))

    # -- branches -----------------------------------------------------------------------
    def branch(self, name: str, values: Sequence[float], start: int, until: int | None = None) -> np.ndarray:
        """Outputs at grid points ``start+1 .. until`` (default ``last``) when ``name`` is set
        to ``values[i]`` at grid point ``start + i`` (before that step; the last value then holds).

        ``values`` of length 1 is a step at ``start``.  Raises :class:`BranchFailed` with the
        FMU's message when the FMU cannot take the values.
        """
        from orchestrator.instance import FmuError

        until = self.last if until is None else int(until)
        if not self.first <= start < until <= self.last:
            raise ValueError(f"branch {start}..{until} outside the window {self.first}..{self.last}")
        self.branches += 1
        out = np.empty((until - start, len(self.columns)))
        values = [float(v) for v in np.atleast_1d(np.asarray(values, dtype=float))]
        with deferred():
            try:
                self._restart_at(start)
                self._fmu.step_through(self._times(start, until), self.columns, out, changes=(name, values))
            except FmuError as exc:
                if self.method == "resimulate":
                    self._fmu.reset()     # the next branch initialises again
                raise BranchFailed(str(exc)) from None
        return out

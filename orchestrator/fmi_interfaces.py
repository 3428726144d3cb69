"""What co-simulation and model exchange do differently for an
:class:`~orchestrator.fmi_instance.FmuInstance`.

Model exchange looks like co-simulation to the caller: :meth:`ModelExchange.do_step`
integrates the states with FMPy's CVode over the step (``fmi2CompletedIntegratorStep`` at its
end, as FMPy's ``simulate_fmu`` does, and an event iteration where the FMU asks for one), and
values set after initialisation are set in event mode, followed by the event iteration and a
restart of CVode at that time (a step or ramp fault is a discontinuity the solver must not
integrate across).
"""
from __future__ import annotations

from typing import Any, Iterable

from fourbar_common.formatting import format_time

from .fmi_instance import FmuError, FmuInstance

__all__ = ["CoSimulation", "ModelExchange"]


class CoSimulation(FmuInstance):
    """Co-simulation: the FMU steps with its own solver (``doStep``)."""

    FMI_TYPE = "CoSimulation"

    @staticmethod
    def _interface(md) -> Any:
        return md.coSimulation

    def do_step(self, t: float, h: float) -> None:
        """``DoStep(t, h)`` (the hot path: no work beyond the call unless it fails)."""
        mark = self._log_count
        try:
            result = self._fmu.doStep(t, h)
        except self._call_error as exc:
            raise self._failure(f"{self.PREFIX}DoStep(t = {format_time(t)} s, h = {format_time(h)} s)",
                                exc.status, mark) from None
        if self._ends_simulation(result):
            raise FmuError(self._describe(f"the FMU asked to end the simulation at t = {format_time(t + h)} s", mark))


class ModelExchange(FmuInstance):
    """Model exchange: FMPy's CVode integrates the FMU's states, events iterated at the FMU's request."""

    FMI_TYPE = "ModelExchange"
    _solver = None                       # FMPy's CVodeSolver, after initialisation
    _inputs: "_SolverInputs"             # what sets the driven inputs at CVode's evaluations

    @staticmethod
    def _interface(md) -> Any:
        return md.modelExchange

    def _initialized(self) -> None:
        self._event_iteration()
        self._start_solver()

    def do_step(self, t: float, h: float) -> None:
        """CVode over the step."""
        self._integrate(t, t + h)

    def set_values(self, values: Iterable[tuple[str, Any]]) -> None:
        """Set variables by name; after initialisation in event mode at the current time, then the
        event iteration and CVode restarted."""
        if self._solver is not None:
            self._call(f"{self.PREFIX}EnterEventMode", self._fmu.enterEventMode)
            self._set(values)
            self._event_iteration()
            self._solver.reset(self._time)
            return
        self._set(values)

    def _event_iteration(self) -> None:
        """``fmi2NewDiscreteStates`` until the FMU needs no more, then continuous-time mode."""
        while True:
            needed, terminate = self._update_discrete_states()[:2]
            if terminate:
                raise FmuError(self._describe(f"the FMU asked to end the simulation at t = "
                                              f"{format_time(self._time)} s", self._log_count - 3))
            if not needed:
                break
        self._call(f"{self.PREFIX}EnterContinuousTimeMode", self._fmu.enterContinuousTimeMode)

    def _start_solver(self) -> None:
        """FMPy's CVode on the FMU's states, from the current time (the case's tolerance, else FMPy's default)."""
        from fmpy.sundials import CVodeSolver

        md, fmu = self.md, self._fmu
        self._inputs = _SolverInputs(self)
        self._solver = CVodeSolver(
            nx=md.numberOfContinuousStates, nz=md.numberOfEventIndicators, get_x=fmu.getContinuousStates,
            set_x=fmu.setContinuousStates, get_dx=self._derivatives(), get_z=fmu.getEventIndicators,
            get_nominals=fmu.getNominalsOfContinuousStates, set_time=self._inputs.set_time, input=self._inputs,
            startTime=self._time, **({"relativeTolerance": self._tolerance} if self._tolerance else {}))

    def _integrate(self, t: float, t_end: float) -> None:
        """CVode from ``t`` to ``t_end`` (a state event stops it early: the event is handled, and on)."""
        mark = self._log_count
        try:
            while t < t_end:
                state_event, _roots, t = self._solver.step(t, t_end)
                self._inputs.check()
                self._fmu.setTime(t)
                self.set_inputs(t)       # CVode's last evaluation may lie past t (it interpolates back)
                step_event, terminate = self._fmu.completedIntegratorStep()
                if terminate:
                    raise FmuError(self._describe(f"the FMU asked to end the simulation at t = {format_time(t)} s",
                                                  mark))
                if state_event or step_event:
                    self._time = t
                    self._fmu.enterEventMode()
                    self._event_iteration()
                    self._solver.reset(t)
        except self._call_error as exc:
            raise self._failure(f"model exchange from t = {format_time(t)} s to {format_time(t_end)} s",
                                exc.status, mark) from None
        except FmuError:
            raise
        except Exception as exc:             # CVode's own failure (fmpy.sundials raises RuntimeError or Exception)
            self._failed_status = 3
            raise FmuError(self._describe(f"CVode failed between t = {format_time(t)} s and "
                                          f"{format_time(t_end)} s ({exc})", mark), 3) from None
        self._time = t_end


class _SolverInputs:
    """The driven inputs (:meth:`~orchestrator.fmi_instance.FmuInstance.drive_inputs`) set to their
    values at every time CVode evaluates the model: FMPy's CVodeSolver calls ``set_time`` before
    each evaluation of the derivatives and of the event indicators (its ``input.apply`` only
    before the latter).  A failure inside CVode's callback cannot raise through the C solver:
    it is kept and raised by :meth:`check` after the solver's step."""

    def __init__(self, instance: FmuInstance):
        self._instance = instance
        self._error: BaseException | None = None

    def set_time(self, time: float) -> None:
        if self._error is not None:
            return
        self._instance._fmu.setTime(time)
        try:
            self._instance.set_inputs(time)
        except Exception as exc:        # raised again by check(), outside the C solver
            self._error = exc

    def apply(self, time, continuous=True, discrete=True, after_event=False) -> None:
        return None                     # set_time has set them

    def check(self) -> None:
        error, self._error = self._error, None
        if error is not None:
            raise error

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
        self._solver = CVodeSolver(
            nx=md.numberOfContinuousStates, nz=md.numberOfEventIndicators, get_x=fmu.getContinuousStates,
            set_x=fmu.setContinuousStates, get_dx=self._derivatives(), get_z=fmu.getEventIndicators,
            get_nominals=fmu.getNominalsOfContinuousStates, set_time=fmu.setTime, input=_NoInputs(),
            startTime=self._time, **({"relativeTolerance": self._tolerance} if self._tolerance else {}))

    def _integrate(self, t: float, t_end: float) -> None:
        """CVode from ``t`` to ``t_end`` (a state event stops it early: the event is handled, and on)."""
        mark = self._log_count
        try:
            while t < t_end:
                state_event, _roots, t = self._solver.step(t, t_end)
                self._fmu.setTime(t)
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


class _NoInputs:
    """FMPy's CVodeSolver applies the inputs at every evaluation; the orchestrator sets none."""

    def apply(self, time, continuous=True, discrete=True, after_event=False) -> None:
        return None

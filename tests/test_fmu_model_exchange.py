"""The native FMUs' FMI 2.0 Model Exchange, in two hosts: FMPy with CVode, and a host of this
module that integrates the FMU's derivatives with scipy's DOP853 and applies a fault at an event.

Model Exchange leaves the integration to the host: the continuous states are the file's
independent coordinates, their rates and the drivers' work, and every other coordinate comes
from the constraints at each evaluation (coordinate partitioning), so the constraints hold to
round-off whatever the host's solver, while the accuracy is the solver's.
"""
from __future__ import annotations

import ctypes

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Model
from scipy.integrate import DOP853

from fmu_src import fmi_hosts   # the hosts' runners: one home
from support import (COSIM_TOL, CVODE_RTOL, FLAVOUR_AGREE, RESIDUAL, flavour_span,
                     fmucheck_or_skip, fmusim_or_skip, lengths_and_angles, swept_mechanisms)


MECHANISMS = swept_mechanisms()   # support.BENCHMARK_MECHANISMS: tested in their own files


@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_model_exchange_in_fmpy_agrees_with_co_simulation(mechanism, mechanism_fmus):
    fmu = str(mechanism_fmus.get(mechanism, "native"))
    names = lengths_and_angles(fmu)
    stop = flavour_span(mechanism)
    cs = simulate_fmu(fmu, fmi_type="CoSimulation", stop_time=stop, output_interval=0.01,
                      start_values={"rtol": COSIM_TOL, "atol": COSIM_TOL}, output=names)
    me = simulate_fmu(fmu, fmi_type="ModelExchange", solver="CVode", relative_tolerance=CVODE_RTOL, stop_time=stop,
                      output_interval=0.01, output=names + ["constraint_residual"])
    assert np.array_equal(cs["time"], me["time"])
    worst = max(float(np.max(np.abs(cs[n] - me[n]))) for n in names)
    assert worst <= FLAVOUR_AGREE, (mechanism, worst)
    assert float(np.max(me["constraint_residual"])) <= RESIDUAL


@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_constraints_hold_at_the_hosts_default_tolerance(mechanism, mechanism_fmus):
    """FMPy's CVode at its default rtol (1e-4 here): the motion is the solver's, the loops still close."""
    fmu = str(mechanism_fmus.get(mechanism, "native"))
    me = simulate_fmu(fmu, fmi_type="ModelExchange", solver="CVode", stop_time=10.0, output_interval=0.01,
                      output=["constraint_residual"])
    assert len(me) == 1001 and float(np.max(me["constraint_residual"])) <= RESIDUAL


@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_model_exchange_in_fmusim_agrees_with_co_simulation(mechanism, mechanism_fmus, tmp_path):
    """fmusim (the Reference-FMUs' host) integrating with its own CVode; skipped without fmusim
    ($FMUSIM or PATH; scripts/build_fmusim.sh builds it)."""
    fmusim = fmusim_or_skip()
    fmu = mechanism_fmus.get(mechanism, "native")
    names = tuple(lengths_and_angles(fmu))
    stop = flavour_span(mechanism)
    run = fmi_hosts.run_fmusim(fmusim, fmu, names, fmi_hosts.Experiment(stop=stop), tmp_path,
                               model_exchange_tolerance=CVODE_RTOL)
    assert run.exit_code == 0 and run.values is not None, run.message
    cs = simulate_fmu(str(fmu), stop_time=stop, output_interval=0.01, output=list(names),
                      start_values={"rtol": COSIM_TOL, "atol": COSIM_TOL})
    assert run.values.shape == (len(cs), len(names))
    assert np.allclose(run.time, cs["time"], rtol=0, atol=1e-12)
    worst = max(float(np.max(np.abs(run.values[:, k] - cs[n]))) for k, n in enumerate(names))
    assert worst <= FLAVOUR_AGREE, (mechanism, worst)


@pytest.mark.parametrize("mechanism", ["fourbar", "fourbar_driven"])
def test_the_compliance_checker_finds_nothing_and_runs_model_exchange(mechanism, mechanism_fmus, tmp_path):
    """fmuCheck -k me: the model description and the model-exchange calls raise no warning or
    error (it refused the FMU's ModelExchange element when it came after CoSimulation, as FMI
    2.0's schema orders them); its forward Euler (1e-5 s) follows co-simulation at 1e-12 within
    1e-3 m over 1 s: Euler's O(h) error plus the reference's linear interpolation between its
    0.01 s rows (its rows fall at the Euler steps), measured 1.2e-4 m on the four-bar."""
    fmu = mechanism_fmus.get(mechanism, "native")
    names = tuple(n for n in lengths_and_angles(fmu) if n[:1] in "xy")[:6]
    checked = fmi_hosts.run_fmucheck(fmucheck_or_skip(), fmu, names, stop=1.0, step=1e-5, points=101, workdir=tmp_path)
    assert checked.checker_errors == 0 and checked.checker_warnings == 0, checked.log[-3000:]
    run = checked.run
    assert run.values is not None and len(run.time) >= 100, run.message
    cs = simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.01, output=list(names),
                      start_values={"rtol": 1e-12, "atol": 1e-12})
    worst = max(float(np.max(np.abs(np.interp(run.time, cs["time"], cs[n]) - run.values[:, k])))
                for k, n in enumerate(names))
    assert worst <= 1e-3, (mechanism, worst)


class _Host:
    """A Model Exchange host: scipy's DOP853 on the FMU's derivatives, fmi2CompletedIntegratorStep
    after every accepted step, the outputs read at the grid points from the dense output."""

    def __init__(self, fmu: str, tmp):
        self.md = read_model_description(fmu)
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        self.nx = len(self.md.derivatives)
        self.model = FMU2Model(guid=self.md.guid, unzipDirectory=extract(fmu, unzipdir=str(tmp)),
                               modelIdentifier=self.md.modelExchange.modelIdentifier, instanceName="me")
        self.model.instantiate()
        self.model.setupExperiment(startTime=0.0)
        self.model.enterInitializationMode()
        self.model.exitInitializationMode()
        self._event()

    def _pointer(self, a: np.ndarray):
        return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))

    def _event(self) -> None:
        changed = self.model.newDiscreteStates()[3]
        assert changed is False                     # valuesOfContinuousStatesChanged: the states are kept
        self.model.enterContinuousTimeMode()

    def states(self) -> np.ndarray:
        x = np.zeros(self.nx)
        self.model.getContinuousStates(self._pointer(x), self.nx)
        return x

    def _set(self, t: float, x: np.ndarray) -> None:
        self.model.setTime(t)
        x = np.ascontiguousarray(x, dtype=float)
        self.model.setContinuousStates(self._pointer(x), self.nx)

    def derivatives(self, t: float, x: np.ndarray) -> np.ndarray:
        self._set(t, x)
        dx = np.zeros(self.nx)
        self.model.getDerivatives(self._pointer(dx), self.nx)
        return dx

    def run(self, t0: float, t1: float, times: np.ndarray, names: list[str], tol: float) -> list[list[float]]:
        """Integrate from t0 to t1; the outputs at ``times`` (within [t0, t1])."""
        solver = DOP853(self.derivatives, t0, self.states(), t1, rtol=tol, atol=tol)
        rows, k = [], 0
        refs = [self.vr[n] for n in names]
        pending = list(times)
        while True:
            t_prev = solver.t
            if solver.status == "running":
                solver.step()
                assert solver.status != "failed", solver
            dense = solver.dense_output() if solver.t > t_prev else None
            while k < len(pending) and (pending[k] <= solver.t or solver.status == "finished"):
                self._set(pending[k], dense(pending[k]) if dense is not None and pending[k] != solver.t
                          else solver.y)
                rows.append(self.model.getReal(refs))
                k += 1
            self._set(solver.t, solver.y)
            self.model.completedIntegratorStep()
            if solver.status == "finished":
                return rows

    def change(self, t: float, name: str, value: float) -> None:
        self.model.enterEventMode()
        self.model.setTime(t)
        self.model.setReal([self.vr[name]], [value])
        self._event()

    def close(self) -> None:
        self.model.terminate()
        self.model.freeInstance()


def test_a_fault_at_an_event_in_a_scipy_host_matches_co_simulation(native_fmu, tmp_path):
    """The paper's Case 2 (L2 1.0 -> 1.1 m at 10 s) in Model Exchange: the host integrates to the
    fault, sets L2 in event mode, fmi2NewDiscreteStates re-assembles the linkage keeping the
    crank's angle and rate, and the run goes on; against co-simulation's Case 2, both at 1e-12."""
    names = ["x2", "y2", "x3", "y3", "x4", "y4", "L2"]
    grid = np.round(np.arange(0.0, 16.0 + 1e-9, 0.01), 10)
    host = _Host(str(native_fmu), tmp_path)
    try:
        rows = host.run(0.0, 10.0, grid[grid <= 10.0], names, 1e-12)      # the row at 10 s: before the fault
        host.change(10.0, "L2", 1.1)
        rows += host.run(10.0, 16.0, grid[grid > 10.0], names, 1e-12)
    finally:
        host.close()
    me, cs = np.array(rows), _cosim_case2(str(native_fmu), names)
    assert me.shape == cs.shape == (1601, len(names))
    assert np.array_equal(me[:, -1] == 1.1, grid > 10.0)                # L2 read back: the fault after 10 s
    worst = float(np.max(np.abs(me[:, :-1] - cs[:, :-1])))
    assert worst <= FLAVOUR_AGREE, worst


def _cosim_case2(fmu: str, names: list[str]) -> np.ndarray:
    """Case 2 in co-simulation at rtol = atol = 1e-12: L2 set to 1.1 before the step from 10 s."""
    from fmpy.fmi2 import FMU2Slave
    md = read_model_description(fmu)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(fmu), modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="cs")
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.setReal([vr["rtol"], vr["atol"]], [1e-12, 1e-12])
    slave.exitInitializationMode()
    rows = []
    refs = [vr[n] for n in names]
    for k in range(1601):
        t = round(k * 0.01, 10)
        rows.append(slave.getReal(refs))
        if k == 1600:
            break
        if k == 1000:
            slave.setReal([vr["L2"]], [1.1])
        slave.doStep(t, 0.01)
    slave.terminate()
    slave.freeInstance()
    return np.array(rows)

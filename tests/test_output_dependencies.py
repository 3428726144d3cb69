"""Mechanism FMUs' output dependencies (issue 40; docs/mechanisms.md, *Model structure*): each
output and each state derivative in ``<ModelStructure>`` lists the states and inputs it depends
on (``fmu_src.mechanism.table.output_dependencies``, ``derivative_dependencies``), so that a
master can tell which outputs feed an input straight through.

- Checked against the FMU itself: in model exchange, at a fixed state, each input is moved
  alone; an output or derivative declared independent of it must not move, one declared
  dependent must (tests/mechanisms/input_pendulum.toml: four inputs that act like loads;
  tests/mechanisms/input_driven_crank.toml: a driver input, which moves the positions).
- ``fmpy validate`` finds nothing in the three FMUs (pythonfmu, native FMI 2.0 and 3.0).
- ``orchestrator.system_order.gauss_seidel_order`` breaks a loop at the mechanism: on a small test
  .ssp of two pendulums (tests/ssp_testing.py) and on the shipped bench (systems/motor_fourbar.toml).

FMUs come from the session's ``mechanism_fmus`` (built once, shared with tests/test_fmu_inputs.py).
"""
from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Model
from fmpy.fmi3 import FMU3Model
from fmpy.validation import validate_fmu

from fmu_src.mechanism.check import prepare_mechanism
from fmu_src.mechanism.table import derivative_dependencies, output_dependencies
from orchestrator.system_order import gauss_seidel_order
from orchestrator.system_description import describe_system
from ssp_testing import TestComponent, write_ssp
from support import REPO

PENDULUM = str(REPO / "tests" / "mechanisms" / "input_pendulum.toml")
CRANK = str(REPO / "tests" / "mechanisms" / "input_driven_crank.toml")

#: An unknown declared independent of an input is computed without reading it, from the same
#: state: the same number, but for the dependent coordinates' Newton iteration, which starts
#: from the last solution (it converges to ~1e-14; relative, plus an absolute 1e-12 for zeros).
SAME = 1e-10
#: An unknown declared dependent moves by at least this much (relative to 1 + |value|) when the
#: input moves by DELTA: the inputs enter linearly (loads) or through the positions (a driver),
#: with factors of order 0.1-10 here; 1e-6 is far above the iteration's noise and far below them.
MOVES = 1e-6
DELTA = 0.5


class _Model:
    """A native FMU in model exchange (FMI 2.0 or 3.0) in continuous-time mode: inputs and
    states set, outputs and derivatives read."""

    def __init__(self, fmu: Path, tmp: Path):
        md = read_model_description(str(fmu))
        self.md = md
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.n = sum(1 for v in md.modelVariables if v.derivative is not None)
        unzip = extract(str(fmu), unzipdir=str(tmp))
        self.fmi3 = md.fmiVersion.startswith("3")
        if self.fmi3:
            self.fmu = FMU3Model(guid=md.instantiationToken, unzipDirectory=unzip,
                                 modelIdentifier=md.modelExchange.modelIdentifier, instanceName="deps")
            self.fmu.instantiate()
            self.fmu.enterInitializationMode(startTime=0.0)
        else:
            self.fmu = FMU2Model(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.modelExchange.modelIdentifier,
                                 instanceName="deps")
            self.fmu.instantiate()
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        if not self.fmi3:
            self.fmu.newDiscreteStates()
        self.fmu.enterContinuousTimeMode()

    def set(self, values: dict[str, float]) -> None:
        (self.fmu.setFloat64 if self.fmi3 else self.fmu.setReal)([self.vr[n] for n in values], list(values.values()))

    def get(self, names) -> np.ndarray:
        return np.array((self.fmu.getFloat64 if self.fmi3 else self.fmu.getReal)([self.vr[n] for n in names]))

    def states(self) -> np.ndarray:
        x = (ctypes.c_double * self.n)()
        self.fmu.getContinuousStates(x, self.n)
        return np.array(x[:])

    def at(self, x: np.ndarray, inputs: dict[str, float], names) -> np.ndarray:
        """``names``' values with the inputs set, then the state ``x``."""
        self.set(inputs)
        if self.n:
            self.fmu.setContinuousStates((ctypes.c_double * self.n)(*x), self.n)
        return self.get(names)

    def close(self) -> None:
        self.fmu.terminate()
        self.fmu.freeInstance()


def _declared(md) -> dict[str, set[str]]:
    """Each output's and derivative's declared knowns, by name (None: every known)."""
    unknowns = list(md.outputs) + list(md.derivatives)
    return {u.variable.name: None if u.dependencies is None else {d.name for d in u.dependencies} for u in unknowns}


def _moved_by_each_input(fmu: Path, tmp: Path, base: dict[str, float], rates: dict[str, float]):
    """Per input, the unknowns (outputs and derivatives) that move when the input alone moves
    by DELTA, in model exchange at a fixed state (the start with ``rates`` added): (declared,
    moved, held) name sets: each unknown either moved (by more than MOVES) or held (within SAME)."""
    model = _Model(fmu, tmp)
    try:
        declared = _declared(model.md)
        names = sorted(declared)
        x = model.states()
        for name, rate in rates.items():          # a moving state: the velocity terms count too
            index = [v.name for v in model.md.modelVariables if v.derivative is not None].index(f"der({name})")
            x[index] += rate
        inputs = [v.name for v in model.md.modelVariables if v.causality == "input"]
        found = {}
        for u in inputs:
            before = model.at(x, base, names)
            after = model.at(x, {**base, u: base[u] + DELTA}, names)
            again = model.at(x, base, names)
            noise = np.abs(again - before)            # the iteration's own: must be far below both limits
            assert np.all(noise <= SAME * (1 + np.abs(before)) + 1e-12), f"{u}: not repeatable"
            change = np.abs(after - before)
            moved = {n for n, c, b in zip(names, change, before) if c > MOVES * (1 + abs(b))}
            held = {n for n, c, b in zip(names, change, before) if c <= SAME * (1 + abs(b)) + 1e-12}
            assert moved | held == set(names), f"{u}: neither held nor moved: {sorted(set(names) - moved - held)}"
            found[u] = ({n for n in names if declared[n] is None or u in declared[n]}, moved, held)
        return found
    finally:
        model.close()


PENDULUM_INPUTS = {"F_P": 1.5, "tau_A": -0.7, "tau_arm": 0.4, "push": 2.0}
PENDULUM_RATES = {"vx1": 0.3, "omega2": -0.8, "omega3": 1.1}


@pytest.mark.parametrize("kind", ["native", pytest.param("native3", marks=pytest.mark.slow)])
def test_pendulum_outputs_move_with_exactly_the_inputs_they_declare(mechanism_fmus, tmp_path, kind):
    fmu = mechanism_fmus.get(PENDULUM, kind)
    found = _moved_by_each_input(fmu, tmp_path, PENDULUM_INPUTS, PENDULUM_RATES)
    assert set(found) == set(PENDULUM_INPUTS)
    for u, (declared, moved, held) in found.items():
        assert moved == declared, f"{u}: declared {sorted(declared)}, moved {sorted(moved)}"
    # the point of it: the states' functions do not feed an input through, the forces do
    assert "omega2" not in found["tau_A"][0] and "O_Fx" in found["tau_A"][0]
    assert "der(omega2)" in found["tau_A"][0] and "der(theta2)" not in found["tau_A"][0]


@pytest.mark.slow
def test_driver_input_moves_the_positions_its_rate_only_the_velocities(mechanism_fmus, tmp_path):
    """A driver input (kind = "position"): its position moves the positions, its rate the
    velocities (not the positions), its acceleration only what needs the multipliers; nothing
    moves that does not declare it."""
    fmu = mechanism_fmus.get(CRANK, "native")
    base = {"crank": 0.6, "crank_d": 1.2, "crank_dd": -0.5}
    found = _moved_by_each_input(fmu, tmp_path, base, {})
    for u, (declared, moved, held) in found.items():
        # at most the declared: the derivation's reading is by symbols, so a few declared ones
        # hold still here (O2_x, the crank's pivot on the ground; omega2, which is crank_d)
        assert moved <= declared, f"{u}: moved but not declared: {sorted(moved - declared)}"
    assert {"theta3", "omega3", "crank_torque"} <= found["crank"][0]
    assert "omega3" in found["crank_d"][0] and "theta3" not in found["crank_d"][0]
    assert "crank_torque" in found["crank_dd"][0] and "omega3" not in found["crank_dd"][0]


def test_declared_dependencies_follow_the_derivation():
    """From the output kinds (no FMU): the bench's four-bar's speed does not feed its torque
    input through, its reactions and the input's power do; the work outputs are their states."""
    eqs = prepare_mechanism("fourbar_motor").equations
    outputs = {d.unknown: d for d in output_dependencies(eqs)}
    assert outputs["omega2"].inputs == () and outputs["omega2"].states == ("theta2", "omega2")
    assert outputs["theta3"].inputs == () and outputs["theta3"].states == ("theta2",)
    assert outputs["O2_Fx"].inputs == ("crank_torque",)
    assert outputs["crank_torque_power"].inputs == ("crank_torque",)
    assert outputs["crank_torque_work"].states == ("crank_torque_work",) and outputs["crank_torque_work"].inputs == ()
    derivatives = {d.unknown: d for d in derivative_dependencies(eqs)}
    assert derivatives["der(theta2)"].states == ("omega2",) and derivatives["der(theta2)"].constant
    assert derivatives["der(omega2)"].inputs == ("crank_torque",)
    assert derivatives["der(dissipated)"].inputs == ()


@pytest.mark.parametrize("kind", ["native", pytest.param("native3", marks=pytest.mark.slow),
                                  pytest.param("pythonfmu", marks=pytest.mark.slow)])
def test_fmpy_validate_finds_nothing_and_every_output_lists_its_dependencies(mechanism_fmus, kind):
    fmu = mechanism_fmus.get(PENDULUM, kind)
    assert validate_fmu(str(fmu)) == []
    md = read_model_description(str(fmu))
    declared = _declared(md)
    assert all(d is not None for d in declared.values())
    eqs = prepare_mechanism(PENDULUM).equations
    for dep in output_dependencies(eqs):
        # a co-simulation-only FMU (pythonfmu) has no states to list: the inputs alone
        expected = set(dep.inputs) if kind == "pythonfmu" else set(dep.inputs) | set(dep.states)
        assert declared[dep.unknown] == expected, dep.unknown


def test_gauss_seidel_breaks_a_loop_at_the_output_that_does_not_feed_through(mechanism_fmus, tmp_path):
    """Two pendulums in a loop: a's reaction O_Fx (through the multipliers: feeds its inputs
    through) pushes b, b's speed omega2 (a state's function) turns a.  Both are fed, so
    Gauss-Seidel starts with the one whose connected output does not feed through: b, though
    a comes first in the file (with no dependency lists, every output fed through: a first)."""
    fmu = mechanism_fmus.get(PENDULUM, "native")
    ssp = write_ssp(tmp_path / "loop.ssp", "Loop",
                    [TestComponent("a", fmu, inputs=("tau_arm",), outputs=("O_Fx",)),
                     TestComponent("b", fmu, inputs=("F_P",), outputs=("omega2",))],
                    [("a.O_Fx", "b.F_P"), ("b.omega2", "a.tau_arm")])
    system = describe_system(ssp)
    assert not system.component("b").direct_inputs("omega2")
    assert system.component("a").direct_inputs("O_Fx")
    assert gauss_seidel_order(system) == ("b", "a")


@pytest.mark.slow
def test_gauss_seidel_steps_the_bench_from_the_mechanism(bench_ssp):
    """The shipped bench: every component feeds its inputs through but the four-bar (its speed
    is a state's), so Gauss-Seidel steps the four-bar first, then along the connections."""
    order = gauss_seidel_order(describe_system(bench_ssp))
    # the loop (controller, motor, fourbar, sensor; the controller first in the file) is broken at
    # the four-bar, then followed along the connections: the sensor reads the crank's speed, the
    # controller the sensor, the motor the controller's voltage (the speed profile, which has no
    # input, may come anywhere before the controller)
    assert order.index("fourbar") < order.index("sensor") < order.index("controller") < order.index("motor"), order
    assert order.index("profile") < order.index("controller"), order

"""Model Exchange's directional derivatives (issue 26): every native FMU, FMI 2.0 and 3.0, gives
the derivatives of its states' derivatives and of its outputs along any direction of the states
(fmi2GetDirectionalDerivative, fmi3GetDirectionalDerivative), exact from the generated
derivatives of the equations (dae.c: dae_directional).

They are checked against an independent estimate: central finite differences of the same FMU's
derivatives and outputs (fmi2GetDerivatives, fmi2GetReal after fmi2SetContinuousStates), with
Richardson extrapolation, at a state away from the start (rates not zero, so the terms in the
rates count), along every state's unit vector and along a mixed direction (linearity).
"""
from __future__ import annotations

import ctypes
import sys
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass

import numpy as np
import pytest
from fmpy import extract, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Model
from fmpy.fmi3 import FMU3Model, FMU3Slave
from support import swept_mechanisms

MECHANISMS = swept_mechanisms()   # support.BENCHMARK_MECHANISMS: tested in their own files

#: Finite-difference step of the states (rad, m, rad/s, m/s, J): central differences with h and
#: h/2, Richardson-extrapolated, leave a truncation error ~ h^4 (1e-20) and a round-off error
#: ~ 1e-16 |f| / h = 1e-11 |f|, amplified a little by the extrapolation.
STEP = 1e-5
#: |exact - finite differences| / max(1, |value|): measured at most 3.5e-9 (the five-bar's joint
#: forces, whose round-off the Newton-Raphson tolerance of the dependent coordinates, ~1e-16 m,
#: lifts); a term left out (e.g. d(Phi_q qd)/dq, of the size of the rates squared, or the
#: multipliers' change in a force output) is off by 1e-2 or more.
AGREE = 1e-7
#: The state the derivatives are taken at: the start, each coordinate moved by POSITION_SHIFT
#: (rad or m) and each rate set to RATES (rad/s or m/s), scaled by the state's place (1, 2, ...),
#: so that no two states have the same value and no rate is zero.
POSITION_SHIFT, RATES = 0.05, 0.7


@dataclass(frozen=True)
class _Variables:
    states: list[int]          # value references, in the FMU's state order
    derivatives: list[int]
    outputs: list[int]
    names: list[str]           # of derivatives + outputs (messages)
    n_coordinates: int         # states that are coordinates (then as many rates, then the drivers' work)


def _variables(md) -> _Variables:
    derivatives = [v for v in md.modelVariables if v.derivative is not None]
    outputs = [v for v in md.modelVariables if v.causality == "output"]
    # a coordinate's derivative depends on its rate only (<ModelStructure>); a rate's and a
    # driver's power on every state
    n_coordinates = sum(1 for u in md.derivatives if u.dependencies is not None and len(u.dependencies) == 1)
    return _Variables([d.derivative.valueReference for d in derivatives], [d.valueReference for d in derivatives],
                      [o.valueReference for o in outputs], [d.name for d in derivatives] + [o.name for o in outputs],
                      n_coordinates)


class _Host:
    """One native FMU in model exchange through FMPy (FMI 2.0 or 3.0), after initialization, in
    continuous-time mode: states in, derivatives, outputs and directional derivatives out."""

    def __init__(self, fmu, tmp_path):
        md = read_model_description(str(fmu))
        self.v = _variables(md)
        self.n = len(self.v.states)
        unzip = extract(str(fmu), unzipdir=str(tmp_path))
        self.fmi3 = md.fmiVersion.startswith("3")
        if self.fmi3:
            self.fmu = FMU3Model(guid=md.instantiationToken, unzipDirectory=unzip,
                                 modelIdentifier=md.modelExchange.modelIdentifier, instanceName="dd")
            self.fmu.instantiate()
            self.fmu.enterInitializationMode(startTime=0.0)
        else:
            self.fmu = FMU2Model(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.modelExchange.modelIdentifier,
                                 instanceName="dd")
            self.fmu.instantiate()
            self.fmu.setupExperiment(startTime=0.0)
            self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        if not self.fmi3:
            self.fmu.newDiscreteStates()
        self.fmu.enterContinuousTimeMode()
        self.fmu.setTime(0.5)

    def states(self) -> np.ndarray:
        x = (ctypes.c_double * self.n)()
        self.fmu.getContinuousStates(x, self.n)
        return np.array(x[:])

    def evaluate(self, x: np.ndarray) -> np.ndarray:
        """The derivatives, then the outputs, at the states x."""
        self.fmu.setContinuousStates((ctypes.c_double * self.n)(*x), self.n)
        dx = (ctypes.c_double * self.n)()
        if self.fmi3:
            self.fmu.getContinuousStateDerivatives(dx, self.n)
            out = self.fmu.getFloat64(self.v.outputs)
        else:
            self.fmu.getDerivatives(dx, self.n)
            out = self.fmu.getReal(self.v.outputs)
        return np.concatenate([dx[:], out])

    def directional(self, x: np.ndarray, direction: np.ndarray, unknowns=None, knowns=None) -> np.ndarray:
        self.evaluate(x)
        unknowns = self.v.derivatives + self.v.outputs if unknowns is None else unknowns
        knowns = self.v.states if knowns is None else knowns
        if self.fmi3:
            return np.array(self.fmu.getDirectionalDerivative(unknowns, knowns, list(direction), len(unknowns)))
        return np.array(self.fmu.getDirectionalDerivative(unknowns, knowns, list(direction)))

    def finite_differences(self, x: np.ndarray, direction: np.ndarray) -> np.ndarray:
        def central(h):
            return (self.evaluate(x + h * direction) - self.evaluate(x - h * direction)) / (2 * h)
        return (4 * central(STEP / 2) - central(STEP)) / 3

    def close(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


def _away_from_start(host: _Host) -> np.ndarray:
    x = host.states()
    k = host.v.n_coordinates
    place = np.arange(1, host.n + 1)
    x[:k] += POSITION_SHIFT * place[:k]
    x[k:2 * k] = RATES * place[k:2 * k]
    # as a host's integrator gets there: an accepted step (the predictor of the dependent
    # coordinates starts from it; a jump of the states far from the last accepted step may land a
    # dependent angle on another turn, the same configuration)
    host.evaluate(x)
    host.fmu.completedIntegratorStep()
    return x


@pytest.fixture(params=["native", "native3"], ids=["fmi2", "fmi3"])
def flavour(request):
    return request.param


@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_directional_derivatives_match_finite_differences(mechanism, flavour, mechanism_fmus, tmp_path):
    if not sys.platform.startswith("linux"):
        pytest.skip("FMPy loads the platform's binary; measured on x86_64-linux")
    host = _Host(mechanism_fmus.get(mechanism, flavour), tmp_path)
    try:
        x = _away_from_start(host)
        rng = np.random.default_rng(7)
        directions = list(np.eye(host.n)) + [rng.uniform(-1.0, 1.0, host.n)]
        for direction in directions:
            exact = host.directional(x, direction)
            estimate = host.finite_differences(x, direction)
            error = np.abs(exact - estimate) / np.maximum(1.0, np.abs(estimate))
            worst = int(np.argmax(error))
            assert error[worst] <= AGREE, (mechanism, list(direction), host.v.names[worst], exact[worst],
                                           estimate[worst])
        # linear in the direction: the mixed direction is the sum of the unit ones
        columns = np.array([host.directional(x, e) for e in np.eye(host.n)]).T
        mixed = directions[-1]
        assert np.allclose(host.directional(x, mixed), columns @ mixed, rtol=1e-12, atol=1e-12)
    finally:
        host.close()


def test_what_is_not_a_directional_derivative_is_refused_with_a_message(mechanism_fmus, tmp_path, capsys):
    """A known that is not a state (a parameter), an unknown that is neither a derivative nor an
    output: fmi2Error naming the variable, and the instance goes on; co-simulation refuses."""
    fmu = mechanism_fmus.get("fourbar", "native")
    host = _Host(fmu, tmp_path / "me")
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    try:
        x = _away_from_start(host)
        with pytest.raises(FMICallException):
            host.directional(x, [1.0], knowns=[vr["L2"]], unknowns=[vr["x2"]])
        assert "L2 is not a continuous state" in capsys.readouterr().out
        with pytest.raises(FMICallException):
            host.directional(x, [1.0], knowns=[vr["theta2"]], unknowns=[vr["L2"]])
        assert "L2 is neither a state's derivative nor an output" in capsys.readouterr().out
        # still usable: the same call with a state and an output works
        assert np.isfinite(host.directional(x, [1.0], knowns=[vr["theta2"]], unknowns=[vr["x2"]])).all()
    finally:
        host.close()


def test_fmi3_co_simulation_refuses_with_a_message(mechanism_fmus, tmp_path, capsys):
    fmu = mechanism_fmus.get("fourbar", "native3")
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzip = extract(str(fmu), unzipdir=str(tmp_path))
    cs = FMU3Slave(guid=md.instantiationToken, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                   instanceName="cs")
    cs.instantiate()
    try:
        cs.enterInitializationMode(startTime=0.0)
        cs.exitInitializationMode()
        with pytest.raises(FMICallException):
            cs.getDirectionalDerivative([vr["x2"]], [vr["theta2"]], [1.0], 1)
        assert "not provided (in co-simulation" in capsys.readouterr().out
    finally:
        cs.terminate()
        cs.freeInstance()


@pytest.mark.parametrize("flavour", ["native", "native3"], ids=["fmi2", "fmi3"])
def test_in_initialization_mode_they_are_those_of_the_start(flavour, mechanism_fmus, tmp_path):
    """FMI 2.0 and 3.0 allow the call in initialization mode, where the knowns are the
    initialization's: the states' start parameters (theta2_start, omega2_start), and the states
    are initial unknowns.  The derivatives are those at the state the start values give: the
    numbers right after the initialization.  A call that fails there (a start value that
    cannot be assembled) leaves the instance in initialization mode, where the host corrects it."""
    fmu = mechanism_fmus.get("fourbar", flavour)
    md = read_model_description(str(fmu))
    v = _variables(md)
    vr = {x.name: x.valueReference for x in md.modelVariables}
    states = [x.name for x in md.modelVariables if x.valueReference in v.states]
    starts = [vr[f"{name}_start"] for name in states]
    unknowns, seed = v.derivatives + v.outputs, [1.0] * len(v.states)
    unzip = extract(str(fmu), unzipdir=str(tmp_path))
    fmi3 = flavour == "native3"
    if fmi3:
        fmu = FMU3Model(guid=md.instantiationToken, unzipDirectory=unzip,
                        modelIdentifier=md.modelExchange.modelIdentifier, instanceName="me")
        derivative = lambda u, k, s: fmu.getDirectionalDerivative(u, k, s, len(u))      # noqa: E731
        set_real = fmu.setFloat64
    else:
        fmu = FMU2Model(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.modelExchange.modelIdentifier,
                        instanceName="me")
        derivative, set_real = fmu.getDirectionalDerivative, fmu.setReal
    fmu.instantiate()
    try:
        if fmi3:
            fmu.enterInitializationMode(startTime=0.0)
        else:
            fmu.setupExperiment(startTime=0.0)
            fmu.enterInitializationMode()
        # L2 = 10 m cannot close the loop (the crank tip at 30 deg is 7.55 m from the rocker pivot,
        # the coupler and rocker reach 6.5 m): refused, the instance still initializing
        set_real([vr["L2"]], [10.0])
        with pytest.raises(FMICallException):
            derivative(unknowns, starts, seed)
        set_real([vr["L2"]], [1.0])
        during = np.array(derivative(unknowns, starts, seed))
        by_states = np.array(derivative(unknowns, v.states, seed))
        identity = np.array(derivative(v.states, starts, seed))
        fmu.exitInitializationMode()
        after = np.array(derivative(unknowns, v.states, seed))
        with pytest.raises(FMICallException):             # start parameters are no knowns after it
            derivative(unknowns, starts, seed)
    finally:
        fmu.freeInstance()
    assert np.array_equal(during, by_states)            # a state and its start value are one known there
    assert np.array_equal(identity, seed)                # d(state)/d(its start value) = 1
    # after initialization the dependent coordinates are solved again from the states (Newton-
    # Raphson to round-off), so the two agree to round-off, not bit for bit (measured: 1 ulp)
    assert np.isfinite(during).all() and np.allclose(during, after, rtol=1e-12, atol=1e-12)


def test_model_descriptions_declare_them_for_model_exchange_only(mechanism_fmus):
    """providesDirectionalDerivative(s) true in <ModelExchange>, false in <CoSimulation> (no inputs)."""
    for flavour, attribute in (("native", "providesDirectionalDerivative"),
                               ("native3", "providesDirectionalDerivatives")):
        with zipfile.ZipFile(mechanism_fmus.get("fourbar", flavour)) as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
        assert root.find("ModelExchange").get(attribute) == "true", flavour
        assert root.find("CoSimulation").get(attribute) == "false", flavour

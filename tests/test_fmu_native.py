"""The native FMU (build/FourBarNative.fmu): generated C, no Python at run time.

Checked here: validity, agreement with the pythonfmu FMU and the physics at tight
tolerances, independent instances, FMU state save/restore and serialization, fmi2Reset,
errors that leave the host alive, recompiling from the shipped sources, and clean exits of
fresh processes.  The physics tests of test_fmu_physics.py run for both FMUs too.
"""
from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
import zipfile
from ctypes import byref

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (FMU2Slave, calloc, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                       fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, free)
from fmpy.logging import addLoggerProxy
from fmpy.validation import validate_fmu

from reference_theta2 import simulate as reference

pytestmark = pytest.mark.slow    # whole 100 s runs; `make check` leaves them out

CENTRES = ["x2", "y2", "x3", "y3", "x4", "y4"]
TIGHT = {"rtol": 1e-12, "atol": 1e-12}
THETA2_0 = math.radians(30.0)
TABLE1 = dict(L1=3.0, L2=1.0, L3=4.0, L4=2.5, m2=1.0, m3=1.0, m4=1.0, g=9.81)


def simulate(fmu, stop=100.0, start_values=None, l2_step=None, output=None):
    """simulate_fmu on the 0.01 s grid; ``l2_step=(t, value)`` as an FMI input signal."""
    signal = None
    if l2_step is not None:
        t, value = l2_step
        signal = np.array([(0.0, 1.0), (t, 1.0), (t, value)], dtype=[("time", float), ("L2", float)])
    return simulate_fmu(str(fmu), stop_time=stop, output_interval=0.01, start_values=start_values or {},
                        input=signal, output=output)


def centres(result) -> np.ndarray:
    return np.column_stack([np.asarray(result[n], dtype=float) for n in CENTRES])


# -- a slave driven by hand ---------------------------------------------------------------
LOG: list[str] = []
_LOGGER = fmi2CallbackLoggerTYPE(lambda env, name, status, category, message:
                                 LOG.append(message.decode(errors="replace")))


class Slave:
    """An instantiated native FMU (FMPy's FMU2Slave) with a logger that lives as long as the module."""

    def __init__(self, unzipdir, md, name="fourbar"):
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = _LOGGER
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        addLoggerProxy(byref(callbacks))
        self.callbacks = callbacks
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        self.fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                             modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
        self.fmu.instantiate(callbacks=callbacks, loggingOn=True)
        self.t = 0.0
        self.k = 0

    def initialize(self, stop=100.0, **values):
        self.fmu.setupExperiment(startTime=0.0, stopTime=stop)
        self.set(**values)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        self.k = 0

    def set(self, **values):
        if values:
            self.fmu.setReal([self.vr[n] for n in values], list(values.values()))

    def get(self, names=CENTRES):
        return self.fmu.getReal([self.vr[n] for n in names])

    def step(self, n=1):
        """n steps of 0.01 s on FMPy's grid (t_k = k * 0.01); the rows after each step."""
        rows = []
        for _ in range(n):
            t = self.k * 0.01
            self.fmu.doStep(t, (self.k + 1) * 0.01 - t)
            self.k += 1
            rows.append(self.get())
        return np.array(rows)

    def free(self):
        self.fmu.freeInstance()


@pytest.fixture(scope="module")
def native(native_fmu):
    md = read_model_description(str(native_fmu))
    unzipdir = extract(str(native_fmu))
    yield unzipdir, md
    shutil.rmtree(unzipdir, ignore_errors=True)


# -- validity and identity ---------------------------------------------------------------
def test_fmpy_validate_finds_no_problem(native_fmu):
    assert validate_fmu(str(native_fmu)) == []


def test_same_variables_as_the_pythonfmu_fmu(native_fmu, fourbar_fmu):
    def table(path):
        md = read_model_description(str(path))
        return [(v.name, v.valueReference, v.type, v.causality, v.variability, v.initial,
                 float(v.start) if v.type == "Real" and v.start is not None else v.start,
                 v.unit, v.displayUnit, v.description) for v in md.modelVariables]
    assert table(native_fmu) == table(fourbar_fmu)


def test_ships_its_sources_and_needs_no_python(native_fmu):
    with zipfile.ZipFile(native_fmu) as z:
        names = z.namelist()
        md = read_model_description(str(native_fmu))
    listed = md.buildConfigurations[0].sourceFileSets[0].sourceFiles
    assert listed and all(f"sources/{name}" in names for name in listed)
    assert "sources/fourbar_equations.c" in names and "sources/fmi2Functions.h" in names
    assert not any(n.startswith("resources/") and n.endswith(".py") for n in names)
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
    assert not md.coSimulation.needsExecutionTool


# -- agreement and physics at tight tolerances --------------------------------------------
@pytest.fixture(scope="module")
def tight_pairs(native_fmu, fourbar_fmu):
    """{case: (native result, pythonfmu result)} at rtol = atol = 1e-12, Cases 1 and 2."""
    cases = {"case1": None, "case2": (10.0, 1.1)}
    return {name: (simulate(native_fmu, start_values=TIGHT, l2_step=step),
                   simulate(fourbar_fmu, start_values=TIGHT, l2_step=step)) for name, step in cases.items()}


@pytest.mark.parametrize("case", ["case1", "case2"])
def test_native_agrees_with_pythonfmu(tight_pairs, case):
    native, python = tight_pairs[case]
    err = np.abs(centres(native) - centres(python)).max()
    # Same derivation, same DOP853 tableau and step control; only the floating-point
    # summation order differs (C loops vs numpy).  Measured 4e-12 m; the bound 1e-9 m.
    assert err <= 1e-9, f"max |native - pythonfmu| = {err:.3g} m ({case})"


@pytest.mark.parametrize("case", ["case1", "case2"])
def test_native_constraint_residual(tight_pairs, case):
    native, _ = tight_pairs[case]
    # Coordinate partitioning puts every reported state on Phi = 0, Phi_q qd = 0 up to
    # round-off (measured 2.2e-15); 1e-12 is the bound.
    assert native["constraint_residual"].max() <= 1e-12


def test_native_case2_against_independent_formulation(tight_pairs):
    native, _ = tight_pairs["case2"]
    times = np.round(np.arange(10001) * 0.01, 10)
    ref = reference(times, THETA2_0, switches=((10.0, {"L2": 1.1}),), **TABLE1)
    # Two formulations each integrated at 1e-12: they differ by the independent model's
    # finite-difference derivatives (~1e-8 m measured); 1e-6 m is the accuracy target.
    assert np.abs(centres(native) - ref).max() <= 1e-6


# -- instances, state, reset -------------------------------------------------------------
def test_two_instances_in_one_process_are_independent(native):
    unzipdir, md = native
    a, b = Slave(unzipdir, md, "a"), Slave(unzipdir, md, "b")
    alone = Slave(unzipdir, md, "alone")
    try:
        a.initialize(stop=5.0, L2=1.0, **TIGHT)
        b.initialize(stop=5.0, L2=1.1, **TIGHT)
        rows_a, rows_b = [], []
        for _ in range(500):                     # interleaved, step by step
            rows_a.append(a.step()[0])
            rows_b.append(b.step()[0])
        alone.initialize(stop=5.0, L2=1.1, **TIGHT)
        rows_alone = alone.step(500)
    finally:
        for s in (a, b, alone):
            s.free()
    rows_a, rows_b = np.array(rows_a), np.array(rows_b)
    # Each sees its own crank: |centre of link 2| = L2 / 2 (exact up to round-off).
    assert np.allclose(np.hypot(rows_a[:, 0], rows_a[:, 1]), 0.5, rtol=0, atol=1e-12)
    assert np.allclose(np.hypot(rows_b[:, 0], rows_b[:, 1]), 0.55, rtol=0, atol=1e-12)
    # And instance b computed exactly what the same set-up computes alone: no shared state.
    assert np.array_equal(rows_b, rows_alone)
    times = np.round(np.arange(501) * 0.01, 10)
    ref_a = reference(times, THETA2_0, **TABLE1)[1:]
    ref_b = reference(times, THETA2_0, **{**TABLE1, "L2": 1.1})[1:]
    # Tight tolerances over 5 s: the independent formulation's ~1e-8 m, bound 1e-6 m.
    assert np.abs(rows_a - ref_a).max() <= 1e-6 and np.abs(rows_b - ref_b).max() <= 1e-6


def test_get_and_set_fmu_state_reproduce_a_run_bit_for_bit(native):
    unzipdir, md = native
    s = Slave(unzipdir, md)
    try:
        s.initialize()
        s.step(300)
        state = s.fmu.getFMUstate()
        k0 = s.k
        s.set(L2=1.1)                               # a fault in the branch, pending parameters too
        first = s.step(400)
        s.fmu.setFMUstate(state)
        s.k = k0
        s.set(L2=1.1)
        second = s.step(400)
        # Serialized and read back: the same again.
        blob = s.fmu.serializeFMUstate(state)
        restored = s.fmu.deSerializeFMUstate(blob)
        s.fmu.setFMUstate(restored)
        s.k = k0
        s.set(L2=1.1)
        third = s.step(400)
        s.fmu.freeFMUstate(state)
        s.fmu.freeFMUstate(restored)
    finally:
        s.free()
    assert np.array_equal(first, second) and np.array_equal(first, third)
    assert np.hypot(*first[-1, :2]) == pytest.approx(0.55, abs=1e-12)   # the branch did apply L2


def test_set_fmu_state_rejects_a_foreign_blob(native):
    unzipdir, md = native
    s = Slave(unzipdir, md)
    try:
        s.initialize(stop=1.0)
        state = s.fmu.getFMUstate()
        blob = bytearray(s.fmu.serializeFMUstate(state))
        blob[0] ^= 0xFF                              # not our magic any more
        LOG.clear()
        with pytest.raises(FMICallException):
            s.fmu.deSerializeFMUstate(bytes(blob))
        assert any("not a state of this FMU" in m for m in LOG), LOG
        s.fmu.freeFMUstate(state)
    finally:
        s.free()


def test_reset_then_rerun_gives_the_same_result(native):
    unzipdir, md = native
    s = Slave(unzipdir, md)
    try:
        s.initialize(stop=3.0)
        first = s.step(300)
        s.fmu.reset()
        s.initialize(stop=3.0)
        second = s.step(300)
    finally:
        s.free()
    assert np.array_equal(first, second)


# -- errors ---------------------------------------------------------------------------------
def test_bad_mass_mid_run_is_an_error_and_the_host_goes_on(native):
    unzipdir, md = native
    s = Slave(unzipdir, md)
    try:
        s.initialize(stop=2.0)
        s.step(100)
        s.set(m3=-1.0)
        LOG.clear()
        with pytest.raises(FMICallException) as info:
            s.step()
        assert info.value.status == 3                # fmi2Error, not fatal
        assert any("m3 = -1.0 kg: must be a finite positive number" in m and "at t = 1 s" in m for m in LOG), LOG
        # The instance can be reset and reused in the same process.
        s.fmu.reset()
        s.initialize(stop=2.0)
        assert s.step(10).shape == (10, 6)
    finally:
        s.free()


def test_fixed_parameter_cannot_change_mid_run(native):
    unzipdir, md = native
    s = Slave(unzipdir, md)
    try:
        s.initialize(stop=1.0)
        LOG.clear()
        with pytest.raises(FMICallException):
            s.set(rtol=1e-6)
        assert any("rtol is a fixed parameter" in m for m in LOG), LOG
    finally:
        s.free()


def test_unknown_integrator_is_rejected_with_the_choices(native_fmu):
    md = read_model_description(str(native_fmu))
    unzipdir = extract(str(native_fmu))
    s = Slave(unzipdir, md)
    try:
        LOG.clear()
        with pytest.raises(FMICallException):
            s.fmu.setString([s.vr["integrator"]], ["Euler"])
        assert any("integrator = 'Euler': must be one of DOP853, RK45" in m for m in LOG), LOG
    finally:
        s.free()
        shutil.rmtree(unzipdir, ignore_errors=True)


# -- from the shipped sources -----------------------------------------------------------
@pytest.mark.skipif(shutil.which("cmake") is None, reason="FMPy compiles source FMUs with CMake")
def test_recompiled_from_shipped_sources_reproduces_the_outputs(native_fmu, tmp_path):
    from fmpy.build import build_platform_binary

    unzipdir = tmp_path / "unzipped"
    with zipfile.ZipFile(native_fmu) as z:
        z.extractall(unzipdir)
    shutil.rmtree(unzipdir / "binaries")
    (tmp_path / "cmake").mkdir()
    build_platform_binary(unzipdir, build_dir=tmp_path / "cmake")
    assert list((unzipdir / "binaries").rglob("FourBarNative.*"))
    md = read_model_description(str(unzipdir))
    rebuilt = simulate_fmu(str(unzipdir), model_description=md, stop_time=20.0, output_interval=0.01,
                           input=np.array([(0.0, 1.0), (10.0, 1.0), (10.0, 1.1)],
                                          dtype=[("time", float), ("L2", float)]))
    original = simulate(native_fmu, stop=20.0, l2_step=(10.0, 1.1))
    # The same C compiled by CMake (its own flags) instead of build_fmu.py: strict IEEE C99
    # either way, so the same numbers are expected; 1e-9 m is the two-FMU agreement bound.
    assert np.abs(centres(rebuilt) - centres(original)).max() <= 1e-9


# -- fresh processes ----------------------------------------------------------------------
_CHILD = """
import sys
from fmpy import simulate_fmu
r = simulate_fmu(sys.argv[1], stop_time=5.0, output_interval=0.01)
assert len(r) == 501 and abs(r["theta2"][0] - 0.5235987755982988) < 1e-15
"""


def test_twenty_fresh_processes_exit_cleanly(native_fmu):
    # No exit hook, no LD_PRELOAD/PYTHONHOME/PYTHONPATH: what a user of plain FMPy does.
    env = {k: v for k, v in os.environ.items() if k not in ("LD_PRELOAD", "PYTHONHOME", "PYTHONPATH")}
    codes = []
    for batch in range(10):                      # two at a time (2 cores)
        procs = [subprocess.Popen([sys.executable, "-c", _CHILD, str(native_fmu)], env=env,
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE) for _ in range(2)]
        for p in procs:
            out, err = p.communicate(timeout=120)
            codes.append((p.returncode, err.decode()[-300:]))
    assert [c for c, _ in codes] == [0] * 20, [c for c in codes if c[0] != 0]

"""Physics of the FourBar FMU, run through FMPy: assembly, constraints, energy, accuracy.

Table 1 tolerances (rtol 1e-9, atol 1e-6) bound the Runge-Kutta *local* error at ~1e-6
per step, which compounds to ~1e-4 m / ~1e-3 J over 100 s (docs/benchmarks.md measures
it).  The accuracy and energy targets (1e-6 m, 1e-8 J) are therefore checked with the
FMU's tolerances tightened to rtol = atol = 1e-12: they verify the formulation, not the
coarseness of Table 1's settings.
"""
from __future__ import annotations

import math
import shutil

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi1 import FMICallException

from support import file_key, logged_callbacks, shared_result

pytestmark = pytest.mark.slow    # whole 100 s runs; `make check` leaves them out

TABLE1 = dict(L1=3.0, L2=1.0, L3=4.0, L4=2.5, m2=1.0, m3=1.0, m4=1.0, g=9.81)
#: Table 1's tolerances, set explicitly (the FMU's defaults are tighter, see variables.py).
TABLE1_TOLERANCES = {"rtol": 1e-9, "atol": 1e-6}
THETA2_0 = math.radians(30.0)
TIGHT = {"rtol": 1e-12, "atol": 1e-12}
CENTRES = ["x2", "y2", "x3", "y3", "x4", "y4"]
ALL = CENTRES + ["theta2", "theta3", "theta4", "omega2", "omega3", "omega4", "energy",
                 "constraint_residual"]


def run(fmu, stop=100.0, start_values=None, l2_step=None, output=ALL, capture_log=False):
    """Simulate with FMPy on the 0.01 s grid; ``l2_step=(t, value)`` the standard FMI way.

    With ``capture_log`` the FMU's messages are appended to ``LOG`` (see ``_logged_instance``).
    """
    signal = None
    if l2_step is not None:
        t, value = l2_step
        signal = np.array([(0.0, TABLE1["L2"]), (t, TABLE1["L2"]), (t, value)],
                          dtype=[("time", float), ("L2", float)])
    kwargs = dict(stop_time=stop, output_interval=0.01, start_values=start_values or {},
                  input=signal, output=output)
    if not capture_log:
        return simulate_fmu(str(fmu), **kwargs)
    md = read_model_description(str(fmu))
    unzipdir = extract(str(fmu))
    instance = _logged_instance(md, unzipdir)
    try:
        result = simulate_fmu(unzipdir, model_description=md, fmu_instance=instance, debug_logging=True, **kwargs)
    except FMICallException as exc:
        # FMI 2.0 allows no call after fmi2Fatal, freeInstance included (and a pythonfmu slave
        # freed after fatal corrupts the heap): free only after a non-fatal failure.
        if exc.status != 4:
            instance.freeInstance()
        raise
    finally:
        shutil.rmtree(unzipdir, ignore_errors=True)
    instance.freeInstance()
    return result


# FMPy's logger proxy keeps a pointer to the last registered ctypes logger in one
# process-wide C variable.  simulate_fmu(logger=f) makes a thunk per call and frees it
# afterwards, leaving that pointer dangling (heap corruption at a later log call or at
# exit).  So the tests register one thunk that lives as long as this module.
LOG: list[str] = []


def _logged_instance(md, unzipdir):
    callbacks = logged_callbacks(lambda status, text: LOG.append(text))
    instance = FMU2Slave(guid=md.guid, unzipDirectory=unzipdir,
                         modelIdentifier=md.coSimulation.modelIdentifier, instanceName="FourBar")
    instance.instantiate(callbacks=callbacks, loggingOn=True)   # pythonfmu logs only when on
    instance.kept_callbacks = callbacks
    return instance


def shared_run(folder, fmu, **kwargs):
    """``run(fmu, **kwargs)`` made once per test session, also when both xdist workers run tests
    of this module (support.shared_result): a 100 s run at tight tolerances costs ~18 s of CPU on
    the pythonfmu FMU."""
    return shared_result(folder, "physics-run", file_key(fmu) + repr(sorted(kwargs.items())).encode(),
                         lambda: run(fmu, **kwargs))


@pytest.fixture(scope="module")
def case1(either_fmu, shared_folder):
    return shared_run(shared_folder, either_fmu, start_values=TABLE1_TOLERANCES)


@pytest.fixture(scope="module")
def case2(either_fmu, shared_folder):
    return shared_run(shared_folder, either_fmu, start_values=TABLE1_TOLERANCES, l2_step=(10.0, 1.1))


@pytest.fixture(scope="module")
def case1_tight(either_fmu, shared_folder):
    return shared_run(shared_folder, either_fmu, start_values=TIGHT)


@pytest.fixture(scope="module")
def case2_tight(either_fmu, shared_folder):
    return shared_run(shared_folder, either_fmu, start_values=TIGHT, l2_step=(10.0, 1.1))


def joint_mismatch(r, L2):
    """Largest joint separation (m) computed from the reported centres and angles alone."""
    L1, L3, L4 = TABLE1["L1"], TABLE1["L3"], TABLE1["L4"]
    c2, s2 = np.cos(r["theta2"]), np.sin(r["theta2"])
    c3, s3 = np.cos(r["theta3"]), np.sin(r["theta3"])
    c4, s4 = np.cos(r["theta4"]), np.sin(r["theta4"])
    gaps = [
        r["x2"] - L2 / 2 * c2, r["y2"] - L2 / 2 * s2,                                 # ground pin O2
        r["x2"] + L2 / 2 * c2 - (r["x3"] - L3 / 2 * c3), r["y2"] + L2 / 2 * s2 - (r["y3"] - L3 / 2 * s3),
        r["x3"] + L3 / 2 * c3 - (r["x4"] + L4 / 2 * c4), r["y3"] + L3 / 2 * s3 - (r["y4"] + L4 / 2 * s4),
        r["x4"] - L4 / 2 * c4 - L1, r["y4"] - L4 / 2 * s4,                            # ground pin O4
    ]
    return np.max(np.abs(gaps), axis=0)


def test_initial_assembly_is_table1(case1):
    # Table 1 gives the angles to 0.01 deg.
    assert math.degrees(case1["theta2"][0]) == pytest.approx(30.0, abs=1e-12)
    assert math.degrees(case1["theta3"][0]) == pytest.approx(20.71, abs=0.01)
    assert math.degrees(case1["theta4"][0]) == pytest.approx(49.98, abs=0.01)
    assert case1["omega2"][0] == 0.0


def test_nothing_moves_without_gravity(either_fmu):
    r = run(either_fmu, stop=5.0, start_values={"g": 0.0})
    for name in ALL[:-2]:
        # At rest with no force the exact solution is constant; allow round-off only.
        assert np.ptp(r[name]) <= 1e-12, name


@pytest.mark.parametrize("which", ["case1", "case2"])
def test_constraints_hold_at_every_output(which, either_fmu, request):
    r = request.getfixturevalue(which)      # either_fmu named so that the case runs for each FMU
    assert len(r) == 10001
    # The FMU's own residual: positions and velocities satisfy Phi = 0, Phi_q qd = 0.
    assert r["constraint_residual"].max() <= 1e-10
    # Independently, from the published centres and angles (L2 = 1.1 m after t = 10 s).
    L2 = np.where(r["time"] > 10.0 + 1e-9, 1.1, 1.0) if which == "case2" else 1.0
    assert joint_mismatch(r, L2).max() <= 1e-10


def test_energy_constant_case1(case1_tight):
    # Conservative system: T + V constant.  Tight tolerances (see module docstring); both FMUs
    # measured 5.8e-10 J over 100 s, the bound is the FMU issue's 1e-9 J.
    drift = np.ptp(case1_tight["energy"])
    assert drift <= 1e-9, f"energy drift {drift:.3g} J over 100 s"


def test_energy_at_table1_tolerances(case1):
    # Table 1's atol = 1e-6 rad per step: measured drift ~1e-3 J of 23.69 J.  This bound
    # (1e-2 J, 0.04 %) catches a formulation error, which shows as drift of order 1 J.
    assert np.ptp(case1["energy"]) <= 1e-2


def test_energy_changes_only_at_the_fault(case2_tight):
    t, e = case2_tight["time"], case2_tight["energy"]
    before, after = e[t <= 10.0 + 1e-9], e[t > 10.0 + 1e-9]
    assert np.ptp(before) <= 1e-8 and np.ptp(after) <= 1e-8
    # Re-assembly with a longer crank at the same theta2, omega2 changes T + V.
    assert abs(after[0] - before[-1]) > 1e-3


@pytest.fixture(scope="module")
def times():
    return np.round(np.arange(10001) * 0.01, 10)


def test_agrees_with_independent_formulation_case1(case1_tight, times, theta2_reference):
    ref = theta2_reference(times, THETA2_0, **TABLE1)
    fmu = np.column_stack([case1_tight[n] for n in CENTRES])
    err = np.abs(fmu - ref).max()
    assert err <= 1e-6, f"max |FMU - theta2 formulation| = {err:.3g} m"


def test_agrees_with_independent_formulation_case2(case2_tight, times, theta2_reference):
    ref = theta2_reference(times, THETA2_0, switches=((10.0, {"L2": 1.1}),), **TABLE1)
    fmu = np.column_stack([case2_tight[n] for n in CENTRES])
    err = np.abs(fmu - ref).max()
    assert err <= 1e-6, f"max |FMU - theta2 formulation| = {err:.3g} m"
    # Output convention: the row at 10.00 s has the old crank, 10.01 s the new one.
    k = int(np.searchsorted(case2_tight["time"], 10.0 - 1e-9))
    for j, L2 in ((k, 1.0), (k + 1, 1.1)):
        r = case2_tight[j]
        assert math.hypot(r["x2"], r["y2"]) == pytest.approx(L2 / 2, abs=1e-12)


def test_rk45_is_selectable_and_accurate(either_fmu, times, theta2_reference):
    r = run(either_fmu, stop=10.0, start_values={"integrator": "RK45", "rtol": 1e-11, "atol": 1e-11},
            output=CENTRES)
    ref = theta2_reference(times[:1001], THETA2_0, **TABLE1)
    assert np.abs(np.column_stack([r[n] for n in CENTRES]) - ref).max() <= 1e-6


@pytest.mark.parametrize("name, value, unit", [("L4", -1.0, "m"), ("m3", 0.0, "kg"), ("L1", float("nan"), "m")])
def test_bad_start_parameters_are_rejected(either_fmu, name, value, unit):
    """A value outside a parameter's range is refused when the FMU initialises; the native FMU
    refuses a NaN at fmi2SetReal already (nothing is set), the pythonfmu FMU at initialisation
    (its setter cannot refuse: pythonfmu turns an exception there into fmi2Fatal)."""
    LOG.clear()
    native_nan = either_fmu.name.startswith("FourBarNative") and value != value
    with pytest.raises(FMICallException, match="fmi2SetReal" if native_nan else "fmi2ExitInitializationMode"):
        run(either_fmu, stop=0.1, start_values={name: value}, capture_log=True)
    if native_nan:
        assert any(name in m and "finite" in m for m in LOG), LOG
    else:
        assert any(f"{name} = {value!r} {unit}: must be a finite positive number" in m for m in LOG), LOG


def test_unassemblable_length_fails_the_step_cleanly(either_fmu):
    # L2 = 10 m puts the crank tip ~10 m from the rocker pivot; L3 + L4 = 6.5 m.  The native
    # FMU's doStep returns fmi2Error (simulate_fmu raises); the pythonfmu FMU can only return
    # fmi2Discard (its non-fatal failure status) and simulate_fmu returns the rows so far.  Both
    # log an error-level message naming the parameter, its values and why.
    LOG.clear()
    if either_fmu.name.startswith("FourBarNative"):
        with pytest.raises(FMICallException, match="fmi2DoStep") as info:
            run(either_fmu, stop=2.0, l2_step=(1.0, 10.0), capture_log=True)
        assert info.value.status == 3   # fmi2Error
    else:
        r = run(either_fmu, stop=2.0, l2_step=(1.0, 10.0), capture_log=True)
        assert r["time"][-1] == pytest.approx(1.0, abs=1e-12)
    text = " ".join(LOG)
    assert "L2 1 -> 10" in text and "the loop cannot be closed" in text and "in joint" in text, text

"""The IFToMM benchmark A01, the simple pendulum (fmu_src/mechanisms/iftomm_pendulum.toml),
against its published reference solution and pass criterion (issue 39 item 4).

The problem, the criterion and the reference (x and y of the point mass P1 every 0.5 s for
2000 s, six digits) with their sources are in tests/data/iftomm_pendulum_reference.toml.  The
criterion: every one of the 4000 output steps within 1e-3 m of the reference ("high precision";
1e-1 is "low precision").  Both native FMUs (FMI 2.0 and 3.0 co-simulation) run the whole span
at rtol = atol = 1e-12 (measured: 5.5e-7 m, the table's six-digit rounding; 0.1 s of CPU each),
and must also be within 1e-6 m of it.
The pythonfmu FMU runs the first 100 s (200 output steps; 4.5 s of CPU, the whole span would
take about 90 s) and must match the reference there and the native FMU within 1e-9 m, the
issue's bound for the two FMUs.  At rtol = 1e-8 the native FMU misses the criterion (1.4e-3 m
after 2000 s): the bound is not loose, and a bar 1 % longer misses it by far.
"""
from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu

REPO = Path(__file__).resolve().parents[1]
DATA = tomllib.loads((REPO / "tests" / "data" / "iftomm_pendulum_reference.toml").read_text())
CRITERION = DATA["criterion"]["high_precision"]
SPAN = DATA["problem"]["span"]
STEP = DATA["criterion"]["output_step"]
TIGHT = 1e-12
#: the pythonfmu FMU's span [s] (a Python right-hand side: 2000 s would cost about 90 s of CPU)
PYTHON_SPAN = 100.0
#: the table's six-digit rounding (5.1e-7 m) plus room for the FMU's own error at TIGHT [m]
ROUNDING = 1e-6
#: the two FMUs agree within this [m] at TIGHT (the issue's bound; measured 1.4e-11 m)
AGREE = 1e-9


def _reference(stop: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    n = int(round(stop / STEP)) + 1
    ref = DATA["reference"]
    return (np.arange(n) * ref["step"], np.array(ref["x"][:n]), np.array(ref["y"][:n]))


def _run(fmu: Path, stop: float, tol: float = TIGHT, **start) -> np.ndarray:
    return simulate_fmu(str(fmu), stop_time=stop, output_interval=STEP, output=["P1x", "P1y", "energy"],
                        start_values={"rtol": tol, "atol": tol, **start})


def _error(result: np.ndarray, stop: float) -> float:
    t, x, y = _reference(stop)
    assert np.allclose(result["time"], t, rtol=0, atol=1e-9), "the output steps are the reference's"
    return float(max(np.abs(result["P1x"] - x).max(), np.abs(result["P1y"] - y).max()))


@pytest.fixture(scope="module")
def native(mechanism_fmus):
    return _run(mechanism_fmus.get("iftomm_pendulum", "native"), SPAN)


@pytest.fixture(scope="module")
def python_run(mechanism_fmus):
    return _run(mechanism_fmus.get("iftomm_pendulum", "pythonfmu"), PYTHON_SPAN)


def test_the_reference_table_is_the_whole_span_and_every_row_is_on_the_bar():
    t, x, y = _reference(SPAN)
    assert len(DATA["reference"]["x"]) == len(DATA["reference"]["y"]) == 4001 and t[-1] == SPAN
    # six significant digits: |P1| = 1 m to within 1e-5 m; a mistyped digit among the first five
    # moves a row off the circle by more
    assert np.abs(np.hypot(x, y) - DATA["problem"]["length"]).max() <= 1e-5
    assert (x[0], y[0]) == (-1.0, 0.0)


def test_the_native_fmu_meets_the_published_criterion_over_the_whole_span(native):
    assert native["time"][-1] == pytest.approx(SPAN)
    assert _error(native, SPAN) <= CRITERION
    # tighter: the exact pendulum differs from the table by its six-digit rounding (5.1e-7 m,
    # tests/data's cross-check); the FMU adds about 5e-8 m to that over 2000 s
    assert _error(native, SPAN) <= ROUNDING
    # no energy is lost or gained: T + V stays that of the start (0 J) to the tolerance's order
    assert np.abs(native["energy"] - native["energy"][0]).max() <= 1e-7


def test_the_fmi3_native_fmu_meets_it_too(mechanism_fmus):
    result = _run(mechanism_fmus.get("iftomm_pendulum", "native3"), SPAN)
    assert _error(result, SPAN) <= CRITERION


def test_the_pythonfmu_fmu_meets_it_and_agrees_with_the_native_one(native, python_run):
    assert _error(python_run, PYTHON_SPAN) <= CRITERION
    n = len(python_run)
    for name in ("P1x", "P1y"):
        assert np.abs(python_run[name] - native[name][:n]).max() <= AGREE, name


def test_a_bar_one_percent_longer_fails_the_criterion(mechanism_fmus):
    # the period grows by 0.5 %: over 2000 s (about 800 swings) the phases part completely
    result = _run(mechanism_fmus.get("iftomm_pendulum", "native"), SPAN, L=1.01)
    assert _error(result, SPAN) > 100 * CRITERION


def test_the_fmu_states_the_published_problem(mechanism_fmus):
    from fmpy import read_model_description

    start = {v.name: v.start for v in read_model_description(
        str(mechanism_fmus.get("iftomm_pendulum", "native"))).modelVariables}
    problem = DATA["problem"]
    assert float(start["m"]) == problem["mass"] and float(start["L"]) == problem["length"]
    assert float(start["g"]) == problem["g"]
    assert float(start["theta1_start"]) == pytest.approx(problem["theta0"], abs=1e-15)
    assert float(start["omega1_start"]) == 0.0

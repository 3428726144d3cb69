"""Case 3 (ramp fault + sensor noise): the ramp sets L2 at every grid point of [20, 30] s
(checked against plain FMPy fed the same values), the noise touches x2 only, is exactly
the documented draws of default_rng(seed), has the requested standard deviation within
sampling error, and is reproducible whatever the flush interval."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from orchestrator import ExchangeSettings, Noise, load_case, run_case
from support import case_file

COLUMNS = ["x2", "y2", "x3", "y3", "x4", "y4"]
STOP = 40.0          # s: covers before (0-20 s), during (20-30 s) and after the ramp; 100 s adds nothing here
STD = 0.005          # m, cases/case3_ramp_noise.toml


def _table(path: Path) -> np.ndarray:
    lines = path.read_text().splitlines()
    assert lines[0].startswith("time," + ",".join(COLUMNS) + ",")    # then the drawing's columns
    return np.array([[float(v) for v in line.split(",")[:1 + len(COLUMNS)]] for line in lines[1:]])


@pytest.fixture(scope="module")
def case3(fourbar_fmu, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("case3")
    case = load_case(case_file("case3_ramp_noise", fourbar_fmu, tmp))
    result = run_case(case, tmp / "out", stop=STOP)
    assert result.ok, result.error
    return case, result, _table(result.exchange_path)


def ramp_l2(t: np.ndarray) -> np.ndarray:
    """L2 in force *during* the step that starts at t: 1.0 before 20 s, linear to 1.05 at 30 s, then 1.05 (m).

    Written as docs/orchestrator.md specifies the ramp, ``from*(1-f) + to*f`` with
    ``f = (k - k_start)/(k_end - k_start)``: the FMU's adaptive integrator turns a
    last-bit difference in L2 into differences at its tolerance (~1e-6), so the
    reference must be fed the very same numbers.
    """
    k = np.rint(t / 0.01)
    f = np.clip((k - 2000) / (3000 - 2000), 0.0, 1.0)
    return 1.0 * (1.0 - f) + 1.05 * f


@pytest.fixture(scope="module")
def reference(fourbar_fmu):
    """Plain FMPy, L2 given as a table with one value per grid point of the ramp (held between points)."""
    from fmpy import simulate_fmu

    t = 0.0 + np.arange(2000, 3001) * 0.01      # the grid exactly as FMPy computes it (start + k*step)
    table = np.zeros(len(t) + 2, dtype=[("time", float), ("L2", float)])
    table["time"] = np.concatenate(([0.0], t, [STOP]))
    table["L2"] = np.concatenate(([1.0], ramp_l2(t), [1.05]))
    return simulate_fmu(str(fourbar_fmu), stop_time=STOP, output_interval=0.01, input=table, output=COLUMNS,
                        start_values={"L1": 3.0, "L2": 1.0, "L3": 4.0, "L4": 2.5,
                                      "rtol": 1e-9, "atol": 1e-6})   # Case 3's (Table 1's) tolerances


def test_ramp_matches_fmpy_fed_the_same_values(case3, reference):
    _, result, table = case3
    assert table.shape == (4001, 7) and result.rows_written == 4001
    assert_array_equal(table[:, 0], reference["time"])
    for i, name in enumerate(COLUMNS[1:], start=2):
        # Noise-free columns: the same FMU fed the same L2 at every point (acceptance bound 1e-12).
        assert_allclose(table[:, i], reference[name], rtol=0, atol=1e-12, err_msg=name)


def test_ramp_changes_the_crank_gradually(case3, reference):
    """Row t_k shows L2 set at t_(k-1): |crank centre| = L2/2 (clean x2 from the reference)."""
    _, _, table = case3
    t = table[:, 0]
    half_l2 = np.hypot(reference["x2"], table[:, 2])
    expected = np.concatenate(([0.5], ramp_l2(t[:-1]) / 2))
    # Assembled state projected onto the constraints to round-off; 1e-9 m leaves room for the projection.
    assert_allclose(half_l2, expected, rtol=0, atol=1e-9)
    assert half_l2[t == 20.0][0] == pytest.approx(0.5, abs=1e-9)          # row at ramp start: unchanged
    assert half_l2[t == 25.01][0] == pytest.approx(0.5125, abs=1e-9)      # halfway
    assert half_l2[t == 30.01][0] == pytest.approx(0.525, abs=1e-9)       # from one step after the end


def test_noise_is_the_documented_draws(case3, reference):
    case, _, table = case3
    residual = table[:, 1] - reference["x2"]
    draws = STD * np.random.default_rng(case.noise.seed).standard_normal(len(residual))
    # x2 + e is rounded once when written (|x2| < 1 m -> error < 1.2e-16 m); the subtraction is exact-ish.
    assert_allclose(residual, draws, rtol=0, atol=1e-15)


def test_noise_is_reproducible_and_independent_of_flush_interval(case3, tmp_path):
    """Same seed, other flush interval (0.1 s instead of 1 s) and a shorter run: identical rows.

    The short runs end before the ramp, so they drop the event (an event after the stop
    time is a configuration error).
    """
    case, result, _ = case3
    case = dataclasses.replace(case, events=())
    again = dataclasses.replace(case, exchange=ExchangeSettings(flush_interval=0.1))
    short = run_case(again, tmp_path / "again", stop=3.0)
    long_lines = result.exchange_path.read_text().splitlines()
    assert short.exchange_path.read_text().splitlines() == long_lines[:302]
    other = run_case(dataclasses.replace(case, noise=Noise(seed=case.noise.seed + 1, std={"x2": STD})),
                     tmp_path / "other", stop=0.5)
    other_rows = [line.split(",") for line in other.exchange_path.read_text().splitlines()[1:]]
    first_rows = [line.split(",") for line in long_lines[1:52]]
    assert all(a[1] != b[1] for a, b in zip(other_rows[1:], first_rows[1:]))   # x2: other noise
    assert all(a[2:] == b[2:] for a, b in zip(other_rows, first_rows))         # other columns: untouched


def test_run_json_records_ramp_and_noise(case3):
    case, result, _ = case3
    record = json.loads(result.run_json_path.read_text())
    assert record["events"] == [{"type": "ramp", "variable": "L2", "from": 1.0, "to": 1.05,
                                 "start": 20.0, "end": 30.0}]
    assert record["fault_time"] == 20.0
    assert record["noise"] == {"seed": case.noise.seed, "std": {"x2": 0.005}}
    assert record["status"] == "finished" and record["experiment"]["stop"] == STOP

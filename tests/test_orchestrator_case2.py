"""Case 2 end to end: the exchange file equals plain FMPy with the same L2 step, the fault
lands on its grid point (row 10.00 s old geometry, 10.01 s new), floats round-trip, and
run.json carries the ground truth.  One 100 s run and one reference run, shared."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from orchestrator import run_case
from support import case_file, recorded_columns

COLUMNS = ["x2", "y2", "x3", "y3", "x4", "y4"]


@pytest.fixture(scope="module")
def case2_run(fourbar_fmu, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("case2")
    path = case_file("case2_fault_L2", fourbar_fmu, tmp)
    result = run_case(path, tmp / "out")
    text = result.exchange_path.read_text()
    return result, text


@pytest.fixture(scope="module")
def reference(fourbar_fmu):
    """Plain FMPy: the same FMU, start values, grid and L2 step (as an input signal at 10 s)."""
    from fmpy import simulate_fmu

    signal = np.array([(0.0, 1.0), (10.0, 1.0), (10.0, 1.1), (100.0, 1.1)], dtype=[("time", float), ("L2", float)])
    start_values = {"L1": 3.0, "L2": 1.0, "L3": 4.0, "L4": 2.5, "m2": 1.0, "m3": 1.0, "m4": 1.0, "g": 9.81,
                    "theta2_start": 0.5235987755982988, "omega2_start": 0.0, "rtol": 1e-9, "atol": 1e-6}
    return simulate_fmu(str(fourbar_fmu), start_time=0.0, stop_time=100.0, output_interval=0.01,
                        relative_tolerance=1e-9, start_values=start_values, input=signal, output=COLUMNS)


def _table(text: str) -> np.ndarray:
    lines = text.splitlines()
    return np.array([[float(v) for v in line.split(",")] for line in lines[1:]])


def test_header_and_row_count(case2_run, fourbar_fmu):
    result, text = case2_run
    assert result.status == "finished" and result.ok and result.error is None
    columns = recorded_columns(fourbar_fmu)        # the paper's six, then where the joints are
    assert text.startswith("time," + ",".join(columns) + "\n")
    assert text.endswith("\n") and "\r" not in text
    lines = text.splitlines()
    assert len(lines) == 1 + 10_001
    assert result.rows_written == 10_001 and result.last_time == 100.0
    assert all(line.count(",") == len(columns) for line in lines)


def test_times_are_the_integer_grid(case2_run, reference):
    table = _table(case2_run[1])
    k = np.arange(10_001)
    assert_array_equal(table[:, 0], 0.0 + k * 0.01)      # start + k*step, no accumulated drift
    assert_array_equal(table[:, 0], reference["time"])


def test_outputs_equal_simulate_fmu(case2_run, reference):
    table = _table(case2_run[1])
    for i, name in enumerate(COLUMNS, start=1):
        # Acceptance: <= 1e-12.  Same FMU, same grid, same doStep sizes -> identical in practice.
        assert_allclose(table[:, i], reference[name], rtol=0, atol=1e-12, err_msg=name)


def test_fault_lands_on_its_grid_point(case2_run):
    """Row 10.00 s: old crank (L2 = 1.0); row 10.01 s: new crank (L2 = 1.1).

    The crank centre (x2, y2) is the midpoint of a rod pinned at the origin, so
    |(x2, y2)| = L2/2 exactly for an assembled state.
    """
    table = _table(case2_run[1])
    t = table[:, 0]
    half_l2 = np.hypot(table[:, 1], table[:, 2])
    i10 = int(np.flatnonzero(t == 10.0)[0])
    assert t[i10 + 1] == 10.01
    # Positions are projected onto the constraints to round-off at every communication point.
    assert_allclose(half_l2[: i10 + 1], 0.5, rtol=0, atol=1e-9)      # every row up to and including 10.00 s
    assert_allclose(half_l2[i10 + 1:], 0.55, rtol=0, atol=1e-9)      # every row from 10.01 s
    # The rest of the linkage did not change: rocker centre at L4/2 = 1.25 m from its pivot (3, 0).
    assert_allclose(np.hypot(table[:, 5] - 3.0, table[:, 6]), 1.25, rtol=0, atol=1e-9)


def test_floats_round_trip_with_at_most_17_digits(case2_run):
    text = case2_run[1]
    tokens = [tok for line in text.splitlines()[1:2001] for tok in line.split(",")]
    for tok in tokens:
        assert repr(float(tok)) == tok                                # exact round trip, shortest form
        digits = re.sub(r"[^0-9]", "", tok.split("e")[0]).lstrip("0")
        assert len(digits) <= 17


def test_run_json_carries_the_ground_truth(case2_run, fourbar_fmu):
    from fmpy import read_model_description

    result, _ = case2_run
    record = json.loads(result.run_json_path.read_text())
    md = read_model_description(str(fourbar_fmu))
    assert record["schema"] == 2
    assert record["status"] == "finished"
    assert record["case"] == "case2_fault_L2"
    assert record["case_file"].endswith("case2_fault_L2.toml")
    assert record["fmu"] == {"path": str(Path(fourbar_fmu).resolve()), "guid": md.guid, "model_name": "FourBar",
                             "fmi_type": "CoSimulation"}
    assert record["experiment"] == {"start": 0.0, "stop": 100.0, "step": 0.01, "tolerance": 1e-9}
    assert record["parameters"]["L2"] == {"start": 1.0, "source": "case", "type": "Real", "variability": "tunable",
                                          "unit": "m"}
    assert record["parameters"]["theta2_start"]["start"] == 0.5235987755982988
    assert record["events"] == [{"type": "step", "time": 10.0, "variable": "L2", "value": 1.1}]
    assert record["fault_time"] == 10.0
    assert record["outputs"] == recorded_columns(fourbar_fmu)
    assert record["noise"] is None
    assert record["rows_written"] == 10_001 and record["last_time"] == 100.0
    assert record["error"] is None
    assert record["finished_at"] is not None and record["started_at"] <= record["finished_at"]
    assert record["wall_time_s"] > 0
    assert not list(result.out_dir.glob(".*.tmp"))           # no temporary file left behind


def test_native_fmu_reproduces_the_case2_exchange_file(fourbar_fmu, native_fmu, tmp_path, capsys):
    """``fourbar-run --fmu build/FourBarNative.fmu`` writes Case 2's exchange file to <= 1e-9 m."""
    from orchestrator.cli import main

    path = case_file("case2_fault_L2", fourbar_fmu, tmp_path)
    tight = ["--set", "rtol=1e-12", "--set", "atol=1e-12", "--quiet"]
    assert main([str(path), "--out", str(tmp_path / "py"), *tight]) == 0
    assert main([str(path), "--fmu", str(native_fmu), "--out", str(tmp_path / "native"), *tight]) == 0
    python = _table((tmp_path / "py" / "exchange.csv").read_text())
    native = _table((tmp_path / "native" / "exchange.csv").read_text())
    # both FMUs declare the same drawing: the same columns (the joints' too, also compared)
    assert python.shape == native.shape == (10001, 1 + len(recorded_columns(native_fmu)))
    assert_array_equal(python[:, 0], native[:, 0])
    # Same derivation and integrator in C and numpy; at 1e-12 only the summation order differs
    # (measured 3e-12 m).  1e-9 m is the bound.
    assert np.abs(python[:, 1:] - native[:, 1:]).max() <= 1e-9
    run = json.loads((tmp_path / "native" / "run.json").read_text())
    assert run["status"] == "finished" and run["fmu"]["model_name"] == "FourBarNative"
    assert Path(run["fmu"]["path"]) == native_fmu.resolve()


def test_fmu_option_names_a_missing_file(tmp_path, fourbar_fmu, capsys):
    from orchestrator.cli import main

    path = case_file("case2_fault_L2", fourbar_fmu, tmp_path)
    assert main([str(path), "--fmu", str(tmp_path / "nothere.fmu"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "fmu (from --fmu)" in err and "file not found" in err and "Traceback" not in err

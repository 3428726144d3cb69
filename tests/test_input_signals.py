"""Input signals of case files (orchestrator.input_signals): values and exact derivatives
against closed forms and numpy, and the refusals of bad ``[inputs]`` tables.

No FMU is run here (tests/test_run_inputs.py runs them); a case is checked against a small
pythonfmu FMU with one input only where the refusal needs the FMU's variables.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from numpy.testing import assert_allclose

from orchestrator.input_signals import (Constant, CsvColumn, Ramp, Sine, Step, Table, derivative_order,
                                        parse_inputs)
from orchestrator.validation import ProblemReporter

finite = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False)
#: Every property test: no time limit per example (the machine may be loaded) and the same
#: examples on every run (derandomized, no example database), as the project's other fuzzers.
PROPERTY = settings(deadline=None, derandomize=True, database=None, max_examples=100)


class Reporter(ProblemReporter):
    def __init__(self):
        self.raw = {}
        self.problems = []


def parse(table, tmp_path: Path = Path("."), span=(0.0, 10.0), inputs=None):
    reporter = Reporter()
    signals = parse_inputs(reporter, table, inputs, tmp_path, span, "Test.fmu")
    return signals, reporter.problems


# ---------------------------------------------------------------------------- closed forms

@PROPERTY
@given(amplitude=finite, frequency=st.floats(0.0, 50.0), phase=st.floats(-7.0, 7.0), offset=finite,
       t=st.floats(0.0, 100.0))
def test_sine_and_its_derivatives_are_the_closed_forms(amplitude, frequency, phase, offset, t):
    s = Sine(amplitude, frequency, phase, offset)
    w = 2 * math.pi * frequency
    scale = abs(amplitude) * (1 + w) ** 2 + abs(offset)
    # a few ulps of the largest term: the same formula evaluated in a different order
    assert_allclose(s.at(t), offset + amplitude * math.sin(w * t + phase), rtol=0, atol=1e-12 * scale)
    assert_allclose(s.at(t, 1), amplitude * w * math.cos(w * t + phase), rtol=0, atol=1e-12 * scale)
    assert_allclose(s.at(t, 2), -amplitude * w * w * math.sin(w * t + phase), rtol=0, atol=1e-12 * scale)


def test_sine_derivatives_match_central_differences():
    """An independent check of the derivatives: central differences of the value (h = 1e-5 s,
    truncation error ~ h^2 * |u'''| / 6 ~ 1e-8 for this signal)."""
    s = Sine(2.0, 1.5, 0.3, 0.1)
    h = 1e-5
    for t in np.linspace(0.0, 3.0, 31):
        assert_allclose(s.at(t, 1), (s.at(t + h) - s.at(t - h)) / (2 * h), rtol=0, atol=1e-7)
        assert_allclose(s.at(t, 2), (s.at(t + h, 1) - s.at(t - h, 1)) / (2 * h), rtol=0, atol=1e-6)


def test_step_is_right_continuous_with_zero_derivatives():
    s = Step(before=1.0, after=3.0, time=2.0)
    assert [s.at(t) for t in (0.0, 1.999999, 2.0, 5.0)] == [1.0, 1.0, 3.0, 3.0]
    assert {s.at(t, k) for t in (0.0, 2.0, 5.0) for k in (1, 2)} == {0.0}


def test_ramp_values_and_slopes_piece_by_piece():
    r = Ramp(from_=1.0, start=2.0, slope=0.5, duration=4.0)
    assert r.end == 6.0 and r.to == 3.0
    assert [r.at(t) for t in (0.0, 2.0, 3.0, 5.5, 6.0, 9.0)] == [1.0, 1.0, 1.5, 2.75, 3.0, 3.0]
    # right-hand derivative: the slope from the start (included) to the end (excluded)
    assert [r.at(t, 1) for t in (1.9, 2.0, 5.9, 6.0)] == [0.0, 0.5, 0.5, 0.0]
    assert r.at(3.0, 2) == 0.0
    endless = Ramp(from_=0.0, start=1.0, slope=-2.0)
    assert endless.at(101.0) == -200.0 and endless.at(101.0, 1) == -2.0 and endless.to is None


def test_constant():
    assert Constant(2.5).at(7.0) == 2.5 and Constant(2.5).at(7.0, 1) == 0.0


def test_an_order_above_four_is_refused():
    with pytest.raises(ValueError, match="order"):
        Sine(1.0, 1.0).at(0.0, 5)


@PROPERTY
@given(t=st.floats(0.0, 10.0))
def test_sine_derivatives_of_order_three_and_four_are_the_closed_forms(t):
    """A driver input's acceleration input needs the position's 3rd and 4th derivatives (its
    own first and second, for the FMU's interpolation)."""
    s = Sine(0.5, 0.5, 0.2, 1.0)
    w = np.pi
    # w^4 ~ 97: a few ulps of the largest term
    assert_allclose(s.at(t, 3), -0.5 * w ** 3 * math.cos(w * t + 0.2), rtol=0, atol=1e-12)
    assert_allclose(s.at(t, 4), 0.5 * w ** 4 * math.sin(w * t + 0.2), rtol=0, atol=1e-12)


def test_a_driver_inputs_rates_are_derived_from_its_position():
    """An FMU input <name> with inputs <name>_d and <name>_dd (a driver input): those the case
    does not give follow the position's exact derivatives."""
    from orchestrator.input_signals import Derivative, driver_rates

    crank = Sine(0.5, 0.5, 0.0, 0.5)
    inputs = {n: Var(n) for n in ("crank", "crank_d", "crank_dd", "tau")}
    derived = driver_rates({"crank": crank, "tau": Constant(1.0)}, inputs)
    assert derived == {"crank_d": Derivative(crank, 1, "crank"), "crank_dd": Derivative(crank, 2, "crank")}
    for t in (0.0, 0.3, 1.7):
        assert derived["crank_d"].at(t) == crank.at(t, 1) and derived["crank_d"].at(t, 2) == crank.at(t, 3)
        assert derived["crank_dd"].at(t) == crank.at(t, 2) and derived["crank_dd"].at(t, 2) == crank.at(t, 4)
    # a rate the case gives is kept; an FMU without both rate inputs gets none
    assert set(driver_rates({"crank": crank, "crank_d": Constant(0.0)}, inputs)) == {"crank_dd"}
    assert driver_rates({"crank": crank}, {"crank": Var("crank"), "crank_d": Var("crank_d")}) == {}


#: Table times on a 0.01 s grid: rows a subnormal apart make numpy.interp's slope overflow (the
#: case file refuses such rows, test_bad_signals_are_refused_naming_the_field).
grid_times = st.integers(-5000, 5000).map(lambda k: k / 100)
table_rows = st.lists(st.tuples(grid_times, finite), min_size=1, max_size=12)


@PROPERTY
@given(rows=table_rows, t=st.floats(-60.0, 60.0))
def test_table_interpolates_as_numpy_interp_away_from_repeated_times(rows, t):
    rows = sorted(rows, key=lambda r: r[0])
    times = [r[0] for r in rows]
    if any(times.count(x) > 1 for x in times):
        return                # repeated times: the step test below
    table = Table(tuple(times), tuple(r[1] for r in rows))
    # numpy.interp computes the same line with its own rounding (a few ulps of the values)
    assert_allclose(table.at(t), np.interp(t, times, [r[1] for r in rows]), rtol=0, atol=1e-9)


@PROPERTY
@given(rows=st.lists(st.tuples(grid_times, finite), min_size=2, max_size=8, unique_by=lambda r: r[0]),
       jump=finite)
def test_a_repeated_time_is_a_step_to_the_later_row(rows, jump):
    rows = sorted(rows)
    ts, vs = [r[0] for r in rows], [r[1] for r in rows]
    k = len(rows) // 2
    times = ts[:k + 1] + ts[k:]               # ts[k] twice
    values = vs[:k + 1] + [jump] + vs[k + 1:]
    table = Table(tuple(times), tuple(values))
    assert table.at(ts[k]) == jump            # from the repeated time on: the later row
    if k > 0:
        before = np.nextafter(ts[k], -np.inf)
        # just before: the line from the previous row to the first of the repeated rows
        assert_allclose(table.at(before), np.interp(before, ts[:k + 1], vs[:k + 1]), rtol=0, atol=1e-6)


def test_table_slopes_are_the_segments_and_zero_outside():
    table = Table((0.0, 1.0, 1.0, 3.0), (0.0, 2.0, 5.0, 1.0))
    assert [table.at(t, 1) for t in (-1.0, 0.0, 0.5, 1.0, 2.0, 3.0, 4.0)] == [0.0, 2.0, 2.0, -2.0, -2.0, 0.0, 0.0]
    assert table.at(0.5, 2) == 0.0 and table.at(1.0) == 5.0 and table.at(9.0) == 1.0


# ---------------------------------------------------------------------------- the case table

def test_each_signal_type_is_read():
    signals, problems = parse({
        "a": 1.5,
        "b": {"type": "step", "before": 0, "after": 2.0, "time": 1.0},
        "c": {"type": "ramp", "from": 0.0, "to": 2.0, "start": 1.0, "duration": 4.0},
        "d": {"type": "ramp", "from": 0.0, "to": 2.0, "start": 1.0, "slope": 0.5},
        "e": {"type": "ramp", "from": 1.0, "start": 0.0, "slope": -1.0},
        "f": {"type": "sine", "amplitude": 2.0, "frequency": 0.5},
        "g": {"type": "table", "rows": [[0.0, 1.0], [2.0, 3.0], [2.0, 0.0]]},
        "h": {"type": "constant", "value": -1},
    })
    assert problems == []
    assert signals["a"] == Constant(1.5) and signals["h"] == Constant(-1.0)
    assert signals["b"] == Step(0.0, 2.0, 1.0)
    assert signals["c"] == Ramp(0.0, 1.0, 0.5, 4.0) == signals["d"]
    assert signals["e"] == Ramp(1.0, 0.0, -1.0, None)
    assert signals["f"] == Sine(2.0, 0.5, 0.0, 0.0)
    assert signals["g"] == Table((0.0, 2.0, 2.0), (1.0, 3.0, 0.0))


def test_what_the_case_gives_reads_back_the_same():
    """Case.as_dict (re-validated by apply_overrides) writes each signal as the case file would."""
    given_ = {"r": Ramp(0.25, 1.0, 0.5, 4.0), "s": Sine(2.0, 0.5, 0.1, 3.0), "t": Table((0.0, 1.0), (1.0, 2.0)),
              "u": Step(1.0, 2.0, 0.5), "v": Constant(1.0), "w": Ramp(1.0, 0.0, -1.0)}
    again, problems = parse({name: s.as_toml() for name, s in given_.items()})
    assert problems == [] and again == given_


@pytest.mark.parametrize("item, expected", [
    ({"type": "sine", "amplitude": float("nan"), "frequency": 1.0}, "inputs.u.amplitude = nan: expected a finite number"),
    ({"type": "sine", "amplitude": 1.0, "frequency": float("inf")}, "inputs.u.frequency = inf: expected a finite number"),
    ({"type": "sine", "amplitude": 1.0, "frequency": -1.0}, "inputs.u.frequency = -1.0: expected a frequency >= 0 Hz"),
    ({"type": "ramp", "from": 0.0, "to": 1.0, "start": 0.0, "duration": -2.0},
     "inputs.u.duration = -2.0: expected a duration > 0 s"),
    ({"type": "ramp", "from": 0.0, "to": 1.0, "start": 0.0, "slope": -2.0},
     "inputs.u.slope = -2.0: expected a slope of the sign of to - from"),
    ({"type": "ramp", "from": 0.0, "to": 1.0, "start": 0.0}, "inputs.u: a ramp gives `to` and `duration`"),
    ({"type": "ramp", "from": 0.0, "to": 1.0, "start": 0.0, "slope": 1.0, "duration": 1.0},
     "got to, duration, slope"),
    ({"type": "step", "before": 0.0, "after": "high", "time": 1.0},
     'inputs.u.after = "high": expected a number, got a string'),
    ({"type": "step", "before": 0.0, "time": 1.0}, "inputs.u.after: missing; expected the value from the step on"),
    ({"type": "square", "amplitude": 1.0}, 'inputs.u.type = "square": expected one of'),
    ({"amplitude": 1.0}, "inputs.u.type: missing"),
    ({"type": "sine", "amplitude": 1.0, "frequency": 1.0, "phse": 0.1},
     "inputs.u.phse: unknown key; did you mean 'phase'?"),
    ({"type": "table", "rows": [[0.0, 1.0], [2.0, 3.0], [1.0, 0.0]]},
     "inputs.u.rows[2] = [1.0, 0.0]: time 1.0 s is before the previous row's 2.0 s"),
    ({"type": "table", "rows": [[0.0, 1.0], [0.0, 2.0], [0.0, 3.0]]}, "is given a third time"),
    ({"type": "table", "rows": [[0.0, 1.0, 2.0]]}, "inputs.u.rows[0] = [0.0, 1.0, 2.0]: expected a row [time in s, value]"),
    ({"type": "table", "rows": []}, "inputs.u.rows = []: expected a non-empty array"),
    ({"type": "table", "rows": [[0.0, 0.0], [5e-324, 1.0]]}, "the slope between them is not a finite number"),
    (True, "inputs.u = true: expected a number (a constant) or a table with type"),
    ("__import__('os')", "inputs.u = \"__import__('os')\": expected a number (a constant) or a table"),
])
def test_bad_signals_are_refused_naming_the_field(item, expected):
    signals, problems = parse({"u": item})
    assert signals == {}
    assert any(expected in p for p in problems), problems


class Var:
    def __init__(self, name, type_="Real"):
        self.name, self.type = name, type_


def test_an_input_the_fmu_lacks_is_refused_listing_its_inputs():
    inputs = {"tau": Var("tau"), "F": Var("F"), "on": Var("on", "Boolean")}
    signals, problems = parse({"tua": 1.0, "tau": 2.0, "on": 1.0}, inputs=inputs)
    assert signals == {"tau": Constant(2.0)}
    assert problems == ["inputs.tua = 1.0: Test.fmu has no input named 'tua'; its inputs: tau, F, on",
                        "inputs.on = 1.0: on is an Boolean input; [inputs] drives Real inputs only"]
    _, problems = parse({"x": 1.0}, inputs={})
    assert problems == ["inputs.x = 1.0: Test.fmu has no input named 'x'; its inputs: none (it declares no input "
                        "variables)"]


# ---------------------------------------------------------------------------- CSV columns

def csv_input(tmp_path, text: str, span=(0.0, 2.0), **keys):
    (tmp_path / "u.csv").write_text(text)
    return parse({"u": {"type": "csv", "file": "u.csv", "column": "torque", **keys}}, tmp_path, span)


def test_a_csv_column_is_a_table_with_its_file_recorded(tmp_path):
    signals, problems = csv_input(tmp_path, "time,torque,other\n0,1.0,x\n1,3.0,y\n1,0.0,z\n2,2.0,w\n")
    assert problems == []
    u = signals["u"]
    assert isinstance(u, CsvColumn) and u.times == (0.0, 1.0, 1.0, 2.0) and u.values == (1.0, 3.0, 0.0, 2.0)
    assert u.at(0.5) == 2.0 and u.at(1.0) == 0.0 and u.at(1.5, 1) == 2.0
    record = u.as_dict()
    assert record["rows"] == 4 and len(record["sha256"]) == 64 and record["file"] == str(tmp_path / "u.csv")
    signals, problems = csv_input(tmp_path, "t;torque\n0;1\n", time="t")
    assert any("no column named 't', 'torque' in its header" in p for p in problems), problems


@pytest.mark.parametrize("text, expected", [
    ("time,torque\n0,1\n1,nan\n2,3\n", "line 3, column 'torque': 'nan' is not a finite number"),
    ("time,torque\n0,1\n1,1e999\n2,3\n", "line 3, column 'torque': '1e999' is not a finite number"),
    ("time,torque\n0,1\n1,__import__('os')\n", "line 3, column 'torque': \"__import__('os')\" is not a finite number"),
    ("time,torque\n0,1\n1\n", "line 3, column 'torque': '' is not a finite number"),
    ("time,torque\n0,1\n2,2\n1,3\n", "data row 3, column 'time': time 1.0 s is before the previous row's 2.0 s"),
    ("time,force\n0,1\n", "no column named 'torque' in its header; it has: 'time', 'force'"),
    ("time,torque\n0.5,1\n2,1\n", "its 'time' column runs from 0.5 to 2.0 s, which does not cover the run, 0.0 to 2.0 s"),
    ("time,torque\n0,1\n1.5,1\n", "runs from 0.0 to 1.5 s, which does not cover the run"),
    ("", "empty; expected a header row"),
    ("time,torque\n", "has a header but no rows"),
])
def test_bad_csv_files_are_refused_naming_file_line_and_column(tmp_path, text, expected):
    signals, problems = csv_input(tmp_path, text)
    assert signals == {}
    assert len(problems) == 1 and problems[0].startswith(f'inputs.u.file = "u.csv" ({tmp_path / "u.csv"}): '), problems
    assert expected in problems[0], problems


def test_a_missing_or_special_csv_file_is_refused(tmp_path):
    _, problems = parse({"u": {"type": "csv", "file": "none.csv", "column": "c"}}, tmp_path)
    assert problems == [f'inputs.u.file = "none.csv" ({tmp_path / "none.csv"}): file not found (relative to the '
                        f"case file's folder)"]
    fifo = tmp_path / "fifo.csv"
    import os
    os.mkfifo(fifo)
    _, problems = parse({"u": {"type": "csv", "file": "fifo.csv", "column": "c"}}, tmp_path)
    assert len(problems) == 1 and "expected a CSV file" in problems[0], problems


# ---------------------------------------------------------------------------- what the FMU accepts

class _CS:
    def __init__(self, can, order):
        self.canInterpolateInputs, self.maxOutputDerivativeOrder = can, order


class _MD:
    def __init__(self, version="2.0", cs=None):
        self.fmiVersion, self.coSimulation = version, cs


def test_derivative_order_follows_the_model_description():
    assert derivative_order(_MD(cs=None)) == 0                       # model exchange only
    assert derivative_order(_MD(cs=_CS(False, 2))) == 0
    assert derivative_order(_MD(cs=_CS(True, 0))) == 1
    assert derivative_order(_MD(cs=_CS(True, 1))) == 1
    assert derivative_order(_MD(cs=_CS(True, 2))) == 2
    assert derivative_order(_MD("3.0", cs=_CS(True, 2))) == 0        # FMI 3.0 has no input derivatives


def test_recorded_signals_drive_a_replay_as_the_run_did(tmp_path):
    """run.json's record of each signal (as_dict) gives the same signal back; a CSV file changed
    since the run is refused."""
    from orchestrator.input_signals import Derivative, recorded_signals
    from orchestrator.validation import ConfigError

    (tmp_path / "u.csv").write_text("time,torque\n0,1\n2,3\n")
    signals, problems = parse({"u": {"type": "csv", "file": "u.csv", "column": "torque"}}, tmp_path, (0.0, 2.0))
    assert problems == [] and isinstance(signals["u"], CsvColumn)
    signals.update(r=Ramp(0.0, 1.0, 0.5, 2.0), s=Sine(1.0, 2.0, 0.5, 0.1), e=Ramp(1.0, 0.0, -1.0))
    signals.update(s_d=Derivative(signals["s"], 1, "s"), s_dd=Derivative(signals["s"], 2, "s"))
    records = {name: s.as_dict() for name, s in signals.items()}
    assert recorded_signals(records) == signals
    (tmp_path / "u.csv").write_text("time,torque\n0,1\n2,4\n")
    with pytest.raises(ConfigError, match="changed since the run"):
        recorded_signals(records)

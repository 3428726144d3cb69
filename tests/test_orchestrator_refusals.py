"""Case validation refuses what cannot be meant (issue 36, item 2): a communication step that
makes one doStep last for days, rates and angles no linkage reaches (also through --set),
non-finite values, and wrong types in every list and table; fuzzed case files give a
ConfigError, never another exception.
"""
from __future__ import annotations

import json
import os
import math
import tomllib

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from orchestrator import ConfigError, load_case
from orchestrator.limits import MAX_STEP, UNIT_LIMITS
from support import case_file


def refused(path, **kwargs) -> str:
    with pytest.raises(ConfigError) as info:
        load_case(path, **kwargs)
    return str(info.value)


def test_a_step_of_days_is_refused_with_the_file_field_and_value(native_fmu, tmp_path):
    """The issue's case: step = 1e9 s over 1e9 s passed validation and sat in one doStep."""
    path = case_file("case1_normal", native_fmu, tmp_path, step=1e9, stop=1e9)
    text = refused(path)
    assert f"{path}: experiment.step = 1000000000.0: expected a communication step <= {MAX_STEP:g} s" in text


def test_a_step_at_the_bound_is_accepted(native_fmu, tmp_path):
    path = case_file("case1_normal", native_fmu, tmp_path, step=MAX_STEP, stop=100.0)
    assert load_case(path).experiment.n_steps == 10


@pytest.mark.parametrize("name,value", [("omega2_start", 1e15), ("omega2_start", -2e4), ("theta2_start", 1e308)])
def test_rates_and_angles_no_linkage_reaches_are_refused_also_from_set(native_fmu, tmp_path, name, value):
    path = case_file("case1_normal", native_fmu, tmp_path)
    text = refused(path, overrides={name: value})
    unit = "rad/s" if name.startswith("omega") else "rad"
    assert f"parameters.{name} (from --set {name}) = {value!r}: expected |{name}| <= {UNIT_LIMITS[unit]:g} {unit}" \
        in text


def test_a_rate_within_the_bound_is_accepted(native_fmu, tmp_path):
    path = case_file("case1_normal", native_fmu, tmp_path)
    assert load_case(path, overrides={"omega2_start": -UNIT_LIMITS["rad/s"]}).parameters["omega2_start"] == -1e4


@pytest.mark.parametrize("extra,field", [
    ('[outputs]\nvariables = ["x2", [1, 2]]\n', "outputs.variables[1] = [1, 2]: expected a variable name"),
    ('[outputs]\nvariables = ["x2", {a = 1}]\n', "outputs.variables[1] = {\"a\": 1}: expected a variable name"),
    ('[[events]]\ntype = "step"\ntime = 1.0\nvariable = ["L2"]\nvalue = 1.1\n', "events[0].variable = [\"L2\"]"),
    ('[[events]]\ntype = "ramp"\nvariable = {x = 1}\nfrom = 1.0\nto = 1.1\nstart = 1.0\nend = 2.0\n',
     "events[0].variable = {\"x\": 1}"),
])
def test_wrong_types_in_lists_and_tables_are_refused(native_fmu, tmp_path, extra, field):
    """The issue's TypeError (an unhashable list as an output name) and its siblings."""
    path = case_file("case1_normal", native_fmu, tmp_path)
    text = path.read_text()
    text = text[:text.index("[outputs]")] + text[text.index("[exchange]"):] if "[outputs]" in extra else text
    path.write_text(text + "\n" + extra)
    assert field in refused(path)


def test_a_step_too_small_to_count_is_refused(native_fmu, tmp_path):
    """(stop - start)/step overflows to inf: refused, not an OverflowError."""
    path = case_file("case1_normal", native_fmu, tmp_path, step=5e-324)
    assert "experiment.stop = 100.0: (stop - start)/step = inf is not a whole number" in refused(path)


# ------------------------------------------------------------------------------ fuzzing

_SCALARS = st.one_of(st.none(), st.booleans(), st.integers(min_value=-2**70, max_value=2**70),
                     st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8),
                     st.sampled_from(["x2", "L2", "omega2_start", "step", "ramp", "time", "RK45"]))
_VALUES = st.recursive(_SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=3),
                                                         st.dictionaries(st.sampled_from(
                                                             ["type", "time", "variable", "value", "from", "to",
                                                              "start", "end", "seed", "std", "x2", "L2"]),
                                                             inner, max_size=4)),
                       max_leaves=8)
_SECTIONS = {
    "experiment": ["start", "stop", "step", "tolerance"],
    "parameters": ["L1", "L2", "omega2_start", "theta2_start", "rtol", "nope"],
    "outputs": ["variables", "drawing"],
    "noise": ["seed", "std"],
    "exchange": ["flush_interval", "realtime_factor", "max_rows"],
}


@st.composite
def mutations(draw):
    """(section, key, value) replacements of a valid case; ``key`` None replaces the whole section."""
    count = draw(st.integers(min_value=1, max_value=3))
    out = []
    for _ in range(count):
        section = draw(st.sampled_from([*_SECTIONS, "events", "name", "fmi_type", "description"]))
        if section in _SECTIONS and draw(st.booleans()):
            out.append((section, draw(st.sampled_from(_SECTIONS[section])), draw(_VALUES)))
        else:
            out.append((section, None, draw(_VALUES)))
    return out


@settings(max_examples=int(os.environ.get("FUZZ_EXAMPLES", "150")), deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(changes=mutations())
def test_fuzzed_case_files_give_a_config_error_or_a_case(native_fmu, tmp_path, changes):
    """Any exception but ConfigError is a bug (the issue: 12 of 300 fuzzed files gave a traceback)."""
    base = tomllib.loads(case_file("case1_normal", native_fmu, tmp_path).read_text())
    for section, key, value in changes:
        if key is None:
            base[section] = value
        else:
            table = base.get(section)
            table = dict(table) if isinstance(table, dict) else {}
            table[key] = value
            base[section] = table
    path = tmp_path / "fuzzed.json"
    # the raw dict goes in as a Case would be merged: through apply_overrides' validator
    from orchestrator.config import _Validator

    try:
        case = _Validator(base, str(path), tmp_path, {}, source=None).case()
    except ConfigError as exc:
        assert str(exc).startswith(f"invalid case {path}")
        return
    exp = case.experiment
    assert 0 < exp.step <= MAX_STEP and math.isfinite(exp.stop)
    assert all(not isinstance(v, float) or math.isfinite(v) for v in case.parameters.values()), \
        json.dumps(case.parameters, default=str)


def test_a_pace_slower_than_the_bound_is_refused(native_fmu, tmp_path):
    from orchestrator.limits import MIN_REALTIME_FACTOR

    path = case_file("case1_normal", native_fmu, tmp_path)
    assert "exchange.realtime_factor (from --realtime) = 1e-300: expected 0 (as fast as possible) or a factor >= " \
           "0.001" in refused(path, realtime=1e-300)
    assert load_case(path, realtime=MIN_REALTIME_FACTOR).exchange.realtime_factor == MIN_REALTIME_FACTOR


def test_a_ramp_over_every_point_sets_each_value_once(native_fmu, tmp_path):
    """Ramps are computed as the loop reaches each point (no table with a value per point, which
    for a ramp over ten million points held ten million entries).  Real runs with ramps:
    tests/test_orchestrator_ramp_noise.py; here the values the loop sets, in the case's order."""
    from orchestrator.run import _actions, _schedule

    extra = ('[[events]]\ntype = "ramp"\nvariable = "L2"\nfrom = 1.0\nto = 1.1\nstart = 0.0\nend = 2.0\n'
             '[[events]]\ntype = "step"\ntime = 1.0\nvariable = "L3"\nvalue = 4.05\n')
    path = case_file("case1_normal", native_fmu, tmp_path, stop=2.0, extra=extra)
    case = load_case(path)
    steps, timed = _schedule(case)
    n = case.experiment.n_steps
    values = [_actions(k, timed, n) for k in range(n + 1)]
    assert values[0] == [("L2", 1.0)] and values[n] == [("L2", 1.1)]
    assert values[100] == [("L2", 1.05), ("L3", 4.05)]          # the case's order: ramp, then step
    assert steps == {100: [("L3", 4.05)]}


def test_a_case_file_nested_too_deeply_is_refused(native_fmu, tmp_path):
    """tomllib recurses once per level of nested arrays: 5000 levels raised RecursionError
    (a traceback in fourbar-run, found by benchmarks/fuzz_inputs.py)."""
    path = case_file("case1_normal", native_fmu, tmp_path)
    path.write_text(path.read_text() + "\ndeep = " + "[" * 5000 + "]" * 5000 + "\n")
    assert "nested too deeply to be a case file" in refused(path)


@pytest.mark.parametrize("kind", ["fifo", "directory", "huge"])
def test_a_case_path_that_is_no_case_file_is_refused_without_reading_it(kind, native_fmu, tmp_path):
    """A FIFO would block the reader for ever; a directory or a 2 MB file is no case file."""
    path = tmp_path / "case.toml"
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "directory":
        path.mkdir()
    else:
        path.write_text("# " + "x" * (2 << 20) + "\n")
    message = refused(path)
    assert {"fifo": "is a FIFO", "directory": "is a directory", "huge": "larger than"}[kind] in message, message

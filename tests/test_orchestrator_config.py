"""Case files: the shipped cases reproduce Table 1; every invalid example is rejected by
`fourbar-run` with exit code 2 and its own message (file, field, value, expectation),
before anything is written; --set/--stop/--realtime are validated like the file."""
from __future__ import annotations

import dataclasses
import json
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from orchestrator import (Case, ConfigError, RampEvent, StepEvent, apply_overrides, load_case)
from orchestrator.cli import main
from support import case_file
from support import REPO

TABLE1 = {"L1": 3.0, "L2": 1.0, "L3": 4.0, "L4": 2.5, "m2": 1.0, "m3": 1.0, "m4": 1.0, "g": 9.81,
          "theta2_start": 0.5235987755982988, "omega2_start": 0.0, "rtol": 1e-9, "atol": 1e-6}


# --------------------------------------------------------------------------- shipped cases

@pytest.mark.parametrize("name", ["case1_normal", "case2_fault_L2", "case3_ramp_noise"])
def test_shipped_cases_reproduce_table1(name):
    raw = tomllib.loads((REPO / "cases" / f"{name}.toml").read_text())
    assert raw["fmu"] == "../build/FourBar.fmu"
    assert raw["parameters"] == TABLE1
    assert raw["experiment"] == {"start": 0.0, "stop": 100.0, "step": 0.01, "tolerance": 1e-9}
    assert raw["name"] == name


def test_shipped_cases_load(fourbar_fmu, tmp_path):
    case1 = load_case(case_file("case1_normal", fourbar_fmu, tmp_path))
    case2 = load_case(case_file("case2_fault_L2", fourbar_fmu, tmp_path))
    case3 = load_case(case_file("case3_ramp_noise", fourbar_fmu, tmp_path))
    assert case1.events == () and case1.fault_time is None and case1.noise is None
    assert case2.events == (StepEvent(time=10.0, variable="L2", value=1.1),)
    assert case2.fault_time == 10.0
    assert case2.experiment.n_steps == 10_000
    assert case2.outputs == ("x2", "y2", "x3", "y3", "x4", "y4")
    assert case2.exchange.flush_interval == 1.0 and case2.exchange.realtime_factor == 0.0
    assert case3.events == (RampEvent(variable="L2", from_=1.0, to=1.05, start=20.0, end=30.0),)
    assert case3.fault_time == 20.0
    assert case3.noise.std == {"x2": 0.005} and isinstance(case3.noise.seed, int)
    assert case2.fmu == fourbar_fmu.resolve()
    with pytest.raises(dataclasses.FrozenInstanceError):
        case2.name = "other"


def test_overrides_are_validated_like_the_file(fourbar_fmu, tmp_path):
    case = load_case(case_file("case2_fault_L2", fourbar_fmu, tmp_path))
    changed = apply_overrides(case, overrides={"L2": 1.05, "integrator": "RK45"}, stop=20.0, realtime=2.0)
    assert changed.parameters["L2"] == 1.05 and changed.parameters["integrator"] == "RK45"
    assert changed.experiment.stop == 20.0 and changed.exchange.realtime_factor == 2.0
    assert case.parameters["L2"] == 1.0            # the original is untouched (frozen)
    with pytest.raises(ConfigError) as info:
        apply_overrides(case, overrides={"L2": "long", "nope": 1}, stop=5.0)
    text = str(info.value)
    assert 'parameters.L2 (from --set L2) = "long": expected a number in m' in text
    assert "parameters.nope (from --set nope) = 1: FourBar.fmu has no variable named 'nope'" in text
    assert "events[0].time = 10.0: outside the experiment: expected a time in [0.0, 5.0) s " \
           "(experiment.stop from --stop)" in text
    assert len(info.value.problems) == 3
    # A Case edited in code is checked too.
    bad = dataclasses.replace(case, events=(StepEvent(time=10.005, variable="L2", value=1.1),))
    with pytest.raises(ConfigError, match="not on the communication grid"):
        apply_overrides(bad)


# --------------------------------------------------------------------------- invalid examples

BASE = """\
fmu = {fmu}
[experiment]
start = 0.0
stop = 2.0
step = 0.01
"""

STEP = """
[[events]]
type = "step"
time = {time}
variable = "{var}"
value = {value}
"""

RAMP = """
[[events]]
type = "ramp"
variable = "{var}"
from = 1.0
to = 1.05
start = {start}
end = {end}
"""

# (id, case-file text appended to BASE ("^": put before it, "!": a whole file from SPECIAL),
#  expected message parts)
INVALID = [
    ("unknown-top-key", '^colour = "red"\n',
     ["colour: unknown key; expected one of: name, description, fmu, fmi_type, experiment"]),
    ("unknown-key-suggestion", "",  # replaced below: tolrance in [experiment]
     ["experiment.tolrance: unknown key; did you mean 'tolerance'?"]),
    ("wrong-type-string", "!stop-string",
     ['experiment.stop = "100": expected a number in s, got a string']),
    ("wrong-type-bool", "!stop-bool", ["experiment.stop = true: expected a number in s, got a boolean"]),
    ("not-finite", "!stop-nan", ["experiment.stop = nan: expected a finite number"]),
    ("stop-before-start", "!stop-before-start", ["experiment.stop = 1.0: expected a time after experiment.start = 2.0 s"]),
    ("step-not-positive", "!step-zero", ["experiment.step = 0.0: expected a number > 0 s"]),
    ("stop-off-grid", "!stop-off-grid", ["experiment.stop = 2.0: (stop - start)/step = 66.6666667 is not a whole "
                                         "number of steps of 0.03 s"]),
    ("missing-experiment", "!no-experiment", ["experiment: missing; expected a [experiment] table"]),
    ("missing-fmu-file", "!fmu-missing", ['fmu = "no/such/FourBar.fmu": file not found (resolved to ']),
    ("not-an-fmu", "!fmu-not-zip", ['fmu = "notes.txt": not a readable FMU']),
    ("unknown-parameter", "[parameters]\nL9 = 1.0\n",
     ["parameters.L9 = 1.0: FourBar.fmu has no variable named 'L9'"]),
    ("parameter-typo", "[parameters]\nL_2 = 1.0\n", ["has no variable named 'L_2'; did you mean 'L2'?"]),
    ("parameter-is-output", "[parameters]\nx2 = 0.5\n",
     ["parameters.x2 = 0.5: x2 is an output (continuous) of FourBar.fmu and has no settable start value"]),
    ("parameter-wrong-type", '[parameters]\nL2 = "long"\n', ['parameters.L2 = "long": expected a number in m, got a string']),
    ("string-parameter-wrong-type", "[parameters]\nintegrator = 3\n",
     ["parameters.integrator = 3: integrator is String; expected a string, got an integer"]),
    ("unknown-output", '[outputs]\nvariables = ["x2", "x9"]\n',
     ['outputs.variables[1] = "x9": FourBar.fmu has no variable named \'x9\'']),
    ("duplicate-output", '[outputs]\nvariables = ["x2", "x2"]\n',
     ['outputs.variables[1] = "x2": listed twice']),
    ("time-as-output", '[outputs]\nvariables = ["time", "x2"]\n', ['outputs.variables[0] = "time": \'time\' is the first column']),
    ("event-after-stop", STEP.format(time=5.0, var="L2", value=1.1),
     ["events[0].time = 5.0: outside the experiment: expected a time in [0.0, 2.0) s"]),
    ("event-at-stop", STEP.format(time=2.0, var="L2", value=1.1),
     ["events[0].time = 2.0: outside the experiment: expected a time in [0.0, 2.0) s"]),
    ("event-before-start", STEP.format(time=-1.0, var="L2", value=1.1),
     ["events[0].time = -1.0: outside the experiment"]),
    ("event-off-grid", STEP.format(time=1.005, var="L2", value=1.1),
     ["events[0].time = 1.005: not on the communication grid start + k*step (step 0.01 s); expected e.g. 1 or 1.01 "
      "(off-grid events are rejected)"]),
    ("event-non-tunable", STEP.format(time=1.0, var="theta2_start", value=0.1),
     ['events[0].variable = "theta2_start": theta2_start is a parameter (fixed) and cannot change during a run; '
      "expected a tunable parameter or an input of FourBar.fmu: L1, L2, L3, L4, m2, m3, m4, g"]),
    ("event-on-output", STEP.format(time=1.0, var="x2", value=0.1),
     ['events[0].variable = "x2": x2 is an output (continuous) and cannot change during a run']),
    ("event-unknown-variable", STEP.format(time=1.0, var="L7", value=0.1),
     ['events[0].variable = "L7": FourBar.fmu has no variable named \'L7\'']),
    ("event-value-type", STEP.format(time=1.0, var="L2", value='"big"'),
     ['events[0].value = "big": expected a number in m, got a string']),
    ("event-missing-value", '[[events]]\ntype = "step"\ntime = 1.0\nvariable = "L2"\n',
     ["events[0].value: missing; expected the new value"]),
    ("event-unknown-type", '[[events]]\ntype = "pulse"\n', ['events[0].type = "pulse": expected "step" or "ramp"']),
    ("event-unknown-key", '[[events]]\ntype = "step"\ntime = 1.0\nvariable = "L2"\nvalue = 1.1\nduration = 2\n',
     ["events[0].duration: unknown key; expected one of: type, time, variable, value"]),
    ("ramp-end-before-start", RAMP.format(var="L2", start=1.5, end=1.0),
     ["events[0].end = 1.0: expected a time after events[0].start = 1.5 s"]),
    ("ramp-past-stop", RAMP.format(var="L2", start=1.0, end=3.0),
     ["events[0].end = 3.0: outside the experiment: expected a time in [0.0, 2.0] s"]),
    ("ramp-off-grid", RAMP.format(var="L2", start=1.0, end=1.555),
     ["events[0].end = 1.555: not on the communication grid"]),
    ("ramp-non-tunable", RAMP.format(var="rtol", start=1.0, end=1.5),
     ['events[0].variable = "rtol": rtol is a parameter (fixed) and cannot change during a run']),
    ("overlapping-events", STEP.format(time=1.0, var="L2", value=1.1) + RAMP.format(var="L2", start=0.5, end=1.5),
     ["events[0] and events[1] overlap: both set L2 at t = 1.0 s"]),
    ("chained-ramps-must-agree", RAMP.format(var="L2", start=0.5, end=1.0) + RAMP.format(var="L2", start=1.0, end=1.5),
     ["events[0] and events[1] overlap: both set L2 at t = 1.0 s"]),
    ("noise-negative-std", '[noise]\nseed = 1\nstd = { x2 = -0.005 }\n', ["noise.std.x2 = -0.005: expected a number >= 0 m"]),
    ("noise-not-an-output", '[noise]\nseed = 1\nstd = { theta2 = 0.1 }\n',
     ["noise.std.theta2 = 0.1: theta2 is not an output of this case; expected one of: x2, y2, x3, y3, x4, y4"]),
    ("noise-without-seed", '[noise]\nstd = { x2 = 0.005 }\n', ["noise.seed: missing; expected an integer >= 0"]),
    ("noise-bad-seed", '[noise]\nseed = -3\nstd = { x2 = 0.005 }\n', ["noise.seed = -3: expected an integer >= 0"]),
    ("flush-not-positive", "[exchange]\nflush_interval = 0\n", ["exchange.flush_interval = 0.0: expected a number > 0 s"]),
    ("realtime-negative", "[exchange]\nrealtime_factor = -1\n", ["exchange.realtime_factor = -1.0: expected a number >= 0"]),
    ("bad-name", '^name = "two words"\n', ['name = "two words": expected a non-empty string of letters, digits']),
    ("invalid-toml", "!invalid-toml", ["not valid TOML"]),
]

SPECIAL = {
    "stop-string": 'fmu = {fmu}\n[experiment]\nstop = "100"\nstep = 0.01\n',
    "stop-bool": "fmu = {fmu}\n[experiment]\nstop = true\nstep = 0.01\n",
    "stop-nan": "fmu = {fmu}\n[experiment]\nstop = nan\nstep = 0.01\n",
    "stop-before-start": "fmu = {fmu}\n[experiment]\nstart = 2.0\nstop = 1.0\nstep = 0.01\n",
    "step-zero": "fmu = {fmu}\n[experiment]\nstop = 2.0\nstep = 0\n",
    "stop-off-grid": "fmu = {fmu}\n[experiment]\nstop = 2.0\nstep = 0.03\n",
    "no-experiment": "fmu = {fmu}\n",
    "fmu-missing": 'fmu = "no/such/FourBar.fmu"\n[experiment]\nstop = 2.0\nstep = 0.01\n',
    "fmu-not-zip": 'fmu = "notes.txt"\n[experiment]\nstop = 2.0\nstep = 0.01\n',
    "invalid-toml": "fmu = {fmu}\n[experiment\nstop = 2.0\n",
}


def _case_text(case_id: str, body: str, fmu: Path) -> str:
    fmu_toml = json.dumps(str(fmu))
    if body.startswith("!"):
        return SPECIAL[body[1:]].replace("{fmu}", fmu_toml)
    if body.startswith("^"):               # top-level keys go before the first table
        return body[1:] + BASE.replace("{fmu}", fmu_toml)
    if case_id == "unknown-key-suggestion":
        return BASE.replace("{fmu}", fmu_toml).replace("step = 0.01\n", "step = 0.01\ntolrance = 1e-9\n")
    return BASE.replace("{fmu}", fmu_toml) + body


@pytest.mark.parametrize("case_id, body, expected", INVALID, ids=[c[0] for c in INVALID])
def test_invalid_case_gets_its_message_and_exit_2(case_id, body, expected, fourbar_fmu, tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("not an FMU\n")
    path = tmp_path / "bad.toml"
    path.write_text(_case_text(case_id, body, fourbar_fmu))
    out = tmp_path / "out"
    code = main([str(path), "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 2, captured.err
    assert "Traceback" not in captured.err
    assert captured.err.startswith("fourbar-run: error: invalid case ")
    lines = captured.err.splitlines()[1:]
    for part in expected:
        # Each problem line names the file, then the field, the value and the expectation.
        matching = [line for line in lines if part in line]
        assert matching, f"{part!r} not in:\n{captured.err}"
        assert all(line.strip().startswith(f"{path}: ") for line in matching)
    assert not out.exists()                # nothing ran, nothing written


def test_every_problem_is_listed_at_once(fourbar_fmu, tmp_path, capsys):
    path = tmp_path / "many.toml"
    path.write_text('colour = 1\n' + BASE.replace("{fmu}", json.dumps(str(fourbar_fmu)))
                    + STEP.format(time=5.0, var="L2", value=1.1)
                    + STEP.format(time=1.0, var="theta2_start", value=0.1)
                    + '[noise]\nseed = 1\nstd = { x2 = -1.0 }\n')
    assert main([str(path)]) == 2
    err = capsys.readouterr().err
    assert err.splitlines()[0] == f"fourbar-run: error: invalid case {path}: 4 problems"
    for part in ("colour: unknown key", "events[0].time = 5.0: outside", "events[1].variable = \"theta2_start\"",
                 "noise.std.x2 = -1.0"):
        assert part in err


@pytest.mark.parametrize("argv_tail, expected", [
    (["--set", "L2"], "--set 'L2': expected NAME=VALUE"),
    (["--set", "L2=abc"], 'parameters.L2 (from --set L2) = "abc": expected a number in m, got a string'),
    (["--set", "speed=3"], "parameters.speed (from --set speed) = 3: FourBar.fmu has no variable named 'speed'"),
    (["--set", "x2=0.1"], "x2 is an output (continuous) of FourBar.fmu and has no settable start value"),
    (["--stop", "5"], "events[0].time = 10.0: outside the experiment: expected a time in [0.0, 5.0) s "
                      "(experiment.stop from --stop)"),
    (["--stop", "20.005"], "experiment.stop (from --stop) = 20.005: (stop - start)/step = 2000.5 is not a whole number"),
    (["--realtime", "-1"], "exchange.realtime_factor (from --realtime) = -1.0: expected a number >= 0"),
    (["--stop", "abc"], "argument --stop: invalid float value: 'abc'"),
    (["--frobnicate"], "unrecognized arguments: --frobnicate"),
])
def test_bad_command_line_gets_exit_2(argv_tail, expected, fourbar_fmu, tmp_path, capsys):
    path = case_file("case2_fault_L2", fourbar_fmu, tmp_path)
    out = tmp_path / "out"
    code = main([str(path), "--out", str(out), *argv_tail])
    err = capsys.readouterr().err
    assert code == 2, err
    assert expected in err
    assert "Traceback" not in err
    assert not out.exists()


def test_missing_case_file_exit_2(tmp_path, capsys):
    missing = tmp_path / "nope.toml"
    assert main([str(missing)]) == 2
    assert f"{missing}: case file not found" in capsys.readouterr().err


def test_help_and_version(capsys):
    assert main(["--version"]) == 0
    assert re.fullmatch(r"fourbar-run \S+\n", capsys.readouterr().out)
    assert main(["--help"]) == 0
    text = capsys.readouterr().out
    for option in ("--out", "--stop", "--realtime", "--set", "--quiet", "--version", "exit status"):
        assert option in text


def test_cli_summary_line_and_set(fourbar_fmu, tmp_path, capsys):
    path = case_file("case1_normal", fourbar_fmu, tmp_path)
    out = tmp_path / "out"
    code = main([str(path), "--out", str(out), "--stop", "0.5", "--set", "L2=1.05"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    lines = captured.out.splitlines()
    assert len(lines) == 1 and lines[0].startswith("case1_normal: finished, 51 rows, t = 0 .. 0.5 s")
    assert captured.err == ""              # no progress bar: stderr is not a terminal here
    record = json.loads((out / "run.json").read_text())
    assert record["parameters"]["L2"]["start"] == 1.05 and record["experiment"]["stop"] == 0.5
    assert record["parameters"]["L2"]["source"] == "set" and record["parameters"]["L1"]["source"] == "case"
    assert main([str(path), "--out", str(out), "--stop", "0.1", "--quiet"]) == 0
    assert capsys.readouterr().out == ""


def test_importing_the_cli_is_light():
    """`fourbar-run --help` must not pay for FMPy/numpy: heavy imports happen in the handler."""
    code = "import sys, orchestrator.cli; print(sorted(m for m in ('fmpy', 'numpy', 'pandas', 'tqdm') if m in sys.modules))"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO)
    assert result.stdout.strip() == "[]"


def test_case_dataclass_round_trip(fourbar_fmu, tmp_path):
    case = load_case(case_file("case3_ramp_noise", fourbar_fmu, tmp_path))
    assert isinstance(case, Case)
    assert apply_overrides(case) == case       # as_dict -> validate gives the same case back
    assert case.as_dict()["events"] == [{"type": "ramp", "variable": "L2", "from": 1.0, "to": 1.05,
                                         "start": 20.0, "end": 30.0}]


def test_the_model_description_is_read_once_per_run(fourbar_fmu, tmp_path, monkeypatch):
    """Validation keeps what it read of the FMU (GUID, variables): loading a case and running it
    parses the model description once, and a rebuilt FMU file is read again."""
    import fmpy
    from orchestrator import run_case

    calls = []
    real = fmpy.read_model_description

    def counting(filename, *args, **kwargs):
        calls.append(str(filename))
        return real(filename, *args, **kwargs)

    monkeypatch.setattr(fmpy, "read_model_description", counting)
    case = load_case(case_file("case1_normal", fourbar_fmu, tmp_path))
    assert case.fmu_description.guid == real(str(fourbar_fmu)).guid
    assert "L2" in case.fmu_description.variables
    result = run_case(case, tmp_path / "out", stop=0.05)
    assert result.status == "finished"
    assert len(calls) == 1, calls                  # load_case only; overrides and run.json reuse it
    record = json.loads((tmp_path / "out" / "run.json").read_text())
    assert record["fmu"]["guid"] == case.fmu_description.guid and record["units"]["x2"] == "m"
    # the same file with a new modification time counts as rebuilt: read again
    copy = tmp_path / "copy.fmu"
    copy.write_bytes(Path(fourbar_fmu).read_bytes())
    moved = apply_overrides(case, fmu=copy)
    assert len(calls) == 2 and moved.fmu_description.path == copy.resolve()
    stamp = copy.stat()
    os.utime(copy, ns=(stamp.st_atime_ns, stamp.st_mtime_ns + 1_000_000_000))
    touched = apply_overrides(moved)
    assert len(calls) == 3
    apply_overrides(touched, overrides={"L2": 1.05})  # unchanged since: reused
    assert len(calls) == 3


def test_chained_ramps_sharing_an_end_point_are_accepted(fourbar_fmu, tmp_path):
    path = tmp_path / "chain.toml"
    path.write_text(BASE.replace("{fmu}", json.dumps(str(fourbar_fmu)))
                    + RAMP.format(var="L2", start=0.5, end=1.0)
                    + '\n[[events]]\ntype = "ramp"\nvariable = "L2"\nfrom = 1.05\nto = 1.1\nstart = 1.0\nend = 1.5\n'
                    + STEP.format(time=1.0, var="L3", value=4.1))
    case = load_case(path)
    assert [e.first_time for e in case.events] == [0.5, 1.0, 1.0]
    assert case.fault_time == 0.5

"""The orchestrator is not tied to FourBar: a second, small pythonfmu FMU (built here, in a
child process) with an input, a tunable gain, a fixed offset and an Integer output runs
from a case file; its outputs show exactly which values were set before each doStep."""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from orchestrator import ConfigError, load_case, run_case
from orchestrator.cli import main

STEPPER = textwrap.dedent('''
    from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability
    from pythonfmu.enums import Fmi2Status
    from pythonfmu.variables import Integer, Real


    class Stepper(Fmi2Slave):
        """Echoes what the master set: y = offset + gain*u over the last step, u_seen = u, steps = count."""

        def __init__(self, **kwargs):
            super().__init__(**kwargs)
            self.gain = 1.0
            self.offset = 0.0
            self.u = 0.0
            self.y = 0.0
            self.u_seen = 0.0
            self.t_end = 0.0
            self.steps = 0
            self.register_variable(Real("gain", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
            self.register_variable(Real("offset", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
            self.register_variable(Real("u", causality=Fmi2Causality.input))
            self.register_variable(Real("y", causality=Fmi2Causality.output))
            self.register_variable(Real("u_seen", causality=Fmi2Causality.output))
            self.register_variable(Real("t_end", causality=Fmi2Causality.output))
            self.register_variable(Integer("steps", causality=Fmi2Causality.output, variability=Fmi2Variability.discrete))

        def exit_initialization_mode(self):
            self.y = self.offset
            self.t_end = self._start

        def setup_experiment(self, start_time, stop_time=None, tolerance=None):
            self._start = start_time

        def do_step(self, current_time, step_size):
            if self.gain > 100.0:
                self.log(f"gain = {self.gain} exceeds 100: the actuator saturates", Fmi2Status.error)
                return False
            self.steps += 1
            self.u_seen = self.u
            self.y = self.offset + self.gain * self.u
            self.t_end = current_time + step_size
            return True
''')


@pytest.fixture(scope="module")
def stepper_fmu(tmp_path_factory) -> Path:
    """Stepper.fmu, built by pythonfmu in a child process (keeps this process's sys.modules clean)."""
    tmp = tmp_path_factory.mktemp("stepper")
    script = tmp / "Stepper.py"
    script.write_text(STEPPER)
    subprocess.run([sys.executable, "-c", "import sys; from pythonfmu.builder import FmuBuilder; "
                    "FmuBuilder.build_FMU(sys.argv[1], dest=sys.argv[2])", str(script), str(tmp)],
                   check=True, capture_output=True, timeout=120)
    return tmp / "Stepper.fmu"


CASE = """\
name = "stepper"
fmu = {fmu}

[experiment]
start = 1.0
stop = 3.0
step = 0.1

[parameters]
offset = 0.5

[[events]]
type = "ramp"
variable = "u"
from = 0.0
to = 1.0
start = 1.5
end = 2.0

[[events]]
type = "step"
time = 2.5
variable = "gain"
value = {gain}

[outputs]
variables = ["y", "u_seen", "t_end", "steps"]

[exchange]
flush_interval = 0.5
"""


def write_case(tmp: Path, fmu: Path, gain: float = 3.0) -> Path:
    path = tmp / "stepper.toml"
    path.write_text(CASE.format(fmu=json.dumps(str(fmu)), gain=gain))
    return path


def test_any_cosimulation_fmu_runs(stepper_fmu, tmp_path):
    result = run_case(write_case(tmp_path, stepper_fmu), tmp_path / "out")
    assert result.ok, result.error
    lines = result.exchange_path.read_text().splitlines()
    assert lines[0] == "time,y,u_seen,t_end,steps"
    rows = [line.split(",") for line in lines[1:]]
    assert len(rows) == 21                                 # 1.0 .. 3.0 s by 0.1 s
    for k, (t, y, u_seen, t_end, steps) in enumerate(rows):
        assert float(t) == 1.0 + k * 0.1
        assert steps == str(k)                             # Integer output written as an integer
        assert float(t_end) == float(t)                    # doStep(t_k, t_(k+1) - t_k) ends exactly on the grid
        # Row k shows what was set before doStep k-1, i.e. at t_(k-1) (grid index j = k - 1):
        j = k - 1
        u = 0.0 if j < 5 else (1.0 if j >= 10 else 0.0 * (1 - (j - 5) / 5) + 1.0 * ((j - 5) / 5))
        gain = 3.0 if j >= 15 else 1.0                     # the gain step at 2.5 s = grid index 15
        assert float(u_seen) == (u if k > 0 else 0.0)
        assert float(y) == (0.5 + gain * u if k > 0 else 0.5)
    by_time = {round(float(r[0]), 9): r for r in rows}
    assert by_time[2.5][1] == "1.5" and by_time[2.6][1] == "3.5"   # event row: before; next row: after
    assert by_time[1.6][2] == "0.0" and by_time[1.7][2] == "0.2"   # ramp starts at 1.5 (from = 0.0)
    record = json.loads(result.run_json_path.read_text())
    assert record["fmu"]["model_name"] == "Stepper"
    assert record["fault_time"] == 1.5 and record["status"] == "finished"
    assert record["outputs"] == ["y", "u_seen", "t_end", "steps"]


def test_generic_fmu_failure_carries_its_log_message(stepper_fmu, tmp_path, capsys):
    out = tmp_path / "out"
    assert main([str(write_case(tmp_path, stepper_fmu, gain=150.0)), "--out", str(out)]) == 1
    record = json.loads((out / "run.json").read_text())
    assert record["status"] == "failed"
    assert "fmi2DoStep(t = 2.5 s" in record["error"]
    assert "gain = 150.0 exceeds 100: the actuator saturates" in record["error"]
    assert record["rows_written"] == 16                   # rows 1.0 .. 2.5 s
    assert "gain = 150.0 exceeds 100" in capsys.readouterr().err


def test_generic_fmu_is_validated_against_its_own_variables(stepper_fmu, tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(CASE.format(fmu=json.dumps(str(stepper_fmu)), gain="true")
                    .replace('variable = "u"', 'variable = "offset"')
                    .replace('"steps"]', '"steps", "x2"]'))
    with pytest.raises(ConfigError) as info:
        load_case(path)
    problems = "\n".join(info.value.problems)
    assert 'events[0].variable = "offset": offset is a parameter (fixed) and cannot change during a run; ' \
           "expected a tunable parameter or an input of Stepper.fmu: gain, u" in problems
    assert "events[1].value = true: expected a number, got a boolean" in problems
    assert "outputs.variables[4] = \"x2\": Stepper.fmu has no variable named 'x2'" in problems
    # Without [outputs], the default (the four-bar's x2 ... y4) does not exist in this FMU.
    path.write_text(CASE.format(fmu=json.dumps(str(stepper_fmu)), gain=3.0)
                    .replace('[outputs]\nvariables = ["y", "u_seen", "t_end", "steps"]\n', ""))
    with pytest.raises(ConfigError) as info:
        load_case(path)
    assert info.value.problems == (
        "outputs: missing, and the default outputs x2, y2, x3, y3, x4, y4 are not all variables of Stepper.fmu "
        "(lacking: x2, y2, x3, y3, x4, y4); expected [outputs] variables = [...] naming outputs of Stepper.fmu, "
        "e.g. y, u_seen, t_end, steps",)


def test_step_through_steps_sets_and_reads_like_single_calls(stepper_fmu):
    """The replay's fast loop (FmuInstance.step_through): a change set before its step, the
    last value held, each row read after its step, and a failing step reported with the
    FMU's own message, as fmi2DoStep through FMPy would."""
    import numpy as np

    from orchestrator.case import describe_fmu
    from orchestrator.instance import FmuError, instance_for

    with instance_for(describe_fmu(stepper_fmu), "fast") as fmu:
        fmu.setup_experiment(0.0, 1.0, None)
        fmu.set_values([("offset", 0.5), ("u", 2.0)])
        fmu.enter_initialization_mode()
        fmu.exit_initialization_mode()
        out = np.full((4, 2), np.nan)
        fmu.step_through([0.0, 0.1, 0.2, 0.3, 0.4], ("y", "t_end"), out, changes=("gain", [1.0, 3.0]))
        assert out[:, 0].tolist() == [2.5, 6.5, 6.5, 6.5]         # y = 0.5 + gain * 2, gain 1 then 3
        assert out[:, 1] == pytest.approx([0.1, 0.2, 0.3, 0.4], abs=1e-15)
        assert fmu.reader(["steps"])() == [4]
        with pytest.raises(FmuError, match=r"fmi2DoStep\(t = 0\.4 s.*gain = 150\.0 exceeds 100"):
            fmu.step_through([0.4, 0.5], ("y",), np.empty((1, 1)), changes=("gain", [150.0]))

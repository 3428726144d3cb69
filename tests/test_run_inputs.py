"""fourbar-run drives FMU inputs from a case file's ``[inputs]`` (orchestrator.input_signals).

A small pythonfmu FMU (built once, in a child process) echoes what the master set: ``u_seen``
is the input ``u`` at the start of the last step and ``x`` integrates the held input, so the
rows show exactly which value was set before each doStep.  Checked here: the values set at
each step's start, the input columns of exchange.csv, run.json's record of the signals, and
the refusals (exit 2, nothing written).
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from numpy.testing import assert_allclose

from fourbar_common.contract.run_record import read_run_record
from orchestrator import load_case, run_case
from support import FOURBAR_RUN, REPO

ECHO = textwrap.dedent('''
    from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability
    from pythonfmu.variables import Real


    class Echo(Fmi2Slave):
        """u_seen = u over the last step; x = integral of u, held over each step; y = gain*u."""

        def __init__(self, **kwargs):
            super().__init__(**kwargs)
            self.gain = 1.0
            self.u = 0.0
            self.w = 0.0
            self.u_seen = 0.0
            self.x = 0.0
            self.register_variable(Real("gain", causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
            self.register_variable(Real("u", causality=Fmi2Causality.input))
            self.register_variable(Real("w", causality=Fmi2Causality.input))
            self.register_variable(Real("u_seen", causality=Fmi2Causality.output))
            self.register_variable(Real("x", causality=Fmi2Causality.output))

        def exit_initialization_mode(self):
            self.u_seen = self.u

        def do_step(self, current_time, step_size):
            self.u_seen = self.u
            self.x += self.gain * self.u * step_size
            return True
''')


@pytest.fixture(scope="module")
def echo_fmu(tmp_path_factory) -> Path:
    """Echo.fmu, built by pythonfmu in a child process (keeps this process's sys.modules clean)."""
    tmp = tmp_path_factory.mktemp("echo")
    script = tmp / "Echo.py"
    script.write_text(ECHO)
    subprocess.run([sys.executable, "-c", "import sys; from pythonfmu.builder import FmuBuilder; "
                    "FmuBuilder.build_FMU(sys.argv[1], dest=sys.argv[2])", str(script), str(tmp)],
                   check=True, capture_output=True, timeout=120)
    return tmp / "Echo.fmu"


def write_case(folder: Path, fmu: Path, inputs: str, extra: str = "") -> Path:
    path = folder / "echo.toml"
    path.write_text(f'name = "echo"\nfmu = {json.dumps(str(fmu))}\n{extra}\n'
                    f'[experiment]\nstart = 0.0\nstop = 2.0\nstep = 0.1\n\n'
                    f'[outputs]\nvariables = ["u_seen", "x"]\n\n[inputs]\n{inputs}\n')
    return path


def run_cli(*args) -> subprocess.CompletedProcess:
    return subprocess.run([FOURBAR_RUN, *map(str, args)], capture_output=True, text=True, timeout=120, cwd=REPO)


def test_inputs_are_set_at_each_step_start_and_written_after_the_outputs(echo_fmu, tmp_path):
    case = write_case(tmp_path, echo_fmu, 'u = { type = "sine", amplitude = 2.0, frequency = 0.5, offset = 1.0 }\n'
                                          'w = { type = "step", before = 0.0, after = 3.0, time = 1.0 }\n')
    result = run_case(load_case(case), out_dir=tmp_path / "out")
    assert result.status == "finished"
    data = pd.read_csv(result.exchange_path)
    assert list(data.columns) == ["time", "u_seen", "x", "u", "w"]
    t = data["time"].to_numpy()
    u = 1.0 + 2.0 * np.sin(np.pi * t)
    # the input columns: each signal's value at the row's time, written exactly (17 digits)
    assert_allclose(data["u"], u, rtol=0, atol=1e-15)       # the same formula, round-off only
    assert list(data["w"]) == [0.0 if tk < 1.0 - 1e-9 else 3.0 for tk in t]
    # the FMU saw u(t_k) over the step from t_k: u_seen at row k+1 is u at row k; row 0 is the
    # value set before initialisation, u(start)
    assert_allclose(data["u_seen"][1:], u[:-1], rtol=0, atol=1e-15)
    assert data["u_seen"][0] == u[0]
    # x integrates the held input: the left Riemann sum
    assert_allclose(data["x"], np.concatenate([[0.0], np.cumsum(u[:-1] * 0.1)]), rtol=0, atol=1e-12)
    record = read_run_record(result.run_json_path)
    assert [(i.name, dict(i.signal)) for i in record.inputs] == [
        ("u", {"type": "sine", "amplitude": 2.0, "frequency": 0.5, "phase": 0.0, "offset": 1.0}),
        ("w", {"type": "step", "before": 0.0, "after": 3.0, "time": 1.0})]
    assert record.input_derivatives == 0          # pythonfmu FMUs cannot interpolate inputs
    assert record.outputs == ("u_seen", "x", "u", "w")


def test_a_csv_column_and_a_table_drive_inputs_with_steps_at_repeated_times(echo_fmu, tmp_path):
    (tmp_path / "drive.csv").write_text("t,torque\n0,0\n1,1\n1,-1\n2,0\n")
    case = write_case(tmp_path, echo_fmu, 'u = { type = "csv", file = "drive.csv", time = "t", column = "torque" }\n'
                                          'w = { type = "table", rows = [[0.0, 5.0], [0.5, 5.0], [0.5, 1.0]] }\n')
    result = run_case(load_case(case), out_dir=tmp_path / "out")
    data = pd.read_csv(result.exchange_path)
    t = data["time"].to_numpy()
    expected_u = np.where(t < 1.0 - 1e-9, t, t - 2.0)          # up to 1 at 1 s, then from -1 back to 0
    assert_allclose(data["u"], expected_u, rtol=0, atol=1e-12)  # interpolation round-off
    assert_allclose(data["u_seen"][1:], expected_u[:-1], rtol=0, atol=1e-12)
    assert list(data["w"]) == [5.0 if tk < 0.5 - 1e-9 else 1.0 for tk in t]
    signal = read_run_record(result.run_json_path).inputs[0].signal
    assert signal["type"] == "csv" and signal["rows"] == 4 and signal["column"] == "torque"


def test_a_constant_input_and_a_fault_on_a_parameter_run_together(echo_fmu, tmp_path):
    """Faults still change parameters between steps while an input is driven."""
    case = write_case(tmp_path, echo_fmu, "u = 0.5\n",
                      extra='[[events]]\ntype = "step"\ntime = 1.0\nvariable = "gain"\nvalue = 2.0\n')
    result = run_case(load_case(case), out_dir=tmp_path / "out")
    data = pd.read_csv(result.exchange_path)
    # x = 0.05 per step before 1.0 s, 0.1 per step after (gain 2): 0.5 + 1.0 at 2 s
    assert_allclose(data["x"].iloc[-1], 1.5, rtol=0, atol=1e-12)
    assert list(data["u"]) == [0.5] * 21


@pytest.mark.parametrize("inputs, extra, expected", [
    ("tau = 1.0\n", "", "inputs.tau = 1.0: Echo.fmu has no input named 'tau'; its inputs: u, w"),
    ("u = 1.0\n", "[parameters]\nu = 2.0\n",
     "parameters.u = 2.0: u is given in [inputs] already; expected each input given once, in [inputs]"),
    ("u = 1.0\n", '[[events]]\ntype = "step"\ntime = 1.0\nvariable = "u"\nvalue = 2.0\n',
     'events[0].variable = "u": u is given in [inputs] already'),
    ("u = 1.0\n", "input_derivatives = true\n",
     "input_derivatives = true: Echo.fmu does not say canInterpolateInputs (FMI 2.0 co-simulation); "
     "expected false or leave it out"),
    ("u = 1.0\n", "input_derivatives = 3\n", "input_derivatives = 3: expected true, false, or the order 0, 1 or 2"),
    ('u = { type = "ramp", from = 0.0, to = 1.0, start = 0.5, duration = -1.0 }\n', "",
     "inputs.u.duration = -1.0: expected a duration > 0 s"),
    ('u = { type = "csv", file = "short.csv", column = "u" }\n', "",
     "inputs.u.file = \"short.csv\" ("),
])
def test_bad_inputs_exit_2_naming_the_field_and_nothing_is_written(echo_fmu, tmp_path, inputs, extra, expected):
    (tmp_path / "short.csv").write_text("time,u\n0,1\n1.5,2\n")
    case = write_case(tmp_path, echo_fmu, inputs, extra=extra)
    out = tmp_path / "out"
    out.mkdir()
    (out / "exchange.csv").write_text("a previous run\n")
    proc = run_cli(case, "--out", out)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr
    assert any(line.strip().startswith(f"{case}: ") and expected in line for line in proc.stderr.splitlines()), \
        proc.stderr
    assert (out / "exchange.csv").read_text() == "a previous run\n"       # nothing already written is lost
    assert sorted(p.name for p in out.iterdir()) == ["exchange.csv"]


def test_the_inputs_section_in_help():
    proc = run_cli("--help")
    assert proc.returncode == 0 and "[inputs]" in proc.stdout, proc.stdout


def test_overrides_keep_the_inputs(echo_fmu, tmp_path):
    """apply_overrides validates Case.as_dict again: each signal reads back as it was."""
    from orchestrator import apply_overrides

    (tmp_path / "drive.csv").write_text("time,torque\n0,0\n2,1\n")
    case = load_case(write_case(tmp_path, echo_fmu, 'u = { type = "ramp", from = 0.0, to = 1.0, start = 0.3, '
                                                    'duration = 0.7 }\n'
                                                    'w = { type = "csv", file = "drive.csv", column = "torque" }\n'))
    again = apply_overrides(case, overrides={"gain": 2.0})
    assert again.inputs == case.inputs and again.parameters == {"gain": 2.0}



# ---------------------------------------------------------------------------- a mechanism with inputs
#
# tests/mechanisms/input_pendulum.toml (the inputs engineer's test mechanism): a slider on a
# guide carrying a double pendulum, pushed by inputs F_P (N, along the guide), tau_A, tau_arm,
# push, each with a [[loads]] twin driven by a parameter (F_P_load, ...).

INPUT_PENDULUM = REPO / "tests" / "mechanisms" / "input_pendulum.toml"
PENDULUM_OUTPUTS = ("x1", "theta2", "theta3", "vx1", "omega2", "omega3")


@pytest.fixture(scope="module")
def pendulum_native(mechanism_fmus) -> Path:
    return mechanism_fmus.get(str(INPUT_PENDULUM), "native")


def pendulum_case(folder: Path, fmu: Path, name: str, *, step: float, stop: float = 2.0, inputs: str = "",
                  extra: str = "", parameters: str = "") -> Path:
    """A case of the input pendulum at tight integrator tolerances (its rtol/atol parameters)."""
    path = folder / f"{name}.toml"
    path.write_text(f'name = "{name}"\nfmu = {json.dumps(str(fmu))}\n{extra}\n'
                    f'[experiment]\nstart = 0.0\nstop = {stop!r}\nstep = {step!r}\ntolerance = 1e-10\n\n'
                    f'[parameters]\nrtol = 1e-10\natol = 1e-12\n{parameters}\n'
                    f'[outputs]\nvariables = {json.dumps(list(PENDULUM_OUTPUTS))}\ndrawing = false\n\n'
                    f'[inputs]\n{inputs}\n')
    return path


def pendulum_run(folder: Path, fmu: Path, name: str, **settings) -> pd.DataFrame:
    result = run_case(load_case(pendulum_case(folder, fmu, name, **settings)), out_dir=folder / name)
    assert result.status == "finished", result.error
    return pd.read_csv(result.exchange_path)


@pytest.mark.parametrize("kind, fmi_type", [
    ("native", "CoSimulation"), ("native", "ModelExchange"),
    # the FMI 3.0 build costs ~18 s (shared with tests/test_fmu_inputs.py's, slow there too)
    pytest.param("native3", "CoSimulation", marks=pytest.mark.slow),
    pytest.param("native3", "ModelExchange", marks=pytest.mark.slow)])
def test_a_constant_input_moves_the_mechanism_as_the_same_constant_load(mechanism_fmus, tmp_path, kind, fmi_type):
    """F_P = 3 N and tau_arm = 0.5 N*m as inputs, or 0 and their [[loads]] twins at 3 N and
    0.5 N*m: the same generalized forces, so the same motion (to integrator round-off: the
    two forces enter through different generated expressions), in FMI 2.0 and 3.0."""
    fmu = mechanism_fmus.get(str(INPUT_PENDULUM), kind)
    flavour = f'fmi_type = "{fmi_type}"'
    driven = pendulum_run(tmp_path, fmu, "driven", step=0.01, extra=flavour, inputs="F_P = 3.0\ntau_arm = 0.5\n")
    loaded = pendulum_run(tmp_path, fmu, "loaded", step=0.01, extra=flavour,
                          parameters="F_P_load = 3.0\ntau_arm_load = 0.5\n")
    assert read_run_record(tmp_path / "driven" / "run.json").fmu.fmi_type == fmi_type
    assert list(driven.columns) == ["time", *PENDULUM_OUTPUTS, "F_P", "tau_arm"]
    assert list(driven["F_P"]) == [3.0] * len(driven)
    # rtol 1e-10 over 2 s of motion of O(1) m and rad: round-off differences stay far below 1e-8
    assert_allclose(driven[list(PENDULUM_OUTPUTS)], loaded[list(PENDULUM_OUTPUTS)], rtol=0, atol=1e-8)
    # and the load did something: the slider moved by far more than the tolerance
    assert abs(driven["x1"].iloc[-1] - driven["x1"].iloc[0]) > 1e-2


def coupling_errors(folder: Path, fmu: Path, signal: str, step: float, column: str) -> dict[int, float]:
    """Largest error of ``column`` over 2 s with the input ``signal`` on F_P at the communication
    ``step``, by input derivative order (0: held), against model exchange, where CVode evaluates
    the input at every time it needs (rtol 1e-10): the reference."""
    reference = pendulum_run(folder, fmu, "reference", step=step, inputs=f"F_P = {signal}\n",
                             extra='fmi_type = "ModelExchange"')
    assert read_run_record(folder / "reference" / "run.json").fmu.fmi_type == "ModelExchange"
    errors = {}
    for order in (0, 1, 2):
        run = pendulum_run(folder, fmu, f"order{order}", step=step, inputs=f"F_P = {signal}\n",
                           extra=f"input_derivatives = {order}")
        assert read_run_record(folder / f"order{order}" / "run.json").input_derivatives == order
        errors[order] = float(np.max(np.abs(run[column] - reference[column])))
    return errors


def test_input_derivatives_reduce_the_coupling_error_of_a_sine(pendulum_native, tmp_path):
    """A 2 N, 1 Hz sine force on the slider at a 0.05 s step.  Held over each step the force lags
    by half a step (an O(h) error); with its first derivative the FMU extrapolates it linearly
    within the step (O(h^2)), with the second quadratically (O(h^3)).  Measured on the slider's
    speed vx1 (m/s; the force's first integral): held 3.2e-2, order 1 5.8e-3, order 2 2.7e-4,
    factors 5.5 and 22; the asserted factors leave margins of 1.8 and 4."""
    errors = coupling_errors(tmp_path, pendulum_native, '{ type = "sine", amplitude = 2.0, frequency = 1.0 }', 0.05,
                             "vx1")
    assert errors[0] > 1e-3                    # held: the coupling error is there to be reduced
    assert errors[1] < errors[0] / 3
    assert errors[2] < errors[1] / 5


def test_a_ramp_with_its_slope_has_no_coupling_error(pendulum_native, tmp_path):
    """A ramp whose corners lie on the grid is exactly linear within every step: with its first
    derivative the FMU sees the exact force, so only the integrators' errors remain (measured:
    held 0.14 m, order 1 and 2 3.0e-9 m)."""
    errors = coupling_errors(tmp_path, pendulum_native,
                             '{ type = "ramp", from = 0.0, to = 20.0, start = 0.5, duration = 1.0 }', 0.05, "x1")
    assert errors[0] > 1e-2
    assert errors[1] < 1e-7                    # rtol 1e-10, atol 1e-12 in both: far below
    assert errors[2] < 1e-7


def test_model_exchange_follows_a_step_input(pendulum_native, tmp_path):
    """A step of F_P on the grid: co-simulation sets the new value for the steps from its time on,
    exactly; model exchange must agree (CVode integrates across the jump under its error control)."""
    signal = 'F_P = { type = "step", before = 0.0, after = 20.0, time = 0.5 }\ntau_arm = { type = "table", rows = ' \
             '[[0.0, 0.0], [1.0, 1.0], [1.0, -1.0], [2.0, 0.0]] }\n'
    cs = pendulum_run(tmp_path, pendulum_native, "cs", step=0.05, inputs=signal)
    me = pendulum_run(tmp_path, pendulum_native, "me", step=0.05, inputs=signal, extra='fmi_type = "ModelExchange"')
    # rtol 1e-10 in both integrators over 2 s (the table is linear within each step: derivatives
    # order 1 by default make co-simulation exact too); CVode crosses the jumps under its error
    # control alone: measured 1.0e-7 (omega3, rad/s) once the work outputs (the loads' and inputs' works) are
    # continuous states too (i39-energy), so 1e-6 is asked; a step set late or not at all is off
    # by far more (F_P's 20 N on ~3.5 kg moves x1 by a h^2 / 2 ~ 7e-3 m within one 0.05 s step)
    assert_allclose(me[list(PENDULUM_OUTPUTS)], cs[list(PENDULUM_OUTPUTS)], rtol=0, atol=1e-6)


def test_input_derivatives_are_set_only_after_initialisation(pendulum_native, tmp_path, monkeypatch):
    """FMI 2.0 allows fmi2SetRealInputDerivatives in initialisation mode and between steps, not
    before: the start values of the inputs are set alone, the derivatives from the first step on."""
    from orchestrator.fmi_instance import FmuInstance
    from orchestrator.instance import Fmi2CoSimulation

    calls: list[tuple[str, float]] = []
    exit_init, set_derivatives = FmuInstance.exit_initialization_mode, Fmi2CoSimulation._set_input_derivatives
    monkeypatch.setattr(FmuInstance, "exit_initialization_mode",
                        lambda self: (calls.append(("initialised", 0.0)), exit_init(self))[1])
    monkeypatch.setattr(Fmi2CoSimulation, "_set_input_derivatives",
                        lambda self, t, order: (calls.append((f"order {order}", t)), set_derivatives(self, t, order))[1])
    pendulum_run(tmp_path, pendulum_native, "driven", step=0.5, stop=1.0, extra="input_derivatives = 2",
                 inputs='F_P = { type = "sine", amplitude = 2.0, frequency = 1.0 }\n')
    assert calls == [("initialised", 0.0), ("order 1", 0.0), ("order 2", 0.0), ("order 1", 0.5), ("order 2", 0.5)]


# ---------------------------------------------------------------------------- a driver input

CRANK = REPO / "tests" / "mechanisms" / "input_driven_crank.toml"      # inputs crank, crank_d, crank_dd
SINE_CRANK = REPO / "tests" / "mechanisms" / "sine_driven_crank.toml"  # theta2_start + A sin(w t) in the file
CRANK_OUTPUTS = ("theta2", "theta3", "theta4", "omega2", "omega3", "omega4")
#: sine_driven_crank.toml's driver: theta2_start = 30 deg, A = 0.5 rad, w = pi rad/s (0.5 Hz)
CRANK_SIGNAL = f'{{ type = "sine", amplitude = 0.5, frequency = 0.5, offset = {math.radians(30.0)!r} }}'


def crank_run(folder: Path, fmu: Path, name: str, inputs: str = "", extra: str = "") -> pd.DataFrame:
    path = folder / f"{name}.toml"
    path.write_text(f'name = "{name}"\nfmu = {json.dumps(str(fmu))}\n{extra}\n'
                    f'[experiment]\nstop = 2.0\nstep = 0.01\ntolerance = 1e-10\n\n'
                    f'[parameters]\nrtol = 1e-10\natol = 1e-12\n\n'
                    f'[outputs]\nvariables = {json.dumps(list(CRANK_OUTPUTS))}\ndrawing = false\n\n[inputs]\n{inputs}\n')
    result = run_case(load_case(path), out_dir=folder / name)
    assert result.status == "finished", result.error
    return pd.read_csv(result.exchange_path)


@pytest.mark.parametrize("fmi_type", ["ModelExchange", "CoSimulation"])
def test_a_driver_input_given_its_position_alone_is_the_driver_in_the_file(mechanism_fmus, tmp_path, fmi_type):
    """The case gives the crank's angle only; its rate and acceleration inputs (crank_d,
    crank_dd) follow the sine's exact derivatives, so the linkage moves as the same sine written
    as a driver in the mechanism file.  Model exchange: exact at every evaluation (rtol 1e-10:
    1e-9 rad and rad/s).  Co-simulation (order 2 derivatives): each step's position is the sine's
    second-order Taylor polynomial from the step's start, off by at most A w^3 h^3/6 = 2.6e-6 rad
    at h = 0.01 s (tests/test_fmu_inputs.py measures the same with FMPy), within 1 %."""
    flavour = f'fmi_type = "{fmi_type}"' + ("\ninput_derivatives = 2" if fmi_type == "CoSimulation" else "")
    fed = crank_run(tmp_path, mechanism_fmus.get(str(CRANK), "native"), "fed", f"crank = {CRANK_SIGNAL}\n", flavour)
    written = crank_run(tmp_path, mechanism_fmus.get(str(SINE_CRANK), "native"), "written",
                        extra=f'fmi_type = "{fmi_type}"')
    t = fed["time"].to_numpy()
    assert_allclose(fed["crank_d"], 0.5 * np.pi * np.cos(np.pi * t), rtol=0, atol=1e-14)    # written exactly
    assert_allclose(fed["crank_dd"], -0.5 * np.pi ** 2 * np.sin(np.pi * t), rtol=0, atol=1e-13)
    bound = 1e-9 if fmi_type == "ModelExchange" else 1.01 * 0.5 * np.pi ** 3 * 0.01 ** 3 / 6
    assert np.max(np.abs(fed["theta2"] - written["theta2"])) <= bound
    assert np.ptp(fed["theta2"]) > 0.9                                     # the crank swings +-A
    signals = {i.name: dict(i.signal) for i in read_run_record(tmp_path / "fed" / "run.json").inputs}
    assert signals["crank_dd"] == {"type": "derivative", "of": "crank", "order": 2}

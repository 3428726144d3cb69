"""fourbar-run on a system of FMUs (an .ssp; issue 40, point 3).

The system: two instances ``a`` and ``b`` of the test mechanism InputPendulum
(tests/mechanisms/input_pendulum.toml, a slider carrying a double pendulum, built once per
session), in a loop: ``a.omega2 -> b.tau_arm`` and ``b.omega2 -> a.tau_arm`` (each arm's rate
pushes the other's arm, 1 N.m per rad/s), ``b.mr`` bound to 0.7 kg in an .ssv file.  Both start
at rest, so every connected output is 0 at t = 0: FMPy's ``simulate_ssp``, which gives every
input 0.0 at its first step, then sees the same inputs as fourbar-run, which gives it the
outputs at t = 0.  It is a genuine loop (Gauss-Seidel differs from Jacobi) of smooth signals.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from ssp_testing import TestComponent, ssd_text, ssv_text, write_ssp

from fourbar_common.contract.run_record import read_run_record

MECHANISM = str(Path(__file__).parent / "mechanisms" / "input_pendulum.toml")


def pair(a: Path | None, b: Path | None) -> list[TestComponent]:
    """The test system's components ``a`` and ``b`` with these FMUs."""
    return [TestComponent("a", a, inputs=("tau_arm",), outputs=("omega2",)),
            TestComponent("b", b, inputs=("tau_arm",), outputs=("omega2",))]


CONNECTIONS = [("a.omega2", "b.tau_arm"), ("b.omega2", "a.tau_arm")]
BOUND = {"b.mr": 0.7}
OUTPUTS = ["a.omega2", "b.omega2", "a.theta2", "b.theta3"]
STOP = 2.0
STEP = 0.02


@pytest.fixture(scope="session")
def pendulum(mechanism_fmus) -> Path:
    return mechanism_fmus.get(MECHANISM, "native")


@pytest.fixture(scope="session")
def system(pendulum, tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("system")
    return write_ssp(folder / "Pair.ssp", "TestSystem", pair(pendulum, pendulum), CONNECTIONS, system_ssv=BOUND)


def write_case(folder: Path, ssp: Path, *, name: str = "pair", step: float = STEP, master: str = "",
               extra: str = "", outputs=OUTPUTS) -> Path:
    path = folder / f"{name}.toml"
    path.write_text(f'name = "{name}"\nsystem = {json.dumps(str(ssp))}\n'
                    f"[experiment]\nstop = {STOP!r}\nstep = {step!r}\n"
                    f"[outputs]\nvariables = {json.dumps(list(outputs))}\n"
                    + (f"[master]\n{master}\n" if master else "") + extra, encoding="utf-8")
    return path


def run(folder: Path, ssp: Path, **kw) -> np.ndarray:
    """Run the case; its exchange rows as a (rows, columns) array, time first."""
    from orchestrator import run_case

    case = write_case(folder, ssp, **kw)
    result = run_case(case, folder / f"out_{kw.get('name', 'pair')}")
    assert result.status == "finished", result.error
    return np.loadtxt(result.exchange_path, delimiter=",", skiprows=1, ndmin=2)


@pytest.fixture(scope="session")
def runs(system, tmp_path_factory):
    """The runs the tests compare, each made once: Jacobi/Gauss-Seidel, hold/extrapolate at STEP,
    and the reference (Jacobi at STEP/16, hold: its coupling error has converged, see the test)."""
    folder = tmp_path_factory.mktemp("system_runs")
    made = {}
    for name, master, step in (("jacobi", "", STEP),
                               ("gs", 'algorithm = "gauss-seidel"', STEP),
                               ("extrap", 'inputs = "extrapolate"', STEP),
                               ("ref", "", STEP / 16),
                               ("ref8", "", STEP / 8)):
        made[name] = run(folder, system, name=name, master=master, step=step)
    made["folder"] = folder
    return made


def on_coarse_grid(fine: np.ndarray, every: int) -> np.ndarray:
    return fine[::every]


def test_jacobi_equals_fmpy_simulate_ssp(system, runs, tmp_path):
    """Same .ssp, same step: FMPy's row labelled t_k holds the outputs after its step from t_k
    (it records, then ``time += step_size``), i.e. at t_{k+1}: our row k+1.  Bindings: FMPy's
    simulate_ssp ignores the SSD's, so it is handed the same .ssv as its parameter_set."""
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import read_ssv

    ssv = tmp_path / "bound.ssv"
    ssv.write_text(ssv_text(BOUND), encoding="utf-8")
    theirs = simulate_ssp(str(system), stop_time=STOP, step_size=STEP, parameter_set=read_ssv(str(ssv)))
    ours = runs["jacobi"]
    n = min(len(theirs), len(ours) - 1)      # FMPy's `time < stop` with time += step may add a row
    assert n >= round(STOP / STEP) - 1
    assert_allclose(ours[1:n + 1, 0], theirs["time"][:n] + STEP, rtol=0, atol=1e-12)  # labels: theirs + step
    for i, column in enumerate(OUTPUTS[:2], start=1):
        # same FMUs, same calls in the same order: equal to round-off of the time arguments
        # (FMPy's accumulated time vs. our start + k*step) at most
        assert_allclose(ours[1:n + 1, i], theirs[column][:n], rtol=0, atol=1e-12, err_msg=column)
    assert np.max(np.abs(ours[:, 1])) > 0.1      # it moved: the comparison is not of zeros


def coupling_error(coarse: np.ndarray, ref: np.ndarray, every: int) -> float:
    """Largest difference of the coupled rates from the reference at the coarse grid's times."""
    fine = on_coarse_grid(ref, every)
    assert_allclose(fine[:, 0], coarse[:, 0], rtol=0, atol=1e-9)
    return float(np.max(np.abs(coarse[:, 1:3] - fine[:, 1:3])))


def test_reference_has_converged(runs):
    """The reference's own coupling error is small against the errors compared below: halving
    its step (STEP/8 -> STEP/16) changes it far less than STEP's error (first order: by about half
    the STEP/8 run's error, which is 1/8 of STEP's)."""
    e_step = coupling_error(runs["jacobi"], runs["ref"], 16)
    e_ref = coupling_error(runs["ref8"][::1], runs["ref"], 2)
    assert e_ref < 0.25 * e_step, (e_ref, e_step)


def test_gauss_seidel_differs_and_is_closer(runs):
    e_jacobi = coupling_error(runs["jacobi"], runs["ref"], 16)
    e_gs = coupling_error(runs["gs"], runs["ref"], 16)
    assert np.max(np.abs(runs["gs"][:, 1:3] - runs["jacobi"][:, 1:3])) > 1e-6   # not the same algorithm
    assert e_gs < e_jacobi, (e_gs, e_jacobi)


def test_extrapolation_reduces_the_coupling_error(runs):
    """InputPendulum says canInterpolateInputs: its connected inputs get the slope of the last
    two communication points (fmi2SetRealInputDerivatives)."""
    e_hold = coupling_error(runs["jacobi"], runs["ref"], 16)
    e_extrap = coupling_error(runs["extrap"], runs["ref"], 16)
    assert e_extrap < 0.5 * e_hold, (e_extrap, e_hold)   # first to second order in the step


def test_run_json_records_the_system(runs, system):
    record = read_run_record(runs["folder"] / "out_gs" / "run.json")
    assert record.system is not None and record.system.algorithm == "gauss-seidel"
    assert record.system.sha256 == __import__("hashlib").sha256(system.read_bytes()).hexdigest()
    assert [c.name for c in record.system.components] == ["a", "b"]
    assert {(c.source, c.target) for c in record.system.connections} == set(CONNECTIONS)
    b = record.system.component("b")
    assert b.parameters["mr"] == 0.7 and record.system.component("a").parameters["mr"] == 0.5
    assert b.guid and b.model_identifier == "InputPendulumNative" and b.fmi_version == "2.0"
    assert record.parameter("b.mr").source == "ssp" and record.parameter("a.mr").source == "fmu"
    assert record.outputs[:2] == ("a.omega2", "b.omega2")
    one_fmu = read_run_record(runs["folder"] / "out_jacobi" / "run.json")
    assert one_fmu.system.order == ("a", "b")


def test_fault_on_component_variable_applied_on_time(system, runs, tmp_path):
    """A step on a.push (an unconnected input) at t = 1 s: the row at 1 s is still the
    fault-free run's (rows show the state before the change), the next one is not."""
    fault = 'type = "step"\ntime = 1.0\nvariable = "a.push"\nvalue = 5.0\n'
    rows = run(tmp_path, system, name="fault", extra=f"[[events]]\n{fault}")
    k = round(1.0 / STEP)
    healthy = runs["jacobi"]
    assert_allclose(rows[:k + 1], healthy[:k + 1], rtol=0, atol=0)     # same calls up to the event
    assert np.max(np.abs(rows[k + 1, 1:] - healthy[k + 1, 1:])) > 1e-6


def test_case_override_wins_over_the_binding(system, tmp_path):
    from orchestrator import load_case

    case = load_case(write_case(tmp_path, system, extra="[parameters]\n\"b.mr\" = 0.9\n"))
    from orchestrator.run import _parameter_starts

    starts = {p.name: p for p in _parameter_starts(case)}
    assert starts["b.mr"].start == 0.9 and starts["b.mr"].source == "case"


# ---------------------------------------------------------------------------------- refusals

def refused(tmp_path: Path, case: Path, capsys) -> str:
    """Run the CLI on ``case`` into a folder holding an earlier run's exchange.csv: exit 2, the
    folder unchanged; returns stderr."""
    from orchestrator.cli import main

    out = tmp_path / "out"
    out.mkdir(exist_ok=True)
    (out / "exchange.csv").write_text("time,x\n0.0,1.0\n", encoding="utf-8")
    code = main([str(case), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2, err
    assert (out / "exchange.csv").read_text(encoding="utf-8") == "time,x\n0.0,1.0\n"
    assert sorted(p.name for p in out.iterdir()) == ["exchange.csv"]
    return err


@pytest.mark.parametrize("variable, expected", [
    ("c.omega2", "has no component 'c'"),
    ("a.omega9", "has no variable named 'a.omega9'"),
])
def test_unknown_component_or_variable(system, tmp_path, capsys, variable, expected):
    err = refused(tmp_path, write_case(tmp_path, system, outputs=["a.omega2", variable]), capsys)
    assert "outputs.variables[1]" in err and expected in err


def test_connected_input_is_the_masters(system, tmp_path, capsys):
    fault = '[[events]]\ntype = "step"\ntime = 1.0\nvariable = "b.tau_arm"\nvalue = 1.0\n'
    err = refused(tmp_path, write_case(tmp_path, system, extra=fault), capsys)
    assert "events[0].variable" in err and "fed by the connection a.omega2 -> b.tau_arm" in err


def test_both_fmu_and_system(system, pendulum, tmp_path, capsys):
    case = write_case(tmp_path, system)
    case.write_text(f"fmu = {json.dumps(str(pendulum))}\n" + case.read_text(encoding="utf-8"), encoding="utf-8")
    err = refused(tmp_path, case, capsys)
    assert "system = " in err and "exactly one of fmu" in err


def test_missing_ssp(tmp_path, capsys):
    err = refused(tmp_path, write_case(tmp_path, tmp_path / "Nowhere.ssp"), capsys)
    assert "system = " in err and "file not found" in err


def test_bad_master_algorithm(system, tmp_path, capsys):
    err = refused(tmp_path, write_case(tmp_path, system, master='algorithm = "newton"\norder = ["a"]'), capsys)
    assert "master.algorithm = 'newton'" in err or 'master.algorithm = "newton"' in err


def test_zip_with_parent_paths(pendulum, tmp_path, capsys):
    ssp = write_ssp(tmp_path / "Evil.ssp", "TestSystem", pair(pendulum, pendulum), CONNECTIONS,
                    extra={"../../evil.txt": b"x"})
    err = refused(tmp_path, write_case(tmp_path, ssp), capsys)
    assert "'../../evil.txt'" in err and "path traversal" in err
    assert not (tmp_path.parent / "evil.txt").exists()


def test_ssd_with_a_dtd(pendulum, tmp_path, capsys):
    dtd = '<!DOCTYPE x [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">]>'
    ssd = ssd_text("TestSystem", pair(None, None), CONNECTIONS, preamble=dtd)
    ssp = write_ssp(tmp_path / "Dtd.ssp", "TestSystem", pair(pendulum, pendulum), CONNECTIONS, ssd=ssd)
    err = refused(tmp_path, write_case(tmp_path, ssp), capsys)
    assert "SystemStructure.ssd" in err and "document type declaration" in err


def test_component_failing_mid_run_is_named(system, tmp_path):
    """A push of 1e200 N at 0.5 s makes a's integrator give up: the run fails naming the
    component and its FMU's own message; the rows before stay."""
    from orchestrator import run_case

    fault = '[[events]]\ntype = "step"\ntime = 0.5\nvariable = "a.push"\nvalue = 1e200\n'
    result = run_case(write_case(tmp_path, system, name="failing", extra=fault), tmp_path / "out")
    assert result.status == "failed"
    assert result.error.startswith("component 'a' (a.fmu): fmi2DoStep(t = 0.5 s"), result.error
    assert "InputPendulum 'a'" in result.error          # the FMU's own log line
    assert result.rows_written == round(0.5 / STEP) + 1
    record = read_run_record(tmp_path / "out" / "run.json")
    assert record.status == "failed" and record.error == result.error


def test_inputs_noise_and_a_given_order(system, runs, tmp_path):
    """[inputs] drives an unconnected component input (its column is named component.variable),
    [noise] perturbs a component's column only as written, [master] order is used and recorded."""
    inputs = '[inputs]\n"a.F_P" = { type = "constant", value = 0.0 }\n'
    noise = '[noise]\nseed = 3\nstd = { "b.omega2" = 0.01 }\n'
    order = 'algorithm = "gauss-seidel"\norder = ["b", "a"]'
    rows = run(tmp_path, system, name="extras", extra=inputs + noise, master=order)
    clean = run(tmp_path, system, name="clean", extra=inputs, master=order)
    header = (tmp_path / "out_extras" / "exchange.csv").read_text(encoding="utf-8").splitlines()[0]
    # the outputs, then the drawing's columns (a's: the first component that declares one), then the input
    assert header.startswith("time," + ",".join(OUTPUTS) + ",a.") and header.endswith(",a.F_P")
    assert np.all(rows[:, -1] == 0.0)
    assert_allclose(rows[:, 1], clean[:, 1], rtol=0, atol=0)      # the noise never reaches the FMUs
    assert 0.005 < np.std(rows[:, 2] - clean[:, 2]) < 0.02        # std 0.01 over 101 draws
    record = read_run_record(tmp_path / "out_extras" / "run.json")
    assert record.system.order == ("b", "a") and record.inputs[0].name == "a.F_P"
    assert np.max(np.abs(clean[:, 1] - runs["gs"][:, 1])) > 1e-6   # b before a is not a before b


def test_sigterm_keeps_the_rows_of_a_system_run(system, tmp_path):
    """The one-FMU run's promises hold for a system: the installed fourbar-run, paced at real
    time, says running with a live writer, then on SIGTERM exits 143 with run.json interrupted
    and every row it counted in exchange.csv."""
    import signal
    import subprocess

    from support import FOURBAR_RUN, wait_for_rows

    case = write_case(tmp_path, system, name="paced", extra="[exchange]\nrealtime_factor = 1.0\n"
                                                          "flush_interval = 0.1\n")
    out = tmp_path / "out"
    proc = subprocess.Popen([FOURBAR_RUN, str(case), "--out", str(out), "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        running = wait_for_rows(out, proc, rows=2)
        assert running["writer"]["pid"] == proc.pid and running["system"]["components"][1]["name"] == "b"
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=60)      # a hang guard, not a timing
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 143, err
    record = read_run_record(out / "run.json")
    assert record.status == "interrupted" and record.error.startswith("terminated by SIGTERM at t = ")
    lines = (out / "exchange.csv").read_text(encoding="utf-8").splitlines()
    assert len(lines) - 1 == record.rows_written >= 2


def test_a_binding_on_an_input_is_recorded(pendulum, tmp_path):
    """An inline binding may give an unconnected input its start value (a.F_P here, with the
    .ssv's b.mr): both are applied and recorded among the component's effective values."""
    ssp = write_ssp(tmp_path / "Bound.ssp", "TestSystem", pair(pendulum, pendulum), CONNECTIONS,
                    system_parameters={"a.F_P": 0.25, "b.ma": 1.5})
    rows = run(tmp_path, ssp, name="bound", outputs=["a.F_P", "a.omega2"])
    assert np.all(rows[:, 1] == 0.25)
    record = read_run_record(tmp_path / "out_bound" / "run.json")
    assert record.system.component("a").parameters["F_P"] == 0.25
    assert record.system.component("b").parameters["ma"] == 1.5 and record.parameter("b.ma").source == "ssp"


@pytest.mark.slow        # one more FMU build (InputPendulum's FMI 3.0 twin, ~15-20 s)
def test_an_fmi3_component_gives_the_same_run(pendulum, mechanism_fmus, runs, tmp_path):
    """b as the FMI 3.0 build of the same model: the same C model behind another FMI layer, so
    the system's rows equal the all-FMI 2.0 run's exactly (0: same arithmetic), and run.json
    records each component's FMI version."""
    pendulum3 = mechanism_fmus.get(MECHANISM, "native3")
    ssp = write_ssp(tmp_path / "Mixed.ssp", "TestSystem", pair(pendulum, pendulum3), CONNECTIONS, system_ssv=BOUND)
    rows = run(tmp_path, ssp, name="mixed")
    assert_allclose(rows, runs["jacobi"], rtol=0, atol=0)
    record = read_run_record(tmp_path / "out_mixed" / "run.json")
    assert [c.fmi_version for c in record.system.components] == ["2.0", "3.0"]


def test_initial_connections_settled_as_libcosim_does(pendulum, mechanism_fmus, tmp_path):
    """Connections settled in initialisation mode: the press's motor torque (30 N.m at t = 0,
    not 0) drives a's arm, a's joint reaction O_Fx (direct feed-through of that torque) pushes
    b's slider, b's arm rate turns a's rod.  libcosim sets the connected inputs in
    initialisation mode until they settle; fourbar-run's Jacobi run gives the same rows (rows
    matched by step number: both label a row with its step's end).  Reading the outputs only
    after initialisation instead puts O_Fx 18 N off from the first step on."""
    libcosim = pytest.importorskip("libcosimpy.CosimExecution", reason="libcosimpy is not installed")
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    press = mechanism_fmus.get("fourbar_press", "native")
    components = [TestComponent("press", press, outputs=("motor_torque",)),
                  TestComponent("a", pendulum, inputs=("tau_arm", "tau_A"), outputs=("O_Fx",)),
                  TestComponent("b", pendulum, inputs=("F_P",), outputs=("omega2",))]
    connections = [("press.motor_torque", "a.tau_arm"), ("a.O_Fx", "b.F_P"), ("b.omega2", "a.tau_A")]
    ssp = write_ssp(tmp_path / "Feed.ssp", "Feed", components, connections)
    columns = ["a.O_Fx", "b.omega2"]
    ours = run(tmp_path, ssp, name="feed", outputs=columns)
    n = len(ours) - 1

    log_output_level(CosimLogLevel.WARNING)
    execution = libcosim.CosimExecution.from_ssp_file(str(ssp), round(STEP * 1e9))
    observer = CosimObserver.create_time_series(buffer_size=n + 10)
    execution.add_observer(observer=observer)
    slots = []
    for column in columns:
        component, name = column.split(".")
        index = execution.slave_index_from_instance_name(component)
        ref = {v.name.decode(): v.reference for v in execution.slave_variables(index)}[name]
        observer.start_time_series(index, ref, CosimVariableType.REAL)
        slots.append((index, ref))
    assert execution.step(n)
    for i, (index, ref) in enumerate(slots, start=1):
        _t, steps, values = observer.time_series_real_samples(index, ref, from_step=1, sample_count=n)
        assert list(steps) == list(range(1, n + 1))
        # same FMUs, same calls: equal to round-off at most (libcosim's integer-ns clock)
        assert_allclose(ours[1:, i], values, rtol=0, atol=1e-12, err_msg=columns[i - 1])
    assert abs(ours[0, 1]) > 1.0           # the feed-through carried a real torque at t = 0


def test_a_component_that_is_not_an_fmu(pendulum, tmp_path, capsys):
    ssp = write_ssp(tmp_path / "Broken.ssp", "TestSystem", pair(pendulum, None), CONNECTIONS,
                    extra={"resources/b.fmu": b"not a zip"})
    err = refused(tmp_path, write_case(tmp_path, ssp), capsys)
    assert "component 'b' (resources/b.fmu): not a readable FMU" in err

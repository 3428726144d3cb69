"""One SSP 1.0 system run in FMPy, libcosim and Ecos (fmu_src/ssp_masters.py): the same numbers.

The system (tests/ssp_testing.py writes it, checked against SSP 1.0's schema): the native FMU
of Table 1's press (build/FourBarPressNative.fmu, "press": no inputs) and two instances of the
input pendulum (tests/mechanisms/input_pendulum.toml, built once per session: "arm" and
"rod"), connected

    press.motor_work -> arm.tau_arm        (one way: a torque on the arm)
    arm.vx1 -> rod.F_P,  rod.vx1 -> arm.F_P (a loop: each slider pushed by the other's speed)

Every connected output is 0.0 at t = 0 (the work starts at 0, both sliders at rest): FMPy's
simulate_ssp feeds 0.0 to every input in the first step where libcosim and Ecos feed the
outputs' initial values (test_a_nonzero_initial_output_separates_fmpy_from_the_others shows
the difference).  Parameter values are bound three ways: none, inline ssv:ParameterSet,
resources/<component>.ssv.

Alignment: each master's rows are matched by step number (``MasterRun.times`` = n * step, n =
1..N), not by the masters' own labels: FMPy labels the row after the step [t_n, t_n+1] with
t_n and accumulates ``time += step``; libcosim labels it t_n+1 on its nanosecond grid; Ecos
with t_n+1 from its accumulated clock (test_each_master_labels_its_rows_its_way).

1e-12: the same FMI calls on the same binaries give the same doubles (measured: 0.0); the
bound only admits round-off in the masters' time arithmetic, which the native FMU absorbs by
snapping communication times to whole nanoseconds (docs/contracts.md).  The states here are
of order 0.1..10, so 1e-12 is ~10^3..10^4 ulp: a pass means "the same numbers".
"""
from __future__ import annotations

import itertools
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
from ssp_testing import TestComponent, write_ssp
from support import FOURBAR_RUN, REPO

from fmu_src.ssp_masters import MASTERS, MasterError, available, run_ecos, run_fmpy, run_libcosim, run_master, steps_of

PENDULUM = str(REPO / "tests" / "mechanisms" / "input_pendulum.toml")
STOP, STEP = 2.0, 0.01          # 200 macro steps: ~0.1 s of CPU a master
TOL = 1e-12
BINDINGS = ("none", "inline", "ssv")
VARIABLES = ["press.motor_work", "arm.vx1", "arm.theta2", "arm.x1", "rod.vx1", "rod.theta3"]
CONNECTIONS = [("press.motor_work", "arm.tau_arm"), ("arm.vx1", "rod.F_P"), ("rod.vx1", "arm.F_P")]
#: Bound values, each far from the FMU's default (m1 2.0, mr 0.5, T2 0.5).
VALUES = {"press": {"T2": 0.8}, "arm": {"m1": 3.0}, "rod": {"mr": 0.7}}


def _skip_missing(master: str) -> None:
    message = available(master)
    if message is not None:
        pytest.skip(message)


def _components(pendulum: Path, press_outputs=("motor_work", "theta2")) -> list[TestComponent]:
    return [TestComponent("press", REPO / "build" / "FourBarPressNative.fmu", outputs=press_outputs,
                          parameters=VALUES["press"]),
            TestComponent("arm", pendulum, inputs=("tau_arm", "F_P"), outputs=("vx1", "theta2", "x1"),
                          parameters=VALUES["arm"]),
            TestComponent("rod", pendulum, inputs=("F_P",), outputs=("vx1", "theta3"), parameters=VALUES["rod"])]


@pytest.fixture(scope="module")
def pendulum(mechanism_fmus) -> Path:
    return mechanism_fmus.get(PENDULUM, "native")


@pytest.fixture(scope="module")
def press() -> Path:
    fmu = REPO / "build" / "FourBarPressNative.fmu"
    if not fmu.exists():
        pytest.skip("build/FourBarPressNative.fmu is missing: run `make mechanisms`")
    return fmu


@pytest.fixture(scope="module")
def systems(pendulum, press, tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("ssp")
    return {b: write_ssp(folder / f"test_{b}.ssp", "TestSystem", _components(pendulum), CONNECTIONS, bindings=b)
            for b in BINDINGS}


@pytest.fixture(scope="module")
def runs(systems):
    """run(master, bindings): each run made once per module."""
    made = {}

    def run(master: str, bindings: str):
        _skip_missing(master)
        if (master, bindings) not in made:
            made[master, bindings] = run_master(master, systems[bindings], STOP, STEP, VARIABLES)
        return made[master, bindings]

    return run


def _worst(a, b) -> tuple[float, str]:
    return max((float(np.max(np.abs(a[v] - b[v]))), v) for v in VARIABLES)


@pytest.mark.parametrize("bindings", BINDINGS)
@pytest.mark.parametrize("first, second", list(itertools.combinations(MASTERS, 2)))
def test_masters_agree(runs, first, second, bindings):
    a, b = runs(first, bindings), runs(second, bindings)
    np.testing.assert_array_equal(a.times, b.times)
    assert len(a.times) == steps_of(STOP, STEP)
    worst, where = _worst(a, b)
    assert worst <= TOL, f"{first} and {second} ({bindings} bindings) differ by {worst:.3e} in {where}"
    # Not a system at rest: every column moves.
    for v in VARIABLES:
        assert np.ptp(a[v]) > 1e-3, v


@pytest.mark.parametrize("master", MASTERS)
def test_bindings_take_effect_in_either_form(runs, master):
    none, inline, ssv = (runs(master, b) for b in BINDINGS)
    worst, where = _worst(inline, ssv)
    assert worst == 0.0, f"{master}: inline and .ssv bindings differ by {worst:.3e} in {where}"
    # The bound masses and friction change the motion by far more than round-off (measured:
    # arm.x1 at 2 s is 0.166 m unbound, -0.075 m bound).
    for v in ("press.motor_work", "arm.x1", "rod.theta3"):
        assert np.max(np.abs(inline[v] - none[v])) > 1e-2, f"{master}: {v} does not see the bindings"


@pytest.mark.parametrize("master", ["libcosim", "Ecos"])
def test_the_bound_values_are_the_components_parameters(systems, master):
    """libcosim and Ecos record any variable: the parameters read back are the bound values."""
    _skip_missing(master)
    names = [f"{c}.{p}" for c, values in VALUES.items() for p in values]
    for bindings in ("inline", "ssv"):
        run = run_master(master, systems[bindings], 0.02, STEP, names)
        for name in names:
            component, parameter = name.split(".")
            assert np.all(run[name] == VALUES[component][parameter]), (master, bindings, name, run[name])


def test_each_master_labels_its_rows_its_way(runs):
    n = steps_of(STOP, STEP)
    times = np.arange(1, n + 1) * STEP
    labels = {m: runs(m, "none").labels for m in MASTERS if available(m) is None}
    if "FMPy" in labels:      # the step's start, accumulated by time += step (not n * step)
        np.testing.assert_allclose(labels["FMPy"], times - STEP, rtol=0, atol=1e-12)
        assert labels["FMPy"][-1] != times[-2], "FMPy's clock no longer accumulates: update docs/systems.md"
    if "libcosim" in labels:  # the step's end, n * 10^7 ns / 1e9 exactly
        np.testing.assert_array_equal(labels["libcosim"], np.arange(1, n + 1) * 10_000_000 / 1e9)
    if "Ecos" in labels:      # the step's end, within round-off of its clock
        np.testing.assert_allclose(labels["Ecos"], times, rtol=0, atol=1e-12)


def test_an_input_column_is_the_next_steps_value_in_fmpy_and_ecos_the_last_steps_in_libcosim(systems):
    """arm.tau_arm is fed press.motor_work.  In the row after step n, FMPy and Ecos show the value
    set for step n + 1 (the source's output at t_n+1, the same row); libcosim shows the value held
    over step n (the source's output at t_n, the row before; 0.0 in the first row)."""
    names = ["press.motor_work", "arm.tau_arm"]
    for master in MASTERS:
        if available(master) is not None:
            continue
        run = run_master(master, systems["none"], 0.1, STEP, names)
        source, column = run["press.motor_work"], run["arm.tau_arm"]
        if master == "libcosim":
            np.testing.assert_array_equal(column, np.concatenate([[0.0], source[:-1]]))
        else:
            np.testing.assert_array_equal(column, source)


def test_a_nonzero_initial_output_separates_fmpy_from_the_others(pendulum, press, tmp_path):
    """press.motor_torque is 46.7 N.m at t = 0: libcosim and Ecos give it to the arm in the first
    step, FMPy gives 0.0.  The press (no inputs) still agrees; the arm does not, from row 1."""
    for master in ("libcosim", "Ecos"):
        if available(master) is None:
            other = master
            break
    else:
        pytest.skip("neither libcosim nor Ecos is installed")
    ssp = write_ssp(tmp_path / "torque.ssp", "Torque", _components(pendulum, ("motor_torque",)),
                    [("press.motor_torque", "arm.tau_arm")] + CONNECTIONS[1:], bindings="none")
    names = ["press.motor_torque", "arm.vx1"]
    fmpy_run, other_run = run_fmpy(ssp, 0.1, STEP, names), run_master(other, ssp, 0.1, STEP, names)
    assert other_run["press.motor_torque"][0] > 1.0
    np.testing.assert_array_equal(fmpy_run["press.motor_torque"], other_run["press.motor_torque"])
    assert abs(fmpy_run["arm.vx1"][0] - other_run["arm.vx1"][0]) > 1e-3


# -- what a master cannot do is refused with a message -----------------------------------------

def test_fmpy_refuses_an_unconnected_input_connector(pendulum, press, tmp_path):
    components = _components(pendulum)
    components[1] = TestComponent("arm", pendulum, inputs=("tau_arm", "F_P", "push"), outputs=("vx1",))
    ssp = write_ssp(tmp_path / "loose.ssp", "Loose", components, CONNECTIONS)
    with pytest.raises(MasterError, match=r"arm\.push have no connection.*never its start value"):
        run_fmpy(ssp, 0.1, STEP, ["arm.vx1"])


def test_fmpy_records_connectors_only(systems):
    with pytest.raises(MasterError, match=r"arm\.m1 is not one"):
        run_fmpy(systems["none"], 0.1, STEP, ["arm.m1"])


def test_parameter_sets_of_several_names_and_parameter_connectors(pendulum, press, runs, tmp_path):
    """The project's system builder names each component's ssv:ParameterSet after the component
    and lists bound parameters as connectors of kind "parameter": each master still applies
    every bound value (Ecos: set before init, as it applies one named set only), and FMPy, which
    records a parameter connector as 0.0, is refused that column."""
    ssp = write_ssp(tmp_path / "named.ssp", "Named", _components(pendulum), CONNECTIONS, set_name=None,
                    parameter_connectors=True)
    for master in MASTERS:
        if available(master) is None:
            run = run_master(master, ssp, STOP, STEP, VARIABLES)
            worst, where = _worst(run, runs(master, "inline"))
            assert worst == 0.0, f"{master}: {worst:.3e} in {where}"
    with pytest.raises(MasterError, match=r"arm\.m1 \(a parameter connector\) as 0\.0"):
        run_fmpy(ssp, 0.1, STEP, ["arm.m1"])


def test_fmi3_components_run_in_ecos_only(tmp_path):
    fmu3 = REPO / "build" / "FourBarPressNative3.fmu"
    if not fmu3.exists():
        pytest.skip("build/FourBarPressNative3.fmu is missing: run `make mechanisms`")
    ssp = write_ssp(tmp_path / "fmi3.ssp", "Fmi3", [TestComponent("press", fmu3, outputs=("motor_work",))], [])
    for master in ("FMPy", "libcosim"):
        if available(master) is None:
            with pytest.raises(MasterError, match=r"FMI 1\.0 and 2\.0 components only, not press \(FMI 3\.0\)"):
                run_master(master, ssp, 0.02, STEP, ["press.motor_work"])
    _skip_missing("Ecos")
    assert run_ecos(ssp, 0.02, STEP, ["press.motor_work"])["press.motor_work"][-1] > 1.0


@pytest.mark.parametrize("stop, step, message", [
    (1.005, 0.01, "not a whole number of steps"),
    (1.0, -0.01, "must be positive"),
])
def test_a_grid_the_masters_cannot_share_is_refused(stop, step, message):
    with pytest.raises(MasterError, match=message):
        steps_of(stop, step)


def test_libcosim_refuses_a_step_off_its_nanosecond_grid(systems):
    _skip_missing("libcosim")
    with pytest.raises(MasterError, match="whole number of nanoseconds"):
        run_libcosim(systems["none"], 1e-9 * 2.5 * 4, 1e-9 * 2.5, ["arm.vx1"])


def test_an_unknown_variable_is_named(systems):
    for master in ("libcosim", "Ecos"):
        if available(master) is None:
            with pytest.raises(MasterError, match="nosuch"):
                run_master(master, systems["none"], 0.02, STEP, ["arm.nosuch"])


# -- feed-through: the initial exchange --------------------------------------------------------
# press.motor_torque (46.7 N.m at t = 0) -> arm.tau_arm, and arm.O_Fx (the reaction at the arm's
# pin: it depends on tau_arm directly, through the accelerations) -> rod.F_P.  Which O_Fx the rod
# gets over the first step depends on whether the master settles the connections through
# feed-through before the first step: libcosim and Ecos do (the reaction with tau_arm = 46.7),
# a master that reads the outputs once after initialisation gives the reaction with tau_arm's
# start value 0.  (FMPy gives 0.0 to both inputs: not compared here.)
FT_VARIABLES = ["press.motor_torque", "arm.O_Fx", "arm.x1", "rod.x1"]
FT_CONNECTIONS = [("press.motor_torque", "arm.tau_arm"), ("arm.O_Fx", "rod.F_P")]


@pytest.fixture(scope="module")
def feedthrough(pendulum, press, tmp_path_factory) -> Path:
    components = [TestComponent("press", press, outputs=("motor_torque",)),
                  TestComponent("arm", pendulum, inputs=("tau_arm",), outputs=("O_Fx", "x1")),
                  TestComponent("rod", pendulum, inputs=("F_P",), outputs=("x1",))]
    return write_ssp(tmp_path_factory.mktemp("ft") / "feedthrough.ssp", "Feedthrough", components, FT_CONNECTIONS,
                     bindings="none")


def _initial_outputs(fmu: Path, inputs: dict[str, float], names: list[str], folder: Path) -> list[float]:
    """The outputs ``names`` of ``fmu`` after initialisation with ``inputs`` set (FMPy's FMU2Slave)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu), str(folder)),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="probe")
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    if inputs:
        slave.setReal([vr[k] for k in inputs], list(inputs.values()))
    slave.exitInitializationMode()
    values = slave.getReal([vr[n] for n in names])
    slave.terminate()
    slave.freeInstance()
    return values


def test_libcosim_and_ecos_settle_the_initial_exchange_through_feedthrough(feedthrough, pendulum, press, tmp_path):
    _skip_missing("libcosim")
    _skip_missing("Ecos")
    a = run_libcosim(feedthrough, STOP, STEP, [*FT_VARIABLES, "rod.F_P"])
    b = run_ecos(feedthrough, STOP, STEP, FT_VARIABLES)
    worst, where = max((float(np.max(np.abs(a[v] - b[v]))), v) for v in FT_VARIABLES)
    assert worst <= TOL, f"libcosim and Ecos differ by {worst:.3e} in {where}"
    (torque,) = _initial_outputs(press, {}, ["motor_torque"], tmp_path / "press")
    (settled,) = _initial_outputs(pendulum, {"tau_arm": torque}, ["O_Fx"], tmp_path / "settled")
    (unsettled,) = _initial_outputs(pendulum, {}, ["O_Fx"], tmp_path / "unsettled")
    assert abs(settled - unsettled) > 1.0, (settled, unsettled)     # the test can tell them apart
    # libcosim records an input as the value it held over the step that ended at the row's time.
    assert abs(a["rod.F_P"][0] - settled) <= TOL, (a["rod.F_P"][0], settled, unsettled)


# -- fourbar-run's Jacobi master (issue 40, point 3) -------------------------------------------

def _fourbar_run(ssp: Path, variables: list[str], folder: Path):
    """fourbar-run's Jacobi run of ``ssp``: (k, the exchange columns)."""
    case = folder / "ssp_jacobi.toml"
    columns = ", ".join(f'"{v}"' for v in variables)
    case.write_text(f'name = "ssp_jacobi"\nsystem = "{ssp.as_posix()}"\n\n'
                    f'[experiment]\nstart = 0.0\nstop = {STOP}\nstep = {STEP}\n\n'
                    f'[master]\nalgorithm = "jacobi"\n\n[outputs]\nvariables = [{columns}]\n', encoding="utf-8")
    out = folder / "out"
    proc = subprocess.run([FOURBAR_RUN, str(case), "--out", str(out), "--quiet"], capture_output=True, text=True,
                          timeout=300, cwd=REPO)
    assert proc.returncode == 0, proc.stderr[-3000:]
    from fourbar_common.contract.exchange import read_exchange

    data = read_exchange(out / "exchange.csv", variables)
    return np.rint(np.asarray(data.time) / STEP).astype(int), data.values


@pytest.mark.parametrize("system", ["loop", "feedthrough"])
def test_fourbar_run_jacobi_matches_the_other_masters(system, systems, feedthrough, runs, tmp_path):
    """Rows are matched by time: fourbar-run labels a row with its communication point
    (start + k * step, k = 0..N), so its rows k = 1..N are the others' rows after step k.
    "loop": the bound test system, against all three masters.  "feedthrough": against libcosim
    and Ecos, which settle the initial exchange through feed-through (FMPy gives 0.0)."""
    if system == "loop":
        ssp, variables, masters = systems["inline"], VARIABLES, MASTERS
    else:
        ssp, variables, masters = feedthrough, FT_VARIABLES, ("libcosim", "Ecos")
    k, values = _fourbar_run(ssp, variables, tmp_path)
    after = k >= 1
    for master in masters:
        if available(master) is not None:
            continue
        other = runs(master, "inline") if system == "loop" else run_master(master, ssp, STOP, STEP, variables)
        assert np.array_equal(k[after], np.arange(1, len(other.times) + 1)), "fourbar-run's grid is not k * step"
        for v in variables:
            worst = float(np.max(np.abs(values[v][after] - other[v])))
            assert worst <= TOL, (f"fourbar-run (jacobi) and {master} differ by {worst:.3e} in {v}"
                                  + (" (does fourbar-run settle the initial exchange through feed-through, "
                                     "as libcosim and Ecos do?)" if system == "feedthrough" else ""))


def test_the_command_compares_the_masters_and_exits_2_on_bad_input(systems, capsys):
    from fmu_src.ssp_masters import main

    assert main([str(systems["inline"]), "arm.x1", "rod.theta3", "--stop", "0.1", "--step", str(STEP)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == len(MASTERS) and "10 steps (the reference)" in lines[0], lines
    for line in lines[1:]:
        found = re.search(r"\| = (\S+) \(", line)
        assert "skipped" in line or (found and float(found.group(1)) <= TOL), line
    assert main([str(systems["inline"]), "arm.x1", "--stop", "0.105", "--step", str(STEP)]) == 2
    assert "0.105 s is not a whole number of steps" in capsys.readouterr().err

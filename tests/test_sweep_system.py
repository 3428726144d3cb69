"""fourbar-sweep on a system case (issue 40, point 6): faults on ``component.parameter``.

The base case is cases/motor_fourbar_healthy.toml on the bench (the ``bench_ssp`` fixture:
build/MotorFourBar.ssp, or built once).  Of the bench the tests need only its four-bar
component ``fourbar`` (fmu_src/mechanisms/fourbar_motor.toml, whose rocker bearing's friction
is ``T4``) and the connection that drives its ``crank_torque``: the signal monitored is that
connection's source (the motor's torque on the bench), read from the .ssp.

Cheap checks (no run): the sweep file's faults name ``component.parameter``, with the start
value the system gives them (an SSP binding when there is one); an unknown component or
variable and an input fed by a connection are refused, naming the key and the value; the
shipped sweeps/motor_fourbar.toml plans its scenarios on the bench.  One slow test runs two
short scenarios (fourbar.T4 doubled at 9 s, and no fault; 10 s each at the bench's 1 ms step)
on a local Dask cluster of two worker processes and checks the table and the run folders.
"""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from support import REPO
from sweep import SweepError, load_sweep, plan_scenarios

MECHANISM = "fourbar"
STOP, TRAIN, FAULT_TIME = 10.0, (4.0, 8.5), 9.0


def _driving_torque(ssp: Path) -> str:
    """The output that drives the four-bar's crank (the motor's torque on the bench)."""
    from orchestrator.ssp import read_ssp

    return next(c.source for c in read_ssp(ssp).connections if c.target == f"{MECHANISM}.crank_torque")


@pytest.fixture(scope="module")
def base_case(bench_ssp, tmp_path_factory) -> Path:
    """cases/motor_fourbar_healthy.toml, its system the fixture's .ssp."""
    text = (REPO / "cases" / "motor_fourbar_healthy.toml").read_text(encoding="utf-8")
    shipped = 'system = "../build/MotorFourBar.ssp"'
    assert shipped in text
    path = tmp_path_factory.mktemp("sweep_system_case") / "motor_fourbar_healthy.toml"
    path.write_text(text.replace(shipped, f"system = {json.dumps(str(bench_ssp))}"), encoding="utf-8")
    return path


def _sweep_file(folder: Path, case: Path, variable, *, signal: str, extra: str = "") -> Path:
    path = folder / "system_sweep.toml"
    path.write_text(f'name = "system_sweep"\ncase = {json.dumps(str(case))}\nstop = {STOP!r}\n'
                    f"[fault]\nvariable = {json.dumps(variable)}\nkind = \"step\"\nrelative = 1.0\n"
                    f"time = {FAULT_TIME!r}\nno_fault = true\n"
                    f'[monitor]\nsignal = "{signal}"\nmodel = "harmonic"\ntrain = {list(TRAIN)!r}\n'
                    + extra, encoding="utf-8")
    return path


def test_faults_name_component_parameters_at_the_systems_start_values(base_case, bench_ssp, tmp_path):
    from orchestrator.ssp import read_ssp
    from orchestrator.system_description import describe_system

    system = describe_system(bench_ssp)
    own = {f"{c.name}.{v.name}": v.start for c in system.components for v in c.model.modelVariables
           if v.causality == "parameter" and v.variability == "tunable" and v.type == "Real"}
    bound = {p.name: float(p.value) for p in read_ssp(bench_ssp).parameters if p.name in own}
    differing = [n for n, v in bound.items() if float(own[n]) != v]
    names = [f"{MECHANISM}.T4", *differing[:1]]
    sweep = load_sweep(_sweep_file(tmp_path, base_case, names, signal=_driving_torque(bench_ssp)))
    assert [v.name for v in sweep.fault.variables] == names
    assert sweep.fault.variables[0].base_value == float(own[f"{MECHANISM}.T4"])   # no binding: the FMU's start
    if differing:        # a bound parameter starts at its binding, not at its FMU's start
        assert sweep.fault.variables[1].base_value == bound[differing[0]]
    plan = plan_scenarios(sweep)
    assert {s.variable for s in plan} == {*names, None}


@pytest.mark.parametrize("variable, expected", [
    (f"{MECHANISM}.nope", r'fault\.variable = "fourbar\.nope": not a tunable Real parameter'),
    ("nobody.T4", r'fault\.variable = "nobody\.T4": not a tunable Real parameter'),
    (f"{MECHANISM}.crank_torque", r'fault\.variable = "fourbar\.crank_torque": fed by the connection from \w+\.\w+'),
])
def test_unknown_or_connected_variables_are_refused(base_case, bench_ssp, tmp_path, variable, expected):
    with pytest.raises(SweepError, match=expected):
        load_sweep(_sweep_file(tmp_path, base_case, variable, signal=_driving_torque(bench_ssp)))


def test_the_shipped_bench_sweep_plans_its_scenarios(bench_ssp, base_case, tmp_path):
    text = (REPO / "sweeps" / "motor_fourbar.toml").read_text(encoding="utf-8")
    path = tmp_path / "motor_fourbar.toml"
    path.write_text(text.replace('case = "../cases/motor_fourbar_healthy.toml"', f"case = {json.dumps(str(base_case))}"),
                    encoding="utf-8")
    sweep = load_sweep(path)
    plan = plan_scenarios(sweep)
    assert all("." in v.name for v in sweep.fault.variables)
    assert len(plan) == len(sweep.fault.variables) * len(sweep.fault.size) + 1


@pytest.mark.slow
def test_a_system_sweep_runs_on_dask_and_names_the_component_parameter(base_case, bench_ssp, tmp_path):
    from dask.distributed import Client, LocalCluster

    from fourbar_common.contract.run_record import read_run_record
    from sweep import run_sweep

    signal = _driving_torque(bench_ssp)
    path = _sweep_file(tmp_path, base_case, f"{MECHANISM}.T4", signal=signal)
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as lc, \
            Client(lc) as client:
        result = run_sweep(path, tmp_path / "out", client=client)
    table = result.table
    assert result.complete and list(table["status"]) == ["ok", "ok"], table[["scenario_id", "error"]]
    fault = table[table["has_fault"]].iloc[0]
    healthy = table[~table["has_fault"]].iloc[0]
    assert fault["variable"] == f"{MECHANISM}.T4" and fault["fault_value"] == 2 * fault["base_value"]
    assert (table["signal"] == signal).all()
    # doubling the rocker bearing's friction changes the torque the drive must give at once
    # (within the 1 s the sweep's default latency allows); the healthy run raises no alarm
    assert fault["detected"] and fault["latency"] <= 1.0, fault
    assert not healthy["detected"] and healthy["false_alarms"] == 0, healthy
    # each scenario is a system run of the bench, its fault on the component's parameter
    from orchestrator.ssp import read_ssp

    sha = read_ssp(bench_ssp).sha256
    assert (table["fmu_guid"] == sha).all()
    record = read_run_record(tmp_path / "out" / "runs" / fault["scenario_id"] / "run.json")
    assert record.system is not None and record.system.sha256 == sha
    assert [(e.variable, e.time) for e in record.events] == [(f"{MECHANISM}.T4", FAULT_TIME)]


def test_an_fmu_key_on_a_system_case_is_refused_naming_it(base_case, bench_ssp, tmp_path):
    path = _sweep_file(tmp_path, base_case, f"{MECHANISM}.T4", signal=_driving_torque(bench_ssp))
    path.write_text(f"fmu = {json.dumps(str(bench_ssp))}\n" + path.read_text(encoding="utf-8"), encoding="utf-8")
    with pytest.raises(SweepError, match=r'fmu = ".*": the base case motor_fourbar_healthy\.toml runs a system'):
        load_sweep(path)

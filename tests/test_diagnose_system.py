"""fourbar-diagnose on a system run (issue 40, point 6): the replay is the run, the candidates.

Short runs (2 s, 2000 macro steps) of the shipped bench (conftest's bench_ssp): the
diagnosis' replay (diagnose.simulator with the orchestrator's SystemInstance and the run's
master) must give the run's own rows, and a branch that changes ``motor.R`` at a grid point
the rows of a run whose case changed it there, to the last bit (the same FMUs, the same
master, the same macro steps: nothing may differ).  The full chain on the three fault cases
is tests/test_system_faults.py.
"""
from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from fourbar_common.contract.exchange import read_exchange
from fourbar_common.contract.layout import RunFolder

COLUMNS = ["motor.current", "sensor.measured", "fourbar.omega2", "controller.voltage"]
STOP, STEP, FAULT = 2.0, 0.001, 1.0


def _case(folder: Path, ssp: Path, name: str, events: str = "") -> Path:
    path = folder / f"{name}.toml"
    path.write_text(f'name = "{name}"\nsystem = {json.dumps(str(ssp))}\n[experiment]\nstop = {STOP}\nstep = {STEP}\n'
                    f"[outputs]\nvariables = {json.dumps(COLUMNS)}\n{events}", encoding="utf-8")
    return path


def _run(folder: Path, ssp: Path, name: str, events: str = "") -> Path:
    from orchestrator import run_case

    result = run_case(_case(folder, ssp, name, events), folder / name)
    assert result.status == "finished", result.error
    run = folder / name
    run_id = json.loads((run / "run.json").read_text())["run_id"]
    # the monitor's verdict, as the diagnosis reads it: an alarm just after the fault
    (run / "summary.json").write_text(json.dumps({"run_id": run_id, "first_alarm_time": FAULT + 0.1,
                                                  "signal": COLUMNS[0], "signals": COLUMNS[:2]}))
    return run


@pytest.fixture(scope="module")
def runs(bench_ssp, tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("diagnose_system")
    return {"healthy": _run(folder, bench_ssp, "healthy"),
            "winding": _run(folder, bench_ssp, "winding",
                            f'[[events]]\ntype = "step"\ntime = {FAULT}\nvariable = "motor.R"\nvalue = 1.5\n')}


def _rows(run: Path) -> np.ndarray:
    data = read_exchange(RunFolder(run).exchange, COLUMNS)
    return np.column_stack([data.values[c] for c in COLUMNS])


def test_the_replay_and_a_branch_are_the_runs_to_the_last_bit(runs):
    from diagnose.inputs import read_inputs
    from diagnose.simulator import Simulator

    inputs = read_inputs(runs["winding"], summary=runs["winding"] / "summary.json", columns=COLUMNS)
    assert inputs.master is not None and inputs.master.algorithm == "jacobi"
    assert "motor.R" in inputs.hypotheses and "fourbar.T4" in inputs.hypotheses
    grid = inputs.grid
    first, c, last = grid.index(0.5), grid.index(FAULT), grid.index(1.5)
    healthy, faulty = _rows(runs["healthy"]), _rows(runs["winding"])
    with Simulator(inputs.simulator_fmu, inputs.parameters, COLUMNS, grid, inputs.tolerance, first, last,
                   master=inputs.master) as sim:
        assert sim.method == "snapshot"
        assert np.array_equal(sim.healthy, healthy[first:last + 1])
        unchanged = sim.branch("motor.R", [1.0], c)        # restores every component and the master's memory
        changed = sim.branch("motor.R", [1.5], c)
    assert np.array_equal(unchanged, healthy[c + 1:last + 1])
    assert np.array_equal(changed, faulty[c + 1:last + 1])
    assert not np.array_equal(changed, unchanged)


def test_candidates_narrow_to_parameters_or_components(runs):
    from diagnose.errors import DiagnoseError
    from diagnose.inputs import read_inputs

    summary = runs["winding"] / "summary.json"
    narrowed = read_inputs(runs["winding"], summary=summary, candidates=["sensor", "motor.R"])
    assert narrowed.hypotheses == ("motor.R", "sensor.gain", "sensor.bias", "sensor.resolution")
    with pytest.raises(DiagnoseError, match=r"--candidates motor\.Q: not a tunable Real parameter"):
        read_inputs(runs["winding"], summary=summary, candidates=["motor.Q"])


def test_a_rebuilt_system_is_refused_with_both_digests(runs, tmp_path, capsys):
    from diagnose.cli import main

    run = runs["winding"]
    record = json.loads((run / "run.json").read_text())
    copy = tmp_path / "MotorFourBar.ssp"
    copy.write_bytes(Path(record["system"]["path"]).read_bytes())
    with zipfile.ZipFile(copy, "a") as archive:       # another file: another SHA-256, still a readable .ssp
        archive.comment = b"rebuilt"
    code = main([str(run), "--summary", str(run / "summary.json"), "--fmu", str(copy), "--out", str(tmp_path / "d")])
    err = capsys.readouterr().err
    assert code == 2 and f"{copy}: SHA-256" in err and record["system"]["sha256"] in err and "rebuilt" in err
    assert not (tmp_path / "d").exists()

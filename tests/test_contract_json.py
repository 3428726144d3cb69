"""The JSON files of a run folder and of a sweep folder through their contract modules (issue 38, item 1).

One real run folder (Case 2's L2 step, native FMU, 16 s; the monitor's harmonic replay on x2;
the diagnosis) is made once per session: each of its JSON files is read by the contract and
written back byte for byte.  A file with several bad fields raises one ContractError listing
every problem with its field; a schema newer than the reader's is refused with its field named.
"""
from __future__ import annotations

import csv
import json
import subprocess
from dataclasses import replace

import pytest

from fourbar_common.contract.diagnosis import DiagnosisRecord, read_diagnosis, write_diagnosis
from fourbar_common.contract.json_files import JsonFileError
from fourbar_common.contract.layout import RunFolder, SweepFolder
from fourbar_common.contract.problems import ContractError
from fourbar_common.contract.run_record import RunRecordError, read_run_record, write_run_record
from fourbar_common.contract.summary import MonitorSummary, read_summary, write_summary
from fourbar_common.contract.sweep_results import (RESULT_COLUMNS, DetectorSummary, SweepRecord, SweepSummary,
                                                   format_row, read_sweep_record, read_sweep_summary,
                                                   results_header, write_sweep_record, write_sweep_summary)
from support import FOURBAR_RUN, REPO, case_file


#: diagnosis.json's keys in the order fourbar-diagnose has written them since schema 1 got its last field
#: (``settled``), and those of each fit: a reader of old files and the writer must agree on them.
DIAGNOSIS_KEYS = ["schema", "case", "run_id", "verdict", "message", "best", "ramp", "ranking", "alarm_time",
                  "onset_time", "window", "rows", "columns", "units", "noise", "value_window", "first_fit",
                  "separating", "distinct_gap", "settled", "healthy_chi2", "reduced_chi2", "simulator", "branches",
                  "seconds"]
FIT_KEYS = ["parameter", "kind", "before", "value", "stderr", "change_time", "end_time", "chi2", "rows", "rms",
            "evaluations", "refused", "open_end", "at_bound", "change", "relative_change"]


@pytest.fixture(scope="session")
def made(tmp_path_factory, native_fmu):
    """Case 2 (L2 1.0 -> 1.1 m at 10 s) for 16 s, monitored on x2 (harmonic model), diagnosed:
    the run folder, the monitor's result and the diagnosis."""
    from diagnose import diagnose
    from diagnose.outputs import write_outputs
    from monitor import replay

    tmp = tmp_path_factory.mktemp("contract_json")
    folder = RunFolder(tmp / "case2")
    path = case_file("case2_fault_L2", native_fmu, tmp / "case2.toml", name="case2")
    subprocess.run([FOURBAR_RUN, str(path), "--out", str(folder.root), "--stop", "16.0", "--quiet"], check=True,
                   timeout=600)
    result = replay(folder.exchange, out_dir=folder.monitor, model="harmonic", signal="x2", plots=False)
    diagnosis = diagnose(folder.root)
    write_outputs(diagnosis, folder.diagnosis_folder, plot=False)
    return folder, result, diagnosis


@pytest.fixture(scope="session")
def run(made) -> RunFolder:
    return made[0]


def _dumped(data) -> str:
    """What fourbar-cosim has always written for a JSON file's object."""
    return json.dumps(data, indent=2, allow_nan=False) + "\n"


# -- round trips on a real run folder ------------------------------------------------------------------------

def test_run_json_reads_and_writes_back_byte_for_byte(run, tmp_path):
    record = read_run_record(run.run_record)
    assert record.case == "case2" and record.status == "finished" and record.fault_time == 10.0
    write_run_record(tmp_path / "run.json", record)
    assert (tmp_path / "run.json").read_bytes() == run.run_record.read_bytes()


def test_summary_json_reads_and_writes_back_byte_for_byte(run, tmp_path):
    summary = read_summary(run.summary)
    record = read_run_record(run.run_record)
    # what the diagnosis and the sweep ask of it, typed
    assert summary.run_id == record.run_id and summary.monitored == ("x2",) and summary.detector == "cusum"
    assert summary.alarms >= 1 and summary.first_alarm_time == summary.alarm_episodes[0].time
    assert summary.fault_time == 10.0 and 10.0 < summary.first_alarm_time < 16.0
    assert summary.period is not None and summary.period.refined_s == summary.fits[0].period.refined_s
    assert summary.outputs is not None and summary.outputs.plots == ()          # plots=False
    write_summary(tmp_path / "summary.json", summary)
    assert (tmp_path / "summary.json").read_bytes() == run.summary.read_bytes()


def test_summary_json_is_the_monitors_summary_as_it_always_wrote_it(made):
    """The file is the monitor's own ``Summary.as_json()`` (its layout, unchanged) with the outputs."""
    from monitor.outputs import jsonable

    run, result, _ = made
    expected = {**jsonable(result.summary.as_json()),
                "outputs": {"events": "events.jsonl", "evaluations": "evaluations.csv", "forecast": "forecast.csv",
                            "plots": []}}
    assert run.summary.read_text() == _dumped(expected)


def test_diagnosis_json_reads_and_writes_back_byte_for_byte(run, tmp_path):
    diagnosis = read_diagnosis(run.diagnosis)
    assert diagnosis.verdict == "explained" and diagnosis.best is not None
    assert diagnosis.best.parameter == "L2" and diagnosis.best.kind == "step"
    # 1 % of the change: the noise-free target is 0.1 % (tests/test_diagnose.py); this checks the reading
    assert diagnosis.best.value == pytest.approx(1.1, rel=1e-3)
    assert diagnosis.ranking[0] == diagnosis.best
    write_diagnosis(tmp_path / "diagnosis.json", diagnosis)
    assert (tmp_path / "diagnosis.json").read_bytes() == run.diagnosis.read_bytes()
    data = json.loads(run.diagnosis.read_text())
    assert list(data) == DIAGNOSIS_KEYS
    assert all(list(fit) == FIT_KEYS for fit in (data["best"], data["ramp"], *data["ranking"]))


def test_diagnosis_json_holds_what_the_diagnosis_found(made):
    _, _, diagnosis = made
    record = read_diagnosis(made[0].diagnosis)
    assert record == diagnosis.record()
    assert record.best.value == diagnosis.best.value and record.best.stderr == diagnosis.best.stderr
    assert record.window == diagnosis.window and record.columns == diagnosis.columns


def test_the_view_reads_the_diagnosis_through_the_contract(run):
    from view.sources import RunFolder as ViewFolder

    update = ViewFolder(run.root).poll()
    best = read_diagnosis(run.diagnosis).best
    assert update.diagnosis is not None and update.diagnosis.parameter == best.parameter == "L2"
    assert update.diagnosis.value == best.value and update.diagnosis.change_time == best.change_time


def test_an_ambiguous_settled_diagnosis_is_written_whole(tmp_path):
    """The parts a clean run's diagnosis leaves empty (``separating``, ``settled``), from the
    diagnosis's own types: an infinite standard error and a zero healthy value written as null."""
    from diagnose.diagnosis import Diagnosis, Separation, Settlement
    from diagnose.fit import Fit
    from diagnose.outputs import write_outputs

    def fit(parameter: str, value: float, stderr: float, before: float = 1.0) -> Fit:
        return Fit(parameter=parameter, kind="step", before=before, value=value, stderr=stderr, change_time=10.0,
                   end_time=10.0, chi2=812.5, rows=800, rms=0.005, evaluations=9)

    best, other = fit("m3", 1.1, 0.009), fit("g", 9.79, float("inf"), before=0.0)
    d = Diagnosis(verdict="explained", message="m3 changed", best=best, ranking=(best, other), ramp=None,
                  alarm_time=14.35, onset_time=10.4, window=(9.35, 17.35), rows=800, columns=("x2",),
                  noise={"x2": 0.005}, healthy_chi2=5e4, reduced_chi2=1.02, simulator="FourBarNative.fmu (snapshot)",
                  branches=4838, seconds=40.6, units={"x2": "m"},
                  separating=(Separation("x2", 1e-4, "m", 0.02),),
                  settled=Settlement(window=(9.35, 26.35), runner_up=other, first_gap=5.7, gap=13.5))
    write_outputs(d, tmp_path, plot=False)
    data = json.loads((tmp_path / "diagnosis.json").read_text())
    assert list(data) == DIAGNOSIS_KEYS and data["settled"]["distinct_gap"] == 13.5
    assert data["settled"]["runner_up"]["stderr"] is None and data["settled"]["runner_up"]["relative_change"] is None
    assert data["separating"] == [{"column": "x2", "difference": 1e-4, "unit": "m", "share": 0.02}]
    record = read_diagnosis(tmp_path / "diagnosis.json")
    assert record == d.record() and record.settled.runner_up.parameter == "g" and record.settled.window == (9.35, 26.35)


# -- the sweep's files ------------------------------------------------------------------------------------------

def test_sweep_json_of_a_real_sweep_file_reads_back(tmp_path, native_fmu):
    from sweep import load_sweep

    case = case_file("case1_normal", native_fmu, tmp_path)
    text = (REPO / "sweeps" / "smoke.toml").read_text()
    (tmp_path / "smoke.toml").write_text(text.replace('case = "../cases/case1_normal.toml"', f'case = "{case}"'))
    sweep = load_sweep(tmp_path / "smoke.toml")
    data = {**sweep.as_dict(), "scenarios": 8, "out_dir": str(tmp_path), "cluster": "LocalCluster(2)",
            "started_at": "2026-01-01T00:00:00+00:00"}
    path = SweepFolder(tmp_path).record
    written = write_sweep_record(path, data)
    assert path.read_text() == _dumped(json.loads(json.dumps(data, default=str)))     # the bytes written before
    again = read_sweep_record(path)
    assert again == written and again.name == "smoke" and again.fmu_guid == sweep.fmu_guid
    assert again.monitor["signal"] == "x2" and again.fault["variable"] == ["L2"]


def test_sweep_summary_and_results_row_round_trip(tmp_path):
    summary = SweepSummary(
        variable="L2", variables=("L2",), unit="m", detector=DetectorSummary("cusum", 1000.0, 0.1),
        latency_limit=2.0, scenarios=8, ok=8, failed=0,
        series=({"series": "harmonic, σ = 0 m", "noise_std": 0.0, "failed": 0,
                 "sizes": [{"relative_change": 0.02, "n": 1, "p_detected": 1.0}]},),
        classification=({"variable": "L2", "relative_change": 0.02, "right": 1, "detected": 1},),
        name="smoke", planned=8, skipped=0, ran=8, interrupted=False, wall_seconds=12.5,
        finished_at="2026-01-01T00:00:00+00:00")
    path = SweepFolder(tmp_path).summary
    assert write_sweep_summary(path, summary.to_json()) == summary
    assert read_sweep_summary(path) == summary
    assert path.read_text() == _dumped(summary.to_json())
    without = replace(summary, classification=None)
    assert "classification" not in without.to_json() and SweepSummary.from_json(without.to_json()) == without

    row = {"scenario_id": "a1", "index": 0, "relative_change": 0.1, "has_fault": True, "alarms": 2,
           "error": 'he said "no", twice', "latency": None}
    line = format_row(row)
    assert results_header().rstrip("\n").split(",") == list(RESULT_COLUMNS)
    cells = next(csv.reader([line]))
    assert cells[:2] == ["a1", "0"] and cells[list(RESULT_COLUMNS).index("error")] == row["error"]
    assert cells[list(RESULT_COLUMNS).index("relative_change")] == "0.1"
    column = list(RESULT_COLUMNS).index
    assert cells[column("has_fault")] == "True" and cells[column("latency")] == ""


# -- bad files: every problem, with its field -------------------------------------------------------------------

def test_a_bad_summary_lists_every_problem_with_its_field(run, tmp_path):
    data = json.loads(run.summary.read_text())
    data["first_alarm_time"] = "soon"
    data["alarms"] = 1.5
    data["fits"][0]["period"]["refined_s"] = [3.0]
    data["alarm_episodes"] = [{"signal": "x2"}]
    data["timing_s"] = 7
    (tmp_path / "summary.json").write_text(json.dumps(data))
    with pytest.raises(ContractError) as info:
        read_summary(tmp_path / "summary.json")
    assert {p.field for p in info.value.problems} == {"alarms", "first_alarm_time", "fits[0].period.refined_s",
                                                      "alarm_episodes[0].time", "timing_s"}
    text = str(info.value)
    assert text.startswith(f"{tmp_path / 'summary.json'}: ")
    assert 'first_alarm_time: got "soon", expected a finite number or null' in text


def test_a_bad_diagnosis_lists_every_problem_with_its_field(run):
    data = json.loads(run.diagnosis.read_text())
    data["verdict"] = "maybe"
    data["best"]["value"] = "1.1"
    data["ranking"][1]["kind"] = "jump"
    data["window"] = [1.0]
    del data["ranking"][0]["parameter"]
    with pytest.raises(ContractError) as info:
        DiagnosisRecord.from_json(data, "diagnosis.json")
    assert {p.field for p in info.value.problems} == {"verdict", "best.value", "ranking[0].parameter",
                                                      "ranking[1].kind", "window"}
    assert "verdict: got \"maybe\", expected explained | ambiguous | unexplained | no_change" in str(info.value)


def test_a_bad_sweep_record_lists_every_problem(tmp_path):
    with pytest.raises(ContractError) as info:
        SweepRecord.from_json({"description": 3, "fault": [], "scenarios": "8"}, "sweep.json")
    assert {p.field for p in info.value.problems} == {"name", "description", "fault", "scenarios"}


def test_run_json_errors_are_contract_errors_with_their_field(run, tmp_path):
    data = json.loads(run.run_record.read_text())
    data["parameters"]["L2"]["start"] = "long"
    with pytest.raises(RunRecordError) as info:
        from fourbar_common.contract.run_record import RunRecord

        RunRecord.from_json(data, "run.json")
    assert isinstance(info.value, ContractError)
    assert info.value.problems[0].field == "parameters.L2.start"
    assert str(info.value) == 'run.json: field \'parameters.L2.start\' = "long": expected a finite number ' \
                              '(the parameter is Real)'                        # the message it always had


def test_not_json_and_not_an_object_are_refused_naming_the_file(tmp_path):
    path = tmp_path / "summary.json"
    path.write_text("{not json")
    with pytest.raises(JsonFileError, match=f"^{path}: not valid JSON"):
        read_summary(path)
    path.write_text("[1, 2]")
    with pytest.raises(ContractError) as info:
        read_summary(path)
    assert info.value.problems[0].field == "" and "an array; expected a JSON object" in str(info.value)


def test_contract_errors_cross_processes_whole():
    """A Dask worker's error reaches the sweep pickled: its source, problems and text survive."""
    import pickle

    from fourbar_common.contract.problems import Problem
    from monitor import OptionError

    errors = [ContractError("summary.json", [Problem("alarms", "got 1.5, expected an integer")]),
              RunRecordError("run.json", Problem("status", "bad"), "run.json: field 'status' = 1: expected a string"),
              OptionError("a message in no known form", [Problem("window", "expected a positive number")])]
    for error in errors:
        again = pickle.loads(pickle.dumps(error))
        assert type(again) is type(error) and str(again) == str(error) and again.problems == error.problems


# -- schema versions --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("reader, build", [
    (MonitorSummary.from_json, lambda: MonitorSummary().to_json()),
    (DiagnosisRecord.from_json, lambda: DiagnosisRecord(verdict="no_change").to_json()),
    (SweepRecord.from_json, lambda: SweepRecord(name="s").to_json()),
])
def test_a_newer_schema_is_refused_and_an_older_file_without_one_is_read(reader, build):
    data = build()
    data["schema"] = 2
    with pytest.raises(ContractError) as info:
        reader(data, "file.json")
    assert [p.field for p in info.value.problems] == ["schema"]
    assert "written by a newer fourbar-cosim: update this one" in str(info.value)
    data.pop("schema")
    assert reader(data, "file.json").schema == 1


def test_a_summary_written_before_grid_and_indeterminate_still_reads(run):
    """Old run folders: summary.json written before the time-grid check lacks ``grid`` and ``indeterminate``."""
    data = json.loads(run.summary.read_text())
    del data["grid"], data["indeterminate"]
    summary = MonitorSummary.from_json(data)
    assert summary.grid is None and summary.indeterminate is None and summary.first_alarm_time is not None


# -- the monitor's option errors, structured for the sweep ------------------------------------------------------

def test_option_errors_carry_their_problems_by_option():
    from monitor import MonitorOptions, OptionError

    with pytest.raises(OptionError) as info:
        MonitorOptions(model="x", window=-1.0).validated()
    problems = info.value.problems
    assert [p.field for p in problems] == ["model", "window"]
    assert str(info.value).splitlines()[1:] == [f"  {p}" for p in problems]     # the text is unchanged
    made = OptionError.listing("monitor options", problems)
    assert str(made) == str(info.value) and made.problems == problems


def test_a_sweep_file_names_each_bad_monitor_option_with_its_value(tmp_path, native_fmu):
    from sweep import SweepError, load_sweep

    case = case_file("case1_normal", native_fmu, tmp_path)
    text = (REPO / "sweeps" / "smoke.toml").read_text().replace('case = "../cases/case1_normal.toml"',
                                                                f'case = "{case}"')
    (tmp_path / "bad.toml").write_text(text.replace("[report]", "window = -1.0\nevery = 0.0\n\n[report]"))
    with pytest.raises(SweepError) as info:
        load_sweep(tmp_path / "bad.toml")
    assert "monitor.window = -1.0: expected a positive number of seconds, got -1.0" in str(info.value)
    assert "monitor.every = 0.0: " in str(info.value)


# -- no part parses or dumps a run folder's JSON file itself -------------------------------------------------------

#: Calls of the JSON parsers and writers the parts still make, and why: none reads or writes a
#: JSON file of a run or sweep folder.
ALLOWED_JSON_CALLS = {
    ("orchestrator/validation.py", "json.dumps"),   # a value shown in a message
    ("sweep/plan.py", "json.dumps"),                # a scenario's canonical text, hashed into its id
}


def test_the_parts_read_and_write_json_files_only_through_the_contract():
    import ast

    found = set()
    for part in ("orchestrator", "monitor", "view", "diagnose", "sweep"):
        for path in sorted((REPO / part).glob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if not isinstance(node, ast.Call):
                    continue
                f = node.func
                name = (f"{f.value.id}.{f.attr}" if isinstance(f, ast.Attribute) and isinstance(f.value, ast.Name)
                        else f.id if isinstance(f, ast.Name) else "")
                if name in ("json.loads", "json.load", "json.dumps", "json.dump", "read_json_file", "parse_json",
                            "write_json_atomic", "write_json_file"):
                    found.add((f"{part}/{path.name}", name))
    assert found <= ALLOWED_JSON_CALLS, sorted(found - ALLOWED_JSON_CALLS)


def test_the_parts_join_no_contract_file_name_into_a_path():
    """``folder / "summary.json"`` and the like are spelled once, in contract/layout.py."""
    import ast

    from fourbar_common.contract import layout

    names = {layout.EXCHANGE, layout.RUN_RECORD, layout.MONITOR_FOLDER, layout.EVENTS, layout.EVALUATIONS,
             layout.FORECAST, layout.SUMMARY, layout.DIAGNOSIS, layout.DIAGNOSIS_FOLDER, layout.SWEEP_RECORD,
             layout.SWEEP_RESULTS, layout.SWEEP_SUMMARY, layout.SWEEP_RUNS}
    joined = []
    for part in ("orchestrator", "monitor", "view", "diagnose", "sweep"):
        for path in sorted((REPO / part).glob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                right = node.right if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Div) else None
                parts = str(right.value).split("/") if isinstance(right, ast.Constant) else []
                if parts and (parts[0] in names or parts[-1] in names):
                    joined.append(f"{part}/{path.name}:{node.lineno}: / {right.value!r}")
    assert not joined, joined

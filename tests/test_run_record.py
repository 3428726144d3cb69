"""run.json as one typed record (fourbar_common.contract.run_record.RunRecord): every
parameter's start value with its source, read back by the monitor and the diagnosis; case files that name no
parameter, or only some, run, monitor and diagnose (issue 23, item 1).

The FMU's parameters are read here with FMPy directly (not through the orchestrator's
FmuDescription), so a writer that drops or mislabels one is caught.
"""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from fourbar_common.contract.run_record import RunRecord, RunRecordError, read_run_record
from support import FOURBAR_MONITOR, FOURBAR_RUN

FOURBAR_DIAGNOSE = str(Path(sys.executable).parent / "fourbar-diagnose")


def _fmu_parameters(fmu: Path) -> dict[str, object]:
    """Every parameter of ``fmu`` with its declared start value, from modelDescription.xml (FMPy)."""
    from fmpy import read_model_description

    starts = {}
    for v in read_model_description(str(fmu)).modelVariables:
        if v.causality == "parameter":
            starts[v.name] = float(v.start) if v.type == "Real" else v.start
    return starts


def _case(path: Path, fmu: Path, *, parameters: str = "", events: str = "", stop: float = 0.5) -> Path:
    path.write_text(f'name = "{path.stem}"\nfmu = {json.dumps(Path(fmu).as_posix())}\n'
                    f"[experiment]\nstop = {stop!r}\nstep = 0.01\n{parameters}{events}", encoding="utf-8")
    return path


def _step(variable: str, value: float, time: float) -> str:
    return f'\n[[events]]\ntype = "step"\ntime = {time!r}\nvariable = "{variable}"\nvalue = {value!r}\n'


# -- the record written by a run ------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def subset_run(native_fmu, tmp_path_factory):
    """A 0.5 s run of a case naming L1 and L3 only, L3 overridden (``overrides=``), L2 stepped."""
    from orchestrator import load_case, run_case

    tmp = tmp_path_factory.mktemp("record")
    path = _case(tmp / "subset.toml", native_fmu, parameters="[parameters]\nL1 = 3.1\nL3 = 4.0\n",
                 events=_step("L2", 1.01, 0.2))
    case = load_case(path, overrides={"L3": 4.1})
    # run_case validates the Case again (apply_overrides with stop=): the override must stay an override.
    result = run_case(case, tmp / "out", stop=0.4)
    assert result.ok, result.error
    return result


def test_every_fmu_parameter_is_recorded_with_its_source(subset_run, native_fmu):
    record = read_run_record(subset_run.run_json_path)
    fmu = _fmu_parameters(native_fmu)
    assert record.schema == 2 and record.complete
    assert [p.name for p in record.parameters] == list(fmu)          # all of them, tunable and fixed, in FMU order
    assert record.sources == {**{n: "fmu" for n in fmu}, "L1": "case", "L3": "set"}
    assert record.start_values == {**fmu, "L1": 3.1, "L3": 4.1}
    # the start value, not the value after the step (events are recorded apart)
    assert record.start_values["L2"] == 1.0 and record.events[0].value == 1.01
    integrator = record.parameter("integrator")
    assert (integrator.type, integrator.variability, integrator.start) == ("String", "fixed", "DOP853")
    theta = record.parameter("theta2_start")
    assert (theta.type, theta.variability, theta.unit) == ("Real", "fixed", "rad")
    assert record.parameter("g").tunable and record.parameter("g").unit == "m/s2"
    assert record.experiment.stop == 0.4 and record.rows_written == 41 and record.status == "finished"


def test_the_record_round_trips(subset_run):
    on_disk = json.loads(subset_run.run_json_path.read_text(encoding="utf-8"))
    record = RunRecord.from_json(on_disk)
    assert record.to_json() == on_disk                       # what the writer wrote is exactly the schema
    assert RunRecord.from_json(record.to_json()) == record
    assert on_disk["parameters"]["L3"] == {"start": 4.1, "source": "set", "type": "Real", "variability": "tunable",
                                           "unit": "m"}


BROKEN = {
    "parameters.L2.start": lambda d: d["parameters"]["L2"].update(start="long"),
    "parameters.L2.source": lambda d: d["parameters"]["L2"].update(source="cli"),
    "parameters.integrator.start": lambda d: d["parameters"]["integrator"].update(start=3),
    "parameters.g.start": lambda d: d["parameters"]["g"].pop("start"),
    "experiment.step": lambda d: d["experiment"].pop("step"),
    "fmu.guid": lambda d: d["fmu"].update(guid=None),
    "events[0].time": lambda d: d["events"][0].update(time="soon"),
    "status": lambda d: d.update(status="done"),
    "schema": lambda d: d.update(schema=3),
    "parameters": lambda d: d.update(parameters=[]),
}


@pytest.mark.parametrize("field", list(BROKEN))
def test_a_broken_field_is_named(subset_run, field):
    data = json.loads(subset_run.run_json_path.read_text(encoding="utf-8"))
    BROKEN[field](data)
    with pytest.raises(RunRecordError, match=re.escape(f"run.json: field '{field}'")):
        RunRecord.from_json(data, "run.json")


def test_readers_report_a_broken_record_by_field(subset_run, tmp_path):
    """The monitor's reader and fourbar-diagnose (exit 2, no traceback) name the field."""
    from monitor import read_run_info

    data = json.loads(subset_run.run_json_path.read_text(encoding="utf-8"))
    data["parameters"]["L2"]["start"] = "long"
    (tmp_path / "run.json").write_text(json.dumps(data), encoding="utf-8")
    info = read_run_info(tmp_path / "exchange.csv")
    assert info.status == "unreadable" and "field 'parameters.L2.start'" in info.error
    proc = subprocess.run([FOURBAR_DIAGNOSE, str(tmp_path), "--no-plot"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert "field 'parameters.L2.start'" in proc.stderr and "Traceback" not in proc.stderr


def test_a_schema_1_record_is_read_and_completed_from_the_fmu(subset_run, native_fmu):
    """Schema 1 kept a flat mapping of what the case set, without sources: read as source
    "unknown"; completed_with adds the FMU's defaults (what diagnose does for such a run)."""
    from orchestrator.case import describe_fmu

    new = json.loads(subset_run.run_json_path.read_text(encoding="utf-8"))
    old = {**new, "schema": 1, "parameters": {"L1": 3.1, "L3": 4.1}}
    record = RunRecord.from_json(old)
    assert record.schema == 1 and not record.complete
    assert record.start_values == {"L1": 3.1, "L3": 4.1} and set(record.sources.values()) == {"unknown"}
    full = record.completed_with(describe_fmu(native_fmu).parameter_starts())
    assert full.start_values == {**_fmu_parameters(native_fmu), "L1": 3.1, "L3": 4.1}
    assert full.sources["L2"] == "fmu" and full.sources["L1"] == "unknown"
    assert full.parameter("L1").variability == "tunable"
    # the minimal schema 1 files older tools (and tests) wrote: absent fields are None
    minimal = RunRecord.from_json({"schema": 1, "status": "running", "fault_time": 10.0, "events": [], "error": None})
    assert minimal.fault_time == 10.0 and minimal.fmu is None and minimal.parameters == ()


def test_a_set_value_keeps_its_source_through_revalidation(native_fmu, tmp_path):
    """A Case carries which values came from overrides, through apply_overrides and replace."""
    from orchestrator import apply_overrides, load_case

    path = _case(tmp_path / "c.toml", native_fmu, parameters="[parameters]\nL1 = 3.1\n")
    case = load_case(path, overrides={"L2": 1.05})
    assert case.overridden == {"L2"}
    again = apply_overrides(replace(case, description="changed"), stop=0.3, overrides={"m2": 1.2})
    assert again.overridden == {"L2", "m2"} and again.parameters == {"L1": 3.1, "L2": 1.05, "m2": 1.2}


# -- the whole chain on case files that do not name every parameter ---------------------------------------------

# Three case files a user may write, each with a 2 % step of L2 at 20 s of a 40 s run:
# no [parameters] (the FMU's own values), another geometry naming only L1-L4 (assembles:
# it runs), and Table 1 with only the start angle changed.
CHAIN = {
    "no_parameters": ("", 1.0),
    "other_geometry": ("[parameters]\nL1 = 3.2\nL2 = 0.9\nL3 = 3.8\nL4 = 2.6\n", 0.9),
    "start_angle_only": ("[parameters]\ntheta2_start = 0.7\n", 1.0),
}
FAULT_TIME = 20.0


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CHAIN))
def test_a_case_without_every_parameter_runs_monitors_and_diagnoses(tmp_path, native_fmu, name):
    parameters, l2 = CHAIN[name]
    after = round(l2 * 1.02, 12)
    path = _case(tmp_path / f"{name}.toml", native_fmu, parameters=parameters,
                 events=_step("L2", after, FAULT_TIME), stop=40.0)
    run = tmp_path / "run"
    subprocess.run([FOURBAR_RUN, str(path), "--out", str(run), "--quiet"], check=True, timeout=300)
    record = read_run_record(run / "run.json")
    assert record.start_values["L2"] == l2 and len(record.parameters) == len(_fmu_parameters(native_fmu))

    proc = subprocess.run([FOURBAR_MONITOR, str(run / "exchange.csv"), "--model", "harmonic", "--no-plots"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stdout + proc.stderr              # 1: an alarm
    summary = json.loads((run / "monitor" / "summary.json").read_text())
    assert summary["false_alarms_before_fault"] == 0
    # Noise-free 2 % step: detected within 0.03 s here (measured 0.02-0.03 s); 1 s leaves room
    # for the detector's redesign without letting a missed step pass.
    assert FAULT_TIME < summary["first_alarm_time"] <= FAULT_TIME + 1.0

    proc = subprocess.run([FOURBAR_DIAGNOSE, str(run), "--no-plot"], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    best = json.loads((run / "diagnosis" / "diagnosis.json").read_text())["best"]
    assert best["parameter"] == "L2" and best["kind"] == "step"
    assert best["before"] == pytest.approx(l2, rel=1e-12)       # the healthy value run.json recorded
    # noise-free: the diagnosis targets, value within 0.1 % and time within 0.02 s
    assert best["value"] == pytest.approx(after, rel=1e-3)
    assert best["change_time"] == pytest.approx(FAULT_TIME, abs=0.02)


# -- issue 36: what is not a run record is refused, naming the file and what is wrong ------------------
@pytest.mark.parametrize("text, expected", [
    ("[" * 100_000 + "]" * 100_000, "JSON nested too deeply"),
    ('{"schema": 2, "x": ' + "{\"a\": " * 50_000 + "1" + "}" * 50_000 + "}", "JSON nested too deeply"),
    ("{}", "not a run record: fields schema, status, run_id, case, experiment, rows_written are missing "
           "(the object is empty)"),
    ('{"hello": 1}', "not a run record: fields schema, status"),
    ("", "is empty (0 bytes): not a run record"),
    ("  \n", "is empty (3 bytes): not a run record"),
])
def test_what_is_not_a_record_is_refused(tmp_path, text, expected):
    path = tmp_path / "run.json"
    path.write_text(text)
    with pytest.raises(RunRecordError) as info:
        read_run_record(path)
    assert str(info.value).startswith(f"{path}: ") and expected in str(info.value)


def test_a_huge_run_json_is_refused(tmp_path, monkeypatch):
    import fourbar_common.contract.json_files as rr

    path = tmp_path / "run.json"
    path.write_text('{"schema": 2, "pad": "' + "x" * 2000 + '"}')
    monkeypatch.setattr(rr, "MAX_JSON_BYTES", 1000)       # the default (16 MB) with a small file
    with pytest.raises(RunRecordError, match="larger than 1000 bytes"):
        read_run_record(path)


@pytest.mark.parametrize("make, kind", [(os.mkfifo, "a FIFO"), (os.mkdir, "a directory")])
def test_a_fifo_or_folder_is_not_opened(tmp_path, make, kind):
    from fourbar_common.files import NotRegularFileError, open_regular

    path = tmp_path / "run.json"
    make(path)                         # a blocking open of a FIFO without a writer would hang here
    with pytest.raises(RunRecordError, match=f"run.json: is {kind}"):
        read_run_record(path)
    with pytest.raises(NotRegularFileError, match=f"is {kind}"):
        open_regular(path)

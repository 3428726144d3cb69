"""The view's reading of a run folder, without a browser: complete lines only, a replaced file
starts again, bad rows are counted, the timeline's windows and bins (issue 25)."""
from __future__ import annotations

import json
import os

import numpy as np
import pandas as pd
import pytest

from view import RunFolder, RunFolderError, check_run_folder
from view.timeline import Series, Timeline


def _record(run_id: str = "a" * 32, status: str = "running") -> dict:
    return {"schema": 2, "status": status, "run_id": run_id, "case": "c", "case_file": None, "description": "",
            "fmu": {"path": "F.fmu", "guid": "g", "model_name": "M"},
            "experiment": {"start": 0.0, "stop": 10.0, "step": 0.01, "tolerance": None},
            "parameters": {}, "events": [], "fault_time": None, "outputs": ["x2"], "units": {}, "noise": None,
            "exchange": {"flush_interval": 1.0, "realtime_factor": 0.0, "max_rows": 1000},
            "rows_written": 0, "last_time": None, "started_at": "2026-11-24T00:00:00Z", "updated_at": None,
            "finished_at": None, "wall_time_s": 0.0, "error": None,
            "writer": {"pid": os.getpid(), "host": __import__("socket").gethostname(), "heartbeat_s": 2.0}}


@pytest.fixture
def folder(tmp_path):
    (tmp_path / "run.json").write_text(json.dumps(_record()))
    (tmp_path / "exchange.csv").write_text("time,x2\n")
    return tmp_path


def test_only_complete_lines_are_read_and_each_once(folder):
    source = RunFolder(folder)
    first = source.poll()
    assert first.record is not None and first.rows is None
    with open(folder / "exchange.csv", "a") as f:
        f.write("0.0,1.0\n0.01,1.5\n0.02,2.")           # the last line is not yet written
    rows = source.poll().rows
    assert list(rows["time"]) == [0.0, 0.01] and list(rows["x2"]) == [1.0, 1.5]
    assert source.poll().rows is None                   # nothing new
    with open(folder / "exchange.csv", "a") as f:
        f.write("5\n")
    assert list(source.poll().rows["x2"]) == [2.5]      # the completed line, whole


def test_a_new_run_in_the_folder_starts_again(folder):
    source = RunFolder(folder)
    (folder / "exchange.csv").write_text("time,x2\n0.0,1.0\n0.01,2.0\n")
    source.poll()
    # fourbar-run replaces both files for a new run: a new run_id, a shorter exchange file
    (folder / "exchange.csv").write_text("time,x2\n0.0,7.0\n")
    (folder / "run.json").write_text(json.dumps(_record("b" * 32)))
    update = source.poll()
    assert update.restarted and list(update.rows["x2"]) == [7.0]
    timeline = Timeline()
    timeline.feed(update)
    assert timeline.generation == 1 and timeline.rows.n == 1


def test_rows_that_do_not_parse_are_skipped_and_said(folder):
    (folder / "exchange.csv").write_text("time,x2\n0.0,1.0\nnot,a,row\n0.02,x\n0.03,3.0\n")
    update = RunFolder(folder).poll()
    assert list(update.rows["time"]) == [0.0, 0.02, 0.03]     # 0.02's x2 is NaN: the row's time is kept
    assert any("do not parse" in w for w in update.warnings), update.warnings


def test_a_dead_writer_is_noticed(folder):
    record = _record()
    record["writer"]["pid"] = 2 ** 22 + 12345             # above pid_max's default: no such process
    (folder / "run.json").write_text(json.dumps(record))
    assert RunFolder(folder).poll().writer_gone
    record["status"] = "finished"
    (folder / "run.json").write_text(json.dumps(record))
    assert not RunFolder(folder).poll().writer_gone


def test_a_broken_run_json_is_a_problem_not_an_exception(folder):
    record = _record()
    record["experiment"]["step"] = "fast"
    (folder / "run.json").write_text(json.dumps(record))
    update = RunFolder(folder).poll()
    assert update.record is None and "experiment.step" in update.record_problem


def test_what_is_not_a_run_folder_is_said(tmp_path):
    with pytest.raises(RunFolderError, match="no such folder"):
        check_run_folder(tmp_path / "missing")
    with pytest.raises(RunFolderError, match="not a run folder"):
        check_run_folder(tmp_path)
    (tmp_path / "exchange.csv").write_text("time,x2\n")
    with pytest.raises(RunFolderError, match="no run.json"):
        check_run_folder(tmp_path)


def test_series_windows_and_bins():
    s = Series(("time", "v"))
    t = np.arange(0, 3600, 0.01)                        # an hour at 100 Hz
    v = np.sin(2 * np.pi * t / 3.0)
    for k in range(0, len(t), 50_000):                  # appended in blocks, as polls do
        s.append(pd.DataFrame({"time": t[k:k + 50_000], "v": v[k:k + 50_000]}))
    assert s.n == len(t)
    assert s.append(pd.DataFrame({"time": [1.0], "v": [9.0]})) == 0      # not after the last row: ignored
    part = s.between(100.0, 120.0, ("v",))
    assert len(part["time"]) == 2000 and part["time"][0] > 100.0 and part["time"][-1] == pytest.approx(120.0)
    env = s.envelope("v", 3600.0, 2.4)                 # 1,500 bins over the hour
    assert len(env["time"]) == 1500
    # a 3 s sine in 2.4 s bins: each bin's max is near the top and min near the bottom, or the
    # bin holds one side of the swing; never outside [-1, 1]
    assert env["high"].max() <= 1.0 and env["low"].min() >= -1.0 and (env["high"] - env["low"]).min() > 0.5
    assert s.index_at(0.005) == 0 and s.index_at(-1.0) == -1
    assert s.nbytes <= 2 * len(t) * 2 * 8               # two float columns, doubling growth


# -- issue 36: files that are not files, JSON nested too deeply, empty records ----------------------
NESTED = "[" * 100_000 + "]" * 100_000


@pytest.mark.parametrize("name", ["exchange.csv", "run.json", "monitor/events.jsonl"])
def test_a_fifo_in_the_folder_is_refused_without_blocking(folder, name):
    (folder / "monitor").mkdir()
    path = folder / name
    path.unlink(missing_ok=True)
    os.mkfifo(path)            # opened for reading in blocking mode, it would hang (no writer)
    with pytest.raises(RunFolderError, match=f"{name}: is a FIFO \\(named pipe\\), not a regular file"):
        check_run_folder(folder)


def test_a_fifo_appearing_later_is_never_opened(folder):
    source = RunFolder(folder)
    (folder / "monitor").mkdir()
    os.mkfifo(folder / "monitor" / "events.jsonl")
    update = source.poll()              # returns (a blocking open would hang the test)
    assert update.events == []


@pytest.mark.parametrize("text, expected", [
    (NESTED, "JSON nested too deeply"),
    ("{}", "not a run record: fields schema, status, run_id, case, experiment, rows_written are missing"),
    ("", "is empty (0 bytes): not a run record"),
])
def test_nested_or_empty_run_json_is_a_problem(folder, text, expected):
    (folder / "run.json").write_text(text)
    update = RunFolder(folder).poll()
    assert update.record is None and expected in update.record_problem


def test_a_nested_events_line_or_diagnosis_is_a_warning(folder):
    (folder / "monitor").mkdir()
    event = {"time": 1.0, "event": "alarm", "state": "alarm", "statistic": 2.0, "threshold": 1.0}
    (folder / "monitor" / "events.jsonl").write_text(NESTED + "\n" + json.dumps(event) + "\n" + '{"time": 2.0')
    (folder / "diagnosis").mkdir()
    (folder / "diagnosis" / "diagnosis.json").write_text(NESTED)
    update = RunFolder(folder).poll()
    assert [e.time for e in update.events] == [1.0]            # the torn last line is not read
    assert any("events.jsonl: JSON nested too deeply" in w for w in update.warnings)
    assert any("diagnosis.json: cannot be read" in w and "nested too deeply" in w for w in update.warnings)

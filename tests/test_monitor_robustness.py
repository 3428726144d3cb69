"""Every robustness case of issue 4 has a defined behaviour — skip and count with a warning,
or a clear error (exit code 2) — and never a traceback.

The files are orchestrator-produced Case 1 / Case 2 exchange files, copied and then damaged.
Following is driven through ``follow(..., sleep=script)``: the script runs one action at each
idle poll, so appending, truncating or replacing the file happens at known points and the
tests do not depend on timing.  Models: ``harmonic`` (fast); the file handling is the same
for both.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from monitor import (ExchangeFormatError, ExchangeMissingError, ExchangeReader, ExchangeWarning, Monitor,
                     MonitorOptions, follow, read_exchange, replay)
from monitor.cli import main
from monitor.errors import RunJsonError
from test_monitor_support import copy_run, orchestrated

FAST = dict(model="harmonic")


@pytest.fixture(scope="module")
def case2(tmp_path_factory, fourbar_fmu) -> Path:
    return orchestrated(tmp_path_factory, fourbar_fmu, "case2")


@pytest.fixture(scope="module")
def case1(tmp_path_factory, fourbar_fmu) -> Path:
    return orchestrated(tmp_path_factory, fourbar_fmu, "case1")


@pytest.fixture(scope="module")
def case2_lines(case2) -> list[bytes]:
    """[header, t=0.00, t=0.01, ...] in the paper's seven columns (time and the link centres:
    the joint positions a run also records are cut off, so the damaged rows below are 7 wide)."""
    lines = case2.read_bytes().splitlines(keepends=True)
    assert lines[0].startswith(b"time,x2,y2,x3,y3,x4,y4")
    return [b",".join(line.rstrip(b"\n").split(b",")[:7]) + b"\n" for line in lines]


@pytest.fixture(scope="module")
def reference(case2):
    return replay(case2, **FAST)


def row(t: float) -> int:
    """Index in the line list of the row at time t (0.01 s grid)."""
    return 1 + int(round(t / 0.01))


def run_json(directory: Path, status: str, fault_time: float | None = 10.0, error: str | None = None) -> None:
    (directory / "run.json").write_text(json.dumps({"schema": 1, "status": status, "fault_time": fault_time,
                                                    "events": [], "error": error}))


def cli(argv: list[str], capsys) -> tuple[int, str, str]:
    code = main(argv)
    printed = capsys.readouterr()
    assert "Traceback" not in printed.err + printed.out
    return code, printed.out, printed.err


class Script:
    """A fake ``sleep`` for follow(): runs the next action at each idle poll."""

    def __init__(self, *actions):
        self.actions = list(actions)
        self.calls = 0

    def __call__(self, seconds: float) -> None:
        self.calls += 1
        if self.actions:
            self.actions.pop(0)()
        elif self.calls > 10_000:
            raise AssertionError("follow() did not stop")


# -- the file is not there yet ----------------------------------------------------------------
def test_follow_waits_for_the_file(case2, reference, tmp_path):
    target = tmp_path / "late" / "exchange.csv"
    waits = []
    script = Script(lambda: None, lambda: None, lambda: copy_run(case2, target.parent))
    r = follow(target, poll=0.01, timeout=30, sleep=script, on_wait=waits.append, **FAST)
    assert len(waits) == 2 and "waiting for" in waits[0]
    assert waits[1].startswith("following run ") and json.loads((target.parent / "run.json").read_text())["run_id"] in waits[1]
    assert r.first_alarm_time == reference.first_alarm_time == pytest.approx(10.01)
    assert r.evaluations.equals(reference.evaluations)


def test_follow_gives_up_when_the_file_never_comes(tmp_path, capsys):
    with pytest.raises(ExchangeMissingError, match="did not appear within 0.2 s"):
        follow(tmp_path / "never.csv", poll=0.02, timeout=0.2, **FAST)
    code, out, err = cli([str(tmp_path / "never.csv"), "--follow", "--timeout", "0.2", "--poll", "0.02",
                          "--model", "harmonic"], capsys)
    assert code == 2 and "did not appear within 0.2 s" in err


def test_replay_of_a_missing_file_or_a_directory(tmp_path, capsys):
    code, _, err = cli([str(tmp_path / "nothing.csv")], capsys)
    assert code == 2 and "nothing.csv: exchange file not found" in err
    code, _, err = cli([str(tmp_path)], capsys)
    assert code == 2 and "is a directory with no exchange.csv in it" in err


def test_a_run_folder_is_read_as_its_exchange_file(case2, reference, tmp_path, capsys):
    """fourbar-monitor RUN_DIR, as fourbar-diagnose and fourbar-view take it: its exchange.csv,
    outputs in RUN_DIR/monitor; the library's replay alike."""
    copy_run(case2, tmp_path / "run")
    code, out, err = cli([str(tmp_path / "run"), "--model", "harmonic", "--no-plots"], capsys)
    assert code == 1, err                   # Case 2 alarms
    summary = json.loads((tmp_path / "run" / "monitor" / "summary.json").read_text())
    assert summary["first_alarm_time"] == reference.first_alarm_time
    assert replay(tmp_path / "run", out_dir=tmp_path / "lib", **FAST).first_alarm_time == reference.first_alarm_time


# -- empty, header only, partial lines ----------------------------------------------------------
def test_empty_file(tmp_path, capsys):
    (tmp_path / "exchange.csv").write_bytes(b"")
    code, _, err = cli([str(tmp_path / "exchange.csv"), "--model", "harmonic"], capsys)
    assert code == 2 and "file is empty; expected a header line" in err
    with pytest.raises(ExchangeFormatError, match="empty"):
        read_exchange(tmp_path / "exchange.csv")


def test_header_only(tmp_path, case2_lines, capsys):
    (tmp_path / "exchange.csv").write_bytes(case2_lines[0])
    code, _, err = cli([str(tmp_path / "exchange.csv"), "--model", "harmonic"], capsys)
    assert code == 2 and "has a header but no data rows" in err
    # a header still being written (no newline yet) is not a header
    (tmp_path / "exchange.csv").write_bytes(case2_lines[0][:9])
    code, _, err = cli([str(tmp_path / "exchange.csv"), "--model", "harmonic"], capsys)
    assert code == 2 and "header line is not terminated" in err


def test_follow_header_only_then_rows(case2, case2_lines, reference, tmp_path):
    """While following, an empty or header-only file means 'not written yet': wait."""
    path = tmp_path / "exchange.csv"
    path.write_bytes(b"")
    run_json(tmp_path, "running")

    def header():
        path.write_bytes(case2_lines[0][:5])

    def header_done():
        path.write_bytes(case2_lines[0])

    def rows():
        path.write_bytes(b"".join(case2_lines))
        run_json(tmp_path, "finished")

    r = follow(path, poll=0.01, timeout=30, sleep=Script(header, header_done, rows), **FAST)
    assert r.evaluations.equals(reference.evaluations)


def test_partial_last_line_is_not_read(case2_lines, reference, tmp_path, capsys):
    path = tmp_path / "exchange.csv"
    cut = case2_lines[row(50.0)]
    path.write_bytes(b"".join(case2_lines[:row(50.0)]) + cut[:11])     # '50.0,0.1234' without newline
    run_json(tmp_path, "finished")
    warnings = []
    r = replay(path, on_warning=warnings.append, **FAST)
    assert r.summary.last_time == pytest.approx(49.99)
    assert r.summary.rows.skipped == 0
    assert any("incomplete last line (11 bytes without newline)" in w for w in warnings)
    assert r.first_alarm_time == reference.first_alarm_time
    # following: the line is read once it is complete
    path.write_bytes(b"".join(case2_lines[:row(50.0)]) + cut[:11])
    run_json(tmp_path, "running")

    def complete():
        with open(path, "ab") as fh:
            fh.write(cut[11:] + b"".join(case2_lines[row(50.0) + 1:]))
        run_json(tmp_path, "finished")

    r = follow(path, poll=0.01, timeout=30, sleep=Script(complete), **FAST)
    assert r.summary.rows.rows == 10001 and r.summary.rows.skipped == 0
    assert r.evaluations.equals(reference.evaluations)


# -- bad rows: skipped and counted ----------------------------------------------------------------
def damaged(lines: list[bytes], replacements: dict[int, bytes], inserts: dict[int, list[bytes]]) -> bytes:
    out = []
    for i, line in enumerate(lines):
        out.extend(inserts.get(i, []))
        out.append(replacements.get(i, line))
    return b"".join(out)


def test_malformed_and_non_numeric_rows(case2_lines, reference, tmp_path, capsys):
    path = tmp_path / "exchange.csv"
    bad = {
        row(5.0): b"5.0,abc,0.1,0.2,0.3,0.4,0.5\n",              # non-numeric x2 (inside training)
        row(30.0): b"30.0,0.1,0.2\n",                             # too few fields
        row(40.0): b"\n",                                         # blank line
        row(41.0): b"41.0,0.25,,0.1,0.2,0.3,0.4\n",               # empty y2 field: not used, row kept
    }
    inserts = {row(20.0): [b"this is not a row\n", b"20.0,0.1,0.2,0.3,0.4,0.5,0.6,0.7\n"]}
    path.write_bytes(damaged(case2_lines, bad, inserts))
    run_json(tmp_path, "finished")
    code, out, err = cli([str(path), "--model", "harmonic", "--no-plots", "--out", str(tmp_path / "m")], capsys)
    assert code == 1
    assert "line 502: column x2: value 'abc' is not a number; row skipped" in err
    assert "3 fields, expected 7" in err and "blank line" in err and "8 fields, expected 7" in err
    summary = json.loads((tmp_path / "m" / "summary.json").read_text())
    assert summary["rows"]["non_numeric"] == 1 and summary["rows"]["malformed"] == 4
    assert summary["rows"]["rows"] == 10001 - 4 + 1      # 41.0 with an empty y2 is valid for x2
    assert summary["first_alarm_time"] == reference.first_alarm_time
    with pytest.warns(ExchangeWarning, match="skipped 5 of"):
        df = read_exchange(path, columns=["x2"])
    assert df.attrs["reader_stats"]["skipped"] == 5
    with pytest.warns(ExchangeWarning):
        assert len(read_exchange(path)) == 10001 - 4     # all columns: the 41.0 row (empty y2) goes too


def test_nan_and_inf(case2_lines, reference, tmp_path, capsys):
    path = tmp_path / "exchange.csv"
    bad = {row(3.0): b"3.0,nan,0,0,0,0,0\n", row(25.0): b"25.0,inf,0,0,0,0,0\n",
           row(26.0): b"26.0,-Infinity,0,0,0,0,0\n", row(27.0): b"NaN,0.1,0,0,0,0,0\n"}
    path.write_bytes(damaged(case2_lines, bad, {}))
    warnings = []
    r = replay(path, on_warning=warnings.append, **FAST)
    assert r.summary.rows.non_finite == 4
    assert any("column x2: value 'inf' is not finite" in w for w in warnings)
    assert any("column time: value 'NaN' is not finite" in w for w in warnings)
    assert r.first_alarm_time == reference.first_alarm_time


def test_duplicate_and_decreasing_time(case2_lines, reference, tmp_path):
    path = tmp_path / "exchange.csv"
    inserts = {row(30.01): [case2_lines[row(30.0)]],                          # 30.00 again
               row(31.0): [b"29.5,0.1,0,0,0,0,0\n", case2_lines[row(30.99)]]}  # back in time, repeat
    path.write_bytes(damaged(case2_lines, {}, inserts))
    warnings = []
    r = replay(path, on_warning=warnings.append, **FAST)
    assert r.summary.rows.duplicate_time == 2 and r.summary.rows.decreasing_time == 1
    assert any("is before the previous row's time" in w for w in warnings)
    assert r.summary.rows.rows == 10001
    assert r.evaluations.equals(reference.evaluations)


def test_missing_column(case2_lines, tmp_path, capsys):
    path = tmp_path / "exchange.csv"
    path.write_bytes(b"".join(case2_lines))
    code, _, err = cli([str(path), "--signal", "theta9", "--model", "harmonic"], capsys)
    assert code == 2
    assert "header has no column 'theta9'; columns are time, x2, y2, x3, y3, x4, y4" in err
    path.write_bytes(b"t,x2\n0.0,1.0\n")
    code, _, err = cli([str(path), "--model", "harmonic"], capsys)
    assert code == 2 and "no column 'time'" in err
    path.write_bytes(b"time,x2,x2\n0.0,1.0,1.0\n")
    code, _, err = cli([str(path), "--model", "harmonic"], capsys)
    assert code == 2 and "more than once" in err


def test_not_utf8_header(tmp_path, capsys):
    path = tmp_path / "exchange.csv"
    path.write_bytes(b"time,x\xff2\n0.0,1.0\n")
    code, _, err = cli([str(path), "--model", "harmonic"], capsys)
    assert code == 2 and "header) is not UTF-8" in err


def test_data_ending_before_the_training_window(case2_lines, tmp_path, capsys):
    path = tmp_path / "exchange.csv"
    path.write_bytes(b"".join(case2_lines[:row(5.0) + 1]))
    code, _, err = cli([str(path), "--model", "harmonic"], capsys)
    assert code == 2 and "the data ends at t = 5 s, before the end of the training window 9 s" in err


def test_constant_signal(tmp_path, capsys):
    path = tmp_path / "exchange.csv"
    path.write_text("time,x2\n" + "".join(f"{k * 0.01!r},0.25\n" for k in range(2001)))
    code, _, err = cli([str(path), "--model", "harmonic"], capsys)
    assert code == 2 and "the signal is constant (0.25)" in err


def test_bad_options(case2, capsys):
    """Each message names the option once, the value and what is expected; exit 2."""
    for argv, text in ((["--threshold", "-1"], "argument --threshold: expected a positive number in the signal's "
                                               "units or 'auto', got '-1'"),
                       (["--threshold", "abc"], "expected a positive number in the signal's units or 'auto'"),
                       (["--window", "0"], "argument --window: expected a positive number of seconds, got '0'"),
                       (["--every", "x"], "argument --every: expected a positive number of seconds, got 'x'"),
                       (["--persistence", "0"], "expected an integer ≥ 1"),
                       (["--model", "arima"], "invalid choice: 'arima'"),
                       (["--train", "9", "0"], "train: expected START END with END > START")):
        code, _, err = cli([str(case2), *argv], capsys)
        assert code == 2, argv
        assert text in err, (argv, err)
        last = err.strip().splitlines()[-1]
        assert last.count(argv[0]) <= 1, last          # the option's name once, not twice


# -- the file is truncated or replaced while following ----------------------------------------------
def test_truncated_while_following(case1, case2, case2_lines, reference, tmp_path):
    """As when fourbar-run starts again in the same directory (O_TRUNC, same inode)."""
    path = copy_run(case1, tmp_path)
    text1 = path.read_bytes()
    path.write_bytes(text1[:len(text1) // 2])                # Case 1 up to ~50 s ...
    run_json(tmp_path, "running", fault_time=None)
    inode = path.stat().st_ino

    def truncate_and_rewrite():                              # ... then Case 2 from the start, beyond 50 s
        with open(path, "r+b") as fh:
            fh.truncate(0)
            fh.write(b"".join(case2_lines[:row(70.0)]))

    def rest():
        with open(path, "ab") as fh:
            fh.write(b"".join(case2_lines[row(70.0):]))
        run_json(tmp_path, "finished")

    warnings = []
    r = follow(path, poll=0.01, timeout=30, sleep=Script(truncate_and_rewrite, rest),
               on_warning=warnings.append, out_dir=tmp_path / "m", plots=False, **FAST)
    assert path.stat().st_ino == inode
    assert any("replaced or truncated; starting again" in w for w in warnings)
    assert r.summary.restarts == 1
    assert r.evaluations.equals(reference.evaluations)
    assert r.first_alarm_time == pytest.approx(10.01)
    logged = (tmp_path / "m" / "evaluations.csv").read_text().splitlines()
    assert len(logged) == len(reference.evaluations) + 1     # the log restarted with the new file


def test_replaced_while_following(case1, case2, reference, tmp_path):
    """A new file renamed over the old one (new inode), as an atomic writer does."""
    path = copy_run(case1, tmp_path)
    run_json(tmp_path, "running", fault_time=None)

    def replace():
        tmp = tmp_path / "exchange.csv.new"
        tmp.write_bytes(case2.read_bytes())
        os.replace(tmp, path)
        run_json(tmp_path, "finished")

    warnings = []
    r = follow(path, poll=0.01, timeout=30, sleep=Script(replace), on_warning=warnings.append, **FAST)
    assert r.summary.restarts == 1 and any("replaced or truncated" in w for w in warnings)
    assert r.evaluations.equals(reference.evaluations)


def test_reader_restarts_after_deletion(case2, tmp_path):
    path = copy_run(case2, tmp_path, run_json=False)
    with ExchangeReader(path, ["x2"]) as reader:
        assert len(reader.read_to_end()) == 10001
        path.unlink()
        gone = reader.poll()
        assert gone.missing and gone.restarted
        copy_run(case2, tmp_path, run_json=False)
        again = reader.read_to_end()
        assert len(again) == 10001 and reader.stats.restarts == 1


# -- run.json -------------------------------------------------------------------------------------------
def test_run_json_missing(case2, reference, tmp_path):
    path = copy_run(case2, tmp_path, run_json=False)
    r = replay(path, **FAST)
    assert r.run_info is None
    assert r.first_alarm_time == reference.first_alarm_time
    assert r.fault_time is None and r.detection_latency is None and r.false_alarms is None
    assert r.exit_code == 1
    # following without run.json: no one says the run ended, so it stops after --timeout
    warnings = []
    r = follow(path, poll=0.01, timeout=0.3, on_warning=warnings.append, **FAST)
    assert r.status == "timeout" and any("no new rows for 0.3 s" in w for w in warnings)
    assert r.evaluations.equals(reference.evaluations)


def test_run_json_failed(case2_lines, tmp_path, capsys):
    path = tmp_path / "exchange.csv"
    path.write_bytes(b"".join(case2_lines[:row(15.0) + 1]))
    run_json(tmp_path, "running")

    def fail():
        run_json(tmp_path, "failed", error="doStep failed at t = 15.01 s: cannot assemble")

    warnings = []
    script = Script(fail)
    r = follow(path, poll=0.01, timeout=30, sleep=script, on_warning=warnings.append, **FAST)
    assert script.calls == 1                              # stopped at once, no timeout wait
    assert r.status == "run_failed" and r.exit_code == 1
    assert any("the run failed: doStep failed at t = 15.01 s" in w for w in warnings)
    assert r.first_alarm_time == pytest.approx(10.01)       # the rows written are still monitored
    code, out, err = cli([str(path), "--model", "harmonic", "--no-plots"], capsys)
    assert code == 1 and "the run failed: doStep failed" in out + err


def test_run_json_failed_before_training(case2_lines, tmp_path, capsys):
    path = tmp_path / "exchange.csv"
    path.write_bytes(b"".join(case2_lines[:row(4.0) + 1]))
    run_json(tmp_path, "failed", error="FMU crashed")
    code, out, err = cli([str(path), "--model", "harmonic", "--follow", "--no-plots"], capsys)
    assert code == 1
    assert "the run failed: FMU crashed" in err and "before the training window was complete" in err


def test_run_json_unreadable(case2, tmp_path, capsys):
    """A run.json that is not a run record is refused (issue 36: it used to be read as "fault
    time unknown", and an alarm at the fault was then called a false alarm)."""
    path = copy_run(case2, tmp_path)
    (tmp_path / "run.json").write_text("{not json")
    with pytest.raises(RunJsonError, match="run.json: not valid JSON"):
        replay(path, **FAST)
    code, out, err = cli([str(path), "--model", "harmonic", "--no-plots", "--out", str(tmp_path / "m")], capsys)
    assert code == 2 and "run.json: not valid JSON" in err and not (tmp_path / "m").exists()


# -- memory stays bounded ---------------------------------------------------------------------------------
@pytest.mark.parametrize("detector, evaluations, first", [("cusum", 11910, 9.1), ("mae", 11906, 9.5)])
def test_memory_is_bounded_when_following_a_long_run(detector, evaluations, first):
    """1200 s of a periodic signal in 1 s blocks: buffers stay bounded, no alarm."""
    period = 3.0573
    mon = Monitor(MonitorOptions(model="harmonic", detector=detector, history_points=2000, evaluation_points=1000))
    sizes = []
    for block in range(1200):
        t = np.round(block + np.arange(1, 101) * 0.01, 10)
        x = 0.5 * np.cos(2 * np.pi * t / period) + 0.1 * np.cos(6 * np.pi * t / period)
        mon.feed(t, x)
        sizes.append(mon.buffered_samples)
    assert mon.n_evaluations == evaluations
    assert max(sizes[100:]) <= max(sizes[100:200]) and max(sizes) < 5000
    assert len(mon.history) <= 2000 and len(mon.evaluations) <= 1000
    ev = mon.evaluation_frame()
    assert ev["time"].iloc[0] == pytest.approx(first) and ev["time"].iloc[-1] > 1190   # spans the whole run
    assert mon.detector.alarms == 0

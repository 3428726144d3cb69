"""Failures mid-run keep what was written: an FMU that cannot apply a fault and a disk that
fills up each leave a readable exchange file (complete lines only), a `failed` run.json with
the reason (the FMU's own message), exit code 1 and a freed FMU instance.  An FMU that
cannot initialise with the case's start values fails before anything is written (exit 2)."""
from __future__ import annotations

import errno
import json
import subprocess
import sys

import pandas as pd
import pytest

from orchestrator import run_case
from orchestrator.cli import main
from orchestrator.exchange import ExchangeWriter
from support import case_file, recorded_columns
from support import REPO



@pytest.fixture
def instance_calls(monkeypatch):
    """Counts FMU2Slave.instantiate / freeInstance calls (the real ones still run)."""
    from fmpy.fmi2 import FMU2Slave

    calls = {"instantiate": 0, "freeInstance": 0}
    for name in calls:
        original = getattr(FMU2Slave, name)

        def wrapper(self, *args, _original=original, _name=name, **kwargs):
            calls[_name] += 1
            return _original(self, *args, **kwargs)

        monkeypatch.setattr(FMU2Slave, name, wrapper)
    return calls


L2_TO_10 = """
[[events]]          # impossible: the loop cannot close with a 10 m crank
type = "step"
time = 1.0
variable = "L2"
value = 10.0
"""


def test_failing_fmu_keeps_rows_and_reports_its_message(fourbar_fmu, tmp_path, capsys, instance_calls):
    path = case_file("case1_normal", fourbar_fmu, tmp_path, extra=L2_TO_10)
    out = tmp_path / "out"
    code = main([str(path), "--out", str(out), "--stop", "3"])
    err = capsys.readouterr().err
    assert code == 1
    assert "Traceback" not in err
    assert "run failed after 101 rows (last t = 1 s)" in err
    # The FMU's reason, captured through the FMI logger, reaches the user and run.json.
    fmu_message = "cannot apply L2 1 -> 10 at t = 1 s: the loop cannot be closed"
    assert fmu_message in err
    record = json.loads((out / "run.json").read_text())
    assert record["status"] == "failed"
    assert record["error"].startswith("fmi2DoStep(t = 1 s, h = 0.01 s) returned discard: ")
    assert fmu_message in record["error"]
    assert record["rows_written"] == 101 and record["last_time"] == 1.0
    assert record["finished_at"] is not None
    # The exchange file is readable: header + every row up to the fault time, complete lines.
    data = (out / "exchange.csv").read_text()
    assert data.endswith("\n")
    frame = pd.read_csv(out / "exchange.csv")
    assert list(frame.columns) == ["time", *recorded_columns(fourbar_fmu)]
    assert len(frame) == 101 and frame["time"].iloc[-1] == 1.0
    assert instance_calls == {"instantiate": 1, "freeInstance": 1}


def test_failed_initialisation_is_reported(fourbar_fmu, tmp_path, capsys, instance_calls):
    """A start value the FMU refuses (an unknown integrator: no model description can say which
    strings are allowed) fails fmi2ExitInitializationMode, which runs before anything is
    written: exit 2, the FMU's message and the value set, and no output folder at all."""
    path = case_file("case1_normal", fourbar_fmu, tmp_path)
    out = tmp_path / "out"
    assert main([str(path), "--out", str(out), "--stop", "1", "--set", "integrator=Euler"]) == 2
    err = capsys.readouterr().err
    assert "fmi2ExitInitializationMode returned fatal" in err
    assert "integrator = 'Euler': must be one of DOP853, RK45" in err
    assert "integrator = 'Euler' (from --set)" in err      # the value the case set away from the FMU's
    assert "nothing was run or written" in err
    assert not out.exists()
    # FMI 2.0 allows no call after fmi2Fatal, not even fmi2FreeInstance (and freeing a
    # pythonfmu slave then corrupts the heap): the instance must be left alone.
    assert instance_calls == {"instantiate": 1, "freeInstance": 0}


def test_disk_full_keeps_complete_lines(fourbar_fmu, tmp_path, monkeypatch, instance_calls):
    """The 4th write (rows 1.01-2.00 s) stores half its bytes, then fails with ENOSPC."""
    original = ExchangeWriter._write
    writes = {"n": 0}

    def failing_write(self, data):
        writes["n"] += 1
        if writes["n"] == 4:
            original(self, data[: len(data) // 2])       # a partial block reaches the disk...
            raise OSError(errno.ENOSPC, "No space left on device")
        return original(self, data)

    monkeypatch.setattr(ExchangeWriter, "_write", failing_write)
    path = case_file("case1_normal", fourbar_fmu, tmp_path)
    result = run_case(path, tmp_path / "out", stop=5.0)
    assert result.status == "failed" and not result.ok
    assert "No space left on device" in result.error and "exchange.csv" in result.error
    data = result.exchange_path.read_bytes()
    assert data.endswith(b"\n")                            # ...and is cut back to the last complete row
    lines = data.decode().splitlines()
    assert len(lines) == 1 + 101 and lines[-1].startswith("1.0,")  # header, row 0, rows 0.01-1.00 s
    record = json.loads(result.run_json_path.read_text())
    assert record["status"] == "failed" and record["rows_written"] == 101
    assert "No space left on device" in record["error"]
    assert instance_calls == {"instantiate": 1, "freeInstance": 1}


def test_unwritable_output_directory_is_a_run_failure(fourbar_fmu, tmp_path, capsys):
    path = case_file("case1_normal", fourbar_fmu, tmp_path)
    blocker = tmp_path / "file"
    blocker.write_text("a file, not a directory\n")
    assert main([str(path), "--out", str(blocker / "out"), "--stop", "0.1"]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err and "run failed" in err and "Not a directory" in err


def test_fmu_logging_after_a_run_is_safe(fourbar_fmu, tmp_path):
    """Regression: FMPy's logger proxy keeps the Python logger in one process-wide C
    variable.  A per-run ctypes logger, freed after the run, left it dangling and the next
    FMU that logged in the process (here simulate_fmu with debug logging) crashed
    (segfault).  Run in a child process so a crash cannot take pytest down."""
    code = f"""
import gc, numpy as np
from fmpy import simulate_fmu
from orchestrator import run_case
path = {str(case_file('case1_normal', fourbar_fmu, tmp_path))!r}
for i in range(2):
    assert run_case(path, {str(tmp_path / 'out')!r}, stop=0.2).ok
    gc.collect()
    junk = [bytearray(64) for _ in range(100000)]        # reuse freed memory
signal = np.array([(0.0, 1.0), (0.1, 1.0), (0.1, 1.1), (0.2, 1.1)], dtype=[("time", float), ("L2", float)])
result = simulate_fmu({str(fourbar_fmu)!r}, stop_time=0.2, output_interval=0.01, input=signal, debug_logging=True)
print("rows", len(result))
"""
    # With the old per-run logger this child crashed in 6 of 6 tries (SIGSEGV/SIGILL).
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=REPO)
    assert done.returncode == 0, (done.returncode, done.stderr[-2000:])
    assert "rows 21" in done.stdout
    # The FMU's message still reaches FMPy's default printer (the orchestrator routes it there).
    assert "applied L2 1 -> 1.1 at t = 0.1 s" in done.stdout


@pytest.mark.parametrize("setting, text, runs", [
    ("L2=0", "parameters.L2 (from --set L2) = 0: expected > 0 (declared min of L2", False),
    ("m2=-1", "parameters.m2 (from --set m2) = -1: expected > 0 (declared min of m2", False),
    ("integrator=Euler", "the FMU refused the case's start values", True),
])
def test_invalid_start_values_are_a_case_error(setting, text, runs, either_fmu, tmp_path):
    """Exit 2 (an input error) with the FMU's own words, no pythonfmu wrapper text, and no claim
    of kept rows.  Lengths and masses are rejected before anything runs: both FMUs declare
    min > 0.  FMI 2.0 cannot declare the allowed values of a String, so the integrator is
    refused by the FMU at fmi2ExitInitializationMode, before the first row."""
    from support import FOURBAR_RUN

    out = tmp_path / "out"
    proc = subprocess.run([FOURBAR_RUN, str(case_file("case1_normal", either_fmu, tmp_path)), "--set", setting,
                           "--out", str(out), "--stop", "1"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert text in proc.stderr
    assert "Fatal py exception" not in proc.stderr and "PyObject_CallMethod" not in proc.stderr
    assert "rows kept" not in proc.stderr
    if runs:
        assert "integrator = 'Euler'" in proc.stderr and "DOP853" in proc.stderr
    assert not out.exists()       # rejected before anything was written (by validation or by the FMU)

"""fourbar-run under what a new user writes or does (issue 23, "inputs and signals").

Each test runs the real command (``.venv/bin/fourbar-run``) on the native FMU (fast) and
checks the exit code, the message and the files left behind:

- a step longer than the span, and a run longer than the row bound: exit 2, nothing written;
- SIGTERM: handled like Ctrl-C (rows kept, run.json ``interrupted``), exit 143;
- start values the FMU refuses: exit 2, the FMU's words and the value set, nothing written,
  a previous run's files untouched; a failure after the start keeps rows (exit 1);
- run.json is as readable as exchange.csv (the umask decides, not mkstemp's 0600);
- a re-run removes the previous run's monitor/ and diagnosis/ (and only those).
"""
from __future__ import annotations

import json
import os
import re
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from orchestrator import ConfigError, load_case
from orchestrator.case import DEFAULT_MAX_ROWS
from support import FOURBAR_MONITOR, FOURBAR_RUN, REPO, case_file


def run(*args, timeout=120, umask=None, **kwargs) -> subprocess.CompletedProcess:
    preexec = (lambda: os.umask(umask)) if umask is not None else None
    return subprocess.run([FOURBAR_RUN, *map(str, args)], capture_output=True, text=True, timeout=timeout,
                          cwd=REPO, preexec_fn=preexec, **kwargs)


def no_traceback(proc) -> None:
    assert "Traceback" not in proc.stderr, proc.stderr


def folder_bytes(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (relative path -> content)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


# ---------------------------------------------------------------------- impossible or absurd sizes

def test_a_step_longer_than_the_span_is_refused(native_fmu, tmp_path):
    """step = 1e9 s over 12 s: 12/1e9 = 1.2e-8 rounds to 0 whole steps within the grid
    tolerance, which the whole-number check alone accepted (one row, exit 0)."""
    path = case_file("case1_normal", native_fmu, tmp_path, step=1e9, stop=12.0)
    out = tmp_path / "out"
    proc = run(path, "--out", out)
    assert proc.returncode == 2, proc.stderr
    assert "experiment.step = 1000000000.0: (stop - start)/step = 1.2e-08 is less than one step" in proc.stderr
    assert "the span is 12.0 s" in proc.stderr
    assert "nothing was run or written" in proc.stderr
    no_traceback(proc)
    assert not out.exists()


def test_a_run_over_the_row_bound_is_refused_before_anything_is_written(native_fmu, tmp_path):
    path = case_file("case1_normal", native_fmu, tmp_path, stop=1e15)
    out = tmp_path / "out"
    started = time.monotonic()
    proc = run(path, "--out", out)
    assert proc.returncode == 2, proc.stderr
    # The size, the bound and both ways to allow it (0.01 s step: 1e17 steps + the row at t = 0).
    assert "would write 100,000,000,000,000,001 rows" in proc.stderr
    assert f"more than exchange.max_rows = {DEFAULT_MAX_ROWS:,}" in proc.stderr
    assert "[exchange] max_rows = 100000000000000001" in proc.stderr and "--max-rows" in proc.stderr
    no_traceback(proc)
    assert not out.exists()
    # Refused by validation, not after writing: 30 s is far above a validation (< 2 s) and
    # far below what writing rows until a bound would take.
    assert time.monotonic() - started < 30


def test_the_row_bound_is_exact_and_can_be_raised(native_fmu, tmp_path):
    """The default allows exactly DEFAULT_MAX_ROWS rows; --max-rows and [exchange] max_rows
    move the bound (checked on real runs of 101 rows)."""
    path = case_file("case1_normal", native_fmu, tmp_path)
    step = 0.01
    at_bound = (DEFAULT_MAX_ROWS - 1) * step        # rows = n + 1 = DEFAULT_MAX_ROWS
    assert load_case(path, stop=at_bound).experiment.n_steps + 1 == DEFAULT_MAX_ROWS
    with pytest.raises(ConfigError, match=f"would write {DEFAULT_MAX_ROWS + 1:,} rows"):
        load_case(path, stop=at_bound + step)
    assert load_case(path, stop=at_bound + step, max_rows=DEFAULT_MAX_ROWS + 1).exchange.max_rows \
        == DEFAULT_MAX_ROWS + 1

    out = tmp_path / "out"
    proc = run(path, "--out", out, "--stop", 1, "--max-rows", 100)        # 101 rows > 100
    assert proc.returncode == 2 and "exchange.max_rows (from --max-rows) = 100" in proc.stderr, proc.stderr
    assert not out.exists()
    bounded = case_file("case1_normal", native_fmu, tmp_path / "bounded.toml", extra="max_rows = 101\n")
    proc = run(bounded, "--out", out, "--stop", 1, "-q")                      # [exchange] is the last table
    assert proc.returncode == 0, proc.stderr
    assert (out / "exchange.csv").read_text().count("\n") == 1 + 101
    proc = run(path, "--out", out, "--stop", 1, "--max-rows", "1e3")         # not an integer: usage error
    assert proc.returncode == 2 and "--max-rows: invalid int value" in proc.stderr
    no_traceback(proc)


def test_an_fmu_without_a_binary_for_this_platform_is_a_case_error(native_fmu, tmp_path):
    """The native FMU without binaries/ (its sources kept): FMPy cannot load it; that used to be
    a Python traceback from inside FMPy."""
    import zipfile

    stripped = tmp_path / "NoBinary.fmu"
    with zipfile.ZipFile(native_fmu) as zin, zipfile.ZipFile(stripped, "w") as zout:
        for item in zin.infolist():
            if not item.filename.startswith("binaries/"):
                zout.writestr(item, zin.read(item.filename))
    out = tmp_path / "out"
    proc = run(case_file("case1_normal", native_fmu, tmp_path), "--fmu", stripped, "--out", out, "--stop", 1)
    assert proc.returncode == 2, proc.stderr
    assert "has no binary for this platform" in proc.stderr and "it has: sources" in proc.stderr
    assert "fmpy compile" in proc.stderr
    no_traceback(proc)
    assert not out.exists()


# ---------------------------------------------------------------------- signals

def _wait_for_rows(csv: Path, rows: int, proc, timeout=30.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and proc.poll() is None:
        if csv.exists() and csv.read_bytes().count(b"\n") >= 1 + rows:
            return
        time.sleep(0.02)
    raise AssertionError(f"{csv}: fewer than {rows} rows after {timeout} s")


def test_sigterm_keeps_rows_and_says_so(native_fmu, tmp_path):
    """SIGTERM mid-run (real time x4, so the run lasts 25 s): rows kept, run.json
    `interrupted` with the reason, a message, exit 143 = 128 + SIGTERM."""
    path = case_file("case1_normal", native_fmu, tmp_path)
    out = tmp_path / "out"
    proc = subprocess.Popen([FOURBAR_RUN, str(path), "--out", str(out), "--realtime", "4"], cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for_rows(out / "exchange.csv", 101, proc)      # the blocks up to t = 1 s are out
        proc.send_signal(signal.SIGTERM)
        stdout, stderr = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + signal.SIGTERM, stderr
    assert "terminated by SIGTERM after" in stderr and "kept in" in stderr and "Traceback" not in stderr
    record = json.loads((out / "run.json").read_text())
    assert record["status"] == "interrupted"
    assert record["error"].startswith("terminated by SIGTERM at t = ")
    assert record["finished_at"] is not None
    data = (out / "exchange.csv").read_bytes()
    assert data.endswith(b"\n")
    rows = data.count(b"\n") - 1
    assert record["rows_written"] == rows and 101 <= rows < 10_001
    assert record["last_time"] == pytest.approx((rows - 1) * 0.01, abs=1e-9)   # grid times: k*0.01
    # The message writes the last time as a user reads it (at most the step's 2 decimals),
    # not its repr (k*0.01 is often 1.8900000000000001 and the like).
    shown = re.search(r"\(last t = (\S+) s\)", stderr)
    assert shown is not None, stderr
    assert float(shown.group(1)) == pytest.approx(record["last_time"], abs=1e-12)   # 1e-12: round-off only
    assert len(shown.group(1).partition(".")[2]) <= 2, stderr


def test_sigterm_while_the_fmu_loads_writes_nothing(native_fmu, tmp_path):
    """A SIGTERM that arrives while the FMU is initialised (sent by the process to itself from
    fmi2ExitInitializationMode, so it lands there every time): exit 143, nothing written."""
    path = case_file("case1_normal", native_fmu, tmp_path)
    out = tmp_path / "out"
    code = f"""
import os, signal, sys
from orchestrator import instance
from orchestrator.cli import main
original = instance.FmuInstance.exit_initialization_mode
def exit_and_signal(self):
    original(self)
    os.kill(os.getpid(), signal.SIGTERM)
instance.FmuInstance.exit_initialization_mode = exit_and_signal
sys.exit(main([{str(path)!r}, "--out", {str(out)!r}, "--stop", "1"]))
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=REPO)
    assert proc.returncode == 128 + signal.SIGTERM, proc.stderr
    assert "terminated by SIGTERM before the run started; nothing was written" in proc.stderr
    no_traceback(proc)
    assert not out.exists()


# ---------------------------------------------------------------------- start values the FMU refuses

@pytest.mark.parametrize("fmu_kind", ["native", pytest.param("pythonfmu", marks=pytest.mark.slow)])
def test_refused_start_values_write_nothing_and_name_the_value(fmu_kind, native_fmu, fourbar_fmu, tmp_path):
    """L2 = 1e308 passes the model description (min > 0) but not the FMU: the pythonfmu FMU's
    arithmetic overflows (its message names no parameter), the native one cannot assemble.
    Exit 2 means nothing was written: the previous run's files stay byte for byte."""
    fmu = native_fmu if fmu_kind == "native" else fourbar_fmu
    path = case_file("case1_normal", fmu, tmp_path)
    out = tmp_path / "out"
    assert run(path, "--out", out, "--stop", "0.2", "-q").returncode == 0
    (out / "monitor").mkdir()
    (out / "monitor" / "summary.json").write_text("{}\n")
    before = folder_bytes(out)

    proc = run(path, "--out", out, "--stop", "0.2", "--set", "L2=1e308")
    assert proc.returncode == 2, proc.stderr
    assert "the FMU refused the case's start values: fmi2ExitInitializationMode returned" in proc.stderr
    # The values the case set away from the FMU's own start values: the one override.
    assert "the case sets these away from the FMU's own start values: L2 = 1e+308 (from --set)" in proc.stderr
    # The native FMU's iteration runs away; the pythonfmu FMU's float arithmetic breaks down
    # first or after it, depending on the numpy/scipy versions (a domain error in 2.4/1.17).
    assert ("the loop cannot be closed" in proc.stderr
            or (fmu_kind == "pythonfmu" and "the arithmetic overflowed" in proc.stderr)), proc.stderr
    assert "nothing was run or written" in proc.stderr
    no_traceback(proc)
    assert folder_bytes(out) == before


def test_a_failure_after_the_start_keeps_rows_and_says_so(native_fmu, tmp_path):
    """An L2 step the loop cannot close, at t = 1.89 s: grid point 189 = 189*0.01, which is
    1.8900000000000001 in binary; the messages write it as 1.89 (they printed its repr)."""
    extra = '\n[[events]]\ntype = "step"\ntime = 1.89\nvariable = "L2"\nvalue = 10.0\n'
    path = case_file("case1_normal", native_fmu, tmp_path, extra=extra)
    out = tmp_path / "out"
    proc = run(path, "--out", out, "--stop", 3)
    assert proc.returncode == 1, proc.stderr
    assert "run failed after 190 rows (last t = 1.89 s)" in proc.stderr and "rows kept in" in proc.stderr
    assert "fmi2DoStep(t = 1.89 s, h = 0.01 s) returned error" in proc.stderr
    assert "1.8900000000000001" not in proc.stderr
    no_traceback(proc)
    record = json.loads((out / "run.json").read_text())
    assert record["status"] == "failed" and record["rows_written"] == 190
    assert record["error"].startswith("fmi2DoStep(t = 1.89 s,")
    assert record["last_time"] == 189 * 0.01         # the file keeps the exact grid time
    assert (out / "exchange.csv").read_text().count("\n") == 1 + 190


# ---------------------------------------------------------------------- files a run writes

@pytest.mark.parametrize("umask, mode", [(0o022, 0o644), (0o027, 0o640)])
def test_run_json_is_as_readable_as_the_exchange_file(umask, mode, native_fmu, tmp_path):
    """run.json went through mkstemp (0600: unreadable by others whatever the umask)."""
    out = tmp_path / "out"
    proc = run(case_file("case1_normal", native_fmu, tmp_path), "--out", out, "--stop", "0.1", "-q", umask=umask)
    assert proc.returncode == 0, proc.stderr
    for name in ("run.json", "exchange.csv"):
        assert stat.S_IMODE((out / name).stat().st_mode) == mode, name


def test_atomic_replacement_applies_the_umask(tmp_path):
    """Every file written through fourbar_common (summary.json, results, diagnosis.json) gets
    the mode an ordinary open() would give, on creation and on replacement."""
    from fourbar_common import replace_atomically, write_json_atomic

    previous = os.umask(0o027)
    try:
        write_json_atomic(tmp_path / "a.json", {"x": 1})
        write_json_atomic(tmp_path / "a.json", {"x": 2})
        replace_atomically(tmp_path / "b.csv", lambda tmp: tmp.write_text("t\n"))
        with open(tmp_path / "ordinary", "w") as handle:
            handle.write("x")
    finally:
        os.umask(previous)
    ordinary = stat.S_IMODE((tmp_path / "ordinary").stat().st_mode)
    assert ordinary == 0o640
    for name in ("a.json", "b.csv"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == ordinary, name
    assert json.loads((tmp_path / "a.json").read_text()) == {"x": 2}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json", "b.csv", "ordinary"]   # no temporary left


# ---------------------------------------------------------------------- re-runs

@pytest.mark.slow
def test_a_rerun_removes_the_previous_runs_derived_outputs(native_fmu, tmp_path):
    """The monitor's real outputs and a diagnosis folder describe the old rows: the new run
    removes them once it has started, and says so."""
    path = case_file("case1_normal", native_fmu, tmp_path)
    out = tmp_path / "out"
    assert run(path, "--out", out, "--stop", 20, "-q").returncode == 0
    monitored = subprocess.run([FOURBAR_MONITOR, str(out / "exchange.csv"), "--model", "harmonic", "--no-plots",
                                "-q"], capture_output=True, text=True, timeout=120, cwd=REPO)
    assert monitored.returncode == 0, monitored.stderr
    assert (out / "monitor" / "summary.json").is_file()
    (out / "diagnosis").mkdir()
    (out / "diagnosis" / "diagnosis.json").write_text("{}\n")
    (out / "notes").mkdir()                               # not a derived output: kept
    (out / "notes" / "mine.txt").write_text("keep\n")

    proc = run(path, "--out", out, "--stop", 1)
    assert proc.returncode == 0, proc.stderr
    assert f"removed the previous run's monitor/ and diagnosis/ from {out}" in proc.stdout
    assert not (out / "monitor").exists() and not (out / "diagnosis").exists()
    assert (out / "notes" / "mine.txt").read_text() == "keep\n"
    assert json.loads((out / "run.json").read_text())["rows_written"] == 101


def test_a_folder_that_is_not_a_previous_run_loses_nothing(native_fmu, tmp_path):
    """--out on a folder without run.json (e.g. a source tree with a monitor/ package), or a
    monitor/ without the monitor's summary.json: nothing but exchange.csv and run.json is
    touched."""
    path = case_file("case1_normal", native_fmu, tmp_path)
    tree = tmp_path / "tree"
    (tree / "monitor").mkdir(parents=True)
    (tree / "monitor" / "summary.json").write_text("{}\n")        # a marker, but no run.json beside it
    proc = run(path, "--out", tree, "--stop", "0.1")
    assert proc.returncode == 0 and "removed" not in proc.stdout, proc.stdout
    assert (tree / "monitor" / "summary.json").is_file()
    (tree / "monitor" / "summary.json").unlink()                  # now a run folder, monitor/ without marker
    (tree / "monitor" / "__init__.py").write_text("")
    proc = run(path, "--out", tree, "--stop", "0.1")
    assert proc.returncode == 0 and "removed" not in proc.stdout, proc.stdout
    assert (tree / "monitor" / "__init__.py").is_file()

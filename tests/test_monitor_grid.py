"""The monitor checks the exchange file's time grid (issue 36): gaps, jumps, off-grid and
duplicated rows give a warning naming the span and the documented exit 5 ("indeterminate")
when no alarm was raised; a gap is skipped, not evaluated point by point.  Non-regular files,
nested and empty JSON records are refused (exit 2) by the monitor, the diagnosis and the
view's readers; output write errors name the file and leave nothing partial (exit 4).

The runs are real: Case 1 and Case 2 of the native FMU by ``fourbar-run``, then damaged.
Commands run as processes with a generous hang guard (``GUARD`` s; the measured times are
in docs/monitor.md, from benchmarks-free commands given there), never a timing assertion.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from support import FOURBAR_MONITOR, FOURBAR_RUN, case_file

#: Hang guard of one command (s): the acceptance target is 10 s; the machine may be loaded.
GUARD = 120
BIN = Path(sys.executable).parent
FOURBAR_DIAGNOSE = str(BIN / "fourbar-diagnose")
HARMONIC = ["--model", "harmonic", "--no-plots"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory, native_fmu) -> dict[str, Path]:
    """Case 1 and Case 2 of the native FMU: {name: run folder}."""
    base = tmp_path_factory.mktemp("grid_runs")
    out = {}
    procs = {}
    for name, case in (("case1", "case1_normal"), ("case2", "case2_fault_L2")):
        toml = case_file(case, native_fmu, base / f"{name}.toml")
        procs[name] = subprocess.Popen([FOURBAR_RUN, str(toml), "--out", str(base / name), "--quiet"],
                                       stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        out[name] = base / name
    for name, proc in procs.items():
        stdout, stderr = proc.communicate(timeout=300)
        assert proc.returncode == 0, f"{name}: {stdout}\n{stderr}"
    return out


def lines_of(folder: Path) -> list[bytes]:
    return (folder / "exchange.csv").read_bytes().splitlines(keepends=True)


def time_of(line: bytes) -> float:
    return float(line.split(b",", 1)[0])


def copy_with(run: Path, dest: Path, lines: list[bytes], *, run_json: bool = True) -> Path:
    dest.mkdir(parents=True, exist_ok=True)
    (dest / "exchange.csv").write_bytes(b"".join(lines))
    if run_json:
        shutil.copy(run / "run.json", dest / "run.json")
    return dest / "exchange.csv"


def with_time(line: bytes, t: float) -> bytes:
    return repr(t).encode() + b"," + line.split(b",", 1)[1]


class Lines:
    """A process's stdout read line by line in a thread, so a test can wait for a line (with
    the hang guard) before acting."""

    def __init__(self, proc: subprocess.Popen):
        import queue
        import threading

        self.lines: list[str] = []
        self._queue: "queue.Queue[str | None]" = queue.Queue()
        self._thread = threading.Thread(target=self._pump, args=(proc,), daemon=True)
        self._thread.start()

    def _pump(self, proc: subprocess.Popen) -> None:
        for line in proc.stdout:
            self._queue.put(line)
        self._queue.put(None)

    def wait_for(self, text: str, timeout: float = GUARD) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            try:
                line = self._queue.get(timeout=max(0.0, deadline - time.monotonic()))
            except Exception:
                break
            if line is None:
                break
            self.lines.append(line)
            if text in line:
                return
        raise AssertionError(f"no line with {text!r}: {''.join(self.lines)}")

    def rest(self) -> str:
        self._thread.join(timeout=GUARD)
        while not self._queue.empty():
            line = self._queue.get()
            if line is not None:
                self.lines.append(line)
        return "".join(self.lines)


def monitor(*args: str) -> subprocess.CompletedProcess:
    proc = subprocess.run([FOURBAR_MONITOR, *args], capture_output=True, text=True, timeout=GUARD)
    assert "Traceback" not in proc.stdout + proc.stderr, proc.stderr
    return proc


# -- the grid ---------------------------------------------------------------------------------------
def test_gap_in_the_training_window_is_indeterminate(runs, tmp_path):
    """Rows 1.37-6.88 s removed from Case 2 (fault at 10 s): main said "0, fault NOT detected"."""
    lines = lines_of(runs["case2"])
    kept = [lines[0]] + [ln for ln in lines[1:] if not 1.37 - 1e-9 <= time_of(ln) <= 6.88 + 1e-9]
    assert len(lines) - len(kept) == 552
    path = copy_with(runs["case2"], tmp_path / "gap", kept)
    proc = monitor(str(path), *HARMONIC)
    assert proc.returncode == 5, proc.stdout + proc.stderr
    assert "time jumps from t = 1.36 s to t = 6.89 s: 552 row(s) of the 0.01 s grid (run.json) are missing" \
        in proc.stderr
    assert "inside the training window 0–9 s: no model fitted" in proc.stderr
    assert "verdict: INDETERMINATE" in proc.stdout
    summary = json.loads((tmp_path / "gap" / "monitor" / "summary.json").read_text())
    assert summary["grid"]["missing_rows"] == 552 and summary["indeterminate"]


def test_gap_after_training_is_skipped_and_the_fault_still_found(runs, tmp_path):
    """A gap 30-60 s in Case 2: the alarm at the fault (10 s) stands (exit 1), the gap is warned
    about and skipped: no evaluation inside it."""
    lines = lines_of(runs["case2"])
    kept = [lines[0]] + [ln for ln in lines[1:] if not 30.0 < time_of(ln) < 60.0]
    path = copy_with(runs["case2"], tmp_path / "gap", kept)
    proc = monitor(str(path), *HARMONIC, "--out", str(tmp_path / "m"))
    assert proc.returncode == 1
    assert "time jumps from t = 30 s to t = 60 s: 2999 row(s)" in proc.stderr
    assert "ALARM at t = 10.0" in proc.stdout and "but the time grid is broken" in proc.stdout
    ev = np.loadtxt(tmp_path / "m" / "evaluations.csv", delimiter=",", skiprows=1, usecols=0)
    assert not ((ev > 30.0 + 1e-9) & (ev < 60.0 - 1e-9)).any()   # nothing evaluated inside the gap
    summary = json.loads((tmp_path / "m" / "summary.json").read_text())
    assert summary["grid"]["skipped_gaps"] == 1


@pytest.mark.parametrize("with_run_json", [True, False])
def test_a_1e6_s_time_jump(runs, tmp_path, with_run_json):
    """Case 1 (healthy) with every row after 50 s moved 1e6 s later: main evaluated the empty
    span every 0.1 s for minutes.  With run.json the moved rows are past its stop (off the
    grid); without, the jump is a gap of 1e8 rows that is skipped.  Never exit 0."""
    lines = lines_of(runs["case1"])
    moved = [lines[0]] + [ln if time_of(ln) <= 50.0 else with_time(ln, time_of(ln) + 1e6) for ln in lines[1:]]
    path = copy_with(runs["case1"], tmp_path / "jump", moved, run_json=with_run_json)
    proc = monitor(str(path), *HARMONIC, "--out", str(tmp_path / "m"))
    summary = json.loads((tmp_path / "m" / "summary.json").read_text())
    if with_run_json:
        assert proc.returncode == 5, proc.stdout + proc.stderr
        assert "5000 row(s) from t = 1000050.01 s to t = 1000100 s are off the 0.01 s grid (run.json)" in proc.stderr
        assert summary["grid"]["off_grid_rows"] == 5000
    else:
        assert proc.returncode in (1, 5), proc.stdout + proc.stderr     # the phase after a jump is arbitrary
        assert "time jumps from t = 50 s to t = 1000050.01 s: 100000000 row(s)" in proc.stderr
        assert summary["grid"]["skipped_gaps"] == 1
        assert summary["evaluations"] < 2000          # 100 s of data at 0.1 s, not 1e7 evaluations


def test_1e9_s_steps(runs, tmp_path):
    """After 50 s, 200,000 rows 1e-9 s apart (main allocated memory for the time span): now
    they are off the grid, and the rows run.json records after 50 s are missing."""
    lines = lines_of(runs["case1"])
    head = [ln for ln in lines[1:] if time_of(ln) <= 50.0]
    tiny = [with_time(lines[1 + 5001 + (i % 1000)], 50.0 + (i + 1) * 1e-9) for i in range(200_000)]
    path = copy_with(runs["case1"], tmp_path / "tiny", [lines[0], *head, *tiny])
    proc = monitor(str(path), *HARMONIC, "--out", str(tmp_path / "m"))
    assert proc.returncode == 5, proc.stdout + proc.stderr
    assert "off the 0.01 s grid (run.json); skipped" in proc.stderr
    summary = json.loads((tmp_path / "m" / "summary.json").read_text())
    assert summary["grid"]["off_grid_rows"] == 200_000
    assert "run.json records rows up to t = 100 s" in proc.stderr    # the rows after 50 s are missing


def test_duplicated_rows(runs, tmp_path):
    lines = lines_of(runs["case1"])
    i = 1 + 3000                                  # the row at 30.00 s
    path = copy_with(runs["case1"], tmp_path / "dup", lines[:i + 1] + [lines[i], lines[i]] + lines[i + 1:])
    proc = monitor(str(path), *HARMONIC)
    assert proc.returncode == 5, proc.stdout + proc.stderr
    assert "is equal to the previous row's time 30.0" in proc.stderr
    assert "2 duplicated row(s)" in proc.stdout


def test_whole_grid_exits_0(runs, tmp_path):
    """The untouched Case 1 file: no grid warning, exit 0 (the check does not cry wolf)."""
    proc = monitor(str(runs["case1"] / "exchange.csv"), *HARMONIC, "--out", str(tmp_path / "m"))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "grid" not in proc.stderr and "verdict: no alarm" in proc.stdout


def test_without_run_json_the_dominant_step_is_the_grid(runs, tmp_path):
    lines = lines_of(runs["case1"])
    kept = [lines[0]] + [ln for ln in lines[1:] if not 40.0 < time_of(ln) < 40.5]
    path = copy_with(runs["case1"], tmp_path / "own", kept, run_json=False)
    proc = monitor(str(path), *HARMONIC)
    assert proc.returncode == 5, proc.stdout + proc.stderr
    assert "49 row(s) of the 0.01 s grid (the file's dominant step; no run.json) are missing" in proc.stderr


def test_follow_checks_the_grid_too(runs, tmp_path):
    """--follow of a finished run's copy is refused (ended run); follow a growing one instead:
    the gap file appended in blocks while the monitor follows."""
    lines = lines_of(runs["case2"])
    kept = [ln for ln in lines[1:] if not 1.37 - 1e-9 <= time_of(ln) <= 6.88 + 1e-9]
    folder = tmp_path / "live"
    folder.mkdir()
    record = json.loads((runs["case2"] / "run.json").read_text())
    record.update(status="running", run_id="live-run", writer={"pid": os.getpid(), "host": os.uname().nodename,
                                                               "heartbeat_s": 1.0})
    (folder / "run.json").write_text(json.dumps(record))
    (folder / "exchange.csv").write_bytes(lines[0] + b"".join(kept[:300]))
    proc = subprocess.Popen([FOURBAR_MONITOR, str(folder), "--follow", "--poll", "0.05", "--timeout", "60",
                             *HARMONIC], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out = Lines(proc)
        out.wait_for("following run live-run")
        with open(folder / "exchange.csv", "ab") as f:
            f.write(b"".join(kept[300:]))
        record["status"] = "finished"
        (folder / "run.json.tmp").write_text(json.dumps(record))
        os.replace(folder / "run.json.tmp", folder / "run.json")
        err = proc.stderr.read()
        proc.wait(timeout=GUARD)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 5, out.rest() + err
    assert "552 row(s) of the 0.01 s grid (run.json) are missing" in err


# -- files that are not files -------------------------------------------------------------------------
def test_fifo_exchange_is_refused(runs, tmp_path):
    folder = tmp_path / "fifo"
    folder.mkdir()
    os.mkfifo(folder / "exchange.csv")
    shutil.copy(runs["case2"] / "run.json", folder / "run.json")
    for args in ([str(folder / "exchange.csv")], [str(folder)], [str(folder), "--follow", "--timeout", "5"]):
        proc = monitor(*args, *HARMONIC)
        assert proc.returncode == 2, proc.stdout + proc.stderr
        assert "exchange.csv: is a FIFO (named pipe), not a regular file" in proc.stderr
    (folder / "monitor").mkdir()
    (folder / "monitor" / "summary.json").write_text(json.dumps({"first_alarm_time": 10.0, "signals": ["x2"]}))
    proc = subprocess.run([FOURBAR_DIAGNOSE, str(folder)], capture_output=True, text=True, timeout=GUARD)
    assert proc.returncode == 2 and "is a FIFO" in proc.stderr, proc.stdout + proc.stderr


@pytest.mark.parametrize("name", ["run.json", "monitor/summary.json"])
def test_fifo_json_is_refused(runs, tmp_path, name):
    folder = tmp_path / "run"
    shutil.copytree(runs["case2"], folder)
    subprocess.run([FOURBAR_MONITOR, str(folder), *HARMONIC], capture_output=True, timeout=GUARD)
    (folder / name).unlink()
    os.mkfifo(folder / name)
    if name == "run.json":
        proc = monitor(str(folder), *HARMONIC, "--out", str(tmp_path / "m"))
        assert proc.returncode == 2 and "run.json: is a FIFO (named pipe), not a regular file" in proc.stderr
    proc = subprocess.run([FOURBAR_DIAGNOSE, str(folder)], capture_output=True, text=True, timeout=GUARD)
    assert proc.returncode == 2 and str(folder / name) in proc.stderr, proc.stderr
    assert "is a FIFO (named pipe), not a regular file" in proc.stderr


def test_directory_as_exchange_is_refused(runs, tmp_path):
    folder = tmp_path / "dir"
    (folder / "exchange.csv").mkdir(parents=True)
    proc = monitor(str(folder / "exchange.csv"), *HARMONIC)
    assert proc.returncode == 2, proc.stdout + proc.stderr


def test_follow_a_folder_that_does_not_exist_yet(native_fmu, tmp_path):
    """--follow DIR started before DIR exists waits for the folder, then its exchange.csv."""
    folder = tmp_path / "later"
    proc = subprocess.Popen([FOURBAR_MONITOR, str(folder), "--follow", "--poll", "0.1", "--timeout", "60",
                             *HARMONIC], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        out = Lines(proc)
        out.wait_for(f"waiting for {folder / 'exchange.csv'} to appear")
        time.sleep(0.5)
        assert proc.poll() is None            # still waiting, not dead on "Is a directory"
        toml = case_file("case1_normal", native_fmu, tmp_path / "case1.toml")
        run = subprocess.run([FOURBAR_RUN, str(toml), "--out", str(folder), "--quiet"], capture_output=True,
                             text=True, timeout=300)
        assert run.returncode == 0, run.stderr
        err = proc.stderr.read()
        proc.wait(timeout=GUARD)
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
    assert proc.returncode == 0, out.rest() + err
    assert (folder / "monitor" / "summary.json").is_file()


def test_follow_a_folder_that_never_comes(tmp_path):
    proc = monitor(str(tmp_path / "never"), "--follow", "--poll", "0.1", "--timeout", "1", *HARMONIC)
    assert proc.returncode == 2
    assert "exchange.csv: the exchange file did not appear within 1 s" in proc.stderr


# -- JSON records -------------------------------------------------------------------------------------------
NESTED = "[" * 100_000 + "]" * 100_000


@pytest.mark.parametrize("text, expected", [
    (NESTED, "JSON nested too deeply"),
    ('{"schema": 2, "status": "finished", "x": ' + NESTED + "}", "JSON nested too deeply"),
    ("{}", "not a run record: fields schema, status, run_id, case, experiment, rows_written are missing"),
    ("", "is empty (0 bytes): not a run record"),
])
def test_bad_run_json_is_refused(runs, tmp_path, text, expected):
    folder = tmp_path / "run"
    shutil.copytree(runs["case2"], folder)
    subprocess.run([FOURBAR_MONITOR, str(folder), *HARMONIC], capture_output=True, timeout=GUARD)
    (folder / "run.json").write_text(text)
    proc = monitor(str(folder), *HARMONIC, "--out", str(tmp_path / "m"))
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert expected in proc.stderr and "fault time unknown" not in proc.stdout + proc.stderr
    assert not (tmp_path / "m").exists()                                  # nothing written
    proc = subprocess.run([FOURBAR_DIAGNOSE, str(folder)], capture_output=True, text=True, timeout=GUARD)
    assert proc.returncode == 2 and expected in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    from view.sources import RunFolder

    update = RunFolder(folder).poll()
    assert expected in update.record_problem


def test_nested_summary_json_in_diagnose(runs, tmp_path):
    folder = tmp_path / "run"
    shutil.copytree(runs["case2"], folder)
    (folder / "monitor").mkdir()
    (folder / "monitor" / "summary.json").write_text(NESTED)
    proc = subprocess.run([FOURBAR_DIAGNOSE, str(folder)], capture_output=True, text=True, timeout=GUARD)
    assert proc.returncode == 2 and "summary.json: not a readable monitor summary (JSON nested too deeply" \
        in proc.stderr, proc.stderr


# -- writing the outputs ---------------------------------------------------------------------------------
def test_disk_full_names_the_file_and_leaves_nothing(runs, tmp_path):
    """The outputs on a 64 kB tmpfs (ENOSPC, a real full disk; root only): forecast.csv of Case 2
    is ~0.5 MB, so the write fails; the error names the file, nothing partial is left, exit 4."""
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("mounting a small tmpfs needs root")
    small = tmp_path / "small"
    small.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(small)], capture_output=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.decode().strip()}")
    try:
        proc = monitor(str(runs["case2"] / "exchange.csv"), "--model", "harmonic", "--out", str(small / "m"))
        assert proc.returncode == 4, proc.stdout + proc.stderr
        assert "No space left on device" in proc.stderr and f"{small / 'm'}/" in proc.stderr
        assert "verdict: ALARM at t = 10.0" in proc.stdout          # the verdict is still given
        assert sorted(p.name for p in (small / "m").iterdir()) == []   # no partial output, no temporary
    finally:
        subprocess.run(["umount", str(small)], check=False)


def test_read_only_output_folder(runs, tmp_path):
    from support import unwritable_folder

    folder = unwritable_folder(tmp_path)
    proc = monitor(str(runs["case2"] / "exchange.csv"), *HARMONIC, "--out", str(folder / "m"))
    # refused before reading (exit 2) when the folder's mode says so; for root, who ignores
    # modes, a read-only file system refuses the first write: exit 4, the file named, nothing left
    assert proc.returncode in (2, 4) and str(folder / "m") in proc.stderr, proc.stdout + proc.stderr
    assert not (folder / "m").exists()


@pytest.mark.parametrize("detector", ["cusum", "mae"])
def test_a_skipped_gap_costs_no_evaluations(runs, tmp_path, detector):
    """Both detectors move their clocks past a skipped gap: Case 2 with its rows after 50 s
    moved 1e6 s later (no run.json, so the jump is a gap of 1e8 rows, not off the grid) gives
    about 100 s of evaluations every 0.1 s, none inside the gap."""
    from monitor import replay

    lines = lines_of(runs["case2"])
    moved = [lines[0]] + [ln if time_of(ln) <= 50.0 else with_time(ln, time_of(ln) + 1e6) for ln in lines[1:]]
    path = copy_with(runs["case2"], tmp_path / "jump", moved, run_json=False)
    warnings: list[str] = []
    r = replay(path, model="harmonic", detector=detector, on_warning=warnings.append)
    t = r.evaluations["time"].to_numpy()
    assert 800 <= len(t) <= 1000                   # (100 - 9) s / 0.1 s = 910 evaluations, give or take the gap's edges
    assert not ((t > 50.0 + 1e-9) & (t < 1e6 + 50.0)).any()
    assert r.summary.grid.skipped_gaps == 1 and r.first_alarm_time == pytest.approx(10.0, abs=0.6)
    assert any("100000000 row(s)" in w for w in warnings)


def test_a_fifo_among_the_outputs_is_refused_before_reading(runs, tmp_path):
    """Opening a FIFO for writing blocks until someone reads it: refused (exit 2), nothing read."""
    out = tmp_path / "m"
    out.mkdir()
    os.mkfifo(out / "events.jsonl")
    proc = monitor(str(runs["case2"] / "exchange.csv"), *HARMONIC, "--out", str(out))
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "events.jsonl: is a FIFO (named pipe), not a regular file" in proc.stderr

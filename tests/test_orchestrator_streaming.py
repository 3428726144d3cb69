"""The exchange file while it grows: a reader polling it during a run (another process, as
the monitor would) only ever finds complete rows behind the last newline and a run.json
that parses; real-time mode releases each block when its time has come on the wall
clock (1 s simulated at factor 1 takes 1.0-1.3 s); Ctrl-C keeps the rows, says
`interrupted` and exits 130."""
from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from orchestrator import ExchangeSettings, load_case, run_case
from support import case_file, recorded_columns
from support import REPO

FOURBAR_RUN = [sys.executable, "-m", "orchestrator.cli"]


def complete_part(data: bytes) -> bytes:
    """What a reader may use: everything up to and including the last newline."""
    return data[: data.rfind(b"\n") + 1]


def check_rows(complete: bytes, columns: list[str], step: float = 0.01) -> int:
    """Every complete line after the header ``time,<columns>`` is a whole row on the grid;
    returns the row count."""
    lines = complete.decode().splitlines()
    if not lines:
        return 0
    assert lines[0] == ",".join(["time", *columns])
    for k, line in enumerate(lines[1:]):
        fields = line.split(",")
        assert len(fields) == 1 + len(columns), f"partial row {k}: {line!r}"
        values = [float(v) for v in fields]          # every field parses
        assert values[0] == 0.0 + k * step           # no row missing, none out of order
    return len(lines) - 1


def test_concurrent_reader_never_sees_a_partial_row(fourbar_fmu, tmp_path):
    # Many small appends (every 0.05 s of simulated time) at 8x real time: ~1.5 s of run.
    path = case_file("case2_fault_L2", fourbar_fmu, tmp_path, flush_interval=0.05)
    out = tmp_path / "out"
    exchange, run_json = out / "exchange.csv", out / "run.json"
    proc = subprocess.Popen([*FOURBAR_RUN, str(path), "--out", str(out), "--stop", "12", "--realtime", "8"],
                            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    snapshots, sizes, partial_tails, statuses = [], set(), 0, []
    last_rows_json = 0
    try:
        while True:
            running = proc.poll() is None
            if run_json.exists():
                record = json.loads(run_json.read_text())     # must always parse (atomic replace)
                statuses.append(record["status"])
                assert record["rows_written"] >= last_rows_json
                last_rows_json = record["rows_written"]
            if exchange.exists():
                data = exchange.read_bytes()
                complete = complete_part(data)
                partial_tails += data != complete
                rows = check_rows(complete, recorded_columns(fourbar_fmu))
                # run.json is written after the rows it counts (read before the exchange file here).
                assert rows >= last_rows_json
                snapshots.append(complete)
                sizes.add(len(data))
            if not running:
                break
            time.sleep(0.002)
        stdout, stderr = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, stderr
    final = exchange.read_bytes()
    assert check_rows(final, recorded_columns(fourbar_fmu)) == 1201 and final.endswith(b"\n")
    assert all(final.startswith(s) for s in snapshots)     # nothing seen was later rewritten
    assert len(sizes) >= 10, "the reader should have watched the file grow"
    assert statuses[0] == "running" and statuses[-1] == "finished"
    assert set(statuses) <= {"running", "finished"}
    print(f"polls {len(snapshots)}, distinct sizes {len(sizes)}, polls with an unfinished last line {partial_tails}")


def _watch_rows(path: Path, stop: threading.Event, seen: list) -> None:
    """Record (monotonic time, last complete time value) whenever the file grows."""
    last = None
    while not stop.is_set():
        try:
            data = complete_part(path.read_bytes())
        except FileNotFoundError:
            data = b""
        if data != last and data.count(b"\n") > 1:
            last = data
            tail = data[: -1].rsplit(b"\n", 1)[-1]
            seen.append((time.monotonic(), float(tail.split(b",")[0])))
        time.sleep(0.001)


@pytest.fixture(scope="module")
def pacing_fmu(request):
    """The native FMU when it can be built, else the pythonfmu one.

    Pacing is the orchestrator's job, and this test watches it from a thread of the same
    process.  The pythonfmu FMU runs Python inside every doStep and holds the GIL meanwhile,
    so the watching thread and the pacing sleeps compete with it (a 4 s run at 4x once took
    1.34 s in a clean-clone suite); FMPy's ctypes calls into the native FMU release the GIL.
    """
    from fmu_src.native_build import find_compiler
    name = "native_fmu" if find_compiler() is not None else "fourbar_fmu"
    return request.getfixturevalue(name)


@pytest.mark.parametrize("factor, stop", [(1.0, 1.0), (4.0, 4.0)])
def test_realtime_pacing(factor, stop, pacing_fmu, tmp_path):
    """1 s of wall time for `stop` simulated seconds at `factor`; no block released early."""
    case = load_case(case_file("case1_normal", pacing_fmu, tmp_path))
    case = dataclasses.replace(case, exchange=ExchangeSettings(flush_interval=0.1, realtime_factor=factor))
    out = tmp_path / "out"
    out.mkdir()
    seen: list = []
    stop_event = threading.Event()
    watcher = threading.Thread(target=_watch_rows, args=(out / "exchange.csv", stop_event, seen))
    watcher.start()
    try:
        result = run_case(case, out, stop=stop)
    finally:
        stop_event.set()
        watcher.join()
    assert result.ok and result.rows_written == round(stop / 0.01) + 1
    # Acceptance: 1.0-1.3 s of wall time, from the first row (t = 0) to the last (t = stop).
    assert 1.0 <= result.sim_wall_time_s <= 1.3, result.sim_wall_time_s
    # The same seen from outside by a reader polling every 1 ms (first row at t = 0 s).
    (w0, t0), (w1, t1) = seen[0], seen[-1]
    assert t0 == 0.0 and t1 == stop
    # EARLY: the reader's clock at the first row (w0) can itself be late: it polls every 1 ms and
    # shares the GIL with the FMU's Python code (5.1 ms was seen once in a full-suite run).  An
    # unpaced run would show the last block ~1 s early, so 20 ms still catches it.
    EARLY = 0.02
    assert 1.0 - EARLY <= w1 - w0 <= 1.3, w1 - w0
    lateness = []
    for wall, t in seen:
        # A block is never visible before its simulated time is due (EARLY: the reader's
        # own lag at the first row, above).
        assert t / factor <= (wall - w0) + EARLY
        lateness.append((wall - w0) - t / factor)
    # Nor is it held much longer than one block (0.1 s / factor).  Single blocks can be late on
    # a busy machine: the whole process was once stalled for 0.66 s in a CI run (the block at
    # t = 0.3 s appeared at 0.96 s, and the run still finished on time), so the bound is on the
    # typical block, not the worst.  A run that buffers its rows shows most blocks late by up
    # to stop/factor = 1 s (median ~0.5 s), so a median of 0.1/factor + 0.1 s and three blocks
    # in four within 0.1/factor + 0.3 s still catch it.
    lateness.sort()
    assert lateness[len(lateness) // 2] <= 0.1 / factor + 0.1, lateness
    assert lateness[(3 * len(lateness)) // 4] <= 0.1 / factor + 0.3, lateness
    print(f"factor {factor}: loop {result.sim_wall_time_s:.4f} s, seen by reader {w1 - w0:.4f} s "
          f"(whole run_case {result.wall_time_s:.3f} s including FMU loading)")


def test_ctrl_c_keeps_rows_and_exits_130(fourbar_fmu, tmp_path):
    path = case_file("case2_fault_L2", fourbar_fmu, tmp_path)
    out = tmp_path / "out"
    proc = subprocess.Popen([*FOURBAR_RUN, str(path), "--out", str(out), "--realtime", "2"], cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:           # wait until some blocks are out (t >= 1 s)
            path_csv = out / "exchange.csv"
            if path_csv.exists() and path_csv.read_bytes().count(b"\n") >= 1 + 101:
                break
            time.sleep(0.02)
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, stderr
    assert "interrupted after" in stderr and "Traceback" not in stderr
    data = (out / "exchange.csv").read_bytes()
    assert data.endswith(b"\n")
    rows = check_rows(data, recorded_columns(fourbar_fmu))
    record = json.loads((out / "run.json").read_text())
    assert record["status"] == "interrupted"
    assert record["error"].startswith("interrupted by Ctrl-C at t = ")
    assert record["rows_written"] == rows and 101 <= rows < 10_001
    assert record["last_time"] == 0.0 + (rows - 1) * 0.01
    assert record["finished_at"] is not None


@pytest.mark.skipif(not hasattr(os, "getpgid"), reason="POSIX only")
def test_interrupt_via_api_raises_keyboardinterrupt(fourbar_fmu, tmp_path):
    """run_case records `interrupted` and raises RunInterrupted (a KeyboardInterrupt) with the result."""
    out = tmp_path / "api"
    code = f"""
import os, pathlib, signal, sys, threading, time
from orchestrator import run_case, RunInterrupted

def interrupt_once_rows_appear():
    csv = pathlib.Path({str(out / 'exchange.csv')!r})
    while not (csv.exists() and csv.read_bytes().count(b"\\n") > 2):
        time.sleep(0.01)
    os.kill(os.getpid(), signal.SIGINT)

threading.Thread(target=interrupt_once_rows_appear, daemon=True).start()
try:
    run_case({str(case_file('case1_normal', fourbar_fmu, tmp_path))!r}, {str(out)!r}, realtime=5.0)
except RunInterrupted as exc:
    assert isinstance(exc, KeyboardInterrupt)
    print(exc.result.status, exc.result.rows_written)
    sys.exit(0)
sys.exit(3)
"""
    result = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    status, rows = result.stdout.split()
    assert status == "interrupted" and 0 < int(rows) < 10_001

"""The monitor on real runs of fourbar-run: where it writes, which run it follows, a dead writer.

Each test starts ``fourbar-run`` in its own process (the Case 1/2 files with the FMU under
test) and watches it with ``fourbar-monitor`` or :func:`monitor.follow`, as a user would.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import threading
import time
from pathlib import Path

import pytest

from monitor import follow, replay
from monitor.cli import main
from support import FOURBAR_MONITOR, FOURBAR_RUN, REPO, case_file

pytestmark = pytest.mark.slow


def run(case: Path, out: Path, *args: str) -> dict:
    proc = subprocess.run([FOURBAR_RUN, str(case), "--out", str(out), "--quiet", *args],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    return json.loads((out / "run.json").read_text())


def files_under(path: Path) -> set[str]:
    return {str(p.relative_to(path)) for p in path.rglob("*")}


# -- item 7: where the outputs go, and nothing written for a rejected input ----------------------------
def test_rejected_input_writes_nothing(tmp_path, capsys):
    text = tmp_path / "README.md"
    shutil.copy(REPO / "README.md", text)
    before = files_under(tmp_path)
    assert main([str(text), "--model", "harmonic"]) == 2
    assert "fourbar-monitor: error:" in capsys.readouterr().err
    assert files_under(tmp_path) == before          # no events.jsonl, no evaluations.csv, no folder


def test_default_output_folder_is_never_a_source_folder(fourbar_fmu, tmp_path, capsys):
    out = tmp_path / "run"
    run(case_file("case2_fault_L2", fourbar_fmu, tmp_path), out, "--stop", "12")
    # fourbar-run's own folder: <run>/monitor, as the architecture shows
    assert main([str(out / "exchange.csv"), "--model", "harmonic", "--no-plots", "-q"]) == 1
    assert (out / "monitor" / "summary.json").exists()
    # any other file name: <stem>.monitor beside it (a dotted name no Python package can have)
    other = tmp_path / "monitor"                     # a folder named like this project's package ...
    other.mkdir()
    (other / "__init__.py").write_text("")
    shutil.copy(out / "exchange.csv", tmp_path / "case2_copy.csv")
    assert main([str(tmp_path / "case2_copy.csv"), "--model", "harmonic", "--no-plots", "-q"]) == 1
    assert (tmp_path / "case2_copy.monitor" / "summary.json").exists()
    assert files_under(other) == {"__init__.py"}    # ... is left alone
    # a default folder holding files the monitor did not write is refused, and left as it was
    foreign = tmp_path / "case2_copy.monitor" / "notes.txt"
    foreign.write_text("mine")
    capsys.readouterr()
    assert main([str(tmp_path / "case2_copy.csv"), "--model", "harmonic", "-q"]) == 2
    err = capsys.readouterr().err
    assert "holds files the monitor did not write (notes.txt)" in err and "--out" in err


# -- item 8: a follower tells runs apart ---------------------------------------------------------------
def test_follow_on_a_finished_run_follows_the_next_one(fourbar_fmu, tmp_path):
    """Started on a folder whose run has ended, the follower waits for the next run (whatever
    the timing of the restart) and says which run it follows."""
    out = tmp_path / "run"
    old = run(case_file("case2_fault_L2", fourbar_fmu, tmp_path), out, "--stop", "12")
    messages: list[str] = []
    waiting = threading.Event()
    result = {}

    def on_wait(message: str) -> None:
        messages.append(message)
        if "waiting for the next run" in message:
            waiting.set()

    def target() -> None:
        result["r"] = follow(out / "exchange.csv", model="harmonic", poll=0.05, timeout=120, on_wait=on_wait)

    thread = threading.Thread(target=target)
    thread.start()
    assert waiting.wait(120), messages
    assert old["run_id"] in messages[0] and "finished" in messages[0]
    new = run(case_file("case1_normal", fourbar_fmu, tmp_path), out, "--stop", "12")
    thread.join(120)
    assert not thread.is_alive()
    r = result["r"]
    assert new["run_id"] != old["run_id"]
    assert r.summary.run.run_id == new["run_id"] and r.summary.case == "case1_normal"
    assert any(m.startswith(f"following run {new['run_id']}") for m in messages), messages
    assert r.status == "finished" and r.summary.samples == 1201 and r.summary.fault_time is None
    assert r.summary.alarms == 0                     # Case 1: none of the old run's faulty rows was read


def test_follow_on_a_finished_run_without_a_new_one_says_so(fourbar_fmu, tmp_path, capsys):
    out = tmp_path / "run"
    old = run(case_file("case1_normal", fourbar_fmu, tmp_path), out, "--stop", "12")
    before = files_under(out)
    code = main([str(out / "exchange.csv"), "--follow", "--timeout", "1", "--poll", "0.05", "--model", "harmonic"])
    err = capsys.readouterr().err
    assert code == 2
    assert "no new run started within 1 s" in err and old["run_id"] in err and "without --follow" in err
    assert files_under(out) == before


# -- item 9: a dead writer -------------------------------------------------------------------------------
def test_killed_writer_is_noticed_at_once(fourbar_fmu, tmp_path):
    """kill -9 of fourbar-run: run.json still says running; a follower on this host ends within
    seconds (not after --timeout) with exit 3, and a replay says the run was cut off."""
    case = case_file("case1_normal", fourbar_fmu, tmp_path)
    out = tmp_path / "run"
    writer = subprocess.Popen([FOURBAR_RUN, str(case), "--out", str(out), "--quiet", "--realtime", "5"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        record: dict = {}
        while time.monotonic() < deadline:         # until the run is past its training window
            try:
                record = json.loads((out / "run.json").read_text())
            except (FileNotFoundError, ValueError):
                record = {}
            if (record.get("last_time") or 0) >= 12.0:
                break
            time.sleep(0.05)
        assert record.get("status") == "running" and record["writer"]["pid"] == writer.pid
        follower = subprocess.Popen([FOURBAR_MONITOR, str(out / "exchange.csv"), "--follow", "--model", "harmonic",
                                     "--poll", "0.05", "--timeout", "600", "--no-plots", "-q"],
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(3.0)                             # it is following
        assert follower.poll() is None
        os.kill(writer.pid, signal.SIGKILL)
        killed = time.monotonic()
        writer.wait(30)
        stdout, stderr = follower.communicate(timeout=60)
        noticed = time.monotonic() - killed
    finally:
        for proc in (writer,):
            if proc.poll() is None:
                proc.kill()
    assert json.loads((out / "run.json").read_text())["status"] == "running"      # nobody closed it
    assert follower.returncode == 3, (stdout, stderr)
    # the pid check, not the 600 s silence timeout: a hang guard far below 600 s and far above the
    # time a loaded machine needs (14 s measured with a load average of 9 on 2 cores)
    assert noticed < 120.0, noticed
    assert "the run was cut off" in stderr and f"pid {writer.pid}" in stderr
    summary = json.loads((out / "monitor" / "summary.json").read_text())
    assert summary["status"] == "run_lost" and summary["last_time"] >= 12.0
    r = replay(out / "exchange.csv", model="harmonic")
    assert r.status == "run_lost" and r.exit_code == 3
    assert any("the run was cut off" in w for w in r.warnings)

"""Following a live run gives what replaying the finished file gives.

``fourbar-monitor --follow`` (default model: Prophet) is started first, in its own process,
on a directory that does not exist yet; once it says it is waiting, ``fourbar-run`` runs
Case 2 for 20 s of simulated time at 10x real time (2 s of wall time, exchange blocks every
1 s of simulated time = 0.1 s of wall time).  The monitor must see the file appear and grow,
and its first alarm time — indeed every evaluation — must equal those of a replay of the
finished file.
"""
from __future__ import annotations

import datetime as dt
import json
import subprocess
import threading
import time

import pandas as pd
import pytest

from monitor import ALARM_MESSAGE, replay
from support import FOURBAR_MONITOR, FOURBAR_RUN, case_file


def _read_until(stream, text: str, timeout: float) -> list[str]:
    """Lines of ``stream`` up to the one containing ``text`` (in a thread, with a deadline)."""
    lines: list[str] = []
    found = threading.Event()

    def reader():
        for line in stream:
            lines.append(line)
            if text in line:
                found.set()
                return

    threading.Thread(target=reader, daemon=True).start()
    if not found.wait(timeout):
        raise AssertionError(f"no line with {text!r} within {timeout} s; got {lines!r}")
    return lines


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_follow_live_run_matches_replay(tmp_path, fourbar_fmu):
    case = case_file("case2_fault_L2", fourbar_fmu, tmp_path / "case2.toml")
    run_dir = tmp_path / "live"
    exchange = run_dir / "exchange.csv"
    mon_dir = tmp_path / "followed"
    monitor = subprocess.Popen([FOURBAR_MONITOR, str(exchange), "--follow", "--poll", "0.05", "--timeout", "120",
                                "--out", str(mon_dir), "--no-plots"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        head = _read_until(monitor.stdout, "waiting for", timeout=120)
        assert not exchange.exists()
        started = time.time()
        run = subprocess.run([FOURBAR_RUN, str(case), "--out", str(run_dir), "--realtime", "10", "--stop", "20",
                              "--quiet"], capture_output=True, text=True, timeout=300)
        assert run.returncode == 0, run.stderr
        rest, err = monitor.communicate(timeout=120)
    finally:
        if monitor.poll() is None:
            monitor.kill()
            monitor.communicate()
    out = "".join(head) + rest
    assert monitor.returncode == 1, out + err
    assert "Traceback" not in err
    assert ALARM_MESSAGE in out and "t=   10.01 s  ALARM" in out

    run_json = json.loads((run_dir / "run.json").read_text())
    assert run_json["status"] == "finished" and run_json["last_time"] == 20.0
    followed = json.loads((mon_dir / "summary.json").read_text())
    assert followed["status"] == "finished" and followed["last_time"] == 20.0
    assert followed["rows"]["rows"] == 2001 and followed["rows"]["skipped"] == 0
    # it really followed: the rows came in many reads (20 blocks of 1 s of data, 0.1 s apart;
    # a busy machine may merge some)
    assert followed["reads_with_rows"] >= 3
    events = [json.loads(line) for line in (mon_dir / "events.jsonl").read_text().splitlines()]
    trained_wall = dt.datetime.fromisoformat(events[0]["wall"]).timestamp()
    assert events[0]["event"] == "trained" and trained_wall > started

    replayed = replay(exchange)           # the finished file, same defaults
    assert followed["first_alarm_time"] == replayed.first_alarm_time == pytest.approx(10.01)
    assert followed["detection_latency_s"] == replayed.detection_latency
    logged = pd.read_csv(mon_dir / "evaluations.csv")
    pd.testing.assert_frame_equal(logged, replayed.evaluations, check_exact=True)

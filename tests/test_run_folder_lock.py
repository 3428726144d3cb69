"""One writer per run folder, and an exchange.csv that is the file the run wrote (issue 36, item 4).

Real ``fourbar-run`` processes on the native FMU:

- two runs into one folder: the second exits 2 naming the holder (process, host, since
  when) and changes nothing; the first run's exchange.csv is byte-identical to a solo run's;
- a lock left by a run killed with SIGKILL does not block the next run, and the FMU that
  run unpacked is removed by the next one;
- a symbolic link or a FIFO at exchange.csv is refused (exit 2), the link's target untouched;
- exchange.csv replaced during the run (``sed -i``): the run says so (exit 1, run.json ``failed``);
- the disk fills up (a 200 kB tmpfs): run.json ends ``failed`` with the error, not ``running``.
"""
from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import time
from datetime import datetime
from pathlib import Path

import pytest

from support import FOURBAR_RUN, REPO, case_file, wait_for_rows

#: s: hang guard only; no test here depends on the machine's speed.
HANG_GUARD = 120.0


def run(*args, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([FOURBAR_RUN, *map(str, args)], capture_output=True, text=True, timeout=HANG_GUARD,
                          cwd=REPO, **kwargs)


def start(*args, **kwargs) -> subprocess.Popen:
    return subprocess.Popen([FOURBAR_RUN, *map(str, args)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=REPO, **kwargs)




def test_a_second_writer_is_refused_and_the_first_run_is_untouched(native_fmu, tmp_path):
    path = case_file("case1_normal", native_fmu, tmp_path, stop=10.0, flush_interval=0.5)
    solo = run(path, "--out", tmp_path / "solo", "--quiet")
    assert solo.returncode == 0, solo.stderr
    out = tmp_path / "shared"
    # real time: the first run holds the folder for at least 10 s, however fast the machine
    first = start(path, "--out", out, "--quiet", "--realtime", "1")
    record = wait_for_rows(out, first)
    second = run(path, "--out", out, "--quiet")
    assert second.returncode == 2, second.stderr
    holder = re.search(r"another writer holds this folder: fourbar-run \(pid (\d+), on host ([^,]+), "
                       r"since ([^)]+)\)", second.stderr)
    assert holder, second.stderr
    assert int(holder[1]) == first.pid and holder[2] == socket.gethostname()
    # The lock's "since" (whole seconds) and run.json's started_at (ms) both stamp this run's
    # start, taken moments apart in either order: equal to within the 1 s truncation plus
    # start-up (60 s is a hang guard against a stale or foreign stamp, not a speed bound).
    since = datetime.fromisoformat(holder[3])
    started = datetime.fromisoformat(record["started_at"])
    assert abs((since - started).total_seconds()) <= 60.0, (holder[3], record["started_at"])
    assert "nothing was run or written" in second.stderr and "Traceback" not in second.stderr
    _, err = first.communicate(timeout=HANG_GUARD)
    assert first.returncode == 0, err
    assert json.loads((out / "run.json").read_text())["run_id"] == record["run_id"]
    assert (out / "exchange.csv").read_bytes() == (tmp_path / "solo" / "exchange.csv").read_bytes()


def test_a_lock_and_an_unpacked_fmu_left_by_a_killed_run_do_not_stay(native_fmu, tmp_path):
    path = case_file("case1_normal", native_fmu, tmp_path, stop=10.0, flush_interval=0.5)
    out = tmp_path / "out"
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    env = {**os.environ, "TMPDIR": str(scratch)}
    killed = start(path, "--out", out, "--quiet", "--realtime", "1", env=env)
    wait_for_rows(out, killed)
    assert json.loads((out / ".lock").read_text())["pid"] == killed.pid
    killed.send_signal(signal.SIGKILL)
    killed.communicate(timeout=HANG_GUARD)
    left = list(scratch.glob("fourbar-fmu-*"))
    assert len(left) == 1 and left[0].name.startswith(f"fourbar-fmu-{killed.pid}-")
    old = time.time() - 3600           # an hour ago: past orchestrator.unpacked.SETTLE
    os.utime(left[0], (old, old))
    again = run(path, "--out", out, "--quiet", "--stop", "1", env=env)
    assert again.returncode == 0, again.stderr
    assert json.loads((out / "run.json").read_text())["status"] == "finished"
    assert list(scratch.glob("fourbar-fmu-*")) == []


def test_a_symbolic_link_at_exchange_csv_is_refused_and_its_target_untouched(native_fmu, tmp_path):
    path = case_file("case1_normal", native_fmu, tmp_path, stop=1.0)
    out = tmp_path / "out"
    out.mkdir()
    target = tmp_path / "precious.txt"
    target.write_text("keep me\n")
    (out / "exchange.csv").symlink_to(target)
    proc = run(path, "--out", out, "--quiet")
    assert proc.returncode == 2, proc.stderr
    assert f"{out / 'exchange.csv'}: is a symbolic link; refusing to follow it" in proc.stderr
    assert target.read_text() == "keep me\n"
    assert (out / "exchange.csv").is_symlink() and not (out / "run.json").exists()


def test_a_fifo_at_exchange_csv_is_refused_without_hanging(native_fmu, tmp_path):
    path = case_file("case1_normal", native_fmu, tmp_path, stop=1.0)
    out = tmp_path / "out"
    out.mkdir()
    os.mkfifo(out / "exchange.csv")
    proc = run(path, "--out", out, "--quiet")
    assert proc.returncode == 2, proc.stderr
    assert "is not a regular file" in proc.stderr and not (out / "run.json").exists()


def test_exchange_csv_replaced_during_the_run_is_reported(native_fmu, tmp_path):
    """``sed -i`` writes a new file and renames it over exchange.csv: the run wrote on into the
    old inode and reported every row; now it says the file at the path is not its own."""
    path = case_file("case1_normal", native_fmu, tmp_path, stop=10.0, flush_interval=0.5)
    out = tmp_path / "out"
    proc = start(path, "--out", out, "--quiet", "--realtime", "5")
    wait_for_rows(out, proc, rows=2)
    subprocess.run(["sed", "-i", "2d", str(out / "exchange.csv")], check=True, timeout=HANG_GUARD)
    _, err = proc.communicate(timeout=HANG_GUARD)
    assert proc.returncode == 1, err
    record = json.loads((out / "run.json").read_text())
    assert record["status"] == "failed"
    assert f"{out / 'exchange.csv'} was replaced during the run" in record["error"]
    assert "was replaced during the run" in err


@pytest.fixture
def small_disk(tmp_path):
    """A 200 kB tmpfs (root only; skipped elsewhere)."""
    mount = tmp_path / "small"
    mount.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=200k", "tmpfs", str(mount)], capture_output=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.decode().strip()}")
    try:
        yield mount
    finally:
        subprocess.run(["umount", str(mount)], capture_output=True)


def test_a_full_disk_ends_run_json_failed(native_fmu, tmp_path, small_disk):
    """ENOSPC on a real (small) file system: exchange.csv keeps its complete rows and run.json
    says ``failed`` with the error (written into the space reserved when the run started)."""
    path = case_file("case1_normal", native_fmu, tmp_path, flush_interval=0.1)   # 100 s: ~2 MB of rows
    out = small_disk / "out"
    proc = run(path, "--out", out, "--quiet")
    assert proc.returncode == 1, proc.stderr
    assert "No space left on device" in proc.stderr and "Traceback" not in proc.stderr
    record = json.loads((out / "run.json").read_text())
    assert record["status"] == "failed" and "No space left on device" in record["error"]
    assert str(out / "exchange.csv") in record["error"]
    data = (out / "exchange.csv").read_bytes()
    assert data.endswith(b"\n") and data.count(b"\n") == 1 + record["rows_written"] > 1
    assert not (out / ".run.json.reserve").exists()


@pytest.mark.parametrize("delay", [0.0, 0.15, 0.3, 0.6])
def test_run_json_never_counts_a_row_a_kill_cut(native_fmu, tmp_path, delay):
    """kill -9 at some moment of a run with large appends (flush every 10 s of simulated time:
    1,000 rows, about 400 kB per append): whatever the moment, every row run.json counts is a
    complete line with every column (a torn last line may follow; readers ignore it)."""
    path = case_file("case1_normal", native_fmu, tmp_path, flush_interval=10.0)
    out = tmp_path / "out"
    # paced at 20x (5 s of wall time, an append every 0.5 s): unpaced, an idle machine could
    # finish the 100 s run before the first poll saw it running (a test of the machine's speed)
    proc = start(path, "--out", out, "--quiet", "--realtime", "20")
    wait_for_rows(out, proc, rows=1)
    time.sleep(delay)
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=HANG_GUARD)
    record = json.loads((out / "run.json").read_text())
    lines = (out / "exchange.csv").read_bytes().split(b"\n")
    header, complete = lines[0], lines[1:-1]          # lines[-1]: after the last "\n" (b"" or a torn line)
    assert len(complete) >= record["rows_written"] >= 1
    width = header.count(b",")
    assert all(line.count(b",") == width for line in complete[:record["rows_written"]])

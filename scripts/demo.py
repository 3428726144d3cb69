#!/usr/bin/env python3
"""The paper's live scenario: Case 2 simulated and monitored by two separate processes.

``fourbar-run`` drives the FMU and appends to out/<case>/exchange.csv; ``fourbar-monitor
--follow``, started first in its own process, waits for that file, trains on 0-9 s and
watches the rest.  They share nothing but the files.  The verdict comes from the
monitor's summary.json; after an alarm ``fourbar-diagnose`` names the changed parameter.

With the view (default; --no-view skips it) ``fourbar-view`` serves the run folder on
127.0.0.1 from the moment the run starts and prints its URL: the mechanism moving, the
signal with its forecast, the detector and the verdict, live.  At the end the view stays up
until Enter or Ctrl-C when the demo runs in a terminal, and stops otherwise.

Usage: python scripts/demo.py [--speedup 10] [--case cases/case2_fault_L2.toml] [--model prophet] [--no-view]
       (--speedup 1 runs at wall-clock pace, as in the paper)
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import time
from pathlib import Path

from fourbar_common.contract.layout import SUMMARY
from fourbar_common.contract.summary import read_summary

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", default=str(REPO / "cases" / "case2_fault_L2.toml"))
    parser.add_argument("--speedup", type=float, default=10.0,
                        help="simulated seconds per wall-clock second (default %(default)s; 1 = real time)")
    parser.add_argument("--model", default="prophet", choices=["prophet", "harmonic"])
    parser.add_argument("--out", default=None, help="output folder (default out/<case name>)")
    parser.add_argument("--no-view", action="store_true", help="do not serve the live browser view")
    args = parser.parse_args(argv)
    if args.speedup <= 0:
        parser.error("--speedup must be positive")

    case = Path(args.case)
    out = Path(args.out) if args.out else REPO / "out" / case.stem
    if out.exists():
        shutil.rmtree(out)      # a stale exchange file would be followed by the monitor
    out.mkdir(parents=True)
    exchange = out / "exchange.csv"
    monitor_out = out / "monitor"

    print(f"demo: {case.name} at {args.speedup:g}x real time; orchestrator and monitor run as "
          f"separate processes sharing only {exchange.relative_to(REPO) if exchange.is_relative_to(REPO) else exchange}")
    monitor = subprocess.Popen(
        [str(BIN / "fourbar-monitor"), str(exchange), "--follow", "--out", str(monitor_out),
         "--model", args.model, "--timeout", "120"])
    time.sleep(0.5)
    runner = subprocess.Popen(
        [str(BIN / "fourbar-run"), str(case), "--out", str(out), "--realtime", f"{args.speedup:g}"])
    view = None if args.no_view else _start_view(out, runner)
    try:
        code = _finish(runner, monitor, out, monitor_out)
        if view is not None:
            _linger(view, out)
        return code
    except KeyboardInterrupt:
        return 130
    finally:
        for proc in (runner, monitor, view):
            if proc is not None and proc.poll() is None:
                proc.terminate()
                try:
                    proc.wait(timeout=10)
                except subprocess.TimeoutExpired:
                    proc.kill()


def _start_view(out: Path, runner: subprocess.Popen) -> subprocess.Popen | None:
    """fourbar-view on the run folder once fourbar-run has created it; prints the URL."""
    deadline = time.monotonic() + 30
    while not (out / "run.json").exists():
        if runner.poll() is not None or time.monotonic() > deadline:
            return None
        time.sleep(0.05)
    view = subprocess.Popen([str(BIN / "fourbar-view"), str(out), "--quiet"], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    url = view.stdout.readline().strip()
    if not url:
        print("demo: the live view did not start (run `fourbar-view` on the folder to see why)", file=sys.stderr)
        return None
    print(f"demo: live view at {url}  (open it in a browser)", flush=True)
    return view


def _linger(view: subprocess.Popen, out: Path) -> None:
    """Keep the view up for a user at a terminal; stop it otherwise."""
    shown = _shown(out)
    if sys.stdin.isatty():
        print(f"\ndemo: the view stays up for replay; press Enter (or Ctrl-C) to stop it. Later: fourbar-view {shown}")
        try:
            input()
        except EOFError:
            pass
    else:
        print(f"\ndemo: view stopped; replay it any time with: fourbar-view {shown}")


def _finish(runner: subprocess.Popen, monitor: subprocess.Popen, out: Path, monitor_out: Path) -> int:
    run_code = runner.wait()
    monitor_code = monitor.wait(timeout=300)

    summary_path = monitor_out / SUMMARY
    if run_code != 0 or not summary_path.exists():
        print(f"demo: failed (fourbar-run exit {run_code}, fourbar-monitor exit {monitor_code})", file=sys.stderr)
        return 1
    summary = read_summary(summary_path)
    print()
    print("== verdict ==")
    fault = summary.fault_time
    alarm = summary.first_alarm_time
    latency = summary.detection_latency_s
    print(f"fault injected at      : {fault if fault is not None else 'none'} s (from run.json)")
    print(f"first alarm at         : {alarm if alarm is not None else 'none'} s")
    if latency is not None:
        print(f"detection latency      : {latency:.2f} s   (paper: fault at 10 s, detected at 14 s -> 4 s)")
    print(f"false alarms before it : {summary.false_alarms_before_fault}")
    plots = sorted(monitor_out.glob("*.png"))
    print(f"plots                  : {', '.join(_shown(p) for p in plots)}")
    if alarm is None:
        return 1
    print()
    print("== diagnosis (fourbar-diagnose: which parameter changed, to what, and when) ==")
    diagnosed = subprocess.run([str(BIN / "fourbar-diagnose"), str(out)])
    # 0: explained by one parameter; 1: not explained (still a finished diagnosis); 2: bad input.
    return 0 if diagnosed.returncode in (0, 1) else 1


def _shown(path: Path) -> str:
    return str(path.relative_to(REPO)) if path.is_relative_to(REPO) else str(path)


if __name__ == "__main__":
    sys.exit(main())

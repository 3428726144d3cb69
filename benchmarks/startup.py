#!/usr/bin/env python3
"""Start-up time of the commands, as whole processes, against a bare ``python -c pass``.

Side by side in one run, each a new process: ``python -c pass``; ``fourbar-monitor --help``;
a replay of Case 2 (100 s, 10,001 rows) with the harmonic model, with its default outputs
(events, evaluations, forecast, summary and the three PNG figures) and with ``--no-plots``;
the same replay with the Prophet model; and the ``--help`` of the other commands
(``fourbar-run``, ``fourbar-diagnose``, ``fourbar-view``, ``fourbar-sweep``).  The Case 2 run
folder is made once by ``fourbar-run`` (on the native FMU when there is one: it is faster and
the monitor's work is the same).

The commands are run in rounds, each round every command once in turn, after one warm-up round
(the page cache, Prophet's Stan binary, the modules' bytecode caches: the commands run without
``PYTHONDONTWRITEBYTECODE``, as an installed command does, so a module is compiled once, not at
every start).  Reported per command: the median wall time and CPU
time (user + system, the process's own accounting), and the medians over the rounds of the
command's wall and CPU time minus bare Python's in the same round (so a machine's drift between
rounds cancels), against issue 38's targets: ``--help`` at most 0.5 s above bare Python, the
harmonic replay at most 2 s above it.  The load average before and after is printed: the machine
is shared, and other processes lengthen wall times (not CPU times).

Prints markdown (the section of docs/benchmarks.md: ``python benchmarks/run_all.py --only
startup --write docs/benchmarks.md``).  Exit status 0, 1 when a command failed (its exit
status was not the one expected), 2 usage error; a missed target is reported, not an error.

Usage: python benchmarks/startup.py [--repeat 7] [--fmu build/FourBarNative.fmu]
       python benchmarks/startup.py --quick       # the smoke test's setting: one round, no warm-up
"""
from __future__ import annotations

import argparse
import datetime as dt
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from run_all import machine

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
CASE2 = REPO / "cases" / "case2_fault_L2.toml"

#: Issue 38's targets, seconds above bare Python's start-up.
HELP_TARGET_S = 0.5
HARMONIC_TARGET_S = 2.0


@dataclass(frozen=True)
class Command:
    """One row: its label, the process to start, the exit status it must end with, its target
    (seconds above bare Python; None: none)."""

    label: str
    argv: tuple[str, ...]
    exit_status: int
    target: float | None = None


@dataclass(frozen=True)
class Timing:
    """One process's wall and CPU seconds."""

    wall: float
    cpu: float


def case2_run(folder: Path, fmu: Path | None) -> Path:
    """Case 2's exchange.csv, run once by fourbar-run into ``folder``."""
    argv = [str(BIN / "fourbar-run"), str(CASE2), "--out", str(folder), "--quiet"]
    if fmu is not None:
        argv += ["--fmu", str(fmu)]
    proc = subprocess.run(argv, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"fourbar-run {CASE2.name} failed (exit {proc.returncode}): {proc.stderr.strip()[-2000:]}")
    return folder / "exchange.csv"


def commands(exchange: Path, scratch: Path) -> list[Command]:
    monitor = str(BIN / "fourbar-monitor")
    replay = (monitor, str(exchange), "--quiet")
    return [
        Command("python -c pass", (sys.executable, "-c", "pass"), 0),
        Command("fourbar-monitor --help", (monitor, "--help"), 0, HELP_TARGET_S),
        Command("harmonic replay of Case 2", (*replay, "--model", "harmonic", "--out", str(scratch / "harmonic")),
                1, HARMONIC_TARGET_S),
        Command("harmonic replay of Case 2, `--no-plots`",
                (*replay, "--model", "harmonic", "--no-plots", "--out", str(scratch / "harmonic-no-plots")), 1),
        Command("Prophet replay of Case 2", (*replay, "--model", "prophet", "--out", str(scratch / "prophet")), 1),
        *(Command(f"fourbar-{name} --help", (str(BIN / f"fourbar-{name}"), "--help"), 0)
          for name in ("run", "diagnose", "view", "sweep")),
    ]


#: The commands' environment: Python's default of caching modules' bytecode (__pycache__, which
#: git ignores), whatever this process was started with.
ENV = {name: value for name, value in os.environ.items() if name != "PYTHONDONTWRITEBYTECODE"}


def timed(command: Command) -> Timing:
    """Run ``command`` once as a new process (output discarded); its wall and CPU seconds."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.run(command.argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=ENV)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != command.exit_status:
        raise SystemExit(f"{' '.join(command.argv)}: exit {proc.returncode}, expected {command.exit_status}:\n"
                         f"{proc.stderr.strip()[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return Timing(wall, cpu)


def measure(cmds: list[Command], rounds: int, warmup: bool) -> list[list[Timing]]:
    """Per command, its timings over ``rounds`` rounds (every command once per round, in turn)."""
    if warmup:
        for command in cmds:
            timed(command)
    timings: list[list[Timing]] = [[] for _ in cmds]
    for _ in range(rounds):
        for row, command in zip(timings, cmds):
            row.append(timed(command))
    return timings


def table(cmds: list[Command], timings: list[list[Timing]]) -> list[str]:
    """The markdown table: per command its wall and CPU medians, and both above bare Python's
    (the median over the rounds of the difference within a round) against its target."""
    bare = timings[0]
    lines = ["| process | wall s, median (min-max) | wall s above bare Python | CPU s, median | "
             "CPU s above bare Python | target: s above bare Python | met: wall / CPU |",
             "|---|---:|---:|---:|---:|---:|---|"]
    for command, row in zip(cmds, timings):
        walls = [t.wall for t in row]
        above = statistics.median(t.wall - b.wall for t, b in zip(row, bare))
        cpu_above = statistics.median(t.cpu - b.cpu for t, b in zip(row, bare))
        first = command is cmds[0]
        target = met = ""
        if command.target is not None:
            target = f"<= {command.target:g}"
            met = " / ".join("yes" if x <= command.target else "**no**" for x in (above, cpu_above))
        lines.append(f"| {command.label} | {statistics.median(walls):.2f} ({min(walls):.2f}-{max(walls):.2f}) | "
                     f"{'' if first else f'{above:.2f}'} | {statistics.median(t.cpu for t in row):.2f} | "
                     f"{'' if first else f'{cpu_above:.2f}'} | {target} | {met} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                     epilog="exit status: 0 measured, 1 a command failed, 2 usage error")
    parser.add_argument("--repeat", type=int, default=7, metavar="N", help="rounds counted (default 7)")
    parser.add_argument("--fmu", type=Path, metavar="FMU",
                        help="the FMU that runs Case 2 (default build/FourBarNative.fmu if built, else the case's)")
    parser.add_argument("--quick", action="store_true", help="one round, no warm-up (a smoke test)")
    args = parser.parse_args(argv)
    if args.repeat < 1:
        parser.error(f"--repeat {args.repeat}: must be at least 1")
    fmu = args.fmu
    if fmu is None and (REPO / "build" / "FourBarNative.fmu").is_file():
        fmu = REPO / "build" / "FourBarNative.fmu"
    if fmu is not None and not fmu.is_file():
        parser.error(f"--fmu {fmu}: no such file")
    rounds = 1 if args.quick else args.repeat
    with tempfile.TemporaryDirectory(prefix="startup-") as tmp:
        scratch = Path(tmp)
        exchange = case2_run(scratch / "case2_fault_L2", fmu)
        cmds = commands(exchange, scratch)
        load_before = os.getloadavg()[0]
        timings = measure(cmds, rounds, warmup=not args.quick)
        load_after = os.getloadavg()[0]
    print(f"Measured {dt.date.today().isoformat()} on: {machine()}; "
          f"median of {rounds} round(s){'' if args.quick else ' after a warm-up round'}, every command once per "
          f"round; Case 2 run on {fmu.name if fmu is not None else 'the case file’s FMU'}.")
    print()
    print(*table(cmds, timings), sep="\n")
    print()
    print("Each row is a new process, its output discarded, its modules' bytecode cached (as Python does unless "
          "told not to). The replays write their outputs to a scratch folder "
          "(events, evaluations, forecast, summary; the three PNG figures unless `--no-plots`) and end with exit 1 "
          "(Case 2's alarm). Targets (issue 38): `--help` <= 0.5 s and the harmonic replay <= 2 s above bare Python. "
          "CPU s is the process's own user + system time: on a loaded machine the wall time also holds the time "
          "the process waited for a CPU, its CPU time does not.")
    print()
    print("What a replay loads is what it uses (tests/test_startup_imports.py checks what `--help` and a harmonic "
          "replay import): pandas (the exchange file, the result's frames), scipy.optimize and scipy.interpolate "
          "(the period, the CUSUM's limit, the phase tracker) and, for the three PNG figures, matplotlib; the "
          "difference between the two harmonic rows is matplotlib's import and the drawing of the figures. "
          "The monitor runs BLAS on one thread (threadpoolctl: more threads only wait, busily, for its small "
          "fits) and labels its log axes in plain text (no mathtext parser to build).")
    print()
    print(f"Load average (1 min) before / after: {load_before:.2f} / {load_after:.2f} "
          "(other processes on the machine lengthen the wall times).")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``fourbar-run``: run a case file through its FMU and write the exchange file.

Exit codes: 0 finished, 1 the run failed (FMU error, I/O error, exchange.csv changed under
the run), 2 usage or case-file error, folder held by another writer (nothing written), 130 interrupted (Ctrl-C), 143 terminated (SIGTERM).  Heavy
imports (FMPy, numpy) happen inside the handler, so ``--help`` and ``--version`` answer
at once.
"""
from __future__ import annotations

import argparse
import os
import signal
import sys

from fourbar_common.version import VersionAction

__all__ = ["main"]

_DESCRIPTION = """\
Run a co-simulation case: drive the case's FMU (FMI 2.0 or 3.0; co-simulation, or model
exchange integrated by FMPy's CVode: the case's fmi_type) with FMPy over the
communication grid start + k*step, apply the case's faults (step and ramp events) exactly
on their grid points, and stream the outputs to DIR/exchange.csv (CSV, appended every
flush interval of simulated time) with DIR/run.json (status, parameters, injected faults).
"""

_EPILOG = """\
examples:
  fourbar-run cases/case2_fault_L2.toml
  fourbar-run cases/case2_fault_L2.toml --realtime 1          # wall-clock pace (100 s)
  fourbar-run cases/case1_normal.toml --stop 20 --set L2=1.05 --out out/try
  fourbar-run --fmu build/FourBarNative.fmu cases/case2_fault_L2.toml   # the native FMU

The row at an event's time shows the state before the change (the change acts from the
next step on).  A run writes at most exchange.max_rows rows (default 10,000,000) unless
--max-rows allows more.  The FMU is initialised before anything is written; once the run
starts, the folder's previous monitor/ and diagnosis/ outputs are removed.
FMU inputs are driven by the case's [inputs] table, one signal per input, e.g.
  [inputs]
  tau = { type = "sine", amplitude = 2.0, frequency = 0.5 }   # N*m; also a number (constant),
  # type = "step", "ramp", "table" (rows = [[t, u], ...]) or "csv" (file, time, column)
set at each step's start (with their derivatives when the FMU can interpolate inputs) and
written after the outputs in exchange.csv.
A case may run a system of FMUs instead: system = "../build/X.ssp" (SSP 1.0) in place of
fmu, variables named component.variable (motor.current, fourbar.omega2), and
  [master]
  algorithm = "jacobi"        # or "gauss-seidel" (order from the connections, or order = [...])
                              # or "monolithic": every component through Model Exchange as one
                              # ODE (DOP853), the reference without coupling error
  inputs = "hold"             # or "extrapolate" (input derivatives where a component accepts them)
("Systems" in docs/orchestrator.md).
Case-file keys: docs/orchestrator.md.
One run writes into a folder at a time (a lock, DIR/.lock); a case file's fmu (or the FMUs
in its system) is native code this command loads, so run only case files you would run as programs.
exit status: 0 finished, 1 run failed (or exchange.csv changed under the run), 2 usage or
case-file error, another writer holding DIR, or a link at DIR/exchange.csv (nothing
written), 130 interrupted (Ctrl-C), 143 terminated (SIGTERM), also during a step that does
not end; rows computed before a failure or a signal are kept.
"""


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="fourbar-run", description=_DESCRIPTION, epilog=_EPILOG,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("case", metavar="CASE.toml", help="the case file to run")
    parser.add_argument("--out", metavar="DIR", help="output directory (default: out/<case name>)")
    parser.add_argument("--fmu", metavar="FMU",
                        help="run this FMU instead of the case file's, e.g. build/FourBarNative.fmu (the native "
                             "FMU: no Python in the FMU, faster: docs/benchmarks.md measures how much) or "
                             "build/FourBarNative3.fmu (FMI 3.0); it must have the case's variables")
    parser.add_argument("--stop", metavar="SECONDS", type=float,
                        help="end time in s, replacing experiment.stop (must stay on the grid)")
    parser.add_argument("--realtime", metavar="FACTOR", type=float,
                        help="pace simulated time to the wall clock: 1 = real time, 20 = 20x faster, "
                             "0 = as fast as possible (replaces exchange.realtime_factor)")
    parser.add_argument("--set", metavar="NAME=VALUE", action="append", default=[], dest="overrides",
                        help="start value of an FMU parameter, replacing [parameters]; VALUE is read as "
                             "TOML (1.1, 3, true, \"RK45\"), else as a string; repeatable")
    parser.add_argument("--max-rows", metavar="N", type=int,
                        help="allow the run to write up to N rows (replaces exchange.max_rows; default "
                             "10,000,000): a longer run is refused before anything is written")
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress bar, no summary line")
    parser.add_argument("--version", action=VersionAction)
    return parser


def _parse_overrides(items: list[str]) -> dict:
    """``NAME=VALUE`` strings -> {name: value}; ValueError names the bad item."""
    import tomllib

    overrides = {}
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ValueError(f"--set {item!r}: expected NAME=VALUE, e.g. --set L2=1.1")
        try:
            value = tomllib.loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            value = text
        overrides[name] = value
    return overrides


def main(argv: list[str] | None = None) -> int:
    from fourbar_common.signals import StopSignals
    from fourbar_common.console import closed_stdout_tolerated

    # Ctrl-C and SIGTERM end fourbar-run with one line, at any moment
    # (and a reader that stops early, `| head`, costs nothing but the console)
    with StopSignals(), closed_stdout_tolerated():
        return _main(argv)


def _main(argv: list[str] | None) -> int:
    from fourbar_common.signals import exit_code, signal_of, stop_reason

    try:
        parser = _parser()
        try:
            args = parser.parse_args(argv)
        except SystemExit as exc:   # --help, --version (0) or a usage error (2, message printed)
            return int(exc.code or 0)
        try:
            overrides = _parse_overrides(args.overrides)
        except ValueError as exc:
            print(f"fourbar-run: error: {exc}", file=sys.stderr)
            return 2
        return _run(args.case, out=args.out, stop=args.stop, realtime=args.realtime, overrides=overrides,
                    quiet=args.quiet, fmu=args.fmu, max_rows=args.max_rows)
    except KeyboardInterrupt as exc:     # before or after the run (a run reports its own)
        signum = signal_of(exc)
        print(f"fourbar-run: {stop_reason(signum)}; no run was started, nothing was written", file=sys.stderr)
        return exit_code(signum)


def _run(case: str, *, out, stop, realtime, overrides, quiet: bool, fmu=None, max_rows=None) -> int:
    from fourbar_common.formatting import format_time
    from fourbar_common.signals import exit_code

    from .validation import ConfigError
    from .run import OutputRefused, RunInterrupted, run_case

    try:
        result = run_case(case, out, stop=stop, realtime=realtime, overrides=overrides or None,
                          progress=not quiet and sys.stderr.isatty(), fmu=fmu, max_rows=max_rows)
    except ConfigError as exc:
        print(f"fourbar-run: error: {exc}", file=sys.stderr)
        print("fourbar-run: nothing was run or written", file=sys.stderr)
        return 2
    except OutputRefused as exc:
        print(f"fourbar-run: error: {exc}", file=sys.stderr)
        print("fourbar-run: nothing was run or written", file=sys.stderr)
        return 2
    except RunInterrupted as exc:
        r = exc.result
        if r.started:
            verb = "terminated by SIGTERM" if exc.signum == signal.SIGTERM else "interrupted"
            print(f"fourbar-run: {r.case.name}: {verb} after {r.rows_written} rows (last t = {format_time(r.last_time)} s); "
                  f"kept in {r.exchange_path}; status in {r.run_json_path}", file=sys.stderr)
        else:
            print(f"fourbar-run: {r.case.name}: {r.error}; nothing was written", file=sys.stderr)
        if r.abandoned:
            # A thread is still inside the FMU's C code: run.json and the rows are final, and
            # neither the FMU nor the interpreter can be torn down under that thread.
            print(f"fourbar-run: the FMU did not return from its step; exiting without it", file=sys.stderr)
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(exit_code(exc.signum))
        return exit_code(exc.signum)
    if not result.ok:
        where = (f"after {result.rows_written} rows (last t = {format_time(result.last_time)} s)" if result.rows_written
                 else "before the first row")
        print(f"fourbar-run: error: {result.case.name}: run failed {where}: {result.error}", file=sys.stderr)
        if result.rows_written:
            print(f"fourbar-run: rows kept in {result.exchange_path}; status in {result.run_json_path}",
                  file=sys.stderr)
        elif result.started:
            print(f"fourbar-run: no rows were written; status in {result.run_json_path}", file=sys.stderr)
        else:
            print(f"fourbar-run: the run did not start; nothing was written in {result.out_dir}", file=sys.stderr)
        return 1
    if not quiet:
        exp = result.case.experiment
        if result.replaced:
            print(f"{result.case.name}: removed the previous run's "
                  f"{' and '.join(name + '/' for name in result.replaced)} from {result.out_dir}")
        print(f"{result.case.name}: finished, {result.rows_written} rows, t = {format_time(exp.start)} .. "
              f"{format_time(result.last_time)} s, {len(result.case.events)} event(s), {result.wall_time_s:.2f} s wall "
              f"-> {result.exchange_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

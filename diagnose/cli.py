"""``fourbar-diagnose``: after an alarm, name the parameter that changed, its new value and when.

Exit codes: 0 explained by one parameter, 1 not explained (or no change found), 3 ambiguous (two
parameters explain it about equally well), 2 bad input
(no alarm in the run, a missing or stale summary, an FMU that is not the run's, an --out
that cannot be written, ...; nothing written), 4 the verdict was printed but its files could
not be written, 130 interrupted (Ctrl-C), 143 terminated (SIGTERM).
"""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

from fourbar_common.contract.layout import RunFolder
from fourbar_common.version import VersionAction

__all__ = ["AMBIGUOUS", "OUTPUTS_NOT_WRITTEN", "build_parser", "main"]

#: Exit status when the diagnosis was computed (and printed) but its files could not be written.
OUTPUTS_NOT_WRITTEN = 4
#: Exit status of the verdict ``ambiguous``: two parameters explain the change about equally well.
AMBIGUOUS = 3

_EPILOG = """\
what it does:
  Replays the run's FMU (the native FMU beside it when there is one: it saves its state, so
  each "what if" starts where the healthy run was) and fits every tunable parameter alone as
  the cause: a step whose value (least squares) and grid time (search) explain the monitored
  columns best from --lookback s before the monitor's first alarm to --horizon s after it.
  The best is also fitted as a linear ramp. Hypotheses are ranked by chi-square, scaled by
  each column's noise, estimated from the --noise-span s before that.
  A system run (an .ssp) is replayed with the run's master and macro step; its parameters
  are named component.parameter (motor.R, fourbar.T4, sensor.bias, controller.Kp), every
  tunable Real one of every component a candidate unless --candidates narrows them.

verdicts:
  explained      one parameter explains the change within the noise (exit 0)
  unexplained    the best single parameter leaves residuals well above the noise: two
                 faults at once, or a change the model does not have (exit 1)
  no_change      the data after the alarm follow the healthy model: a false alarm (exit 1)
  ambiguous      two parameters explain it about equally well (chi-square under 9 apart per
                 independent residual): both named, and the outputs that would separate them (exit 3)

outputs (in --out, default RUN_DIR/diagnosis): diagnosis.json, diagnosis.png

examples:
  fourbar-diagnose out/case2_fault_L2
  fourbar-diagnose out/case3_ramp_noise --horizon 5
  fourbar-diagnose RUN_DIR --columns x2,y2,x3,y3,x4,y4    # the four-bar's link centres, not only the monitored ones
  fourbar-diagnose out/motor_fourbar_winding --candidates fourbar.T4,motor.R,sensor,controller.Kp

--out is checked before the diagnosis: a file, a folder that cannot be created or written
is refused at once (exit 2). The verdict is printed before the files are written; if they
cannot be written then, the message says which (exit 4).
Ctrl-C or SIGTERM stops the diagnosis with one line and writes nothing (exit 130 / 143); a
signal during the writing of the files lets them finish first.

A FIFO, device or folder in place of exchange.csv, run.json or summary.json, and JSON that
is empty, nested too deeply or too large, are refused with the file named (exit 2).

exit status: 0 explained, 1 unexplained or no change, 3 ambiguous, 2 bad input or unusable --out (nothing
written), 4 verdict printed but its files not (all) written, 130 interrupted (Ctrl-C),
143 terminated (SIGTERM)
"""


def build_parser() -> argparse.ArgumentParser:
    from .diagnosis import DiagnoseOptions

    defaults = DiagnoseOptions()
    p = argparse.ArgumentParser(prog="fourbar-diagnose", formatter_class=argparse.RawDescriptionHelpFormatter,
                                description="Classify the fault behind a monitor alarm: which parameter changed, "
                                            "to what value, and when.", epilog=_EPILOG)
    p.add_argument("run_dir", metavar="RUN_DIR", help="a run folder: exchange.csv, run.json, monitor/summary.json")
    p.add_argument("--out", metavar="DIR", help="output folder (default RUN_DIR/diagnosis)")
    p.add_argument("--summary", metavar="FILE", help="the monitor's summary.json (default RUN_DIR/monitor/summary.json)")
    p.add_argument("--fmu", metavar="FMU", help="the FMU the run used, if it moved (its GUID must match run.json's)")
    p.add_argument("--use-run-fmu", action="store_true",
                   help="simulate with the run's own FMU even when a faster native FMU is beside it")
    p.add_argument("--columns", metavar="COL[,COL...]", help="columns to fit (default: the monitored ones)")
    p.add_argument("--candidates", metavar="NAME[,NAME...]",
                   help="parameters fitted as the cause (default: every tunable Real parameter; of a system run, "
                        "every component's, named component.parameter); a component's name (motor) stands for all "
                        "of its tunable Real parameters")
    p.add_argument("--lookback", type=float, default=defaults.lookback, metavar="S",
                   help="s before the first alarm where the change may lie (default %(default)s)")
    p.add_argument("--horizon", type=float, default=defaults.horizon, metavar="S",
                   help="s of data after the first alarm used by the fit (default %(default)s)")
    p.add_argument("--max-horizon", type=float, default=defaults.max_horizon, metavar="S",
                   help="a step whose value's standard error is above %s of it is fitted again on twice the "
                        "horizon, and again, up to S s after the first alarm (default %%(default)s; equal to "
                        "--horizon: never)" % f"{100 * defaults.precision:g} %%")
    p.add_argument("--noise-span", type=float, default=defaults.noise_span, metavar="S",
                   help="s of healthy data before the lookback that give the noise level (default %(default)s)")
    p.add_argument("--no-ramp", action="store_true", help="fit steps only")
    p.add_argument("--no-plot", action="store_true", help="write diagnosis.json only")
    p.add_argument("--quiet", action="store_true", help="print the verdict line only")
    p.add_argument("--version", action=VersionAction)
    return p


def main(argv: list[str] | None = None) -> int:
    from fourbar_common.signals import StopSignals, exit_code, signal_of, stop_reason
    from fourbar_common.console import closed_stdout_tolerated

    # Ctrl-C and SIGTERM end the command with one line, at any moment
    # (and a reader that stops early, `| head`, costs nothing but the console)
    with StopSignals(), closed_stdout_tolerated():
        try:
            return _main(argv)
        except KeyboardInterrupt as exc:     # before the diagnosis began (the diagnosis reports its own)
            signum = signal_of(exc)
            print(f"fourbar-diagnose: {stop_reason(signum)}; nothing was written", file=sys.stderr)
            return exit_code(signum)


def _main(argv: list[str] | None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    for name in ("lookback", "horizon", "max_horizon", "noise_span"):
        value = getattr(args, name)
        if not value > 0:
            print(f"fourbar-diagnose: error: --{name.replace('_', '-')} {value!r}: expected a positive number of "
                  f"seconds", file=sys.stderr)
            return 2
    if args.max_horizon < args.horizon:
        print(f"fourbar-diagnose: error: --max-horizon {args.max_horizon:g} is shorter than --horizon "
              f"{args.horizon:g}: give at least the horizon (equal: the value is never fitted again)", file=sys.stderr)
        return 2
    from fourbar_common.signals import deferred, exit_code, signal_of, stop_reason

    from .diagnosis import DiagnoseOptions, change_text, diagnose_inputs, fit_text
    from .errors import DiagnoseError, NoAlarm
    from .inputs import read_inputs
    from .outputs import OutputError, prepare_out_dir, remove_empty, write_outputs

    columns = [c.strip() for c in args.columns.split(",") if c.strip()] if args.columns else None
    candidates = [c.strip() for c in args.candidates.split(",") if c.strip()] if args.candidates else None
    out = Path(args.out) if args.out else RunFolder(args.run_dir).diagnosis_folder
    options = DiagnoseOptions(lookback=args.lookback, horizon=args.horizon, max_horizon=args.max_horizon,
                              noise_span=args.noise_span, ramp=not args.no_ramp)
    created: list[Path] = []
    d = failure = None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            inputs = read_inputs(args.run_dir, summary=args.summary, fmu=args.fmu, columns=columns,
                                 use_run_fmu=args.use_run_fmu, candidates=candidates)
            created = prepare_out_dir(out, plot=not args.no_plot)      # before the long part
            if inputs.resimulates and not args.use_run_fmu:
                print(f"fourbar-diagnose: note: {inputs.run_fmu.name} cannot save its state and no FMU of the same "
                      f"model beside it can, so every branch re-simulates the run from its start (minutes); with "
                      f"the native FMU of the same mechanism beside it, it takes seconds (python build_fmu.py "
                      f"--mechanism NAME builds both into one folder)", file=sys.stderr,
                      flush=True)
            d = diagnose_inputs(inputs, options)
        except (NoAlarm, DiagnoseError) as exc:
            failure = exc
        except OSError as exc:       # an input file that cannot be read
            failure = DiagnoseError(f"{exc.filename or ''}: {exc.strerror or exc}")
        except KeyboardInterrupt as exc:
            remove_empty(created)
            signum = signal_of(exc)
            print(f"fourbar-diagnose: {stop_reason(signum)} before the diagnosis was complete; nothing was written",
                  file=sys.stderr)
            return exit_code(signum)
    for w in caught:      # e.g. malformed rows skipped in exchange.csv: one line each, no source trace
        print(f"fourbar-diagnose: warning: {w.message}", file=sys.stderr)
    if d is None:
        remove_empty(created)
        label = "" if isinstance(failure, NoAlarm) else "error: "
        print(f"fourbar-diagnose: {label}{failure}", file=sys.stderr)
        return 2
    # The verdict is printed before the files are written: it is not lost if they cannot be.
    print(f"diagnosis: {d.message}", flush=True)
    if not args.quiet:
        print(f"  fitted {', '.join(d.columns)} over t = {d.window[0]:.2f}..{d.window[1]:.2f} s "
              f"(first alarm {d.alarm_time:.2f} s); noise {', '.join(f'{k} {v:.2g}' for k, v in d.noise.items())}")
        if d.sharpened:
            print(f"  {d.best.parameter} fitted again over t = {d.value_window[0]:.2f}..{d.value_window[1]:.2f} s; "
                  f"over the first window: {fit_text(d.first_fit, d.units.get(d.best.parameter, ''))}")
        print(f"  {'hypothesis':<10} {'new value':>14} {'change':>9} {'at t [s]':>9} {'residual RMS':>13}")
        for f in d.ranking:       # relative changes; absolute (with the unit) where the healthy value is 0
            change = change_text(f, d.units.get(f.parameter, ""), 3)
            print(f"  {f.parameter:<10} {f.value:>14.6g} {change:>9} {f.change_time:>9.2f} {f.rms:>13.3g}")
        print(f"  {d.branches} branches on {d.simulator} in {d.seconds:.1f} s", flush=True)
    written: list[Path] = []
    try:
        with deferred():       # a signal now waits until the files are complete
            written = write_outputs(d, out, plot=not args.no_plot)
    except OutputError as exc:
        kept = f"; written: {', '.join(map(str, exc.written))}" if exc.written else " (the verdict above is not saved)"
        print(f"fourbar-diagnose: error: cannot write {exc.path}: {exc.reason}; not written: "
              f"{', '.join(map(str, exc.not_written))}{kept}", file=sys.stderr)
        return OUTPUTS_NOT_WRITTEN
    except KeyboardInterrupt as exc:
        signum = signal_of(exc)
        print(f"fourbar-diagnose: {stop_reason(signum)} after the verdict above; wrote "
              f"{', '.join(map(str, written))}", file=sys.stderr)
        return exit_code(signum)
    if not args.quiet:
        print(f"  wrote {', '.join(str(p) for p in written)}")
    return 0 if d.explained else AMBIGUOUS if d.ambiguous else 1


if __name__ == "__main__":
    sys.exit(main())

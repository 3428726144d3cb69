"""``fourbar-monitor``: the paper's analysis part as a command (see ``--help``).

Exit codes: 0 no alarm, 1 alarm (or the monitored run failed), 2 usage or input error,
3 the run was cut off (its writer died without closing run.json), 4 the verdict was printed
but the outputs could not be written, 5 indeterminate (no alarm, broken time grid),
130 interrupted (Ctrl-C), 143 terminated (SIGTERM).  Input problems are reported in one line naming the file, field
and value — never with a traceback.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any, Sequence, TextIO

from fourbar_common.contract.layout import SUMMARY
from fourbar_common.version import VersionAction

from .options import FollowOptions, MonitorOptions, add_arguments, option_names

__all__ = ["main", "build_parser"]

_EPILOG = """\
what it does:
  Reads the exchange file written by fourbar-run (time,x2,y2,...; a last line without a
  newline is ignored until it is complete). On the training window (default 0-9 s) it finds
  the period of the signal (FFT, then a least-squares refinement) and fits the model
  (Prophet with one custom seasonality at that period, or a least-squares Fourier series).
  An alarm prints the paper's message:
    "Undefined signal is detected or the estimation is out of work. Please check the system"

detector 'cusum' (default):
  Every sample's residual against the forecast, kept in phase with the data by a tracker
  that learns only from data --guard s old, is divided by the noise scale learnt from
  held-out training data (at least --noise-floor x the amplitude) and fed to a two-sided
  CUSUM per signal. Its limit h is set from --false-alarm-rate (per hour of data). An alarm
  latches and clears after --clear-after s without a new crossing: one episode per fault.
  Several --signal columns are monitored jointly (one phase, one alarm): each column's model
  has its own period, a whole fraction of their common period (x2 2.24 s, y2 1.12 s: 2.24 s);
  columns that share no period are refused (exit 2, naming them and their periods).

detector 'mae' (the paper's rule):
  Every --every s the newest --window s are compared with the forecast (mean absolute
  error); --persistence evaluations above the threshold raise the alarm. Threshold 'auto':
  max(k*V, 1% of the amplitude) + z*G*|t - t_c|*sigma_P/P   with k = 2, z = 4
  V: largest windowed MAE of a model fitted on the first 2/3 of the training window and
  scored on the rest. Details: docs/monitor.md.

outputs (in --out; default <exchange dir>/monitor beside fourbar-run's run.json, else
<exchange dir>/<exchange name>.monitor; nothing is written when the input is rejected):
  events.jsonl  evaluations.csv  forecast.csv  summary.json  history.png  statistic.png  spectrum.png

examples:
  fourbar-monitor out/case2_fault_L2/exchange.csv
  fourbar-monitor out/case2_fault_L2/exchange.csv --follow        # while fourbar-run runs
  fourbar-monitor exchange.csv --signal x2,x3,x4 --false-alarm-rate 0.001
  fourbar-monitor exchange.csv --detector mae --model harmonic --threshold 0.01 --window 0.3

options of the other detector (--window with cusum, --false-alarm-rate with mae, ...) are
refused unless left at their defaults; --every shorter than the file's sample step is refused
once the step is known (after the training window), before anything is written.

Ctrl-C or SIGTERM: --follow ends as if the run had ended (summary.json, plots and the verdict
are written); a replay stops at once, keeps the events, evaluations and forecasts written so far
(no summary.json) and says so in one line; stopped before it wrote anything, it says so and
names any files an earlier session left in the output folder, with their times, as that
session's.

time grid: rows are checked against run.json's grid (start + k*step; without run.json the
file's dominant step). Missing rows, time jumps, rows off the grid or duplicated are warned
about with their span; a gap is skipped, not evaluated. A FIFO, device or folder in place of
exchange.csv or run.json, and a run.json that is not a run record (empty, {}, not JSON, nested
too deeply), are refused (exit 2). --follow DIR before DIR exists waits for the folder.

exit status: 0 no alarm, 1 alarm or failed run, 2 usage/input error (nothing written), 3 the
run was cut off (its writer died: run.json still says running), 4 verdict printed but the
outputs could not be written (the file is named; partial outputs removed), 5 indeterminate:
no alarm, but the time grid is broken in the training or monitored window,
130 interrupted (Ctrl-C), 143 terminated (SIGTERM)
"""


def _positive_seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}")
    return value


def build_parser() -> argparse.ArgumentParser:
    """The arguments: what is monitored comes from :mod:`monitor.options` (defaults, choices,
    checks and help in one place); display and output flags are the command's own."""
    p = argparse.ArgumentParser(
        prog="fourbar-monitor",
        description="Watch a signal of a fourbar-cosim exchange file and alarm when it stops "
                    "following its periodic forecast (FFT period + Prophet, as in the paper).",
        epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("exchange", metavar="EXCHANGE.csv",
                   help="exchange file written by fourbar-run, or the run folder holding it (exchange.csv)")
    p.add_argument("--follow", action="store_true",
                   help="follow the run writing the file: the one running now, or else the next one to start "
                        "(a folder whose run has ended is not re-read: replay it without --follow); stop when "
                        "run.json says the run ended or its writer is gone; default: replay a finished file")
    p.add_argument("--out", metavar="DIR", type=Path,
                   help="output directory (default: <exchange dir>/monitor for a fourbar-run folder, else "
                        "<exchange dir>/<exchange name>.monitor)")
    groups = {"model": p.add_argument_group("model"), "detection": p.add_argument_group("detection"),
              "following": p.add_argument_group("following and output")}
    add_arguments(groups, MonitorOptions)
    add_arguments(groups, FollowOptions)
    g = groups["following"]
    g.add_argument("--status-every", type=_positive_seconds, default=None, metavar="S",
                   help="print a status line at most every S s of data time (default: 1 with --follow, "
                        "10 when replaying); state changes and alarms are always printed")
    g.add_argument("--no-plots", action="store_true", help="do not write the PNG figures")
    v = g.add_mutually_exclusive_group()
    v.add_argument("--quiet", "-q", action="store_true", help="print only alarms, warnings and the verdict")
    v.add_argument("--verbose", "-v", action="store_true", help="print a status line for every evaluation")
    p.add_argument("--version", action=VersionAction)
    return p


class _Printer:
    """Status lines on stdout (rate-limited), warnings and errors on stderr."""

    MAX_WARNINGS = 20

    def __init__(self, args: argparse.Namespace, out: TextIO, err: TextIO):
        self.args = args
        self.out = out
        self.err = err
        self.next_status = -math.inf
        self.n_warnings = 0
        self.last_time: float | None = None     # of the latest evaluation
        self.detector: Any = None               # the detector's class (set once the options are checked)

    def _line(self, text: str) -> None:
        print(text, file=self.out, flush=True)

    def event(self, e: Any) -> None:
        from .detector import ALARM_MESSAGE

        name = self.detector.label
        if e.kind == "trained":
            if self.args.quiet:
                return
            self._line(f"t={e.time:8.2f} s  TRAINED  {self.detector.describe(e)}")
        elif e.kind == "alarm":
            why = self.detector.describe(e)
            self._line(f"t={e.time:8.2f} s  ALARM    {name} {e.statistic:.5g} > threshold {e.threshold:.5g}{why}\n"
                       f"           {ALARM_MESSAGE}")
        elif not self.args.quiet:
            stat = "" if e.statistic is None else f"  {name} {e.statistic:.5g}  threshold {e.threshold:.5g}"
            self._line(f"t={e.time:8.2f} s  {e.kind.upper():8s}{stat}  {e.message}")

    def evaluation(self, t: float, statistic: float, threshold: float, state: Any) -> None:
        self.last_time = t
        if self.args.quiet:
            return
        if self.args.verbose or t >= self.next_status - 1e-9:
            self._line(f"t={t:8.2f} s  {state.value:8s} {self.detector.label} {statistic:.5g}  "
                       f"threshold {threshold:.5g}")
            step = self.args.status_every
            self.next_status = (math.floor(t / step + 1e-9) + 1) * step

    def warning(self, message: str) -> None:
        self.n_warnings += 1
        if self.n_warnings <= self.MAX_WARNINGS:
            print(f"fourbar-monitor: warning: {message}", file=self.err, flush=True)
        elif self.n_warnings == self.MAX_WARNINGS + 1:
            print("fourbar-monitor: warning: further warnings not shown (counts in summary.json)",
                  file=self.err, flush=True)

    def wait(self, message: str) -> None:
        if not self.args.quiet:
            self._line(f"fourbar-monitor: {message} (--timeout {self.args.timeout:g} s)")


def _verdict(result: Any, out_dir: Path, stopped: str = "interrupted") -> str:
    s = result.summary
    first = s.first_alarm
    if first is not None:
        name = s.options.detector_class.label
        head = f"ALARM at t = {first.time:g} s ({name} {first.statistic:.4g} > {first.threshold:.4g})"
        if s.fault_time is not None:
            lat = s.detection_latency
            head += (f"; fault at {s.fault_time:g} s (run.json): " +
                     (f"detected {lat:.3g} s after it" if lat is not None else "not detected after it") +
                     f", {s.false_alarms} false alarm(s) before it")
        elif s.false_alarms is not None:
            head += "; run.json records no fault: false alarm"
        if s.indeterminate is not None:
            head += f"; but {s.indeterminate}"
    elif s.indeterminate is not None:
        head = f"INDETERMINATE: no alarm, but {s.indeterminate}"
        if s.fault_time is not None:
            head += f"; fault at {s.fault_time:g} s (run.json) not detected in the rows that could be judged"
    else:
        head = "no alarm"
        if s.max_statistic_over_threshold is not None:
            head += f" (largest statistic/limit {s.max_statistic_over_threshold:.3g})"
        if s.fault_time is not None:
            head += f"; fault at {s.fault_time:g} s (run.json) NOT detected"
    if result.status == "interrupted":
        head = f"{stopped}; {head}"
    extra = ""
    if result.status in ("run_failed", "run_lost"):
        extra = f"; {result.error}"
    elif result.status == "timeout":
        extra = "; stopped: no new rows within --timeout"
    span = ""
    if s.last_time is not None:
        span = f" [{s.evaluations} evaluations up to t = {s.last_time:g} s]"
    where = f"outputs in {out_dir}" if result.output_error is None else "no outputs written (error below)"
    return f"verdict: {head}{extra}{span}; {where}"


def main(argv: Sequence[str] | None = None) -> int:
    from fourbar_common.signals import StopSignals, exit_code, signal_of, stop_reason
    from fourbar_common.console import closed_stdout_tolerated

    # Ctrl-C and SIGTERM end the monitor with one line, at any moment
    # (and a reader that stops early, `| head`, costs nothing but the console)
    with StopSignals() as stop, closed_stdout_tolerated():
        try:
            return _main(argv, stop)
        except KeyboardInterrupt as exc:      # before the monitoring began
            signum = signal_of(exc)
            print(f"fourbar-monitor: {stop_reason(signum)}; nothing was written", file=sys.stderr, flush=True)
            return exit_code(signum)


def _main(argv: Sequence[str] | None, stop: Any) -> int:
    from fourbar_common.signals import signal_of

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:            # --help, --version (0) or a usage error (2)
        return int(exc.code or 0)
    out, err = sys.stdout, sys.stderr
    if args.status_every is None:
        args.status_every = 1.0 if args.follow else 10.0
    printer = _Printer(args, out, err)
    settings = {name: getattr(args, name) for name in option_names() if hasattr(args, name)}
    from .errors import MonitorError

    out_dir = None
    earlier: dict[str, tuple[int, int, int]] = {}      # the output folder's files before this session
    try:
        from .options import merged
        from .outputs import checked_default_out_dir, checked_out_dir
        from .reader import exchange_file
        from .session import follow, replay

        exchange = exchange_file(args.exchange, later=args.follow)      # a run folder: its exchange.csv
        options = merged(MonitorOptions(), settings)   # inconsistent options are refused before anything is read
        if not options.signal:                         # the run's default signal (x2 for the four-bar)
            from .session import with_run_signal

            options = with_run_signal(options, exchange)
            settings["signal"] = args.signal = options.signal
        printer.detector = options.detector_class
        out_dir = checked_out_dir(args.out) if args.out is not None else checked_default_out_dir(exchange)
        earlier = _output_stamps(out_dir)

        if not args.quiet:
            mode = "following" if args.follow else "replaying"
            how = options.detector_class.settings_text(options)
            print(f"fourbar-monitor: {mode} {exchange} (signal {args.signal}, model {args.model}, {how})",
                  file=out, flush=True)
        common = dict(out_dir=out_dir, plots=not args.no_plots, on_event=printer.event,
                      on_evaluation=printer.evaluation, on_warning=printer.warning, **settings)
        # one BLAS thread: the monitor's linear algebra is small (normal equations of a few dozen
        # unknowns), so more threads only wait for work, busily: on 2 cores a replay of Case 2 spent
        # 0.9 s of CPU in training instead of 0.2 s, with the same numbers (docs/benchmarks.md)
        from threadpoolctl import threadpool_limits

        with threadpool_limits(limits=1, user_api="blas"):
            if args.follow:
                result = follow(exchange, poll=args.poll, timeout=args.timeout, on_wait=printer.wait, **common)
            else:
                result = replay(exchange, **common)
    except MonitorError as exc:
        if stop.received is not None:       # e.g. Prophet's optimiser killed by the same Ctrl-C
            return _stopped(stop.received, printer, out_dir, err, earlier)
        print(f"fourbar-monitor: error: {exc}", file=err, flush=True)
        return 2
    except KeyboardInterrupt as exc:
        return _stopped(signal_of(exc), printer, out_dir, err, earlier)
    except ImportError as exc:            # an optional library missing from this environment
        print(f"fourbar-monitor: error: cannot import {exc.name or exc}: {exc}; install it, or use "
              "--model harmonic", file=err, flush=True)
        return 2
    except OSError as exc:                # e.g. --out not writable
        if stop.received is not None:
            return _stopped(stop.received, printer, out_dir, err, earlier)
        where = exc.filename or (out_dir if out_dir is not None else args.exchange)
        print(f"fourbar-monitor: error: {where}: {exc.strerror or exc}", file=err, flush=True)
        return 2
    except Exception:
        if stop.received is not None:     # a library that failed because the signal reached it too
            return _stopped(stop.received, printer, out_dir, err, earlier)
        raise
    print(_verdict(result, out_dir, stop.reason), file=out, flush=True)
    if result.output_error is not None:
        print(f"fourbar-monitor: error: {result.output_error}", file=err, flush=True)
    if result.status == "interrupted":     # --follow stopped by a signal: the outputs are complete
        return stop.exit_code
    return result.exit_code


def _output_stamps(out_dir: Path | None) -> dict[str, tuple[int, int, int]]:
    """The monitor's files in ``out_dir`` now: name → (inode, mtime in ns, size)."""
    from .outputs import OUTPUT_FILES

    stamps = {}
    for name in OUTPUT_FILES if out_dir is not None else ():
        try:
            st = (out_dir / name).stat()
        except OSError:
            continue
        stamps[name] = (st.st_ino, st.st_mtime_ns, st.st_size)
    return stamps


def _stopped(signum: int, printer: "_Printer", out_dir: Path | None, err: TextIO,
             earlier: dict[str, tuple[int, int, int]]) -> int:
    """One line for a monitor stopped by a signal before its summary: what this session kept
    where, and which files there are an earlier session's (``earlier``: the folder before it)."""
    import datetime as dt

    from fourbar_common.signals import exit_code, stop_reason

    now = _output_stamps(out_dir)
    ours = [name for name, stamp in now.items() if earlier.get(name) != stamp]
    old = [name for name, stamp in now.items() if earlier.get(name) == stamp]
    where = f" at t = {printer.last_time:g} s of data" if printer.last_time is not None else ""
    if ours:
        what = (f"kept {', '.join(ours)} in {out_dir}" + ("" if SUMMARY in ours else
                                                          " (up to then; no summary.json: the replay did not end)"))
    else:
        what = "nothing was written this time"
    if old:
        def written(name: str) -> str:
            when = dt.datetime.fromtimestamp(now[name][1] / 1e9, dt.timezone.utc)
            return f"{name} {when:%Y-%m-%d %H:%M:%S} UTC"
        what += (f"; {', '.join(written(n) for n in old)} in {out_dir} "
                 f"{'are' if len(old) > 1 else 'is'} from an earlier session, not this one")
    print(f"fourbar-monitor: {stop_reason(signum)}{where}; {what}", file=err, flush=True)
    return exit_code(signum)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

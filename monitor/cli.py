"""``fourbar-monitor``: the paper's analysis part as a command (see ``--help``).

Exit codes: 0 no alarm, 1 alarm (or the monitored run failed), 2 usage or input error,
130 interrupted.  Input problems are reported in one line naming the file, field and
value — never with a traceback.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any, Sequence, TextIO

__all__ = ["main", "build_parser"]

_EPILOG = """\
what it does:
  Reads the exchange file written by fourbar-run (time,x2,y2,...; a last line without a
  newline is ignored until it is complete). On the training window (default 0-9 s) it finds
  the period of the signal (FFT, then a least-squares refinement), fits the model (Prophet
  with one custom seasonality at that period, or a least-squares Fourier series) and sets
  the threshold. Then every --every seconds of data it compares the newest --window seconds
  with the forecast (mean absolute error); --persistence evaluations above the threshold
  raise the alarm and print the paper's message:
    "Undefined signal is detected or the estimation is out of work. Please check the system"

threshold 'auto' (default):
  max(k*V, 1% of the amplitude) + z*G*|t - t_c|*sigma_P/P   with k = 2, z = 4
  V: largest windowed MAE of a model fitted on the first 2/3 of the training window and
  scored on the rest; the second term covers the forecast drift that the period's
  uncertainty sigma_P allows (negligible on clean data). Details: docs/monitor.md.

outputs (in --out, default <exchange dir>/monitor):
  events.jsonl  evaluations.csv  summary.json  history.png  mae.png  spectrum.png

examples:
  fourbar-monitor out/case2_fault_L2/exchange.csv
  fourbar-monitor out/case2_fault_L2/exchange.csv --follow        # while fourbar-run runs
  fourbar-monitor exchange.csv --model harmonic --threshold 0.01 --window 0.3

exit status: 0 no alarm, 1 alarm or failed run, 2 usage/input error, 130 interrupted
"""


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("fourbar-cosim")
    except Exception:  # noqa: BLE001 - not installed: fall back to the source version
        return "0.1.0"


def _float_arg(accept, expected: str, rejected: str | None = None):
    """argparse type: a finite float for which ``accept(value)`` holds.

    ``expected`` is the message for text that is not a number, ``rejected`` (default: the
    same) the one for a number that is not accepted; both get ", got '<text>'".
    """
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{expected}, got {text!r}") from None
        if not (math.isfinite(value) and accept(value)):
            raise argparse.ArgumentTypeError(f"{rejected or expected}, got {text!r}")
        return value
    return parse


def _positive(name: str):
    return _float_arg(lambda v: v > 0, f"{name}: expected a positive number of seconds")


_nonnegative = _float_arg(lambda v: v >= 0, "expected a number of seconds ≥ 0")
_time = _float_arg(lambda v: True, "expected a time in seconds", "expected a finite time in seconds")
_positive_level = _float_arg(lambda v: v > 0, "expected 'auto' or a positive number in the signal's units")


def _threshold(text: str) -> float | str:
    return "auto" if text.strip().lower() == "auto" else _positive_level(text)


def _count(low: int):
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer ≥ {low}, got {text!r}") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"expected an integer ≥ {low}, got {text!r}")
        return value
    return parse


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="fourbar-monitor",
        description="Watch a signal of a fourbar-cosim exchange file and alarm when it stops "
                    "following its periodic forecast (FFT period + Prophet, as in the paper).",
        epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("exchange", metavar="EXCHANGE.csv", help="exchange file written by fourbar-run")
    p.add_argument("--follow", action="store_true",
                   help="follow the file while it grows (wait for it to appear; stop when run.json says the "
                        "run ended, or after --timeout s without new rows); default: replay a finished file")
    p.add_argument("--out", metavar="DIR", type=Path, help="output directory (default: <exchange dir>/monitor)")
    g = p.add_argument_group("model")
    g.add_argument("--signal", default="x2", help="column to monitor (default: %(default)s)")
    g.add_argument("--train", nargs=2, type=_time, metavar=("START", "END"), default=(0.0, 9.0),
                   help="training window in s (default: 0 9, as in the paper)")
    g.add_argument("--model", choices=("prophet", "harmonic"), default="prophet",
                   help="prophet (the paper's) or harmonic (least-squares Fourier series, fast); "
                        "default: %(default)s")
    g.add_argument("--order", type=_count(1), default=30, help="Fourier order of the model (default: %(default)s)")
    g = p.add_argument_group("detection")
    g.add_argument("--threshold", type=_threshold, default="auto",
                   help="MAE threshold in the signal's units, or 'auto' (default) from the training data")
    g.add_argument("--window", type=_positive("--window"), default=0.5,
                   help="evaluation window: the newest WINDOW s of data (default: %(default)s)")
    g.add_argument("--every", type=_positive("--every"), default=0.1,
                   help="evaluation cadence in s of data time (default: %(default)s)")
    g.add_argument("--persistence", type=_count(1), default=2,
                   help="consecutive evaluations above the threshold before an alarm (default: %(default)s)")
    g.add_argument("--refit", choices=("none", "paper"), default="none",
                   help="none (default): fit once; paper: refit on the latest --refit-samples samples until "
                        "the first evaluation passes (the paper's policy)")
    g.add_argument("--refit-samples", type=_count(32), default=1000, help="samples per refit (default: %(default)s)")
    g = p.add_argument_group("following and output")
    g.add_argument("--poll", type=_positive("--poll"), default=0.2,
                   help="with --follow: seconds between reads of the file (default: %(default)s)")
    g.add_argument("--timeout", type=_nonnegative, default=60.0,
                   help="with --follow: give up after this many seconds without the file or without new rows "
                        "when run.json does not say the run ended; 0 = wait for ever (default: %(default)s)")
    g.add_argument("--status-every", type=_positive("--status-every"), default=None, metavar="S",
                   help="print a status line at most every S s of data time (default: 1 with --follow, "
                        "10 when replaying); state changes and alarms are always printed")
    g.add_argument("--no-plots", action="store_true", help="do not write the PNG figures")
    v = g.add_mutually_exclusive_group()
    v.add_argument("--quiet", "-q", action="store_true", help="print only alarms, warnings and the verdict")
    v.add_argument("--verbose", "-v", action="store_true", help="print a status line for every evaluation")
    p.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
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

    def _line(self, text: str) -> None:
        print(text, file=self.out, flush=True)

    def event(self, e: Any) -> None:
        from .detector import ALARM_MESSAGE

        if e.kind == "trained":
            if self.args.quiet:
                return
            d = e.data
            thr = f"threshold {d['threshold_base']:.4g}"
            if d.get("threshold_slope_per_s"):
                thr += f" + {d['threshold_slope_per_s']:.2g}/s·|t − t_c|"
            self._line(f"t={e.time:8.2f} s  TRAINED  period {d['period_s']:.6g} s (FFT {d['period_fft_s']:.4g} s); "
                       f"{d['model']} order {d['order']} fitted in {d['fit_seconds']:.2f} s; {thr}")
        elif e.kind == "alarm":
            why = " (refit limit reached)" if e.data.get("reason") == "refit_limit" else ""
            self._line(f"t={e.time:8.2f} s  ALARM    MAE {e.mae:.5g} > threshold {e.threshold:.5g}{why}\n"
                       f"           {ALARM_MESSAGE}")
        elif not self.args.quiet:
            mae = "" if e.mae is None else f"  MAE {e.mae:.5g}  threshold {e.threshold:.5g}"
            self._line(f"t={e.time:8.2f} s  {e.kind.upper():8s}{mae}  {e.message}")

    def evaluation(self, t: float, mae: float, threshold: float, state: Any) -> None:
        if self.args.quiet:
            return
        if self.args.verbose or t >= self.next_status - 1e-9:
            self._line(f"t={t:8.2f} s  {state.value:8s} MAE {mae:.5g}  threshold {threshold:.5g}")
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


def _verdict(result: Any, out_dir: Path) -> str:
    s = result.summary
    if s["alarms"]:
        head = f"ALARM at t = {s['first_alarm_time']:g} s (MAE {s['first_alarm_mae']:.4g} > {s['first_alarm_threshold']:.4g})"
        if s.get("fault_time") is not None:
            lat = s.get("detection_latency_s")
            head += (f"; fault at {s['fault_time']:g} s (run.json): " +
                     (f"detected {lat:.3g} s after it" if lat is not None else "not detected after it") +
                     f", {s['false_alarms_before_fault']} false alarm(s) before it")
        elif s.get("false_alarms_before_fault") is not None:
            head += "; run.json records no fault: false alarm"
    else:
        head = "no alarm"
        if s.get("max_mae_over_threshold") is not None:
            head += f" (largest MAE/threshold {s['max_mae_over_threshold']:.3g})"
        if s.get("fault_time") is not None:
            head += f"; fault at {s['fault_time']:g} s (run.json) NOT detected"
    if result.status == "interrupted":
        head = f"interrupted; {head}"
    extra = ""
    if result.status == "run_failed":
        extra = f"; {result.error}"
    elif result.status == "timeout":
        extra = "; stopped: no new rows within --timeout"
    span = ""
    if s.get("last_time") is not None:
        span = f" [{s['evaluations']} evaluations up to t = {s['last_time']:g} s]"
    return f"verdict: {head}{extra}{span}; outputs in {out_dir}"


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:            # --help, --version (0) or a usage error (2)
        return int(exc.code or 0)
    out, err = sys.stdout, sys.stderr
    if args.status_every is None:
        args.status_every = 1.0 if args.follow else 10.0
    printer = _Printer(args, out, err)
    exchange = Path(args.exchange)
    out_dir = args.out if args.out is not None else exchange.parent / "monitor"
    settings = dict(signal=args.signal, train=tuple(args.train), model=args.model, order=args.order,
                    threshold=args.threshold, window=args.window, every=args.every,
                    persistence=args.persistence, refit=args.refit, refit_samples=args.refit_samples)
    from .errors import MonitorError

    previous = _terminate_as_interrupt()
    try:
        from .engine import follow, replay

        if not args.quiet:
            mode = "following" if args.follow else "replaying"
            print(f"fourbar-monitor: {mode} {exchange} (signal {args.signal}, model {args.model}, threshold "
                  f"{args.threshold}, window {args.window:g} s every {args.every:g} s, persistence "
                  f"{args.persistence})", file=out, flush=True)
        common = dict(out_dir=out_dir, plots=not args.no_plots, on_event=printer.event,
                      on_evaluation=printer.evaluation, on_warning=printer.warning, **settings)
        if args.follow:
            result = follow(exchange, poll=args.poll, timeout=args.timeout, on_wait=printer.wait, **common)
        else:
            result = replay(exchange, **common)
    except MonitorError as exc:
        print(f"fourbar-monitor: error: {exc}", file=err, flush=True)
        return 2
    except KeyboardInterrupt:
        print("fourbar-monitor: interrupted", file=err, flush=True)
        return 130
    except ImportError as exc:            # an optional library missing from this environment
        print(f"fourbar-monitor: error: cannot import {exc.name or exc}: {exc}; install it, or use "
              "--model harmonic", file=err, flush=True)
        return 2
    except OSError as exc:                # e.g. --out not writable
        print(f"fourbar-monitor: error: {exc.filename or ''}: {exc.strerror or exc}", file=err, flush=True)
        return 2
    finally:
        _restore_terminate(previous)
    print(_verdict(result, out_dir), file=out, flush=True)
    return result.exit_code


def _terminate_as_interrupt() -> Any:
    """SIGTERM ends the monitor like Ctrl-C (outputs written, exit 130); main thread only."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    return signal.signal(signal.SIGTERM, handler)


def _restore_terminate(previous: Any) -> None:
    import signal

    if previous is not None:
        signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())

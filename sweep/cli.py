"""``fourbar-sweep``: run a sweep file's fault scenarios on Dask and report detection figures.

Exit codes: 0 every scenario of the sweep has a row and none failed, 1 some scenario
failed (its row says why) or the cluster could not be used, 2 usage or sweep-file error
or an unusable --out (nothing run), 130 interrupted (Ctrl-C), 143 terminated (SIGTERM):
finished rows are kept, re-run to resume.  Heavy imports (Dask,
FMPy, pandas) happen inside the handler, so ``--help`` and ``--version`` answer at once.
"""
from __future__ import annotations

import argparse
import sys

from fourbar_common.contract.layout import SweepFolder
from fourbar_common.version import VersionAction

__all__ = ["main"]

_DESCRIPTION = """\
Run a sweep of fault scenarios: each scenario is one co-simulation of the sweep's base case
with one injected fault (orchestrator) followed by a replay of its exchange file by the
monitor.  Scenarios run in parallel on Dask -- a local cluster of worker processes (one per
core) unless --scheduler names an existing one.  The results table (one row per scenario:
inputs, detected or not, latency, false alarms, MAE statistics, run time) is written to
DIR/results.csv (appended as scenarios finish) and DIR/results.parquet, the plots to
DIR/plots/ (detection probability and latency against fault size; ROC), the headline
figures to DIR/summary.json.  Running the same command again skips the scenarios already
in the table, so an interrupted sweep resumes where it stopped.
"""

_EPILOG = """\
examples:
  fourbar-sweep sweeps/smoke.toml                       # 8 short scenarios, a first try
  fourbar-sweep sweeps/l2_step.toml --workers 2
  fourbar-sweep sweeps/l2_step.toml --dashboard          # Dask's dashboard on 127.0.0.1:8787
  fourbar-sweep sweeps/l2_step.toml --dry-run           # count the scenarios, run nothing
  fourbar-sweep sweeps/l2_step.toml --scheduler tcp://10.0.0.5:8786 --out /shared/sweeps/l2

Sweep-file keys, cluster set-up and the meaning of every column: docs/sweep.md.
Ctrl-C or SIGTERM (to the sweep, or Ctrl-C to its whole process group) cancels the
scenarios still running, writes the table, summary and plots from the rows finished so far
and says where; re-run the same command to resume.
exit status: 0 all scenarios done and none failed, 1 a scenario failed or no cluster,
2 usage or sweep-file error or unusable --out (nothing run), 130 interrupted (Ctrl-C),
143 terminated (SIGTERM).
"""


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a number >= 1, got {value}")
    return value


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="fourbar-sweep", description=_DESCRIPTION, epilog=_EPILOG,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("sweep", metavar="SWEEP.toml", help="the sweep file (format: docs/sweep.md)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="address of a running Dask scheduler, e.g. tcp://host:8786 (default: start a "
                             "local cluster); its workers need this package, the FMU and DIR at the same paths")
    parser.add_argument("--dashboard", metavar="HOST:PORT", nargs="?", const="127.0.0.1:8787", default=None,
                        help="serve the local cluster's Dask dashboard (task stream, worker load) at HOST:PORT "
                             "(default when given without one: 127.0.0.1:8787, this computer only; :PORT or PORT "
                             "is 127.0.0.1 too) and print its link; off by default.  The dashboard has no "
                             "authentication: another address (e.g. 0.0.0.0:8787) gets a warning; requests "
                             "naming another host get 403; BOKEH_* variables are ignored")
    parser.add_argument("--workers", metavar="N", type=_positive_int,
                        help="worker processes of the local cluster (default: one per core)")
    parser.add_argument("--out", metavar="DIR", help="output directory (default: out/sweeps/<sweep name>)")
    parser.add_argument("--limit", metavar="N", type=_positive_int,
                        help="run at most N of the scenarios not yet done (the rest on a later run)")
    parser.add_argument("--retry-failed", action="store_true",
                        help="run the scenarios whose row says 'failed' again (their old rows go to stale.csv)")
    parser.add_argument("--dry-run", action="store_true",
                        help="check the sweep file and count the scenarios (done / to run); run nothing")
    parser.add_argument("--quiet", "-q", action="store_true", help="no progress bar, no summary")
    parser.add_argument("--version", action=VersionAction)
    return parser


def main(argv: list[str] | None = None) -> int:
    from fourbar_common.signals import StopSignals, exit_code, signal_of, stop_reason
    from fourbar_common.console import closed_stdout_tolerated

    # Ctrl-C and SIGTERM end the sweep in order, with one line
    # (and a reader that stops early, `| head`, costs nothing but the console)
    with StopSignals() as stop, closed_stdout_tolerated():
        try:
            return _main(argv, stop)
        except KeyboardInterrupt as exc:     # before the sweep began (the sweep reports its own)
            signum = signal_of(exc)
            _err(f"{stop_reason(signum)}; nothing was run")
            return exit_code(signum)


def _main(argv: list[str] | None, stop=None) -> int:
    parser = _parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:   # --help, --version (0) or a usage error (2, message printed)
        return int(exc.code or 0)
    if args.scheduler and args.workers:
        print("fourbar-sweep: error: --workers sets the size of the local cluster; with --scheduler the "
              "cluster's own workers are used (start them with `dask worker`)", file=sys.stderr)
        return 2
    if args.dashboard is not None:
        if args.scheduler:
            print("fourbar-sweep: error: --dashboard serves the local cluster's dashboard; a scheduler given by "
                  "--scheduler serves its own", file=sys.stderr)
            return 2
        from view.served import AddressError, Bind, ignore_bokeh_environment, parse_address

        try:
            bind = parse_address(args.dashboard, 8787, option="--dashboard")
        except AddressError as exc:
            _err(f"error: {exc}")
            return 2
        problem = Bind(bind.host, 0).listen_problem("--dashboard")     # the port may be taken: Dask then picks one
        if problem is not None:
            _err(f"error: {problem}")
            return 2
        args.dashboard = bind.where
        warning = bind.warning("the Dask dashboard")
        if warning:
            _err(warning)
        ignored = ignore_bokeh_environment()      # before Bokeh serves: BOKEH_ALLOW_WS_ORIGIN would widen it
        if ignored and not args.quiet:
            _err(f"note: ignoring {', '.join(ignored)} from the environment for the dashboard")
    return _sweep(args.sweep, scheduler=args.scheduler, workers=args.workers, out=args.out, limit=args.limit,
                  retry_failed=args.retry_failed, dry_run=args.dry_run, quiet=args.quiet, dashboard=args.dashboard,
                  stop=stop)


def _err(message: str) -> None:
    print(f"fourbar-sweep: {message}", file=sys.stderr)


def _percent(x: float | None) -> str:
    return "none" if x is None else f"{100 * x:.3g} %"


def _sweep(path: str, *, scheduler, workers, out, limit, retry_failed: bool, dry_run: bool, quiet: bool,
           dashboard: str | None = None, stop=None) -> int:
    from pathlib import Path

    from fourbar_common.signals import exit_code, signal_of, stop_reason

    from .config import SweepError, load_sweep
    from .results import ResultsError

    try:
        sweep = load_sweep(path)
    except SweepError as exc:
        _err(f"error: {exc}")
        return 2
    if not quiet:
        for note in sweep.notes:
            _err(f"note: {note}")
    if dry_run:
        return _dry_run(sweep, out)

    from .runner import ClusterError, SweepInterrupted, default_workers, run_sweep

    def started(to_run: int, done: int, directory) -> None:
        if quiet:
            return
        where = f"the Dask scheduler at {scheduler}" if scheduler else \
            f"a local cluster of {workers or default_workers()} worker process(es)"
        text = f"{sweep.name}: {done} scenario(s) already in {SweepFolder(directory).results}, {to_run} to run"
        _err(text + (f" on {where}" if to_run else ""))

    try:
        result = run_sweep(sweep, out, scheduler=scheduler, workers=workers, limit=limit, retry_failed=retry_failed,
                           progress=not quiet and sys.stderr.isatty(), on_start=started,
                           dashboard=dashboard, on_dashboard=lambda link: _err(f"Dask dashboard: {link}"))
    except ResultsError as exc:
        _err(f"error: {exc}")
        return 2
    except ClusterError as exc:
        _err(f"error: {exc}")
        return 1
    except SweepInterrupted as exc:
        r = exc.result
        signum = stop.received if stop is not None and stop.received is not None else signal_of(exc)
        _err(f"{sweep.name}: {stop_reason(signum)}: {len(r.table)} of {r.planned} scenarios in {r.files['csv']}; "
             f"run the same command again to resume")
        return exit_code(signum)
    except KeyboardInterrupt as exc:     # before the first scenario, or a second signal while writing the table
        signum = signal_of(exc)
        csv = SweepFolder(Path(out) if out else Path("out") / "sweeps" / sweep.name).results
        kept = (f"the rows of finished scenarios are kept in {csv}; run the same command again to resume"
                if csv.is_file() else "nothing was run")
        _err(f"{sweep.name}: {stop_reason(signum)}; {kept}")
        return exit_code(signum)
    except OSError as exc:               # writing the results: disk full, folder removed meanwhile
        _err(f"error: {exc.filename or sweep.name}: {exc.strerror or exc}; the rows written so far are kept")
        return 1
    if not quiet:
        _report(result)
    failed = result.failed
    if failed:
        _err(f"{sweep.name}: {failed} scenario(s) failed; see the 'error' column of {result.files['csv']}")
        return 1
    return 0


def _dry_run(sweep, out) -> int:
    from pathlib import Path

    from .plan import plan_scenarios
    from .results import ResultsError, ResultsStore

    plan = plan_scenarios(sweep)
    directory = Path(out) if out else Path("out") / "sweeps" / sweep.name
    try:
        store = ResultsStore(directory)
        store.check_dir()
        rows = store.load()
    except ResultsError as exc:
        _err(f"error: {exc}")
        return 2
    ids = {s.id for s in plan}
    done = {r["scenario_id"] for r in rows if r.get("scenario_id") in ids and r.get("fmu_guid") == sweep.fmu_guid}
    kinds = {}
    for s in plan:
        kinds[s.kind] = kinds.get(s.kind, 0) + 1
    detail = ", ".join(f"{n} {k}" for k, n in kinds.items())
    print(f"{sweep.name}: {len(plan)} scenarios ({detail}); {len(done)} already in {SweepFolder(directory).results}, "
          f"{len(plan) - len(done)} to run")
    return 0


def _report(result) -> None:
    s = result.record
    r = result
    print(f"{r.sweep.name}: {len(r.table)} of {r.planned} scenarios in the table ({r.ran} run now, "
          f"{r.skipped} already done), {r.failed} failed, {r.wall_seconds:.1f} s")
    for note in r.notes:
        if note not in r.sweep.notes:
            print(f"  note: {note}")
    failed = r.table[r.table["status"] != "ok"]
    for _, row in failed.head(5).iterrows():
        print(f"  failed {row['scenario_id']} ({row['kind']} {row['variable']} {_percent(row['relative_change'])}"
              f"): {row['error']}")
    if len(failed) > 5:
        print(f"  ... {len(failed) - 5} more failed rows")
    variable, limit = s.variable, s.latency_limit
    size = f"|Δ{variable}|/{variable}" if variable else "relative change"
    print(f"smallest {size} detected within {limit:g} s with no false alarm "
          f"(in every scenario of that size and above):")
    for g in s.series:
        nf = g["no_fault"]
        clean = f"; fault-free runs with an alarm: {nf['runs_with_alarms']}/{nf['n']}" if nf["n"] else ""
        print(f"  {g['series']}: {_percent(g['smallest_reliable_change'])}{clean}")
    if s.classification:
        print("diagnosis (fourbar-diagnose after each alarm): right parameter / detected faults")
        print(f"  {'parameter':<9} {'change':>8} {'noise':>7} {'right':>9} {'value err':>10} {'time err':>9}")
        for c in s.classification:
            value = "-" if c["value_error"] is None else f"{100 * c['value_error']:.2g} %"
            when = "-" if c["time_error"] is None else f"{c['time_error']:.2f} s"
            print(f"  {c['variable']:<9} {_percent(c['relative_change']):>8} {c['noise_std']:>7g} "
                  f"{c['right']:>4}/{c['detected']:<4} {value:>10} {when:>9}")
    for key in ("csv", "parquet", "detection_plot", "roc_plot", "delay_plot", "summary"):
        if key in r.files:
            print(f"  {key.replace('_', ' ')}: {r.files[key]}")


if __name__ == "__main__":
    sys.exit(main())

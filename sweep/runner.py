"""Running a sweep on Dask: plan, skip what is done, run the rest, write the table and plots.

``run_sweep`` plans the scenarios (:mod:`sweep.plan`), reads the results already in the
output directory (:mod:`sweep.results`) and submits only the scenarios without a row.
Each one is a task :func:`sweep.scenario.run_scenario` on a Dask worker: by default a
``LocalCluster`` of worker *processes*, one per core, one thread each (the FMU and the
monitor run Python code, so threads would only contend for the GIL); with ``scheduler``
an existing cluster.  The tasks receive the scenario, the base case (the FMU's path) and
an absolute output directory -- workers load the FMU themselves, so they need the same
environment and the same paths (docs/sweep.md).

Rows are appended to ``results.csv`` as the tasks finish (in completion order), so an
interrupted sweep keeps every finished scenario; ``results.parquet`` is rewritten from them
every ``PARQUET_INTERVAL`` seconds.  At the end the table is rewritten in plan order
(``results.csv`` and ``results.parquet``), summarised (``summary.json``) and
plotted (``plots/detection.png``, ``plots/roc.png``, ``plots/delay_arl0.png``).  Ctrl-C cancels the pending tasks,
writes the same files from the rows so far and raises :class:`SweepInterrupted`.
"""
from __future__ import annotations

import logging
import os
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Iterator

from fourbar_common.contract.evaluations import read_evaluations
from fourbar_common.contract.layout import EVALUATIONS, SweepFolder
from fourbar_common.contract.sweep_results import SweepSummary, write_sweep_record, write_sweep_summary

from .config import Sweep, load_sweep
from .plan import Scenario, plan_scenarios
from .results import ResultsStore, table_from_rows
from .scenario import failed_row, run_scenario

__all__ = ["ClusterError", "SweepInterrupted", "SweepResult", "dashboard_link", "default_workers", "open_client",
           "run_sweep"]


class ClusterError(RuntimeError):
    """The Dask scheduler could not be reached or the local cluster could not start."""


@dataclass(frozen=True)
class SweepResult:
    """What a sweep produced (``table`` is the whole results table, in plan order)."""

    sweep: Sweep
    out_dir: Path
    table: Any                     # pandas.DataFrame, columns sweep.results.COLUMNS
    summary: dict
    planned: int                   # scenarios in the sweep file
    skipped: int                   # already in the results: not run again
    ran: int                       # run by this call
    interrupted: bool
    wall_seconds: float
    files: dict = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    #: summary.json as written, typed (``summary`` is the same as the report's dict)
    record: SweepSummary | None = None

    @property
    def failed(self) -> int:
        return int((self.table["status"] != "ok").sum()) if len(self.table) else 0

    @property
    def complete(self) -> bool:
        return len(self.table) == self.planned


class SweepInterrupted(KeyboardInterrupt):
    """Ctrl-C stopped a sweep; ``result`` holds the rows kept (re-run to resume)."""

    def __init__(self, result: SweepResult):
        super().__init__(f"interrupted after {len(result.table)} of {result.planned} scenarios")
        self.result = result


def default_workers() -> int:
    """One worker per core this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:       # not on Linux
        return max(1, os.cpu_count() or 1)


_NO_DASHBOARD_HTTP = "127.0.0.1:0"    # the scheduler's HTTP API without a dashboard: any free loopback port


@contextmanager
def open_client(scheduler: str | None = None, workers: int | None = None, *,
                timeout: float = 20.0, dashboard: str | None = None) -> Iterator[Any]:
    """A Dask client: on ``scheduler`` (an address), else on a new ``LocalCluster`` of
    ``workers`` processes (default :func:`default_workers`) with one thread each, serving
    its dashboard at ``dashboard`` (e.g. ``":8787"``; None: no dashboard).
    Client and cluster are closed on exit; :func:`dashboard_link` says where it is.

    ``dashboard`` is ``HOST:PORT``, ``:PORT`` or ``PORT`` (127.0.0.1: this computer only;
    :func:`view.served.parse_address`).  The dashboard answers only requests whose Host header
    names the bound address (403 otherwise) and its websocket only those origins."""
    import dask
    from dask.distributed import Client, LocalCluster

    from view.served import Bind, parse_address, refuse_other_hosts

    if scheduler:
        try:
            client = Client(scheduler, timeout=f"{timeout}s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise ClusterError(f"cannot connect to the Dask scheduler at {scheduler!r}: {exc}") from None
        try:
            yield client
        finally:
            client.close()
        return
    n = workers or default_workers()
    # dashboard_address=None turns the dashboard off, but the scheduler still serves its small
    # HTTP API (health, metrics) and binds it to port 8787 by default: when that port is taken
    # (another sweep, any dashboard), distributed warned "Port 8787 is already in use" to a
    # user who asked for no dashboard.  Without a dashboard that API gets a free port on the
    # loopback interface instead, so nothing is printed and nothing is exposed.
    quiet_http = {} if dashboard is not None else {"dashboard_address": _NO_DASHBOARD_HTTP}
    asked = parse_address(dashboard, 8787, option="--dashboard") if dashboard is not None else None
    # the dashboard's websocket takes only the bound address's names as origins (distributed's
    # default is "*": any web page open in this computer's browser could read the dashboard)
    origins = {"distributed.scheduler.dashboard.bokeh-application.allow_websocket_origin":
               [n for n in asked.names() if ":" not in n]} if asked is not None else {}
    try:
        with _children_ignore_sigint(), dask.config.set(origins):
            cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                   dashboard_address=asked.where if asked is not None else None,
                                   scheduler_kwargs=quiet_http, silence_logs=logging.CRITICAL)
    except (OSError, TimeoutError) as exc:
        raise ClusterError(f"cannot start a local Dask cluster of {n} worker processes: {exc}") from None
    if asked is not None:
        http = cluster.scheduler.http_server
        # requests naming another host (DNS rebinding) get 403 before any handler runs
        refuse_other_hosts(cluster.scheduler.http_application, Bind(asked.host, http.port).host_names())
    try:
        with Client(cluster) as client:
            yield client
    finally:
        cluster.close()


def dashboard_link(client) -> str:
    """The dashboard's link at the address its local cluster's scheduler really bound (not
    distributed's ``dashboard_link``, which names the scheduler's host whatever the dashboard
    bound: it printed 127.0.0.1 for a dashboard on 0.0.0.0)."""
    from view.served import Bind

    http = client.cluster.scheduler.http_server
    return Bind(http.address, http.port).url + "status"


@contextmanager
def _children_ignore_sigint() -> Iterator[None]:
    """Ignore SIGINT while the local workers are spawned, so they inherit SIG_IGN.

    Ctrl-C in a terminal reaches the whole process group: the sweep (this process) turns it
    into an orderly stop -- cancel, keep the finished rows, close the cluster, which ends
    the workers -- while workers that took it themselves would die printing tracebacks.
    (Python keeps an inherited SIG_IGN for SIGINT.)  Main thread only; no-op elsewhere.
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def run_sweep(sweep: Sweep | str | Path, out_dir: str | Path | None = None, *, scheduler: str | None = None,
              workers: int | None = None, client: Any = None, progress: bool = False, limit: int | None = None,
              retry_failed: bool = False, on_start: Callable[[int, int, Path], None] | None = None,
              dashboard: str | None = None, on_dashboard: Callable[[str], None] | None = None) -> SweepResult:
    """Run the scenarios of ``sweep`` that have no row yet in ``out_dir``; return the table.

    ``out_dir`` defaults to ``out/sweeps/<sweep name>``.  The cluster is ``client`` (an
    existing ``dask.distributed.Client``, left open), else ``scheduler`` (an address),
    else a new LocalCluster of ``workers`` processes.  ``limit`` runs at most that many of
    the pending scenarios (the rest stay for the next call); ``retry_failed`` runs failed
    scenarios again.  ``progress`` shows a tqdm bar on stderr; ``on_start(to_run, done,
    out_dir)`` is called once the results already there have been read.  ``dashboard``
    serves a new local cluster's Dask dashboard at that address (``on_dashboard(link)``
    is told where); a scheduler given by address has its own.

    Raises :class:`~sweep.config.SweepError` (invalid sweep file),
    :class:`~sweep.results.ResultsError` (an unusable results.csv), :class:`ClusterError`
    and :class:`SweepInterrupted` (Ctrl-C; the finished rows are written first).
    """
    wall0 = time.perf_counter()
    if not isinstance(sweep, Sweep):
        sweep = load_sweep(sweep)
    out = Path(out_dir) if out_dir is not None else Path("out") / "sweeps" / sweep.name
    out = out.resolve()
    plan = plan_scenarios(sweep)
    by_id = {s.id: s for s in plan}
    notes = list(sweep.notes)

    store = ResultsStore(out)
    store.lock()
    try:
        return _sweep_locked(sweep, out, store, plan, by_id, notes, wall0, scheduler=scheduler, workers=workers,
                             client=client, progress=progress, limit=limit, retry_failed=retry_failed,
                             on_start=on_start, dashboard=dashboard,
                             on_dashboard=on_dashboard)
    finally:
        store.unlock()


def _sweep_locked(sweep: Sweep, out: Path, store: ResultsStore, plan, by_id, notes, wall0, *, scheduler, workers,
                  client, progress, limit, retry_failed, on_start, dashboard=None, on_dashboard=None) -> SweepResult:
    existing = store.load()
    kept: dict[str, dict] = {}
    stale: dict[str, list[dict]] = {}
    for row in existing:
        sid = row.get("scenario_id")
        if sid not in by_id:
            reason = "not in the sweep file"
        elif row.get("fmu_guid") != sweep.fmu_guid:
            reason = f"made with another FMU build (GUID {row.get('fmu_guid')})"
        elif retry_failed and row.get("status") != "ok":
            reason = "failed; retried (--retry-failed)"
        elif sid in kept:
            reason = "duplicate row"
        elif not _limit_ok(row, sweep, out):
            reason = f"report.latency_limit changed and the run's {EVALUATIONS} is gone"
        elif sweep.diagnose and row.get("status") == "ok" and row.get("alarms") and not row.get("diagnosis"):
            reason = "diagnose.enabled and the row has no diagnosis"
        else:
            row["index"] = by_id[sid].index
            kept[sid] = row
            continue
        stale.setdefault(reason, []).append(row)
    out.mkdir(parents=True, exist_ok=True)
    for reason, rows in stale.items():
        store.move_to_stale(rows, reason)
        notes.append(f"{len(rows)} row(s) moved to {store.stale_path.name}: {reason}")
    store.rewrite(sorted(kept.values(), key=lambda r: r["index"]))

    pending = [s for s in plan if s.id not in kept]
    if limit is not None:
        pending = pending[:max(0, int(limit))]
    write_sweep_record(SweepFolder(out).record, {
        **sweep.as_dict(), "scenarios": len(plan), "out_dir": str(out),
        "cluster": scheduler or ("client" if client is not None else f"LocalCluster({workers or default_workers()})"),
        "started_at": _now()})
    if on_start is not None:
        on_start(len(pending), len(kept), out)
    new_rows: list[dict] = []
    interrupted = False
    try:
        if pending:
            def snapshot() -> None:     # results.parquet while the sweep runs
                store.write_parquet(table_from_rows(sorted([*kept.values(), *new_rows], key=lambda r: r["index"])))

            if client is not None:
                _run_on(client, sweep, pending, out, store, new_rows, progress, snapshot)
            else:
                with open_client(scheduler, workers, dashboard=dashboard) as own:
                    if on_dashboard is not None and dashboard is not None:
                        on_dashboard(dashboard_link(own))
                    _run_on(own, sweep, pending, out, store, new_rows, progress, snapshot)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        store.close()
    rows = sorted([*kept.values(), *new_rows], key=lambda r: r["index"])
    result = _finish(sweep, out, store, rows, plan, skipped=len(kept), ran=len(new_rows), interrupted=interrupted,
                     wall0=wall0, notes=notes)
    if interrupted:
        raise SweepInterrupted(result)
    return result


def _persistence(sweep: Sweep) -> int:
    from monitor import MonitorOptions

    from .scenario import detector_persistence

    opts = sweep.monitor.options
    return detector_persistence(MonitorOptions(**{k: v for k, v in opts.items() if k in ("detector", "persistence")}))


def _limit_ok(row: dict, sweep: Sweep, out: Path) -> bool:
    """Make ``score_early`` of a stored row use the sweep's latency limit.

    It is the only result that depends on ``report.latency_limit`` (not part of the id): a
    row scored with another limit is scored again from its ``evaluations.csv``; False if
    that file is missing (the scenario is then run again)."""
    if row.get("status") != "ok" or row.get("latency_limit") == sweep.latency_limit:
        return True
    from .scenario import early_score

    path = SweepFolder(out).run(row["scenario_id"]).evaluations
    try:
        ev = read_evaluations(path)     # a ContractError is a ValueError
        row["score_early"] = early_score(ev.time, ev.statistic, ev.threshold, row.get("fault_time"),
                                         _persistence(sweep), sweep.latency_limit)
    except (OSError, ValueError):
        return False
    row["latency_limit"] = sweep.latency_limit
    return True


#: s of wall time between two rewrites of results.parquet while a sweep runs
PARQUET_INTERVAL = 30.0


def _run_on(client, sweep: Sweep, pending: list[Scenario], out: Path, store: ResultsStore,
            new_rows: list[dict], progress: bool, snapshot) -> None:
    from dask.distributed import as_completed
    from tqdm import tqdm

    folder = SweepFolder(out)
    options = dict(sweep.monitor.options)
    futures = {}
    for i, s in enumerate(pending):
        fut = client.submit(run_scenario, s, sweep.case, str(folder.run(s.id).root), options, fmu_guid=sweep.fmu_guid,
                            keep_exchange=sweep.keep_exchange, monitor_plots=sweep.monitor_plots,
                            latency_limit=sweep.latency_limit, diagnose=sweep.diagnose,
                            pure=False, priority=len(pending) - i, key=f"scenario-{s.id}-{os.urandom(4).hex()}")
        futures[fut] = s
    failed = 0
    last_snapshot = time.monotonic()
    bar = tqdm(total=len(pending), desc=sweep.name, unit="scenario", file=sys.stderr, dynamic_ncols=True,
               disable=not progress)
    try:
        for fut in as_completed(list(futures)):
            s = futures.pop(fut)
            try:
                row = fut.result()
            except Exception as exc:      # the worker died (KilledWorker), was cancelled, ...
                row = failed_row(s, f"worker: {type(exc).__name__}: {exc}", fmu_guid=sweep.fmu_guid)
            row["index"] = s.index
            new_rows.append(row)          # first: a Ctrl-C between the two still keeps the row
            store.append(row)
            if row["status"] != "ok":
                failed += 1
                bar.set_postfix(failed=failed, refresh=False)
            bar.update(1)
            fut.release()
            if time.monotonic() - last_snapshot > PARQUET_INTERVAL:
                snapshot()
                last_snapshot = time.monotonic()
    finally:
        bar.close()
        if futures:
            client.cancel(list(futures))


def _finish(sweep: Sweep, out: Path, store: ResultsStore, rows: list[dict], plan, *, skipped: int, ran: int,
            interrupted: bool, wall0: float, notes: list[str]) -> SweepResult:
    from .report import DetectorDesign, classification, plot_delay_arl0, plot_detection, plot_roc, summarize

    store.rewrite(rows)
    store.close()
    table = table_from_rows(rows)
    store.write_parquet(table)
    unit = sweep.monitor.unit
    design = DetectorDesign.from_options(sweep.monitor.options)
    summary = summarize(table, sweep.latency_limit, unit=unit, detector=design)
    files = {"csv": store.csv_path, "parquet": store.parquet_path}
    plots = out / "plots"
    plots.mkdir(exist_ok=True)
    title = (f"{sweep.name}: {', '.join(sweep.fault.names)} faults, {sweep.monitor.signal} monitored, "
             f"stop {sweep.stop:g} s")
    if summary["ok"]:
        files["detection_plot"] = plot_detection(summary, plots / "detection.png", title=title)
        files["roc_plot"] = plot_roc(table, plots / "roc.png", unit=unit, latency_limit=sweep.latency_limit,
                                     detector=design)
        files["delay_plot"] = plot_delay_arl0(table, plots / "delay_arl0.png", unit=unit, detector=design)
    if sweep.diagnose:
        summary["classification"] = classification(table)
    summary.update(name=sweep.name, planned=len(plan), skipped=skipped, ran=ran, interrupted=interrupted,
                   wall_seconds=time.perf_counter() - wall0, finished_at=_now())
    files["summary"] = SweepFolder(out).summary
    record = write_sweep_summary(files["summary"], summary)
    return SweepResult(sweep=sweep, out_dir=out, table=table, summary=summary, planned=len(plan), skipped=skipped,
                       ran=ran, interrupted=interrupted, wall_seconds=time.perf_counter() - wall0, files=files,
                       notes=tuple(notes), record=record)

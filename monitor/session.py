"""Sessions: :func:`replay` a finished exchange file, :func:`follow` a growing one.

Both feed the rows to a :class:`~monitor.stream.Monitor`, read ``run.json`` for the run's
identity, status and fault time, and end in a :class:`~monitor.summary.MonitorResult`.
Output files are created only once the input has been accepted (the first event or
evaluation, or the end of a session that produced a summary), so a rejected input leaves
nothing behind.

Which run a follower follows (``run.json``'s ``run_id``):
    * a run that is running when the follower starts;
    * otherwise the next run to start in that folder: a folder that holds an ended run is
      not replayed by ``follow`` (use :func:`replay`); the follower waits for a new run id.
    A run replaced by a newer one while being followed restarts the monitor on the new one.

A dead writer: while run.json says ``running``, the follower checks on each poll whether
the writing process (``writer.pid`` on ``writer.host``) still exists.  On the same host a
vanished writer ends the session at once with status ``run_lost``.  On another host the
silence timeout decides, where a newer heartbeat (``updated_at``) counts as progress.

The time grid: every batch of rows goes through a :class:`~monitor.grid.GridChecker` (run.json's
grid, else the file's dominant step) before the monitor; gaps longer than ``every`` are
skipped (:meth:`Monitor.skip`), a long gap in the training window leaves nothing to fit, and
problems reaching the training window make the verdict indeterminate
(:attr:`Summary.indeterminate`, exit 5 without an alarm).  A run.json that is not a run
record is refused (:class:`~monitor.errors.RunJsonError`).  An output write error removes the
partial outputs and is the result's ``output_error`` (exit 4); monitoring goes on.
"""
from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .detector import Event, State
from .errors import ExchangeFormatError, ExchangeMissingError, OutputWriteError, RunJsonError
from .grid import GridChecker, GridPiece, grid_of
from .options import FollowOptions, MonitorOptions, merged
from .outputs import OutputWriters
from .reader import ExchangeReader, RunInfo, exchange_file, read_run_info, regular_or_absent
from .stream import Monitor
from .summary import MonitorResult, Summary, Timing, before_fault, score_alarms

__all__ = ["follow", "replay", "warm_up"]

#: Grid problems said one by one (the rest are counted in summary.json's ``grid``).
GRID_WARNINGS = 20

EventCallback = Callable[[Event], None]
EvaluationCallback = Callable[[float, float, float, State], None]
MessageCallback = Callable[[str], None]


class _Session:
    """Shared plumbing of replay and follow: reader, monitor, output files, warnings."""

    def __init__(self, path: Path, options: MonitorOptions, out_dir: str | os.PathLike[str] | None,
                 on_event: EventCallback | None, on_evaluation: EvaluationCallback | None,
                 on_warning: MessageCallback | None):
        self.path = path
        self.options = options
        self.out_dir = None if out_dir is None else Path(out_dir)
        self.on_warning = on_warning
        self.warnings: list[str] = []
        self.started = time.perf_counter()
        self.read_seconds = 0.0
        self.reads_with_rows = 0
        self._writers: OutputWriters | None = None
        self._dropped = 0
        self._grid_warnings = 0
        #: why the outputs could not be written (None: they were)
        self.output_error: str | None = None

        def event_cb(e: Event) -> None:
            self._write(lambda w: w.event(e))
            if on_event is not None:
                on_event(e)

        def eval_cb(t: float, m: float, th: float, s: State) -> None:
            self._write(lambda w: w.evaluation(t, m, th, s))
            if on_evaluation is not None:
                on_evaluation(t, m, th, s)

        def samples_cb(t: np.ndarray, x: np.ndarray, f: np.ndarray) -> None:
            self._write(lambda w: w.forecast(t, x, f))

        self.monitor = Monitor(self.options, source=str(path), on_event=event_cb, on_evaluation=eval_cb,
                               on_samples=samples_cb)
        self.reader = ExchangeReader(path, list(self.options.signals))
        self.grid = GridChecker(str(path), None, watch_from=self.options.train[0])
        #: why nothing could be trained (a long gap in the training window); rows are then not fed
        self.untrainable: str | None = None

    def use_run(self, run: RunInfo | None) -> None:
        """Check the grid against ``run``'s (run.json's experiment); without one, the file's own step.
        Called before the first row of a run is read."""
        experiment = run.record.experiment if run is not None and run.record is not None else None
        self.grid = GridChecker(str(self.path), grid_of(experiment), watch_from=self.options.train[0])
        self.untrainable = None

    def _outputs(self) -> OutputWriters | None:
        """The output files, created at the first thing worth writing."""
        if self._writers is None and self.out_dir is not None and self.output_error is None:
            self._writers = OutputWriters(self.out_dir, self.options.signals, self.options.detector)
        return self._writers

    def _write(self, action: Callable[[OutputWriters], None]) -> None:
        """Write through the output files; a write error (disk full, read-only folder) removes
        the partial outputs, is remembered (exit 4) and said once; monitoring goes on."""
        try:
            writers = self._outputs()
            if writers is not None:
                action(writers)
        except OutputWriteError as exc:
            self._output_failed(exc)

    def _output_failed(self, exc: OutputWriteError) -> None:
        if self._writers is not None:
            self._writers.discard()
            self._writers = None
        elif self.out_dir is not None:
            OutputWriters.discard_in(self.out_dir)
        self.output_error = f"{exc}; the partial outputs in {self.out_dir} were removed"
        self.warnings.append(self.output_error)     # said once, as the error of the result (exit 4)

    def warn(self, message: str) -> None:
        self.warnings.append(message)
        if self.on_warning is not None:
            self.on_warning(message)

    def poll(self) -> tuple[int, bool, bool]:
        """One poll: feed new rows.  Returns (rows, progressed, missing)."""
        start = time.perf_counter()
        before = self.reader.offset
        batch = self.reader.poll()
        self.read_seconds += time.perf_counter() - start
        if batch.restarted:
            self.warn(f"{self.path}: the file was replaced or truncated; starting again from its beginning")
            self.restart()
        dropped = self.reader.stats.duplicate_time + self.reader.stats.decreasing_time - self._dropped
        self._dropped += dropped
        for issue in batch.issues:
            self.warn(issue.message)
            if issue.kind in ("duplicate_time", "decreasing_time") and dropped > 0:
                self.grid.duplicate(float(issue.value), 1, issue.message)
                dropped -= 1
        if dropped > 0:        # beyond the reader's examples: counted
            self.grid.duplicate(self.reader.last_time, dropped, f"{dropped} more duplicated or decreasing row(s)")
        if len(batch):
            self.reads_with_rows += 1
            self._feed(self.grid.split(batch.time, np.column_stack([batch.values[s] for s in self.options.signals])))
        progressed = batch.restarted or self.reader.offset != before
        return len(batch), progressed, batch.missing

    def _feed(self, pieces: list[GridPiece]) -> None:
        """Feed on-grid rows to the monitor, skipping long gaps (:mod:`monitor.grid`)."""
        for issue in self.grid.new_issues:
            self._grid_warnings += 1
            if self._grid_warnings <= GRID_WARNINGS:
                self.warn(issue.message)
            elif self._grid_warnings == GRID_WARNINGS + 1:
                self.warn(f"{self.path}: further time-grid problems are only counted (summary.json 'grid')")
        o = self.options
        for piece in pieces:
            gap = piece.gap_before
            if gap is not None and self.untrainable is None:
                long = gap.end - gap.start > max(o.every, 2.0 * self.grid.grid.step)
                if not self.monitor.trained and long and gap.end > o.train[0] and gap.start < o.train[1]:
                    self.untrainable = (f"{gap.message}, inside the training window {o.train[0]:g}–{o.train[1]:g} s: "
                                        "no model fitted, nothing monitored")
                    self.warn(self.untrainable)
                elif long:
                    self.monitor.skip(gap.start, gap.end)
                    self.grid.stats.skipped_gaps += 1
            if self.untrainable is None:
                self.monitor.feed(piece.time, piece.values)

    def end_of_data(self, run: RunInfo | None) -> None:
        """The data ended: release the rows held to learn the grid; rows run.json records after
        the file's last are missing."""
        self._feed(self.grid.flush())
        if run is not None and run.ended and run.last_time is not None:
            self.grid.missing_after(run.last_time)
            self._feed([])

    def indeterminate(self) -> str | None:
        """Why no verdict can be given on the data (None: the grid was whole where it mattered)."""
        if self.untrainable is not None:
            return self.untrainable
        g = self.grid.stats
        if not g.watched:
            return None
        counts = [f"{n} {what}" for n, what in ((g.missing_rows, "missing"), (g.off_grid_rows, "off the grid"),
                                               (g.duplicate_rows, "duplicated")) if n]
        return (f"the time grid is broken in the training or monitored window ({', '.join(counts)} row(s); "
                f"first: {g.first_watched.message})")

    def restart(self) -> None:
        self.monitor.reset()
        self.grid.reset()
        self.untrainable = None
        self._dropped = 0
        if self._writers is not None:
            self._write(lambda w: w.restart())

    def drain(self) -> tuple[bool, bool]:
        """Read everything available now; returns (anything read, file missing)."""
        any_progress = False
        while True:
            _, progressed, missing = self.poll()
            if missing or not progressed:
                return any_progress, missing
            any_progress = True

    def close(self) -> None:
        self.reader.close()
        if self._writers is not None:
            try:
                self._writers.close()
            except OutputWriteError as exc:
                self._output_failed(exc)

    def reject_empty(self, run: RunInfo | None) -> None:
        """Raise if the file gave no usable row; a failed run's own error is part of the message."""
        try:
            self.reader.check_finished()
        except ExchangeFormatError as exc:
            if run is not None and run.status == "failed":
                raise ExchangeFormatError(f"{exc}; the run failed: {run.error or 'no message in run.json'}") from None
            raise

    def summary(self, status: str, run: RunInfo | None, error: str | None) -> Summary:
        mon = self.monitor
        total = time.perf_counter() - self.started
        alarms = tuple(e for e in mon.events if e.kind == "alarm")
        fault = run.fault_time if run is not None else None
        ev = mon.evaluations.array()
        pre = ev[before_fault(ev[:, 0], fault), 1] if len(ev) else np.empty(0)
        span = None
        if mon.first_time is not None and mon.last_time is not None:
            span = mon.last_time - mon.first_time
        timing = Timing(train=mon.timing["train"], forecast=mon.timing["forecast"],
                        evaluate=mon.timing["evaluate"], read=self.read_seconds, total=total,
                        per_evaluation=(mon.timing["evaluate"] / mon.n_evaluations) if mon.n_evaluations else None,
                        simulated_span=span, realtime_factor=(span / total) if span is not None and total > 0 else None)
        return Summary(
            status=status, error=error, exchange=self.path,
            case=(run.case if run is not None and run.case else self.path.name), options=self.options,
            rows=self.reader.stats, reads_with_rows=self.reads_with_rows, restarts=mon.restarts,
            samples=mon.n_samples, last_time=mon.last_time, fits=tuple(mon.fits), refits=mon.refits,
            final_state=mon.state, evaluations=mon.n_evaluations,
            max_statistic_over_threshold=mon.max_ratio if mon.n_evaluations else None,
            max_statistic_before_fault=float(pre.max()) if pre.size else None,
            alarm_events=alarms, score=score_alarms([e.time for e in alarms], fault) if run is not None else None,
            run=run, timing=timing, warnings=len(self.warnings), grid=self.grid.stats,
            indeterminate=self.indeterminate())

    def result(self, status: str, run: RunInfo | None, error: str | None = None,
               plots: bool = True) -> MonitorResult:
        mon = self.monitor
        result = MonitorResult(self.path, self.summary(status, run, error), [e.as_dict() for e in mon.events],
                               mon.evaluation_frame(), mon.history_frame(), list(self.warnings))
        self._write(lambda w: w.finish(result, plots=plots))
        if self._writers is not None:
            try:
                self._writers.close()
            except OutputWriteError as exc:
                self._output_failed(exc)
        result.output_error = self.output_error
        return result


def warm_up(model: str) -> None:
    """Import the heavy libraries the monitor will need (so a live monitor reacts at once)."""
    import pandas  # noqa: F401
    import scipy.optimize  # noqa: F401
    import sklearn.metrics  # noqa: F401

    from .forecasters import forecaster_class

    forecaster_class(model).warm_up()


#: The signal of a run that names none yet: an exchange file followed before it (and its run.json)
#: exists.  The four-bar's first output, kept so that case behaves as it always did.
FALLBACK_SIGNAL = "x2"


def run_signal(path: Path, run: RunInfo | None) -> str | None:
    """The run's default signal: the exchange file's first column after ``time``, else run.json's
    first recorded output (None: neither is known yet).  x2 for the four-bar."""
    if path.is_file():
        reader = ExchangeReader(path)
        try:
            reader.poll()
        finally:
            reader.close()
        if reader.columns:
            return reader.columns[0]
    if run is not None and run.record is not None and run.record.outputs:
        return run.record.outputs[0]
    return None


def with_run_signal(options: MonitorOptions, path: Path, run: RunInfo | None = None) -> MonitorOptions:
    """``options`` with the run's default signal when they name none (``signal=""``)."""
    if options.signal:
        return options
    if run is None and not path.is_file():
        run = _checked_run_info(path)
    return merged(options, {"signal": run_signal(path, run) or FALLBACK_SIGNAL})


def _checked_run_info(path: Path) -> RunInfo | None:
    """run.json beside ``path`` (None: there is none); one that is not a run record is refused."""
    run = read_run_info(path)
    if run is not None and run.record is None:
        raise RunJsonError(f"{run.error}; a run folder's run.json must be the record fourbar-run writes "
                           "(remove it to monitor the exchange file alone)")
    return run


def _lost_message(run: RunInfo) -> str:
    return (f"{run.path}: the run was cut off: its writer (pid {run.writer_pid} on {run.writer_host}) is gone "
            f"but run.json still says 'running' (last update {run.updated_at}, last row t = {run.last_time} s)")


def replay(exchange_path: str | os.PathLike[str], *, options: MonitorOptions | None = None,
           out_dir: str | os.PathLike[str] | None = None, plots: bool = True,
           on_event: EventCallback | None = None, on_evaluation: EvaluationCallback | None = None,
           on_warning: MessageCallback | None = None, **settings: Any) -> MonitorResult:
    """Monitor a finished exchange file; return a :class:`MonitorResult` (prints nothing).

    ``settings`` are :class:`MonitorOptions` fields (``signal="x2"``, ``model="harmonic"``,
    ``threshold=0.01``, ``train=(0, 9)``, ...), applied over ``options``.  With ``out_dir``
    the files ``events.jsonl``, ``evaluations.csv``, ``summary.json`` and (``plots``) the
    PNG figures are written there once the input is accepted; without it nothing is written.

    Raises :class:`~monitor.errors.ExchangeMissingError`,
    :class:`~monitor.errors.ExchangeFormatError` (empty, header only, missing column, no
    valid row), :class:`~monitor.errors.TrainingError` (data ends before the training
    window, constant signal) and :class:`~monitor.errors.OptionError`.
    """
    opts = merged(options or MonitorOptions(), settings)
    path = exchange_file(exchange_path)
    if not path.exists():
        raise ExchangeMissingError(f"{path}: exchange file not found (use --follow to wait for it)")
    run = _checked_run_info(path)
    opts = with_run_signal(opts, path, run)
    session = _Session(path, opts, out_dir, on_event, on_evaluation, on_warning)
    session.use_run(run)
    try:
        lost = run is not None and run.status == "running" and run.writer_alive() is False
        if lost:
            session.warn(_lost_message(run))
        elif run is not None and run.status == "running":
            session.warn(f"{run.path}: the run is still running; replaying the rows written so far "
                         "(use --follow to follow it)")
        if session.drain()[1]:
            raise ExchangeMissingError(f"{path}: the exchange file disappeared while being read")
        session.reject_empty(run)
        session.end_of_data(run)
        note = session.reader.skip_summary()
        if note:
            session.warn(note)
        status, error = "finished", None
        if run is not None and run.status == "failed":
            status, error = "run_failed", f"the run failed: {run.error or 'no message in run.json'}"
            session.warn(f"{run.path}: {error}")
        elif lost:
            status, error = "run_lost", "the run was cut off (its writer is gone)"
        if session.untrainable is not None:
            pass                                # said already; the verdict is indeterminate
        elif status == "finished" or session.monitor.trained:
            session.monitor.finish()
        else:
            session.warn(f"{path}: the run ended ({status}) before the training window was complete; "
                         "nothing monitored")
        return session.result(status, run, error, plots=plots)
    finally:
        session.close()


def follow(exchange_path: str | os.PathLike[str], *, options: MonitorOptions | None = None,
           out_dir: str | os.PathLike[str] | None = None, plots: bool = True, poll: float = 0.2,
           timeout: float = 60.0, on_event: EventCallback | None = None,
           on_evaluation: EvaluationCallback | None = None, on_warning: MessageCallback | None = None,
           on_wait: MessageCallback | None = None, sleep: Callable[[float], None] = time.sleep,
           **settings: Any) -> MonitorResult:
    """Follow the run writing an exchange file until it ends; return a :class:`MonitorResult`.

    Which run is followed, and how a dead writer is noticed: see the module docstring.
    Reads new complete rows every ``poll`` s and stops when run.json says the run
    ``finished``, ``failed`` or was ``interrupted`` (after reading every row), when its
    writer is gone (status ``run_lost``), or when neither a row nor a heartbeat came for
    ``timeout`` s (``timeout=0``: wait for ever).  Ctrl-C ends it with status
    ``interrupted`` (the outputs are still written).  ``on_wait`` receives what the
    follower waits for and which run it follows.
    """
    opts = merged(options or MonitorOptions(), settings)
    fopts = merged(FollowOptions(), {"poll": poll, "timeout": timeout})
    path = exchange_file(exchange_path, later=True)
    regular_or_absent(path)
    say = on_wait or (lambda message: None)
    opts = with_run_signal(opts, path)
    warm_up(opts.model)
    session = _Session(path, opts, out_dir, on_event, on_evaluation, on_warning)
    initial = _checked_run_info(path)
    skip = initial.identity if initial is not None and initial.status != "running" else None
    if skip is not None:
        say(f"{path.parent} holds {initial.describe()}, which has ended ({initial.status}); waiting for the next "
            "run (replay the ended one without --follow)")
    following: RunInfo | None = None
    last_progress = time.monotonic()
    heartbeat = None
    waiting_said = False
    run: RunInfo | None = None
    status, error = "finished", None
    try:
        try:
            while True:
                run = _checked_run_info(path)      # read before the rows: rows precede the status
                if run is not None and skip is not None and run.identity == skip:
                    run = None                     # still the old, ended run: do not read its rows
                else:
                    if run is not None and run.identity and following is not None \
                            and run.identity != following.identity:
                        session.warn(f"{following.describe()} was replaced by {run.describe()}; following the new run")
                        session.restart()
                        session.reader.close()
                        session.reader = ExchangeReader(path, list(opts.signals))
                    if run is not None and (following is None or run.identity != following.identity):
                        if session.reader.offset == 0:
                            session.use_run(run)
                        following = run
                        say(f"following {run.describe()}")
                    if session.drain()[0]:
                        last_progress = time.monotonic()
                if run is not None and run.updated_at != heartbeat:
                    heartbeat = run.updated_at
                    last_progress = time.monotonic()
                missing = session.reader.header is None and not path.exists()
                if (missing or (skip is not None and following is None)) and not waiting_said:
                    say(f"waiting for {'a new run in ' + str(path.parent) if skip else str(path) + ' to appear'}")
                    waiting_said = True
                if run is not None and not missing:
                    if run.ended:
                        session.drain()
                        if run.status == "failed":
                            status, error = "run_failed", f"the run failed: {run.error or 'no message in run.json'}"
                            session.warn(f"{run.path}: {error}")
                        elif run.status == "interrupted":
                            status = "run_interrupted"
                            session.warn(f"{run.path}: the run was interrupted; stopping")
                        break
                    if run.status == "running" and run.writer_alive() is False:
                        again = _checked_run_info(path)  # it may have ended just before exiting
                        if again is not None and again.identity == run.identity and again.status == "running":
                            session.drain()
                            status, error = "run_lost", "the run was cut off (its writer is gone)"
                            session.warn(_lost_message(again))
                            run = again
                            break
                        continue
                idle = time.monotonic() - last_progress
                if fopts.timeout and idle > fopts.timeout:
                    if skip is not None and following is None:
                        raise ExchangeMissingError(f"{path.parent}: no new run started within {fopts.timeout:g} s "
                                                   f"(--timeout); it holds {initial.describe()}, which has ended: "
                                                   "replay it without --follow")
                    if session.reader.header is None and not path.exists():
                        raise ExchangeMissingError(f"{path}: the exchange file did not appear within "
                                                   f"{fopts.timeout:g} s (--timeout)")
                    if session.reader.header is None:
                        raise ExchangeFormatError(f"{path}: no complete header line within {fopts.timeout:g} s")
                    status = "timeout"
                    session.warn(f"{path}: no new rows for {fopts.timeout:g} s and run.json does not say the run "
                                 "ended; stopping (--timeout 0 waits for ever)")
                    break
                sleep(fopts.poll)
        except KeyboardInterrupt:
            status = "interrupted"
        note = session.reader.skip_summary()
        if note:
            session.warn(note)
        if session.reader.header is not None:
            session.end_of_data(run)
        if status in ("finished", "timeout"):
            session.reject_empty(run)
            if session.untrainable is None:
                session.monitor.finish()
        elif not session.monitor.trained:
            what = "monitoring was interrupted" if status == "interrupted" else f"the run ended ({status})"
            session.warn(f"{path}: {what} before the training window was complete; nothing monitored")
        return session.result(status, run, error, plots=plots)
    finally:
        session.close()


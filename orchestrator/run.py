"""The co-simulation loop: one case, one FMU instance, one exchange file.

Loop (communication points ``t_k = start + k*step``, ``k = 0 .. n``; integer count)::

    read the outputs at t_k               -> row k (the state before any change at t_k)
    every flush interval: append rows     -> exchange.csv (real-time: once t_k is due)
    set the events due at t_k             (steps at their time, ramp values at each point)
    fmi2DoStep(t_k, t_{k+1} - t_k)

So with L2 set at 10 s, the row at 10.00 s still shows the old geometry and the row at
10.01 s the new one (docs/contracts.md, "The FMUs").  The step passed to the FMU is
``t_{k+1} - t_k`` rather than ``step``: it makes the FMU end each step exactly on the grid
(as ``fmpy.simulate_fmu`` does), instead of drifting by round-off.

Order.  The FMU is instantiated and initialised (experiment set up, start values set,
initialisation mode entered and left) *before* anything is written: an FMU that refuses
the case's start values raises :class:`StartValuesRefused` (a :class:`ConfigError`) and
the output folder is left exactly as it was, a previous run's files included.  Only then
does the run start: it creates exchange.csv empty, removes the previous run's derived
outputs (``monitor/`` and ``diagnosis/``, see :func:`remove_derived_outputs`) and writes
run.json.

run.json is written when the run starts (``running``, after exchange.csv was created
empty, so a reader that sees the new ``run_id`` reads the new file), after flushes (at
most every 0.2 s of wall time), by a heartbeat every ``HEARTBEAT_INTERVAL`` s of wall time
whatever the loop does (``updated_at``; ``writer`` names the process and host), and at the
end (``finished``, ``failed`` or ``interrupted``, with the reason).  Rows already appended
stay whatever happens; the FMU instance is freed unless a thread is still inside it.  Ctrl-C
and SIGTERM stop the loop at the next step (:mod:`orchestrator.pacing`); the initialisation
and the loop run in a worker thread (:mod:`orchestrator.stepping`), so a step that never
returns is abandoned 0.5 s after the signal (``RunResult.abandoned``).

One writer per folder.  Before anything in the folder changes, the run takes the folder's
lock (:class:`fourbar_common.folder_lock.FolderLock`) and opens exchange.csv without
following a symbolic link; either refused raises :class:`OutputRefused` with the folder as
it was.  The run sets :data:`RESERVE_BYTES` aside for its last run.json (a full disk still
ends ``failed``), and at the end checks that exchange.csv at the path is the file it wrote
with every row (:meth:`~orchestrator.exchange.ExchangeWriter.verify`); if not, ``failed``.
"""
from __future__ import annotations

import os
import shutil
import signal
import socket
import sys
import threading
import time
import uuid
from dataclasses import dataclass, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Mapping

from fourbar_common.contract.exchange import TIME_COLUMN
from fourbar_common.contract.layout import DIAGNOSIS, DIAGNOSIS_FOLDER, MONITOR_FOLDER, SUMMARY, RunFolder
from fourbar_common.contract.run_record import (SCHEMA_VERSION, ParameterStart, RecordedExchange, RecordedExperiment,
                                               RecordedFmu, RecordedInput, RecordedNoise, RecordedWriter, RunRecord,
                                               write_run_record)
from fourbar_common.contract.system_record import RecordedComponent, RecordedConnection, RecordedSystem

from .case import Case, RampEvent, StepEvent, Value
from .config import apply_overrides, load_case
from .exchange import ExchangeWriter, format_row
from fourbar_common.formatting import format_time
from fourbar_common.signals import signal_of, stop_reason

from .pacing import InterruptFlag, RealtimePacer
from .validation import ConfigError

__all__ = ["DERIVED_OUTPUTS", "HEARTBEAT_INTERVAL", "RESERVE_BYTES", "OutputRefused", "RunInterrupted", "RunResult", "StartValuesRefused",
           "remove_derived_outputs", "run_case", "SCHEMA_VERSION"]

_RUN_JSON_MIN_INTERVAL = 0.2   # s of wall time between two "running" updates of run.json
#: s of wall time: while the writer lives, run.json's ``updated_at`` is never older than this (plus a write).
HEARTBEAT_INTERVAL = 2.0
#: Folders of a run folder that tools derive from its exchange.csv, each with the file that
#: marks it as theirs: a new run removes them when it starts (they describe the old rows).
DERIVED_OUTPUTS = ((MONITOR_FOLDER, SUMMARY), (DIAGNOSIS_FOLDER, DIAGNOSIS))
#: Bytes set aside in the run folder when the run starts (``.run.json.reserve``) and given
#: back to write the final run.json when the disk filled up: run.json then says ``failed``
#: with the error instead of staying ``running``.  A run.json of the shipped cases is 4-8 kB;
#: the final write needs a temporary copy beside the old one.
RESERVE_BYTES = 64 * 1024
_RESERVE_NAME = ".run.json.reserve"


@dataclass(frozen=True)
class RunResult:
    """What a run produced.  ``status`` is ``finished``, ``failed`` or ``interrupted``."""

    case: Case
    status: str
    out_dir: Path
    exchange_path: Path
    run_json_path: Path
    rows_written: int            # data rows in exchange.csv (header not counted)
    last_time: float | None      # time of the last row written, s
    wall_time_s: float           # the whole run_case call, FMU loading included
    sim_wall_time_s: float | None  # from reading the first row to writing the last one
    error: str | None = None
    #: The run started: exchange.csv and run.json were (re)created.  False when it failed or
    #: was stopped while the FMU was loaded and initialised: then nothing was written.
    started: bool = True
    #: The previous run's derived folders removed when this run started (e.g. ("monitor",)).
    replaced: tuple[str, ...] = ()
    #: A stop signal came while the FMU did not return from a call: its thread was left
    #: inside the FMU, which was not freed.  The process should exit at once (the CLI does).
    abandoned: bool = False

    @property
    def ok(self) -> bool:
        return self.status == "finished"


class RunInterrupted(KeyboardInterrupt):
    """Ctrl-C or SIGTERM stopped a run; run.json says ``interrupted`` (when the run had
    started); ``result`` describes what was kept, ``signum`` is the signal."""

    def __init__(self, result: RunResult, signum: int = signal.SIGINT):
        super().__init__(result.error)
        self.result = result
        self.signum = int(signum)


class OutputRefused(Exception):
    """The output folder cannot take this run, found before anything was changed in it:
    another writer holds its lock (``holder`` names it), or exchange.csv is a symbolic link
    or not a regular file.  The CLI exits 2."""

    def __init__(self, message: str, holder=None):
        super().__init__(message)
        self.holder = holder


class StartValuesRefused(ConfigError):
    """The FMU refused the case's set-up (experiment, start values) before the first row.

    A case error that only the FMU could find (e.g. a String value its model description
    cannot restrict, or a length that makes its arithmetic overflow).  Raised before
    anything is written.  ``problems`` has one line: the FMI call, its status and the FMU's
    message, then which of the case's start values differ from the FMU's own.
    """


def run_case(case: Case | str | Path, out_dir: str | Path | None = None, *, stop: float | None = None,
             realtime: float | None = None, overrides: Mapping[str, Value] | None = None,
             progress: bool = False, fmu: str | Path | None = None, max_rows: int | None = None) -> RunResult:
    """Run ``case`` (a :class:`Case` or a case-file path) and write ``out_dir``.

    ``out_dir`` defaults to ``out/<case name>`` (relative to the working directory).
    ``stop`` (s), ``realtime`` (factor), ``overrides`` (parameter start values), ``fmu``
    (another FMU with the case's variables, e.g. build/FourBarNative.fmu) and ``max_rows``
    replace the case's values; the result is validated again (:class:`~orchestrator.ConfigError`).
    ``progress`` shows a tqdm bar on stderr.

    Start values the FMU refuses raise :class:`StartValuesRefused` (a ``ConfigError``)
    before anything is written.  A failure of the FMU or of writing returns a result with
    status ``failed`` and the reason in ``error`` (also in run.json once the run started;
    ``started`` says whether it did).  Ctrl-C or SIGTERM records ``interrupted`` in run.json
    and raises :class:`RunInterrupted` (a ``KeyboardInterrupt``).
    """
    wall0 = time.monotonic()
    if isinstance(case, Case):
        case = apply_overrides(case, overrides=overrides, stop=stop, realtime=realtime, fmu=fmu, max_rows=max_rows,
                               out_dir_given=out_dir is not None)
    else:
        case = load_case(case, overrides=overrides, stop=stop, realtime=realtime, fmu=fmu, max_rows=max_rows,
                         out_dir_given=out_dir is not None)
    out = Path(out_dir) if out_dir is not None else Path("out") / case.name
    return _Run(case, out, progress, wall0).execute()


def remove_derived_outputs(out_dir: Path) -> tuple[str, ...]:
    """Remove the previous run's derived folders (:data:`DERIVED_OUTPUTS`) from ``out_dir``.

    Only a folder that holds its tool's marker file, in a folder that holds a run.json, is
    removed: ``--out`` pointed at a folder of something else (a source tree has a
    ``monitor/`` package) loses nothing.  Returns the names removed.
    """
    if not RunFolder(out_dir).run_record.is_file():
        return ()
    removed = []
    for name, marker in DERIVED_OUTPUTS:
        folder = out_dir / name
        if folder.is_dir() and not folder.is_symlink() and (folder / marker).is_file():
            shutil.rmtree(folder)
            removed.append(name)
    return tuple(removed)


def _same_value(value: Value, start: str | None) -> bool:
    """``value`` equals a model description's ``start`` attribute (text; None when absent)."""
    if start is None:
        return False
    if isinstance(value, bool):
        return str(start).lower() == str(value).lower()
    if isinstance(value, (int, float)):
        try:
            return float(start) == float(value)
        except (TypeError, ValueError):
            return False
    return str(start) == str(value)


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def _schedule(case: Case) -> tuple[dict[int, list[tuple[str, Value]]], list[tuple[int, int, StepEvent | RampEvent]]]:
    """The step events by grid index (the (variable, value) pairs to set after reading that
    row), and every event in the case's order as (first index, last index, event).  With a
    ramp the loop computes its values at each point as it reaches it (:func:`_actions`): a
    ramp over ten million points would otherwise hold ten million entries."""
    exp = case.experiment
    steps: dict[int, list[tuple[str, Value]]] = {}
    timed: list[tuple[int, int, StepEvent | RampEvent]] = []
    for event in case.events:
        if isinstance(event, StepEvent):
            k = exp.index(event.time)
            steps.setdefault(k, []).append((event.variable, event.value))
            timed.append((k, k, event))
        elif isinstance(event, RampEvent):
            timed.append((exp.index(event.start), exp.index(event.end), event))
    return steps, timed


def _actions(k: int, timed: list[tuple[int, int, StepEvent | RampEvent]], n: int) -> list[tuple[str, Value]]:
    """The (variable, value) pairs to set after reading row ``k``, in the case's event order."""
    actions = []
    for k0, k1, event in timed:
        if k0 <= k <= min(k1, n):
            if isinstance(event, StepEvent):
                actions.append((event.variable, event.value))
            else:
                actions.append((event.variable, event.value_at((k - k0) / (k1 - k0))))
    return actions


def _parameter_starts(case: Case) -> tuple[ParameterStart, ...]:
    """The start value of every parameter of the case's FMU, with its source (run.json)."""
    starts = []
    for default in case.fmu_description.parameter_starts():
        if default.name in case.parameters:
            source = "set" if default.name in case.overridden else "case"
            starts.append(replace(default, start=case.parameters[default.name], source=source))
        else:
            starts.append(default)
    return tuple(starts)


def _system_record(case: Case, parameters: tuple[ParameterStart, ...]) -> RecordedSystem:
    """run.json's ``system``: the archive, the master, each component's FMU and effective parameters."""
    from .system_order import step_order

    described = case.fmu_description
    ssp = described.ssp
    effective: dict[str, dict] = {}
    for p in parameters:
        component, _, variable = p.name.partition(".")
        effective.setdefault(component, {})[variable] = p.start
    for bound in ssp.parameters:     # a binding may set an (unconnected) input's start value too
        if bound.name not in case.parameters:
            kind = described.variables[bound.name].type
            effective.setdefault(bound.component, {})[bound.variable] = _bound_value(kind, bound.value)
    for name, value in case.parameters.items():
        component, _, variable = name.partition(".")
        effective.setdefault(component, {})[variable] = value
    components = tuple(
        RecordedComponent(name=c.name, source=c.source, sha256=c.sha256,
                          model_identifier=c.model.coSimulation.modelIdentifier, model_name=c.model.modelName,
                          fmi_version=c.fmi_version, guid=c.model.guid, parameters=effective.get(c.name, {}))
        for c in described.components)
    master = case.master
    order = step_order(described, master)
    return RecordedSystem(path=str(case.system), sha256=ssp.sha256, name=ssp.name, algorithm=master.algorithm,
                          inputs=master.inputs, step=case.experiment.step, order=tuple(order), components=components,
                          connections=tuple(RecordedConnection(c.source, c.target) for c in ssp.connections),
                          drawing=described.drawn_component if case.drawing is not None else None)


def _bound_value(kind: str, value: Value) -> Value:
    """An SSP binding's value as the variable's type (a Real bound as an Integer is a float)."""
    return float(value) if kind == "Real" else value


class _Run:
    def __init__(self, case: Case, out_dir: Path, progress: bool, wall0: float):
        self.case = case
        self.started = False                    # exchange.csv/run.json of this run (re)created
        self.replaced: tuple[str, ...] = ()
        self.out_dir = out_dir
        self.exchange_path = RunFolder(out_dir).exchange
        self.run_json_path = RunFolder(out_dir).run_record
        self.progress = progress
        self.wall0 = wall0
        self.status = "running"
        self.error: str | None = None
        self.rows_written = 0
        self.last_time: float | None = None
        self.loop_wall0: float | None = None
        self.loop_wall1: float | None = None
        self.last_json_write = -1e300
        self.writer: ExchangeWriter | None = None
        self.bar = None
        self.pending_t: list[float] = []
        self.pending_v: list[list] = []
        self.noise = None
        self.pacer: RealtimePacer | None = None
        self._record_lock = threading.Lock()
        self._heartbeat_stop = threading.Event()
        self._heartbeat: threading.Thread | None = None
        self._io_lock = threading.Lock()        # the worker's rows and appends vs. a take-over
        self._worker_gone = False               # taken over: the worker must not touch rows or file
        self._io_safe = True                    # the take-over found no append in progress
        self.abandoned = False                  # the worker was left inside the FMU
        self.lock = None                        # the folder's FolderLock while the run holds it
        self.reserve: Path | None = None        # the space set aside for the final run.json
        self.record = self._record()

    # -- run.json ---------------------------------------------------------------------
    def _record(self) -> RunRecord:
        case = self.case
        described = case.fmu_description      # set by the validation run_case just did
        md = described.model
        exp, exchange = case.experiment, case.exchange
        parameters = _parameter_starts(case)
        return RunRecord(
            status="running", run_id=uuid.uuid4().hex, case=case.name,
            case_file=str(case.source) if case.source is not None else None,
            description=case.description,
            fmu=RecordedFmu(path=str(case.fmu), guid=md.guid, model_name=md.modelName, fmi_type=case.fmi_type),
            experiment=RecordedExperiment(start=exp.start, stop=exp.stop, step=exp.step, tolerance=exp.tolerance),
            parameters=parameters,
            events=tuple(case.events),
            fault_time=case.fault_time,
            outputs=tuple(case.columns),
            units=described.units(case.columns),
            inputs=tuple(RecordedInput(name=name, signal=signal.as_dict()) for name, signal in case.inputs.items()),
            input_derivatives=case.input_derivative_order,
            drawing=case.drawing,
            noise=RecordedNoise(seed=case.noise.seed, std=dict(case.noise.std)) if case.noise is not None else None,
            exchange=RecordedExchange(flush_interval=exchange.flush_interval,
                                      realtime_factor=exchange.realtime_factor, max_rows=exchange.max_rows),
            rows_written=0, last_time=None, started_at=_now(), updated_at=None, finished_at=None,
            wall_time_s=0.0, error=None,
            writer=RecordedWriter(pid=os.getpid(), host=socket.gethostname(), heartbeat_s=HEARTBEAT_INTERVAL),
            system=_system_record(case, parameters) if case.system is not None else None,
        )

    def _write_record(self, final: bool = False) -> None:
        with self._record_lock:
            now = time.monotonic()
            updated = _now()
            record = replace(self.record, status=self.status, rows_written=self.rows_written,
                             last_time=self.last_time, updated_at=updated, wall_time_s=round(now - self.wall0, 6),
                             error=self.error, finished_at=updated if final else self.record.finished_at)
            write_run_record(self.run_json_path, record)
            self.record = record          # the last run.json written
            self.last_json_write = now

    def _start_heartbeat(self) -> None:
        """Rewrite run.json whenever ``HEARTBEAT_INTERVAL`` s passed without a write (a thread:
        it beats through long real-time waits and slow FMU steps alike)."""
        def beat() -> None:
            while not self._heartbeat_stop.wait(HEARTBEAT_INTERVAL / 4):
                if time.monotonic() - self.last_json_write >= HEARTBEAT_INTERVAL:
                    try:
                        self._write_record()
                    except OSError:      # the main thread reports write failures
                        pass

        self._heartbeat = threading.Thread(target=beat, name="run.json heartbeat", daemon=True)
        self._heartbeat.start()

    def _stop_heartbeat(self) -> None:
        if self._heartbeat is not None:
            self._heartbeat_stop.set()
            self._heartbeat.join()
            self._heartbeat = None

    # -- rows -------------------------------------------------------------------------
    def _flush(self, wait: bool = True) -> None:
        if not self.pending_t:
            return
        if wait and self.pacer is not None:
            self.pacer.wait_until(self.pending_t[-1])
        values = self.pending_v
        if self.noise is not None:
            values = self.noise.apply(values)
        lines = [format_row((t, *v)) for t, v in zip(self.pending_t, values)]
        self.writer.append(lines)
        self.rows_written += len(lines)
        self.last_time = self.pending_t[-1]
        self.pending_t, self.pending_v = [], []
        self.loop_wall1 = time.monotonic()
        if self.bar is not None:
            self.bar.update(len(lines))
        if self.loop_wall1 - self.last_json_write >= _RUN_JSON_MIN_INTERVAL:
            self._write_record()

    # -- the run ----------------------------------------------------------------------
    def execute(self) -> RunResult:
        from .instance import FmuError, instance_for

        stopped_by: int | None = None      # the signal that stopped the run
        note = ""
        try:
            with InterruptFlag() as flag:
                try:
                    with self._instance(instance_for) as fmu:
                        self._initialize_in_worker(fmu, flag)   # refused: StartValuesRefused, nothing written
                        flag.check()               # a signal while the FMU loaded: nothing written
                        self._start_outputs()
                        self._loop(fmu, flag)
                    self.status = "finished"
                except FmuError as exc:
                    note = self._after_failure()
                    if flag.requested:
                        stopped_by = flag.signum
                    else:
                        self.status, self.error = "failed", str(exc) + note
                except KeyboardInterrupt as exc:
                    note = self._after_failure()
                    stopped_by = flag.signum or signal_of(exc)
                except OSError as exc:
                    self.status, self.error = "failed", f"{type(exc).__name__}: {exc}"
                if stopped_by is not None:
                    self.status, self.error = "interrupted", self._stop_message(stopped_by) + note
        except (ConfigError, OutputRefused):   # start values or folder refused: nothing was written
            self._finish()
            raise
        except KeyboardInterrupt as exc:   # a second signal while keeping the rows
            stopped_by = stopped_by or signal_of(exc)
            self.status, self.error = "interrupted", self._stop_message(stopped_by)
            self._finish()
            raise RunInterrupted(self._result(), stopped_by) from None
        except BaseException as exc:   # a bug: record it, then let the traceback through
            self.status, self.error = "failed", f"internal error: {type(exc).__name__}: {exc}"
            self._finish()
            raise
        self._finish()
        result = self._result()
        if stopped_by is not None:
            raise RunInterrupted(result, stopped_by)
        return result

    def _instance(self, instance_for):
        """The FMU instance, or the :class:`~orchestrator.system.SystemInstance` of a system case."""
        if self.case.system is not None:
            if self.case.master.algorithm == "monolithic":
                from .monolithic import MonolithicSystem

                return MonolithicSystem(self.case.fmu_description, self.case.master, self.case.name)
            from .system import SystemInstance

            return SystemInstance(self.case.fmu_description, self.case.master, self.case.name)
        return instance_for(self.case.fmu_description, self.case.name, fmi_type=self.case.fmi_type)

    def _stop_message(self, signum: int) -> str:
        """'interrupted by Ctrl-C at t = 12.3 s', 'terminated by SIGTERM before the run started', ..."""
        if not self.started:
            return f"{stop_reason(signum)} before the run started"
        where = f" at t = {format_time(self.last_time)} s" if self.last_time is not None else ""
        if self.abandoned:
            from .stepping import GRACE

            where += (f"; the FMU had not returned from its call {GRACE:g} s after the signal, so the run "
                      f"ended without it")
        return f"{stop_reason(signum)}{where}"

    def _initialize_in_worker(self, fmu, flag: InterruptFlag) -> None:
        """:meth:`_initialize` in a worker thread, as the loop (an FMU may also hang in its
        initialisation); abandoned after a signal like a stuck step, before anything was written."""
        from .stepping import run_in_worker

        def take_over() -> None:
            self.abandoned = True
            fmu.abandon()

        run_in_worker(lambda: self._initialize(fmu), flag, take_over, name="fmu initialisation")

    def _initialize(self, fmu) -> None:
        """Set up the experiment, set the start values, enter and leave initialisation mode.

        Runs before anything is written; a refusal raises :class:`StartValuesRefused`.
        """
        from .instance import FmuError

        exp = self.case.experiment
        try:
            fmu.setup_experiment(exp.start, max(exp.stop, exp.time(exp.n_steps)), exp.tolerance)
            if self.case.parameters:
                fmu.set_values(self.case.parameters.items())
            if self.case.inputs:     # the inputs' values at the start, before initialisation
                fmu.drive_inputs(tuple(self.case.inputs), tuple(self.case.inputs.values()),
                                 self.case.input_derivative_order)
                fmu.set_inputs(exp.start, derivatives=False)
            fmu.enter_initialization_mode()
            fmu.exit_initialization_mode()
        except FmuError as exc:
            raise self._refused(exc) from None

    def _refused(self, exc: Exception) -> StartValuesRefused:
        """The message for start values the FMU refused: its own words, then the values the
        case set away from the FMU's own start values (the likely culprits; the FMU's
        message does not always name one, e.g. pythonfmu's bare ``OverflowError``)."""
        variables = self.case.fmu_description.variables
        differing = []
        for name, value in self.case.parameters.items():
            default = getattr(variables.get(name), "start", None)
            if not _same_value(value, default):
                origin = " (from --set)" if name in self.case.overridden else ""
                differing.append(f"{name} = {value!r}{origin}")
        if not self.case.parameters:
            culprits = "the case sets no start values (the FMU's own were refused)"
        elif differing:
            culprits = "the case sets these away from the FMU's own start values: " + ", ".join(differing)
        else:
            culprits = "every start value the case sets equals the FMU's own"
        label = str(self.case.source) if self.case.source is not None else f"case {self.case.name!r}"
        return StartValuesRefused(label, [f"parameters: the FMU refused the case's start values: {exc}; {culprits}"])

    def _start_outputs(self) -> None:
        """The run starts: take the folder's lock, create exchange.csv (header only), remove the
        previous run's derived folders, set space aside for the last run.json, write run.json,
        start the heartbeat and the progress bar.  If the lock is held or exchange.csv is not
        a regular file, :class:`OutputRefused` is raised and nothing in the folder changed; if
        exchange.csv cannot be created, nothing of this run was written (``started`` False)."""
        from fourbar_common.folder_lock import FolderLock, FolderLocked

        from .exchange import ExchangeRefused

        self.out_dir.mkdir(parents=True, exist_ok=True)
        try:
            self.lock = FolderLock(self.out_dir, "fourbar-run").acquire()
        except FolderLocked as exc:
            raise OutputRefused(str(exc), exc.holder) from None
        try:
            self.writer = ExchangeWriter(self.exchange_path, (TIME_COLUMN, *self.case.columns))
        except ExchangeRefused as exc:
            raise OutputRefused(f"{exc.filename}: {exc.strerror}") from None
        self.started = True         # from here on, run.json reports what happens
        self.replaced = remove_derived_outputs(self.out_dir)
        self._reserve()
        self._write_record()
        self._start_heartbeat()
        if self.progress:
            from tqdm import tqdm

            self.bar = tqdm(total=self.case.experiment.n_steps + 1, unit="row", desc=self.case.name,
                            file=sys.stderr, dynamic_ncols=True, leave=False)

    def _reserve(self) -> None:
        """Set :data:`RESERVE_BYTES` aside in the folder (see there); best effort."""
        path = self.out_dir / _RESERVE_NAME
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
        except OSError:
            return
        try:
            try:
                os.posix_fallocate(fd, 0, RESERVE_BYTES)
            except (AttributeError, OSError):
                os.write(fd, bytes(RESERVE_BYTES))
            self.reserve = path
        except OSError:
            path.unlink(missing_ok=True)
        finally:
            os.close(fd)

    def _release_reserve(self) -> bool:
        """Give the reserved space back; True if there was some."""
        path, self.reserve = self.reserve, None
        if path is None:
            return False
        try:
            path.unlink()
        except OSError:
            return False
        return True

    def _after_failure(self) -> str:
        """Keep the rows read before a failure (they are valid), without real-time waiting.

        Returns "" or a note for the error message when even that write failed.
        """
        try:
            if self.writer is not None and self._io_safe:
                self._flush(wait=False)
        except OSError as exc:
            return f"; the last rows could not be written: {type(exc).__name__}: {exc}"
        return ""

    def _finish(self) -> None:
        self._stop_heartbeat()
        if self.bar is not None:
            self.bar.close()
        if self.writer is not None:
            if self._io_safe:
                problem = self.writer.verify()
                if problem is not None:
                    self.error = f"{self.error}; {problem}" if self.error else problem
                    self.status = "failed"
            self.writer.close()
        try:
            if self.started:
                self._write_final_record()
        finally:
            self._release_reserve()
            if self.lock is not None:
                self.lock.release()
                self.lock = None

    def _write_final_record(self) -> None:
        """The last run.json; when the disk is full, again with the reserved space given back."""
        for attempt in range(2):
            try:
                self._write_record(final=True)
                return
            except OSError as exc:
                if attempt == 0 and self._release_reserve():
                    continue
                note = (f"run.json could not be written ({exc.strerror or exc}); it still holds the last "
                        f"update ({self.record.status}, {self.record.rows_written} rows)")
                self.error = f"{self.error}; {note}" if self.error else note
                if self.status == "finished":
                    self.status = "failed"
                return

    def _result(self) -> RunResult:
        sim_wall = None
        if self.loop_wall0 is not None and self.loop_wall1 is not None:
            sim_wall = self.loop_wall1 - self.loop_wall0
        return RunResult(case=self.case, status=self.status, out_dir=self.out_dir,
                         exchange_path=self.exchange_path, run_json_path=self.run_json_path,
                         rows_written=self.rows_written, last_time=self.last_time,
                         wall_time_s=time.monotonic() - self.wall0, sim_wall_time_s=sim_wall, error=self.error,
                         started=self.started, replaced=self.replaced, abandoned=self.abandoned)

    def _loop(self, fmu, flag: InterruptFlag) -> None:
        """Run :meth:`_steps` in a worker thread (:mod:`orchestrator.stepping`): this thread
        only waits and handles signals, so a doStep that never returns cannot hold a stop back."""
        from .stepping import run_in_worker

        case = self.case
        if case.noise is not None:
            from .noise import NoiseSource

            self.noise = NoiseSource(case.noise, case.recorded)
        if case.exchange.realtime_factor > 0.0:
            self.pacer = RealtimePacer(case.exchange.realtime_factor, case.experiment.start, flag)
        flag.check()
        run_in_worker(lambda: self._steps(fmu, flag), flag, lambda: self._take_over(fmu))

    def _take_over(self, fmu) -> None:
        """The worker is stuck in the FMU after a stop signal: from now on it touches neither
        the rows nor the file (it checks ``_worker_gone`` under ``_io_lock``), and the FMU
        instance is left to it (never freed under it)."""
        from .stepping import GRACE

        got = self._io_lock.acquire(timeout=GRACE)      # not while it appends a block
        self._worker_gone = True
        self._io_safe = got
        if got:
            self._io_lock.release()
        self.abandoned = True
        fmu.abandon()

    def _steps(self, fmu, flag: InterruptFlag) -> None:
        """The loop proper (in the worker thread)."""
        case = self.case
        exp = case.experiment
        n = exp.n_steps
        start, step = exp.start, exp.step
        flush_every = max(1, round(case.exchange.flush_interval / step))
        steps, timed = _schedule(case)
        ramps = any(isinstance(event, RampEvent) for _, _, event in timed)
        read = fmu.reader(case.recorded)
        written = tuple(case.inputs[name] for name in case.input_columns)   # after what is read
        do_step, set_values = fmu.do_step, fmu.set_values
        set_inputs = fmu.set_inputs if case.inputs else None
        lock = self._io_lock

        self.loop_wall0 = time.monotonic()
        if self.pacer is not None:
            self.pacer.start()
        t = start
        for k in range(n + 1):
            row = read()
            if written:          # each input's value at the row's time
                row = [*row, *(signal.at(t) for signal in written)]
            with lock:
                if self._worker_gone:
                    return
                self.pending_t.append(t)
                self.pending_v.append(row)
            if k % flush_every == 0 or k == n:
                if self.pacer is not None and self.pending_t:
                    self.pacer.wait_until(self.pending_t[-1])
                with lock:
                    if self._worker_gone:
                        return
                    self._flush(wait=False)
            if k == n:
                break
            actions = _actions(k, timed, n) if ramps else steps.get(k)
            if actions:
                set_values(actions)
            if set_inputs is not None:
                set_inputs(t)
            flag.check()
            t_next = start + (k + 1) * step
            do_step(t, t_next - t)
            t = t_next

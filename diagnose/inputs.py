"""Everything a diagnosis reads from a run folder, checked: :func:`read_inputs`.

A run folder is what ``fourbar-run`` wrote (``exchange.csv``, ``run.json``) plus the
monitor's ``monitor/summary.json``.  The diagnosis uses the healthy parameter values and the
time grid from run.json (read as a :class:`fourbar_common.RunRecord`), the first alarm and
the monitored columns from the summary, and the rows of the exchange file.  It never reads
run.json's ``events`` (the injected truth); :attr:`RunInputs.events` keeps them only so that
a score can be computed afterwards.

The healthy model is the start value of every parameter of the FMU as run.json records it
(set by the case file, by ``--set``, or the FMU's own default), so a case file that names
no parameter, or only some, is diagnosed like one that names them all.  A schema 1 run.json
recorded only the values the case set: the others are then the FMU's own start values (the
FMU carries the run's GUID, so they are the run's).

The FMU.  run.json names the FMU the run used and its GUID; that file must still carry
that GUID (otherwise it was rebuilt, and its model may not be the one that made the data).
The branches are simulated by an FMU that can save its state (``canGetAndSetFMUstate``):
the run's own FMU when it can, else one beside it in the same folder that declares the same
parameters and the monitored outputs (``python build_fmu.py [--mechanism NAME]`` builds the
native FMU next to the pythonfmu one from the same derivation, as ``<Name>Native.fmu``,
which is tried first).  Without one, the run's FMU re-simulates from the start for
every branch: the same answer, much slower.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from fourbar_common import Event
from fourbar_common.contract.exchange import read_exchange
from fourbar_common.contract.json_files import JsonFileError
from fourbar_common.contract.layout import RunFolder
from fourbar_common.contract.problems import ContractError
from fourbar_common.contract.run_record import RunRecord, RunRecordError, read_run_record
from fourbar_common.contract.summary import MonitorSummary, read_summary

from .errors import DiagnoseError, NoAlarm
from .simulator import Grid

__all__ = ["RunInputs", "read_inputs"]


@dataclass(frozen=True)
class RunInputs:
    """A checked run folder."""

    run_dir: Path
    times: Any                      # numpy array, s
    data: Any                       # numpy array, rows x columns
    columns: tuple[str, ...]
    units: dict[str, str]
    alarm_time: float
    parameters: dict[str, Any]      # every parameter's start value from run.json (the healthy model)
    hypotheses: tuple[str, ...]     # tunable Real parameters: the candidate causes
    grid: Grid
    tolerance: float | None
    run_fmu: Path                   # the FMU the run used (GUID checked)
    guid: str
    simulator_fmu: Any              # orchestrator FmuDescription of the FMU that simulates
    case: str
    run_id: str | None
    events: tuple[Event, ...]   # the injected truth, for scoring only
    record: RunRecord | None = None     # run.json as read (schema 1: completed with the FMU's defaults)
    master: Any = None              # a system run: its orchestrator Master (simulator_fmu is the system)

    @property
    def resimulates(self) -> bool:
        """True when the simulating FMU cannot save its state: every branch then re-simulates
        the run from its start (the same answer, minutes instead of seconds)."""
        return not _can_save_state(self.simulator_fmu)


def _load_summary(path: Path, fix: str) -> MonitorSummary:
    """The monitor's summary.json (a regular file; deep nesting, a huge file or a FIFO give a
    :class:`DiagnoseError` naming the file, never a traceback or a hang)."""
    what = "monitor summary"
    if not path.exists():
        raise DiagnoseError(f"{path}: no {what}; {fix}")
    try:
        return read_summary(path)
    except FileNotFoundError:
        raise DiagnoseError(f"{path}: no {what}; {fix}") from None
    except (OSError, JsonFileError, ContractError) as exc:
        text = " ".join(str(exc).split())
        text = text[len(str(path)) + 2:] if text.startswith(f"{path}: ") else text
        raise DiagnoseError(f"{path}: not a readable {what} ({text}); {fix}") from None


def _or_unknown(value: Any) -> Any:
    """A summary's figure for a message: ``?`` when the summary does not say."""
    return "?" if value is None else value


def _load_record(path: Path) -> RunRecord:
    fix = "expected a run folder written by fourbar-run"
    if not path.exists():
        raise DiagnoseError(f"{path}: no run.json; {fix}")
    try:
        return read_run_record(path)
    except FileNotFoundError:
        raise DiagnoseError(f"{path}: no run.json; {fix}") from None
    except RunRecordError as exc:
        raise DiagnoseError(str(exc)) from None


def _describe(path: Path, what: str):
    from orchestrator.case import describe_fmu

    try:
        return describe_fmu(path)
    except Exception as exc:    # fmpy raises zipfile/XML/bare exceptions
        raise DiagnoseError(f"{path}: {what} is not a readable FMU ({' '.join(str(exc).split())})") from None


def _mechanism_of(model_name: str) -> str:
    """The mechanism an FMU's model name belongs to: ``FourBarNative3`` and ``FourBarNative`` are
    builds of ``FourBar`` (build_fmu.py names the native FMUs ``<Name>Native`` and ``<Name>Native3``)."""
    for suffix in ("Native3", "Native"):
        if model_name.endswith(suffix) and len(model_name) > len(suffix):
            return model_name[:-len(suffix)]
    return model_name


def _guid_mismatch(fmu: Path, description, recorded, run_json: Path) -> str:
    """Why an FMU whose GUID is not run.json's cannot explain the run: another mechanism's FMU,
    another build (pythonfmu or native) of the run's mechanism, or the run's FMU rebuilt since."""
    name, was = description.model.modelName, recorded.model_name
    given = f"{fmu}: model {name} (GUID {description.guid})"
    ran = f"{run_json} records that the run used {was} (GUID {recorded.guid}, {recorded.path})"
    if _mechanism_of(name) != _mechanism_of(was):
        return (f"{given} is another mechanism's FMU ({_mechanism_of(name)}), but {ran}, a {_mechanism_of(was)}: "
                f"pass --fmu with the run's own FMU")
    if name != was:
        return (f"{given} is another build of {_mechanism_of(was)} than the run's: {ran}; pass --fmu with that "
                f"FMU (the native FMU beside it then replays the run)")
    return (f"{given}: GUID does not match run.json's {recorded.guid}: the FMU was rebuilt after the run, so it may "
            f"not be the model that made the data; run the case again (or pass --fmu with the FMU the run used)")


def _tunable(description) -> set[str]:
    return {v.name for v in description.model.modelVariables
            if v.type == "Real" and v.causality == "parameter" and v.variability == "tunable"}


def _can_save_state(description) -> bool:
    return bool(getattr(description.model.coSimulation, "canGetAndSetFMUstate", False))


def _parameters(description) -> list[tuple]:
    """Every parameter's name, variability and type, in order: two builds of one model (the
    pythonfmu and the native FMU of one mechanism) declare the same list."""
    return [(v.name, v.variability, v.type) for v in description.model.modelVariables if v.causality == "parameter"]


def _pick_simulator(run_description, needed: set[str], prefer_run_fmu: bool):
    """The FMU that simulates the branches (module docstring); ``needed``: the variables it must
    have, with the run FMU's types (the monitored columns and every recorded parameter).

    A candidate beside the run's FMU must declare the same parameters (names, variabilities,
    types, in order) and the needed outputs, so another mechanism built into the same folder
    is not taken for this one; ``<stem>Native.fmu`` (what ``build_fmu.py`` names the native
    FMU) is tried first.  Outputs may differ otherwise (a build with more outputs serves).
    """
    if prefer_run_fmu or _can_save_state(run_description):
        return run_description
    folder = run_description.path.parent
    own = folder / f"{run_description.path.stem}Native.fmu"
    parameters = _parameters(run_description)
    for path in sorted(folder.glob("*.fmu"), key=lambda p: (p != own, p.name)):
        if path == run_description.path:
            continue
        try:
            other = _describe(path, "a candidate simulator")
        except DiagnoseError:     # an unreadable file beside the run's FMU is simply not a candidate
            continue
        types = {v.name: v.type for v in other.model.modelVariables}
        same_types = all(n in types and types[n] == run_description.variables[n].type for n in needed)
        if (_can_save_state(other) and other.model.coSimulation is not None and same_types
                and _tunable(other) == _tunable(run_description) and _parameters(other) == parameters):
            return other
    return run_description


def _system(path: Path, record: RunRecord, run_json: Path):
    """The system a system run ran (its .ssp, SHA-256 checked) and the master that stepped it."""
    from orchestrator.case import Master
    from orchestrator.ssp import SspError
    from orchestrator.system_description import describe_system

    recorded = record.system
    if not path.is_file():
        raise DiagnoseError(f"{path}: the run's system file is missing; rebuild it (python build_fmu.py --system NAME) "
                            f"and run the case again, or pass --fmu PATH if it moved")
    try:
        description = describe_system(path)
    except (SspError, OSError) as exc:
        raise DiagnoseError(f"{path}: the run's system is not readable ({' '.join(str(exc).split())})") from None
    if description.guid != recorded.sha256:
        raise DiagnoseError(f"{path}: SHA-256 {description.guid} is not the {recorded.sha256} {run_json} records: the "
                            f"system was rebuilt after the run, so it may not be the model that made the data; run the "
                            f"case again (or pass --fmu with the .ssp the run used)")
    order = tuple(recorded.order) if recorded.algorithm == "gauss-seidel" else ()
    return description, Master(algorithm=recorded.algorithm, inputs=recorded.inputs, order=order)


def _narrowed(hypotheses: tuple[str, ...], candidates: Sequence[str]) -> tuple[str, ...]:
    """The hypotheses named by ``candidates``: a parameter's name, or a system component's name
    (every hypothesis ``component.*``); a name that matches none is an input error."""
    chosen = []
    for name in candidates:
        matched = [h for h in hypotheses if h == name or h.startswith(f"{name}.")]
        if not matched:
            raise DiagnoseError(f"--candidates {name}: not a tunable Real parameter (nor a component of them); "
                                f"candidates: {', '.join(hypotheses)}")
        chosen.extend(h for h in matched if h not in chosen)
    return tuple(h for h in hypotheses if h in chosen)


def read_inputs(run_dir: str | Path, *, summary: str | Path | None = None, fmu: str | Path | None = None,
                columns: Sequence[str] | None = None, use_run_fmu: bool = False,
                candidates: Sequence[str] | None = None) -> RunInputs:
    """Read and check a run folder (module docstring); raise :class:`DiagnoseError` on bad input.

    ``summary`` defaults to ``RUN_DIR/monitor/summary.json``; ``fmu`` replaces run.json's FMU
    path (a moved build; its GUID must still match); ``columns`` replaces the monitored
    columns; ``use_run_fmu`` simulates with the run's FMU even when a faster one is beside it;
    ``candidates`` narrows the hypotheses to these parameters (``motor.R``) or every tunable
    Real parameter of these components (``motor``).
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise DiagnoseError(f"{run_dir}: not a folder; expected a run folder written by fourbar-run "
                            "(exchange.csv, run.json, monitor/summary.json)")
    folder = RunFolder(run_dir)
    run_json = folder.run_record
    record = _load_record(run_json)
    summary_path = Path(summary) if summary is not None else folder.summary
    info = _load_summary(summary_path, f"run `fourbar-monitor {folder.exchange}` first (it writes "
                                       f"{folder.summary.relative_to(folder.root)})")

    if info.run_id and record.run_id and info.run_id != record.run_id:
        raise DiagnoseError(f"{summary_path}: it belongs to run {info.run_id}, but {run_json} is run "
                            f"{record.run_id} (the case was run again); monitor the new run first")
    alarm = info.first_alarm_time
    if alarm is None:
        raise NoAlarm(f"no fault to classify: the monitor raised no alarm in {summary_path} "
                      f"({_or_unknown(info.evaluations)} evaluations up to t = {_or_unknown(info.last_time)} s)")

    if record.fmu is None:
        raise DiagnoseError(f"{run_json}: no fmu (path, guid, model_name); expected run.json written by fourbar-run")
    guid = record.fmu.guid
    run_fmu = Path(fmu) if fmu is not None else Path(record.fmu.path)
    master = None
    if record.system is not None:
        run_description, master = _system(run_fmu, record, run_json)
    else:
        if not run_fmu.is_file():
            raise DiagnoseError(f"{run_fmu}: the run's FMU is missing; rebuild it with `python build_fmu.py` and run "
                                f"the case again, or pass --fmu PATH if it moved")
        run_description = _describe(run_fmu, "the run's FMU")
        if run_description.guid != guid:
            raise DiagnoseError(_guid_mismatch(run_fmu, run_description, record.fmu, run_json))

    if record.experiment is None:
        raise DiagnoseError(f"{run_json}: no experiment (start, stop, step); expected run.json written by fourbar-run")
    grid = Grid(record.experiment.start, record.experiment.step)
    if not record.complete:          # schema 1: only what the case set; the rest is the FMU's own
        record = record.completed_with(run_description.parameter_starts())
    parameters = record.start_values
    foreign = [n for n in parameters if getattr(run_description.variables.get(n), "causality", None) != "parameter"]
    if foreign:
        raise DiagnoseError(f"{run_json}: parameters {', '.join(foreign)}: not parameters of {run_fmu.name}; "
                            f"expected run.json written by fourbar-run with this FMU")
    hypotheses = tuple(p.name for p in record.parameters
                       if p.type == "Real" and p.tunable and p.start is not None and p.name in run_description.variables)
    if not hypotheses:
        raise DiagnoseError(f"{run_json}: records no tunable Real parameter of {run_fmu.name} with a start value, "
                            f"so no parameter can be fitted as the cause")
    if candidates:
        hypotheses = _narrowed(hypotheses, candidates)

    monitored = info.monitored
    wanted = tuple(columns) if columns else tuple(monitored)
    if not wanted:
        raise DiagnoseError(f"{summary_path}: names no monitored column; pass --columns")
    outputs = {v.name for v in run_description.model.modelVariables if v.causality == "output"}
    unknown = [c for c in wanted if c not in outputs]
    if unknown:
        raise DiagnoseError(f"columns {', '.join(unknown)}: not outputs of {run_fmu.name} "
                            f"(outputs: {', '.join(sorted(outputs))})")

    exchange = RunFolder(run_dir).exchange
    try:
        rows = read_exchange(exchange, wanted)
    except FileNotFoundError:
        raise DiagnoseError(f"{exchange}: exchange file not found") from None
    except ContractError as exc:
        raise DiagnoseError(str(exc)) from None
    if rows.note:           # rows skipped: said as the monitor says it (the CLI prints warnings)
        warnings.warn(rows.note, UserWarning, stacklevel=2)
    times = rows.time
    if times.size < 2 or not times[0] <= alarm <= times[-1]:
        raise DiagnoseError(f"{exchange}: rows cover {times[0] if times.size else '?'}..{times[-1] if times.size else '?'}"
                            f" s, which does not contain the alarm at {alarm} s")
    off_grid = abs((times - grid.start) / grid.step - ((times - grid.start) / grid.step).round()).max()
    if off_grid > 1e-6:
        raise DiagnoseError(f"{exchange}: rows are not on run.json's grid (start {grid.start} s, step {grid.step} s)")

    simulator = (run_description if master is not None
                 else _pick_simulator(run_description, set(wanted) | set(parameters), use_run_fmu))
    units = {c: record.units.get(c, "") for c in wanted}
    return RunInputs(run_dir=run_dir, times=times, data=np.column_stack([rows.values[c] for c in wanted]), columns=wanted,
                     units=units, alarm_time=float(alarm), parameters=parameters, hypotheses=hypotheses, grid=grid,
                     tolerance=record.experiment.tolerance, run_fmu=run_fmu, guid=guid,
                     simulator_fmu=simulator, case=record.case or run_dir.name, run_id=record.run_id,
                     events=record.events, record=record, master=master)

"""Everything a diagnosis reads from a run folder, checked: :func:`read_inputs`.

A run folder is what ``fourbar-run`` wrote (``exchange.csv``, ``run.json``) plus the
monitor's ``monitor/summary.json``.  The diagnosis uses the healthy parameter values and the
time grid from run.json, the first alarm and the monitored columns from the summary, and
the rows of the exchange file.  It never reads run.json's ``events`` (the injected truth);
:attr:`RunInputs.events` keeps them only so that a score can be computed afterwards.

The FMU.  run.json names the FMU the run used and its GUID; that file must still carry
that GUID (otherwise it was rebuilt, and its model may not be the one that made the data).
The branches are simulated by an FMU that can save its state (``canGetAndSetFMUstate``):
the run's own FMU when it can, else one beside it in the same folder with the same
parameters and outputs (``python build_fmu.py`` builds the native FMU next to the pythonfmu
one from the same derivation).  Without one, the run's FMU re-simulates from the start for
every branch: the same answer, much slower.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

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
    parameters: dict[str, float]    # run.json's start values (the healthy model)
    hypotheses: tuple[str, ...]     # tunable Real parameters: the candidate causes
    grid: Grid
    tolerance: float | None
    run_fmu: Path                   # the FMU the run used (GUID checked)
    guid: str
    simulator_fmu: Any              # orchestrator FmuDescription of the FMU that simulates
    case: str
    run_id: str | None
    events: tuple[dict, ...]        # the injected truth, for scoring only


def _load_json(path: Path, what: str, fix: str) -> dict:
    if not path.is_file():
        raise DiagnoseError(f"{path}: no {what}; {fix}")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DiagnoseError(f"{path}: not a readable {what} ({' '.join(str(exc).split())}); {fix}") from None
    if not isinstance(data, dict):
        raise DiagnoseError(f"{path}: expected a JSON object, got {type(data).__name__}; {fix}")
    return data


def _describe(path: Path, what: str):
    from orchestrator.case import describe_fmu

    try:
        return describe_fmu(path)
    except Exception as exc:    # fmpy raises zipfile/XML/bare exceptions
        raise DiagnoseError(f"{path}: {what} is not a readable FMU ({' '.join(str(exc).split())})") from None


def _tunable(description) -> set[str]:
    return {v.name for v in description.model.modelVariables
            if v.type == "Real" and v.causality == "parameter" and v.variability == "tunable"}


def _can_save_state(description) -> bool:
    return bool(getattr(description.model.coSimulation, "canGetAndSetFMUstate", False))


def _pick_simulator(run_description, needed: set[str], prefer_run_fmu: bool):
    """The FMU that simulates the branches (module docstring)."""
    if prefer_run_fmu or _can_save_state(run_description):
        return run_description
    for path in sorted(run_description.path.parent.glob("*.fmu")):
        if path == run_description.path:
            continue
        try:
            other = _describe(path, "a candidate simulator")
        except DiagnoseError:     # an unreadable file beside the run's FMU is simply not a candidate
            continue
        names = {v.name for v in other.model.modelVariables}
        if (_can_save_state(other) and other.model.coSimulation is not None and needed <= names
                and _tunable(other) == _tunable(run_description)):
            return other
    return run_description


def read_inputs(run_dir: str | Path, *, summary: str | Path | None = None, fmu: str | Path | None = None,
                columns: Sequence[str] | None = None, use_run_fmu: bool = False) -> RunInputs:
    """Read and check a run folder (module docstring); raise :class:`DiagnoseError` on bad input.

    ``summary`` defaults to ``RUN_DIR/monitor/summary.json``; ``fmu`` replaces run.json's FMU
    path (a moved build; its GUID must still match); ``columns`` replaces the monitored
    columns; ``use_run_fmu`` simulates with the run's FMU even when a faster one is beside it.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise DiagnoseError(f"{run_dir}: not a folder; expected a run folder written by fourbar-run "
                            "(exchange.csv, run.json, monitor/summary.json)")
    run = _load_json(run_dir / "run.json", "run.json", "expected a run folder written by fourbar-run")
    summary_path = Path(summary) if summary is not None else run_dir / "monitor" / "summary.json"
    info = _load_json(summary_path, "monitor summary",
                      f"run `fourbar-monitor {run_dir / 'exchange.csv'}` first (it writes monitor/summary.json)")

    if info.get("run_id") and run.get("run_id") and info["run_id"] != run["run_id"]:
        raise DiagnoseError(f"{summary_path}: it belongs to run {info['run_id']}, but {run_dir / 'run.json'} is run "
                            f"{run['run_id']} (the case was run again); monitor the new run first")
    alarm = info.get("first_alarm_time")
    if alarm is None:
        raise NoAlarm(f"no fault to classify: the monitor raised no alarm in {summary_path} "
                      f"({info.get('evaluations', '?')} evaluations up to t = {info.get('last_time', '?')} s)")
    if not isinstance(alarm, (int, float)) or not math.isfinite(alarm):
        raise DiagnoseError(f"{summary_path}: first_alarm_time = {alarm!r}; expected a time in s")

    fmu_info = run.get("fmu") or {}
    guid = fmu_info.get("guid")
    recorded = fmu_info.get("path")
    if not guid or not recorded:
        raise DiagnoseError(f"{run_dir / 'run.json'}: no fmu.path/fmu.guid; expected run.json written by fourbar-run")
    run_fmu = Path(fmu) if fmu is not None else Path(recorded)
    if not run_fmu.is_file():
        raise DiagnoseError(f"{run_fmu}: the run's FMU is missing; rebuild it with `python build_fmu.py` and run the "
                            f"case again, or pass --fmu PATH if it moved")
    run_description = _describe(run_fmu, "the run's FMU")
    if run_description.guid != guid:
        raise DiagnoseError(f"{run_fmu}: GUID {run_description.guid} does not match run.json's {guid}: the FMU was "
                            f"rebuilt after the run, so it may not be the model that made the data; run the case "
                            f"again (or pass --fmu with the FMU the run used)")

    experiment = run.get("experiment") or {}
    try:
        grid = Grid(float(experiment["start"]), float(experiment["step"]))
    except (KeyError, TypeError, ValueError):
        raise DiagnoseError(f"{run_dir / 'run.json'}: experiment.start/step missing; expected run.json written by "
                            "fourbar-run") from None
    parameters = {k: float(v) for k, v in (run.get("parameters") or {}).items()
                  if isinstance(v, (int, float)) and not isinstance(v, bool)}
    hypotheses = tuple(n for n in sorted(_tunable(run_description), key=list(parameters).index)
                       if n in parameters) if parameters else ()
    if not hypotheses:
        raise DiagnoseError(f"{run_dir / 'run.json'}: none of the FMU's tunable parameters has a value in "
                            f"'parameters'; expected run.json written by fourbar-run")

    monitored = info.get("signals") or [s.strip() for s in str(info.get("signal", "")).split(",") if s.strip()]
    wanted = tuple(columns) if columns else tuple(monitored)
    if not wanted:
        raise DiagnoseError(f"{summary_path}: names no monitored column; pass --columns")
    outputs = {v.name for v in run_description.model.modelVariables if v.causality == "output"}
    unknown = [c for c in wanted if c not in outputs]
    if unknown:
        raise DiagnoseError(f"columns {', '.join(unknown)}: not outputs of {run_fmu.name} "
                            f"(outputs: {', '.join(sorted(outputs))})")

    from monitor import MonitorError, read_exchange

    exchange = run_dir / "exchange.csv"
    try:
        frame = read_exchange(exchange, list(wanted))
    except MonitorError as exc:
        raise DiagnoseError(str(exc)) from None
    times = frame["time"].to_numpy(dtype=float)
    if times.size < 2 or not times[0] <= alarm <= times[-1]:
        raise DiagnoseError(f"{exchange}: rows cover {times[0] if times.size else '?'}..{times[-1] if times.size else '?'}"
                            f" s, which does not contain the alarm at {alarm} s")
    off_grid = abs((times - grid.start) / grid.step - ((times - grid.start) / grid.step).round()).max()
    if off_grid > 1e-6:
        raise DiagnoseError(f"{exchange}: rows are not on run.json's grid (start {grid.start} s, step {grid.step} s)")

    simulator = _pick_simulator(run_description, set(wanted) | set(hypotheses), use_run_fmu)
    units = {c: run.get("units", {}).get(c, "") for c in wanted}
    return RunInputs(run_dir=run_dir, times=times, data=frame[list(wanted)].to_numpy(dtype=float), columns=wanted,
                     units=units, alarm_time=float(alarm), parameters=parameters, hypotheses=hypotheses, grid=grid,
                     tolerance=experiment.get("tolerance"), run_fmu=run_fmu, guid=guid,
                     simulator_fmu=simulator, case=str(run.get("case", run_dir.name)), run_id=run.get("run_id"),
                     events=tuple(run.get("events") or ()))

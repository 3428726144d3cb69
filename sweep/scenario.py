"""One scenario, run where it is scheduled (a Dask worker): the orchestrator, then the monitor.

:func:`run_scenario` receives plain data -- the :class:`~sweep.plan.Scenario`, the base
:class:`orchestrator.Case` (a description: the FMU's *path*, never a loaded FMU) and the
scenario's directory -- and returns one row of the results table as a dict.  The FMU is
extracted, instantiated and freed inside :func:`orchestrator.run_case` in the worker's
process.  Any failure (a case the orchestrator rejects, an FMU that cannot apply the
fault, a monitor that cannot train, an unexpected exception) becomes a row with status
``"failed"`` and the message, so one bad scenario never stops a sweep.

Scoring (times are evaluation times ``t_k``; an evaluation covers the samples in
``(t_k - window, t_k]``; the row written at the fault time still shows the healthy state):

``false_alarms``      alarms raised at ``t_k <= t_fault`` (every alarm without a fault);
``detected``          an alarm is raised at some ``t_k > t_fault``;
``detection_time``    the first such ``t_k``; ``latency = detection_time - t_fault``;
``mae_*_pre/post``    max and mean windowed MAE over ``t_k <= t_fault`` / ``t_k > t_fault``;
``score_pre/post``    the largest threshold multiplier ``c`` the detector's rule would still
                      exceed: ``max_k min(r_k, .., r_{k+p-1})`` over runs of ``p``
                      (``persistence``) consecutive evaluations ending before / after the
                      fault, with ``r = MAE / threshold`` (so the detector alarms when the
                      score is above 1; with ``refit = "paper"`` this ignores refits);
``score_early``       the same over the runs ending in ``(t_fault, t_fault + latency_limit]``:
                      above 1 means "detected within the latency limit" at that threshold.
"""
from __future__ import annotations

import os
import socket
import time
from dataclasses import replace
from pathlib import Path
from typing import Any, Mapping

from fourbar_common.contract.layout import RunFolder
from fourbar_common.formatting import format_time

from .plan import Scenario

__all__ = ["RESULT_FIELDS", "early_score", "failed_row", "run_scenario", "scenario_case", "score"]

#: Result columns added to a scenario's inputs (types in :mod:`sweep.results`).
RESULT_FIELDS = ("status", "error", "detected", "detection_time", "latency", "first_alarm_time", "alarms",
                 "false_alarms", "threshold_base", "period", "evaluations", "statistic_max_pre", "statistic_mean_pre",
                 "statistic_max_post", "statistic_mean_post", "score_pre", "score_post", "score_early", "latency_limit",
                 "delay_arl0_0.1h", "delay_arl0_1h", "delay_arl0_10h", "delay_arl0_100h", "delay_arl0_1000h",
                 "delay_arl0_10000h", "rows_written", "fmu_guid", "diagnosis", "diagnosed_variable", "diagnosed_kind",
                 "diagnosed_value", "diagnosed_time", "diagnosed_end_time", "diagnosed_runner_up",
                 "run_seconds", "monitor_seconds", "diagnosis_seconds", "wall_seconds", "cpu_seconds", "worker")


def scenario_case(base, scenario: Scenario):
    """The base case with the scenario's fault and noise (validated when it is run)."""
    from orchestrator import Noise, RampEvent, StepEvent

    events = ()
    if scenario.kind == "step":
        events = (StepEvent(time=scenario.fault_time, variable=scenario.variable, value=scenario.fault_value),)
    elif scenario.kind == "ramp":
        events = (RampEvent(variable=scenario.variable, from_=scenario.base_value, to=scenario.fault_value,
                            start=scenario.fault_time, end=scenario.fault_time + scenario.ramp_duration),)
    noise = None
    if scenario.noise_std > 0:
        noise = Noise(seed=scenario.noise_seed, std={s.strip(): scenario.noise_std for s in scenario.signal.split(",")})
    exchange = replace(base.exchange, realtime_factor=0.0)
    return replace(base, name=f"scenario-{scenario.id}", events=events, noise=noise, exchange=exchange)


def _empty_result() -> dict[str, Any]:
    return {name: None for name in RESULT_FIELDS}


def failed_row(scenario: Scenario, message: str, **extra: Any) -> dict[str, Any]:
    """A result row with status ``failed`` and ``message``."""
    row = scenario.inputs()
    row.update(_empty_result())
    row.update(status="failed", error=message)
    row.update(extra)
    return row


def score(times, mae, threshold, alarm_times, fault_time: float | None, persistence: int,
          latency_limit: float | None = None) -> dict[str, Any]:
    """Detection figures of one monitored run (definitions in the module docstring).

    Alarms are scored by :func:`monitor.score_alarms`, the monitor's own rule, so the
    sweep and summary.json cannot disagree on a false alarm or a latency.
    """
    import numpy as np

    from monitor import score_alarms
    from monitor.summary import before_fault

    t = np.asarray(times, dtype=float)
    mae = np.asarray(mae, dtype=float)
    thr = np.asarray(threshold, dtype=float)
    scored = score_alarms(alarm_times, fault_time)
    ratio = mae / thr
    p = max(1, int(persistence))
    if ratio.size >= p:
        runs = np.lib.stride_tricks.sliding_window_view(ratio, p).min(axis=1)
        run_end = t[p - 1:]
    else:
        runs = run_end = np.empty(0)
    pre = before_fault(t, fault_time)
    post = ~pre
    run_pre = before_fault(run_end, fault_time)

    def stat(fn, values):
        return float(fn(values)) if values.size else None

    return {
        "detected": scored.detected,
        "detection_time": scored.detection_time,
        "latency": scored.latency,
        "first_alarm_time": scored.alarm_times[0] if scored.alarm_times else None,
        "alarms": scored.alarms,
        "false_alarms": scored.false_alarms,
        "evaluations": int(t.size),
        "statistic_max_pre": stat(np.max, mae[pre]), "statistic_mean_pre": stat(np.mean, mae[pre]),
        "statistic_max_post": stat(np.max, mae[post]), "statistic_mean_post": stat(np.mean, mae[post]),
        "score_pre": stat(np.max, runs[run_pre]), "score_post": stat(np.max, runs[~run_pre]),
        "score_early": early_score(t, mae, thr, fault_time, p, latency_limit),
        "latency_limit": latency_limit,
    }


def detector_persistence(options: Any) -> int:
    """Consecutive evaluations above the limit that make an alarm under ``options`` (a
    :class:`monitor.MonitorOptions`): the detector's own rule, e.g. 1 for the CUSUM (any crossing)."""
    return int(options.detector_class.alarm_persistence(options))


#: The false-alarm levels (mean hours between false alarms) of the delay-vs-ARL0 curve.
ARL0_HOURS = (0.1, 1.0, 10.0, 100.0, 1000.0, 10000.0)


def delay_column(hours: float) -> str:
    return f"delay_arl0_{hours:g}h"


def delays_at_arl0(times, statistic, design, fault_time: float | None) -> dict[str, Any]:
    """Detection delay the same run would have had with the limit set for each ``ARL0_HOURS``.

    ``design`` is the run's fitted rule of a detector with ``arl0_curve`` (the CUSUM's
    :class:`~monitor.sequential.CusumDesign`): its run's limit ``h`` and ``limit_at_arl0(hours)``.
    The statistic does not depend on the limit until its first crossing, so the first
    evaluation after the fault where it reaches the limit ``h(ARL0)`` (Siegmund, same
    ``k``, sampling step and statistic count as the run's design) is that limit's
    detection time, at the evaluation cadence.  That holds for limits up to the run's own
    ``h`` only (after the run's alarm the statistic restarts from zero), so levels above the
    run's design are left None: a sweep with a smaller ``false_alarm_rate`` reaches them.
    None also when not reached, or reached before the fault (a false alarm at that level).
    """
    import numpy as np

    from monitor.summary import before_fault

    out: dict[str, Any] = {delay_column(h): None for h in ARL0_HOURS}
    if fault_time is None:
        return out
    t = np.asarray(times, dtype=float)
    s = np.asarray(statistic, dtype=float)
    pre = before_fault(t, fault_time)
    pre_max = float(s[pre].max()) if pre.any() else 0.0
    for hours in ARL0_HOURS:
        h = design.limit_at_arl0(hours)
        if h > design.h * (1 + 1e-9) or pre_max >= h:
            continue
        hit = np.flatnonzero(~pre & (s >= h))
        if hit.size:
            out[delay_column(hours)] = round(float(t[hit[0]]) - float(fault_time), 9)
    return out


def early_score(times, mae, threshold, fault_time: float | None, persistence: int,
                latency_limit: float | None) -> float | None:
    """``score_early``: the post-fault score over runs ending within ``latency_limit`` s of the fault."""
    import numpy as np

    from monitor.summary import before_fault

    if fault_time is None or latency_limit is None:
        return None
    t = np.asarray(times, dtype=float)
    ratio = np.asarray(mae, dtype=float) / np.asarray(threshold, dtype=float)
    p = max(1, int(persistence))
    if ratio.size < p:
        return None
    runs = np.lib.stride_tricks.sliding_window_view(ratio, p).min(axis=1)
    end = t[p - 1:]
    sel = ~before_fault(end, fault_time) & before_fault(end, fault_time + latency_limit)
    return float(runs[sel].max()) if sel.any() else None


def diagnosis_fields(run_dir: Path) -> dict[str, Any]:
    """The diagnosis of a monitored run folder as result columns (``diagnosis`` is the verdict,
    ``failed: ...`` when the diagnosis could not run)."""
    t0 = time.perf_counter()
    try:
        from diagnose import DiagnoseError, diagnose

        d = diagnose(run_dir)
    except DiagnoseError as exc:
        return {"diagnosis": f"failed: {' '.join(str(exc).split())}", "diagnosis_seconds": time.perf_counter() - t0}
    best = d.best
    return {"diagnosis": d.verdict, "diagnosed_variable": best.parameter, "diagnosed_kind": best.kind,
            "diagnosed_value": best.value, "diagnosed_time": best.change_time, "diagnosed_end_time": best.end_time,
            # the other candidate of an ambiguous verdict (None otherwise)
            "diagnosed_runner_up": d.runner_up.parameter if d.ambiguous and d.runner_up is not None else None,
            "diagnosis_seconds": d.seconds}


def run_scenario(scenario: Scenario, base_case, run_dir: str, monitor_options: Mapping[str, Any], *,
                 fmu_guid: str = "", keep_exchange: bool = True, monitor_plots: bool = False,
                 latency_limit: float | None = None, diagnose: bool = False) -> dict[str, Any]:
    """Run one scenario (orchestrator run + monitor replay, + the diagnosis after an alarm when
    ``diagnose``) and return its result row."""
    wall0 = time.perf_counter()
    cpu0 = time.process_time()
    worker = f"{socket.gethostname()}:{os.getpid()}"
    row = scenario.inputs()
    row.update(_empty_result())
    row.update(fmu_guid=fmu_guid, worker=worker)

    def finish(**values: Any) -> dict[str, Any]:
        row.update(values)
        row["wall_seconds"] = time.perf_counter() - wall0
        row["cpu_seconds"] = time.process_time() - cpu0     # of the worker process: < wall when CPUs are shared
        return row

    try:
        from monitor import MonitorError
        from orchestrator import ConfigError, run_case

        out = Path(run_dir)
        try:
            result = run_case(scenario_case(base_case, scenario), out)
        except ConfigError as exc:
            return finish(status="failed", error=f"case rejected: {' '.join(str(exc).split())}")
        row.update(rows_written=result.rows_written, run_seconds=result.wall_time_s)
        if not result.ok:
            where = f"at t = {format_time(result.last_time)} s" if result.last_time is not None else "before the first row"
            return finish(status="failed", error=f"run {result.status} {where}: {result.error}")
        options = dict(monitor_options)
        options.update(model=scenario.model, threshold=scenario.threshold_value, signal=scenario.signal)
        every = float(options.get("every", 0.1))
        options.setdefault("evaluation_points", max(20000, int(scenario.stop / every) + 100))
        m0 = time.perf_counter()
        try:
            from monitor import replay

            monitored = replay(result.exchange_path, out_dir=RunFolder(out).monitor, plots=monitor_plots, **options)
        except MonitorError as exc:
            return finish(status="failed", error=f"monitor: {' '.join(str(exc).split())}",
                          monitor_seconds=time.perf_counter() - m0)
        monitor_seconds = time.perf_counter() - m0
        ev = monitored.evaluations
        alarm_times = [e.time for e in monitored.summary.alarm_events]          # typed, not re-read by key
        figures = score(ev["time"].to_numpy(), ev["statistic"].to_numpy(), ev["threshold"].to_numpy(), alarm_times,
                        scenario.fault_time, detector_persistence(monitored.options), latency_limit)
        fit = monitored.summary.fit
        if fit is not None and monitored.options.detector_class.arl0_curve:   # a design re-set by its ARL0
            figures.update(delays_at_arl0(ev["time"].to_numpy(), ev["statistic"].to_numpy(), fit.rule,
                                          scenario.fault_time))
        period = monitored.period
        if diagnose and alarm_times:
            figures.update(diagnosis_fields(out))
        if not keep_exchange:
            result.exchange_path.unlink(missing_ok=True)
        return finish(status="ok", error=None, threshold_base=(getattr(fit.rule, "base", None) or getattr(fit.rule, "h", None))
                      if fit is not None else None,
                      period=period.period if period is not None else None,
                      monitor_seconds=monitor_seconds, **figures)
    except Exception as exc:    # a bug or an unexpected environment problem: keep the sweep going
        return finish(status="failed", error=f"internal error: {type(exc).__name__}: {exc}")

"""What a monitor session found: the typed :class:`Summary`, its fault scoring and :class:`MonitorResult`.

Fault scoring has one home, :func:`score_alarms` (the sweep scores its scenarios with it).
The row written at the fault time still shows the healthy state (the change is visible from
the next row on), so an alarm at ``t <= fault_time`` cannot have been caused by the fault:
it is a false alarm.  The detection latency is measured to the first alarm after the fault.
``summary.json`` is :meth:`Summary.as_json`, written (and read by everyone) as the contract's
:class:`fourbar_common.contract.summary.MonitorSummary`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fourbar_common.contract.summary import SCHEMA_VERSION as SUMMARY_SCHEMA

from .detector import ALARM_MESSAGE, Event, Fit, State
from .options import MonitorOptions
from .grid import GridStats
from .reader import ReaderStats, RunInfo
from .spectrum import PeriodEstimate
from .threshold import ThresholdRule

__all__ = ["INDETERMINATE_EXIT", "OUTPUT_ERROR_EXIT", "FaultScore", "MonitorResult", "SCHEMA", "Summary", "Timing", "before_fault", "score_alarms"]

#: Exit status of a session whose output files could not be written (the verdict was printed).
OUTPUT_ERROR_EXIT = 4
#: Exit status of a session whose data allow no verdict (no alarm, broken time grid).
INDETERMINATE_EXIT = 5
#: Version of summary.json's layout (the contract's).
SCHEMA = SUMMARY_SCHEMA
#: Times within this of the fault time count as "at the fault time" (evaluation times are sums of floats).
FAULT_TIME_TOLERANCE = 1e-9


def before_fault(times: Any, fault_time: float | None) -> Any:
    """True where a time shows the healthy state: ``t <= fault_time`` (everywhere without a fault)."""
    t = np.asarray(times, dtype=float)
    if fault_time is None:
        return np.ones(t.shape, dtype=bool)
    return t <= float(fault_time) + FAULT_TIME_TOLERANCE


@dataclass(frozen=True)
class FaultScore:
    """Alarms scored against the fault time (``fault_time`` None: a run without a fault)."""

    fault_time: float | None
    alarm_times: tuple[float, ...]
    false_alarms: int
    detection_time: float | None

    @property
    def alarms(self) -> int:
        return len(self.alarm_times)

    @property
    def detected(self) -> bool:
        return self.detection_time is not None

    @property
    def latency(self) -> float | None:
        if self.detection_time is None or self.fault_time is None:
            return None
        return round(self.detection_time - self.fault_time, 9)


def score_alarms(alarm_times: Any, fault_time: float | None) -> FaultScore:
    """Score alarm times against the fault time (rules in the module docstring)."""
    times = tuple(sorted(float(a) for a in alarm_times))
    healthy = before_fault(times, fault_time)
    after = [t for t, h in zip(times, healthy) if not h]
    return FaultScore(None if fault_time is None else float(fault_time), times, int(np.sum(healthy)),
                      after[0] if after else None)


@dataclass(frozen=True)
class Timing:
    """Where the session's time went (wall seconds)."""

    train: float
    forecast: float
    evaluate: float
    read: float
    total: float
    per_evaluation: float | None
    simulated_span: float | None
    realtime_factor: float | None


@dataclass(frozen=True)
class Summary:
    """Everything a session found, typed; ``summary.json`` is :meth:`as_json`.

    ``score`` is None when there is no run.json (the fault time is then unknown, so alarms
    cannot be scored); ``case`` is the run's name from run.json, or the exchange file's.
    """

    status: str                         # finished | run_failed | run_interrupted | run_lost | timeout | interrupted
    error: str | None
    exchange: Path
    case: str
    options: MonitorOptions
    rows: ReaderStats
    reads_with_rows: int
    restarts: int
    samples: int
    last_time: float | None
    fits: tuple[Fit, ...]
    refits: int
    final_state: State
    evaluations: int
    max_statistic_over_threshold: float | None
    max_statistic_before_fault: float | None
    alarm_events: tuple[Event, ...]
    score: FaultScore | None
    run: RunInfo | None
    timing: Timing
    warnings: int
    grid: GridStats | None = None
    #: why the data allow no verdict (a broken time grid where it mattered), None when they do
    indeterminate: str | None = None

    # -- the figures people ask for -----------------------------------------------------------
    @property
    def signal(self) -> str:
        return self.options.signal

    @property
    def fit(self) -> Fit | None:
        """The first fit (on the training window)."""
        return self.fits[0] if self.fits else None

    @property
    def period(self) -> PeriodEstimate | None:
        return self.fit.estimate if self.fit is not None else None

    @property
    def validation_mae(self) -> float | None:
        """The largest windowed MAE of the validation model (mae detector, auto threshold), else None."""
        rule = self.fits[0].rule if self.fits else None
        return rule.details.get("validation_mae_max") if isinstance(rule, ThresholdRule) else None

    @property
    def alarms(self) -> int:
        """Alarm episodes: an alarm latches (cusum) or needs a clear first (mae), so each alarm event starts one."""
        return len(self.alarm_events)

    @property
    def first_alarm(self) -> Event | None:
        return self.alarm_events[0] if self.alarm_events else None

    @property
    def first_alarm_time(self) -> float | None:
        return self.first_alarm.time if self.first_alarm is not None else None

    @property
    def fault_time(self) -> float | None:
        return self.run.fault_time if self.run is not None else None

    @property
    def detection_latency(self) -> float | None:
        return self.score.latency if self.score is not None else None

    @property
    def false_alarms(self) -> int | None:
        return self.score.false_alarms if self.score is not None else None

    def as_json(self) -> dict[str, Any]:
        """The summary.json object (layout ``SCHEMA``, the contract's
        :data:`~fourbar_common.contract.summary.SCHEMA_VERSION`; keys in docs/monitor.md)."""
        fit = self.fit
        first = self.first_alarm
        t = self.timing
        return {
            "schema": SCHEMA,
            "status": self.status,
            "error": self.error,
            "exchange": str(self.exchange),
            "case": self.case,
            "run_id": self.run.run_id if self.run is not None else None,
            "signal": self.signal,
            "signals": list(self.options.signals),
            "detector": self.options.detector,
            "options": self.options.as_dict(),
            "rows": self.rows.as_dict(),
            "grid": self.grid.as_dict() if self.grid is not None else None,
            "indeterminate": self.indeterminate,
            "reads_with_rows": self.reads_with_rows,
            "restarts": self.restarts,
            "samples": self.samples,
            "last_time": self.last_time,
            "period": fit.estimate.as_dict() if fit else None,
            "model": fit.forecaster.settings() if fit else None,
            "fit_seconds": fit.forecaster.fit_seconds if fit else None,
            "train_seconds": fit.seconds if fit else None,
            "validation_mae": self.validation_mae,
            "threshold": fit.rule.as_dict() if fit else None,
            "fits": [f.as_dict() for f in self.fits],
            "refits": self.refits,
            "final_state": self.final_state.value,
            "evaluations": self.evaluations,
            "max_statistic_over_threshold": self.max_statistic_over_threshold,
            "max_statistic_before_fault": self.max_statistic_before_fault,
            "alarms": self.alarms,
            "alarm_episodes": [{"time": e.time, **{k: e.data[k] for k in ("signal", "side", "onset") if k in e.data}}
                               for e in self.alarm_events[:1000]],
            "alarm_times": [e.time for e in self.alarm_events[:1000]],
            "first_alarm_time": first.time if first else None,
            "first_alarm_statistic": first.statistic if first else None,
            "first_alarm_threshold": first.threshold if first else None,
            "message": ALARM_MESSAGE if first else None,
            "run_status": self.run.status if self.run else None,
            "run_error": self.run.error if self.run else None,
            "fault_time": self.fault_time,
            "detection_latency_s": self.detection_latency,
            "false_alarms_before_fault": self.false_alarms,
            "timing_s": {"train": t.train, "forecast": t.forecast, "evaluate": t.evaluate, "read": t.read,
                         "total": t.total, "per_evaluation": t.per_evaluation,
                         "simulated_span": t.simulated_span, "realtime_factor": t.realtime_factor},
            "warnings": self.warnings,
        }


@dataclass
class MonitorResult:
    """What :func:`monitor.replay` and :func:`monitor.follow` return."""

    exchange_path: Path
    summary: Summary
    events: list[dict[str, Any]]
    evaluations: Any                  # DataFrame time, mae, threshold, state
    history: Any                      # DataFrame time, <signal>, forecast (decimated when long)
    warnings: list[str] = field(default_factory=list)
    #: why the output files could not be written (they were removed); None when they were
    output_error: str | None = None

    @property
    def status(self) -> str:
        return self.summary.status

    @property
    def error(self) -> str | None:
        return self.summary.error

    @property
    def options(self) -> MonitorOptions:
        return self.summary.options

    @property
    def fits(self) -> tuple[Fit, ...]:
        return self.summary.fits

    @property
    def run_info(self) -> RunInfo | None:
        return self.summary.run

    @property
    def first_alarm_time(self) -> float | None:
        return self.summary.first_alarm_time

    @property
    def alarmed(self) -> bool:
        return self.summary.alarms > 0

    @property
    def fault_time(self) -> float | None:
        return self.summary.fault_time

    @property
    def detection_latency(self) -> float | None:
        return self.summary.detection_latency

    @property
    def false_alarms(self) -> int | None:
        return self.summary.false_alarms

    @property
    def period(self) -> PeriodEstimate | None:
        return self.summary.period

    @property
    def exit_code(self) -> int:
        """0 no alarm, 1 alarm or failed run, 3 the run was cut off (its writer died),
        4 the verdict was reached but the output files could not be written, 5 indeterminate (no alarm, but the time grid was broken in the training or monitored
        window: :attr:`Summary.indeterminate`), 130 interrupted (the command returns 143 instead
        when SIGTERM stopped it: ``fourbar_common.signals.exit_code``)."""
        if self.status == "interrupted":
            return 130
        if self.output_error is not None:
            return OUTPUT_ERROR_EXIT
        if self.status == "run_lost":
            return 3
        if self.alarmed or self.status == "run_failed":
            return 1
        return INDETERMINATE_EXIT if self.summary.indeterminate is not None else 0

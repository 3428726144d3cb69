"""monitor/summary.json, typed: :class:`MonitorSummary`, what ``fourbar-monitor`` found in one session.

The monitor writes it (:func:`write_summary`, from its own ``monitor.Summary``) and every
reader (``fourbar-diagnose``, the sweep, tests) reads it through :func:`read_summary` /
:meth:`MonitorSummary.from_json`; nobody else looks up its keys.  The field list and meanings
are docs/monitor.md's ("summary.json").

The summary's own structure is typed here (counts, the period estimate, the fits, the alarm
episodes, the timings, the outputs).  Three sections belong to the code that chose their
content and are kept as the JSON objects it wrote: ``options`` (the session's settings by name,
those of its detector included: the detector owns them), ``model`` (the forecaster's settings)
and ``threshold`` (the detector's threshold rule); a fit carries its own ``model`` and
``threshold`` the same way.

Schema :data:`SCHEMA_VERSION`.  A field absent from a file reads as its default (None, 0 or
empty): files written before it existed lack it, and a summary written by hand for
``fourbar-diagnose --summary`` may hold only ``run_id``, ``first_alarm_time`` and
``signals``.  A field present but of the wrong type, or a schema this reader does not read, is
a problem; :class:`~.problems.ContractError` lists every problem of the file.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Mapping

from .json_files import FieldReader, read_json_file, write_json_file
from .layout import SUMMARY
from .problems import ContractError, Problem

__all__ = ["AlarmEpisode", "FitRecord", "GridCounts", "GridExample", "MonitorSummary", "PeriodRecord",
           "READABLE_SCHEMAS", "RowCounts", "SCHEMA_VERSION", "SummaryOutputs", "TimingRecord", "read_summary",
           "write_summary"]

#: The schema :meth:`MonitorSummary.to_json` writes.
SCHEMA_VERSION = 1
#: The schemas :meth:`MonitorSummary.from_json` reads (a file without ``schema`` is read as 1).
READABLE_SCHEMAS = (1,)

#: A JSON value as a section owned by another part holds it (objects, arrays, scalars).
JsonValue = Any


@dataclass(frozen=True)
class RowCounts:
    """The exchange file's lines and rows read, and the rows skipped by reason."""

    lines: int = 0
    rows: int = 0
    malformed: int = 0
    non_numeric: int = 0
    non_finite: int = 0
    duplicate_time: int = 0
    decreasing_time: int = 0
    restarts: int = 0
    skipped: int = 0

    def to_json(self) -> dict:
        return {name: getattr(self, name) for name in self.__dataclass_fields__}

    @classmethod
    def read(cls, r: FieldReader) -> "RowCounts":
        return cls(**{name: r.integer(name, nullable=False, default=0) for name in cls.__dataclass_fields__})


@dataclass(frozen=True)
class GridExample:
    """One time-grid problem found: its kind, where (s), the rows concerned, what it is."""

    kind: str
    start: float | None
    end: float | None
    rows: int | None
    message: str

    def to_json(self) -> dict:
        return {"kind": self.kind, "from": self.start, "to": self.end, "rows": self.rows, "message": self.message}

    @classmethod
    def read(cls, r: FieldReader) -> "GridExample":
        return cls(kind=r.text("kind", nullable=False, default="") or "", start=r.number("from"), end=r.number("to"),
                   rows=r.integer("rows"), message=r.text("message", default="") or "")


@dataclass(frozen=True)
class GridCounts:
    """The time-grid problems of the exchange file (docs/monitor.md, "Time grid")."""

    missing_rows: int = 0
    gaps: int = 0
    skipped_gaps: int = 0
    off_grid_rows: int = 0
    duplicate_rows: int = 0
    issues: int = 0
    issues_in_window: int = 0
    examples: tuple[GridExample, ...] = ()

    def to_json(self) -> dict:
        return {"missing_rows": self.missing_rows, "gaps": self.gaps, "skipped_gaps": self.skipped_gaps,
                "off_grid_rows": self.off_grid_rows, "duplicate_rows": self.duplicate_rows, "issues": self.issues,
                "issues_in_window": self.issues_in_window, "examples": [e.to_json() for e in self.examples]}

    @classmethod
    def read(cls, r: FieldReader) -> "GridCounts":
        counts = {name: r.integer(name, nullable=False, default=0)
                  for name in ("missing_rows", "gaps", "skipped_gaps", "off_grid_rows", "duplicate_rows", "issues",
                               "issues_in_window")}
        return cls(**counts, examples=tuple(GridExample.read(e) for e in r.objects("examples")))


@dataclass(frozen=True)
class PeriodRecord:
    """The signal's period: the FFT's estimate and the refined one (s), with their quality."""

    fft_s: float | None
    refined_s: float | None
    refined_stderr_s: float | None
    fft_bin_width_hz: float | None
    refine_order: int | None
    residual_rms: float | None
    amplitude: float | None
    fft_harmonic: int | None

    def to_json(self) -> dict:
        return {name: getattr(self, name) for name in self.__dataclass_fields__}

    @classmethod
    def read(cls, r: FieldReader) -> "PeriodRecord":
        ints = ("refine_order", "fft_harmonic")
        return cls(**{name: r.integer(name) if name in ints else r.number(name) for name in cls.__dataclass_fields__})


@dataclass(frozen=True)
class FitRecord:
    """One fit of the model: on the training window, then one per refit.

    ``model`` and ``threshold`` are the forecaster's settings and the detector's threshold rule
    as they wrote them; a fit on several signals adds their common period and ``signals`` (one
    object per signal, written by the detector).
    """

    train_start: float | None
    train_end: float | None
    period: PeriodRecord | None
    model: Mapping[str, JsonValue] | None
    threshold: Mapping[str, JsonValue] | None
    seconds: float | None
    common_period_s: float | None = None
    common_period_stderr_s: float | None = None
    signals: tuple[Mapping[str, JsonValue], ...] | None = None

    def to_json(self) -> dict:
        d = {"train_start": self.train_start, "train_end": self.train_end,
             "period": self.period.to_json() if self.period is not None else None,
             "model": _plain(self.model), "threshold": _plain(self.threshold), "seconds": self.seconds}
        if self.signals is not None:
            d.update(common_period_s=self.common_period_s, common_period_stderr_s=self.common_period_stderr_s,
                     signals=[_plain(s) for s in self.signals])
        return d

    @classmethod
    def read(cls, r: FieldReader) -> "FitRecord":
        period = r.object("period")
        signals = r.value("signals", lambda v: isinstance(v, list) and all(isinstance(s, dict) for s in v),
                          "an array of objects", nullable=True)
        return cls(train_start=r.number("train_start"), train_end=r.number("train_end"),
                   period=PeriodRecord.read(period) if period is not None else None, model=r.mapping("model"),
                   threshold=r.mapping("threshold"), seconds=r.number("seconds"),
                   common_period_s=r.number("common_period_s"),
                   common_period_stderr_s=r.number("common_period_stderr_s"),
                   signals=tuple(signals) if signals is not None else None)


@dataclass(frozen=True)
class AlarmEpisode:
    """One alarm episode: its time (s) and, for a detector that says so, the signal, the side
    of the change (``up``/``down``) and its estimated onset (s); None: not said (not written)."""

    time: float
    signal: str | None = None
    side: str | None = None
    onset: float | None = None

    def to_json(self) -> dict:
        d: dict[str, Any] = {"time": self.time}
        d.update({k: getattr(self, k) for k in ("signal", "side", "onset") if getattr(self, k) is not None})
        return d

    @classmethod
    def read(cls, r: FieldReader) -> "AlarmEpisode":
        return cls(time=r.number("time", nullable=False, required=True, default=0.0), signal=r.text("signal"),
                   side=r.text("side"), onset=r.number("onset"))


@dataclass(frozen=True)
class TimingRecord:
    """Where the session's wall time went (s); the simulated span and the real-time factor."""

    train: float | None = None
    forecast: float | None = None
    evaluate: float | None = None
    read: float | None = None
    total: float | None = None
    per_evaluation: float | None = None
    simulated_span: float | None = None
    realtime_factor: float | None = None

    def to_json(self) -> dict:
        return {name: getattr(self, name) for name in self.__dataclass_fields__}

    @classmethod
    def from_reader(cls, r: FieldReader) -> "TimingRecord":
        return cls(**{name: r.number(name) for name in cls.__dataclass_fields__})


@dataclass(frozen=True)
class SummaryOutputs:
    """The files the session wrote beside summary.json (names in its folder)."""

    events: str
    evaluations: str
    forecast: str
    plots: tuple[str, ...] = ()

    def to_json(self) -> dict:
        return {"events": self.events, "evaluations": self.evaluations, "forecast": self.forecast,
                "plots": list(self.plots)}

    @classmethod
    def read(cls, r: FieldReader) -> "SummaryOutputs":
        return cls(events=r.text("events", default="") or "", evaluations=r.text("evaluations", default="") or "",
                   forecast=r.text("forecast", default="") or "", plots=r.texts("plots"))


@dataclass(frozen=True)
class MonitorSummary:
    """The content of one monitor/summary.json (module docstring; docs/monitor.md)."""

    status: str | None = None
    error: str | None = None
    exchange: str | None = None
    case: str | None = None
    run_id: str | None = None
    signal: str | None = None
    signals: tuple[str, ...] = ()
    detector: str | None = None
    options: Mapping[str, JsonValue] = field(default_factory=dict)
    rows: RowCounts = field(default_factory=RowCounts)
    grid: GridCounts | None = None
    indeterminate: str | None = None
    reads_with_rows: int = 0
    restarts: int = 0
    samples: int = 0
    last_time: float | None = None
    period: PeriodRecord | None = None
    model: Mapping[str, JsonValue] | None = None
    fit_seconds: float | None = None
    train_seconds: float | None = None
    validation_mae: float | None = None
    threshold: Mapping[str, JsonValue] | None = None
    fits: tuple[FitRecord, ...] = ()
    refits: int = 0
    final_state: str | None = None
    evaluations: int | None = None
    max_statistic_over_threshold: float | None = None
    max_statistic_before_fault: float | None = None
    alarms: int = 0
    alarm_episodes: tuple[AlarmEpisode, ...] = ()
    alarm_times: tuple[float, ...] = ()
    first_alarm_time: float | None = None
    first_alarm_statistic: float | None = None
    first_alarm_threshold: float | None = None
    message: str | None = None
    run_status: str | None = None
    run_error: str | None = None
    fault_time: float | None = None
    detection_latency_s: float | None = None
    false_alarms_before_fault: int | None = None
    timing_s: TimingRecord = field(default_factory=TimingRecord)
    warnings: int = 0
    #: the files written beside it; None in :meth:`monitor.Summary.as_json`'s object (not written yet)
    outputs: SummaryOutputs | None = None
    schema: int = SCHEMA_VERSION

    @property
    def monitored(self) -> tuple[str, ...]:
        """The monitored columns: ``signals``, else those of ``signal`` (comma-separated)."""
        return self.signals or tuple(s.strip() for s in (self.signal or "").split(",") if s.strip())

    def to_json(self) -> dict:
        """The JSON object of summary.json (keys in the order the monitor has always written them)."""
        d = {
            "schema": self.schema, "status": self.status, "error": self.error, "exchange": self.exchange,
            "case": self.case, "run_id": self.run_id, "signal": self.signal, "signals": list(self.signals),
            "detector": self.detector, "options": _plain(self.options), "rows": self.rows.to_json(),
            "grid": self.grid.to_json() if self.grid is not None else None, "indeterminate": self.indeterminate,
            "reads_with_rows": self.reads_with_rows, "restarts": self.restarts, "samples": self.samples,
            "last_time": self.last_time, "period": self.period.to_json() if self.period is not None else None,
            "model": _plain(self.model), "fit_seconds": self.fit_seconds, "train_seconds": self.train_seconds,
            "validation_mae": self.validation_mae, "threshold": _plain(self.threshold),
            "fits": [f.to_json() for f in self.fits], "refits": self.refits, "final_state": self.final_state,
            "evaluations": self.evaluations, "max_statistic_over_threshold": self.max_statistic_over_threshold,
            "max_statistic_before_fault": self.max_statistic_before_fault, "alarms": self.alarms,
            "alarm_episodes": [e.to_json() for e in self.alarm_episodes], "alarm_times": list(self.alarm_times),
            "first_alarm_time": self.first_alarm_time, "first_alarm_statistic": self.first_alarm_statistic,
            "first_alarm_threshold": self.first_alarm_threshold, "message": self.message,
            "run_status": self.run_status, "run_error": self.run_error, "fault_time": self.fault_time,
            "detection_latency_s": self.detection_latency_s,
            "false_alarms_before_fault": self.false_alarms_before_fault, "timing_s": self.timing_s.to_json(),
            "warnings": self.warnings,
        }
        if self.outputs is not None:
            d["outputs"] = self.outputs.to_json()
        return d

    @classmethod
    def from_json(cls, data: Any, source: str = SUMMARY) -> "MonitorSummary":
        """The summary in ``data`` (a parsed summary.json); :class:`ContractError` naming
        ``source`` and listing every problem (field, message) when it is not one."""
        problems: list[Problem] = []
        r = FieldReader(data, "", problems)
        schema = r.schema(READABLE_SCHEMAS)
        rows, grid, period, timing, outputs = (r.object(k) for k in ("rows", "grid", "period", "timing_s", "outputs"))
        summary = cls(
            status=r.text("status"), error=r.text("error"), exchange=r.text("exchange"), case=r.text("case"),
            run_id=r.text("run_id"), signal=r.text("signal"), signals=r.texts("signals"),
            detector=r.text("detector"), options=r.mapping("options", nullable=False) or {},
            rows=RowCounts.read(rows) if rows is not None else RowCounts(),
            grid=GridCounts.read(grid) if grid is not None else None, indeterminate=r.text("indeterminate"),
            reads_with_rows=r.integer("reads_with_rows", nullable=False, default=0),
            restarts=r.integer("restarts", nullable=False, default=0),
            samples=r.integer("samples", nullable=False, default=0), last_time=r.number("last_time"),
            period=PeriodRecord.read(period) if period is not None else None, model=r.mapping("model"),
            fit_seconds=r.number("fit_seconds"), train_seconds=r.number("train_seconds"),
            validation_mae=r.number("validation_mae"), threshold=r.mapping("threshold"),
            fits=tuple(FitRecord.read(f) for f in r.objects("fits")),
            refits=r.integer("refits", nullable=False, default=0), final_state=r.text("final_state"),
            evaluations=r.integer("evaluations"),
            max_statistic_over_threshold=r.number("max_statistic_over_threshold"),
            max_statistic_before_fault=r.number("max_statistic_before_fault"),
            alarms=r.integer("alarms", nullable=False, default=0),
            alarm_episodes=tuple(AlarmEpisode.read(e) for e in r.objects("alarm_episodes")),
            alarm_times=r.numbers("alarm_times", nullable=False) or (),
            first_alarm_time=r.number("first_alarm_time"), first_alarm_statistic=r.number("first_alarm_statistic"),
            first_alarm_threshold=r.number("first_alarm_threshold"), message=r.text("message"),
            run_status=r.text("run_status"), run_error=r.text("run_error"), fault_time=r.number("fault_time"),
            detection_latency_s=r.number("detection_latency_s"),
            false_alarms_before_fault=r.integer("false_alarms_before_fault"),
            timing_s=TimingRecord.from_reader(timing) if timing is not None else TimingRecord(),
            warnings=r.integer("warnings", nullable=False, default=0),
            outputs=SummaryOutputs.read(outputs) if outputs is not None else None, schema=schema,
        )
        if problems:
            raise ContractError(source, problems)
        return summary


def _plain(value: Any) -> Any:
    """A section kept as JSON, as a fresh plain object (a Mapping becomes a dict)."""
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def read_summary(path: str | os.PathLike[str]) -> MonitorSummary:
    """Read and check the summary.json at ``path``.

    Raises ``FileNotFoundError`` when there is none, :class:`JsonFileError` (not a regular
    file's JSON: not JSON, nested too deeply, too large, not UTF-8), ``OSError`` (a FIFO or a
    folder in its place included) and :class:`ContractError` (not a summary: every problem
    listed with its field), each naming the file.
    """
    return MonitorSummary.from_json(read_json_file(path), str(path))


def write_summary(path: str | os.PathLike[str], summary: MonitorSummary) -> None:
    """Replace ``path`` by ``summary`` atomically."""
    write_json_file(path, summary.to_json())

"""A sweep folder's own files, typed: ``sweep.json``, ``results.csv`` and ``summary.json``.

``fourbar-sweep`` (``sweep/runner.py``, ``sweep/results.py``) writes them through this module
and reads ``results.csv`` back with its columns (:data:`RESULT_COLUMNS`):

``sweep.json``   :class:`SweepRecord`: the sweep as planned (its file's settings, the FMU and
                 its GUID, the scenarios' count, the cluster, when it started).
``results.csv``  one row per scenario, the columns of :data:`RESULT_COLUMNS` in that order;
                 a cell is :func:`format_cell` of its value ('' missing, ``repr`` of a float,
                 ``True``/``False``), a row :func:`format_row`.
``summary.json`` :class:`SweepSummary`: the detection figures per series, the diagnosis
                 scoring (``[diagnose] enabled``), how the sweep ran.

The sections whose keys come from the sweep file or from the report's grouping (``fault``,
``noise``, ``monitor`` of sweep.json; each series and classification row of summary.json) are
kept as the JSON objects written.  A field absent from a file reads as its default; a field
of the wrong type, or a schema this reader does not read, is a problem, and
:class:`~.problems.ContractError` lists every problem of the file.  Neither JSON file carried
a schema before :data:`SCHEMA_VERSION` was introduced: one without ``schema`` is read as
schema 1, the one written now, and ``schema`` is not written (the files stay as they were).
"""
from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

from .json_files import FieldReader, plain_json, read_json_file, write_json_file
from .layout import SWEEP_RECORD, SWEEP_SUMMARY
from .problems import ContractError, Problem

__all__ = ["DetectorSummary", "READABLE_SCHEMAS", "RESULT_COLUMNS", "RUNTIME_COLUMNS", "SCHEMA_VERSION", "SweepRecord",
           "SweepSummary", "format_cell", "format_row", "read_sweep_record", "read_sweep_summary", "results_header",
           "write_sweep_record", "write_sweep_summary"]

#: The layout of sweep.json and summary.json (not written: files without it are this schema).
SCHEMA_VERSION = 1
#: The schemas the readers read.
READABLE_SCHEMAS = (1,)

#: Every column of results.csv, in order, and its type: str, float, int (nullable), bool (nullable).
RESULT_COLUMNS: dict[str, str] = {
    # inputs
    "scenario_id": "str", "index": "int", "variable": "str", "kind": "str", "relative_change": "float",
    "fault_value": "float", "base_value": "float", "fault_time": "float", "ramp_duration": "float",
    "noise_std": "float", "noise_seed": "int", "signal": "str", "model": "str", "threshold": "str",
    "stop": "float", "has_fault": "bool",
    # results
    "status": "str", "error": "str", "detected": "bool", "detection_time": "float", "latency": "float",
    "first_alarm_time": "float", "alarms": "int", "false_alarms": "int", "threshold_base": "float",
    "period": "float", "evaluations": "int", "statistic_max_pre": "float", "statistic_mean_pre": "float",
    "statistic_max_post": "float", "statistic_mean_post": "float", "score_pre": "float", "score_post": "float",
    "score_early": "float", "latency_limit": "float", "delay_arl0_0.1h": "float", "delay_arl0_1h": "float",
    "delay_arl0_10h": "float", "delay_arl0_100h": "float", "delay_arl0_1000h": "float", "delay_arl0_10000h": "float",
    "rows_written": "int", "fmu_guid": "str",
    "diagnosis": "str", "diagnosed_variable": "str", "diagnosed_kind": "str", "diagnosed_value": "float",
    "diagnosed_time": "float", "diagnosed_end_time": "float", "diagnosed_runner_up": "str",
    # how it ran (differ between otherwise identical runs)
    "run_seconds": "float", "monitor_seconds": "float", "diagnosis_seconds": "float", "wall_seconds": "float",
    "cpu_seconds": "float", "worker": "str",
}
#: Columns that describe how a row was computed (time, place), not what it found.
RUNTIME_COLUMNS = ("run_seconds", "monitor_seconds", "diagnosis_seconds", "wall_seconds", "cpu_seconds", "worker")


# ------------------------------------------------------------------------------------ results.csv

def format_cell(value: Any) -> str:
    """One CSV field: '' for missing (None, NaN, pandas' NA), ``repr`` for floats (read back
    exactly), ``True``/``False`` for booleans, the integer's digits for integers."""
    if value is None or type(value).__name__ == "NAType":
        return ""
    if isinstance(value, bool) or type(value).__name__ == "bool_":
        return "True" if value else "False"
    if isinstance(value, float) or type(value).__name__.startswith("float"):
        v = float(value)
        return "" if math.isnan(v) else repr(v)
    if isinstance(value, int) or type(value).__name__.startswith(("int", "uint")):
        return str(int(value))
    return str(value)


def format_row(row: Mapping[str, Any]) -> str:
    """One line of results.csv (``\\n``-terminated): ``row``'s value of every column of
    :data:`RESULT_COLUMNS` (absent: missing), quoted as the csv module does."""
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow([format_cell(row.get(name)) for name in RESULT_COLUMNS])
    return buf.getvalue()


def results_header(extra: Sequence[str] = ()) -> str:
    """The first line of results.csv (with ``extra`` column names: stale.csv's)."""
    return ",".join([*RESULT_COLUMNS, *extra]) + "\n"


# ------------------------------------------------------------------------------------ the JSON files

def _section(r: FieldReader, key: str) -> Mapping[str, Any] | None:
    return r.mapping(key)


def _sections(r: FieldReader, key: str) -> tuple[Mapping[str, Any], ...]:
    items = r.value(key, lambda v: isinstance(v, list) and all(isinstance(x, dict) for x in v),
                    "an array of objects", default=[]) or []
    return tuple(items)


@dataclass(frozen=True)
class SweepRecord:
    """The content of sweep.json: the sweep file's settings as planned, and how it was started.

    ``fault``, ``noise``, ``monitor``, ``sample``, ``report``, ``output`` and ``diagnose`` are
    the sweep file's tables as read (docs/sweep.md).
    """

    name: str
    description: str = ""
    sweep_file: str | None = None
    case_file: str | None = None
    fmu: str | None = None
    fmu_guid: str | None = None
    stop: float | None = None
    fault: Mapping[str, Any] = field(default_factory=dict)
    noise: Mapping[str, Any] = field(default_factory=dict)
    monitor: Mapping[str, Any] = field(default_factory=dict)
    sample: Mapping[str, Any] | None = None
    report: Mapping[str, Any] = field(default_factory=dict)
    output: Mapping[str, Any] = field(default_factory=dict)
    diagnose: Mapping[str, Any] = field(default_factory=dict)
    scenarios: int | None = None
    out_dir: str | None = None
    cluster: str | None = None
    started_at: str | None = None
    schema: int = SCHEMA_VERSION

    def to_json(self) -> dict:
        """The JSON object of sweep.json (its keys in the order fourbar-sweep has always written them)."""
        return {"name": self.name, "description": self.description, "sweep_file": self.sweep_file,
                "case_file": self.case_file, "fmu": self.fmu, "fmu_guid": self.fmu_guid, "stop": self.stop,
                "fault": dict(self.fault), "noise": dict(self.noise), "monitor": dict(self.monitor),
                "sample": dict(self.sample) if self.sample is not None else None, "report": dict(self.report),
                "output": dict(self.output), "diagnose": dict(self.diagnose), "scenarios": self.scenarios,
                "out_dir": self.out_dir, "cluster": self.cluster, "started_at": self.started_at}

    @classmethod
    def from_json(cls, data: Any, source: str = SWEEP_RECORD) -> "SweepRecord":
        """The record in ``data``; :class:`ContractError` listing every problem when it is not one."""
        problems: list[Problem] = []
        r = FieldReader(data, "", problems)
        record = cls(
            name=r.text("name", nullable=False, required=True, default="") or "",
            description=r.text("description", default="") or "", sweep_file=r.text("sweep_file"),
            case_file=r.text("case_file"), fmu=r.text("fmu"), fmu_guid=r.text("fmu_guid"), stop=r.number("stop"),
            fault=_section(r, "fault") or {}, noise=_section(r, "noise") or {}, monitor=_section(r, "monitor") or {},
            sample=_section(r, "sample"), report=_section(r, "report") or {}, output=_section(r, "output") or {},
            diagnose=_section(r, "diagnose") or {}, scenarios=r.integer("scenarios"), out_dir=r.text("out_dir"),
            cluster=r.text("cluster"), started_at=r.text("started_at"), schema=r.schema(READABLE_SCHEMAS))
        if problems:
            raise ContractError(source, problems)
        return record


@dataclass(frozen=True)
class DetectorSummary:
    """The sweep's detector as the report describes it: its name, in-control ARL (h) and
    evaluation interval (s); None where the detector has none."""

    name: str
    arl0_hours: float | None = None
    every: float | None = None

    def to_json(self) -> dict:
        return {"name": self.name, "arl0_hours": self.arl0_hours, "every": self.every}


@dataclass(frozen=True)
class SweepSummary:
    """The content of a sweep's summary.json (docs/sweep.md, "Summary").

    ``series``: one object per series of scenarios (the key fields that group them, their
    label, the detection figures per fault size, the fault-free runs); ``classification``: one
    object per fault of the diagnosis scoring (present only with ``[diagnose] enabled``).
    """

    variable: str | None
    variables: tuple[str, ...]
    unit: str
    detector: DetectorSummary | None
    latency_limit: float | None
    scenarios: int
    ok: int
    failed: int
    series: tuple[Mapping[str, Any], ...] = ()
    classification: tuple[Mapping[str, Any], ...] | None = None
    name: str | None = None
    planned: int | None = None
    skipped: int | None = None
    ran: int | None = None
    interrupted: bool | None = None
    wall_seconds: float | None = None
    finished_at: str | None = None
    schema: int = SCHEMA_VERSION

    def to_json(self) -> dict:
        """The JSON object of summary.json (keys in the order fourbar-sweep has always written them)."""
        d: dict[str, Any] = {
            "variable": self.variable, "variables": list(self.variables), "unit": self.unit,
            "detector": self.detector.to_json() if self.detector is not None else None,
            "latency_limit": self.latency_limit, "scenarios": self.scenarios, "ok": self.ok, "failed": self.failed,
            "series": [dict(s) for s in self.series]}
        if self.classification is not None:
            d["classification"] = [dict(c) for c in self.classification]
        d.update(name=self.name, planned=self.planned, skipped=self.skipped, ran=self.ran,
                 interrupted=self.interrupted, wall_seconds=self.wall_seconds, finished_at=self.finished_at)
        return d

    @classmethod
    def from_json(cls, data: Any, source: str = SWEEP_SUMMARY) -> "SweepSummary":
        """The summary in ``data``; :class:`ContractError` listing every problem when it is not one."""
        problems: list[Problem] = []
        r = FieldReader(data, "", problems)
        detector = r.object("detector")
        summary = cls(
            variable=r.text("variable"), variables=r.texts("variables"), unit=r.text("unit", default="") or "",
            detector=None if detector is None else DetectorSummary(
                name=detector.text("name", nullable=False, required=True, default="") or "",
                arl0_hours=detector.number("arl0_hours"), every=detector.number("every")),
            latency_limit=r.number("latency_limit"), scenarios=r.integer("scenarios", nullable=False, default=0),
            ok=r.integer("ok", nullable=False, default=0), failed=r.integer("failed", nullable=False, default=0),
            series=_sections(r, "series"),
            classification=_sections(r, "classification") if "classification" in r.data else None,
            name=r.text("name"), planned=r.integer("planned"), skipped=r.integer("skipped"), ran=r.integer("ran"),
            interrupted=r.flag("interrupted"), wall_seconds=r.number("wall_seconds"),
            finished_at=r.text("finished_at"), schema=r.schema(READABLE_SCHEMAS))
        if problems:
            raise ContractError(source, problems)
        return summary


def _write(path: str | os.PathLike[str], record: Any) -> None:
    write_json_file(path, record.to_json())


def read_sweep_record(path: str | os.PathLike[str]) -> SweepRecord:
    """Read and check a sweep.json (errors as :func:`~.summary.read_summary`'s)."""
    return SweepRecord.from_json(read_json_file(path), str(path))


def write_sweep_record(path: str | os.PathLike[str], data: Mapping[str, Any],
                       default: Callable[[Any], Any] | None = str) -> SweepRecord:
    """Write sweep.json from the sweep's description ``data`` (``default`` converts what JSON has
    no type for, such as a path), checked by :meth:`SweepRecord.from_json`; return the record."""
    record = SweepRecord.from_json(plain_json(data, default=default), str(path))
    _write(path, record)
    return record


def read_sweep_summary(path: str | os.PathLike[str]) -> SweepSummary:
    """Read and check a sweep's summary.json (errors as :func:`~.summary.read_summary`'s)."""
    return SweepSummary.from_json(read_json_file(path), str(path))


def write_sweep_summary(path: str | os.PathLike[str], data: Mapping[str, Any],
                        default: Callable[[Any], Any] | None = str) -> SweepSummary:
    """Write a sweep's summary.json from the report's figures ``data``, checked by
    :meth:`SweepSummary.from_json`; return the summary."""
    summary = SweepSummary.from_json(plain_json(data, default=default), str(path))
    _write(path, summary)
    return summary

"""diagnosis/diagnosis.json, typed: :class:`DiagnosisRecord`, the verdict ``fourbar-diagnose`` writes.

``fourbar-diagnose`` computes a ``diagnose.Diagnosis`` (which holds more: the curves it plots)
and writes its :meth:`~diagnose.Diagnosis.record`, this file's content, with
:func:`write_diagnosis`; the view, the orchestrator and the tests read it with
:func:`read_diagnosis` / :meth:`DiagnosisRecord.from_json`.  The fields and their meaning are
docs/diagnose.md's; every non-finite number (an infinite standard error, say) is written as
null.

Schema :data:`SCHEMA_VERSION`.  A field absent from a file reads as its default (files
written before it existed lack it); ``verdict`` is required.  A field of the wrong type, or a
schema this reader does not read, is a problem; :class:`~.problems.ContractError` lists every
problem of the file.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Mapping

from .json_files import FieldReader, is_number, read_json_file, write_json_file
from .layout import DIAGNOSIS
from .problems import ContractError, Problem

__all__ = ["DiagnosedFit", "DiagnosisRecord", "READABLE_SCHEMAS", "SCHEMA_VERSION", "SeparatingColumn", "Settlement",
           "VERDICTS", "read_diagnosis", "write_diagnosis"]

#: The schema :meth:`DiagnosisRecord.to_json` writes.
SCHEMA_VERSION = 1
#: The schemas :meth:`DiagnosisRecord.from_json` reads.
READABLE_SCHEMAS = (1,)
#: What a diagnosis can conclude.
VERDICTS = ("explained", "ambiguous", "unexplained", "no_change")


@dataclass(frozen=True)
class DiagnosedFit:
    """One hypothesis fitted: ``parameter`` changed as a ``step`` or a ``ramp`` (times in s,
    values in the parameter's unit; None where the number was not finite)."""

    parameter: str
    kind: str                          # step | ramp
    before: float | None
    value: float | None
    stderr: float | None
    change_time: float | None
    end_time: float | None
    chi2: float | None
    rows: int | None
    rms: float | None
    evaluations: int | None
    refused: str | None = None
    open_end: bool = False
    at_bound: bool = False
    change: float | None = None
    relative_change: float | None = None

    def to_json(self) -> dict:
        return {name: getattr(self, name) for name in self.__dataclass_fields__}

    @classmethod
    def read(cls, r: FieldReader) -> "DiagnosedFit":
        return cls(parameter=r.text("parameter", nullable=False, required=True, default="") or "",
                   kind=r.choice("kind", ("step", "ramp"), required=True, default="step") or "step",
                   before=r.number("before"), value=r.number("value"), stderr=r.number("stderr"),
                   change_time=r.number("change_time"), end_time=r.number("end_time"), chi2=r.number("chi2"),
                   rows=r.integer("rows"), rms=r.number("rms"), evaluations=r.integer("evaluations"),
                   refused=r.text("refused"), open_end=bool(r.flag("open_end", default=False)),
                   at_bound=bool(r.flag("at_bound", default=False)), change=r.number("change"),
                   relative_change=r.number("relative_change"))


@dataclass(frozen=True)
class SeparatingColumn:
    """An output that tells the best two explanations apart: the RMS of the difference of their
    simulations (``difference``, in ``unit``) and that as a share of the column's swing."""

    column: str
    difference: float | None
    unit: str
    share: float | None

    def to_json(self) -> dict:
        return {"column": self.column, "difference": self.difference, "unit": self.unit, "share": self.share}

    @classmethod
    def read(cls, r: FieldReader) -> "SeparatingColumn":
        return cls(column=r.text("column", nullable=False, required=True, default="") or "",
                   difference=r.number("difference"), unit=r.text("unit", default="") or "", share=r.number("share"))


@dataclass(frozen=True)
class Settlement:
    """Two explanations the first window could not tell apart, fitted again on ``window``."""

    window: tuple[float, float] | None
    runner_up: DiagnosedFit | None
    first_gap: float | None
    distinct_gap: float | None

    def to_json(self) -> dict:
        return {"window": _list(self.window), "runner_up": _fit(self.runner_up), "first_gap": self.first_gap,
                "distinct_gap": self.distinct_gap}

    @classmethod
    def read(cls, r: FieldReader) -> "Settlement":
        runner_up = r.object("runner_up")
        return cls(window=_pair(r, "window"), runner_up=DiagnosedFit.read(runner_up) if runner_up else None,
                   first_gap=r.number("first_gap"), distinct_gap=r.number("distinct_gap"))


@dataclass(frozen=True)
class DiagnosisRecord:
    """The content of one diagnosis.json (module docstring; docs/diagnose.md)."""

    verdict: str
    message: str = ""
    case: str = ""
    run_id: str | None = None
    best: DiagnosedFit | None = None
    ramp: DiagnosedFit | None = None
    ranking: tuple[DiagnosedFit, ...] = ()
    alarm_time: float | None = None
    onset_time: float | None = None
    window: tuple[float, float] | None = None
    rows: int | None = None
    columns: tuple[str, ...] = ()
    units: Mapping[str, str] = field(default_factory=dict)
    noise: Mapping[str, float | None] = field(default_factory=dict)
    value_window: tuple[float, float] | None = None
    first_fit: DiagnosedFit | None = None
    separating: tuple[SeparatingColumn, ...] = ()
    distinct_gap: float | None = None
    settled: Settlement | None = None
    healthy_chi2: float | None = None
    reduced_chi2: float | None = None
    simulator: str = ""
    branches: int | None = None
    seconds: float | None = None
    schema: int = SCHEMA_VERSION

    def to_json(self) -> dict:
        """The JSON object of diagnosis.json (keys in the order fourbar-diagnose has always written them)."""
        return {
            "schema": self.schema, "case": self.case, "run_id": self.run_id, "verdict": self.verdict,
            "message": self.message, "best": _fit(self.best), "ramp": _fit(self.ramp),
            "ranking": [f.to_json() for f in self.ranking], "alarm_time": self.alarm_time,
            "onset_time": self.onset_time, "window": _list(self.window), "rows": self.rows,
            "columns": list(self.columns), "units": dict(self.units), "noise": dict(self.noise),
            "value_window": _list(self.value_window), "first_fit": _fit(self.first_fit),
            "separating": [c.to_json() for c in self.separating], "distinct_gap": self.distinct_gap,
            "settled": self.settled.to_json() if self.settled is not None else None,
            "healthy_chi2": self.healthy_chi2, "reduced_chi2": self.reduced_chi2, "simulator": self.simulator,
            "branches": self.branches, "seconds": self.seconds,
        }

    @classmethod
    def from_json(cls, data: Any, source: str = DIAGNOSIS) -> "DiagnosisRecord":
        """The diagnosis in ``data`` (a parsed diagnosis.json); :class:`ContractError` naming
        ``source`` and listing every problem (field, message) when it is not one."""
        problems: list[Problem] = []
        r = FieldReader(data, "", problems)
        schema = r.schema(READABLE_SCHEMAS)
        fits = {key: r.object(key) for key in ("best", "ramp", "first_fit")}
        settled = r.object("settled")
        units = r.value("units", lambda v: isinstance(v, dict) and all(isinstance(x, str) for x in v.values()),
                        "an object column = unit (strings)", default={}) or {}
        noise = r.value("noise", lambda v: isinstance(v, dict) and all(x is None or is_number(x) for x in v.values()),
                        "an object column = noise (numbers or null)", default={}) or {}
        record = cls(
            verdict=r.choice("verdict", VERDICTS, required=True, default="") or "",
            message=r.text("message", default="") or "", case=r.text("case", default="") or "",
            run_id=r.text("run_id"), best=_read_fit(fits["best"]), ramp=_read_fit(fits["ramp"]),
            ranking=tuple(DiagnosedFit.read(f) for f in r.objects("ranking")), alarm_time=r.number("alarm_time"),
            onset_time=r.number("onset_time"), window=_pair(r, "window"), rows=r.integer("rows"),
            columns=r.texts("columns"), units=dict(units), noise=dict(noise), value_window=_pair(r, "value_window"),
            first_fit=_read_fit(fits["first_fit"]),
            separating=tuple(SeparatingColumn.read(c) for c in r.objects("separating")),
            distinct_gap=r.number("distinct_gap"), settled=Settlement.read(settled) if settled else None,
            healthy_chi2=r.number("healthy_chi2"), reduced_chi2=r.number("reduced_chi2"),
            simulator=r.text("simulator", default="") or "", branches=r.integer("branches"),
            seconds=r.number("seconds"), schema=schema,
        )
        if problems:
            raise ContractError(source, problems)
        return record


def _read_fit(r: FieldReader | None) -> DiagnosedFit | None:
    return DiagnosedFit.read(r) if r is not None else None


def _fit(fit: DiagnosedFit | None) -> dict | None:
    return fit.to_json() if fit is not None else None


def _pair(r: FieldReader, key: str) -> tuple[float, float] | None:
    pair = r.numbers(key, length=2)
    return (pair[0], pair[1]) if pair is not None else None


def _list(pair: tuple[float, float] | None) -> list | None:
    return list(pair) if pair is not None else None


def read_diagnosis(path: str | os.PathLike[str]) -> DiagnosisRecord:
    """Read and check the diagnosis.json at ``path``.

    Raises ``FileNotFoundError`` when there is none, ``JsonFileError`` (not JSON, nested too
    deeply, too large, not UTF-8), ``OSError`` (a FIFO or a folder in its place included) and
    :class:`ContractError` (not a diagnosis: every problem listed with its field), each naming
    the file.
    """
    return DiagnosisRecord.from_json(read_json_file(path), str(path))


def write_diagnosis(path: str | os.PathLike[str], record: DiagnosisRecord) -> None:
    """Replace ``path`` by ``record`` atomically."""
    write_json_file(path, record.to_json())

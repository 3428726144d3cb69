"""run.json, typed: :class:`RunRecord`, the record ``fourbar-run`` writes beside each exchange file.

One home for the file's schema: the orchestrator writes through :func:`write_run_record`
and every reader (monitor, diagnose, view) goes through :func:`read_run_record` /
:meth:`RunRecord.from_json`, so no reader looks up dict keys of its own.

Schema 2 (written now) records the start value of *every* parameter the FMU declares
(causality ``parameter``: tunable and fixed; Real, Integer, Enumeration, Boolean and String),
whether the case set it or not, each with its :attr:`ParameterStart.source`:

``case``  the case file's ``[parameters]`` table (or a :class:`~orchestrator.Case` built in code);
``set``   an override: ``fourbar-run --set NAME=VALUE``, ``run_case(..., overrides=...)``, a sweep's values;
``fmu``   not set by the run: the FMU's own start value from its modelDescription.xml.

Schema 1 (written before) is still read: its flat ``"parameters"`` held only the values the
case set, with no source (:attr:`ParameterStart.source` ``"unknown"``), and any field may be
absent (the fields it lacks are None).  :meth:`RunRecord.completed_with` adds the FMU's
defaults to such a record.  A schema 2 record is checked in full: every field present and of
its type; a problem raises :class:`RunRecordError` (a
:class:`~.problems.ContractError` whose one problem names the field) naming the file and the field.  Keys this
reader does not know are ignored (a newer writer may add some).  The one optional field is
``drawing`` (:class:`~fourbar_common.drawing.Drawing`, or null): records written before
drawings lack it and read as None.

Standard library only.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Iterable, Mapping, NoReturn

from ..drawing import Drawing, DrawingError
from ..events import Event, RampEvent, StepEvent, Value
from .json_files import (JsonFileError, is_int, is_number, kind_of, parse_json, read_text_file, show_json,
                         write_json_file)
from .layout import RUN_RECORD
from .problems import ContractError, Problem
from .system_record import RecordedSystem

__all__ = [
    "PARAMETER_SOURCES",
    "ParameterStart",
    "READABLE_SCHEMAS",
    "RecordedExchange",
    "RecordedExperiment",
    "RecordedFmu",
    "RecordedInput",
    "RecordedNoise",
    "RecordedWriter",
    "RUN_STATUSES",
    "RunRecord",
    "RunRecordError",
    "SCHEMA_VERSION",
    "read_run_record",
    "write_run_record",
]

#: The schema :meth:`RunRecord.to_json` writes.
SCHEMA_VERSION = 2
#: The schemas :meth:`RunRecord.from_json` reads.
READABLE_SCHEMAS = (1, 2)
#: ``status``: ``running`` while the writer lives, then one of the other three.
RUN_STATUSES = ("running", "finished", "failed", "interrupted")
#: Where a parameter's start value came from (``unknown``: a schema 1 record).
PARAMETER_SOURCES = ("case", "set", "fmu", "ssp", "unknown")
_WRITTEN_SOURCES = ("case", "set", "fmu", "ssp")
_PARAMETER_TYPES = ("Real", "Integer", "Enumeration", "Boolean", "String")
_VARIABILITIES = ("fixed", "tunable")



class RunRecordError(ContractError):
    """run.json is unreadable or not a run record this reader understands.

    The message names the file, the field, the value found and what was expected;
    :attr:`problems` holds that one problem as (field, message) (field ``""``: the file as a
    whole).
    """

    def __init__(self, source: str, problem: Problem, message: str):
        super().__init__(source, (problem,))
        self.args = (message,)

    def __reduce__(self):
        return self.__class__, (self.source, self.problems[0], self.args[0])


def _file_error(path: Any, message: str) -> RunRecordError:
    """A problem of the file as a whole; ``message`` is the whole text, naming the file."""
    prefix = f"{path}: "
    return RunRecordError(str(path), Problem("", message[len(prefix):] if message.startswith(prefix) else message),
                          message)


# ------------------------------------------------------------------------------------ the parts

@dataclass(frozen=True)
class RecordedFmu:
    """The FMU the run used: its path, GUID, model name and the FMI interface the run used
    ("CoSimulation" or "ModelExchange"; records without it are co-simulation runs)."""

    path: str
    guid: str
    model_name: str
    fmi_type: str = "CoSimulation"

    def to_json(self) -> dict:
        return {"path": self.path, "guid": self.guid, "model_name": self.model_name, "fmi_type": self.fmi_type}


@dataclass(frozen=True)
class RecordedExperiment:
    """Time span and communication grid (s); ``tolerance`` None: the FMU's own."""

    start: float
    stop: float
    step: float
    tolerance: float | None = None

    def to_json(self) -> dict:
        return {"start": self.start, "stop": self.stop, "step": self.step, "tolerance": self.tolerance}


@dataclass(frozen=True)
class ParameterStart:
    """The start value one parameter of the FMU had in this run, and where it came from.

    ``start`` is None only for an FMU parameter that declares no start value.  ``type``,
    ``variability`` and ``unit`` are the FMU's declaration (``variability`` None: a schema 1
    record, which did not say).
    """

    name: str
    start: Value | None
    source: str                      # one of PARAMETER_SOURCES
    type: str                        # Real | Integer | Enumeration | Boolean | String
    variability: str | None = None   # tunable | fixed
    unit: str | None = None

    @property
    def tunable(self) -> bool:
        return self.variability == "tunable"

    def to_json(self) -> dict:
        return {"start": self.start, "source": self.source, "type": self.type,
                "variability": self.variability, "unit": self.unit}




@dataclass(frozen=True)
class RecordedInput:
    """An FMU input the case drove (``[inputs]``): its name and its signal as the case gave it,
    ``{"type": "sine", "amplitude": ..., ...}`` (a CSV column also records its file's row count
    and SHA-256).  Its values are the input's column of the exchange file."""

    name: str
    signal: Mapping[str, Any]

    @property
    def kind(self) -> str:
        return str(self.signal.get("type", ""))


@dataclass(frozen=True)
class RecordedNoise:
    """Measurement noise added to the written values: seed and standard deviation per output."""

    seed: int
    std: Mapping[str, float]

    def to_json(self) -> dict:
        return {"seed": self.seed, "std": dict(self.std)}


@dataclass(frozen=True)
class RecordedExchange:
    """How the exchange file was written; ``max_rows``: the most rows the run was allowed
    (None: not recorded)."""

    flush_interval: float
    realtime_factor: float
    max_rows: int | None = None

    def to_json(self) -> dict:
        return {"flush_interval": self.flush_interval, "realtime_factor": self.realtime_factor,
                "max_rows": self.max_rows}


@dataclass(frozen=True)
class RecordedWriter:
    """The process writing the record and its heartbeat period (s)."""

    pid: int
    host: str
    heartbeat_s: float

    def alive(self) -> bool | None:
        """Whether the writing process still exists: None when it cannot be told from here
        (another host); a process id reused within a run is not detected."""
        import socket

        if self.host != socket.gethostname():
            return None
        try:
            os.kill(self.pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:          # exists, owned by someone else
            return True
        return True

    def to_json(self) -> dict:
        return {"pid": self.pid, "host": self.host, "heartbeat_s": self.heartbeat_s}


# ------------------------------------------------------------------------------------ the record

@dataclass(frozen=True)
class RunRecord:
    """The content of one run.json (module docstring).

    Fields that may be None in any record: ``case_file``, ``fault_time``, ``noise``,
    ``last_time``, ``updated_at``, ``finished_at``, ``error``.  The others are None only in a
    schema 1 record that lacked them (``schema`` says which schema was read).
    """

    status: str
    run_id: str | None
    case: str | None
    fmu: RecordedFmu | None
    experiment: RecordedExperiment | None
    parameters: tuple[ParameterStart, ...] = ()
    events: tuple[Event, ...] = ()
    outputs: tuple[str, ...] = ()
    units: Mapping[str, str] = field(default_factory=dict)
    case_file: str | None = None
    description: str = ""
    fault_time: float | None = None
    noise: RecordedNoise | None = None
    exchange: RecordedExchange | None = None
    rows_written: int | None = 0
    last_time: float | None = None
    started_at: str | None = None
    updated_at: str | None = None
    finished_at: str | None = None
    wall_time_s: float | None = 0.0
    error: str | None = None
    writer: RecordedWriter | None = None
    #: How to draw the mechanism (the FMU's drawing annotation); None when the FMU declares
    #: none, the run recorded no drawing columns, or the record predates drawings.
    drawing: Drawing | None = None
    #: The inputs the case drove (optional: records without inputs, or written before them, have none).
    inputs: tuple[RecordedInput, ...] = ()
    #: The order of the input derivatives set at each step's start (0: inputs held over the step).
    input_derivatives: int = 0
    #: The system of FMUs a system run ran (fourbar_common.contract.system_record); None: one FMU.
    system: RecordedSystem | None = None
    schema: int = SCHEMA_VERSION

    # -- what readers ask -------------------------------------------------------------
    @property
    def ended(self) -> bool:
        """True when the record says the run will not append any more rows."""
        return self.status in ("finished", "failed", "interrupted")

    @property
    def start_values(self) -> dict[str, Value]:
        """Every recorded parameter start value by name (schema 1's flat ``parameters``
        mapping, now complete): the healthy model of the run."""
        return {p.name: p.start for p in self.parameters if p.start is not None}

    @property
    def sources(self) -> dict[str, str]:
        """Where each recorded start value came from, by name (``case``, ``set``, ``fmu``)."""
        return {p.name: p.source for p in self.parameters}

    def parameter(self, name: str) -> ParameterStart | None:
        """The entry of parameter ``name``, None when the record has none."""
        return next((p for p in self.parameters if p.name == name), None)

    @property
    def complete(self) -> bool:
        """True when every parameter of the FMU is recorded (schema 2)."""
        return self.schema >= 2

    def completed_with(self, defaults: Iterable[ParameterStart]) -> "RunRecord":
        """This record with ``defaults`` (the FMU's own start values, source ``fmu``) added for
        every parameter it lacks, and the declaration (type, variability, unit) of those it
        has but without one (schema 1).  Order: ``defaults``' (the FMU's), then the rest."""
        recorded = {p.name: p for p in self.parameters}
        merged: list[ParameterStart] = []
        for default in defaults:
            mine = recorded.pop(default.name, None)
            if mine is None:
                merged.append(default)
            else:
                merged.append(replace(mine, type=default.type, variability=mine.variability or default.variability,
                                      unit=mine.unit if mine.unit is not None else default.unit))
        merged.extend(recorded.values())
        return replace(self, parameters=tuple(merged))

    # -- JSON -------------------------------------------------------------------------
    def to_json(self) -> dict:
        """The JSON object of run.json, schema :data:`SCHEMA_VERSION`.  A record read from a
        schema 1 file is read-only (ValueError): it lacks what schema 2 requires."""
        if self.schema != SCHEMA_VERSION:
            raise ValueError(f"a schema {self.schema} record is read-only; only schema {SCHEMA_VERSION} is written")
        data = {
            "schema": SCHEMA_VERSION, "status": self.status, "run_id": self.run_id, "case": self.case,
            "case_file": self.case_file, "description": self.description,
            "fmu": self.fmu.to_json() if self.fmu is not None else None,
            "experiment": self.experiment.to_json() if self.experiment is not None else None,
            "parameters": {p.name: p.to_json() for p in self.parameters},
            "events": [e.as_dict() for e in self.events],
            "fault_time": self.fault_time,
            "outputs": list(self.outputs),
            "units": dict(self.units),
            "noise": self.noise.to_json() if self.noise is not None else None,
            "exchange": self.exchange.to_json() if self.exchange is not None else None,
            "rows_written": self.rows_written, "last_time": self.last_time,
            "started_at": self.started_at, "updated_at": self.updated_at, "finished_at": self.finished_at,
            "wall_time_s": self.wall_time_s, "error": self.error,
            "writer": self.writer.to_json() if self.writer is not None else None,
            "drawing": self.drawing.to_json() if self.drawing is not None else None,
            "inputs": {i.name: dict(i.signal) for i in self.inputs},
            "input_derivatives": self.input_derivatives,
            "system": self.system.to_json() if self.system is not None else None,   # null: one FMU
        }
        return data

    @classmethod
    def from_json(cls, data: Any, source: str = RUN_RECORD) -> "RunRecord":
        """The record in ``data`` (a parsed run.json); :class:`RunRecordError` naming
        ``source`` and the field when it is not a record of a readable schema."""
        return _Parser(source).record(data)


# ------------------------------------------------------------------------------------ reading files

#: The fields a record of every schema has: a JSON object with none of them is not a run record.
_RECORD_FIELDS = ("schema", "status", "run_id", "case", "experiment", "rows_written")


def read_run_record(path: str | os.PathLike[str]) -> RunRecord:
    """Read and check the run.json at ``path``.

    Raises ``FileNotFoundError`` when there is none, :class:`RunRecordError` (naming the file
    and, for a bad record, the field) when it cannot be read, is not a regular file, is
    empty, is not JSON (or nested too deeply, or over :data:`MAX_JSON_BYTES`) or is not a
    record (an empty object ``{}`` included: the message lists the fields it lacks).
    """
    path = Path(path)
    try:
        text = read_text_file(path)
    except FileNotFoundError:
        raise
    except (OSError, JsonFileError) as exc:
        raise _file_error(path, f"{path}: cannot read: {exc}" if not str(exc).startswith(str(path))
                          else str(exc)) from None
    if not text.strip():
        raise _file_error(path, f"{path}: is empty ({len(text.encode())} bytes): not a run record; expected the "
                          f"JSON object fourbar-run writes, with fields {', '.join(_RECORD_FIELDS)}, ...")
    try:
        data = parse_json(text, str(path))
    except JsonFileError as exc:
        raise _file_error(path, str(exc)) from None
    return RunRecord.from_json(data, str(path))


def write_run_record(path: str | os.PathLike[str], record: RunRecord) -> None:
    """Replace ``path`` by ``record`` atomically (a reader sees the old record or the new one)."""
    write_json_file(path, record.to_json())


# ------------------------------------------------------------------------------------ checking

class _Parser:
    """Checks one parsed run.json; every complaint names ``source`` and the dotted field."""

    def __init__(self, source: str):
        self.source = source
        self.lenient = False       # schema 1: absent fields are None

    # -- primitives -------------------------------------------------------------------
    def error(self, where: str, text: str) -> RunRecordError:
        """The error of field ``where`` (``""``: the record as a whole); ``text`` follows the
        file's name in the message."""
        lead = f"field '{where}' "
        return RunRecordError(self.source, Problem(where, text[len(lead):] if text.startswith(lead) else text),
                              f"{self.source}: {text}")

    def fail(self, where: str, value: Any, expected: str) -> NoReturn:
        raise self.error(where, f"field '{where}' = {show_json(value)}: expected {expected}")

    def get(self, obj: dict, key: str, prefix: str, check, expected: str, *, nullable: bool = False,
            default: Any = None) -> Any:
        where = f"{prefix}{key}"
        if key not in obj:
            if self.lenient:
                return default
            raise self.error(where, f"field '{where}' is missing: expected {expected}"
                                 f"{' or null' if nullable else ''} (every run.json of schema {SCHEMA_VERSION} "
                                 f"that fourbar-run writes has it)")
        value = obj[key]
        if value is None and (nullable or self.lenient):
            return default if not nullable else None
        if not check(value):
            self.fail(where, value, expected + (" or null" if nullable else ""))
        return value

    is_number = staticmethod(is_number)
    is_int = staticmethod(is_int)

    @staticmethod
    def is_text(v: Any) -> bool:
        return isinstance(v, str)

    @staticmethod
    def is_object(v: Any) -> bool:
        return isinstance(v, dict)

    def number(self, obj, key, prefix, *, nullable=False, default=None) -> float | None:
        v = self.get(obj, key, prefix, self.is_number, "a finite number", nullable=nullable, default=default)
        return float(v) if v is not None else None

    def text(self, obj, key, prefix, *, nullable=False, default=None) -> str | None:
        return self.get(obj, key, prefix, self.is_text, "a string", nullable=nullable, default=default)

    def obj(self, obj, key, prefix, *, nullable=False) -> dict | None:
        return self.get(obj, key, prefix, self.is_object, "an object", nullable=nullable)

    # -- the record -------------------------------------------------------------------
    def record(self, data: Any) -> RunRecord:
        if not isinstance(data, dict):
            raise self.error("", f"the top level is {kind_of(data)}; expected a JSON object written "
                                 f"by fourbar-run")
        if not any(name in data for name in _RECORD_FIELDS):
            raise self.error("", f"not a run record: fields {', '.join(_RECORD_FIELDS)} are missing"
                                 + (" (the object is empty)" if not data else
                                    f" (it has {', '.join(map(repr, list(data)[:5]))}"
                                    + (", ..." if len(data) > 5 else "") + ")"))
        schema = self.get(data, "schema", "", self.is_int, f"an integer schema version ({' or '.join(map(str, READABLE_SCHEMAS))})")
        if schema not in READABLE_SCHEMAS:
            newer = schema > max(READABLE_SCHEMAS)
            raise self.error("schema", f"field 'schema' = {schema}: this reader reads schemas "
                                 f"{', '.join(map(str, READABLE_SCHEMAS))}"
                                 + ("; the file was written by a newer fourbar-cosim: update this one" if newer else ""))
        self.lenient = schema == 1
        status = self.get(data, "status", "", self.is_text, "a string", default="unknown")
        if schema >= 2 and status not in RUN_STATUSES:
            self.fail("status", status, " | ".join(RUN_STATUSES))
        parameters = self.parameters(data) if schema >= 2 else self.flat_parameters(data)
        fault = self.number(data, "fault_time", "", nullable=True)
        return RunRecord(
            status=status,
            run_id=self.text(data, "run_id", ""),
            case=self.text(data, "case", ""),
            case_file=self.text(data, "case_file", "", nullable=True),
            description=self.text(data, "description", "", default="") or "",
            fmu=self.fmu(data),
            experiment=self.experiment(data),
            parameters=parameters,
            events=self.events(data),
            fault_time=fault,
            outputs=self.outputs(data),
            units=self.units(data),
            noise=self.noise(data),
            exchange=self.exchange(data),
            rows_written=self.get(data, "rows_written", "", lambda v: self.is_int(v) and v >= 0,
                                  "an integer >= 0"),
            last_time=self.number(data, "last_time", "", nullable=True),
            started_at=self.text(data, "started_at", ""),
            updated_at=self.text(data, "updated_at", "", nullable=True),
            finished_at=self.text(data, "finished_at", "", nullable=True),
            wall_time_s=self.number(data, "wall_time_s", ""),
            error=self.text(data, "error", "", nullable=True),
            writer=self.writer(data),
            drawing=self.drawing(data),
            inputs=self.inputs(data),
            input_derivatives=self.get(data, "input_derivatives", "", lambda v: self.is_int(v) and 0 <= v <= 2,
                                            "an integer 0, 1 or 2", default=0) if "input_derivatives" in data else 0,
            system=self.system(data),
            schema=schema,
        )

    def system(self, data: dict) -> RecordedSystem | None:
        """The optional ``system`` (only system runs have it)."""
        value = data.get("system")
        if value is None:
            return None
        try:
            return RecordedSystem.from_json(value)
        except ValueError as exc:
            raise self.error("system", str(exc)) from None

    def drawing(self, data: dict) -> Drawing | None:
        """The optional ``drawing`` (absent in records written before drawings: None)."""
        value = data.get("drawing")
        if value is None:
            return None
        try:
            return Drawing.from_json(value, f"{self.source}: field 'drawing'")
        except DrawingError as exc:
            prefix = f"{self.source}: "
            raise self.error("drawing", str(exc)[len(prefix):] if str(exc).startswith(prefix) else str(exc)) from None

    def fmu(self, data: dict) -> RecordedFmu | None:
        table = self.obj(data, "fmu", "")
        if table is None:
            return None
        values = [self.text(table, key, "fmu.") for key in ("path", "guid", "model_name")]
        if None in values:       # schema 1 without them
            return None
        fmi_type = table.get("fmi_type", "CoSimulation")   # optional: runs written before it are co-simulation
        if fmi_type not in ("CoSimulation", "ModelExchange"):
            raise self.error("fmu.fmi_type", f"field 'fmu.fmi_type' = {fmi_type!r}: expected 'CoSimulation' or "
                                 f"'ModelExchange'")
        return RecordedFmu(*values, fmi_type=fmi_type)

    def experiment(self, data: dict) -> RecordedExperiment | None:
        table = self.obj(data, "experiment", "")
        if table is None:
            return None
        start, stop, step = (self.number(table, key, "experiment.") for key in ("start", "stop", "step"))
        tolerance = self.get(table, "tolerance", "experiment.", lambda v: self.is_number(v) and v > 0,
                             "a number > 0", nullable=True)
        if step is not None and step <= 0:
            self.fail("experiment.step", step, "a number > 0")
        if None in (start, stop, step):      # schema 1 without them
            return None
        return RecordedExperiment(start=start, stop=stop, step=step,
                                  tolerance=float(tolerance) if tolerance is not None else None)

    def start_value(self, where: str, value: Any, vtype: str) -> Value:
        checks = {"Real": (self.is_number, "a finite number"), "Integer": (self.is_int, "an integer"),
                  "Enumeration": (self.is_int, "an integer"), "Boolean": (lambda v: isinstance(v, bool), "true or false"),
                  "String": (self.is_text, "a string")}
        check, expected = checks[vtype]
        if not check(value):
            self.fail(where, value, f"{expected} (the parameter is {vtype})")
        return float(value) if vtype == "Real" else value

    def parameters(self, data: dict) -> tuple[ParameterStart, ...]:
        table = self.obj(data, "parameters", "")
        entries = []
        for name, entry in table.items():
            prefix = f"parameters.{name}."
            if not isinstance(entry, dict):
                self.fail(f"parameters.{name}", entry, 'an object {"start", "source", "type", "variability", "unit"}')
            source = self.text(entry, "source", prefix)
            if source not in _WRITTEN_SOURCES:
                self.fail(f"{prefix}source", source, " | ".join(f'"{s}"' for s in _WRITTEN_SOURCES))
            vtype = self.text(entry, "type", prefix)
            if vtype not in _PARAMETER_TYPES:
                self.fail(f"{prefix}type", vtype, " | ".join(_PARAMETER_TYPES))
            variability = self.text(entry, "variability", prefix)
            if variability not in _VARIABILITIES:
                self.fail(f"{prefix}variability", variability, " | ".join(_VARIABILITIES))
            unit = self.text(entry, "unit", prefix, nullable=True)
            if "start" not in entry:
                self.get(entry, "start", prefix, lambda v: True, "the start value")      # raises: missing
            start = entry["start"]
            if start is None:
                if source != "fmu":
                    self.fail(f"{prefix}start", start, f"a value (only an FMU default may be null; source is {source})")
            else:
                start = self.start_value(f"{prefix}start", start, vtype)
            entries.append(ParameterStart(name=name, start=start, source=source, type=vtype,
                                          variability=variability, unit=unit))
        return tuple(entries)

    def flat_parameters(self, data: dict) -> tuple[ParameterStart, ...]:
        """Schema 1: ``{"L2": 1.0, ...}``, the values the case set (no source, no declaration)."""
        table = self.obj(data, "parameters", "") or {}
        entries = []
        for name, value in table.items():
            if isinstance(value, bool):
                vtype = "Boolean"
            elif self.is_int(value):
                vtype = "Integer"
            elif self.is_number(value):
                vtype = "Real"
            elif isinstance(value, str):
                vtype = "String"
            else:
                self.fail(f"parameters.{name}", value, "a number, boolean or string")
            entries.append(ParameterStart(name=name, start=float(value) if vtype == "Real" else value,
                                          source="unknown", type=vtype))
        return tuple(entries)

    def events(self, data: dict) -> tuple[Event, ...]:
        items = self.get(data, "events", "", lambda v: isinstance(v, list), "an array", default=[])
        events: list[Event] = []
        lenient, self.lenient = self.lenient, False      # an event present is checked in full
        try:
            for i, item in enumerate(items):
                where = f"events[{i}]"
                if not isinstance(item, dict):
                    self.fail(where, item, 'an object with "type": "step" or "ramp"')
                kind = self.text(item, "type", f"{where}.")
                if kind == "step":
                    value = self.get(item, "value", f"{where}.", lambda v: self.is_number(v) or isinstance(v, (bool, str)),
                                     "a number, boolean or string")
                    events.append(StepEvent(time=self.number(item, "time", f"{where}."),
                                               variable=self.text(item, "variable", f"{where}."), value=value))
                elif kind == "ramp":
                    n = {key: self.number(item, key, f"{where}.") for key in ("from", "to", "start", "end")}
                    events.append(RampEvent(variable=self.text(item, "variable", f"{where}."), from_=n["from"],
                                               to=n["to"], start=n["start"], end=n["end"]))
                else:
                    self.fail(f"{where}.type", kind, '"step" or "ramp"')
        finally:
            self.lenient = lenient
        return tuple(events)

    def outputs(self, data: dict) -> tuple[str, ...]:
        items = self.get(data, "outputs", "", lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v),
                         "an array of output names", default=[])
        return tuple(items)

    def inputs(self, data: dict) -> tuple[RecordedInput, ...]:
        """The optional ``inputs``: input name -> its signal (an object with a string ``type``)."""
        if "inputs" not in data:
            return ()
        table = self.get(data, "inputs", "", lambda v: isinstance(v, dict) and all(
            isinstance(x, dict) and isinstance(x.get("type"), str) for x in v.values()),
            "an object input name = signal (an object with a string \"type\")", default={})
        return tuple(RecordedInput(name=name, signal=dict(signal)) for name, signal in table.items())

    def units(self, data: dict) -> dict[str, str]:
        table = self.get(data, "units", "", lambda v: isinstance(v, dict) and all(isinstance(x, str) for x in v.values()),
                         "an object output = unit (strings)", default={})
        return dict(table)

    def noise(self, data: dict) -> RecordedNoise | None:
        table = self.obj(data, "noise", "", nullable=True)
        if table is None:
            return None
        seed = self.get(table, "seed", "noise.", lambda v: self.is_int(v) and v >= 0, "an integer >= 0")
        std = self.get(table, "std", "noise.", lambda v: isinstance(v, dict) and all(self.is_number(x) and x >= 0
                                                                                    for x in v.values()),
                       "an object output = standard deviation >= 0", default={})
        return RecordedNoise(seed=seed if seed is not None else 0, std={k: float(x) for k, x in std.items()})

    def exchange(self, data: dict) -> RecordedExchange | None:
        table = self.obj(data, "exchange", "")
        if table is None:
            return None
        flush = self.get(table, "flush_interval", "exchange.", lambda v: self.is_number(v) and v > 0, "a number > 0")
        factor = self.get(table, "realtime_factor", "exchange.", lambda v: self.is_number(v) and v >= 0,
                          "a number >= 0")
        max_rows = self.get(table, "max_rows", "exchange.", lambda v: self.is_int(v) and v >= 1, "an integer >= 1",
                            nullable=True)
        if None in (flush, factor):
            return None
        return RecordedExchange(flush_interval=float(flush), realtime_factor=float(factor), max_rows=max_rows)

    def writer(self, data: dict) -> RecordedWriter | None:
        table = self.obj(data, "writer", "")
        if table is None:
            return None
        pid = self.get(table, "pid", "writer.", lambda v: self.is_int(v) and v > 0, "a process id > 0")
        host = self.text(table, "host", "writer.")
        beat = self.get(table, "heartbeat_s", "writer.", lambda v: self.is_number(v) and v > 0, "a number > 0")
        if None in (pid, host):
            return None
        return RecordedWriter(pid=pid, host=host, heartbeat_s=float(beat) if beat is not None else 0.0)

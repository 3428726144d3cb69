"""Case files: the typed, validated description of one co-simulation run.

A case file is TOML (schema in docs/orchestrator.md and docs/contracts.md).  ``load_case``
reads it, checks every key against the schema *and* against the FMU's model description,
and either returns a frozen :class:`Case` or raises one :class:`ConfigError` that lists
every problem found, each naming the file, the field, the value and what was expected.

Time grid.  The communication points are ``t_k = start + k*step`` for ``k = 0 .. n``,
``n = (stop - start)/step``, which must be a whole number.  Events must lie on that grid
(a step's ``time``, a ramp's ``start`` and ``end``): an event between two points would be
either moved (silently changing the fault time the monitor is scored against) or would
need a split step (rows no longer on one uniform grid), so it is rejected instead.

This module imports only the standard library at import time; FMPy is imported when a
model description has to be read.
"""
from __future__ import annotations

import difflib
import json
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Union

__all__ = [
    "Case",
    "ConfigError",
    "ProblemReporter",
    "read_toml",
    "show_value",
    "DEFAULT_OUTPUTS",
    "Experiment",
    "ExchangeSettings",
    "Noise",
    "RampEvent",
    "StepEvent",
    "apply_overrides",
    "load_case",
]

#: Outputs written when a case has no ``[outputs]`` table (the paper's order).
DEFAULT_OUTPUTS = ("x2", "y2", "x3", "y3", "x4", "y4")
#: A time is on the grid when ``(time - start)/step`` is within this of a whole number.
GRID_TOLERANCE = 1e-6

_TOP_KEYS = ("name", "description", "fmu", "experiment", "parameters", "events", "outputs", "noise", "exchange")
_EXPERIMENT_KEYS = ("start", "stop", "step", "tolerance")
_STEP_KEYS = ("type", "time", "variable", "value")
_RAMP_KEYS = ("type", "variable", "from", "to", "start", "end")
_OUTPUT_KEYS = ("variables",)
_NOISE_KEYS = ("seed", "std")
_EXCHANGE_KEYS = ("flush_interval", "realtime_factor")
_NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")

Value = Union[float, int, bool, str]


class ConfigError(ValueError):
    """A case file (or an override of it) is invalid; ``problems`` lists every problem.

    ``str(error)`` is the complete report: one line per problem, each starting with the
    case file's name.
    """

    #: What kind of file the report is about ("invalid case <file>: ...").
    subject = "case"

    def __init__(self, source: str | None, problems: list[str] | tuple[str, ...]):
        self.source = source
        self.problems = tuple(problems)
        prefix = f"{source}: " if source else ""
        count = len(self.problems)
        head = f"invalid {self.subject} {source or '(no file)'}: {count} problem{'s' if count != 1 else ''}"
        super().__init__("\n".join([head] + [f"  {prefix}{p}" for p in self.problems]))


@dataclass(frozen=True)
class Experiment:
    """Simulated time span and communication grid, in seconds."""

    start: float
    stop: float
    step: float
    tolerance: float | None = None   # relative tolerance passed to fmi2SetupExperiment (None: FMU's own)

    @property
    def n_steps(self) -> int:
        """Number of communication steps; the run writes ``n_steps + 1`` rows."""
        return round((self.stop - self.start) / self.step)

    def time(self, k: int) -> float:
        """Communication point ``k``: ``start + k*step`` (integer count, no accumulated drift)."""
        return self.start + k * self.step

    def index(self, t: float) -> int | None:
        """Grid index of time ``t``, or None when ``t`` is not on the grid."""
        x = (t - self.start) / self.step
        k = round(x)
        return k if abs(x - k) <= GRID_TOLERANCE else None

    def as_dict(self) -> dict:
        return {"start": self.start, "stop": self.stop, "step": self.step, "tolerance": self.tolerance}


@dataclass(frozen=True)
class StepEvent:
    """Set ``variable`` to ``value`` at ``time`` (s): applied after the row at ``time`` is read."""

    time: float
    variable: str
    value: Value

    @property
    def first_time(self) -> float:
        return self.time

    def as_dict(self) -> dict:
        return {"type": "step", "time": self.time, "variable": self.variable, "value": self.value}


@dataclass(frozen=True)
class RampEvent:
    """Move Real ``variable`` linearly from ``from_`` to ``to`` over [``start``, ``end``] (s).

    The value ``from_*(1-f) + to*f``, ``f = (t - start)/(end - start)``, is set at every
    communication point of the ramp, ends included.
    """

    variable: str
    from_: float
    to: float
    start: float
    end: float

    @property
    def first_time(self) -> float:
        return self.start

    def value_at(self, fraction: float) -> float:
        """Ramp value at ``fraction`` in [0, 1]; exactly ``from_`` at 0 and ``to`` at 1."""
        return self.from_ * (1.0 - fraction) + self.to * fraction

    def as_dict(self) -> dict:
        return {"type": "ramp", "variable": self.variable, "from": self.from_, "to": self.to,
                "start": self.start, "end": self.end}


Event = Union[StepEvent, RampEvent]


@dataclass(frozen=True)
class Noise:
    """Gaussian measurement noise added to written values only (the FMU never sees it).

    ``std`` maps an output name to its standard deviation in the output's unit.  Draws:
    ``numpy.random.default_rng(seed).standard_normal`` row by row, one number per noisy
    output in the order of ``outputs``.
    """

    seed: int
    std: Mapping[str, float]

    def as_dict(self) -> dict:
        return {"seed": self.seed, "std": dict(self.std)}


@dataclass(frozen=True)
class ExchangeSettings:
    """How the exchange file is written."""

    flush_interval: float = 1.0    # simulated seconds between appends
    realtime_factor: float = 0.0   # 0: as fast as possible; 1: wall clock; 20: 20x faster

    def as_dict(self) -> dict:
        return {"flush_interval": self.flush_interval, "realtime_factor": self.realtime_factor}


@dataclass(frozen=True)
class Case:
    """One validated scenario: FMU, experiment, start values, events, outputs, noise, exchange."""

    name: str
    fmu: Path                      # absolute path of the .fmu
    experiment: Experiment
    parameters: Mapping[str, Value] = field(default_factory=dict)
    events: tuple[Event, ...] = ()
    outputs: tuple[str, ...] = DEFAULT_OUTPUTS
    noise: Noise | None = None
    exchange: ExchangeSettings = ExchangeSettings()
    description: str = ""
    source: Path | None = None     # the case file, when loaded from one

    @property
    def fault_time(self) -> float | None:
        """Earliest event time (a step's time or a ramp's start), None without events."""
        return min((e.first_time for e in self.events), default=None)

    def as_dict(self) -> dict:
        """The case as a TOML-shaped dict (what run.json records and what overrides edit)."""
        data = {"name": self.name, "description": self.description, "fmu": str(self.fmu),
                "experiment": {k: v for k, v in self.experiment.as_dict().items() if v is not None},
                "parameters": dict(self.parameters),
                "events": [e.as_dict() for e in self.events],
                "outputs": {"variables": list(self.outputs)},
                "exchange": self.exchange.as_dict()}
        if self.noise is not None:
            data["noise"] = self.noise.as_dict()
        return data


# ---------------------------------------------------------------------------- loading

def load_case(path: str | Path, *, overrides: Mapping[str, Value] | None = None,
              stop: float | None = None, realtime: float | None = None, fmu: str | Path | None = None) -> Case:
    """Read and validate a case file; raise :class:`ConfigError` listing every problem.

    ``overrides`` (parameter start values), ``stop`` (s), ``realtime`` (factor) and ``fmu``
    (a path, relative to the working directory) replace the file's values before validation,
    as the CLI's ``--set``, ``--stop``, ``--realtime`` and ``--fmu``.
    """
    path = Path(path)
    label = str(path)
    raw = read_toml(path, "case file")
    raw.setdefault("name", path.stem)
    raw, origins = _merge_overrides(raw, overrides, stop, realtime, fmu)
    return _Validator(raw, label, path.resolve().parent, origins, source=path.resolve()).case()


def apply_overrides(case: Case, *, overrides: Mapping[str, Value] | None = None,
                    stop: float | None = None, realtime: float | None = None,
                    fmu: str | Path | None = None) -> Case:
    """A new :class:`Case` with the overrides applied, validated again in full.

    Also the way to check a :class:`Case` built or modified in code (all arguments None).
    """
    raw, origins = _merge_overrides(case.as_dict(), overrides, stop, realtime, fmu)
    label = str(case.source) if case.source is not None else f"case {case.name!r}"
    base = case.source.parent if case.source is not None else Path.cwd()
    return _Validator(raw, label, base, origins, source=case.source).case()


def _merge_overrides(raw: dict, overrides, stop, realtime, fmu=None) -> tuple[dict, dict[str, str]]:
    raw = dict(raw)
    origins: dict[str, str] = {}
    if fmu is not None:
        raw["fmu"] = str(Path(fmu).resolve())     # given relative to the working directory
        origins["fmu"] = "--fmu"
    if overrides:
        params = raw.get("parameters")
        params = dict(params) if isinstance(params, dict) else {}
        for name, value in overrides.items():
            params[name] = value
            origins[f"parameters.{name}"] = f"--set {name}"
        raw["parameters"] = params
    if stop is not None:
        exp = raw.get("experiment")
        exp = dict(exp) if isinstance(exp, dict) else {}
        exp["stop"] = stop
        raw["experiment"] = exp
        origins["experiment.stop"] = "--stop"
    if realtime is not None:
        exc = raw.get("exchange")
        exc = dict(exc) if isinstance(exc, dict) else {}
        exc["realtime_factor"] = realtime
        raw["exchange"] = exc
        origins["exchange.realtime_factor"] = "--realtime"
    return raw, origins


def show_value(value: Any) -> str:
    """A value as it would be written in TOML."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (dict, list, tuple)):
        text = json.dumps(value, default=str)
        return text if len(text) <= 60 else text[:57] + "..."
    return repr(value)


def read_toml(path: Path, what: str, error: type[ConfigError] = ConfigError) -> dict:
    """Parse the TOML file ``path`` (a ``what``, e.g. "case file"); raise ``error`` naming the
    file when it is missing, unreadable or not TOML."""
    label = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error(label, [f"{what} not found"]) from None
    except IsADirectoryError:
        raise error(label, [f"is a directory; expected a {what} (TOML)"]) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(label, [f"cannot read the {what}: {exc}"]) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(label, [f"not valid TOML: {exc}"]) from None


class ProblemReporter:
    """Collects validation problems as ``field = value: what was expected`` lines.

    Shared by the case loader here and the sweep loader (``sweep.config``); a subclass
    sets ``self.problems = []`` and may override :meth:`field` to say where a key came from.
    """

    problems: list[str]

    def field(self, name: str) -> str:
        return name

    def problem(self, name: str, value: Any, expected: str) -> None:
        self.problems.append(f"{self.field(name)} = {show_value(value)}: {expected}")

    def missing(self, name: str, expected: str) -> None:
        self.problems.append(f"{self.field(name)}: missing; expected {expected}")

    def unknown_keys(self, table: dict, allowed: tuple[str, ...], where: str) -> None:
        for key in table:
            if key not in allowed:
                close = difflib.get_close_matches(key, allowed, n=1)
                hint = f"did you mean {close[0]!r}? " if close else ""
                place = f"{where}.{key}" if where else key
                self.problems.append(f"{place}: unknown key; {hint}expected one of: {', '.join(allowed)}")


def _kind(value: Any) -> str:
    return {bool: "a boolean", int: "an integer", float: "a float", str: "a string",
            dict: "a table", list: "an array"}.get(type(value), type(value).__name__)


def _role(var) -> str:
    """'a parameter (fixed)', 'an output (continuous)', ... for messages."""
    article = "an" if var.causality[0] in "aeiou" else "a"
    return f"{article} {var.causality} ({var.variability})"


class _Validator(ProblemReporter):
    """Collects every problem of one raw case dict, then builds the Case or raises."""

    def __init__(self, raw: dict, label: str, base_dir: Path, origins: dict[str, str], source: Path | None):
        self.raw = raw
        self.label = label
        self.base_dir = base_dir
        self.origins = origins
        self.source = source
        self.problems: list[str] = []
        self.md = None          # fmpy ModelDescription, when the FMU could be read
        self.fmu_name = "the FMU"
        self.variables: dict = {}

    # -- helpers ------------------------------------------------------------------
    def field(self, name: str) -> str:
        origin = self.origins.get(name)
        return f"{name} (from {origin})" if origin else name

    def table(self, name: str, required: bool = False) -> dict | None:
        value = self.raw.get(name)
        if value is None:
            if required:
                self.missing(name, f"a [{name}] table")
            return None
        if not isinstance(value, dict):
            self.problem(name, value, f"expected a [{name}] table, got {_kind(value)}")
            return None
        return value

    def number(self, name: str, value: Any, unit: str, *, minimum: float | None = None,
               positive: bool = False) -> float | None:
        """A finite float (TOML integers accepted) with optional bounds, else a problem."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.problem(name, value, f"expected a number{unit and ' in ' + unit}, got {_kind(value)}")
            return None
        value = float(value)
        if not math.isfinite(value):
            self.problem(name, value, "expected a finite number")
            return None
        if positive and value <= 0.0:
            self.problem(name, value, f"expected a number > 0{unit and ' ' + unit}")
            return None
        if minimum is not None and value < minimum:
            self.problem(name, value, f"expected a number >= {minimum:g}{unit and ' ' + unit}")
            return None
        return value

    # -- sections -----------------------------------------------------------------
    def case(self) -> Case:
        raw = self.raw
        if not isinstance(raw, dict):
            raise ConfigError(self.label, ["expected a TOML table at the top level"])
        self.unknown_keys(raw, _TOP_KEYS, "")
        name = self.name()
        description = raw.get("description", "")
        if not isinstance(description, str):
            self.problem("description", description, f"expected a string, got {_kind(description)}")
            description = ""
        fmu = self.fmu()
        experiment = self.experiment()
        parameters = self.parameters()
        outputs = self.outputs()
        events = self.events(experiment)
        noise = self.noise(outputs)
        exchange = self.exchange(experiment)
        if self.problems:
            raise ConfigError(self.label, self.problems)
        return Case(name=name, fmu=fmu, experiment=experiment, parameters=parameters, events=events,
                    outputs=outputs, noise=noise, exchange=exchange, description=description,
                    source=self.source)

    def name(self) -> str:
        name = self.raw.get("name")
        if not isinstance(name, str) or not _NAME_PATTERN.match(name):
            self.problem("name", name, "expected a non-empty string of letters, digits, '_', '-', '.' "
                                       "(it names the output directory out/<name>)")
            return "invalid"
        return name

    def fmu(self) -> Path:
        value = self.raw.get("fmu")
        if value is None:
            self.missing("fmu", "the path of an FMI 2.0 co-simulation FMU, relative to the case file")
            return Path()
        if not isinstance(value, str) or not value:
            self.problem("fmu", value, f"expected a path string, got {_kind(value)}")
            return Path()
        path = (self.base_dir / value).resolve()
        if not path.is_file():
            self.problem("fmu", value, f"file not found (resolved to {path}); "
                                       "build it with `python build_fmu.py`; variables not checked")
            return path
        from fmpy import read_model_description   # heavy import, only when a file is there
        try:
            md = read_model_description(str(path))
        except Exception as exc:   # fmpy raises zipfile/XML/ValidationError/bare Exception
            detail = " ".join(str(exc).split())
            self.problem("fmu", value, f"not a readable FMU ({type(exc).__name__}: {detail}); variables not checked")
            return path
        if md.fmiVersion != "2.0" or md.coSimulation is None:
            kinds = "co-simulation" if md.coSimulation is not None else "no co-simulation interface"
            self.problem("fmu", value, f"expected an FMI 2.0 co-simulation FMU, got FMI {md.fmiVersion} "
                                       f"with {kinds}; variables not checked")
            return path
        self.md = md
        self.fmu_name = path.name
        self.variables = {v.name: v for v in md.modelVariables}
        return path

    def experiment(self) -> Experiment | None:
        table = self.table("experiment", required=True)
        if table is None:
            return None
        self.unknown_keys(table, _EXPERIMENT_KEYS, "experiment")
        start = self.number("experiment.start", table.get("start", 0.0), "s")
        stop = step = None
        if "stop" not in table:
            self.missing("experiment.stop", "the end time in s")
        else:
            stop = self.number("experiment.stop", table["stop"], "s")
        if "step" not in table:
            self.missing("experiment.step", "the communication step in s")
        else:
            step = self.number("experiment.step", table["step"], "s", positive=True)
        tolerance = None
        if "tolerance" in table:
            tolerance = self.number("experiment.tolerance", table["tolerance"], "", positive=True)
        if start is None or stop is None or step is None:
            return None
        if stop <= start:
            self.problem("experiment.stop", stop, f"expected a time after experiment.start = {start!r} s")
            return None
        count = (stop - start) / step
        if abs(count - round(count)) > GRID_TOLERANCE:
            self.problem("experiment.stop", stop,
                         f"(stop - start)/step = {count:.9g} is not a whole number of steps of {step!r} s")
            return None
        return Experiment(start=start, stop=stop, step=step, tolerance=tolerance)

    def variable(self, where: str, name: Any, *, settable: str | None = None, shown: Any = None):
        """The model variable ``name`` (None if unknown or no FMU), checking how it is used.

        settable: None (read), "start" (start value) or "event" (changed during the run).
        ``shown`` is the value quoted in a message (default: the name itself).
        """
        shown = name if shown is None else shown
        if not isinstance(name, str):
            self.problem(where, shown, f"expected a variable name (string), got {_kind(name)}")
            return None
        if self.md is None:
            return None
        var = self.variables.get(name)
        if var is None:
            close = difflib.get_close_matches(name, self.variables, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            self.problem(where, shown, f"{self.fmu_name} has no variable named {name!r}{hint}")
            return None
        if settable == "start":
            if var.causality not in ("parameter", "input") or var.variability == "constant" \
                    or var.initial == "calculated":
                self.problem(where, shown, f"{name} is {_role(var)} of {self.fmu_name} and has no settable "
                                           f"start value; expected a parameter or an input")
                return None
        elif settable == "event":
            tunable = var.causality == "input" or (var.causality == "parameter" and var.variability == "tunable")
            if not tunable:
                names = [v.name for v in self.md.modelVariables if v.causality == "input"
                         or (v.causality == "parameter" and v.variability == "tunable")]
                self.problem(where, shown, f"{name} is {_role(var)} and cannot change during a run; "
                                           f"expected a tunable parameter or an input of {self.fmu_name}: "
                                           f"{', '.join(names) or 'none'}")
                return None
        return var

    def value_for(self, where: str, var, value: Any) -> Value | None:
        """``value`` checked against the type (and min/max, when declared) of ``var``."""
        vtype = var.type
        if vtype == "Real":
            unit = f"{var.unit}" if getattr(var, "unit", None) else ""
            result = self.number(where, value, unit)
        elif vtype in ("Integer", "Enumeration"):
            if isinstance(value, bool) or not isinstance(value, int):
                self.problem(where, value, f"{var.name} is {vtype}; expected an integer, got {_kind(value)}")
                return None
            result = value
        elif vtype == "Boolean":
            if not isinstance(value, bool):
                self.problem(where, value, f"{var.name} is Boolean; expected true or false, got {_kind(value)}")
                return None
            return value
        elif vtype == "String":
            if not isinstance(value, str):
                self.problem(where, value, f"{var.name} is String; expected a string, got {_kind(value)}")
                return None
            return value
        else:
            self.problem(where, value, f"{var.name} has type {vtype}, which case files cannot set")
            return None
        if result is None:
            return None
        for bound, op, text in ((var.min, float.__lt__, ">="), (var.max, float.__gt__, "<=")):
            if bound is not None:
                try:
                    limit = float(bound)
                except (TypeError, ValueError):
                    continue
                if op(float(result), limit):
                    # a positive min no one would type (the smallest normal double) says "> 0"
                    need = "> 0" if text == ">=" and 0.0 < limit <= 1e-300 else f"{text} {limit:g}"
                    self.problem(where, value, f"expected {need} (declared {'min' if text == '>=' else 'max'} "
                                               f"of {var.name} in {self.fmu_name})")
                    return None
        return result

    def parameters(self) -> dict[str, Value]:
        table = self.table("parameters")
        if table is None:
            return {}
        params: dict[str, Value] = {}
        for name, value in table.items():
            where = f"parameters.{name}"
            var = self.variable(where, name, settable="start", shown=value)
            if var is None:
                if self.md is not None:
                    continue
                params[name] = value      # FMU unreadable: already reported, keep for the listing
                continue
            checked = self.value_for(where, var, value)
            if checked is not None:
                params[name] = checked
        return params

    def outputs(self) -> tuple[str, ...]:
        table = self.table("outputs")
        if table is None:
            names = list(DEFAULT_OUTPUTS)
            where = "outputs.variables"
            lacking = [n for n in names if n not in self.variables]
            if self.md is not None and lacking:
                offered = [v.name for v in self.md.modelVariables if v.causality == "output"]
                self.problems.append(f"outputs: missing, and the default outputs {', '.join(names)} are not all "
                                     f"variables of {self.fmu_name} (lacking: {', '.join(lacking)}); expected "
                                     f"[outputs] variables = [...] naming outputs of {self.fmu_name}, e.g. "
                                     f"{', '.join(offered) or '(it declares no outputs)'}")
                return ()
        else:
            self.unknown_keys(table, _OUTPUT_KEYS, "outputs")
            names = table.get("variables")
            where = "outputs.variables"
            if names is None:
                self.missing(where, "an array of variable names")
                return ()
            if not isinstance(names, list) or not names:
                self.problem(where, names, "expected a non-empty array of variable names")
                return ()
        seen = set()
        result = []
        for i, name in enumerate(names):
            item = f"{where}[{i}]"
            if name == "time":
                self.problem(item, name, "'time' is the first column already; expected a variable of the FMU")
                continue
            if name in seen:
                self.problem(item, name, "listed twice; expected each output once")
                continue
            seen.add(name)
            var = self.variable(item, name)
            if var is not None and var.type not in ("Real", "Integer", "Enumeration", "Boolean"):
                self.problem(item, name, f"{name} is {var.type}; expected a Real, Integer or Boolean variable")
                continue
            if isinstance(name, str):
                result.append(name)
        return tuple(result)

    def events(self, experiment: Experiment | None) -> tuple[Event, ...]:
        raw = self.raw.get("events")
        if raw is None:
            return ()
        if not isinstance(raw, list):
            self.problem("events", raw, "expected an array of tables ([[events]])")
            return ()
        events: list[Event] = []
        spans: list[tuple[str, int, int, Any, Any, str]] = []   # variable, k0, k1, v0, v1, where
        for i, item in enumerate(raw):
            where = f"events[{i}]"
            if not isinstance(item, dict):
                self.problem(where, item, "expected a table with type = \"step\" or \"ramp\"")
                continue
            kind = item.get("type")
            if kind == "step":
                event = self.step_event(where, item, experiment, spans)
            elif kind == "ramp":
                event = self.ramp_event(where, item, experiment, spans)
            elif kind is None:
                self.missing(f"{where}.type", '"step" or "ramp"')
                continue
            else:
                self.problem(f"{where}.type", kind, 'expected "step" or "ramp"')
                continue
            if event is not None:
                events.append(event)
        if experiment is not None:
            self.check_overlaps(spans, experiment)
        return tuple(events)

    def event_time(self, where: str, value: Any, experiment: Experiment | None, *, last_allowed: bool) -> tuple:
        """(time, grid index) of an event time, reporting range and grid problems."""
        t = self.number(where, value, "s")
        if t is None or experiment is None:
            return t, None
        upper_ok = t <= experiment.stop if last_allowed else t < experiment.stop
        if t < experiment.start or not upper_ok:
            bracket = "]" if last_allowed else ")"
            origin = self.origins.get("experiment.stop")
            note = f" (experiment.stop from {origin})" if origin else ""
            self.problem(where, t, f"outside the experiment: expected a time in [{experiment.start!r}, "
                                   f"{experiment.stop!r}{bracket} s{note}")
            return None, None
        k = experiment.index(t)
        if k is None:
            below = experiment.time(math.floor((t - experiment.start) / experiment.step))
            above = below + experiment.step
            self.problem(where, t, f"not on the communication grid start + k*step (step {experiment.step!r} s); "
                                   f"expected e.g. {below:.12g} or {above:.12g} (off-grid events are rejected)")
            return None, None
        return experiment.time(k), k

    def step_event(self, where, item, experiment, spans) -> StepEvent | None:
        self.unknown_keys(item, _STEP_KEYS, where)
        for key in ("time", "variable", "value"):
            if key not in item:
                self.missing(f"{where}.{key}", {"time": "a time in s", "variable": "a variable name",
                                                "value": "the new value"}[key])
        if any(key not in item for key in ("time", "variable", "value")):
            return None
        t, k = self.event_time(f"{where}.time", item["time"], experiment, last_allowed=False)
        var = self.variable(f"{where}.variable", item["variable"], settable="event")
        value = item["value"]
        if var is not None:
            value = self.value_for(f"{where}.value", var, value)
            if value is None:
                return None
        elif self.md is not None:
            return None
        if t is None:
            return None
        if k is not None:
            spans.append((item["variable"], k, k, value, value, where))
        return StepEvent(time=t, variable=item["variable"], value=value)

    def ramp_event(self, where, item, experiment, spans) -> RampEvent | None:
        self.unknown_keys(item, _RAMP_KEYS, where)
        required = {"variable": "a variable name", "from": "the value at start", "to": "the value at end",
                    "start": "a time in s", "end": "a time in s"}
        for key, expected in required.items():
            if key not in item:
                self.missing(f"{where}.{key}", expected)
        if any(key not in item for key in required):
            return None
        var = self.variable(f"{where}.variable", item["variable"], settable="event")
        if var is not None and var.type != "Real":
            self.problem(f"{where}.variable", item["variable"], f"{var.name} is {var.type}; a ramp needs a Real variable")
            var = None
            bad = True
        else:
            bad = var is None and self.md is not None
        if var is not None:
            v0 = self.value_for(f"{where}.from", var, item["from"])
            v1 = self.value_for(f"{where}.to", var, item["to"])
        else:
            v0 = self.number(f"{where}.from", item["from"], "")
            v1 = self.number(f"{where}.to", item["to"], "")
        t0, k0 = self.event_time(f"{where}.start", item["start"], experiment, last_allowed=False)
        t1, k1 = self.event_time(f"{where}.end", item["end"], experiment, last_allowed=True)
        if t0 is not None and t1 is not None and t1 <= t0:
            self.problem(f"{where}.end", t1, f"expected a time after {where}.start = {t0!r} s")
            return None
        if bad or None in (v0, v1, t0, t1):
            return None
        if k0 is not None and k1 is not None:
            spans.append((item["variable"], k0, k1, v0, v1, where))
        return RampEvent(variable=item["variable"], from_=float(v0), to=float(v1), start=t0, end=t1)

    def check_overlaps(self, spans, experiment: Experiment) -> None:
        """Two events may not set the same variable at the same communication point.

        Exception: one ends where the next starts with the same value (chained ramps).
        """
        by_variable: dict[str, list] = {}
        for span in spans:
            by_variable.setdefault(span[0], []).append(span)
        for variable, items in by_variable.items():
            items.sort(key=lambda s: (s[1], s[2]))
            for a, b in zip(items, items[1:]):
                if b[1] > a[2]:
                    continue
                if b[1] == a[2] and a[1] < a[2] and b[1] < b[2] and a[4] == b[3]:
                    continue
                first, second = sorted((a[5], b[5]), key=lambda w: int(w[7:-1]))
                shared = experiment.time(b[1])
                self.problems.append(f"{first} and {second} overlap: both set {variable} at t = {shared!r} s; "
                                     f"expected events on one variable not to overlap (chained ramps may "
                                     f"share an end point with the same value)")

    def noise(self, outputs: tuple[str, ...]) -> Noise | None:
        table = self.table("noise")
        if table is None:
            return None
        self.unknown_keys(table, _NOISE_KEYS, "noise")
        seed = table.get("seed")
        if seed is None:
            self.missing("noise.seed", "an integer >= 0 (the noise must be reproducible)")
        elif isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            self.problem("noise.seed", seed, "expected an integer >= 0")
            seed = None
        std_table = table.get("std")
        std: dict[str, float] = {}
        if std_table is None:
            self.missing("noise.std", "a table of standard deviations per output, e.g. std = { x2 = 0.005 }")
        elif not isinstance(std_table, dict):
            self.problem("noise.std", std_table, "expected a table output = standard deviation")
        else:
            for name, value in std_table.items():
                where = f"noise.std.{name}"
                if name not in outputs:
                    self.problem(where, value, f"{name} is not an output of this case; expected one of: "
                                               f"{', '.join(outputs)}")
                    continue
                var = self.variables.get(name)
                if var is not None and var.type != "Real":
                    self.problem(where, value, f"{name} is {var.type}; noise needs a Real output")
                    continue
                unit = (getattr(var, "unit", None) or "") if var is not None else ""
                checked = self.number(where, value, unit, minimum=0.0)
                if checked is not None:
                    std[name] = checked
        if seed is None or std_table is None:
            return None
        return Noise(seed=seed, std=std)

    def exchange(self, experiment: Experiment | None) -> ExchangeSettings:
        table = self.table("exchange")
        if table is None:
            return ExchangeSettings()
        self.unknown_keys(table, _EXCHANGE_KEYS, "exchange")
        flush = self.number("exchange.flush_interval", table.get("flush_interval", 1.0), "s", positive=True)
        factor = self.number("exchange.realtime_factor", table.get("realtime_factor", 0.0), "", minimum=0.0)
        return ExchangeSettings(flush_interval=flush if flush is not None else 1.0,
                                realtime_factor=factor if factor is not None else 0.0)

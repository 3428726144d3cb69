"""Case files: read a TOML case file and check it into a :class:`~orchestrator.case.Case`.

A case file is TOML (schema in docs/orchestrator.md and docs/contracts.md).  ``load_case``
reads it, checks every key against the schema *and* against the FMU's model description,
and either returns a frozen :class:`Case` or raises one :class:`ConfigError` that lists
every problem found, each naming the file, the field, the value and what was expected.
The checks common to case and sweep files live in :mod:`orchestrator.validation`.

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
import math
from pathlib import Path
from typing import Any, Mapping

from fourbar_common import Drawing
from fourbar_common.contract.layout import EXCHANGE

from .case import (DEFAULT_OUTPUTS, MASTER_ALGORITHMS, MASTER_INPUTS, Case, Event, ExchangeSettings, Experiment,
                   FmuDescription, Master, Noise, RampEvent, StepEvent, Value, describe_fmu)
from .input_signals import InputSignal, derivative_order, driver_rates, parse_inputs
from .limits import MAX_STEP, MIN_REALTIME_FACTOR, UNIT_LIMITS
from .validation import ConfigError, ProblemReporter, kind_of, name_from_file, read_toml

__all__ = ["apply_overrides", "load_case"]

_TOP_KEYS = ("name", "description", "fmu", "fmi_type", "experiment", "parameters", "events", "outputs", "noise",
             "exchange", "inputs", "input_derivatives", "system", "master")
_MASTER_KEYS = ("algorithm", "inputs", "order")
#: The FMI 2.0 interfaces a case may run (``fmi_type``), as FMPy names them.
FMI_TYPES = ("CoSimulation", "ModelExchange")
_EXPERIMENT_KEYS = ("start", "stop", "step", "tolerance")
_STEP_KEYS = ("type", "time", "variable", "value")
_RAMP_KEYS = ("type", "variable", "from", "to", "start", "end")
_OUTPUT_KEYS = ("variables", "drawing")
_NOISE_KEYS = ("seed", "std")
_EXCHANGE_KEYS = ("flush_interval", "realtime_factor", "max_rows")
#: Rough size of one written value in exchange.csv (``repr`` of a double and a comma), for
#: the size quoted when a run would exceed ``exchange.max_rows``.
_BYTES_PER_VALUE = 20


# ---------------------------------------------------------------------------- loading

def load_case(path: str | Path, *, overrides: Mapping[str, Value] | None = None,
              stop: float | None = None, realtime: float | None = None, fmu: str | Path | None = None,
              max_rows: int | None = None, out_dir_given: bool = False) -> Case:
    """Read and validate a case file; raise :class:`ConfigError` listing every problem.

    ``overrides`` (parameter start values), ``stop`` (s), ``realtime`` (factor), ``fmu``
    (a path, relative to the working directory) and ``max_rows`` replace the file's values
    before validation, as the CLI's ``--set``, ``--stop``, ``--realtime``, ``--fmu`` and
    ``--max-rows``.

    The case's ``name`` labels the run and, by default, names its folder ``out/<name>``, so
    it must be letters, digits, '_', '-', '.'.  A file without ``name`` is named after its
    file name made such a name (:func:`~orchestrator.validation.name_from_file`:
    ``my case.toml`` -> ``my_case``).  ``out_dir_given`` (``--out``): the name only labels
    the run, so a file name with no Latin letter or digit (``案例.toml``) is then the name as
    it is, where without ``--out`` it is refused (a ``name`` written in the file is always
    checked as a folder name).
    """
    path = Path(path)
    label = str(path)
    raw = read_toml(path, "case file")
    raw, origins = _merge_overrides(raw, overrides, stop, realtime, fmu, max_rows)
    return _Validator(raw, label, path.resolve().parent, origins, source=path.resolve(),
                      name_only_labels=out_dir_given).case()


def apply_overrides(case: Case, *, overrides: Mapping[str, Value] | None = None,
                    stop: float | None = None, realtime: float | None = None,
                    fmu: str | Path | None = None, max_rows: int | None = None,
                    out_dir_given: bool = False) -> Case:
    """A new :class:`Case` with the overrides applied, validated again in full.

    Also the way to check a :class:`Case` built or modified in code (all arguments None).
    The case's FMU description is reused while the FMU file is unchanged.
    ``out_dir_given``: as for :func:`load_case`.
    """
    raw, origins = _merge_overrides(case.as_dict(), overrides, stop, realtime, fmu, max_rows)
    for name in case.overridden:           # still an override: run.json records its source as "set"
        origins.setdefault(f"parameters.{name}", f"--set {name}")
    label = str(case.source) if case.source is not None else f"case {case.name!r}"
    base = case.source.parent if case.source is not None else Path.cwd()
    return _Validator(raw, label, base, origins, source=case.source, known=case.fmu_description,
                      name_only_labels=out_dir_given).case()


def _merge_overrides(raw: dict, overrides, stop, realtime, fmu=None, max_rows=None) -> tuple[dict, dict[str, str]]:
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
    for key, value, flag in (("realtime_factor", realtime, "--realtime"), ("max_rows", max_rows, "--max-rows")):
        if value is not None:
            exc = raw.get("exchange")
            exc = dict(exc) if isinstance(exc, dict) else {}
            exc[key] = value
            raw["exchange"] = exc
            origins[f"exchange.{key}"] = flag
    return raw, origins


def _show_bytes(size: float) -> str:
    """``size`` bytes as '1.3 GB', '13 PB', ... (decimal units)."""
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if size < 1000:
            return f"{size:.3g} {unit}"
        size /= 1000
    return f"{size:.3g} EB"


def _role(var) -> str:
    """'a parameter (fixed)', 'an output (continuous)', ... for messages."""
    article = "an" if var.causality[0] in "aeiou" else "a"
    return f"{article} {var.causality} ({var.variability})"


class _Validator(ProblemReporter):
    """Collects every problem of one raw case dict, then builds the Case or raises."""

    def __init__(self, raw: dict, label: str, base_dir: Path, origins: dict[str, str], source: Path | None,
                 known: FmuDescription | None = None, name_only_labels: bool = False):
        self.raw = raw
        self.name_only_labels = name_only_labels   # --out given: the name names no folder
        self.known = known      # an FMU description to reuse if it is still current
        self.label = label
        self.base_dir = base_dir
        self.origins = origins
        self.source = source
        self.problems: list[str] = []
        self.description: FmuDescription | None = None   # when the FMU could be read
        self.fmu_name = "the FMU"
        self.system_path: Path | None = None    # ``system = "X.ssp"``: the archive, when named

    # -- helpers ------------------------------------------------------------------
    def field(self, name: str) -> str:
        origin = self.origins.get(name)
        return f"{name} (from {origin})" if origin else name

    @property
    def md(self):
        """FMPy's model description of the case's FMU, None when it could not be read."""
        return self.description.model if self.description is not None else None

    @property
    def variables(self) -> dict:
        return self.description.variables if self.description is not None else {}

    # -- sections -----------------------------------------------------------------
    def case(self) -> Case:
        raw = self.raw
        if not isinstance(raw, dict):
            raise ConfigError(self.label, ["expected a TOML table at the top level"])
        self.unknown_keys(raw, _TOP_KEYS, "")
        name = self.name()
        description = self.text("description", raw.get("description", "")) or ""
        fmu = self.fmu()
        fmi_type = self.fmi_type()
        experiment = self.experiment()
        parameters = self.parameters()
        outputs = self.outputs()
        drawing, record_drawing = self.drawing()
        recorded = outputs + tuple(c for c in drawing.columns if c not in outputs) if drawing else outputs
        events = self.events(experiment)
        noise = self.noise(recorded)
        inputs = self.inputs(experiment)
        self.given_twice(inputs)
        order = self.input_derivatives(inputs, fmi_type)
        exchange = self.exchange(experiment, recorded + tuple(n for n in inputs if n not in recorded))
        master = self.master()
        self.connected(parameters, events, inputs)
        if self.problems:
            raise ConfigError(self.label, self.problems)
        return Case(name=name, fmu=fmu, experiment=experiment, parameters=parameters, events=events,
                    outputs=outputs, drawing=drawing, record_drawing=record_drawing, noise=noise, exchange=exchange, description=description,
                    source=self.source, fmu_description=self.description, fmi_type=fmi_type,
                    overridden=frozenset(n for n in parameters if f"parameters.{n}" in self.origins),
                    inputs=inputs, input_derivative_order=order, system=self.system_path, master=master)

    def inputs(self, experiment: Experiment | None) -> dict[str, InputSignal]:
        """``[inputs]``: a signal for each named input of the FMU (orchestrator.input_signals),
        and the derivatives of a driver input's position for its rate and acceleration inputs
        the case does not give (:func:`~orchestrator.input_signals.driver_rates`)."""
        inputs = ({v.name: v for v in self.md.modelVariables if v.causality == "input"}
                  if self.md is not None else None)
        span = (experiment.start, experiment.stop) if experiment is not None else None
        signals = parse_inputs(self, self.raw.get("inputs"), inputs, self.base_dir, span, self.fmu_name)
        return {**signals, **driver_rates(signals, inputs)} if inputs is not None else signals

    def given_twice(self, inputs: dict[str, InputSignal]) -> None:
        """An input ``[inputs]`` drives may not also be set by ``[parameters]`` (or ``--set``) or an event."""
        params = self.raw.get("parameters")
        for name in params if isinstance(params, dict) else ():
            if name in inputs and inputs[name].KIND == "derivative":
                self.problem(f"parameters.{name}", params[name], f"{name} is the rate or acceleration of the driver "
                                                                 f"input {inputs[name].of}, which [inputs] drives: "
                                                                 f"it follows the signal; give it in [inputs] instead")
            elif name in inputs:
                self.problem(f"parameters.{name}", params[name], f"{name} is given in [inputs] already; expected "
                                                                 f"each input given once, in [inputs]")
        events = self.raw.get("events")
        for i, item in enumerate(events if isinstance(events, list) else ()):
            if isinstance(item, dict) and isinstance(item.get("variable"), str) and item["variable"] in inputs:
                self.problem(f"events[{i}].variable", item["variable"],
                             f"{item['variable']} is given in [inputs] already; expected each input given once "
                             f"(a step or a ramp is an input signal: type = \"step\" or \"ramp\" in [inputs])")

    def input_derivatives(self, inputs: dict[str, InputSignal], fmi_type: str) -> int:
        """``input_derivatives``: the order of the input derivatives set at each step's start:
        false (0: inputs held over the step), true (the FMU's default order,
        :func:`~orchestrator.input_signals.derivative_order`), 1 or 2 (FMI 2.0 declares no highest
        input order: an FMU that says canInterpolateInputs may be given 2).  Default: true when
        the case has inputs and runs an FMU that can interpolate them in co-simulation."""
        value = self.raw.get("input_derivatives")
        can = derivative_order(self.md) if self.md is not None and fmi_type == "CoSimulation" else 0
        if value is None:
            return can if inputs else 0
        if isinstance(value, bool):
            wanted = can if value else 0
        elif isinstance(value, int) and value in (0, 1, 2):
            wanted = value
        else:
            self.problem("input_derivatives", value, "expected true, false, or the order 0, 1 or 2")
            return 0
        if (value is True or wanted > 0) and can == 0 and self.md is not None:
            if fmi_type != "CoSimulation":
                why = "with fmi_type = \"ModelExchange\" the inputs are set at every evaluation of the model"
            else:
                why = f"{self.fmu_name} does not say canInterpolateInputs (FMI 2.0 co-simulation)"
            self.problem("input_derivatives", value, f"{why}; expected false or leave it out")
            return 0
        return wanted if inputs else 0

    def name(self) -> str:
        """``name``, or the case file's name made a folder name when the file has none."""
        value = self.raw.get("name")
        stem = self.source.stem if self.source is not None else None
        if value is None and stem is not None:
            value = name_from_file(self.source)
            if value is None and self.name_only_labels:
                return stem         # --out: the name names no folder, it only labels the run
            if value is None:
                self.problems.append(
                    f"the file name {self.source.name!r} gives no case name: a case file without a `name` key is "
                    f"named after its file, and {stem!r} has no letter or digit of A-Z, a-z, 0-9 to make the folder "
                    f"name out/<name> from; add a line name = \"...\" (letters, digits, '_', '-', '.') at the top "
                    f"of the file, rename the file, or give --out DIR")
                return "invalid"
        elif self.name_only_labels and value == stem:
            return value            # a Case loaded with --out, checked again (apply_overrides)
        return self.identifier("name", value, "the run and its default folder out/<name>") or "invalid"

    def fmu(self) -> Path:
        value = self.raw.get("fmu")
        if "system" in self.raw:
            if value is not None:
                self.problem("system", self.raw["system"],
                             f"the case also names {self.field('fmu')} = {value!r}; expected exactly one of fmu (one FMU) "
                             f"and system (an .ssp file)")
            return self.system()
        if value is None:
            self.missing("fmu", "the path of an FMI 2.0 or 3.0 FMU, relative to the case file (or system = the path "
                                "of an .ssp file)")
            return Path()
        if not isinstance(value, str) or not value:
            self.problem("fmu", value, f"expected a path string, got {kind_of(value)}")
            return Path()
        path = (self.base_dir / value).resolve()
        if not path.is_file():
            self.problem("fmu", value, f"file not found (resolved to {path}); "
                                       "build it with `python build_fmu.py`; variables not checked")
            return path
        try:
            description = describe_fmu(path, self.known)
            md = description.model
        except Exception as exc:   # fmpy raises zipfile/XML/ValidationError/bare Exception
            detail = " ".join(str(exc).split())
            self.problem("fmu", value, f"not a readable FMU ({type(exc).__name__}: {detail}); variables not checked")
            return path
        if md.fmiVersion not in ("2.0", "3.0") or (md.coSimulation is None and md.modelExchange is None):
            kinds = " and ".join(k for k, i in (("co-simulation", md.coSimulation), ("model exchange", md.modelExchange))
                                 if i is not None) or "no co-simulation or model-exchange interface"
            self.problem("fmu", value, f"expected an FMI 2.0 or 3.0 FMU (co-simulation or model exchange), got FMI "
                                       f"{md.fmiVersion} with {kinds}; variables not checked")
            return path
        self.description = description
        self.fmu_name = path.name
        self.binary(value, path)
        return path

    def system(self) -> Path:
        """``system``: an SSP 1.0 archive (.ssp) run instead of one FMU (orchestrator.system)."""
        from .ssp import SspError
        from .system_description import SystemDescription, describe_system

        value = self.raw.get("system")
        if not isinstance(value, str) or not value:
            self.problem("system", value, f"expected the path of an .ssp file, got {kind_of(value)}")
            return Path()
        path = (self.base_dir / value).resolve()
        self.system_path = path
        if not path.is_file():
            self.problem("system", value, f"file not found (resolved to {path}); build it with "
                                          f"`python build_fmu.py --system NAME`; variables not checked")
            return path
        known = self.known if isinstance(self.known, SystemDescription) else None
        try:
            description = describe_system(path, known)
        except SspError as exc:
            self.problem("system", value, f"cannot be run: {exc}; variables not checked")
            return path
        from fmpy import platform as here

        for component in description.components:
            if here not in component.platforms:
                self.problem("system", value, f"component {component.name!r} ({component.source}) has no binary for "
                                              f"this platform ({here}); it has: "
                                              f"{', '.join(component.platforms) or 'no binaries'}")
        self.description = description
        self.fmu_name = path.name
        return path

    def master(self) -> Master:
        """``[master]``: the algorithm, the input treatment and the Gauss–Seidel order of a system."""
        table = self.table("master")
        if table is None:
            return Master()
        if self.system_path is None:
            self.problem("master", table, "a [master] table steps the components of a system; this case runs one "
                                          "FMU (fmu = ...); expected system = \"X.ssp\" or no [master]")
            return Master()
        self.unknown_keys(table, _MASTER_KEYS, "master")
        algorithm = table.get("algorithm", "jacobi")
        if algorithm not in MASTER_ALGORITHMS:
            self.problem("master.algorithm", algorithm, f"expected one of {', '.join(map(repr, MASTER_ALGORITHMS))}")
            algorithm = "jacobi"
        inputs = table.get("inputs", "hold")
        if inputs not in MASTER_INPUTS:
            self.problem("master.inputs", inputs, f"expected one of {', '.join(map(repr, MASTER_INPUTS))}")
            inputs = "hold"
        order: tuple[str, ...] = ()
        if "order" in table:
            given = table["order"]
            names = self.description.ssp.component_names if self.description is not None else None
            if algorithm not in ("gauss-seidel", "monolithic"):
                self.problem("master.order", given, "an order is for algorithm = \"gauss-seidel\" or "
                                                    "\"monolithic\"; Jacobi steps every component from the same "
                                                    "values")
            elif not isinstance(given, list) or not all(isinstance(n, str) for n in given):
                self.problem("master.order", given, "expected an array of component names")
            elif names is not None and sorted(given) != sorted(names):
                self.problem("master.order", given, f"expected each component of {self.fmu_name} once: "
                                                    f"{', '.join(names)}")
            else:
                order = tuple(given)
        if algorithm == "monolithic":
            if inputs != "hold":
                self.problem("master.inputs", inputs, "the monolithic master exchanges no values between steps: "
                                                      "inputs is for jacobi and gauss-seidel")
            if self.description is not None:
                from .monolithic import monolithic_problems

                for problem in monolithic_problems(self.description, order):
                    self.problem("master.algorithm", algorithm, problem)
        return Master(algorithm=algorithm, inputs=inputs, order=order)

    def connected(self, parameters: dict, events: tuple, inputs: dict) -> None:
        """In a system, an input fed by a connection is the master's: no case value may set it."""
        connections = getattr(self.description, "connected_inputs", None)
        if not connections:
            return
        used = [(f"parameters.{n}", n) for n in parameters] + [(f"inputs.{n}", n) for n in inputs]
        used += [(f"events[{i}].variable", e.variable) for i, e in enumerate(events)]
        for where, name in used:
            if name in connections:
                self.problem(where, name, f"{name} is fed by the connection {connections[name]} of {self.fmu_name}; "
                                          f"expected an unconnected input or a parameter")

    def fmi_type(self) -> str:
        """``fmi_type``: the interface the run uses; by default co-simulation when the FMU offers it."""
        value = self.raw.get("fmi_type")
        md = self.description.model if self.description is not None else None
        offered = [t for t, i in zip(FMI_TYPES, (md.coSimulation, md.modelExchange) if md else (None, None))
                   if i is not None]
        if value is None:
            return offered[0] if offered else FMI_TYPES[0]
        if value not in FMI_TYPES:
            self.problem("fmi_type", value, f"expected one of {', '.join(map(repr, FMI_TYPES))}")
            return FMI_TYPES[0]
        if md is not None and value not in offered:
            self.problem("fmi_type", value, f"the FMU does not offer it (it offers {', '.join(offered)})")
        return value

    def binary(self, value: str, path: Path) -> None:
        """The FMU must hold a binary for this machine (FMPy loads ``binaries/<platform>/``)."""
        from fmpy import platform as here, supported_platforms

        try:
            platforms = supported_platforms(str(path))
        except Exception:          # unreadable as a zip: already reported by the description check
            return
        if here not in platforms:
            has = ", ".join("sources" if p == "c-code" else p for p in platforms) or "no binaries"
            hint = (f"; compile one with `fmpy compile {value}`" if "c-code" in platforms
                    else "; use an FMU built for this platform")
            self.problem("fmu", value, f"has no binary for this platform ({here}); it has: {has}{hint}")

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
        if step is not None and step > MAX_STEP:
            self.problem("experiment.step", step, f"expected a communication step <= {MAX_STEP:g} s: one step is one "
                                                  f"doStep the FMU computes without returning (docs/orchestrator.md, "
                                                  f"\"Refusals\")")
        too_long = step is not None and step > MAX_STEP
        if start is None or stop is None or step is None:
            return None
        if stop <= start:
            self.problem("experiment.stop", stop, f"expected a time after experiment.start = {start!r} s")
            return None
        if self.whole_steps("experiment.stop", stop, stop - start, step, "(stop - start)/step",
                            step_name="experiment.step") is None or too_long:
            return None
        return Experiment(start=start, stop=stop, step=step, tolerance=tolerance)

    def variable(self, where: str, name: Any, *, settable: str | None = None, shown: Any = None):
        """The model variable ``name`` (None if unknown or no FMU), checking how it is used.

        settable: None (read), "start" (start value) or "event" (changed during the run).
        ``shown`` is the value quoted in a message (default: the name itself).
        """
        shown = name if shown is None else shown
        if not isinstance(name, str):
            self.problem(where, shown, f"expected a variable name (string), got {kind_of(name)}")
            return None
        if self.md is None:
            return None
        var = self.variables.get(name)
        if var is None and self.system_path is not None:
            component = name.partition(".")[0]
            names = self.description.ssp.component_names
            if "." not in name or component not in names:
                close = difflib.get_close_matches(component, names, n=1)
                hint = f"; did you mean {close[0]!r}?" if close else ""
                self.problem(where, shown, f"{self.fmu_name} has no component {component!r} (its components: "
                                           f"{', '.join(names)}); expected component.variable{hint}")
                return None
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
                self.problem(where, value, f"{var.name} is {vtype}; expected an integer, got {kind_of(value)}")
                return None
            result = value
        elif vtype == "Boolean":
            if not isinstance(value, bool):
                self.problem(where, value, f"{var.name} is Boolean; expected true or false, got {kind_of(value)}")
                return None
            return value
        elif vtype == "String":
            if not isinstance(value, str):
                self.problem(where, value, f"{var.name} is String; expected a string, got {kind_of(value)}")
                return None
            return value
        else:
            self.problem(where, value, f"{var.name} has type {vtype}, which case files cannot set")
            return None
        if result is None:
            return None
        unit = getattr(var, "unit", None)
        limit = UNIT_LIMITS.get(unit) if isinstance(unit, str) else None
        if limit is not None and abs(result) > limit:
            self.problem(where, value, f"expected |{var.name}| <= {limit:g} {unit}: no linkage reaches it "
                                       f"(docs/orchestrator.md, \"Refusals\")")
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
            if not isinstance(name, str):
                self.problem(item, name, f"expected a variable name (string), got {kind_of(name)}")
                continue
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

    def drawing(self) -> tuple[Drawing | None, bool]:
        """The FMU's drawing, when its columns are to be recorded (``[outputs] drawing``,
        default true; None when the FMU declares no drawing), and the case's flag."""
        table = self.raw.get("outputs")
        wanted = table.get("drawing", True) if isinstance(table, dict) else True
        if not isinstance(wanted, bool):
            self.problem("outputs.drawing", wanted, "expected true (record the joint positions a view draws the "
                                                     "mechanism from) or false")
            return None, True
        if not wanted or self.description is None:
            return None, wanted
        if self.description.drawing_problem is not None:
            self.problems.append(f"fmu: {self.description.drawing_problem}; rebuild the FMU, or set "
                                 f"[outputs] drawing = false to run without drawing the mechanism")
            return None, wanted
        drawing = self.description.drawing
        lacking = [c for c in drawing.columns if c not in self.variables] if drawing is not None else []
        if lacking:
            self.problems.append(f"fmu: its drawing places joints by {', '.join(lacking)}, which {self.fmu_name} "
                                 f"does not declare; rebuild the FMU, or set [outputs] drawing = false")
            return None, wanted
        return drawing, wanted

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
        if not isinstance(item["variable"], str):     # reported by variable()
            return None
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
        if not isinstance(item["variable"], str):     # reported by variable()
            return None
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

    def exchange(self, experiment: Experiment | None, outputs: tuple[str, ...]) -> ExchangeSettings:
        defaults = ExchangeSettings()
        table = self.table("exchange")
        if table is None:
            table = {}
        self.unknown_keys(table, _EXCHANGE_KEYS, "exchange")
        flush = self.number("exchange.flush_interval", table.get("flush_interval", defaults.flush_interval), "s",
                            positive=True)
        factor = self.number("exchange.realtime_factor", table.get("realtime_factor", defaults.realtime_factor), "",
                             minimum=0.0)
        if factor is not None and 0.0 < factor < MIN_REALTIME_FACTOR:
            self.problem("exchange.realtime_factor", factor,
                         f"expected 0 (as fast as possible) or a factor >= {MIN_REALTIME_FACTOR:g}: at "
                         f"{factor:g} the run would take {1 / factor:.3g} s of wall time per simulated second")
            factor = None
        max_rows = self.integer("exchange.max_rows", table.get("max_rows", defaults.max_rows), minimum=1)
        if experiment is not None and max_rows is not None:
            self.row_bound(experiment, outputs, max_rows)
        return ExchangeSettings(flush_interval=flush if flush is not None else defaults.flush_interval,
                                realtime_factor=factor if factor is not None else defaults.realtime_factor,
                                max_rows=max_rows if max_rows is not None else defaults.max_rows)

    def row_bound(self, experiment: Experiment, outputs: tuple[str, ...], max_rows: int) -> None:
        """A run may write at most ``max_rows`` rows unless the case (or ``--max-rows``) allows more:
        a mistyped stop or step must not fill the disk."""
        rows = experiment.n_steps + 1
        if rows <= max_rows:
            return
        size = rows * (1 + len(outputs)) * _BYTES_PER_VALUE
        self.problems.append(
            f"experiment: start = {experiment.start!r}, stop = {experiment.stop!r}, step = {experiment.step!r} s "
            f"would write {rows:,} rows (about {_show_bytes(size)} of {EXCHANGE}), more than "
            f"{self.field('exchange.max_rows')} = {max_rows:,}; shorten the run, or allow it with "
            f"[exchange] max_rows = {rows} in the case file (or --max-rows {rows})")

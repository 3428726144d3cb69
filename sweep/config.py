"""Sweep files: the typed, validated description of a set of fault scenarios.

A sweep file is TOML (every key in docs/sweep.md).  It names a base case file and the
axes of the scenarios: the fault (variable, kind, size, time, ramp duration), the noise on
the monitored signal (standard deviation, seed) and the monitor (model, threshold, and any
other :class:`monitor.options.MonitorOptions` field, fixed for the whole sweep).

Each axis is a value, an array of values (a grid axis: every combination is run) or a
range table ``{min = .., max = .., scale = "linear" | "log"}`` (a sampled axis: ``n``
random draws from ``[sample]``, crossed with the grid).  :func:`load_sweep` checks every
key -- against the schema, against the base case (loaded with
:func:`orchestrator.load_case`) and against the monitor's options -- and either returns a
frozen :class:`Sweep` or raises one :class:`SweepError` listing every problem, each naming
the file, the key, the value and what was expected.

Bounded work: the sweep file and its base case must be regular files (a FIFO or a device
such as /dev/zero would be read forever); the sweep's ``stop`` is checked by the orchestrator
as a case's (``exchange.max_rows``); seeds are integers below 2**63 (the results table stores
them as 64-bit integers); and a sweep plans at most :data:`MAX_SCENARIOS` scenarios (counted
before duplicates are removed: every grid point times every draw, plus the fault-free runs),
so a mistyped grid or ``sample.n`` is refused at once instead of being planned for hours.

Heavy imports (FMPy through the orchestrator, numpy through the monitor) happen inside
:func:`load_sweep`, not at import time.
"""
from __future__ import annotations

import difflib
import math
import os
import stat
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping, Union

from orchestrator.validation import (GRID_TOLERANCE, ConfigError, ProblemReporter, is_number, kind_of,
                                     name_from_file, read_toml, show_value)

__all__ = [
    "FaultSpec",
    "FaultVariable",
    "MonitorSpec",
    "NoiseSpec",
    "Range",
    "SampleSpec",
    "Sweep",
    "MAX_SCENARIOS",
    "MAX_SEED",
    "SweepError",
    "load_sweep",
]

_TOP_KEYS = ("name", "description", "case", "fmu", "stop", "fault", "noise", "monitor", "sample", "report", "output",
             "diagnose")
_FAULT_KEYS = ("variable", "kind", "relative", "value", "time", "ramp_duration", "no_fault")
_NOISE_KEYS = ("std", "seed")
_SAMPLE_KEYS = ("n", "seed")
_REPORT_KEYS = ("latency_limit",)
_OUTPUT_KEYS = ("keep_exchange", "monitor_plots")
_DIAGNOSE_KEYS = ("enabled",)
_RANGE_KEYS = ("min", "max", "scale")
_KINDS = ("step", "ramp")
#: Most scenarios a sweep may plan.  sweeps/parameters.toml plans 676; a million scenarios of
#: 30 s runs are weeks of a 2-core machine, and planning them alone takes minutes.
MAX_SCENARIOS = 1_000_000
#: Largest seed (noise.seed, sample.seed): the results table stores seeds as 64-bit integers.
MAX_SEED = 2 ** 63 - 1


class SweepError(ConfigError):
    """A sweep file is invalid; ``problems`` lists every problem (``str`` is the full report)."""

    subject = "sweep"


@dataclass(frozen=True)
class Range:
    """A sampled axis: uniform in ``[min, max]`` (``scale="log"``: uniform in log)."""

    min: float
    max: float
    scale: str = "linear"
    integer: bool = False      # draw whole numbers (seeds)

    def draw(self, rng) -> float | int:
        """One draw from ``rng`` (a ``numpy.random.Generator``); always one call to it."""
        if self.integer:
            return int(rng.integers(int(self.min), int(self.max) + 1))
        u = float(rng.random())
        if self.scale == "log":
            return math.exp(math.log(self.min) + u * (math.log(self.max) - math.log(self.min)))
        return self.min + u * (self.max - self.min)

    def as_dict(self) -> dict:
        return {"min": self.min, "max": self.max, "scale": self.scale}


Axis = Union[tuple, Range]


@dataclass(frozen=True)
class FaultVariable:
    """A parameter the sweep changes: its name, its value in the base case and its unit."""

    name: str
    base_value: float           # the value in the base case (or the FMU's start value)
    unit: str


@dataclass(frozen=True)
class FaultSpec:
    """The injected fault.  ``variables`` is an axis (each scenario changes one of them);
    ``size`` holds relative changes (``0.01`` = +1 %) when ``size_mode == "relative"``,
    else absolute values in the (single) variable's unit."""

    variables: tuple[FaultVariable, ...]
    kind: tuple[str, ...]
    size_mode: str              # "relative" | "value"
    size: Axis
    time: Axis                  # s, on the case's communication grid
    ramp_duration: Axis         # s, ramps only
    no_fault: bool              # also run scenarios without any fault

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(v.name for v in self.variables)


@dataclass(frozen=True)
class NoiseSpec:
    """Gaussian noise added to the monitored signal in the exchange file (the FMU sees none)."""

    std: Axis                   # in the signal's unit; 0 = no noise
    seed: Axis                  # integers >= 0


@dataclass(frozen=True)
class MonitorSpec:
    """Monitor settings: ``model`` and ``threshold`` are axes, ``options`` fixed."""

    signal: str
    model: tuple[str, ...]
    threshold: Axis             # numbers (signal units) and/or "auto"
    options: Mapping[str, Any]  # other MonitorOptions fields, as given in the file
    unit: str = ""              # the signal's unit (from the FMU)


@dataclass(frozen=True)
class SampleSpec:
    n: int
    seed: int


@dataclass(frozen=True)
class Sweep:
    """One validated sweep file."""

    name: str
    source: Path                # the sweep file (absolute)
    case_path: Path             # the base case file (absolute)
    case: Any                   # orchestrator.Case: the base case with ``stop`` applied
    stop: float                 # s
    fault: FaultSpec
    noise: NoiseSpec
    monitor: MonitorSpec
    sample: SampleSpec | None = None
    latency_limit: float = 2.0  # s: "detected within" for the headline figure
    keep_exchange: bool = True
    monitor_plots: bool = False
    diagnose: bool = False      # run fourbar-diagnose after each alarm and score it
    description: str = ""
    notes: tuple[str, ...] = field(default=())   # things the CLI should tell the user

    @property
    def fmu_guid(self) -> str:
        """GUID of the FMU the scenarios run (rows made with another build are not reused)."""
        return self.case.fmu_description.guid

    def as_dict(self) -> dict:
        """JSON-shaped description (written to ``sweep.json`` in the output directory)."""

        def axis(a: Axis) -> Any:
            return a.as_dict() if isinstance(a, Range) else list(a)

        return {
            "name": self.name, "description": self.description, "sweep_file": str(self.source),
            "case_file": str(self.case_path), "fmu": str(self.case.fmu), "fmu_guid": self.fmu_guid,
            "stop": self.stop,
            "fault": {"variable": list(self.fault.names),
                      "base_value": {v.name: v.base_value for v in self.fault.variables},
                      "unit": {v.name: v.unit for v in self.fault.variables}, "kind": list(self.fault.kind),
                      self.fault.size_mode: axis(self.fault.size), "time": axis(self.fault.time),
                      "ramp_duration": axis(self.fault.ramp_duration), "no_fault": self.fault.no_fault},
            "noise": {"std": axis(self.noise.std), "seed": axis(self.noise.seed)},
            "monitor": {"signal": self.monitor.signal, "model": list(self.monitor.model),
                        "threshold": axis(self.monitor.threshold), **dict(self.monitor.options)},
            "sample": None if self.sample is None else {"n": self.sample.n, "seed": self.sample.seed},
            "report": {"latency_limit": self.latency_limit},
            "output": {"keep_exchange": self.keep_exchange, "monitor_plots": self.monitor_plots},
            "diagnose": {"enabled": self.diagnose},
        }


class _Validator(ProblemReporter):
    """Collects every problem of one raw sweep dict, then builds the Sweep or raises."""

    def __init__(self, raw: dict, path: Path):
        self.raw = raw
        self.path = path
        self.problems: list[str] = []
        self.notes: list[str] = []
        self.ranges: list[str] = []        # keys given as range tables

    def axis(self, key: str, value: Any, check, *, allow_range: bool = True, integer: bool = False,
             unit: str = "") -> Axis | None:
        """A scalar, an array (grid) or a range table (sampled); ``check(key, item)`` validates
        one value and returns it (or None after reporting)."""
        if isinstance(value, dict):
            if not allow_range:
                self.problem(key, value, "expected a value or an array of values (this axis cannot be sampled)")
                return None
            return self.range(key, value, integer=integer, unit=unit, check=check)
        items = value if isinstance(value, list) else [value]
        if not items:
            self.problem(key, value, "expected a non-empty array")
            return None
        out = []
        ok = True
        for i, item in enumerate(items):
            where = f"{key}[{i}]" if isinstance(value, list) else key
            checked = check(where, item)
            if checked is None:
                ok = False
            else:
                out.append(checked)
        return tuple(out) if ok else None

    def range(self, key: str, table: dict, *, integer: bool, unit: str, check) -> Range | None:
        self.ranges.append(key)        # given as a range (valid or not): [sample] is expected
        self.unknown_keys(table, _RANGE_KEYS, key)
        lo, hi = table.get("min"), table.get("max")
        if lo is None:
            self.missing(f"{key}.min", "the lower end of the sampled range")
        if hi is None:
            self.missing(f"{key}.max", "the upper end of the sampled range")
        scale = table.get("scale", "linear")
        if scale not in ("linear", "log"):
            self.problem(f"{key}.scale", scale, 'expected "linear" or "log"')
            scale = None
        if integer and scale == "log":
            self.problem(f"{key}.scale", scale, 'expected "linear" for an integer axis')
            scale = None
        lo = check(f"{key}.min", lo) if lo is not None else None
        hi = check(f"{key}.max", hi) if hi is not None else None
        if lo is None or hi is None or scale is None:
            return None
        if not (is_number(lo) and is_number(hi)):
            self.problem(key, table, "expected numbers for min and max of a sampled range")
            return None
        if not lo < hi:
            self.problem(f"{key}.max", hi, f"expected a value above {key}.min = {show_value(lo)}")
            return None
        if scale == "log" and not (lo > 0):
            self.problem(f"{key}.min", lo, 'expected a number > 0 with scale = "log"')
            return None
        if integer:      # seeds: kept exact (a float of 2**63 - 1 rounds up to 2**63)
            return Range(int(lo), int(hi), scale, integer)
        return Range(float(lo), float(hi), scale, integer)

    # -- the sweep ----------------------------------------------------------------------
    def sweep_name(self, raw: Mapping[str, Any]) -> str | None:
        """The sweep's name: its ``name`` key, else its file name made a folder name
        (``name_from_file``: ``my sweep.toml`` -> ``my_sweep``); a file name with nothing usable
        is refused naming the file and what to do."""
        if "name" in raw:
            return self.identifier("name", raw["name"], "the output directory out/sweeps/<name>")
        name = name_from_file(self.path)
        if name is None:
            self.problems.append(
                f"the file name {self.path.name!r} gives no sweep name: a sweep file without a `name` key is named "
                f"after its file, and {self.path.stem!r} has no letter or digit of A-Z, a-z, 0-9 to make the folder "
                f"name out/sweeps/<name> from; add a line name = \"...\" (letters, digits, '_', '-', '.') at the "
                f"top of the file, or rename the file")
        return name

    def sweep(self) -> Sweep:
        raw = self.raw
        self.unknown_keys(raw, _TOP_KEYS, "")
        name = self.sweep_name(raw)
        description = self.text("description", raw.get("description", "")) or ""

        case = self.base_case()
        stop = self.stop(case)
        experiment = None
        if case is not None and stop is not None:
            experiment = replace(case.experiment, stop=stop)
        monitor = self.monitor(case)
        train_end = self.train_end()
        fault = self.fault(case, experiment, train_end)
        noise = self.noise()
        sample = self.sample()
        report = self.table("report") or {}
        self.unknown_keys(report, _REPORT_KEYS, "report")
        latency_limit = self.number("report.latency_limit", report.get("latency_limit", 2.0), "s", positive=True)
        output = self.table("output") or {}
        self.unknown_keys(output, _OUTPUT_KEYS, "output")
        keep_exchange = self.boolean("output.keep_exchange", output.get("keep_exchange", True))
        monitor_plots = self.boolean("output.monitor_plots", output.get("monitor_plots", False))
        diagnose_table = self.table("diagnose") or {}
        self.unknown_keys(diagnose_table, _DIAGNOSE_KEYS, "diagnose")
        diagnose = self.boolean("diagnose.enabled", diagnose_table.get("enabled", False))

        if stop is not None and train_end is not None and stop <= train_end:
            self.problem("stop", stop, f"expected a time after the monitor's training window, which ends at "
                                       f"{train_end!r} s (monitor.train)")
        if self.ranges and sample is None and "sample" not in raw:
            self.missing("sample", f"a [sample] table with n and seed: {', '.join(self.ranges)} "
                                   f"{'is a range' if len(self.ranges) == 1 else 'are ranges'} to sample")
        if sample is not None and not self.ranges:
            self.problem("sample", raw.get("sample"), "nothing to sample: give some axis as a range table "
                                                      "{min = .., max = .., scale = ..}, or remove [sample]")
        if fault is not None and noise is not None and monitor is not None and (sample is not None or not self.ranges):
            self.scenario_bound(fault, noise, monitor, sample)
        if self.problems:
            raise SweepError(str(self.path), self.problems)
        if case.events or case.noise is not None:
            self.notes.append(f"the base case's [[events]] ({len(case.events)}) and [noise] are replaced by "
                              f"each scenario's fault and noise")
        case = replace(case, experiment=experiment, events=(), noise=None)
        return Sweep(name=name, source=self.path, case_path=case.source, case=case, stop=stop, fault=fault,
                     noise=noise, monitor=monitor, sample=sample, latency_limit=latency_limit,
                     keep_exchange=keep_exchange, monitor_plots=monitor_plots, diagnose=bool(diagnose),
                     description=description, notes=tuple(self.notes))

    def scenario_bound(self, fault: FaultSpec, noise: NoiseSpec, monitor: MonitorSpec,
                       sample: SampleSpec | None) -> None:
        """At most :data:`MAX_SCENARIOS` planned scenarios (see the module docstring)."""
        def size(axis: Axis) -> int:
            return 1 if isinstance(axis, Range) else len(axis)

        draws = sample.n if sample is not None else 1
        clean = size(noise.std) * size(noise.seed) * size(monitor.model) * size(monitor.threshold)
        faulty = (len(fault.variables) * size(fault.kind) * size(fault.size) * size(fault.time)
                  * size(fault.ramp_duration or (None,)) * clean)
        count = (faulty + (clean if fault.no_fault else 0)) * draws
        if count > MAX_SCENARIOS:
            self.problems.append(
                f"the sweep plans {count:,} scenarios ({faulty:,} grid points with a fault"
                f"{f' and {clean:,} without' if fault.no_fault else ''}, times {draws:,} draw(s) of [sample]), more "
                f"than the {MAX_SCENARIOS:,} a sweep may run; expected fewer values in its arrays or a smaller "
                f"sample.n")

    def regular_file(self, key: str, value: str, path: Path, what: str) -> bool:
        """False (after a problem on ``key``) when ``path`` cannot be a readable file: it exists but
        is a FIFO, a device or a socket (read forever, or oddly), or its name cannot be looked up
        (too long, a NUL character).  A missing file or a folder is left to the reader, which
        names it."""
        try:
            mode = os.stat(path).st_mode
        except FileNotFoundError:
            return True
        except (OSError, ValueError) as exc:
            reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
            self.problem(key, value, f"cannot be looked up ({reason}); expected the path of a {what}")
            return False
        if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
            return True
        self.problem(key, value, f"not a regular file (a FIFO, device or socket); expected a {what}")
        return False

    def base_case(self):
        """The base case (validated by the orchestrator, with its FMU description), or None."""
        value = self.raw.get("case")
        if value is None:
            self.missing("case", "the path of the base case file, relative to the sweep file")
            return None
        if not isinstance(value, str) or not value:
            self.problem("case", value, f"expected a path string, got {kind_of(value)}")
            return None
        from orchestrator import ConfigError, load_case

        fmu = self.raw.get("fmu")
        if fmu is not None and (not isinstance(fmu, str) or not fmu):
            self.problem("fmu", fmu, f"expected a path string (relative to the sweep file), got {kind_of(fmu)}")
            fmu = None
        if fmu is not None and not self.regular_file("fmu", fmu, self.path.parent / fmu, "FMU file"):
            return None
        if not self.regular_file("case", value, self.path.parent / value, "case file (TOML)"):
            return None
        path = (self.path.parent / value).resolve()
        try:
            case = load_case(path, fmu=None if fmu is None else self.path.parent / fmu)
        except ConfigError as exc:
            if fmu is not None and _runs_a_system(path):
                self.problem("fmu", fmu, f"the base case {path.name} runs a system (system = an .ssp file); fmu "
                                         f"replaces a one-FMU case's FMU: remove it")
                return None
            for p in exc.problems:
                where = "fmu" if p.startswith("fmu") and fmu is not None else f"case = {show_value(value)}: {path.name}"
                self.problems.append(f"{where}: {p}")
            return None
        return case

    def stop(self, case) -> float | None:
        if "stop" not in self.raw:
            return case.experiment.stop if case is not None else None
        stop = self.number("stop", self.raw["stop"], "s", positive=True)
        if stop is None or case is None:
            return stop
        exp = case.experiment
        if stop <= exp.start:
            self.problem("stop", stop, f"expected a time after the case's experiment.start = {exp.start!r} s")
            return None
        if self.whole_steps("stop", stop, stop - exp.start, exp.step,
                            "not on the case's communication grid: (stop - start)/step") is None:
            return None
        from orchestrator import ConfigError, apply_overrides

        try:        # the case's own checks of a run's length (exchange.max_rows), with this stop
            apply_overrides(replace(case, events=(), noise=None), stop=stop)
        except ConfigError as exc:
            for p in exc.problems:
                self.problems.append(f"stop = {show_value(stop)}: {p}")
            return None
        return stop

    def train_end(self) -> float | None:
        """End of the monitor's training window (s): monitor.train[1], else the monitor's default."""
        from monitor import MonitorOptions

        table = self.raw.get("monitor")
        train = table.get("train") if isinstance(table, dict) else None
        if train is None:
            return float(MonitorOptions.train[1])
        if isinstance(train, list) and len(train) == 2 and all(is_number(v) for v in train):
            return float(train[1])
        return None      # reported by the monitor's own check

    def monitor(self, case) -> MonitorSpec | None:
        from monitor import MonitorOptions
        from monitor import OptionError
        from monitor.forecasters import forecaster_names
        from monitor.options import option_default, option_names

        MODELS = forecaster_names()
        table = self.table("monitor") or {}
        fields = option_names()
        self.unknown_keys(table, fields, "monitor")
        ok = True
        from monitor.options import split_signals

        # the run's default signal: the base case's first output column (x2 for the four-bar)
        default_signal = case.recorded[0] if case is not None and case.recorded else ""
        signal = table.get("signal", default_signal)
        if "signal" not in table and not default_signal:
            pass                          # no base case: reported already
        elif not isinstance(signal, str) or not signal.strip():
            self.problem("monitor.signal", signal, "expected the name of an output column, e.g. \"x2\", or several "
                                                   "separated by commas")
            ok = False
        elif case is not None and any(s not in case.recorded for s in split_signals(signal)):
            self.problem("monitor.signal", signal, f"not an output of the base case; expected one of "
                                                   f"{', '.join(case.recorded)} ([outputs] of {case.source.name}), "
                                                   "or several separated by commas")
            ok = False
        else:
            signal = ",".join(split_signals(signal))

        def model_check(key, item):
            if item not in MODELS:
                self.problem(key, item, f"expected one of {', '.join(MODELS)}")
                return None
            return item

        def threshold_check(key, item):
            if item == "auto":
                return item
            if not is_number(item) or item <= 0:
                self.problem(key, item, "expected a positive number in the signal's unit, or \"auto\"")
                return None
            return float(item)

        models = self.axis("monitor.model", table.get("model", MonitorOptions.model), model_check,
                           allow_range=False)
        thresholds = self.axis("monitor.threshold", table.get("threshold", option_default("threshold")),
                               threshold_check)
        options = {k: v for k, v in table.items() if k not in ("signal", "model", "threshold") and k in fields}
        # the remaining options are checked by the monitor itself, all problems at once
        # a numeric threshold (an MAE level) joins the check, so a detector that does not use it is refused
        level = thresholds.min if isinstance(thresholds, Range) else \
            next((t for t in thresholds or () if t != "auto"), None)
        try:
            trial = dict(options)
            if isinstance(trial.get("train"), list):
                trial["train"] = tuple(trial["train"])
            if level is not None:
                trial["threshold"] = level
            MonitorOptions(**trial).validated()
        except OptionError as exc:
            for problem in exc.problems:
                key = problem.field
                shown = show_value(options.get(key)) if key in options else \
                    show_value(table["threshold"]) if key == "threshold" and level is not None else "(default)"
                self.problems.append(f"monitor.{key} = {shown}: {problem.message}")
            ok = False
        except TypeError as exc:       # a wrong type the dataclass could not even take
            self.problems.append(f"monitor: {exc}")
            ok = False
        if not ok or models is None or thresholds is None:
            return None
        unit = ""
        if case is not None:
            first = signal.split(",")[0]
            unit = case.fmu_description.units([first]).get(first, "")
        return MonitorSpec(signal=signal, model=models, threshold=thresholds, options=options, unit=unit)

    def fault(self, case, experiment, train_end) -> FaultSpec | None:
        table = self.table("fault", required=True)
        if table is None:
            return None
        self.unknown_keys(table, _FAULT_KEYS, "fault")
        ok = True
        variables = self.fault_variables(table.get("variable"), case)
        ok = variables is not None
        unit = variables[0].unit if variables else ""
        for v in variables or ():
            if v.base_value == 0:
                # a relative change cannot move 0, and every size the sweep reports is a relative one
                unit_text = f" {v.unit}" if v.unit else ""
                self.problems.append(
                    f"fault.variable: {v.name} is 0{unit_text} in the base case; a sweep's fault sizes are relative "
                    f"changes (fault.relative, and its report bins every fault by |relative change|), which a zero "
                    f"value does not have: set a non-zero {v.name} in the base case's [parameters], or run its "
                    f"faults as cases (fourbar-run with a [[events]] step; fourbar-diagnose reports its change in "
                    f"{v.unit or 'its unit'})")
                ok = False

        def kind_check(key, item):
            if item not in _KINDS:
                self.problem(key, item, 'expected "step" or "ramp"')
                return None
            return item

        kinds = self.axis("fault.kind", table.get("kind", "step"), kind_check, allow_range=False)

        if "relative" in table and "value" in table:
            self.problems.append("fault.relative and fault.value: both given; expected exactly one "
                                 "(relative changes, or absolute values)")
            ok = False
            size_mode, size = "relative", None
        elif "relative" in table:
            size_mode = "relative"
            size = self.axis("fault.relative", table["relative"], self.relative_change)
        elif "value" in table:
            size_mode = "value"
            size = self.axis("fault.value", table["value"], lambda k, v: self.number(k, v, unit))
            if variables is not None and len(variables) > 1:
                self.problem("fault.value", table["value"], "expected fault.relative when fault.variable names "
                                                            "several parameters (absolute values have one unit)")
                ok = False
        else:
            self.missing("fault.relative", "the fault sizes: relative changes (0.01 = +1 %) in fault.relative, "
                                           "or absolute values in fault.value")
            size_mode, size = "relative", None

        grid = experiment if experiment is not None else (case.experiment if case is not None else None)
        stop = experiment.stop if experiment is not None else None    # None: stop itself is invalid

        def time_check(key, item):
            t = self.number(key, item, "s")
            if t is None:
                return None
            if grid is not None:
                if t < grid.start or (stop is not None and t >= stop):
                    self.problem(key, t, f"expected a time in [{grid.start!r}, {stop!r}) s (from the case's "
                                         f"experiment.start to the sweep's stop)")
                    return None
                if train_end is not None and t < train_end:
                    self.problem(key, t, f"expected a time at or after the end of the monitor's training window "
                                         f"{train_end!r} s (monitor.train), so the model learns the healthy motion")
                    return None
                if not key.endswith((".min", ".max")) and grid.index(t) is None:
                    self.problem(key, t, f"not on the communication grid start + k*step (step {grid.step!r} s)")
                    return None
            return t

        times = self.axis("fault.time", table.get("time"), time_check) if "time" in table else None
        if "time" not in table:
            self.missing("fault.time", "the fault time(s) in s")

        def duration_check(key, item):
            d = self.number(key, item, "s", positive=True)
            if d is None:
                return None
            if grid is not None and not key.endswith((".min", ".max")):
                if self.whole_steps(key, d, d, grid.step, "ramp_duration/step") is None:
                    return None
            return d

        durations: Axis | None = ()
        if "ramp_duration" in table:
            durations = self.axis("fault.ramp_duration", table["ramp_duration"], duration_check)
        elif kinds is not None and "ramp" in kinds:
            self.missing("fault.ramp_duration", "the ramp duration(s) in s (fault.kind includes \"ramp\")")
            durations = None
        if kinds is not None and "ramp" in kinds and stop is not None and times is not None and durations:
            t_max = times.max if isinstance(times, Range) else max(times)
            d_max = durations.max if isinstance(durations, Range) else max(durations)
            if t_max + d_max > stop + GRID_TOLERANCE * grid.step:
                self.problem("fault.ramp_duration", table.get("ramp_duration"),
                             f"a ramp starting at {t_max!r} s and lasting {d_max!r} s ends after stop = "
                             f"{stop!r} s")
                ok = False
        no_fault = self.boolean("fault.no_fault", table.get("no_fault", False))
        if not ok or None in (kinds, size, times, durations, no_fault):
            return None
        return FaultSpec(variables=variables, kind=kinds, size_mode=size_mode, size=size, time=times,
                         ramp_duration=durations, no_fault=no_fault)

    def fault_variables(self, value: Any, case) -> tuple[FaultVariable, ...] | None:
        """``fault.variable``: one name or an array of names of tunable Real parameters."""
        if value is None:
            self.missing("fault.variable", "the name of a tunable parameter of the FMU, e.g. \"L2\", "
                                           "or an array of names")
            return None
        names = value if isinstance(value, list) else [value]
        if not names:
            self.problem("fault.variable", value, "expected a non-empty array of parameter names")
            return None
        tunable = {}
        if case is not None:
            # a system's input fed by a connection is the master's: no fault sets it
            connected = getattr(case.fmu_description, "connected_inputs", {})
            tunable = {v.name: v for v in case.fmu_description.model.modelVariables
                       if v.type == "Real" and v.name not in connected
                       and (v.causality == "input" or (v.causality == "parameter" and v.variability == "tunable"))}
        # a system's parameter starts at its SSP binding when it has one (else its FMU's start)
        starts = {p.name: p.start for p in case.fmu_description.parameter_starts()} if case is not None else {}
        out: list[FaultVariable] = []
        for i, name in enumerate(names):
            key = f"fault.variable[{i}]" if isinstance(value, list) else "fault.variable"
            if not isinstance(name, str):
                self.problem(key, name, f"expected a variable name (string), got {kind_of(name)}")
                continue
            if name in (v.name for v in out):
                self.problem(key, name, "named twice; expected each parameter once")
                continue
            if case is None:
                continue
            var = tunable.get(name)
            if var is None:
                close = difflib.get_close_matches(name, tunable, n=1)
                hint = f"did you mean {close[0]!r}? " if close else ""
                what = f"fed by the connection from {connected[name].source}" if name in connected else \
                    f"not a tunable Real parameter of {case.fmu.name}"
                self.problem(key, name, f"{what}; "
                                        f"{hint}expected one of {', '.join(tunable)}")
                continue
            start = case.parameters.get(name, starts.get(name, var.start))
            try:
                out.append(FaultVariable(name, float(start), var.unit or ""))
            except (TypeError, ValueError):
                self.problem(key, name, f"has no numeric value in the base case or the FMU "
                                        f"(start {start!r}); set it in [parameters]")
        return tuple(out) if len(out) == len(names) else None

    def relative_change(self, key: str, value: Any) -> float | None:
        """A relative change: finite, non-zero (no_fault = true gives fault-free runs), > -1."""
        change = self.number(key, value)
        if change == 0.0:
            self.problem(key, change, "expected a non-zero change (use fault.no_fault = true for runs "
                                      "without a fault)")
            return None
        if change is not None and change <= -1.0:
            self.problem(key, change, "expected a change > -1 (-100 %)")
            return None
        return change

    def seed(self, key: str, value: Any) -> int | None:
        """A seed: an integer in [0, :data:`MAX_SEED`]."""
        seed = self.integer(key, value, minimum=0)
        if seed is not None and seed > MAX_SEED:
            self.problem(key, seed, f"expected an integer <= 2**63 - 1 = {MAX_SEED} (the results table stores "
                                    f"seeds as 64-bit integers)")
            return None
        return seed

    def noise(self) -> NoiseSpec | None:
        table = self.table("noise") or {}
        self.unknown_keys(table, _NOISE_KEYS, "noise")
        std = self.axis("noise.std", table.get("std", 0.0), lambda k, v: self.number(k, v, minimum=0.0))
        seed = self.axis("noise.seed", table.get("seed", 1), self.seed, integer=True)
        if std is None or seed is None:
            return None
        return NoiseSpec(std=std, seed=seed)

    def sample(self) -> SampleSpec | None:
        if "sample" not in self.raw:
            return None
        table = self.table("sample")
        if table is None:
            return None
        self.unknown_keys(table, _SAMPLE_KEYS, "sample")
        n = seed = None
        if "n" not in table:
            self.missing("sample.n", "the number of random draws")
        else:
            n = self.integer("sample.n", table["n"], minimum=1)
        if "seed" not in table:
            self.missing("sample.seed", "an integer seed (the draws are reproducible)")
        else:
            seed = self.seed("sample.seed", table["seed"])
        if n is None or seed is None:
            return None
        return SampleSpec(n=n, seed=seed)


def _runs_a_system(case: Path) -> bool:
    """Whether the case file at ``case`` loads as a system case (``system = "X.ssp"``)."""
    from orchestrator import ConfigError, load_case

    try:
        return load_case(case).system is not None
    except ConfigError:
        return False


def load_sweep(path: str | Path) -> Sweep:
    """Read and validate a sweep file; raise :class:`SweepError` listing every problem."""
    path = Path(path)
    checker = _Validator({}, path)
    if not checker.regular_file("sweep", str(path), path, "sweep file (TOML)"):
        raise SweepError(str(path), checker.problems)
    raw = read_toml(path, "sweep file", SweepError)
    return _Validator(raw, path.resolve()).sweep()

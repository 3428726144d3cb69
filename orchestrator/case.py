"""The typed description of one co-simulation run: :class:`Case` and its parts.

A :class:`Case` is what :func:`orchestrator.load_case` returns after checking a case file
against the schema and the FMU (see :mod:`orchestrator.config`).  It also keeps what that
check read from the FMU (:class:`FmuDescription`), so nothing downstream parses the model
description again.

Time grid.  The communication points are ``t_k = start + k*step`` for ``k = 0 .. n``,
``n = (stop - start)/step``, a whole number.  Events lie on that grid.

Standard library only at import time; FMPy is imported when an FMU is described.
"""
from __future__ import annotations

import os
import zipfile
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any, Mapping

from fourbar_common import Drawing, DrawingError, Event, RampEvent, StepEvent, Value
from fourbar_common.contract.run_record import ParameterStart

from .input_signals import InputSignal
from .validation import grid_steps

__all__ = [
    "DEFAULT_MAX_ROWS",
    "DEFAULT_OUTPUTS",
    "Case",
    "Event",
    "ExchangeSettings",
    "Experiment",
    "FmuDescription",
    "MASTER_ALGORITHMS",
    "MASTER_INPUTS",
    "Master",
    "Noise",
    "RampEvent",
    "StepEvent",
    "Value",
    "describe_fmu",
]

#: Outputs written when a case has no ``[outputs]`` table (the paper's order).
DEFAULT_OUTPUTS = ("x2", "y2", "x3", "y3", "x4", "y4")


def _stamp(path: Path) -> tuple[int, int]:
    st = os.stat(path)
    return st.st_mtime_ns, st.st_size


@dataclass(frozen=True)
class FmuDescription:
    """What was read from an FMU file: FMPy's model description, and the file's
    modification time and size when it was read (so a rebuilt FMU is read again)."""

    path: Path
    stamp: tuple[int, int]
    model: Any                     # fmpy.model_description.ModelDescription
    #: How to draw the mechanism, from the FMU's drawing annotation (None: it has none), and
    #: why the annotation could not be read when it is malformed (``drawing`` is None then).
    drawing: Drawing | None = None
    drawing_problem: str | None = None
    #: FMI 3.0: each variable's own type (Float64, Int32, ...) by name; its ``type`` reads as FMI 2.0's.
    own_types: dict[str, str] = field(default_factory=dict)

    @property
    def guid(self) -> str:
        return self.model.guid

    @cached_property
    def variables(self) -> dict[str, Any]:
        """Model variables by name (FMPy ``ScalarVariable`` objects)."""
        return {v.name: v for v in self.model.modelVariables}

    def units(self, names) -> dict[str, str]:
        """The declared unit of each of ``names`` that has one."""
        return {n: self.variables[n].unit for n in names if n in self.variables and self.variables[n].unit}

    def parameter_starts(self) -> tuple[ParameterStart, ...]:
        """Every parameter the FMU declares (causality ``parameter``, tunable and fixed, any
        type), with its own start value from modelDescription.xml, in the FMU's order
        (source ``fmu``; ``start`` None when it declares none)."""
        return tuple(ParameterStart(name=v.name, start=_start_value(v), source="fmu", type=v.type,
                                    variability=v.variability, unit=getattr(v, "unit", None) or None)
                     for v in self.model.modelVariables if v.causality == "parameter")

    def is_current(self) -> bool:
        """True while the file is the one that was read (same modification time and size)."""
        try:
            return _stamp(self.path) == self.stamp
        except OSError:
            return False


def _start_value(var) -> Value | None:
    """A variable's declared start value as a Python value of its type (FMPy keeps the XML text)."""
    text = var.start
    if text is None:
        return None
    if var.type == "Real":
        return float(text)
    if var.type in ("Integer", "Enumeration"):
        return int(text)
    if var.type == "Boolean":
        return text if isinstance(text, bool) else str(text).strip().lower() in ("true", "1")
    return str(text)


def describe_fmu(path: Path, known: FmuDescription | None = None) -> FmuDescription:
    """The description of the FMU at ``path``: ``known`` when it describes the same,
    unchanged file, else read now (FMPy's exceptions propagate)."""
    path = Path(path)
    if known is not None and known.path == path and known.is_current():
        return known
    from fmpy import read_model_description     # heavy import, only when a file is read

    stamp = _stamp(path)
    model = read_model_description(str(path))
    own_types = _fmi2_type_names(model)
    drawing, problem = _drawing(path)
    return FmuDescription(path=path, stamp=stamp, model=model, drawing=drawing, drawing_problem=problem,
                          own_types=own_types)


#: FMI 3.0's variable types by the FMI 2.0 names the orchestrator (and run.json) use.
_FMI2_TYPE = {"Float64": "Real", "Float32": "Real", "Int8": "Integer", "UInt8": "Integer", "Int16": "Integer",
              "UInt16": "Integer", "Int32": "Integer", "UInt32": "Integer", "Int64": "Integer", "UInt64": "Integer"}


def _fmi2_type_names(model) -> dict[str, str]:
    """An FMI 3.0 description's variables typed with FMI 2.0's names (Float64 -> Real, Int32 ->
    Integer, ...): one vocabulary for every check of a case, and for run.json.  Returns their
    own types by name (what the FMI 3.0 getters and setters are named after); {} for FMI 2.0."""
    if not str(model.fmiVersion).startswith("3"):
        return {}
    own = {v.name: v.type for v in model.modelVariables}
    for v in model.modelVariables:
        v.type = _FMI2_TYPE.get(v.type, v.type)
    return own


def _drawing(path: Path) -> tuple[Drawing | None, str | None]:
    """The drawing annotation of the FMU at ``path`` (FMPy keeps no vendor annotations) and
    the problem that made it unreadable, if any."""
    try:
        with zipfile.ZipFile(path) as z:
            xml = z.read("modelDescription.xml")
        return Drawing.from_model_description(xml, f"{path.name}'s modelDescription.xml"), None
    except DrawingError as exc:
        return None, str(exc)
    except (OSError, KeyError, zipfile.BadZipFile) as exc:   # FMPy read it a moment ago: a race
        return None, f"{path.name}: cannot read modelDescription.xml again: {exc}"


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
        return grid_steps(t - self.start, self.step)

    def as_dict(self) -> dict:
        return {"start": self.start, "stop": self.stop, "step": self.step, "tolerance": self.tolerance}




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


#: ``[master] algorithm``: how a system's components are stepped (orchestrator.system), or
#: integrated as one model without coupling error (orchestrator.monolithic).
MASTER_ALGORITHMS = ("jacobi", "gauss-seidel", "monolithic")
#: ``[master] inputs``: a connected input held over the step, or extrapolated linearly.
MASTER_INPUTS = ("hold", "extrapolate")


@dataclass(frozen=True)
class Master:
    """How a system (``system = "X.ssp"``) is stepped: ``algorithm`` jacobi | gauss-seidel |
    monolithic, ``inputs`` hold | extrapolate, ``order`` the Gauss–Seidel order (monolithic: the
    evaluation order) the case gave (empty: from the connections,
    :func:`orchestrator.system_order.gauss_seidel_order`, :func:`orchestrator.system_order.evaluation_plan`).
    The macro step is ``[experiment] step``."""

    algorithm: str = "jacobi"
    inputs: str = "hold"
    order: tuple[str, ...] = ()

    def as_dict(self) -> dict:
        data = {"algorithm": self.algorithm, "inputs": self.inputs}
        if self.order:
            data["order"] = list(self.order)
        return data


#: Most rows a run may write unless its case allows more (``[exchange] max_rows``,
#: ``--max-rows``): 10 million rows, 28 hours at a 0.01 s step, about 1.4 GB of exchange.csv
#: with six outputs.  A mistyped stop or step is refused before anything is written.
DEFAULT_MAX_ROWS = 10_000_000


@dataclass(frozen=True)
class ExchangeSettings:
    """How the exchange file is written."""

    flush_interval: float = 1.0    # simulated seconds between appends
    realtime_factor: float = 0.0   # 0: as fast as possible; 1: wall clock; 20: 20x faster
    max_rows: int = DEFAULT_MAX_ROWS   # most rows the run may write (checked before it starts)

    def as_dict(self) -> dict:
        return {"flush_interval": self.flush_interval, "realtime_factor": self.realtime_factor,
                "max_rows": self.max_rows}


@dataclass(frozen=True)
class Case:
    """One validated scenario: FMU, experiment, start values, events, outputs, noise, exchange."""

    name: str
    fmu: Path                      # absolute path of the .fmu
    experiment: Experiment
    parameters: Mapping[str, Value] = field(default_factory=dict)
    events: tuple[Event, ...] = ()
    outputs: tuple[str, ...] = DEFAULT_OUTPUTS
    #: The FMU's drawing when its columns are recorded (after ``outputs``: :attr:`recorded`);
    #: None with ``[outputs] drawing = false`` or when the FMU declares no drawing.
    drawing: Drawing | None = None
    #: ``[outputs] drawing``: record the drawing's columns when the FMU declares a drawing.
    record_drawing: bool = True
    noise: Noise | None = None
    exchange: ExchangeSettings = ExchangeSettings()
    description: str = ""
    source: Path | None = None     # the case file, when loaded from one
    #: Names in ``parameters`` whose value came from an override (``--set``, ``overrides=``), not the case.
    overridden: frozenset[str] = frozenset()
    #: What validation read from ``fmu``; set by load_case/apply_overrides, not compared.
    fmu_description: FmuDescription | None = field(default=None, compare=False, repr=False)
    #: The FMI interface the run uses (``fmi_type``): "CoSimulation", or "ModelExchange" with
    #: FMPy's CVode integrating (orchestrator.instance); by default co-simulation when offered.
    fmi_type: str = "CoSimulation"
    #: ``[inputs]``: the signal each FMU input is given, by input name (orchestrator.input_signals).
    inputs: Mapping[str, InputSignal] = field(default_factory=dict)
    #: The input derivatives set at each step's start (``fmi2SetRealInputDerivatives``): 0 (inputs
    #: held over the step), 1 or 2 (``input_derivatives``; by default what the FMU accepts).
    input_derivative_order: int = 0
    #: ``system``: the .ssp the case runs instead of one FMU (then ``fmu`` is the same path and
    #: ``fmu_description`` an orchestrator.system_description.SystemDescription); None: one FMU.
    system: Path | None = None
    #: ``[master]``: how the system's components are stepped (systems only).
    master: Master = Master()

    @property
    def fault_time(self) -> float | None:
        """Earliest event time (a step's time or a ramp's start), None without events."""
        return min((e.first_time for e in self.events), default=None)

    @property
    def recorded(self) -> tuple[str, ...]:
        """The columns read from the FMU after ``time``: ``outputs``, then the drawing's columns
        they do not already name."""
        if self.drawing is None:
            return self.outputs
        return self.outputs + tuple(c for c in self.drawing.columns if c not in self.outputs)

    @property
    def input_columns(self) -> tuple[str, ...]:
        """The inputs written after :attr:`recorded` (each signal's value at the row's time),
        those :attr:`recorded` does not already name."""
        recorded = self.recorded
        return tuple(name for name in self.inputs if name not in recorded)

    @property
    def columns(self) -> tuple[str, ...]:
        """The exchange file's columns after ``time``: :attr:`recorded`, then :attr:`input_columns`."""
        return self.recorded + self.input_columns

    def as_dict(self) -> dict:
        """The case as a TOML-shaped dict (what run.json records and what overrides edit)."""
        data = {"name": self.name, "description": self.description, "fmu": str(self.fmu), "fmi_type": self.fmi_type,
                "experiment": {k: v for k, v in self.experiment.as_dict().items() if v is not None},
                "parameters": dict(self.parameters),
                "events": [e.as_dict() for e in self.events],
                "outputs": {"variables": list(self.outputs), "drawing": self.record_drawing},
                "exchange": self.exchange.as_dict()}
        if self.noise is not None:
            data["noise"] = self.noise.as_dict()
        if self.system is not None:
            del data["fmu"], data["fmi_type"]
            data["system"] = str(self.system)
            data["master"] = self.master.as_dict()
        if self.inputs:
            data["inputs"] = {name: signal.as_toml() for name, signal in self.inputs.items()
                              if signal.KIND != "derivative"}     # derived again from the position
            data["input_derivatives"] = self.input_derivative_order
        return data


"""What case validation reads from an ``.ssp``: :class:`SystemDescription`, one model of it.

The system is seen as one model whose variables are named ``component.variable``.

The system description answers what case validation and run.json ask of an
:class:`~orchestrator.case.FmuDescription` (``model.modelVariables``, ``variables``,
``units``, ``parameter_starts``, ``is_current``, ``guid``; ``canGetAndSetFMUstate`` when every
component can, for the diagnosis' replay), so every check of a case (a
parameter's type and range, an event's variable, an output, noise, an input signal) works
unchanged on ``motor.R`` or ``fourbar.omega2``.  Each component keeps its own model
description (:class:`ComponentDescription`) for the run (:mod:`orchestrator.system`).

The start value a system run gives a parameter: the SSP's parameter binding when it has one
(source ``ssp``), else the FMU's own (source ``fmu``); a case's ``[parameters]`` then
overrides either (``case`` / ``set``).
"""
from __future__ import annotations

import copy
import io
import os
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from types import SimpleNamespace
from typing import Any

from fourbar_common.contract.run_record import ParameterStart
from fourbar_common.drawing import Drawing, DrawingError

from .case import _fmi2_type_names, _start_value
from .ssp import SspConnection, SspError, SspSystem, component_bytes, read_ssp

__all__ = ["ComponentDescription", "SystemDescription", "describe_system"]


@dataclass(frozen=True)
class ComponentDescription:
    """One component: its name in the system, its FMU's path in the archive and SHA-256, and
    FMPy's model description of it (FMI 3.0 types renamed to FMI 2.0's, ``own_types`` keeps them)."""

    name: str
    source: str
    sha256: str
    model: Any
    own_types: dict[str, str] = field(default_factory=dict)
    platforms: tuple[str, ...] = ()

    @cached_property
    def variables(self) -> dict[str, Any]:
        return {v.name: v for v in self.model.modelVariables}

    @property
    def fmi_version(self) -> str:
        return str(self.model.fmiVersion)

    @property
    def can_interpolate_inputs(self) -> bool:
        cs = self.model.coSimulation
        return bool(cs is not None and self.fmi_version.startswith("2") and cs.canInterpolateInputs)

    def direct_inputs(self, output: str) -> bool:
        """Whether ``output`` depends directly on an input (ModelStructure; no dependency list: yes)."""
        inputs = {v.name for v in self.model.modelVariables if v.causality == "input"}
        if not inputs:
            return False
        for unknown in self.model.outputs:
            if unknown.variable.name == output:
                if unknown.dependencies is None:
                    return True
                return any(d.name in inputs for d in unknown.dependencies)
        return True


@dataclass(frozen=True)
class SystemDescription:
    """The system of an ``.ssp`` file as case validation and run.json see it (module docstring)."""

    path: Path
    stamp: tuple[int, int]
    ssp: SspSystem
    components: tuple[ComponentDescription, ...]
    #: The drawing of the first component whose FMU declares one, named as the system's
    #: columns (``fourbar.A_x``: :meth:`Drawing.in_component`), the component's name, and why
    #: that component's drawing could not be read when it is malformed (``drawing`` None then).
    drawing: Drawing | None = None
    drawing_problem: str | None = None
    drawn_component: str | None = None
    own_types: dict[str, str] = field(default_factory=dict)

    @property
    def guid(self) -> str:
        return self.ssp.sha256

    def component(self, name: str) -> ComponentDescription:
        return next(c for c in self.components if c.name == name)

    @cached_property
    def model(self) -> Any:
        """A model description of the whole system: every component's variables named
        ``component.variable``; co-simulation only, FMI "2.0" (the orchestrator's vocabulary)."""
        variables = []
        for component in self.components:
            for v in component.model.modelVariables:
                twin = copy.copy(v)
                twin.name = f"{component.name}.{v.name}"
                variables.append(twin)
        saves = all(getattr(c.model.coSimulation, "canGetAndSetFMUstate", False) for c in self.components)
        cs = SimpleNamespace(modelIdentifier=self.ssp.name, canInterpolateInputs=False, maxOutputDerivativeOrder=0,
                             canGetAndSetFMUstate=saves)
        return SimpleNamespace(modelVariables=variables, fmiVersion="2.0", coSimulation=cs, modelExchange=None,
                               guid=self.ssp.sha256, modelName=self.ssp.name, outputs=[])

    @cached_property
    def variables(self) -> dict[str, Any]:
        return {v.name: v for v in self.model.modelVariables}

    def units(self, names) -> dict[str, str]:
        return {n: self.variables[n].unit for n in names if n in self.variables and self.variables[n].unit}

    @cached_property
    def connected_inputs(self) -> dict[str, SspConnection]:
        """The connection that feeds each connected input, by ``component.variable``."""
        return {c.target: c for c in self.ssp.connections}

    def parameter_starts(self) -> tuple[ParameterStart, ...]:
        """Every component parameter with its start value in this system: the SSP's binding
        (source ``ssp``) or the FMU's own (``fmu``), in the SSD's component order."""
        starts = []
        for component in self.components:
            bound = self.ssp.bindings(component.name)
            for v in component.model.modelVariables:
                if v.causality != "parameter":
                    continue
                binding = bound.get(v.name)
                start, source = (binding.value, "ssp") if binding is not None else (_start_value(v), "fmu")
                if binding is not None and v.type == "Real":
                    start = float(start)
                starts.append(ParameterStart(name=f"{component.name}.{v.name}", start=start, source=source,
                                             type=v.type, variability=v.variability, unit=getattr(v, "unit", None) or None))
        return tuple(starts)

    def is_current(self) -> bool:
        try:
            st = os.stat(self.path)
        except OSError:
            return False
        return (st.st_mtime_ns, st.st_size) == self.stamp


def describe_system(path: Path, known: SystemDescription | None = None) -> SystemDescription:
    """The description of the ``.ssp`` at ``path`` (``known`` when it is the same unchanged
    file); :class:`~orchestrator.ssp.SspError` when it cannot be read or a component's FMU
    does not match its declared connectors."""
    import hashlib

    from fmpy import read_model_description, supported_platforms

    path = Path(path)
    if known is not None and known.path == path and known.is_current():
        return known
    st = os.stat(path)
    ssp = read_ssp(path)
    components = []
    drawn = None
    for component in ssp.components:
        data = component_bytes(ssp, component.name)
        where = f"{path}: component {component.name!r} ({component.source})"
        try:
            model = read_model_description(io.BytesIO(data), validate=False)
            platforms = tuple(supported_platforms(io.BytesIO(data)))
        except Exception as exc:       # FMPy raises zipfile/XML/bare exceptions
            raise SspError(f"{where}: not a readable FMU ({type(exc).__name__}: {' '.join(str(exc).split())})") from None
        if model.coSimulation is None:
            raise SspError(f"{where}: the FMU offers no co-simulation interface; a system runs co-simulation FMUs")
        own = _fmi2_type_names(model)
        described = ComponentDescription(name=component.name, source=component.source,
                                         sha256=hashlib.sha256(data).hexdigest(), model=model, own_types=own,
                                         platforms=platforms)
        _check_connectors(described, component, where)
        components.append(described)
        if drawn is None:
            drawn = _component_drawing(component.name, data, where)
    drawing, problem, component_name = drawn or (None, None, None)
    system = SystemDescription(path=path, stamp=(st.st_mtime_ns, st.st_size), ssp=ssp, components=tuple(components),
                               drawing=drawing, drawing_problem=problem, drawn_component=component_name)
    _check_bindings(system)
    _check_connections(system)
    return system


def _component_drawing(name: str, data: bytes, where: str) -> tuple[Drawing | None, str | None, str] | None:
    """The drawing the component's FMU (``data``) declares, in the system's names, with the
    problem that made it unreadable; None when it declares none."""
    import zipfile

    try:
        with zipfile.ZipFile(io.BytesIO(data)) as z:
            xml = z.read("modelDescription.xml")
        drawing = Drawing.from_model_description(xml, f"{where}: modelDescription.xml")
    except DrawingError as exc:
        return None, str(exc), name
    except (OSError, KeyError, zipfile.BadZipFile):   # FMPy read it a moment ago
        return None
    return (drawing.in_component(name), None, name) if drawing is not None else None


_KINDS = {"input": ("input",), "output": ("output",), "parameter": ("parameter",),
          "calculatedParameter": ("calculatedParameter",), "inout": ("input", "output")}


def _check_connectors(component: ComponentDescription, declared, where: str) -> None:
    for connector in declared.connectors:
        var = component.variables.get(connector.name)
        if var is None:
            raise SspError(f"{where}: <Connector name={connector.name!r}>: the FMU has no variable of that name")
        if var.causality not in _KINDS.get(connector.kind, (connector.kind,)):
            raise SspError(f"{where}: <Connector name={connector.name!r} kind={connector.kind!r}>: the FMU declares "
                           f"it a {var.causality}")


def _check_bindings(system: SystemDescription) -> None:
    for parameter in system.ssp.parameters:
        var = system.component(parameter.component).variables.get(parameter.variable)
        where = f"{system.path}: {parameter.origin} <Parameter name={parameter.name!r}>"
        if var is None:
            raise SspError(f"{where}: component {parameter.component!r} has no variable {parameter.variable!r}")
        if var.causality not in ("parameter", "input") or var.variability == "constant":
            raise SspError(f"{where}: {parameter.variable} is a {var.causality} ({var.variability}); a binding sets "
                           f"a parameter or an input")


def _check_connections(system: SystemDescription) -> None:
    seen: dict[str, SspConnection] = {}
    for connection in system.ssp.connections:
        where = f"{system.path}: <Connection {connection}>"
        start = system.component(connection.start_component).variables[connection.start_connector]
        end = system.component(connection.end_component).variables[connection.end_connector]
        if start.causality != "output":
            raise SspError(f"{where}: {connection.source} is a {start.causality}; a connection starts at an output")
        if end.causality != "input":
            raise SspError(f"{where}: {connection.target} is a {end.causality}; a connection ends at an input")
        if start.type != "Real" or end.type != "Real":
            raise SspError(f"{where}: {connection.source} is {start.type} and {connection.target} {end.type}; "
                           f"fourbar-run connects Real variables only")
        if connection.target in seen:
            raise SspError(f"{where}: {connection.target} is fed twice (also by {seen[connection.target].source})")
        seen[connection.target] = connection

"""What a system needs of each component's FMU, and the checks of a system against it.

:func:`read_interface` reads a built FMU's modelDescription.xml (FMPy's reader) into a typed
:class:`FmuInterface`; :func:`check_system` checks every connection and binding of a
:class:`~fmu_src.system.description.SystemDescription` against the interfaces and raises one
:class:`~fmu_src.system.description.SystemFileError` listing every problem: an unknown variable
(with the closest name), an output where an input belongs or the reverse, a type other than Real,
units that differ, an input connected twice, a bound value that is not a parameter or an
unconnected input, or one outside the variable's [min, max].
"""
from __future__ import annotations

import difflib
from dataclasses import dataclass
from pathlib import Path

from .description import SystemDescription, SystemFileError

__all__ = ["Port", "UnitDefinition", "FmuInterface", "read_interface", "check_system"]


@dataclass(frozen=True)
class Port:
    """One model variable of a component's FMU."""

    name: str
    causality: str            # parameter, calculatedParameter, input, output, local, independent
    variability: str
    type: str                 # Real, Integer, Boolean, String, Enumeration
    unit: str | None
    start: str | None
    min: float | None
    max: float | None
    description: str = ""


@dataclass(frozen=True)
class UnitDefinition:
    """An FMI unit: its name and the SI base-unit exponents, factor and offset."""

    name: str
    exponents: tuple[tuple[str, int], ...]     # (kg, 1), (m, 2)... non-zero only
    factor: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class FmuInterface:
    path: Path
    model_name: str
    guid: str
    fmi_version: str
    co_simulation: bool
    ports: tuple[Port, ...]
    units: tuple[UnitDefinition, ...]

    def port(self, name: str) -> Port | None:
        return next((p for p in self.ports if p.name == name), None)

    def names(self, causality: str) -> tuple[str, ...]:
        return tuple(p.name for p in self.ports if p.causality == causality)


_BASE_UNITS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


def read_interface(path: str | Path) -> FmuInterface:
    """The interface of the FMU at ``path`` (FMI 2.0 or 3.0)."""
    from fmpy import read_model_description

    md = read_model_description(str(path), validate=False)
    ports = []
    for v in md.modelVariables:
        unit = v.unit if v.unit is not None else (v.declaredType.unit if v.declaredType is not None else None)
        ports.append(Port(name=v.name, causality=v.causality, variability=v.variability,
                          type="Real" if v.type in ("Real", "Float64", "Float32") else v.type,
                          unit=unit or None, start=v.start,
                          min=float(v.min) if v.min is not None else None,
                          max=float(v.max) if v.max is not None else None,
                          description=v.description or ""))
    units = []
    for u in md.unitDefinitions:
        base = u.baseUnit
        exponents = tuple((b, int(getattr(base, b, 0) or 0)) for b in _BASE_UNITS
                          if base is not None and int(getattr(base, b, 0) or 0))
        units.append(UnitDefinition(name=u.name, exponents=exponents,
                                    factor=float(base.factor) if base is not None else 1.0,
                                    offset=float(base.offset) if base is not None else 0.0))
    return FmuInterface(path=Path(path), model_name=md.modelName, guid=md.guid, fmi_version=md.fmiVersion,
                        co_simulation=md.coSimulation is not None, ports=tuple(ports), units=tuple(units))


def _unknown(interface: FmuInterface, component: str, variable: str, causality: str) -> str:
    names = interface.names(causality)
    close = difflib.get_close_matches(variable, names, n=1)
    hint = f"did you mean {close[0]!r}? " if close else ""
    return (f"{component}.{variable}: {interface.path.name} has no {causality} {variable!r}; {hint}"
            f"its {causality}s are {', '.join(names) or 'none'}")


def check_system(system: SystemDescription, interfaces: dict[str, FmuInterface]) -> None:
    """Raise SystemFileError listing every connection and binding of ``system`` that its
    components' FMUs (``interfaces`` by instance name) do not fit."""
    problems: list[str] = []
    for name, interface in interfaces.items():
        if not interface.co_simulation:
            problems.append(f"components {name!r}: {interface.path.name} has no co-simulation interface")
    connected = {c.target for c in system.connections}
    for index, c in enumerate(system.connections):
        where = f"connections[{index}] {c.source!r} -> {c.target!r}"
        ends = []
        for component, variable, causality, key in ((c.source_component, c.source_variable, "output", "from"),
                                                     (c.target_component, c.target_variable, "input", "to")):
            interface = interfaces[component]
            port = interface.port(variable)
            if port is None:
                problems.append(f"{where}: {key}: {_unknown(interface, component, variable, causality)}")
            elif port.causality != causality:
                problems.append(f"{where}: {key}: {component}.{variable} is {port.causality!r}, not an {causality}: "
                                f"a connection runs from an output to an input")
                port = None
            elif port.type != "Real":
                problems.append(f"{where}: {key}: {component}.{variable} is of type {port.type}; "
                                f"the connections carry Real values only")
                port = None
            ends.append(port)
        if None not in ends:
            source, target = ends
            if (source.unit or "") != (target.unit or ""):
                problems.append(f"{where}: units differ: {c.source} is in {source.unit or 'no unit'}, "
                                f"{c.target} in {target.unit or 'no unit'}")
    for spec in system.components:
        interface = interfaces[spec.name]
        for variable, value in spec.parameters:
            where = f"components {spec.name!r}.parameters.{variable} = {value!r}"
            port = interface.port(variable)
            if port is None:
                problems.append(f"{where}: {_unknown(interface, spec.name, variable, 'parameter')}")
                continue
            if port.causality == "input" and f"{spec.name}.{variable}" in connected:
                problems.append(f"{where}: {spec.name}.{variable} is a connected input: its value comes from "
                                f"the connection")
                continue
            if port.causality not in ("parameter", "input") or port.variability == "constant":
                problems.append(f"{where}: {spec.name}.{variable} is a{'n' if port.causality[0] in 'aeiou' else ''} "
                                f"{port.causality} ({port.variability}); only parameters and unconnected inputs "
                                f"take a value")
                continue
            if port.type != "Real":
                problems.append(f"{where}: {spec.name}.{variable} is of type {port.type}; only Real values are bound")
                continue
            if port.min is not None and value < port.min or port.max is not None and value > port.max:
                problems.append(f"{where}: outside {spec.name}.{variable}'s range "
                                f"[{port.min if port.min is not None else '-inf'}, "
                                f"{port.max if port.max is not None else 'inf'}] {port.unit or ''}".rstrip())
    if problems:
        raise SystemFileError(f"{system.path}: " + ("\n  ".join([""] + problems) if len(problems) > 1
                                                     else problems[0]))

"""run.json's ``system`` object, typed: what a run of a system of FMUs (an ``.ssp``) ran.

A one-FMU run has no ``system`` (:attr:`RunRecord.system <.run_record.RunRecord.system>` None);
its readers see nothing new.  A system run writes (schema :data:`SYSTEM_SCHEMA`)::

    "system": {"schema": 1, "path": ".../MotorFourBar.ssp", "sha256": "...", "name": "MotorFourBar",
               "algorithm": "jacobi", "inputs": "hold", "step": 0.001, "order": ["motor", ...],
               "components": [{"name": "motor", "source": "resources/DCMotor.fmu", "sha256": "...",
                               "model_identifier": "DCMotorNative", "model_name": "DCMotor",
                               "fmi_version": "2.0", "guid": "{...}",
                               "parameters": {"R": 1.2, ...}}, ...],
               "connections": [{"from": "controller.voltage", "to": "motor.V"}, ...],
               "drawing": "fourbar"}

``order`` is the order the components stepped in (Jacobi: the SSD's, all from the same
values); ``parameters`` every parameter's effective start value in the run (the SSP's binding,
then the case's override; the top-level ``parameters`` of run.json give each one's source, named
``component.variable``).  ``drawing`` names the component whose mechanism run.json's top-level
``drawing`` draws (null, or absent in records written before it: none drawn); that drawing's
joints and parameters are named ``component.name``, like the exchange file's columns
(``fourbar.A_x``) and the faults (``fourbar.L2``), so a view draws a system run as it draws a
one-FMU run.  Standard library only.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

from ..events import Value

__all__ = ["RecordedComponent", "RecordedConnection", "RecordedSystem", "SYSTEM_SCHEMA"]

#: The schema of the ``system`` object written now.
SYSTEM_SCHEMA = 1


@dataclass(frozen=True)
class RecordedConnection:
    """``source`` (``component.output``) feeds ``target`` (``component.input``)."""

    source: str
    target: str

    def to_json(self) -> dict:
        return {"from": self.source, "to": self.target}


@dataclass(frozen=True)
class RecordedComponent:
    """One component of the system: its FMU (path in the archive, SHA-256, model identifier and
    name, FMI version, GUID) and the effective start value of each of its parameters."""

    name: str
    source: str
    sha256: str
    model_identifier: str
    model_name: str
    fmi_version: str
    guid: str
    parameters: Mapping[str, Value] = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"name": self.name, "source": self.source, "sha256": self.sha256,
                "model_identifier": self.model_identifier, "model_name": self.model_name,
                "fmi_version": self.fmi_version, "guid": self.guid, "parameters": dict(self.parameters)}


@dataclass(frozen=True)
class RecordedSystem:
    """The system a run ran (module docstring)."""

    path: str
    sha256: str
    name: str
    algorithm: str
    inputs: str
    step: float
    order: tuple[str, ...]
    components: tuple[RecordedComponent, ...]
    connections: tuple[RecordedConnection, ...]
    drawing: str | None = None
    schema: int = SYSTEM_SCHEMA

    def component(self, name: str) -> RecordedComponent | None:
        return next((c for c in self.components if c.name == name), None)

    def to_json(self) -> dict:
        return {"schema": self.schema, "path": self.path, "sha256": self.sha256, "name": self.name,
                "algorithm": self.algorithm, "inputs": self.inputs, "step": self.step, "order": list(self.order),
                "components": [c.to_json() for c in self.components],
                "connections": [c.to_json() for c in self.connections], "drawing": self.drawing}

    @classmethod
    def from_json(cls, data: Any) -> "RecordedSystem":
        """The system in ``data``; ValueError whose message starts with the field (``system.…``)."""
        return _parse(data)


def _need(obj: Any, key: str, where: str, check, expected: str) -> Any:
    if not isinstance(obj, dict):
        raise ValueError(f"field '{where.rstrip('.')}' is not an object")
    if key not in obj:
        raise ValueError(f"field '{where}{key}' is missing; expected {expected}")
    value = obj[key]
    if not check(value):
        raise ValueError(f"field '{where}{key}' = {value!r}: expected {expected}")
    return value


def _text(v: Any) -> bool:
    return isinstance(v, str)


def _parse(data: Any) -> RecordedSystem:
    where = "system."
    schema = _need(data, "schema", where, lambda v: v == SYSTEM_SCHEMA, f"{SYSTEM_SCHEMA}")
    values = {key: _need(data, key, where, _text, "a string")
              for key in ("path", "sha256", "name", "algorithm", "inputs")}
    step = _need(data, "step", where, lambda v: isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0,
                 "a number > 0")
    order = _need(data, "order", where, lambda v: isinstance(v, list) and all(map(_text, v)),
                  "an array of component names")
    components = []
    for i, item in enumerate(_need(data, "components", where, lambda v: isinstance(v, list), "an array")):
        at = f"{where}components[{i}]."
        texts = {key: _need(item, key, at, _text, "a string")
                 for key in ("name", "source", "sha256", "model_identifier", "model_name", "fmi_version", "guid")}
        parameters = _need(item, "parameters", at, lambda v: isinstance(v, dict), "an object name = value")
        components.append(RecordedComponent(**texts, parameters=dict(parameters)))
    connections = []
    for i, item in enumerate(_need(data, "connections", where, lambda v: isinstance(v, list), "an array")):
        at = f"{where}connections[{i}]."
        connections.append(RecordedConnection(source=_need(item, "from", at, _text, "component.output"),
                                              target=_need(item, "to", at, _text, "component.input")))
    drawing = data.get("drawing")
    if drawing is not None and not (isinstance(drawing, str) and any(c.name == drawing for c in components)):
        raise ValueError(f"field '{where}drawing' = {drawing!r}: expected null or the name of a component "
                         f"({', '.join(c.name for c in components)})")
    return RecordedSystem(**values, step=float(step), order=tuple(order), components=tuple(components),
                          connections=tuple(connections), drawing=drawing, schema=schema)

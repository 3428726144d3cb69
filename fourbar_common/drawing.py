"""How a mechanism is drawn: its bodies, joints and the exchange-file columns that place them.

One home for the drawing's schema.  The FMU build writes it (:meth:`Drawing.to_annotation`;
``fmu_src/mechanism/drawing.py`` makes a mechanism's drawing), and the FMUs declare it in modelDescription.xml as an FMI 2.0
vendor annotation (``<VendorAnnotations><Tool name="fourbar-cosim"><Drawing schema="1">``);
the orchestrator reads it there (:meth:`Drawing.from_model_description`), records the
columns it implies, and keeps the drawing in run.json (:meth:`Drawing.to_json`); a view
reads it back from run.json (:meth:`Drawing.from_json`).  Nothing here knows a mechanism.

Every joint ``J`` has the output columns ``J_x``, ``J_y`` (m): where the joint is, in the
ground frame.  A prismatic joint also has its guide line: ``J_gx``, ``J_gy`` (m), a point of
the line, and ``J_gangle`` (rad), its direction.  A body is drawn through the joints that
touch it, in the order given (a rod from its first joint to its second; a block as a box at
its joints).  A body's ``parameters`` are those its geometry or inertia uses, so a view can
mark the body a fault changes.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Any

__all__ = ["DRAWING_SCHEMA", "DrawingError", "DrawnBody", "DrawnJoint", "Drawing", "TOOL_NAME", "joint_columns"]

#: The annotation's ``Tool`` name, and the one drawing schema this module reads and writes.
TOOL_NAME = "fourbar-cosim"
DRAWING_SCHEMA = 1
BODY_KINDS = ("rod", "block")
#: The column suffixes of a joint, by joint type.
_SUFFIXES = {"revolute": ("x", "y"), "prismatic": ("x", "y", "gx", "gy", "gangle")}
JOINT_TYPES = tuple(_SUFFIXES)


def joint_columns(name: str, joint_type: str) -> tuple[str, ...]:
    """The outputs that place joint ``name``: ``J_x J_y`` (and ``J_gx J_gy J_gangle``, prismatic)."""
    return tuple(f"{name}_{suffix}" for suffix in _SUFFIXES[joint_type])


class DrawingError(ValueError):
    """A drawing that cannot be read; the message names where and what is wrong."""


@dataclass(frozen=True)
class DrawnJoint:
    name: str
    type: str                      # revolute | prismatic
    ground: bool = False           # one of its two points is on the ground

    @property
    def columns(self) -> tuple[str, ...]:
        """The exchange-file columns that place this joint (and a prismatic joint's guide)."""
        return joint_columns(self.name, self.type)

    def to_json(self) -> dict:
        return {"name": self.name, "type": self.type, "ground": self.ground}


@dataclass(frozen=True)
class DrawnBody:
    name: str
    label: str
    kind: str                      # rod | block
    joints: tuple[str, ...]
    parameters: tuple[str, ...] = ()

    def to_json(self) -> dict:
        return {"name": self.name, "label": self.label, "kind": self.kind, "joints": list(self.joints),
                "parameters": list(self.parameters)}


@dataclass(frozen=True)
class Drawing:
    mechanism: str
    bodies: tuple[DrawnBody, ...]
    joints: tuple[DrawnJoint, ...]

    @property
    def columns(self) -> tuple[str, ...]:
        """Every column the drawing needs, joint by joint in the annotation's order."""
        return tuple(c for j in self.joints for c in j.columns)

    def bodies_changed_by(self, parameter: str) -> tuple[DrawnBody, ...]:
        """The bodies whose geometry or inertia ``parameter`` enters."""
        return tuple(b for b in self.bodies if parameter in b.parameters)

    def in_component(self, component: str) -> "Drawing":
        """This drawing as a system run records it: the drawing of component ``component``,
        its joints and parameters named ``component.name`` like the system's columns
        (``fourbar.A_x``) and faults (``fourbar.L2``)."""
        def own(name: str) -> str:
            return f"{component}.{name}"
        return Drawing(mechanism=self.mechanism,
                       bodies=tuple(DrawnBody(name=b.name, label=b.label, kind=b.kind, joints=tuple(map(own, b.joints)),
                                              parameters=tuple(map(own, b.parameters))) for b in self.bodies),
                       joints=tuple(DrawnJoint(name=own(j.name), type=j.type, ground=j.ground) for j in self.joints))

    def to_annotation(self) -> ET.Element:
        """The ``<VendorAnnotations>`` element that declares this drawing in a model description
        (what :meth:`from_model_description` reads)."""
        root = ET.Element("VendorAnnotations")
        tool = ET.SubElement(root, "Tool", {"name": TOOL_NAME})
        node = ET.SubElement(tool, "Drawing", {"schema": str(DRAWING_SCHEMA), "mechanism": self.mechanism})
        for b in self.bodies:
            attrs = {"name": b.name, "label": b.label, "kind": b.kind, "joints": " ".join(b.joints)}
            if b.parameters:
                attrs["parameters"] = " ".join(b.parameters)
            ET.SubElement(node, "Body", attrs)
        for j in self.joints:
            ET.SubElement(node, "Joint", {"name": j.name, "type": j.type} | ({"ground": "true"} if j.ground else {}))
        return root

    def to_json(self) -> dict:
        return {"schema": DRAWING_SCHEMA, "mechanism": self.mechanism,
                "bodies": [b.to_json() for b in self.bodies], "joints": [j.to_json() for j in self.joints]}

    # -- reading ----------------------------------------------------------------------
    @classmethod
    def from_json(cls, data: Any, where: str = "drawing") -> "Drawing":
        """The drawing in ``data`` (what :meth:`to_json` wrote); :class:`DrawingError` naming
        ``where`` and the field otherwise."""
        r = _Reader(where)
        if not isinstance(data, dict):
            r.fail("", data, "an object")
        if data.get("schema") != DRAWING_SCHEMA:
            r.fail("schema", data.get("schema"), f"{DRAWING_SCHEMA} (a newer drawing needs a newer fourbar-cosim)")
        mechanism = r.text(data, "mechanism")
        joints = tuple(DrawnJoint(name=r.text(j, "name", f"joints[{i}]."), type=r.choice(j, "type", JOINT_TYPES, f"joints[{i}]."),
                                  ground=r.flag(j, "ground", f"joints[{i}]."))
                       for i, j in enumerate(r.items(data, "joints")))
        bodies = tuple(DrawnBody(name=r.text(b, "name", f"bodies[{i}]."), label=r.text(b, "label", f"bodies[{i}]."),
                                 kind=r.choice(b, "kind", BODY_KINDS, f"bodies[{i}]."),
                                 joints=r.names(b, "joints", f"bodies[{i}]."),
                                 parameters=r.names(b, "parameters", f"bodies[{i}].", empty_ok=True))
                       for i, b in enumerate(r.items(data, "bodies")))
        return _checked(cls(mechanism=mechanism, bodies=bodies, joints=joints), where)

    @classmethod
    def from_model_description(cls, xml: bytes | str, where: str = "modelDescription.xml") -> "Drawing | None":
        """The drawing an FMU declares in its model description, None when it declares none;
        :class:`DrawingError` naming ``where`` when the annotation is there but malformed."""
        try:
            root = ET.fromstring(xml)
        except ET.ParseError as exc:
            raise DrawingError(f"{where}: not well-formed XML: {exc}") from None
        # FMI 2.0: <VendorAnnotations><Tool name=...>; FMI 3.0: <Annotations><Annotation type=...>
        tool = next((t for t in root.findall("./VendorAnnotations/Tool") if t.get("name") == TOOL_NAME), None)
        if tool is None:
            tool = next((t for t in root.findall("./Annotations/Annotation") if t.get("type") == TOOL_NAME), None)
        node = tool.find("Drawing") if tool is not None else None
        if node is None:
            return None
        where = f"{where}: the {TOOL_NAME} drawing"
        try:
            schema = int(node.get("schema", ""))
        except ValueError:
            schema = None
        data = {"schema": schema, "mechanism": node.get("mechanism"),
                "joints": [{"name": j.get("name"), "type": j.get("type"), "ground": j.get("ground", "false")}
                           for j in node.findall("Joint")],
                "bodies": [{"name": b.get("name"), "label": b.get("label"), "kind": b.get("kind"),
                            "joints": (b.get("joints") or "").split(),
                            "parameters": (b.get("parameters") or "").split()} for b in node.findall("Body")]}
        for j in data["joints"]:
            if j["ground"] not in ("true", "false"):
                raise DrawingError(f"{where}: joint {j['name']!r}: ground = {j['ground']!r}; expected true or false")
            j["ground"] = j["ground"] == "true"
        return cls.from_json(data, where)


def _checked(drawing: Drawing, where: str) -> Drawing:
    """``drawing`` when its names are consistent: unique joints and bodies, every body's
    joints declared, at least one body."""
    names = [j.name for j in drawing.joints]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise DrawingError(f"{where}: joint(s) {', '.join(twice)} declared twice")
    bodies = [b.name for b in drawing.bodies]
    twice = sorted({n for n in bodies if bodies.count(n) > 1})
    if twice:
        raise DrawingError(f"{where}: body(ies) {', '.join(twice)} declared twice")
    if not drawing.bodies:
        raise DrawingError(f"{where}: no body to draw")
    for b in drawing.bodies:
        unknown = [j for j in b.joints if j not in names]
        if unknown:
            raise DrawingError(f"{where}: body {b.name!r} names joint(s) {', '.join(unknown)}, which the drawing "
                               f"does not declare (declared: {', '.join(names) or 'none'})")
    return drawing


class _Reader:
    def __init__(self, where: str):
        self.where = where

    def fail(self, field: str, value: Any, expected: str):
        at = f" field '{field}'" if field else ""
        raise DrawingError(f"{self.where}:{at} = {value!r}; expected {expected}")

    def text(self, obj: dict, key: str, prefix: str = "") -> str:
        value = obj.get(key) if isinstance(obj, dict) else None
        if not isinstance(value, str) or not value:
            self.fail(prefix + key, value, "a non-empty name")
        return value

    def choice(self, obj: dict, key: str, options: tuple[str, ...], prefix: str = "") -> str:
        value = obj.get(key) if isinstance(obj, dict) else None
        if value not in options:
            self.fail(prefix + key, value, " or ".join(options))
        return value

    def flag(self, obj: dict, key: str, prefix: str = "") -> bool:
        value = obj.get(key, False) if isinstance(obj, dict) else None
        if not isinstance(value, bool):
            self.fail(prefix + key, value, "true or false")
        return value

    def items(self, obj: dict, key: str) -> list:
        value = obj.get(key)
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            self.fail(key, value, "an array of objects")
        return value

    def names(self, obj: dict, key: str, prefix: str = "", empty_ok: bool = False) -> tuple[str, ...]:
        value = obj.get(key, [] if empty_ok else None) if isinstance(obj, dict) else None
        if (not isinstance(value, list) or not all(isinstance(v, str) and v for v in value)
                or (not value and not empty_ok)):
            self.fail(prefix + key, value, "an array of names" + ("" if empty_ok else " (at least one)"))
        return tuple(value)

"""How a mechanism is drawn: its joints' position outputs and the drawing annotation (build time).

Every joint ``J`` of a mechanism gives the outputs ``J_x``, ``J_y`` (m, ground frame): where the
joint is.  For a revolute joint that is its second point (the two points coincide up to the
constraint residual); for a prismatic joint the second point too, the point that slides.  A
prismatic joint adds its guide line: ``J_gx``, ``J_gy`` (m), the position of its first point (a
point of the line, fixed to the first body or to the ground), and ``J_gangle`` (rad), the
line's direction from +x (the joint's angle plus the first body's angle).  Their expressions
come from ``derivation`` (``_joint_position_outputs``); the names are made here, in one place.

Both FMUs declare how to draw the mechanism in modelDescription.xml, as an FMI 2.0 vendor
annotation (schema position: after ``DefaultExperiment``, before ``ModelVariables``)::

    <VendorAnnotations>
      <Tool name="fourbar-cosim">
        <Drawing schema="1" mechanism="SliderCrank">
          <Body name="crank" label="2" kind="rod" joints="O2 A" parameters="L2 m2"/>
          ...
          <Joint name="O2" type="revolute" ground="true"/>
          <Joint name="P" type="prismatic" ground="true"/>
        </Drawing>
      </Tool>
    </VendorAnnotations>

A body's ``joints`` are the joints that touch it, in the order it is drawn: along a rod's axis
from its tail; around the centroid of the joints' points (counter-clockwise) for a body whose
joints are not on one line; else in file order.  Its ``parameters`` are those its length,
mass, inertia and points use (file order), so a view can mark the body a fault changes.  A
joint has ``ground="true"`` when one of its points is on the ground.  The annotation does not
repeat the column names: the view derives them from the joints' names and types
(:func:`joint_columns`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from xml.etree import ElementTree as ET

import sympy as sp

from .description import Joint, Mechanism

__all__ = ["DrawnBody", "DrawnJoint", "MechanismDrawing", "drawing_of", "joint_columns", "vendor_annotations",
           "insert_vendor_annotations", "TOOL_NAME", "DRAWING_SCHEMA"]

#: The ``Tool`` name of the annotation and the schema of its ``Drawing`` element.
TOOL_NAME = "fourbar-cosim"
DRAWING_SCHEMA = 1
#: The column suffixes of a joint, by joint type.
_SUFFIXES = {"revolute": ("x", "y"), "prismatic": ("x", "y", "gx", "gy", "gangle")}


def joint_columns(name: str, joint_type: str) -> tuple[str, ...]:
    """The output names that place joint ``name``: ``J_x J_y`` (+ ``J_gx J_gy J_gangle``, prismatic)."""
    return tuple(f"{name}_{suffix}" for suffix in _SUFFIXES[joint_type])


@dataclass(frozen=True)
class DrawnBody:
    """A body of the drawing: the joints that touch it, in drawing order, and its parameters."""

    name: str
    label: str
    kind: str                       # "rod" or "block"
    joints: tuple[str, ...]
    parameters: tuple[str, ...]


@dataclass(frozen=True)
class DrawnJoint:
    """A joint of the drawing; ``ground`` when one of its points is on the ground."""

    name: str
    type: str                       # "revolute" or "prismatic"
    ground: bool

    @property
    def columns(self) -> tuple[str, ...]:
        return joint_columns(self.name, self.type)


@dataclass(frozen=True)
class MechanismDrawing:
    """What the annotation of a mechanism's FMUs says."""

    mechanism: str
    bodies: tuple[DrawnBody, ...]
    joints: tuple[DrawnJoint, ...]

    @property
    def columns(self) -> tuple[str, ...]:
        """Every output the drawing implies, joint by joint in file order."""
        return tuple(c for j in self.joints for c in j.columns)


def _body_joint_order(mech: Mechanism, body_name: str, joints: list[Joint]) -> tuple[str, ...]:
    """The joints touching a body in drawing order (see the module doc), from the body-frame
    positions of their points at the file's parameter values."""
    body = mech.body(body_name)
    values = {sp.Symbol(p.name, real=True): p.value for p in mech.parameters}
    points = []
    for joint in joints:
        ref = joint.first if joint.first.body == body_name else joint.second
        x, y = (float(sp.sympify(e).xreplace(values)) for e in body.points[ref.point])
        points.append((x, y))
    names = [j.name for j in joints]
    scale = max([1.0] + [abs(c) for p in points for c in p])
    if all(abs(y) <= 1e-12 * scale for _, y in points):            # on the body's axis: along it
        order = sorted(range(len(joints)), key=lambda k: points[k][0])
    elif len({(round(x / scale, 12), round(y / scale, 12)) for x, y in points}) >= 3:   # a polygon
        cx = sum(x for x, _ in points) / len(points)
        cy = sum(y for _, y in points) / len(points)
        order = sorted(range(len(joints)), key=lambda k: math.atan2(points[k][1] - cy, points[k][0] - cx))
    else:
        order = list(range(len(joints)))
    return tuple(names[k] for k in order)


def drawing_of(mech: Mechanism) -> MechanismDrawing:
    """The drawing of a mechanism (see the module doc)."""
    order = {p.name: k for k, p in enumerate(mech.parameters)}
    bodies = []
    for body in mech.bodies:
        touching = [j for j in mech.joints if body.name in (j.first.body, j.second.body)]
        exprs = [body.mass, body.inertia] + ([body.length] if body.length is not None else []) \
            + [c for point in body.points.values() for c in point]
        used = {str(s) for e in exprs for s in sp.sympify(e).free_symbols}
        bodies.append(DrawnBody(body.name, body.label, body.kind, _body_joint_order(mech, body.name, touching),
                                tuple(sorted(used & set(order), key=order.__getitem__))))
    joints = tuple(DrawnJoint(j.name, j.type, "ground" in (j.first.body, j.second.body)) for j in mech.joints)
    return MechanismDrawing(mech.name, tuple(bodies), joints)


def vendor_annotations(drawing: MechanismDrawing) -> ET.Element:
    """The ``<VendorAnnotations>`` element that declares ``drawing``."""
    root = ET.Element("VendorAnnotations")
    tool = ET.SubElement(root, "Tool", {"name": TOOL_NAME})
    node = ET.SubElement(tool, "Drawing", {"schema": str(DRAWING_SCHEMA), "mechanism": drawing.mechanism})
    for b in drawing.bodies:
        attrs = {"name": b.name, "label": b.label, "kind": b.kind, "joints": " ".join(b.joints)}
        if b.parameters:
            attrs["parameters"] = " ".join(b.parameters)
        ET.SubElement(node, "Body", attrs)
    for j in drawing.joints:
        ET.SubElement(node, "Joint", {"name": j.name, "type": j.type} | ({"ground": "true"} if j.ground else {}))
    return root


def insert_vendor_annotations(root: ET.Element, drawing: MechanismDrawing) -> None:
    """Put the annotation into a model description's root where the FMI 2.0 schema wants it:
    right before ``<ModelVariables>`` (``VendorAnnotations`` follows ``DefaultExperiment``).
    An existing ``<VendorAnnotations>`` keeps its other tools; this tool's entry is replaced."""
    ours = vendor_annotations(drawing)
    existing = root.find("VendorAnnotations")
    if existing is None:
        root.insert(list(root).index(root.find("ModelVariables")), ours)
        return
    for tool in existing.findall("Tool"):
        if tool.get("name") == TOOL_NAME:
            existing.remove(tool)
    existing.extend(list(ours))

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
repeat the column names: the view derives them from the joints' names and types.  The
schema (its dataclasses, the column names, writing and reading the annotation) has one home,
:mod:`fourbar_common.drawing`; this module makes a mechanism's drawing and puts it into a
model description.
"""
from __future__ import annotations

import math
from xml.etree import ElementTree as ET

import sympy as sp

from fourbar_common.drawing import TOOL_NAME, Drawing, DrawnBody, DrawnJoint, joint_columns

from .description import Joint, Mechanism

__all__ = ["drawing_of", "insert_vendor_annotations", "joint_columns"]


def _body_joint_order(mech: Mechanism, body_name: str, joints: list[Joint]) -> tuple[str, ...]:
    """The joints touching a body in drawing order (see the module doc), from the body-frame
    positions of their points at the file's parameter values."""
    body = mech.body(body_name)
    values = {sp.Symbol(p.name, real=True): p.value for p in mech.parameters}
    points = []
    for joint in joints:
        ref = joint.first if joint.first.body == body_name else joint.second
        x, y = (float(sp.sympify(e, strict=True).xreplace(values)) for e in body.points[ref.point])
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


def drawing_of(mech: Mechanism) -> Drawing:
    """The drawing of a mechanism (see the module doc)."""
    order = {p.name: k for k, p in enumerate(mech.parameters)}
    bodies = []
    for body in mech.bodies:
        touching = [j for j in mech.joints if body.name in (j.first.body, j.second.body)]
        exprs = [body.mass, body.inertia] + ([body.length] if body.length is not None else []) \
            + [c for point in body.points.values() for c in point]
        used = {str(s) for e in exprs for s in sp.sympify(e, strict=True).free_symbols}
        bodies.append(DrawnBody(body.name, body.label, body.kind, _body_joint_order(mech, body.name, touching),
                                tuple(sorted(used & set(order), key=order.__getitem__))))
    joints = tuple(DrawnJoint(j.name, j.type, "ground" in (j.first.body, j.second.body)) for j in mech.joints)
    return Drawing(mech.name, tuple(bodies), joints)


def insert_vendor_annotations(root: ET.Element, drawing: Drawing) -> None:
    """Put the annotation into a model description's root where the FMI 2.0 schema wants it:
    right before ``<ModelVariables>`` (``VendorAnnotations`` follows ``DefaultExperiment``).
    An existing ``<VendorAnnotations>`` keeps its other tools; this tool's entry is replaced."""
    ours = drawing.to_annotation()
    existing = root.find("VendorAnnotations")
    if existing is None:
        root.insert(list(root).index(root.find("ModelVariables")), ours)
        return
    for tool in existing.findall("Tool"):
        if tool.get("name") == TOOL_NAME:
            existing.remove(tool)
    existing.extend(list(ours))

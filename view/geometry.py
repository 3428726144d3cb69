"""Where to draw each part of a mechanism at one instant, from the exchange file's joint columns.

One home for turning a :class:`fourbar_common.Drawing` and rows of exchange.csv into lines,
so the live page and the animation draw the same picture:

- a rod: a segment through its joints, in the drawing's order;
- a block (a slider): a square centred at its joints' mean, ``block_size`` wide;
- a revolute joint to the ground: a triangle under its point (the ground mark of textbook
  figures);
- a prismatic joint's guide: a line through its guide point along its direction, long
  enough to cover every position the slider takes in the rows given.

What moves is drawn from each row's own columns (:meth:`Geometry.frame`), the guides and the
ground marks too: a guide fixed to a moving body (an inverted slider-crank's slotted lever)
turns with it (``<joint>_gx _gy _gangle`` of that row), and a ground point a fault moves (a
pivot distance changed) moves with it.  The :class:`Scene` holds only what is the same in every
frame: the extent, the block size, and each guide's length as a span along the guide from its
guide point (in the guide's own frame, so it is right whatever the guide's angle).

Coordinates are metres in the ground frame.  Bodies a fault changes (their ``parameters``
include an event's variable) are flagged so a view can colour them after the fault.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from fourbar_common import Drawing

__all__ = ["BodyShape", "Frame", "Geometry", "Scene", "faulted_bodies"]


@dataclass(frozen=True)
class BodyShape:
    name: str
    label: str
    kind: str                      # rod | block
    xs: tuple[float, ...]          # a polyline (rod) or a closed square (block)
    ys: tuple[float, ...]


@dataclass(frozen=True)
class Frame:
    """The mechanism at one time."""

    time: float
    bodies: tuple[BodyShape, ...]
    joints: tuple[tuple[str, float, float], ...]          # name, x, y
    guides: tuple[tuple[tuple[float, float], tuple[float, float]], ...] = ()   # ((x0, x1), (y0, y1)) per guide
    ground: tuple[tuple[float, float], ...] = ()          # revolute ground joints' (x, y)


@dataclass(frozen=True)
class Scene:
    """What is the same in every frame: the extent of all frames, the block size, and how far
    each prismatic joint's guide reaches from its guide point (m along the guide: ``(joint,
    s0, s1)``, with ``s0 <= 0 <= s1``)."""

    guide_spans: tuple[tuple[str, float, float], ...]
    x_range: tuple[float, float]
    y_range: tuple[float, float]
    block_size: float


def faulted_bodies(drawing: Drawing, variables) -> set[str]:
    """Names of the bodies whose geometry or inertia any of ``variables`` enters."""
    return {b.name for v in variables for b in drawing.bodies_changed_by(v)}


class Geometry:
    """Frames and the scene of one drawing, from a DataFrame with its joint columns."""

    def __init__(self, drawing: Drawing):
        self.drawing = drawing           # checked where it was read (Drawing.from_json)

    def lacking(self, columns) -> list[str]:
        """The drawing's columns that ``columns`` lacks (empty: every joint can be placed)."""
        have = set(columns)
        return [c for c in self.drawing.columns if c not in have]

    def scene(self, rows: pd.DataFrame) -> Scene:
        """A square extent covering every joint in ``rows`` with a margin, and each guide's span
        covering the slider's positions along it in ``rows`` (each row in its own guide's frame)."""
        xs = np.concatenate([rows[f"{j.name}_x"].to_numpy(float) for j in self.drawing.joints])
        ys = np.concatenate([rows[f"{j.name}_y"].to_numpy(float) for j in self.drawing.joints])
        xs, ys = xs[np.isfinite(xs)], ys[np.isfinite(ys)]
        if not len(xs):
            xs = ys = np.array([0.0])
        span = max(float(np.ptp(xs)), float(np.ptp(ys)), 1e-3)
        block = 0.06 * span
        spans = []
        for j in self.drawing.joints:
            if j.type != "prismatic":
                continue
            gx, gy, ga = (rows[f"{j.name}_{c}"].to_numpy(float) for c in ("gx", "gy", "gangle"))
            # how far along the guide the slider goes from the guide point, each row in its own
            # guide's frame (a guide on a moving body turns), plus a block either side
            s = (rows[f"{j.name}_x"].to_numpy(float) - gx) * np.cos(ga) \
                + (rows[f"{j.name}_y"].to_numpy(float) - gy) * np.sin(ga)
            s = s[np.isfinite(s)]
            s0, s1 = (float(s.min()), float(s.max())) if len(s) else (0.0, 0.0)
            spans.append((j.name, min(s0, 0.0) - 2 * block, max(s1, 0.0) + 2 * block))
        cx, cy = (float(xs.min()) + float(xs.max())) / 2, (float(ys.min()) + float(ys.max())) / 2
        half = 0.5 * span + 3 * block
        return Scene(guide_spans=tuple(spans), x_range=(cx - half, cx + half), y_range=(cy - half, cy + half),
                     block_size=block)

    def frame(self, row, scene: Scene) -> Frame:
        """The mechanism in one exchange row (a Series or a mapping of column to value): bodies,
        joints, each guide through that row's guide point along that row's guide angle over its
        span in ``scene``, and a ground mark under each revolute joint to the ground."""
        block_size = scene.block_size
        where = {j.name: (float(row[f"{j.name}_x"]), float(row[f"{j.name}_y"])) for j in self.drawing.joints}
        shapes = []
        for b in self.drawing.bodies:
            px = [where[n][0] for n in b.joints]
            py = [where[n][1] for n in b.joints]
            if b.kind == "rod":
                shapes.append(BodyShape(b.name, b.label, b.kind, tuple(px), tuple(py)))
            else:
                cx, cy, h = sum(px) / len(px), sum(py) / len(py), block_size / 2
                shapes.append(BodyShape(b.name, b.label, b.kind, (cx - h, cx + h, cx + h, cx - h, cx - h),
                                        (cy - h, cy - h, cy + h, cy + h, cy - h)))
        guides = []
        for name, s0, s1 in scene.guide_spans:
            gx, gy, ga = (float(row[f"{name}_{c}"]) for c in ("gx", "gy", "gangle"))
            ux, uy = math.cos(ga), math.sin(ga)
            guides.append(((gx + s0 * ux, gx + s1 * ux), (gy + s0 * uy, gy + s1 * uy)))
        # a ground mark under each revolute joint to the ground (a prismatic one's guide is its ground)
        ground = tuple(where[j.name] for j in self.drawing.joints if j.ground and j.type == "revolute")
        return Frame(time=float(row["time"]), bodies=tuple(shapes),
                     joints=tuple((n, x, y) for n, (x, y) in where.items()), guides=tuple(guides), ground=ground)

"""The signals of a system run's components, grouped for the page (a plot per component).

A system run (run.json's ``system``: :class:`~fourbar_common.contract.system_record.RecordedSystem`)
names its exchange columns ``component.variable``.  :func:`component_signals` groups the run's
recorded outputs by component, in the system's component order, leaving out the columns that
only place the mechanism's joints (the drawing's): ``motor: motor.current, motor.torque``,
``controller: controller.voltage``, ``fourbar: fourbar.omega2`` ...  A one-FMU run has no
components: the page then shows no component plots.  Pure Python: no page code here.
"""
from __future__ import annotations

from dataclasses import dataclass

from fourbar_common.contract.run_record import RunRecord

__all__ = ["ComponentSignals", "component_signals"]


@dataclass(frozen=True)
class ComponentSignals:
    """One component of a system run and its recorded signals (exchange columns)."""

    component: str
    signals: tuple[str, ...]


def component_signals(record: RunRecord | None, columns) -> tuple[ComponentSignals, ...]:
    """Each component's recorded outputs found in ``columns`` (the exchange file's), drawing
    columns left out, components without any left out; empty for a one-FMU run."""
    if record is None or record.system is None:
        return ()
    have = set(columns)
    drawn = set(record.drawing.columns) if record.drawing is not None else set()
    wanted = [c for c in record.outputs if c in have and c not in drawn]
    groups = []
    for component in record.system.components:
        signals = tuple(c for c in wanted if c.partition(".")[0] == component.name)
        if signals:
            groups.append(ComponentSignals(component.name, signals))
    return tuple(groups)

"""The scenario's events -- a step or a ramp of one FMU variable -- in one home.

A case file declares them (the orchestrator parses and applies them), run.json records them,
and the monitor and the diagnosis read them back as the injected truth.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Union

__all__ = ["Event", "RampEvent", "StepEvent", "Value"]

#: A start or event value of an FMU variable (Real, Integer, Boolean or String).
Value = Union[float, int, bool, str]


@dataclass(frozen=True)
class StepEvent:
    """Set ``variable`` to ``value`` at ``time`` (s): applied after the row at ``time`` is read."""

    time: float
    variable: str
    value: Value

    @property
    def first_time(self) -> float:
        return self.time

    def as_dict(self) -> dict:
        return {"type": "step", "time": self.time, "variable": self.variable, "value": self.value}


@dataclass(frozen=True)
class RampEvent:
    """Move Real ``variable`` linearly from ``from_`` to ``to`` over [``start``, ``end``] (s).

    The value ``from_*(1-f) + to*f``, ``f = (t - start)/(end - start)``, is set at every
    communication point of the ramp, ends included.
    """

    variable: str
    from_: float
    to: float
    start: float
    end: float

    @property
    def first_time(self) -> float:
        return self.start

    def value_at(self, fraction: float) -> float:
        """Ramp value at ``fraction`` in [0, 1]; exactly ``from_`` at 0 and ``to`` at 1."""
        return self.from_ * (1.0 - fraction) + self.to * fraction

    def as_dict(self) -> dict:
        return {"type": "ramp", "variable": self.variable, "from": self.from_, "to": self.to,
                "start": self.start, "end": self.end}


Event = Union[StepEvent, RampEvent]

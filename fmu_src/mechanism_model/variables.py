"""The variable type of the mechanism FMUs, shared by the pythonfmu FMU and the native FMU.

A mechanism's table of variables is generated (``equations.VARIABLES``) from its description;
the value reference of a variable is its position in that table.  The pythonfmu slave
registers the variables in this order (pythonfmu numbers them as registered), and the native
FMU's model description and C tables come from the same rows, so a host can swap one FMU for
the other without touching a value reference.

Plain Python, no imports beyond typing: part of the pythonfmu FMU's run-time package.
"""
from __future__ import annotations

from typing import NamedTuple

__all__ = ["POSITIVE", "Variable", "INTEGRATOR_NAMES", "UNITS"]


class Variable(NamedTuple):
    """One scalar variable of the FMU (FMI 2.0 terms)."""

    name: str
    type: str               # "Real" or "String"
    causality: str          # "parameter", "input", "output" or "local" (the native FMU's Model Exchange states)
    variability: str        # "tunable", "fixed" or "continuous"
    start: float | str | None   # start value (parameters only)
    unit: str | None        # a unit of UNITS (Real only)
    description: str
    display_unit: str | None = None
    minimum: float | None = None    # declared min (FMI: inclusive); POSITIVE means "> 0"
    maximum: float | None = None


#: The smallest positive normal double: as an (inclusive) FMI min it says "greater than zero".
POSITIVE = 2.2250738585072014e-308

#: The values the ``integrator`` parameter accepts (explicit Runge-Kutta methods).
INTEGRATOR_NAMES = ("DOP853", "RK45")

#: Unit definitions: name -> (SI base-unit exponents, [(display unit, factor)]).
UNITS = {
    "m": ({"m": "1"}, []),
    "kg": ({"kg": "1"}, []),
    "kg.m2": ({"kg": "1", "m": "2"}, []),
    "m/s": ({"m": "1", "s": "-1"}, []),
    "m/s2": ({"m": "1", "s": "-2"}, []),
    "rad": ({"rad": "1"}, [("deg", 57.29577951308232)]),
    "rad/s": ({"rad": "1", "s": "-1"}, [("deg/s", 57.29577951308232)]),
    "rad/s2": ({"rad": "1", "s": "-2"}, []),
    "N": ({"kg": "1", "m": "1", "s": "-2"}, []),
    "N.m": ({"kg": "1", "m": "2", "s": "-2"}, []),
    "J": ({"kg": "1", "m": "2", "s": "-2"}, []),
    "W": ({"kg": "1", "m": "2", "s": "-3"}, []),
    "s": ({"s": "1"}, []),
    "1": ({}, []),
}

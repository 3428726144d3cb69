"""The FourBar FMUs' variables: one table for the pythonfmu FMU and the native C FMU.

The value reference of a variable is its position in :data:`VARIABLES`.  The pythonfmu
slave registers the variables in this order (pythonfmu numbers them as registered), and
the native FMU's model description and C tables are generated from the same rows, so a
host can swap one FMU for the other without touching a value reference.  The build checks
the pythonfmu model description against this table.

This module is part of the pythonfmu FMU's run-time package: plain Python, no imports.
"""
from __future__ import annotations

import math
from typing import NamedTuple

__all__ = ["POSITIVE", "Variable", "VARIABLES", "BY_NAME", "PARAMETER_NAMES", "INTEGRATOR_NAMES", "UNITS"]


class Variable(NamedTuple):
    """One scalar variable of the FMU (FMI 2.0 terms)."""

    name: str
    type: str               # "Real" or "String"
    causality: str          # "parameter" or "output"
    variability: str        # "tunable", "fixed" or "continuous"
    start: float | str | None   # start value (parameters only)
    unit: str | None        # a unit of UNITS (Real only)
    description: str
    display_unit: str | None = None
    minimum: float | None = None    # declared min (FMI: inclusive); POSITIVE means "> 0"


#: The smallest positive normal double: as an (inclusive) FMI min it says "greater than zero".
POSITIVE = 2.2250738585072014e-308


def _tunable(name, start, unit, doc, minimum=None):
    return Variable(name, "Real", "parameter", "tunable", start, unit, doc, None, minimum)


def _fixed(name, start, unit, doc, display=None, minimum=None):
    return Variable(name, "Real", "parameter", "fixed", start, unit, doc, display, minimum)


def _output(name, unit, doc, display=None):
    return Variable(name, "Real", "output", "continuous", None, unit, doc, display)


#: Every variable, in value-reference order.
VARIABLES: tuple[Variable, ...] = (
    _tunable("L1", 3.0, "m", "Ground link length: distance between the crank and rocker pivots [m]", POSITIVE),
    _tunable("L2", 1.0, "m", "Crank (link 2) length [m]", POSITIVE),
    _tunable("L3", 4.0, "m", "Coupler (link 3) length [m]", POSITIVE),
    _tunable("L4", 2.5, "m", "Rocker (link 4) length [m]", POSITIVE),
    _tunable("m2", 1.0, "kg", "Crank (link 2) mass, uniform slender rod [kg]", POSITIVE),
    _tunable("m3", 1.0, "kg", "Coupler (link 3) mass, uniform slender rod [kg]", POSITIVE),
    _tunable("m4", 1.0, "kg", "Rocker (link 4) mass, uniform slender rod [kg]", POSITIVE),
    _tunable("g", 9.81, "m/s2", "Gravitational acceleration, acting along -y [m/s2]"),
    _fixed("theta2_start", math.radians(30.0), "rad", "Initial crank angle from +x, counter-clockwise [rad]",
           "deg"),
    _fixed("omega2_start", 0.0, "rad/s", "Initial crank angular velocity [rad/s]"),
    _fixed("rtol", 1e-10, "1", "Relative tolerance of the Runge-Kutta error control [-]", minimum=POSITIVE),
    # rtol, atol: Table 1 gives 1e-9 and 1e-6 (its case files set them).  The defaults are
    # tighter because at Table 1's values the integrator's energy error moves the period of a
    # rotating crank, or of a swing that nearly reaches the top, by up to ~1e-3 (relative) in
    # jumps over minutes, and at rtol 1e-9 one step near a fast passage still shifted a rotating
    # crank's energy by 1e-5 (relative): a healthy run then drifts like a faulty one
    # (docs/monitor.md, Limitations).  1e-10 costs ~15 % more time in the native FMU.
    _fixed("atol", 1e-10, "1", "Absolute tolerance of the Runge-Kutta error control [rad, rad/s]",
           minimum=POSITIVE),
    Variable("integrator", "String", "parameter", "fixed", "DOP853", None,
             "Explicit Runge-Kutta method: DOP853 or RK45"),
    _output("x2", "m", "x of the crank's centre [m]"),
    _output("y2", "m", "y of the crank's centre [m]"),
    _output("x3", "m", "x of the coupler's centre [m]"),
    _output("y3", "m", "y of the coupler's centre [m]"),
    _output("x4", "m", "x of the rocker's centre [m]"),
    _output("y4", "m", "y of the rocker's centre [m]"),
    _output("theta2", "rad", "Crank angle from +x [rad]", "deg"),
    _output("theta3", "rad", "Coupler angle from +x [rad]", "deg"),
    _output("theta4", "rad", "Rocker angle from +x [rad]", "deg"),
    _output("omega2", "rad/s", "Crank angular velocity [rad/s]"),
    _output("omega3", "rad/s", "Coupler angular velocity [rad/s]"),
    _output("omega4", "rad/s", "Rocker angular velocity [rad/s]"),
    _output("energy", "J", "Total mechanical energy T + V, V = 0 at y = 0 [J]"),
    _output("constraint_residual", "1", "max(|Phi|, |Phi_q qd|) of the reported state [m, m/s]"),
)

#: name -> Variable.
BY_NAME = {v.name: v for v in VARIABLES}

#: The model parameters in the order the generated equations take them (p).
PARAMETER_NAMES = ("L1", "L2", "L3", "L4", "m2", "m3", "m4", "g")

#: The values the ``integrator`` parameter accepts.
INTEGRATOR_NAMES = ("DOP853", "RK45")

#: Unit definitions: name -> (SI base-unit exponents, [(display unit, factor)]).
UNITS = {
    "m": ({"m": "1"}, []),
    "kg": ({"kg": "1"}, []),
    "m/s2": ({"m": "1", "s": "-2"}, []),
    "rad": ({"rad": "1"}, [("deg", 57.29577951308232)]),
    "rad/s": ({"rad": "1", "s": "-1"}, [("deg/s", 57.29577951308232)]),
    "J": ({"kg": "1", "m": "2", "s": "-2"}, []),
    "1": ({}, []),
}

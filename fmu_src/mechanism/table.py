"""The FMU variable table of a mechanism: one list for the pythonfmu FMU and the native FMU.

Value-reference order: the file's [parameters] (tunable, or fixed with ``fixed = true``), the
start values of the independent coordinates (``<coordinate>_start``, fixed), the integrator's
``rtol``, ``atol`` and ``integrator``, then the outputs in the file's order.
"""
from __future__ import annotations

from ..mechanism_model.variables import POSITIVE, Variable
from .derivation import MechanismEquations

__all__ = ["variable_table", "DEFAULT_TOLERANCE"]

#: rtol = atol of the Runge-Kutta error control when the case does not set them.  Table 1 gives
#: 1e-9 and 1e-6 (its case files set them).  At those values the integrator's energy error moves
#: the period of a rotating crank, or of a swing that nearly reaches the top, by up to ~1e-3
#: (relative) in jumps over minutes: a healthy run then drifts like a faulty one
#: (docs/monitor.md, Limitations).  1e-10 costs ~15 % more time in the native FMU.
DEFAULT_TOLERANCE = 1e-10


def variable_table(eqs: MechanismEquations) -> tuple[Variable, ...]:
    """Every variable of the mechanism's FMUs, in value-reference order."""
    mech = eqs.mechanism
    rows = []
    for p in mech.parameters:
        rows.append(Variable(p.name, "Real", "parameter", "fixed" if p.fixed else "tunable", p.value, p.unit,
                             p.description, p.display_unit, p.minimum, p.maximum))
    for s in mech.start:
        rows.append(Variable(s.parameter, "Real", "parameter", "fixed", s.value, s.unit, s.description,
                             s.display_unit))
    rows += [
        Variable("rtol", "Real", "parameter", "fixed", DEFAULT_TOLERANCE, "1",
                 "Relative tolerance of the Runge-Kutta error control [-]", None, POSITIVE),
        Variable("atol", "Real", "parameter", "fixed", DEFAULT_TOLERANCE, "1",
                 "Absolute tolerance of the Runge-Kutta error control [units of the independent coordinates]",
                 None, POSITIVE),
        Variable("integrator", "String", "parameter", "fixed", "DOP853", None,
                 "Explicit Runge-Kutta method: DOP853 or RK45"),
    ]
    for out in eqs.outputs:
        rows.append(Variable(out.name, "Real", "output", "continuous", None, out.unit, out.description,
                             out.display_unit))
    names = [v.name for v in rows]
    clash = sorted({n for n in names if names.count(n) > 1})
    if clash:
        from .description import MechanismError
        raise MechanismError(f"{mech.source}: the variable name{'s' if len(clash) > 1 else ''} "
                             f"{', '.join(clash)} would be used twice (a parameter named like an output?)")
    return tuple(rows)

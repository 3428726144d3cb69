"""The FMU variable table of a mechanism: one list for the pythonfmu FMU and the native FMU.

Value-reference order: the file's [parameters] (tunable, or fixed with ``fixed = true``), the
start values of the independent coordinates (``<coordinate>_start``, fixed), the integrator's
``rtol``, ``atol`` and ``integrator``, then the outputs in the file's order, then
``max_evaluations`` (added after the outputs so that no earlier value reference moved), then the
``[[inputs]]``' variables (``causality="input"``) in file order.
"""
from __future__ import annotations

from ..mechanism_model.variables import POSITIVE, Variable
from .derivation import MechanismEquations

__all__ = ["variable_table", "native_variable_table", "model_exchange_states", "DEFAULT_TOLERANCE",
           "DEFAULT_MAX_EVALUATIONS"]

#: rtol = atol of the Runge-Kutta error control when the case does not set them.  Table 1 gives
#: 1e-9 and 1e-6 (its case files set them).  At those values the integrator's energy error moves
#: the period of a rotating crank, or of a swing that nearly reaches the top, by up to ~1e-3
#: (relative) in jumps over minutes: a healthy run then drifts like a faulty one
#: (docs/monitor.md, Limitations).  1e-10 costs ~15 % more time in the native FMU.
DEFAULT_TOLERANCE = 1e-10

#: The most right-hand-side evaluations one communication step (doStep) may take before it ends
#: with an error (both FMUs).  The shipped cases need at most 75 per 0.01 s step, at rtol = atol =
#: 1e-13 too (benchmarks/fmu_step_work.py): a factor of 1333; the runaway step it ends (case 1 at
#: omega2_start = 1e15, which never returned) takes 0.03-0.06 s natively (docs/fmi_hosts.md).
DEFAULT_MAX_EVALUATIONS = 100000.0


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
    rows.append(Variable("max_evaluations", "Real", "parameter", "fixed", DEFAULT_MAX_EVALUATIONS, "1",
                         "Most right-hand-side evaluations one communication step may take; beyond it the step "
                         "ends with an error [-]", None, 1.0))
    for entry in mech.inputs:
        for var in entry.variables:
            rows.append(Variable(var.name, "Real", "input", "continuous", var.start, var.unit, var.description))
    names = [v.name for v in rows]
    clash = sorted({n for n in names if names.count(n) > 1})
    if clash:
        from .description import MechanismError
        raise MechanismError(f"{mech.source}: the variable name{'s' if len(clash) > 1 else ''} "
                             f"{', '.join(clash)} would be used twice (a parameter named like an output?)")
    return tuple(rows)


#: The unit of a state's time derivative (Model Exchange's ``der(...)`` variables).
_RATE_UNITS = {"rad": "rad/s", "rad/s": "rad/s2", "m": "m/s", "m/s": "m/s2", "J": "W"}


def model_exchange_states(eqs: MechanismEquations) -> tuple[tuple[str, str, str], ...]:
    """The native FMU's continuous states for Model Exchange, in the C state vector's order
    (dae.c's y): the file's independent coordinates, their rates, then each driver's work;
    per state ``(name, unit, description)``."""
    mech = eqs.mechanism
    coordinates, rates = mech.start[::2], mech.start[1::2]
    states = [(s.coordinate, s.unit, f"Independent coordinate {s.coordinate} (a continuous state)")
              for s in coordinates]
    states += [(s.coordinate, s.unit, f"Rate {s.coordinate} of {c.coordinate} (a continuous state)")
               for c, s in zip(coordinates, rates)]
    states += [(f"{d.name}_work", "J", f"Work done by driver {d.name} since the start (a continuous state)")
               for d in mech.drivers]
    return tuple(states)


def native_variable_table(eqs: MechanismEquations) -> tuple[Variable, ...]:
    """The native FMU's variables: :func:`variable_table`'s (same value references), then what
    Model Exchange adds: each continuous state that is not an output already, as a local
    variable, and each state's derivative ``der(<state>)``."""
    table = variable_table(eqs)
    names = {v.name for v in table}
    rows = list(table)
    for name, unit, description in model_exchange_states(eqs):
        if name not in names:
            rows.append(Variable(name, "Real", "local", "continuous", None, unit, description))
    for name, unit, description in model_exchange_states(eqs):
        rows.append(Variable(f"der({name})", "Real", "local", "continuous", None, _RATE_UNITS[unit],
                             f"Time derivative of {name}"))
    return tuple(rows)

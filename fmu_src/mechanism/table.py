"""The FMU variable table of a mechanism: one list for the pythonfmu FMU and the native FMU.

Value-reference order: the file's [parameters] (tunable, or fixed with ``fixed = true``), the
start values of the independent coordinates (``<coordinate>_start``, fixed), the integrator's
``rtol``, ``atol`` and ``integrator``, then the outputs in the file's order, then
``max_evaluations`` (added after the outputs so that no earlier value reference moved), then the
``[[inputs]]``' variables (``causality="input"``) in file order.

Also what each output and each Model Exchange state's derivative depends on (the model
descriptions' ``<ModelStructure>``): :func:`output_dependencies`, :func:`derivative_dependencies`.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..mechanism_model.variables import POSITIVE, Variable
from .derivation import MechanismEquations

__all__ = ["variable_table", "native_variable_table", "model_exchange_states", "Dependencies",
           "output_dependencies", "derivative_dependencies", "DEFAULT_TOLERANCE", "DEFAULT_MAX_EVALUATIONS"]

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
    (dae.c's y): the file's independent coordinates, their rates, then the work outputs
    (``MechanismEquations.works``: drivers', loads', inputs', dissipated); per state ``(name, unit, description)``."""
    mech = eqs.mechanism
    coordinates, rates = mech.start[::2], mech.start[1::2]
    states = [(s.coordinate, s.unit, f"Independent coordinate {s.coordinate} (a continuous state)")
              for s in coordinates]
    states += [(s.coordinate, s.unit, f"Rate {s.coordinate} of {c.coordinate} (a continuous state)")
               for c, s in zip(coordinates, rates)]
    states += [(w.name, w.unit, f"{w.description.removesuffix(' [J]')} (a continuous state)") for w in eqs.works]
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


@dataclass(frozen=True)
class Dependencies:
    """What one unknown of ``<ModelStructure>`` depends on: Model Exchange's continuous states
    (names from :func:`model_exchange_states`) and the FMI inputs (variable names), in their
    table orders.  ``constant`` (derivatives only): the unknown is its one state dependency,
    exactly (a coordinate's derivative is its rate)."""

    unknown: str
    states: tuple[str, ...]
    inputs: tuple[str, ...]
    constant: bool = False


class _Knowns:
    """Which states and inputs an expression of (q, qd, lambda, t, p, d) depends on, through
    the symbols it holds: the independent coordinates fix q (the dependent ones solved from
    Phi(q, t, u) = 0: the inputs in Phi), the rates with them fix qd (Phi_q qd = nu: the inputs
    in nu too), and the multipliers come from eq. (11) with the accelerations: every input."""

    def __init__(self, eqs: MechanismEquations):
        states = model_exchange_states(eqs)
        n = len(eqs.mechanism.independent)
        self.coordinates = tuple(name for name, _, _ in states[:n])
        self.rates = tuple(name for name, _, _ in states[n:2 * n])
        self.inputs = tuple(str(u) for u in eqs.inputs)
        self._q, self._qd, self._lam = set(eqs.q), set(eqs.qd), set(eqs.multipliers)
        self._symbols = {str(u): u for u in eqs.inputs}
        self._position = {u for u in eqs.inputs if u in eqs.constraints.free_symbols}
        self._velocity = self._position | {u for u in eqs.inputs if u in eqs.nu.free_symbols}

    def of(self, name: str, expr) -> Dependencies:
        free = expr.free_symbols
        inputs = free & set(self._symbols.values())
        states: tuple[str, ...] = ()
        if free & self._q:
            inputs |= self._position
            states = self.coordinates
        if free & self._qd:
            inputs |= self._velocity
            states = self.coordinates + self.rates
        if free & self._lam:
            return self.accelerations(name)
        return Dependencies(name, states, tuple(u for u in self.inputs if self._symbols[u] in inputs))

    def residual(self, name: str) -> Dependencies:
        """The constraint residual, max(|Phi|, |Phi_q qd - nu|): the coordinates, the rates and
        the inputs in Phi and nu (a driver input's)."""
        return Dependencies(name, self.coordinates + self.rates,
                            tuple(u for u in self.inputs if self._symbols[u] in self._velocity))

    def accelerations(self, name: str) -> Dependencies:
        """An unknown that needs the accelerations (eq. 11): the coordinates, the rates, every input."""
        return Dependencies(name, self.coordinates + self.rates, self.inputs)


def output_dependencies(eqs: MechanismEquations) -> tuple[Dependencies, ...]:
    """Per output, in output order, the states and inputs it depends on, from its kind in the
    derivation (``OutputSpec``): an expression of the state depends on the states it holds
    (and on an input it holds, or that moves the dependent coordinates or rates: a driver
    input), one with the multipliers (a reaction, a driver's torque) on every input too, a work
    output on its own state alone (it is the integral), the constraint residual on the
    coordinates, the rates and the driver inputs."""
    knowns = _Knowns(eqs)
    rows = []
    for out in eqs.outputs:
        if out.integrand is not None:
            rows.append(Dependencies(out.name, (out.name,), ()))
        elif out.expression is not None:
            rows.append(knowns.of(out.name, out.expression))
        else:                                          # RUNTIME_OUTPUTS: constraint_residual
            rows.append(knowns.residual(out.name))
    return tuple(rows)


def derivative_dependencies(eqs: MechanismEquations) -> tuple[Dependencies, ...]:
    """Per Model Exchange state, in :func:`model_exchange_states`' order, what its derivative
    ``der(<state>)`` depends on: a coordinate's is its rate (exactly), a rate's is an
    acceleration (eq. 11: the coordinates, the rates, every input), a work state's is the power
    it integrates (``OutputSpec.integrand``, as :func:`output_dependencies` reads an expression)."""
    knowns = _Knowns(eqs)
    rows = [Dependencies(f"der({c})", (r,), (), constant=True) for c, r in zip(knowns.coordinates, knowns.rates)]
    rows += [knowns.accelerations(f"der({r})") for r in knowns.rates]
    rows += [knowns.of(f"der({w.name})", w.integrand) for w in eqs.works]
    return tuple(rows)

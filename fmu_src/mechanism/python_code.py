"""A mechanism's equations as a plain-Python module: what its pythonfmu FMU ships.

The generated module has no sympy dependency.  Each function evaluates a group of expressions
after common-subexpression elimination (``sympy.cse``) with scalar ``math`` calls, which is
markedly faster than numpy for states of a few dozen numbers.  The linear algebra (Newton-
Raphson, the range-space solve) is numerical, at run time (``mechanism_model.dae``).
"""
from __future__ import annotations

import types
from pathlib import Path

import sympy as sp
from sympy.printing.pycode import PythonCodePrinter

from .derivation import MechanismEquations
from .quoting import comment_text
from .table import variable_table

__all__ = ["generate_module", "load_module"]


class _Printer(PythonCodePrinter):
    """Python printer that writes ``cos(x)`` instead of ``math.cos(x)``."""

    def _print_known_func(self, expr):
        name = expr.func.__name__
        return f"{name}({', '.join(self._print(a) for a in expr.args)})"

    _print_cos = _print_sin = _print_known_func



def _index(params: list[str], name: str | None) -> int:
    """The index of parameter ``name`` in ``params``; -1 for None (a time-function driver)."""
    return -1 if name is None else params.index(name)

def _unpack(names: list[str], array: str) -> str:
    if not names:
        return ""
    return f"    {', '.join(names)}, = {array}"


class _Writer:
    def __init__(self, eqs: MechanismEquations):
        self.eqs = eqs
        self.printer = _Printer({"fully_qualified_modules": False, "standard": "python3"})
        self.arrays = {
            "q": [str(s) for s in eqs.q], "qd": [str(s) for s in eqs.qd], "p": [str(s) for s in eqs.params],
            "d": [str(s) for s in eqs.drive], "lam": [str(s) for s in eqs.multipliers], "t": None,
        }

    def function(self, name: str, args: str, doc: str, exprs: list[sp.Expr], shape: str = "list") -> str:
        """A function returning ``exprs`` as a list, a tuple, a numpy (rows, cols) array or a scalar."""
        replacements, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("_c"), optimizations="basic")
        used = set().union(*(e.free_symbols for e in exprs)) if exprs else set()
        used_names = {str(s) for s in used}
        lines = [f"def {name}({args}):", f'    """{doc}"""']
        for arg in args.split(", "):
            names = self.arrays.get(arg)
            if names and used_names & set(names):
                lines.append(_unpack(names, arg))
        lines += [f"    {s} = {self.printer.doprint(e)}" for s, e in replacements]
        items = ", ".join(self.printer.doprint(e) for e in reduced)
        if shape == "list":
            lines.append(f"    return [{items}]")
        elif shape[0] == "split":
            k = shape[1]
            first = ", ".join(self.printer.doprint(e) for e in reduced[:k])
            rest = ", ".join(self.printer.doprint(e) for e in reduced[k:])
            lines.append(f"    return [{first}], [{rest}]")
        elif shape == "scalar":
            lines.append(f"    return {items}")
        else:
            rows, cols = shape
            lines.append(f"    return array([{items}], dtype=float).reshape({rows}, {cols})")
        return "\n".join(lines) + "\n"


def _guess(eqs: MechanismEquations) -> tuple[float, ...]:
    values = {}
    for body in eqs.mechanism.bodies:
        x, y, angle = body.guess
        values.update({f"x{body.label}": x, f"y{body.label}": y, f"theta{body.label}": angle})
    return tuple(float(values[c]) for c in eqs.coordinates)


def load_module(source: str, name: str) -> types.ModuleType:
    """A generated module, executed as a module of ``fmu_src.mechanism_model`` (in-process
    use: checks at build time, tests); a built FMU ships it as ``mechanism_model/equations.py``."""
    module = types.ModuleType(f"fmu_src.mechanism_model.equations_{name}")
    module.__package__ = "fmu_src.mechanism_model"
    exec(compile(source, f"<{name} equations>", "exec"), module.__dict__)
    return module


def generate_module(eqs: MechanismEquations) -> str:
    """The source text of the mechanism's generated equations module."""
    mech = eqs.mechanism
    w = _Writer(eqs)
    n, m = eqs.n, eqs.m
    qd_sub = {}
    lam = set(eqs.multipliers)
    state_outputs = [o for o in eqs.outputs if o.expression is not None and not (o.expression.free_symbols & lam)]
    force_outputs = [o for o in eqs.outputs if o.expression is not None and o.expression.free_symbols & lam]
    params = [p.name for p in mech.parameters]
    drivers = tuple((d.name, _index(params, d.start), _index(params, d.speed), row)
                    for d, row in zip(mech.drivers, eqs.driver_rows))
    output_kinds = tuple(("force" if o in force_outputs else "state") if o.expression is not None
                         else ("work" if o.work is not None else o.name) for o in eqs.outputs)
    works = tuple(o.work for o in eqs.outputs if o.work is not None)
    header = f'''"""{mech.name} equations, generated by fmu_src/mechanism/python_code.py from {comment_text(Path(mech.source).name)}.

Do not edit: regenerate with ``python build_fmu.py --mechanism ...``.

q = [{", ".join(eqs.coordinates)}], qd = dq/dt; p = ({", ".join(str(x) for x in eqs.params)});
d = the drivers' (s_ref, t_ref, v); lam = the multipliers.
Equation form: M qdd + Phi_q^T lambda = Q, Phi_q qdd = gamma, Phi_q qd = nu.
"""
from math import acos, asin, atan, atan2, cos, exp, log, pi, sin, sqrt, tan, tanh  # noqa: F401  (expressions.FUNCTIONS and CONSTANTS; tanh: [[friction]])

from numpy import array

from .variables import Variable

NAME = {mech.name!r}
DESCRIPTION = {mech.description!r}
COORDINATES = {eqs.coordinates!r}
N_COORDINATES = {n}
N_CONSTRAINTS = {m}
#: Indices in q of the independent coordinates whose start values are parameters.
INDEPENDENT = {eqs.independent!r}
#: The start-value parameters of INDEPENDENT: (position, rate) per coordinate.
START_PARAMETERS = {tuple((s.parameter, r.parameter) for s, r in zip(mech.start[::2], mech.start[1::2]))!r}
PARAMETERS = {tuple(params)!r}
#: The FMI input variables, in value-reference order: p is PARAMETERS' values, then theirs.
INPUTS = {tuple(str(u) for u in eqs.inputs)!r}
#: The index in INPUTS of each driver input's position u (its rate u_d and acceleration u_dd follow).
INPUT_DRIVERS = {tuple([str(u) for u in eqs.inputs].index(d.input) for d in mech.drivers if d.input is not None)!r}
#: Per driver: (name, index in p of its start, index in p of its speed, its row of Phi).
DRIVERS = {drivers!r}
#: Joint (or driver) name -> its rows of Phi.
JOINT_ROWS = {dict(eqs.joint_rows)!r}
#: Per output, in output order: "state" (from ``state_outputs``), "force" (from ``force_outputs``:
#: needs the multipliers), "work" (a driver's work) or "constraint_residual".
OUTPUT_KINDS = {output_kinds!r}
#: The driver index of each "work" output, in output order.
OUTPUT_WORKS = {works!r}
#: Where assembly starts (the bodies' positions and angles given in the file).
GUESS = {_guess(eqs)!r}
#: True when M does not depend on the state (it can be cached per parameter set).
MASS_IS_CONSTANT = {not (eqs.mass_matrix.free_symbols & set(eqs.q))}

VARIABLES = (
'''
    header += "".join(f"    Variable{tuple(v)!r},\n" for v in variable_table(eqs)) + ")\n\n\n"
    M = eqs.mass_matrix
    entries = [(i, j) for i in range(m) for j in range(n) if eqs.jacobian[i, j] != 0]
    header += f"#: The (row, column) of each structurally nonzero entry of Phi_q.\nJACOBIAN_ENTRIES = {tuple(entries)!r}\n\n\n"
    body = [
        w.function("mass_diagonal", "q, p", f"The diagonal of M ({n}).", [M[i, i] for i in range(n)]),
        w.function("forces", "q, qd, t, p", f"Generalized forces Q ({n}).", list(eqs.forces)),
        w.function("constraints", "q, t, p, d", f"Phi ({m}).", list(eqs.constraints)),
        w.function("jacobian", "q, p", f"Phi_q ({m}x{n}), numpy array.", list(eqs.jacobian), (m, n)),
        w.function("kinematics", "q, t, p, d", "(Phi, the nonzero entries of Phi_q in JACOBIAN_ENTRIES order): "
                   "what one Newton-Raphson iteration needs, sharing subexpressions.",
                   list(eqs.constraints) + [eqs.jacobian[i, j] for i, j in entries], ("split", m)),
        w.function("dynamics", "q, qd, t, p, d", "(Q, gamma): the right-hand sides of eq. (11), sharing "
                   "subexpressions.", list(eqs.forces) + list(eqs.gamma), ("split", n)),
        w.function("nu", "t, p, d", f"nu = -Phi_t ({m}): Phi_q qd = nu.", list(eqs.nu)),
        w.function("gamma", "q, qd, t, p, d", f"gamma ({m}): Phi_q qdd = gamma.", list(eqs.gamma)),
        w.function("energy", "q, qd, p", "(T, V) in J.", [eqs.kinetic_energy, eqs.potential_energy]),
        w.function("state_outputs", "q, qd, t, p, d", "The outputs of kind \"state\", in output order.",
                   [o.expression for o in state_outputs]),
        w.function("force_outputs", "q, qd, lam, t, p, d", "The outputs of kind \"force\" (joint reactions, "
                   "drivers' torques and forces), in output order.", [o.expression for o in force_outputs]),
    ]
    del qd_sub
    return header + "\n\n".join(body)

"""Turn the symbolic four-bar equations into a plain-Python/numpy module.

The generated module has no sympy dependency: it is what the FMU ships.  Each
function evaluates a group of expressions after common-subexpression
elimination (``sympy.cse``) with scalar ``math`` calls, which is markedly faster
than numpy for 9-element states.  Linear systems are solved numerically at run
time (``fourbar_model.dae``), never symbolically.
"""
from __future__ import annotations

import sympy as sp
from sympy.printing.pycode import PythonCodePrinter

from .derivation import COORDINATES, INDEPENDENT, PARAMETERS, FourBarEquations, derive_equations

__all__ = ["generate_module", "write_module", "write_if_changed"]


class _Printer(PythonCodePrinter):
    """Python printer that writes ``cos(x)`` instead of ``math.cos(x)``."""

    def _print_known_func(self, expr):
        name = expr.func.__name__
        return f"{name}({', '.join(self._print(a) for a in expr.args)})"

    _print_cos = _print_sin = _print_known_func


def _printer() -> _Printer:
    return _Printer({"fully_qualified_modules": False, "standard": "python3"})


def _preamble(name: str, args: str, doc: str, eqs: FourBarEquations) -> list[str]:
    """``def`` line, docstring and the unpacking of the arguments into symbol names."""
    lines = [f"def {name}({args}):", f'    """{doc}"""']
    names = args.split(", ")
    if "lam" in names:
        lines.append(f"    {', '.join(str(s) for s in eqs.multipliers)}, = lam")
    if "q" in names:
        lines.append(f"    {', '.join(COORDINATES)} = q")
    if "qd" in names:
        lines.append(f"    {', '.join(n + '_d' for n in COORDINATES)} = qd")
    lines.append(f"    {', '.join(PARAMETERS)} = p")
    return lines


def _function(name: str, args: str, doc: str, outputs: dict[str, sp.Matrix | sp.Expr],
              eqs: FourBarEquations, container: str = "array") -> str:
    """One generated function returning the given named outputs (flattened, row-major).

    Matrices are returned as numpy arrays (``container="array"``) or, where the caller
    goes on with scalar code, as plain lists of floats (``container="list"``).
    """
    printer = _printer()
    names = list(outputs)
    flat: list[sp.Expr] = []
    shapes: list[tuple[int, ...]] = []
    for key in names:
        value = outputs[key]
        if isinstance(value, sp.MatrixBase):
            shapes.append(value.shape)
            flat.extend(value)
        else:
            shapes.append(())
            flat.append(value)
    replacements, reduced = sp.cse(flat, symbols=sp.numbered_symbols("_c"), optimizations="basic")
    lines = _preamble(name, args, doc, eqs)
    for sym, expr in replacements:
        lines.append(f"    {sym} = {printer.doprint(expr)}")
    pos = 0
    results = []
    for key, shape in zip(names, shapes):
        if shape == ():
            lines.append(f"    {key} = {printer.doprint(reduced[pos])}")
            pos += 1
        else:
            n = shape[0] * shape[1]
            items = ", ".join(printer.doprint(e) for e in reduced[pos:pos + n])
            pos += n
            if container == "list":
                lines.append(f"    {key} = [{items}]")
            elif shape[1] == 1:
                lines.append(f"    {key} = array([{items}], dtype=float)")
            else:
                lines.append(f"    {key} = array([{items}], dtype=float).reshape({shape[0]}, {shape[1]})")
        results.append(key)
    lines.append(f"    return {', '.join(results)}")
    return "\n".join(lines) + "\n"


def _max_abs_function(name: str, args: str, doc: str, exprs: list[sp.Expr], eqs: FourBarEquations) -> str:
    """A generated function returning max(|e|) over the given expressions."""
    printer = _printer()
    replacements, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("_c"), optimizations="basic")
    lines = _preamble(name, args, doc, eqs)
    lines += [f"    {sym} = {printer.doprint(expr)}" for sym, expr in replacements]
    lines.append(f"    return max({', '.join(f'abs({printer.doprint(e)})' for e in reduced)})")
    return "\n".join(lines) + "\n"


def _fill_function(name: str, matrix: sp.Matrix, eqs: FourBarEquations, doc: str,
                   lower_only: bool = False) -> str:
    """A function writing only the state-dependent entries of ``matrix`` into an array.

    With ``lower_only`` just the lower triangle (with the diagonal) is written: what
    LAPACK reads of a symmetric matrix factorised with ``lower=1``.
    """
    printer = _printer()
    state = set(eqs.q)
    entries = [(i, j, matrix[i, j]) for i in range(matrix.rows) for j in range(matrix.cols)
               if matrix[i, j].free_symbols & state and (j <= i or not lower_only)]
    replacements, reduced = sp.cse([e for _, _, e in entries], symbols=sp.numbered_symbols("_c"),
                                   optimizations="basic")
    lines = _preamble(name, "out, q, p", doc, eqs)
    lines += [f"    {sym} = {printer.doprint(expr)}" for sym, expr in replacements]
    lines += [f"    out[{i}, {j}] = {printer.doprint(e)}" for (i, j, _), e in zip(entries, reduced)]
    return "\n".join(lines) + "\n"


def _rhs_terms_function(eqs: FourBarEquations) -> str:
    """The right-hand side's scalar work in one function, sharing subexpressions.

    From the closed-form positions and the crank rate: the rates of all coordinates
    (``velocities``), the state-dependent lower-triangle entries of S written into the
    flat column-major view ``out`` of the 8x8 array (entry (i, j) at ``i + 8 j``), and the
    right-hand side of S lambda = Phi_q M^-1 Q - gamma with the rates substituted.
    """
    printer = _printer()
    S = eqs.schur_matrix
    n = S.rows
    entries = [(i, j) for i in range(n) for j in range(i + 1) if S[i, j].free_symbols & set(eqs.q)]
    rates = list(eqs.velocities)
    r = list(eqs.schur_rhs.subs(dict(zip(eqs.qd, rates))))
    flat = rates + [S[i, j] for i, j in entries] + r
    replacements, reduced = sp.cse(flat, symbols=sp.numbered_symbols("_c"), optimizations="basic")
    lines = _preamble("rhs_terms", "out, q, omega, p",
                      "Rates qd (list of 9) and the right-hand side r (list of 8) for a crank rate "
                      "omega; writes the state-dependent lower-triangle entries of S into the flat "
                      "column-major view ``out`` (entry (i, j) at i + 8 j).  The fused form of "
                      "``velocities``, ``schur_fill`` and ``schur_rhs`` used by the integrator.", eqs)
    lines += [f"    {sym} = {printer.doprint(expr)}" for sym, expr in replacements]
    k = len(rates)
    lines += [f"    out[{i + n * j}] = {printer.doprint(e)}" for (i, j), e in zip(entries, reduced[k:k + len(entries)])]
    lines.append(f"    return [{', '.join(printer.doprint(e) for e in reduced[:k])}], "
                 f"[{', '.join(printer.doprint(e) for e in reduced[k + len(entries):])}]")
    return "\n".join(lines) + "\n"


def generate_module(eqs: FourBarEquations | None = None) -> str:
    """Return the source text of the generated equations module."""
    eqs = eqs or derive_equations()
    header = f'''"""Four-bar linkage equations, generated by fmu_src/codegen.py from fmu_src/derivation.py.

Do not edit: regenerate with ``python build_fmu.py``.

State ordering q = [{", ".join(COORDINATES)}], qd = its time derivative.
Arguments are sequences of Python floats (lists are fastest), p = the parameter tuple.
Parameters p = ({", ".join(PARAMETERS)}).
Equation form: M qdd + Phi_q^T lambda = Q,  Phi_q qdd = gamma.
"""
from math import atan2, cos, sin, sqrt

from numpy import array

COORDINATES = {COORDINATES!r}
PARAMETERS = {PARAMETERS!r}
N_COORDINATES = {len(COORDINATES)}
N_CONSTRAINTS = {eqs.constraints.shape[0]}
#: The independent coordinate of the coordinate partitioning, and its index in q.
INDEPENDENT = {INDEPENDENT!r}
INDEPENDENT_INDEX = {COORDINATES.index(INDEPENDENT)}
#: True when M does not depend on the state (it can be cached per parameter set).
MASS_IS_CONSTANT = {not (eqs.mass_matrix.free_symbols & (set(eqs.q) | set(eqs.qd)))}


'''
    i = COORDINATES.index(INDEPENDENT)
    body = [
        _function("mass_matrix", "q, p", "Mass matrix M (9x9).", {"M": eqs.mass_matrix}, eqs),
        _function("forces", "q, qd, p", "Generalized forces Q (9,), gravity and velocity terms.",
                  {"Q": eqs.forces}, eqs),
        _function("constraints", "q, p", "Constraint residual Phi (8,).", {"Phi": eqs.constraints}, eqs),
        _function("jacobian", "q, p", "Constraint Jacobian Phi_q (8x9).", {"Phi_q": eqs.jacobian}, eqs),
        _function("gamma", "q, qd, p", "Right-hand side gamma = -(Phi_q qd)_q qd (8,).",
                  {"gamma": eqs.gamma}, eqs),
        _function("schur_matrix", "q, p", "S = Phi_q M^-1 Phi_q^T (8x8), symmetric positive definite "
                  "away from toggle positions.", {"S": eqs.schur_matrix}, eqs),
        _fill_function("schur_fill", eqs.schur_matrix, eqs,
                       "Write the state-dependent entries of the lower triangle of S into ``out`` "
                       "(8x8); the others are those of ``schur_matrix`` for the same parameters.",
                       lower_only=True),
        _rhs_terms_function(eqs),
        _function("schur_rhs", "q, qd, p", "Right-hand side of S lambda = Phi_q M^-1 Q - gamma (list of 8).",
                  {"r": eqs.schur_rhs}, eqs, container="list"),
        _function("accelerations", "lam, q, qd, p", "qdd = M^-1 (Q - Phi_q^T lambda) (9,) for given "
                  "multipliers.",
                  {"qdd": eqs.accelerations}, eqs),
        _function("independent_acceleration", "lam, q, qd, p",
                  f"The {INDEPENDENT} component of ``accelerations`` (rad/s2).",
                  {"qdd": eqs.accelerations[i]}, eqs),
        _function("velocities", "q, omega, p",
                  f"qd (list of 9) solving Phi_q qd = 0 with {INDEPENDENT}_d = omega (coordinate "
                  "partitioning); singular at toggle positions.",
                  {"qd": eqs.velocities}, eqs, container="list"),
        _max_abs_function("constraint_residual", "q, qd, p",
                          "max(|Phi|, |Phi_q qd|) over all 16 components (m and m/s).",
                          list(eqs.constraints) + list(eqs.velocity_constraints), eqs),
        _function("energy", "q, qd, p", "Kinetic and potential energy (J).",
                  {"T": eqs.kinetic_energy, "V": eqs.potential_energy}, eqs),
    ]
    d, a, h, branch = eqs.closure_symbols
    body += [
        _function("closure_reach", "th2, p",
                  "Loop closure at crank angle th2: (d, a, h2), see fmu_src/derivation.py; the loop "
                  "closes only where h2 > 0.", {"d": eqs.closure_reach[0], "a": eqs.closure_reach[1],
                                                 "h2": eqs.closure_reach[2]}, eqs),
        _function("closure_angles", "th2, d, a, h, branch, p",
                  "(th3, th4) in rad from the loop closure's d, a, h = sqrt(h2) on a branch (+1/-1).",
                  {"th3": eqs.closure_angles[0], "th4": eqs.closure_angles[1]}, eqs),
        _function("positions", "th2, th3, th4, p", "q (list of 9) for the three link angles (Phi = 0).",
                  {"q": eqs.positions}, eqs, container="list"),
        _function("branch_indicator", "q, p", "(O4 - A) x (B - A): >= 0 on assembly branch +1, < 0 on -1.",
                  {"cross": eqs.branch_indicator}, eqs),
    ]
    return header + "\n\n".join(body)


def write_if_changed(path, text: str) -> None:
    """Write ``text`` to ``path`` unless the file already holds it (its time stamp is kept,
    so make does not rebuild for a regenerated but unchanged file)."""
    from pathlib import Path
    path = Path(path)
    if not path.exists() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8", newline="\n")


def write_module(path) -> str:
    """Generate the module and write it to ``path``; returns the source text."""
    source = generate_module()
    write_if_changed(path, source)
    return source

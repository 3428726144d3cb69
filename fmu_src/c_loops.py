"""The reduced constraints of the declared partition solved in closed form, loop by loop.

``c_reduction`` leaves the loop closures in the dependent angles ``z``.  For the linkages people
draw, each closure is a pair of rows (its x and y components) in two unknown angles, or a single
row in one, in which every unknown enters through a rotation of a vector of known length:

    dyad:    R(a) u + R(b) w + c = 0      (the four-bar's L3 e3 - L4 e4 + (L2 e2 - L1 ex) = 0)
    single:  alpha cos(a) + beta sin(a) + gamma = 0    (the slider-crank's L3 sin(theta3) + ...)

where u, w, c, alpha, beta, gamma depend on the independent coordinates, time and the angles of
earlier stages only.  A dyad is then the intersection of two circles, |R(a) u| = |u| and
|R(a) u + c| = |w|, and a single row that of a line and the unit circle: two solutions, the
assembly branch picks one.  ``closed_stages`` finds an order in which every row of the reduced
system is such a stage, and the coefficients of each; the native FMU's right-hand side
(``dae.c``, ``closed_positions``) solves them in that order and falls back on Newton-Raphson on the
reduced system where a stage has no clear solution (near a dead point, where the two solutions
meet).  Everything is read off the sympy expressions of the mechanism's constraints; where they
do not have this shape (a slider among the unknowns, a closure with three unknown angles)
``closed_stages`` returns None and Newton-Raphson does all the work, as before.
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations
from typing import Sequence

import sympy as sp

__all__ = ["ClosedStage", "closed_stages"]


@dataclass(frozen=True)
class ClosedStage:
    """One step of the closed-form solution.

    ``unknowns``: positions in ``Reduction.z`` (``c_reduction``) (two for a dyad, one for a single row);
    ``rows``: the rows of ``Reduction.residual`` it solves, ``sign`` how the second enters (a
    dyad's (x, y) are (rows[0], sign * rows[1]));
    ``coefficients``: for a dyad (u_x, u_y, w_x, w_y, c_x, c_y) with R(a) u + R(b) w + c = 0, a
    and b the two unknowns in that order; for a single row (alpha, beta, gamma).  In the
    equations' own symbols.
    """

    unknowns: tuple[int, ...]
    rows: tuple[int, ...]
    sign: int
    coefficients: tuple[sp.Expr, ...]

    @property
    def is_dyad(self) -> bool:
        return len(self.unknowns) == 2


def _linear_in(expr: sp.Expr, trig: dict[sp.Symbol, tuple[sp.Symbol, sp.Symbol]]) -> dict | None:
    """expr as constant + sum of coefficient * (cos or sin of an unknown angle): {key: coefficient}
    with keys (angle, 0 for cos / 1 for sin) and None for the constant; None when expr is not of
    that form (an unknown elsewhere, a product of two)."""
    # cos and sin of a sum with an unknown in it (a point off a body's axis: cos(theta + phi)) are
    # expanded; the others are left as they are (a driven angle's cos(s_ref + v t) is read whole)
    unknown = set(trig)
    compound = {f: sp.expand_trig(f) for f in expr.atoms(sp.cos, sp.sin)
                if f.args[0] not in unknown and f.args[0].free_symbols & unknown}
    expr = sp.expand(expr.xreplace(compound))
    replace, marks = {}, []
    for angle, (c, s) in trig.items():
        replace[sp.cos(angle)] = c
        replace[sp.sin(angle)] = s
        marks += [c, s]
    reduced = expr.xreplace(replace)
    if reduced.free_symbols & set(trig):
        return None
    try:
        poly = sp.Poly(reduced, *marks)
    except sp.PolynomialError:
        return None
    if poly.total_degree() > 1:
        return None
    terms = {None: poly.coeff_monomial(1)}
    for k, mark in enumerate(marks):
        coefficient = poly.coeff_monomial(mark)
        if coefficient != 0:
            terms[(list(trig)[k // 2], k % 2)] = coefficient
    return terms


def _rotation(t1: dict, t2: dict, angle) -> tuple[sp.Expr, sp.Expr] | None:
    """u with (row 1, row 2) = R(angle) u + ..., i.e. row 1 = u_x cos - u_y sin, row 2 = u_y cos +
    u_x sin; None when the rows' cos and sin coefficients do not have that shape."""
    a, b = t1.get((angle, 0), 0), t1.get((angle, 1), 0)
    c, d = t2.get((angle, 0), 0), t2.get((angle, 1), 0)
    if sp.simplify(a - d) != 0 or sp.simplify(b + c) != 0 or (a == 0 and b == 0):
        return None
    return a, c


def _dyad(rows: tuple[sp.Expr, sp.Expr], unknowns, trig) -> tuple[int, tuple[sp.Expr, ...]] | None:
    """The sign and (u_x, u_y, w_x, w_y, c_x, c_y) of a pair of rows in two unknown angles, trying
    the second row as it is and negated (the pair may be (x, -y) or (y, x) in disguise); None if
    neither fits."""
    for sign in (1, -1):
        t1, t2 = _linear_in(rows[0], trig), _linear_in(sign * rows[1], trig)
        if t1 is None or t2 is None:
            return None
        u, w = _rotation(t1, t2, unknowns[0]), _rotation(t1, t2, unknowns[1])
        if u is not None and w is not None:
            return sign, (*u, *w, t1[None], t2[None])
    return None


def _single(row: sp.Expr, unknown, trig) -> tuple[sp.Expr, ...] | None:
    """(alpha, beta, gamma) of a row alpha cos(a) + beta sin(a) + gamma; None if it is not one."""
    terms = _linear_in(row, trig)
    if terms is None:
        return None
    alpha, beta = terms.get((unknown, 0), 0), terms.get((unknown, 1), 0)
    if alpha == 0 and beta == 0:
        return None
    return alpha, beta, terms[None]


def closed_stages(residual: Sequence[sp.Expr], z_indices: Sequence[int], q: Sequence[sp.Symbol],
                  angles: Sequence[int]) -> tuple[ClosedStage, ...] | None:
    """The reduced system (``Reduction.residual`` in ``Reduction.z``, given as ``residual`` and
    ``z_indices``) as a sequence of dyads and single rows (see the module's docstring), each in
    unknowns the earlier ones do not solve; None where it is not one.

    ``q``: the coordinates' symbols; ``angles``: the indices in q that are angles.
    """
    if not z_indices or any(i not in angles for i in z_indices):
        return None
    z = [q[i] for i in z_indices]
    residual = list(residual)
    rows = list(range(len(residual)))
    solved: set[int] = set()
    stages: list[ClosedStage] = []

    def unknown_in(row: int) -> list[int]:
        free = residual[row].free_symbols
        return [k for k in range(len(z)) if k not in solved and z[k] in free]

    while rows:
        found = None
        for r in rows:                          # a single row in one unknown
            ks = unknown_in(r)
            if len(ks) == 1:
                trig = {z[ks[0]]: (sp.Dummy("c"), sp.Dummy("s"))}
                coefficients = _single(residual[r], z[ks[0]], trig)
                if coefficients is not None:
                    found = ClosedStage((ks[0],), (r,), 1, coefficients)
                    break
        if found is None:
            for r1, r2 in combinations(rows, 2):     # a pair of rows in the same two unknowns
                ks = unknown_in(r1)
                if len(ks) != 2 or unknown_in(r2) != ks:
                    continue
                trig = {z[k]: (sp.Dummy("c"), sp.Dummy("s")) for k in ks}
                dyad = _dyad((residual[r1], residual[r2]), [z[k] for k in ks], trig)
                if dyad is not None:
                    found = ClosedStage(tuple(ks), (r1, r2), *dyad)
                    break
        if found is None:
            return None
        rows = [r for r in rows if r not in found.rows]
        solved.update(found.unknowns)
        stages.append(found)
    return tuple(stages)

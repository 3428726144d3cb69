"""The declared partition's constraints reduced to the few coordinates Newton-Raphson must solve for.

In Cartesian coordinates most rows of ``Phi(q, t) = 0`` are linear, with a constant coefficient,
in one body's ``x`` or ``y`` (a pin writes ``x_i + ... - x_j - ... = 0``).  The static
factorisation of the dependent block (``c_codegen._static_lu``) pivots on exactly those
entries.  Here the same pivots are used on the equations themselves, by substitution: each
pivot row is solved in closed form for its pivot coordinate, and what is left is

    r(z; q_independent, t) = Phi[rows](q with the pivot coordinates substituted) = 0,

a system in the Schur complement's coordinates ``z`` only (the dependent angles, and a slider's
position: two for the four-bar, four for the Watt six-bar).  Its Jacobian ``dr/dz`` *is* the
dependent block's Schur complement (the chain rule does the elimination), so its determinant
has the block's sign times the static factorisation's (``MECH_DEP_SIGN``): the assembly branch
reads the same.

The native FMU's right-hand side (``dae.c``) solves ``r = 0`` by Newton-Raphson, fills the
pivot coordinates in from their closed forms, and takes rates and accelerations from the
derivatives below: the same numbers as the full system up to round-off, with far fewer
operations.  Everything is derived here with sympy from the mechanism's ``Phi``; nothing is
written by hand.  ``reduce_constraints`` returns None where a pivot row is not linear in its
pivot coordinate with a constant coefficient (the generic code then keeps the full system).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import sympy as sp

from .mechanism.derivation import MechanismEquations

__all__ = ["Reduction", "reduce_constraints"]


@dataclass(frozen=True)
class Reduction:
    """The reduced constraints of the declared partition, in the equations' own symbols.

    ``z`` and ``eliminated`` are indices in q; ``rows`` are rows of Phi.  With ``zd``, ``qid``
    the rates of z and of the independent coordinates:

    - ``residual`` (R): r, Phi[rows] with ``closed_form`` substituted; ``S = dr/dz`` (R x R),
      ``B = dr/dq_independent`` (R x K), ``r_t = dr/dt`` (R);
    - ``closed_form`` (E): the eliminated coordinates as functions of z, the independent
      coordinates and t; ``G_z`` (E x R), ``G_i`` (E x K), ``g_t`` (E) its derivatives;
    - rates: ``S zd = -(B qid + r_t)``, eliminated rates ``G_z zd + G_i qid + g_t``;
    - accelerations: ``S zdd + B qidd + gamma = 0`` and eliminated accelerations
      ``G_z zdd + G_i qidd + kappa``, where ``gamma`` (R) and ``kappa`` (E) are the rates' time
      derivatives at zero accelerations (functions of q, qd and t).
    """

    z: tuple[int, ...]
    rows: tuple[int, ...]
    eliminated: tuple[int, ...]
    closed_form: tuple[sp.Expr, ...]
    residual: sp.Matrix
    S: sp.Matrix
    B: sp.Matrix
    r_t: sp.Matrix
    G_z: sp.Matrix
    G_i: sp.Matrix
    g_t: sp.Matrix
    gamma: sp.Matrix
    kappa: sp.Matrix


def _time_derivative(exprs: sp.Matrix, coordinates: Sequence[sp.Symbol], rates: Sequence[sp.Symbol],
                     eqs: MechanismEquations) -> sp.Matrix:
    """d/dt of expressions of (coordinates, t, a driver's inputs) along the given rates (the rates
    held fixed; a driver input's rate and acceleration are inputs too: eqs.time_partial)."""
    out = eqs.time_partial(exprs)
    for x, xd in zip(coordinates, rates):
        out += exprs.diff(x) * xd
    return out


def reduce_constraints(eqs: MechanismEquations, pivots: Sequence[tuple[int, int]], rows: Sequence[int],
                       z: Sequence[int]) -> Reduction | None:
    """Solve each pivot row (``pivots``: (row of Phi, index in q), in elimination order) for its
    coordinate and substitute it everywhere; ``rows`` and ``z`` are what is left (the Schur
    complement's rows and coordinates, in its order).  None when a pivot row is not linear in its
    coordinate with a constant nonzero coefficient."""
    q, qd, t = list(eqs.q), list(eqs.qd), eqs.t
    solved: dict[sp.Symbol, sp.Expr] = {}
    for row, index in pivots:
        x = q[index]
        expr = eqs.constraints[row].xreplace(solved)
        coefficient = sp.diff(expr, x)
        if not coefficient.is_number or coefficient == 0:
            return None
        rest = sp.expand(expr - coefficient * x)
        if rest.has(x):
            return None
        value = -rest / coefficient
        solved = {k: v.xreplace({x: value}) for k, v in solved.items()}
        solved[x] = value
    eliminated = tuple(index for _, index in pivots)
    closed = tuple(solved[q[i]] for i in eliminated)
    residual = sp.Matrix([eqs.constraints[r].xreplace(solved) for r in rows])
    gone = {q[i] for i in eliminated}
    if any(e.free_symbols & gone for e in (*closed, *residual)):
        return None
    independent = list(eqs.independent)
    z_syms = [q[i] for i in z]
    i_syms = [q[i] for i in independent]
    zd_syms = [qd[i] for i in z]
    id_syms = [qd[i] for i in independent]
    R, E, K = len(z), len(eliminated), len(independent)
    g = sp.Matrix(closed) if E else sp.zeros(0, 1)
    S = residual.jacobian(z_syms) if R else sp.zeros(0, 0)
    B = residual.jacobian(i_syms) if R and K else sp.zeros(R, K)
    G_z = g.jacobian(z_syms) if E and R else sp.zeros(E, R)
    G_i = g.jacobian(i_syms) if E and K else sp.zeros(E, K)
    r_t = eqs.time_partial(residual) if R else sp.zeros(0, 1)
    g_t = eqs.time_partial(g) if E else sp.zeros(0, 1)
    coordinates, rates = z_syms + i_syms, zd_syms + id_syms
    zd_col, id_col = sp.Matrix(R, 1, zd_syms), sp.Matrix(K, 1, id_syms)
    r_rate = S * zd_col + B * id_col + r_t if R else sp.zeros(0, 1)
    g_rate = G_z * zd_col + G_i * id_col + g_t if E else sp.zeros(0, 1)
    gamma = _time_derivative(r_rate, coordinates, rates, eqs) if R else sp.zeros(0, 1)
    kappa = _time_derivative(g_rate, coordinates, rates, eqs) if E else sp.zeros(0, 1)
    return Reduction(tuple(z), tuple(rows), eliminated, closed, residual, S, B, r_t, G_z, G_i, g_t, gamma, kappa)

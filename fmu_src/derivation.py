"""Symbolic derivation of the four-bar linkage's constrained equations of motion.

Model (README.md, "The mechanical part")
----------------------------------------
Planar four-bar, link 1 is the ground.  The crank (link 2, length ``L2``) is pinned
at the origin, the coupler (link 3, ``L3``) joins the crank tip to the rocker tip,
the rocker (link 4, ``L4``) is pinned at ``(L1, 0)``.  Angles are measured from +x,
counter-clockwise; gravity ``g`` acts along -y.  Every moving link is a slender
uniform rod with its mass at the midpoint and ``I = m L**2 / 12`` about it.

Generalized coordinates (the state ordering used everywhere in this project)::

    q = [x2, y2, th2, x3, y3, th3, x4, y4, th4]

8 holonomic, scleronomic constraints ``Phi(q) = 0`` (two per revolute joint, in
the order: ground-crank, crank-coupler, coupler-rocker, rocker-ground).

Equation form (the paper's eq. (10)-(11))::

    [[M,     Phi_q^T],   [qdd   ]   [Q    ]
     [Phi_q, 0      ]] . [lambda] = [gamma],   gamma = -(Phi_q qd)_q qd

Sign convention of the multipliers: ``M qdd + Phi_q^T lambda = Q``.  The force
that the joints exert on the bodies is therefore ``-Phi_q^T lambda``.

Because ``M`` is diagonal (three rigid bodies in their centre-of-mass frames), eq. (11)
is solved at run time by block elimination (the range-space form)::

    S lambda = Phi_q M^-1 Q - gamma,   S = Phi_q M^-1 Phi_q^T   (8x8, symmetric positive definite)
    qdd = M^-1 (Q - Phi_q^T lambda)

and this module also derives those pieces, plus the rates of the dependent coordinates
for a given crank rate (``Phi_q qd = 0`` solved with ``th2_d = omega2``) and ``Phi_q qd``
itself (the velocity-level constraint, reported as part of the constraint residual).

Position analysis (the closed-form loop closure used for assembly and for coordinate
partitioning) is derived here too, so that every generated code path shares it: with the
crank tip ``A = L2 (cos th2, sin th2)`` at distance ``d`` from the rocker pivot
``O4 = (L1, 0)``, the coupler-rocker joint ``B`` lies at ``a`` along ``A -> O4`` and ``h``
across it, ``a = (L3^2 - L4^2 + d^2) / (2 d)``, ``h^2 = L3^2 - a^2``; ``branch = +1`` puts B
to the left of ``A -> O4`` (Table 1's assembly, the rocker tip above the ground line).  The
loop closes only where ``h^2 > 0``; the run-time code checks that before taking the root.
The link centres then follow from ``Phi = 0``, which is linear in them.

``M`` and ``Q`` come from the Lagrangian ``L = T - V`` (eq. 1) through
Lagrange's equations (eq. 2/10):
``M = d2L/dqd2`` and ``Q = dL/dq - (d2L/dqd dq) qd``.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import sympy as sp

__all__ = ["FourBarEquations", "derive_equations", "COORDINATES", "PARAMETERS", "INDEPENDENT"]

#: Names of the generalized coordinates, in state order.
COORDINATES = ("x2", "y2", "th2", "x3", "y3", "th3", "x4", "y4", "th4")
#: Names of the model parameters, in the order the generated code takes them.
PARAMETERS = ("L1", "L2", "L3", "L4", "m2", "m3", "m4", "g")
#: The independent coordinate of the coordinate partitioning (the crank angle).
INDEPENDENT = "th2"


@dataclass(frozen=True)
class FourBarEquations:
    """Symbolic pieces of the DAE, all as sympy matrices / expressions."""

    q: sp.Matrix          # 9x1 generalized coordinates
    qd: sp.Matrix         # 9x1 generalized velocities
    params: tuple         # sympy symbols, ordered as PARAMETERS
    mass_matrix: sp.Matrix        # 9x9, M
    forces: sp.Matrix             # 9x1, Q
    constraints: sp.Matrix        # 8x1, Phi
    jacobian: sp.Matrix           # 8x9, Phi_q
    gamma: sp.Matrix              # 8x1, -(Phi_q qd)_q qd
    kinetic_energy: sp.Expr
    potential_energy: sp.Expr
    multipliers: sp.Matrix        # 8x1 symbols lambda_0..lambda_7
    schur_matrix: sp.Matrix       # 8x8, S = Phi_q M^-1 Phi_q^T
    schur_rhs: sp.Matrix          # 8x1, Phi_q M^-1 Q - gamma
    accelerations: sp.Matrix      # 9x1, qdd = M^-1 (Q - Phi_q^T lambda), in terms of lambda
    omega: sp.Symbol              # rate of the independent coordinate
    velocities: sp.Matrix         # 9x1, qd solving Phi_q qd = 0 with qd[INDEPENDENT] = omega
    velocity_constraints: sp.Matrix   # 8x1, Phi_q qd
    closure_symbols: tuple        # (d, a, h, branch): intermediate symbols of the loop closure
    closure_reach: sp.Matrix      # 3x1, (d, a, h^2) as functions of th2 and the parameters only
    closure_angles: sp.Matrix     # 2x1, (th3, th4) as functions of th2, d, a, h, branch, parameters
    positions: sp.Matrix          # 9x1, q as a function of (th2, th3, th4) and the parameters
    branch_indicator: sp.Expr     # >= 0 on branch +1, < 0 on branch -1 (a function of q)


@functools.lru_cache(maxsize=None)
def derive_equations() -> FourBarEquations:
    """Derive ``M``, ``Q``, ``Phi``, ``Phi_q`` and ``gamma`` for the four-bar.

    Returns
    -------
    FourBarEquations
        Symbolic matrices; see the module docstring for the equation form and the
        sign convention of the Lagrange multipliers.  The result is cached (the
        derivation takes a few seconds): treat it as read-only.
    """
    q = sp.Matrix(sp.symbols(" ".join(COORDINATES), real=True))
    qd = sp.Matrix(sp.symbols(" ".join(n + "_d" for n in COORDINATES), real=True))
    L1, L2, L3, L4, m2, m3, m4, g = params = sp.symbols(" ".join(PARAMETERS), positive=True)
    x2, y2, th2, x3, y3, th3, x4, y4, th4 = q
    links = ((x2, y2, th2, m2, L2), (x3, y3, th3, m3, L3), (x4, y4, th4, m4, L4))

    # Lagrangian of three slender rods (eq. 1).
    T = sp.Integer(0)
    V = sp.Integer(0)
    for x, y, th, m, L in links:
        xd, yd, thd = (qd[list(q).index(s)] for s in (x, y, th))
        T += sp.Rational(1, 2) * m * (xd**2 + yd**2) + sp.Rational(1, 2) * (m * L**2 / 12) * thd**2
        V += m * g * y
    lagrangian = T - V

    # Lagrange's equations (eq. 2/10): d/dt dL/dqd - dL/dq = Q_ext (+ constraint forces).
    dL_dqd = sp.Matrix([sp.diff(lagrangian, s) for s in qd])
    M = dL_dqd.jacobian(qd)
    Q = sp.Matrix([sp.diff(lagrangian, s) for s in q]) - dL_dqd.jacobian(q) * qd

    # Revolute joints: two scalar equations each.
    c, s = sp.cos, sp.sin
    Phi = sp.Matrix([
        x2 - L2 / 2 * c(th2),                                   # crank pinned at origin
        y2 - L2 / 2 * s(th2),
        (x2 + L2 / 2 * c(th2)) - (x3 - L3 / 2 * c(th3)),        # crank tip = coupler start
        (y2 + L2 / 2 * s(th2)) - (y3 - L3 / 2 * s(th3)),
        (x3 + L3 / 2 * c(th3)) - (x4 + L4 / 2 * c(th4)),        # coupler end = rocker tip
        (y3 + L3 / 2 * s(th3)) - (y4 + L4 / 2 * s(th4)),
        (x4 - L4 / 2 * c(th4)) - L1,                            # rocker pinned at (L1, 0)
        (y4 - L4 / 2 * s(th4)),
    ])
    Phi_q = Phi.jacobian(q)
    gamma = sp.simplify(-(Phi_q * qd).jacobian(q) * qd)
    M, Q = sp.simplify(M), sp.simplify(Q)

    # Block elimination of eq. (11); needs the diagonal M of rigid bodies.
    if not M.is_diagonal():
        raise ValueError("the range-space solution of eq. (11) assumes a diagonal mass matrix")
    M_inv = sp.diag(*[1 / M[i, i] for i in range(M.rows)])
    lam = sp.Matrix(sp.symbols(f"lambda_0:{Phi.rows}", real=True))
    S = (Phi_q * M_inv * Phi_q.T).applyfunc(sp.cancel)
    r = (Phi_q * M_inv * Q - gamma).applyfunc(sp.cancel)
    qdd = M_inv * (Q - Phi_q.T * lam)

    # Coordinate partitioning: rates of the dependent coordinates from Phi_q qd = 0.
    i = COORDINATES.index(INDEPENDENT)
    dependent = [k for k in range(len(COORDINATES)) if k != i]
    omega = sp.Symbol("omega", real=True)
    qd_dep = Phi_q.extract(list(range(Phi.rows)), dependent).LUsolve(-Phi_q[:, i] * omega)
    rates = [omega if k == i else sp.cancel(qd_dep[dependent.index(k)]) for k in range(len(COORDINATES))]

    # Closed-form position analysis (see the module docstring).
    d_, a_, h_ = sp.symbols("d a h", positive=True)
    branch = sp.Symbol("branch", real=True)
    ax, ay = L2 * c(th2), L2 * s(th2)
    dx, dy = L1 - ax, -ay
    d_expr = sp.sqrt(dx**2 + dy**2)
    a_expr = (L3**2 - L4**2 + d_expr**2) / (2 * d_expr)
    reach = sp.Matrix([d_expr, a_expr, L3**2 - a_expr**2])
    bx = ax + a_ * dx / d_ - branch * h_ * dy / d_
    by = ay + a_ * dy / d_ + branch * h_ * dx / d_
    angles = sp.Matrix([sp.atan2(by - ay, bx - ax), sp.atan2(by, bx - L1)])
    centres = [x2, y2, x3, y3, x4, y4]
    # Ground-crank, crank-coupler and rocker-ground joints fix the centres for given angles;
    # the coupler-rocker joint is what the closure above satisfies.
    solved = sp.solve([Phi[k] for k in (0, 1, 2, 3, 6, 7)], centres, dict=True)
    if len(solved) != 1:
        raise ValueError("Phi = 0 should fix the link centres uniquely for given angles")
    positions = sp.Matrix([solved[0].get(k, k) for k in q])

    # Which side of A -> O4 the coupler-rocker joint B lies on: (O4 - A) x (B - A).
    indicator = (L1 - ax) * (L3 * s(th3)) - (0 - ay) * (L3 * c(th3))

    return FourBarEquations(
        q=q, qd=qd, params=tuple(params),
        mass_matrix=M, forces=Q,
        constraints=Phi, jacobian=Phi_q, gamma=gamma,
        kinetic_energy=T, potential_energy=V,
        multipliers=lam, schur_matrix=S, schur_rhs=r, accelerations=qdd,
        omega=omega, velocities=sp.Matrix(rates), velocity_constraints=Phi_q * qd,
        closure_symbols=(d_, a_, h_, branch), closure_reach=reach, closure_angles=angles,
        positions=positions, branch_indicator=indicator,
    )

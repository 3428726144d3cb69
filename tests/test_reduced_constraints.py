"""The native FMU's reduced constraints (fmu_src/c_reduction.py) against the derivation's own
Phi, Phi_q, nu and gamma, for every shipped mechanism.

The native right-hand side solves Newton-Raphson for the Schur complement's coordinates z only,
fills the other dependent coordinates in from closed forms, and takes rates and accelerations
from the reduced derivatives (dae.c: reduced_positions, reduced_rates, reduced_accelerations).
Here every piece is evaluated at random points and checked against the full Cartesian system
it replaces: a sign slip, a missing chain-rule term or a wrong row would show at the first
point.  (That the FMU then agrees with MechanismDAE is tests/test_fmu_native.py's.)
"""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from fmu_src.c_codegen import declared_reduction
from fmu_src.mechanism.check import prepare_mechanism, start_state
from fmu_src.mechanism.description import shipped_mechanisms

#: Random points per mechanism.
POINTS = 20
#: Every comparison is of one double-precision evaluation of a few dozen terms against another
#: of the same quantities (sizes of order the links, 1-5 m, and their rates): round-off is
#: ~1e-15 of that; 1e-10 relative leaves room for ill-conditioned points (the Schur complement
#: is solved with S) and is still far below any term that is missing or of the wrong sign.
TOL = 1e-10


@pytest.fixture(scope="module", params=shipped_mechanisms())
def case(request):
    checked = prepare_mechanism(request.param)
    eqs = checked.equations
    red = declared_reduction(eqs)
    _, _, p = start_state(checked.module)
    values = dict(zip(eqs.params, p))
    by_name = {symbol.name: value for symbol, value in values.items()}
    for k, driver in enumerate(eqs.mechanism.drivers):      # d = (s_ref, t_ref, v) per driver (dae_drive_at)
        s_ref, t_ref, speed = eqs.drive[3 * k:3 * k + 3]
        values |= {s_ref: by_name[driver.start], t_ref: 0.0, speed: by_name[driver.speed]}
    return request.param, eqs, red, values


def _numeric(expr, symbols, values):
    """A sympy matrix or expression evaluated at {symbol: value}."""
    return np.array(sp.Matrix(expr).xreplace({s: values[s] for s in symbols if s in values}).evalf(),
                    dtype=float)


def test_every_shipped_mechanism_has_a_reduction(case):
    """Else the native FMU would silently keep the full system for it."""
    name, eqs, red, _ = case
    assert red is not None, name
    assert len(red.z) + len(red.eliminated) == eqs.m
    assert set(red.z) | set(red.eliminated) | set(eqs.independent) == set(range(eqs.n))


def test_closed_forms_rates_and_accelerations_satisfy_the_full_system(case):
    """At random z, independent coordinates, rates, accelerations and time: the closed forms
    satisfy their rows of Phi = 0, Phi_q qd = nu and Phi_q qdd = gamma exactly (to round-off), and
    what is left of each is the reduced residual, S zd + B qd_i + r_t and S zdd + B qdd_i + gamma_r;
    S is the Schur complement of Phi_q's dependent block over the closed forms' rows and columns."""
    name, eqs, red, values = case
    rng = np.random.default_rng(24)
    q, qd, t = list(eqs.q), list(eqs.qd), eqs.t
    qdd = [sp.Symbol(f"qdd_{c}", real=True) for c in eqs.coordinates]
    z, e, ind = list(red.z), list(red.eliminated), list(eqs.independent)
    pivot_rows = [r for r in range(eqs.m) if r not in red.rows]
    rows = list(red.rows)
    # what the closed forms and the reduced pieces are functions of
    fns = {
        "closed": sp.lambdify([q, t, list(values)], list(red.closed_form)),
        "residual": sp.lambdify([q, t, list(values)], list(red.residual)),
        "S": sp.lambdify([q, t, list(values)], red.S),
        "B": sp.lambdify([q, t, list(values)], red.B),
        "r_t": sp.lambdify([q, t, list(values)], list(red.r_t)),
        "gamma_r": sp.lambdify([q, qd, t, list(values)], list(red.gamma)),
        "rates": sp.lambdify([q, qd, t, list(values)], list(red.G_z * sp.Matrix(len(z), 1, [qd[i] for i in z])
                                                            + red.G_i * sp.Matrix(len(ind), 1, [qd[i] for i in ind])
                                                            + red.g_t) if e else []),
        "acc": sp.lambdify([q, qd, qdd, t, list(values)],
                           list(red.G_z * sp.Matrix(len(z), 1, [qdd[i] for i in z])
                                + red.G_i * sp.Matrix(len(ind), 1, [qdd[i] for i in ind]) + red.kappa) if e else []),
        "phi": sp.lambdify([q, t, list(values)], list(eqs.constraints)),
        "J": sp.lambdify([q, list(values)], eqs.jacobian),
        "nu": sp.lambdify([t, list(values)], list(eqs.nu)),
        "gamma": sp.lambdify([q, qd, t, list(values)], list(eqs.gamma)),
    }
    p = list(values.values())
    for _ in range(POINTS):
        qv = rng.uniform(-np.pi, np.pi, eqs.n)
        qdv = rng.uniform(-5.0, 5.0, eqs.n)
        qddv = rng.uniform(-20.0, 20.0, eqs.n)
        tv = float(rng.uniform(0.0, 10.0))
        qv[e] = fns["closed"](qv, tv, p)
        phi = np.array(fns["phi"](qv, tv, p))
        scale = max(1.0, np.abs(qv).max())
        assert np.abs(phi[pivot_rows]).max(initial=0.0) <= TOL * scale, (name, phi[pivot_rows])
        assert np.allclose(phi[rows], fns["residual"](qv, tv, p), rtol=TOL, atol=TOL * scale), name
        J = np.array(fns["J"](qv, p), dtype=float)
        dep = [i for i in range(eqs.n) if i not in ind]
        A = J[np.ix_(pivot_rows, e)]
        schur = J[np.ix_(rows, z)] - J[np.ix_(rows, e)] @ np.linalg.solve(A, J[np.ix_(pivot_rows, z)])
        S = np.array(fns["S"](qv, tv, p), dtype=float).reshape(len(z), len(z))
        assert np.allclose(S, schur, rtol=TOL, atol=TOL * scale), (name, S, schur)
        assert len(dep) == eqs.m
        # rates
        qdv[e] = fns["rates"](qv, qdv, tv, p)
        nu = np.array(fns["nu"](tv, p), dtype=float)
        left = J @ qdv - nu
        rate_scale = scale * max(1.0, np.abs(qdv).max())
        assert np.abs(left[pivot_rows]).max(initial=0.0) <= TOL * rate_scale, (name, left[pivot_rows])
        B = np.array(fns["B"](qv, tv, p), dtype=float).reshape(len(z), len(ind))
        reduced = S @ qdv[z] + B @ qdv[ind] + np.array(fns["r_t"](qv, tv, p), dtype=float)
        assert np.allclose(left[rows], reduced, rtol=TOL, atol=TOL * rate_scale), name
        # accelerations
        qddv[e] = fns["acc"](qv, qdv, qddv, tv, p)
        gamma = np.array(fns["gamma"](qv, qdv, tv, p), dtype=float)
        left = J @ qddv - gamma
        acc_scale = rate_scale * max(1.0, np.abs(qdv).max(), np.abs(qddv).max())
        assert np.abs(left[pivot_rows]).max(initial=0.0) <= TOL * acc_scale, (name, left[pivot_rows])
        reduced = S @ qddv[z] + B @ qddv[ind] + np.array(fns["gamma_r"](qv, qdv, tv, p), dtype=float)
        assert np.allclose(left[rows], reduced, rtol=TOL, atol=TOL * acc_scale), name


# -- the loop closures in closed form (fmu_src/c_loops.py) ----------------------------------------
def _stages(eqs, red):
    from fmu_src.c_loops import closed_stages
    angles = [i for i, name in enumerate(eqs.coordinates) if name.startswith("theta")]
    return closed_stages(red.residual, red.z, eqs.q, angles)


def test_every_shipped_mechanisms_loops_are_solved_in_closed_form_and_the_forms_are_its_rows(case):
    """Each stage's form is its rows exactly (symbolically): a dyad's rows (x, sign * y) are
    R(a) u + R(b) w + c, a single row alpha cos(a) + beta sin(a) + gamma; the stages solve every
    row and every z once, each in unknowns no earlier stage solves, and their coefficients read
    only what earlier stages and the independent coordinates give."""
    name, eqs, red, _ = case
    if not red.z:       # no closed loop (a pendulum): every dependent coordinate has a closed form
        assert len(red.residual) == 0, name
        return
    stages = _stages(eqs, red)
    assert stages is not None, f"{name}: the native FMU would run Newton-Raphson at every evaluation"
    z = [eqs.q[i] for i in red.z]
    assert sorted(r for st in stages for r in st.rows) == list(range(len(red.residual)))
    assert sorted(k for st in stages for k in st.unknowns) == list(range(len(z)))
    solved: set = set()
    for st in stages:
        later = {z[k] for k in range(len(z)) if k not in solved and k not in st.unknowns}
        assert not set().union(*(sp.sympify(c).free_symbols for c in st.coefficients)) & (later | {z[k] for k in st.unknowns})
        a = z[st.unknowns[0]]
        if st.is_dyad:
            b = z[st.unknowns[1]]
            ux, uy, wx, wy, cx, cy = st.coefficients
            form_x = ux * sp.cos(a) - uy * sp.sin(a) + wx * sp.cos(b) - wy * sp.sin(b) + cx
            form_y = uy * sp.cos(a) + ux * sp.sin(a) + wy * sp.cos(b) + wx * sp.sin(b) + cy
            assert sp.simplify(red.residual[st.rows[0]] - form_x) == 0, name
            assert sp.simplify(st.sign * red.residual[st.rows[1]] - form_y) == 0, name
        else:
            alpha, beta, gamma = st.coefficients
            assert sp.simplify(red.residual[st.rows[0]] - (alpha * sp.cos(a) + beta * sp.sin(a) + gamma)) == 0, name
        solved.update(st.unknowns)


def test_loops_of_another_shape_are_left_to_newton_raphson():
    """Three unknown angles in one loop, a loop that is not two rotations (a length times cos of
    one angle against another length times sin), a slider among the unknowns: no closed form."""
    from fmu_src.c_loops import closed_stages
    a, b, c, s = sp.symbols("theta_a theta_b theta_c s_x", real=True)
    L = sp.Symbol("L", positive=True)
    q = [a, b, c, s]
    three = [sp.cos(a) + sp.cos(b) + sp.cos(c) - 1, sp.sin(a) + sp.sin(b) + sp.sin(c)]
    assert closed_stages(three, [0, 1, 2], q, [0, 1, 2]) is None
    skewed = [L * sp.cos(a) + sp.cos(b) - 1, 2 * L * sp.sin(a) + sp.sin(b)]
    assert closed_stages(skewed, [0, 1], q, [0, 1, 2]) is None
    slider = [L * sp.cos(a) - s, L * sp.sin(a) - 1]
    assert closed_stages(slider, [0, 3], q, [0, 1, 2]) is None
    # ... while the same loop as two rotations is one dyad, found with its rows in either order
    dyad = [L * sp.sin(a) - 2 * sp.sin(b) + 1, L * sp.cos(a) - 2 * sp.cos(b) - 3]
    (stage,) = closed_stages(dyad, [0, 1], q, [0, 1, 2])
    assert stage.is_dyad and stage.rows == (0, 1) and stage.sign == -1

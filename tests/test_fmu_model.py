"""The symbolic model and its generated code, checked without the FMU wrapper."""
from __future__ import annotations

import math
import types
import zipfile

import numpy as np
import pytest
import sympy as sp
from numpy.testing import assert_allclose

from fmu_src.codegen import generate_module
from fmu_src.derivation import COORDINATES, PARAMETERS, derive_equations
from fmu_src.fourbar_model.dae import FourBarDAE, assemble

P = (3.0, 1.0, 4.0, 2.5, 1.0, 1.0, 1.0, 9.81)


@pytest.fixture(scope="module")
def eqs():
    return derive_equations()


@pytest.fixture(scope="module")
def gen():
    module = types.ModuleType("fourbar_equations_under_test")
    exec(compile(generate_module(), "<generated>", "exec"), module.__dict__)
    return module


def random_states(n=5, seed=7):
    rng = np.random.default_rng(seed)
    return [(rng.normal(size=9), rng.normal(size=9)) for _ in range(n)]


def test_mass_matrix_is_rigid_rods(eqs):
    L2, L3, L4 = sp.symbols("L2 L3 L4", positive=True)
    m2, m3, m4 = sp.symbols("m2 m3 m4", positive=True)
    expected = sp.diag(m2, m2, m2 * L2**2 / 12, m3, m3, m3 * L3**2 / 12, m4, m4, m4 * L4**2 / 12)
    assert sp.simplify(eqs.mass_matrix - expected) == sp.zeros(9, 9)


def test_generated_code_matches_sympy(eqs, gen):
    symbols = list(eqs.q) + list(eqs.qd) + list(eqs.params)
    f = sp.lambdify(symbols, [eqs.constraints, eqs.jacobian, eqs.gamma, eqs.forces], "numpy")
    for q, qd in random_states():
        Phi, J, gamma, Q = (np.asarray(a, float) for a in f(*q, *qd, *P))
        # Same expressions evaluated two ways: agree to round-off.
        assert_allclose(gen.constraints(list(q), P), Phi.ravel(), rtol=0, atol=1e-12)
        assert_allclose(gen.jacobian(list(q), P), J, rtol=0, atol=1e-12)
        assert_allclose(gen.gamma(list(q), list(qd), P), gamma.ravel(), rtol=0, atol=1e-12)
        assert_allclose(gen.forces(list(q), list(qd), P), Q.ravel(), rtol=0, atol=1e-12)


def test_generated_range_space_pieces_match_sympy(eqs, gen):
    # S = Phi_q M^-1 Phi_q^T, its right-hand side, the rates and qdd(lambda): generated
    # code against the same symbolic expressions evaluated by lambdify.
    lam_sym = list(eqs.multipliers)
    symbols = list(eqs.q) + list(eqs.qd) + list(eqs.params) + lam_sym + [eqs.omega]
    f = sp.lambdify(symbols, [eqs.schur_matrix, eqs.schur_rhs, eqs.accelerations, eqs.velocities], "numpy")
    rng = np.random.default_rng(3)
    for q, qd in random_states():
        lam, omega = rng.normal(size=8), float(rng.normal())
        S, r, qdd, rates = (np.asarray(a, float) for a in f(*q, *qd, *P, *lam, omega))
        assert_allclose(gen.schur_matrix(list(q), P), S, rtol=0, atol=1e-12)
        filled = gen.schur_matrix([0.0] * 9, P)
        gen.schur_fill(filled, list(q), P)
        assert_allclose(np.tril(filled), np.tril(S), rtol=0, atol=1e-12)
        assert_allclose(gen.schur_rhs(list(q), list(qd), P), r.ravel(), rtol=0, atol=1e-12)
        assert_allclose(gen.accelerations(list(lam), list(q), list(qd), P), qdd.ravel(), rtol=0, atol=1e-12)
        assert gen.independent_acceleration(list(lam), list(q), list(qd), P) == pytest.approx(qdd.ravel()[2], abs=1e-12)
        assert_allclose(gen.velocities(list(q), omega, P), rates.ravel(), rtol=0, atol=1e-9)


def test_range_space_solve_agrees_with_the_full_augmented_system(gen):
    # The integrator solves eq. (11) by block elimination through S (8x8 Cholesky); the
    # reference solves the full 17x17 system by LU.  Both are exact up to round-off: the
    # tolerance is a few hundred ulps of the largest multiplier (~10 N).
    dae = FourBarDAE(gen, P)
    for theta2, omega2 in ((0.5, 0.0), (2.0, -3.0), (-2.9, 5.0), (4.0, 1.0)):
        q, qd = assemble(theta2, omega2, P, gen)
        qdd_ref, lam_ref = dae.accelerations(q, qd)
        lam = dae.multipliers(list(q), list(qd))
        assert_allclose(lam, lam_ref, rtol=0, atol=1e-12 * max(1.0, np.abs(lam_ref).max()) * 100)
        qdd = gen.accelerations(list(lam), list(q), list(qd), P)
        assert_allclose(qdd, qdd_ref, rtol=0, atol=1e-10)
        dae.start(0.0, q, qd)
        assert dae._rhs(0.0, np.array([theta2, omega2]))[1] == pytest.approx(qdd_ref[2], abs=1e-10)


def test_generated_rates_satisfy_the_velocity_constraint(gen):
    # qd from the symbolic solution of Phi_q qd = 0 (with th2_d = omega2), checked against
    # the numeric Jacobian; also at crank angles far from Table 1's start.
    for theta2 in np.linspace(-np.pi, np.pi, 13):
        q, qd = assemble(float(theta2), 1.7, P, gen)
        assert qd[2] == 1.7
        assert_allclose(gen.jacobian(list(q), P) @ qd, 0, atol=1e-13)
        assert gen.constraint_residual(list(q), list(qd), P) < 1e-13


def test_gamma_is_minus_time_derivative_of_jacobian_times_rates(gen):
    # gamma = -(Phi_q qd)_q qd = -(d/dt Phi_q) qd; check by central differences along qd.
    eps = 1e-6
    for q, qd in random_states():
        dJ = (gen.jacobian(list(q + eps * qd), P) - gen.jacobian(list(q - eps * qd), P)) / (2 * eps)
        assert_allclose(gen.gamma(list(q), list(qd), P), -dJ @ qd, rtol=0, atol=1e-7)


def test_lambda_sign_convention_ground_pushes_up(gen):
    # M qdd + Phi_q^T lambda = Q: joints act on the bodies with -Phi_q^T lambda.  At rest
    # under gravity the two ground pins (rows 1 and 7 carry y) must push up with less than
    # the total weight, and momentum balance must close: sum m ydd = R_y - sum m g.
    dae = FourBarDAE(gen, P)
    q, qd = assemble(math.radians(30), 0.0, P, gen)
    qdd, lam = dae.accelerations(q, qd)
    weight = sum(P[4:7]) * P[7]
    R_y = -(lam[1] + lam[7])
    R_x = -(lam[0] + lam[6])
    masses = np.array(P[4:7])
    assert 0.0 < R_y < weight
    assert sum(masses * qdd[[1, 4, 7]]) == pytest.approx(R_y - weight, abs=1e-12)
    assert sum(masses * qdd[[0, 3, 6]]) == pytest.approx(R_x, abs=1e-12)


def test_accelerations_satisfy_the_constraints(gen):
    dae = FourBarDAE(gen, P)
    q, qd = assemble(0.7, 2.0, P, gen)
    qdd, _ = dae.accelerations(q, qd)
    J = gen.jacobian(list(q), P)
    assert_allclose(J @ qdd, gen.gamma(list(q), list(qd), P), rtol=0, atol=1e-12)
    assert_allclose(J @ qd, 0, atol=1e-12)
    assert_allclose(gen.constraints(list(q), P), 0, atol=1e-14)


def test_fmu_ships_no_sympy_and_lists_requirements(fourbar_fmu):
    with zipfile.ZipFile(fourbar_fmu) as z:
        names = z.namelist()
        sources = {n: z.read(n).decode() for n in names if n.startswith("resources/fourbar") and n.endswith(".py")}
        requirements = z.read("resources/requirements.txt").decode().split()
    assert "resources/fourbar_model/equations.py" in names
    assert not any("sympy" in line for src in sources.values() for line in src.splitlines()
                   if line.strip().startswith(("import", "from"))), "the FMU must not import sympy"
    assert {r.split(">")[0].split("=")[0] for r in requirements} == {"numpy", "scipy"}


def test_fmu_is_valid_with_units_and_default_experiment(fourbar_fmu):
    from fmpy import read_model_description
    from fmpy.validation import validate_fmu
    assert validate_fmu(str(fourbar_fmu)) == []
    md = read_model_description(str(fourbar_fmu))
    de = md.defaultExperiment
    assert (float(de.startTime), float(de.stopTime), float(de.stepSize), float(de.tolerance)) == (0, 100, 0.01, 1e-9)
    v = {sv.name: sv for sv in md.modelVariables}
    for name in ("L1", "L2", "L3", "L4", "m2", "m3", "m4", "g"):
        assert (v[name].causality, v[name].variability) == ("parameter", "tunable")
    for name in ("theta2_start", "omega2_start", "rtol", "atol"):
        assert (v[name].causality, v[name].variability) == ("parameter", "fixed")
    for name in ("x2", "y2", "x3", "y3", "x4", "y4", "theta2", "theta3", "theta4",
                 "omega2", "omega3", "omega4", "energy", "constraint_residual"):
        assert v[name].causality == "output"
    assert v["L2"].unit == "m" and v["energy"].unit == "J" and v["theta3"].unit == "rad"
    assert float(v["theta2_start"].start) == pytest.approx(math.radians(30), abs=1e-15)

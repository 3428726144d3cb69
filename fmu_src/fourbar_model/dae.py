"""Integration of the four-bar's Lagrange-multiplier DAE (numpy and scipy only).

Coordinates ``q = [x2, y2, th2, x3, y3, th3, x4, y4, th4]`` (link centres and
angles), parameters ``p = (L1, L2, L3, L4, m2, m3, m4, g)``.

At every right-hand-side evaluation the paper's eq. (11)::

    [[M,     Phi_q^T],   [qdd   ]   [Q    ]
     [Phi_q, 0      ]] . [lambda] = [gamma]

is solved for the accelerations and the multipliers, with ``M qdd + Phi_q^T lambda = Q``:
the joints act on the bodies with ``-Phi_q^T lambda``.  ``M`` of three rigid bodies is
diagonal, so the solve is done by block elimination (the range-space form)::

    (Phi_q M^-1 Phi_q^T) lambda = Phi_q M^-1 Q - gamma,   qdd = M^-1 (Q - Phi_q^T lambda)

with the 8x8 symmetric positive definite matrix factorised by LAPACK (``dposv``).  All
the pieces (``S``, its right-hand side, ``qdd(lambda)``) are generated from the sympy
derivation.  ``FourBarDAE.accelerations`` solves the full 17x17 system with ``dgesv``
instead; the tests check that the two agree.

Constraint stabilisation is by generalized-coordinate partitioning (Wehage and
Haug): the explicit Runge-Kutta method integrates only the independent pair
``y = [th2, omega2]``; the eight dependent coordinates are recovered from
``Phi(q) = 0`` (closed-form loop closure on a fixed assembly branch) and their
rates from ``Phi_q qd = 0`` (solved symbolically at build time) whenever the state is
needed.  This is projection onto the constraint manifold carried to its limit: every
reported state satisfies ``Phi = 0`` and ``Phi_q qd = 0`` to round-off, the integrator
never drifts off the manifold, and it is never restarted unless a parameter changes.

Speed: the FMU spends its time in Python, so the right-hand side is a handful of
scalar generated functions and one LAPACK call, and states are kept as lists of floats.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.integrate import DOP853, RK45
from scipy.linalg import lapack

__all__ = ["AssemblyError", "IntegrationError", "FourBarDAE", "assemble", "branch_of", "snap_time",
           "INTEGRATORS", "BRANCH_OPEN", "TIME_RESOLUTION"]

#: Explicit Runge-Kutta methods that may be selected (scipy classes).
INTEGRATORS = {"DOP853": DOP853, "RK45": RK45}

#: Assembly branch of Table 1 (theta3 = 20.71 deg, theta4 = 49.98 deg at theta2 = 30 deg):
#: the coupler-rocker joint lies to the left of the line from the crank tip to the rocker
#: pivot, which puts the rocker tip above the ground line.  The other branch is -1.
BRANCH_OPEN = 1.0

#: Time resolution of the FMU: 1 ns.  Communication times are snapped to whole
#: nanoseconds, so masters that compute the same grid differently (FMPy: n*h; libcosim:
#: integer nanoseconds) drive exactly the same arithmetic.  Without it a one-ulp difference
#: at a re-assembly changes the Runge-Kutta step sequence, and at Table 1's atol = 1e-6
#: the trajectories then differ by up to the global error (~3e-3 m was measured).
TIME_RESOLUTION = 1e-9
_TICKS = 1e9    # 1 / TIME_RESOLUTION, exactly: t * _TICKS is the arithmetic the native FMU does too


def snap_time(t):
    """``t`` (s, float or array) rounded to whole ``TIME_RESOLUTION`` ticks, in one canonical form."""
    if isinstance(t, float):
        return round(t * _TICKS) / _TICKS
    return np.round(np.asarray(t) * _TICKS) / _TICKS if np.ndim(t) else round(float(t) * _TICKS) / _TICKS


class AssemblyError(ValueError):
    """The linkage cannot be closed with the given lengths at the given crank angle."""


class IntegrationError(RuntimeError):
    """The Runge-Kutta integration failed (step size collapse, singular system...)."""


def _positions(theta2: float, p, branch: float, eq) -> list[float]:
    """Closed-form position analysis: q (list of 9) for a crank angle (rad) on a branch.

    The closure is generated from the derivation (``closure_reach``, ``closure_angles``,
    ``positions``).  Raises AssemblyError, naming the lengths, when the loop cannot be
    closed or is at a toggle position (coupler and rocker aligned: Phi_q is singular).
    """
    try:
        d, a, h2 = eq.closure_reach(theta2, p)
    except ZeroDivisionError:          # the crank tip on the rocker pivot: never closable
        d, a, h2 = 0.0, math.inf, -math.inf
    L3 = p[2]
    if not h2 > 1e-18 * L3 * L3:
        L1, L2, L4 = p[0], p[1], p[3]
        reach = f"between {abs(L3 - L4):.6g} m and {L3 + L4:.6g} m"
        why = ("cannot be closed" if not h2 >= 0.0 else "is at a toggle (singular) position")
        raise AssemblyError(
            f"the loop {why}: the crank tip is {d:.6g} m from the rocker pivot at theta2 = "
            f"{math.degrees(theta2):.6g} deg, but coupler L3 = {L3:g} m and rocker L4 = {L4:g} m "
            f"can only span distances {reach} (L1 = {L1:g} m, L2 = {L2:g} m)")
    th3, th4 = eq.closure_angles(theta2, d, a, math.sqrt(h2), branch, p)
    return eq.positions(theta2, th3, th4, p)


def assemble(theta2: float, omega2: float, p, eq, branch: float = BRANCH_OPEN
             ) -> tuple[np.ndarray, np.ndarray]:
    """Consistent (q, qd) arrays for a crank angle (rad) and crank rate (rad/s) on a branch."""
    q = _positions(theta2, p, branch, eq)
    return np.array(q), np.array(_rates(eq, q, omega2, p))


def _rates(eq, q, omega2, p) -> list:
    """qd from Phi_q qd = 0 with th2_d = omega2 (generated closed form)."""
    try:
        return eq.velocities(q, omega2, p)
    except ZeroDivisionError:
        raise AssemblyError("the constraint Jacobian is singular: the linkage is at a toggle position") from None


def branch_of(q, p, eq) -> float:
    """The closure branch (+1 or -1) of a configuration, see ``BRANCH_OPEN``."""
    return 1.0 if eq.branch_indicator(list(q), p) >= 0.0 else -1.0


class FourBarDAE:
    """Explicit Runge-Kutta integration of the four-bar DAE, one communication step at a time.

    Parameters
    ----------
    eq : module
        The generated equations module (``mass_matrix``, ``forces``, ``jacobian``, ``gamma``...).
    p : tuple
        ``(L1, L2, L3, L4, m2, m3, m4, g)`` in m, kg and m/s^2.
    method : {"DOP853", "RK45"}
    rtol, atol : float
        Tolerances of the Runge-Kutta error control on ``[th2, omega2]`` (rad, rad/s).
    t_bound : float
        Time the integrator may not step beyond (the experiment's stop time), s.
    """

    def __init__(self, eq, p, method: str = "DOP853", rtol: float = 1e-10,
                 atol: float = 1e-10, t_bound: float = math.inf):
        if method not in INTEGRATORS:
            raise ValueError(f"integrator {method!r} is not one of {sorted(INTEGRATORS)}")
        self.eq = eq
        self.method = method
        self.rtol = rtol
        self.atol = atol
        self.t_bound = t_bound
        self.rhs_evaluations = 0
        self.starts = 0
        self._solver = None
        self._dense = None
        self._set_parameters(p)

    def _set_parameters(self, p) -> None:
        self.p = tuple(float(v) for v in p)
        n, m = self.eq.N_COORDINATES, self.eq.N_CONSTRAINTS
        zeros = [0.0] * n
        # S = Phi_q M^-1 Phi_q^T with its constant entries in place; schur_fill updates the others.
        self._S = np.asfortranarray(self.eq.schur_matrix(zeros, self.p))
        self._S_flat = self._S.reshape(-1, order="F")     # a view: entry (i, j) at i + 8 j
        # For the full augmented system of ``accelerations``.
        self._A = np.zeros((n + m, n + m), order="F")
        self._A[:n, :n] = self.eq.mass_matrix(zeros, self.p)
        self._n = n

    # -- the DAE -----------------------------------------------------------------
    def state(self, theta2: float, omega2: float) -> tuple[list, list]:
        """Full consistent (q, qd), as lists of floats, for the independent pair on the current branch."""
        q = _positions(theta2, self.p, self.branch, self.eq)
        return q, _rates(self.eq, q, omega2, self.p)

    def accelerations(self, q, qd) -> tuple[np.ndarray, np.ndarray]:
        """Solve the full 17x17 eq. (11) for (qdd, lambda) at a consistent state (LAPACK dgesv).

        The reference for the range-space solve used while integrating (``multipliers``).
        """
        eq, p, A, n = self.eq, self.p, self._A, self._n
        ql, qdl = list(q), list(qd)
        if not eq.MASS_IS_CONSTANT:
            A[:n, :n] = eq.mass_matrix(ql, p)
        J = eq.jacobian(ql, p)
        A[:n, n:] = J.T
        A[n:, :n] = J
        b = np.concatenate([eq.forces(ql, qdl, p), eq.gamma(ql, qdl, p)])
        lu, piv, x, info = lapack.dgesv(A, b)
        if info != 0:
            raise IntegrationError("the augmented matrix [[M, Phi_q^T], [Phi_q, 0]] is singular")
        return x[:n], x[n:]

    def multipliers(self, q, qd) -> np.ndarray:
        """lambda of eq. (11) at a consistent state, by the range-space solve (8x8 Cholesky)."""
        S = self._S
        self.eq.schur_fill(S, q, self.p)
        c, lam, info = lapack.dposv(S, self.eq.schur_rhs(q, qd, self.p), lower=1)
        if info != 0:
            raise IntegrationError("Phi_q M^-1 Phi_q^T is singular: the linkage is at a toggle position")
        return lam

    def _rhs(self, t: float, y: np.ndarray) -> np.ndarray:
        self.rhs_evaluations += 1
        theta2, omega2 = y.tolist()
        eq, p = self.eq, self.p
        q = _positions(theta2, p, self.branch, eq)
        qd, r = eq.rhs_terms(self._S_flat, q, omega2, p)      # fills S's lower triangle
        c, lam, info = lapack.dposv(self._S, r, lower=1)
        if info != 0:
            raise IntegrationError("Phi_q M^-1 Phi_q^T is singular: the linkage is at a toggle position")
        return np.array((omega2, eq.independent_acceleration(lam.tolist(), q, qd, p)))

    # -- time stepping -----------------------------------------------------------
    def start(self, t: float, q, qd, branch: float | None = None,
              first_step: float | None = None) -> None:
        """(Re)start the integrator at time t from a consistent state (q, qd)."""
        self.branch = branch_of(q, self.p, self.eq) if branch is None else branch
        self.t = float(t)
        self.q, self.qd = [float(v) for v in q], [float(v) for v in qd]
        self._dense = None
        kwargs = {} if first_step is None else {"first_step": first_step}
        self._solver = INTEGRATORS[self.method](
            self._rhs, self.t, np.array([self.q[self.eq.INDEPENDENT_INDEX], self.qd[self.eq.INDEPENDENT_INDEX]]), self.t_bound,
            rtol=self.rtol, atol=self.atol, **kwargs)
        self.starts += 1

    def advance(self, t_end: float) -> None:
        """Integrate to ``t_end`` (s) and store the consistent state in ``q``, ``qd``.

        The integrator keeps its own step size; communication points inside an accepted
        step are read from its dense output.  Masters step on a regular grid, so the
        points of the grid that fall inside the current step are interpolated together
        in one vectorised call and cached.
        """
        solver = self._solver
        eps = 1e-12 * max(1.0, abs(t_end))      # a step ending within round-off reaches t_end
        try:
            while solver.t < t_end - eps:
                message = solver.step()
                self._dense = None
                if solver.status == "failed":
                    raise IntegrationError(f"{self.method} failed at t = {solver.t:.9g} s: {message}")
            if abs(solver.t - t_end) <= eps:
                y = solver.y.tolist()
            else:
                y = self._interpolate(t_end)
            if not (math.isfinite(y[0]) and math.isfinite(y[1])):
                raise IntegrationError(f"{self.method} produced a non-finite state before t = {t_end:.9g} s")
            self.q, self.qd = self.state(y[0], y[1])
        except AssemblyError as exc:
            raise IntegrationError(f"at t = {t_end:.9g} s {exc}") from None
        self._last_step = t_end - self.t
        self.t = float(t_end)

    def _interpolate(self, t_end: float) -> list:
        """[th2, omega2] at t_end inside the last accepted step, from the dense output."""
        if self._dense is None:
            dense = self._solver.dense_output()
            table = {}
            dt = getattr(self, "_last_step", 0.0)
            if dt > 0.0:
                n = int((self._solver.t - t_end) / dt) + 1
                # Predicted grid, snapped like the master's times are (whole nanoseconds),
                # keyed by integer nanoseconds.
                grid = snap_time(t_end + dt * np.arange(n))
                keys = np.round(grid * _TICKS).astype(np.int64).tolist()
                table = dict(zip(keys, dense(grid).T.tolist()))
            self._dense = (dense, table)
        dense, table = self._dense
        y = table.get(round(t_end * _TICKS))
        return dense(t_end).tolist() if y is None else y

    def change_parameters(self, p) -> None:
        """Apply new lengths/masses at the current time by re-assembly keeping th2 and omega2.

        Raises AssemblyError (state unchanged) when the new geometry cannot be assembled.
        """
        p = tuple(float(v) for v in p)
        branch = branch_of(self.q, self.p, self.eq)
        i = self.eq.INDEPENDENT_INDEX
        q, qd = assemble(float(self.q[i]), float(self.qd[i]), p, self.eq, branch)
        self._set_parameters(p)
        step = getattr(self._solver, "h_abs", None)
        self.start(self.t, q, qd, branch=branch, first_step=step or None)

    # -- derived outputs ---------------------------------------------------------
    def energy(self) -> float:
        """Total mechanical energy T + V (J) of the current state."""
        T, V = self.eq.energy(self.q, self.qd, self.p)
        return T + V

    def constraint_residual(self) -> float:
        """max(|Phi(q)|_inf in m, |Phi_q qd|_inf in m/s) of the current state."""
        return self.eq.constraint_residual(self.q, self.qd, self.p)

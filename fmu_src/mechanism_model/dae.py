"""Integration of a mechanism's Lagrange-multiplier DAE (numpy and scipy only).

At every right-hand-side evaluation the paper's eq. (11)::

    [[M,     Phi_q^T],   [qdd   ]   [Q    ]
     [Phi_q, 0      ]] . [lambda] = [gamma]

is solved for the accelerations and the multipliers, with ``M qdd + Phi_q^T lambda = Q``: the
joints act on the bodies with ``-Phi_q^T lambda``.  ``M`` is diagonal (each body in its centre
of mass frame), so the solve is the range-space form::

    (Phi_q M^-1 Phi_q^T) lambda = Phi_q M^-1 Q - gamma,   qdd = M^-1 (Q - Phi_q^T lambda)

with the symmetric positive definite matrix factorised by LAPACK (``dposv``).

Constraint stabilisation is generalized-coordinate partitioning (Wehage and Haug): the
explicit Runge-Kutta method integrates the independent coordinates and their rates (plus each
driver's work); the dependent coordinates are recovered from ``Phi(q, t) = 0`` by
Newton-Raphson, started from the last accepted state moved along its velocity (so the assembly
branch is kept by continuity), and their rates from ``Phi_q qd = nu``.  Every reported state
satisfies both to round-off.  Newton-Raphson starts from the second-order Taylor predictor of the
last accepted Runge-Kutta state: it converges in one to three iterations, and on the branch the
motion is on (a stage of a rejected step never becomes a base).  When the independent coordinates
near a dead point (their velocity ratio, reviewed after every accepted Runge-Kutta step at its end,
passes REPARTITION_AWAY) others are chosen, from a column-pivoted QR factorization of ``Phi_q``, and
the integrator restarts; it returns to the declared ones below REPARTITION_RETURN.  A parameter
change keeps the declared coordinates and rates whatever the integrator uses (change_parameters).  A driven mechanism with no degree of freedom integrates only
its drivers' work: its positions come from the constraints alone.
"""
from __future__ import annotations

import math

import numpy as np
from scipy.integrate import DOP853, RK45
from scipy.linalg import lapack, qr

__all__ = ["AssemblyError", "IntegrationError", "MechanismDAE", "choose_partition", "snap_time", "INTEGRATORS",
           "TIME_RESOLUTION"]

#: Explicit Runge-Kutta methods that may be selected (scipy classes).
INTEGRATORS = {"DOP853": DOP853, "RK45": RK45}

#: Time resolution of the FMU: 1 ns.  Communication times are snapped to whole
#: nanoseconds, so masters that compute the same grid differently (FMPy: n*h; libcosim:
#: integer nanoseconds) drive exactly the same arithmetic.  Without it a one-ulp difference
#: at a re-assembly changes the Runge-Kutta step sequence, and at Table 1's atol = 1e-6
#: the trajectories then differ by up to the global error (~3e-3 m was measured).
TIME_RESOLUTION = 1e-9
_TICKS = 1e9    # 1 / TIME_RESOLUTION, exactly: t * _TICKS is the arithmetic the native FMU does too

#: Newton-Raphson stops once a correction is below NEWTON_STEP times (1 + |q|): convergence is
#: quadratic, so the error left is of the order of its square, far below round-off.
NEWTON_STEP = 1e-8
NEWTON_ITERATIONS = 25
#: The partition review measures how near the independent coordinates are to a dead point by
#: their *velocity ratio*: the largest rate of a dependent coordinate per unit rate of the
#: independent ones, ||diag(1/s_dep) Phi_d^-1 Phi_i diag(s_ind)||_inf, with s = 1 for an angle and
#: s = the mechanism's size (length_scale: the largest distance between two bodies' centres at
#: assembly) for a position, so that a position's rate counts as the angular rate that moves a
#: point at that distance as fast.  A kinematic quantity, independent of how the constraint rows
#: are scaled (unlike the LU pivot ratio reviewed before, which a mere change of size moved below
#: its threshold on a quick-return with no dead point at all): infinite exactly at a dead point
#: (the independent coordinates no longer fix the others); for a crank driving a rocker through a
#: coupler, about (crank / rocker) / sin(transmission angle).  Away from dead points it stays
#: near 1 (the shipped mechanisms' and tests/mechanisms' motions: at most about 1.1;
#: ``python benchmarks/fault_phase.py`` prints it).
#: The integrator leaves the declared ([start]) coordinates when their ratio exceeds
#: REPARTITION_AWAY: a dependent coordinate moving 5 times faster than the crank, a transmission
#: angle of about 12 degrees for a crank-rocker whose crank and rocker are equally long.  Not
#: lower: every motion of the shipped and test mechanisms stays below 1.1.  Not higher: the
#: Runge-Kutta error control acts on the independent coordinates only, so a dependent one's error
#: grows with the ratio; at 20 a generated four-bar swinging through a fold lost 1.6e-5 J over
#: 30 s, at 10 1.2e-4 J, at 5 under the 1e-5 J of tests/test_generated_cases.py ...
REPARTITION_AWAY = 5.0
#: ... and takes them back once it is below REPARTITION_RETURN (about 30 degrees there): hysteresis,
#: so a motion that lingers near the threshold does not flip back and forth.  Other coordinates
#: in use are left for the column-pivoted QR's choice when their own ratio exceeds REPARTITION_AWAY.
REPARTITION_RETURN = 2.0
#: A new choice is taken only when its velocity ratio is at least this many times smaller than
#: that of the coordinates in use (no change between two choices of similar quality).
REPARTITION_GAIN = 2.0
#: Sub-steps tried, in turn, to follow the branch from the last accepted state to a trial stage
#: the Taylor predictor does not reach (Newton-Raphson diverging from it).
CONTINUATION_STEPS = (2, 4, 8, 32)
#: Steps tried, in turn, to follow the branch to other parameters or start values (assemble,
#: change_parameters) when Newton-Raphson does not reach them directly.
FOLLOW_STEPS = (1, 8, 32, 128)
#: Restarts with other independent coordinates allowed within one communication step, when a
#: Runge-Kutta step fails because the dependent block went singular inside it.
RESCUES = 2


def snap_time(t):
    """``t`` (s, float or array) rounded to whole ``TIME_RESOLUTION`` ticks, in one canonical form."""
    if isinstance(t, float):
        return round(t * _TICKS) / _TICKS
    return np.round(np.asarray(t) * _TICKS) / _TICKS if np.ndim(t) else round(float(t) * _TICKS) / _TICKS


class AssemblyError(ValueError):
    """The mechanism cannot be assembled (Phi = 0 has no solution near the guess, or a toggle)."""


class IntegrationError(RuntimeError):
    """The Runge-Kutta integration failed (step size collapse, singular system...)."""


def _det_sign(lu: np.ndarray, piv: np.ndarray) -> int:
    """The sign of the determinant of an LU-factorized matrix (LAPACK's lu and 0-based piv)."""
    flips = int(np.count_nonzero(lu.diagonal() < 0.0)) + int(np.count_nonzero(piv != _RANGE[:piv.size]))
    return -1 if flips % 2 else 1


def _velocity_ratio(Jp: np.ndarray, m: int, scale: np.ndarray) -> float:
    """||diag(1/s_d) Phi_d^-1 Phi_i diag(s_i)||_inf for Phi_q with its dependent columns first
    (Jp, m x n) and each column's scale s (1 for an angle, the length scale for a position):
    the largest dependent rate per unit independent rate; inf where Phi_d is singular."""
    if Jp.shape[1] == m:
        return 0.0
    lu, piv, info = lapack.dgetrf(Jp[:, :m])
    if info != 0:
        return math.inf
    x, info = lapack.dgetrs(lu, piv, Jp[:, m:])
    ratio = float(np.max(np.sum(np.abs(x) * scale[m:], axis=1) / scale[:m]))
    return ratio if math.isfinite(ratio) else math.inf


def length_scale(coordinates, q) -> float:
    """The mechanism's size at q: the largest distance between two bodies' centres (x<label>,
    y<label>), 1 m for a mechanism with fewer than two moving centres (or all at one point)."""
    names = list(coordinates)
    centres = [(q[i], q[names.index("y" + name[1:])]) for i, name in enumerate(names)
               if name.startswith("x") and "y" + name[1:] in names]
    span = max((math.hypot(a[0] - b[0], a[1] - b[1]) for k, a in enumerate(centres) for b in centres[k + 1:]),
               default=0.0)
    return span if span > 0.0 else 1.0


_RANGE = np.arange(256)


def choose_partition(J: np.ndarray, n_independent: int) -> tuple[int, ...]:
    """The independent coordinates from a column-pivoted QR of Phi_q: the columns QR picks
    first form the best-conditioned dependent block; the rest are independent."""
    _, perm = qr(J, mode="r", pivoting=True)
    return tuple(sorted(int(i) for i in perm[J.shape[1] - n_independent:]))


class MechanismDAE:
    """Explicit Runge-Kutta integration of a mechanism's DAE, one communication step at a time.

    Parameters
    ----------
    eq : module
        The mechanism's generated equations module.
    p : sequence of float
        The parameters, in ``eq.PARAMETERS`` order.
    method : {"DOP853", "RK45"}
    rtol, atol : float
        Tolerances of the Runge-Kutta error control on the independent coordinates, their
        rates and the drivers' work.
    t_bound : float
        Time the integrator may not step beyond (the experiment's stop time), s.

    The Jacobian is kept with its columns permuted, dependent coordinates first (``_Jp``,
    Fortran order), so that the dependent block is a contiguous view; only its structurally
    nonzero entries are written.
    """

    def __init__(self, eq, p, method: str = "DOP853", rtol: float = 1e-10, atol: float = 1e-10,
                 t_bound: float = math.inf):
        if method not in INTEGRATORS:
            raise ValueError(f"integrator {method!r} is not one of {sorted(INTEGRATORS)}")
        self.eq, self.method, self.rtol, self.atol, self.t_bound = eq, method, rtol, atol, t_bound
        self.n, self.m = eq.N_COORDINATES, eq.N_CONSTRAINTS
        self.rhs_evaluations = 0
        self.failed_evaluations = 0
        self._cap = None        # during advance: (evaluation count not to pass, its message's words)
        self.starts = 0
        self.repartitions = 0
        self._solver = None
        self._dense = None
        self.p = tuple(float(v) for v in p)
        inputs = getattr(eq, "INPUTS", ())
        if inputs and len(self.p) == len(eq.PARAMETERS):      # the inputs at their start values
            start = {v.name: v.start for v in eq.VARIABLES}
            self.p += tuple(float(start[name]) for name in inputs)
        self.d = self.drive_at(0.0)
        self._input_poly = None     # (t0, [(index in p, u, u', u'')]): inputs that move within a step
        self.work = [0.0] * len(eq.DRIVERS)
        self.t, self.q, self.qd = 0.0, list(eq.GUESS), [0.0] * self.n
        self._Jp = np.zeros((self.m, self.n), order="F")
        self._Jp_flat = self._Jp.reshape(-1, order="F")        # a view: entry (i, k) at i + m k
        self._minv = None
        self._angle = np.array([c.startswith("theta") for c in eq.COORDINATES], dtype=bool)
        self._set_length_scale(1.0)
        self._set_partition(tuple(eq.INDEPENDENT))

    def __setstate__(self, state) -> None:
        """A copy (copy.deepcopy with the equations module in its memo) writes its own _Jp."""
        self.__dict__.update(state)
        self._Jp_flat = self._Jp.reshape(-1, order="F")

    # -- set-up -----------------------------------------------------------------------
    def _set_length_scale(self, length: float) -> None:
        """The velocity ratio's length (m): positions count in units of it (REPARTITION_AWAY)."""
        self.length_scale = float(length)
        self._scale = np.where(self._angle, 1.0, self.length_scale)

    def _set_partition(self, independent: tuple[int, ...]) -> None:
        self.independent = tuple(independent)
        self.dependent = tuple(i for i in range(self.n) if i not in self.independent)
        self._order = list(self.dependent + self.independent)       # column k of _Jp is q[_order[k]]
        column = {j: k for k, j in enumerate(self._order)}
        self._flat_index = np.array([i + self.m * column[j] for i, j in self.eq.JACOBIAN_ENTRIES], dtype=np.intp)
        self._Jp[:] = 0.0          # the structural zeros move with the columns
        self._minv = None

    def drive_at(self, t: float) -> list:
        """The drivers' (s_ref, t_ref, v) for a start at time t (s_ref = the start parameter)."""
        d = []
        for _, start, speed, _ in self.eq.DRIVERS:
            d += [self.p[start] if start >= 0 else 0.0, t, self.p[speed] if speed >= 0 else 0.0]   # -1: a function of t
        return d

    def assemble(self, t: float, guess, rates) -> None:
        """The consistent state at time t: q[INDEPENDENT] and qd[INDEPENDENT] from ``guess`` and
        ``rates`` (sequences of n), the dependent coordinates on the file's assembly branch.

        The file's guesses assemble the mechanism at its default parameters and start values
        (checked before the build).  From there the parameters and the independent coordinates
        move to the ones asked for along a straight path, in 1, 8, 32, then 128 steps, each
        solved by Newton-Raphson from the previous one on the same branch (the dependent block's
        determinant keeps its sign): so a start far from the file's (another crank angle,
        another geometry) lands on the branch the file means, not on whichever Newton-Raphson
        reaches from the guesses.  An angle may also be reached the other way round (+/- 2 pi).
        """
        target_p = self.p
        start = {v.name: v.start for v in self.eq.VARIABLES}
        p0 = tuple(float(start[name]) for name in self.eq.PARAMETERS + getattr(self.eq, "INPUTS", ()))
        base = list(self.eq.GUESS)
        for i, (position, _) in zip(self.independent, self.eq.START_PARAMETERS):
            base[i] = float(start[position])
        target = [float(guess[i]) for i in self.independent]
        try:
            self.p, self.d = p0, self.drive_at(t)
            q0 = self.positions(base, t)
            sign = self._sign if self.dependent else 1
        except AssemblyError:
            q0, sign = None, None
        finally:
            self.p = target_p
        q = None
        if q0 is not None:
            turns = [0.0] + ([2 * math.pi, -2 * math.pi] if any(self.eq.COORDINATES[i].startswith("theta")
                                                                 for i in self.independent) else [])
            for turn in turns:
                end = [v + (turn if self.eq.COORDINATES[i].startswith("theta") else 0.0)
                       for i, v in zip(self.independent, target)]
                q = self._follow(q0, p0, target_p, end, t, sign)
                if q is not None:
                    for i, v in zip(self.independent, target):
                        q[i] = v
                    self.d = self.drive_at(t)
                    q = self.positions(q, t)
                    break
        self.p, self.d = target_p, self.drive_at(t)
        if q is None:
            q = self.positions(guess, t)      # the guesses themselves (raises with the reason)
        qd = self.velocities([rates[i] for i in self.independent], t)
        self.t, self.q, self.qd = float(t), q, qd
        self._set_length_scale(length_scale(self.eq.COORDINATES, q))

    def _follow(self, q0, p0, p1, end, t: float, sign: int, anchor_drivers: bool = True) -> list | None:
        """q at parameters p1 and independent coordinates ``end`` by following the branch from
        q0 (at p0) in 1, 8, 32 or 128 equal steps; None when every try leaves the branch or fails.
        With ``anchor_drivers`` (assembly) the drivers sit at their start values at time t for
        each step's parameters; without (a change mid-run) they stay where self.d has them.
        Leaves self.p = p1."""
        start = [q0[i] for i in self.independent]
        for n in FOLLOW_STEPS:
            q = list(q0)
            try:
                for k in range(1, n + 1):
                    s = k / n
                    self.p = tuple(a + s * (b - a) for a, b in zip(p0, p1))
                    if anchor_drivers:
                        self.d = self.drive_at(t)
                    for i, a, b in zip(self.independent, start, end):
                        q[i] = a + s * (b - a)
                    q = self.positions(q, t)
                    if self.dependent and self._sign != sign:
                        raise AssemblyError("the other assembly branch")
                self.p = p1
                return q
            except AssemblyError:
                continue
        self.p = p1
        return None

    def worst_joint(self, phi) -> str:
        k = int(np.argmax(np.abs(phi)))
        return next((name for name, rows in self.eq.JOINT_ROWS.items() if k in rows), f"row {k}")

    def rank_problem(self) -> str | None:
        """Why the constraints at the current q are not independent, or None."""
        J = self.eq.jacobian(self.q, self.p)
        s = np.linalg.svd(J, compute_uv=False)
        if s.size and s.min() < 1e-9 * max(1.0, s.max()):
            # The rows that depend on earlier ones: QR of Phi_q^T with column pivoting.
            _, r, perm = qr(J.T, pivoting=True)
            rank = int(np.sum(np.abs(np.diag(r)) > 1e-9 * max(1.0, abs(r[0, 0]))))
            rows = sorted(int(k) for k in perm[rank:])
            names = sorted({name for name, rs in self.eq.JOINT_ROWS.items() if set(rs) & set(rows)})
            return (f"redundant constraints: rank {rank} of {J.shape[0]} constraint rows; joint(s) "
                    f"{', '.join(names)} repeat what the others already fix")
        return None

    # -- kinematics -------------------------------------------------------------------
    def _kinematics(self, q, t: float) -> list:
        """Phi at q (returned) and Phi_q at q (into _Jp)."""
        phi, entries = self.eq.kinematics(q, t, self.p, self.d)
        self._Jp_flat[self._flat_index] = entries
        return phi

    def positions(self, guess, t: float) -> list:
        """q with q[independent] from ``guess`` and Phi(q, t) = 0, by Newton-Raphson from ``guess``;
        on return _Jp holds Phi_q at q."""
        q = [float(v) for v in guess]
        dependent, m = self.dependent, self.m
        converged = False
        for _ in range(NEWTON_ITERATIONS + 1):
            try:
                phi = self._kinematics(q, t)
            except (ValueError, OverflowError):        # cos(inf): the iteration ran away
                raise AssemblyError("the loop cannot be closed: Newton-Raphson diverged") from None
            if converged:
                self._sign = _det_sign(lu, piv)     # of the last factorization: the branch of q
                return q
            lu, piv, dx, info = lapack.dgesv(self._Jp[:, :m], phi)
            if info != 0:
                raise AssemblyError("the constraint Jacobian is singular there (a toggle or dead-point "
                                    "configuration)")
            step = 0.0
            for i, dxi in zip(dependent, dx.tolist()):
                qi = q[i] - dxi
                q[i] = qi
                r = abs(dxi) / (1.0 + abs(qi))
                if not r <= step:
                    step = r
            if not math.isfinite(step):
                break
            converged = step <= NEWTON_STEP
        phi = self.eq.constraints(q, t, self.p, self.d)
        raise AssemblyError(f"the loop cannot be closed: Phi = 0 has no solution near the previous configuration "
                            f"(Newton-Raphson left a residual of {np.max(np.abs(phi)):.3g} in joint "
                            f"{self.worst_joint(phi)})")

    def velocities(self, qd_independent, t: float) -> list:
        """qd with qd[independent] given and Phi_q qd = nu (Phi_q from the last ``positions``)."""
        m = self.m
        qd = [0.0] * self.n
        for i, v in zip(self.independent, qd_independent):
            qd[i] = float(v)
        rhs = np.array(self.eq.nu(t, self.p, self.d)) if self.eq.DRIVERS else np.zeros(m)
        if self.independent:
            rhs -= self._Jp[:, m:] @ np.asarray(qd_independent, dtype=float)
        lu, piv, x, info = lapack.dgesv(self._Jp[:, :m], rhs)
        if info != 0:
            raise AssemblyError("the constraint Jacobian is singular: a toggle (dead-point) configuration")
        for i, v in zip(self.dependent, x.tolist()):
            qd[i] = v
        return qd

    # -- the DAE ----------------------------------------------------------------------
    def _mass_inverse(self, q) -> np.ndarray:
        """M^-1's diagonal in _Jp's column order."""
        if self._minv is None or not self.eq.MASS_IS_CONSTANT:
            self._minv = 1.0 / np.asarray(self.eq.mass_diagonal(q, self.p))[self._order]
        return self._minv

    def _solve_permuted(self, q, qd, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(qdd in _Jp's column order, lambda) of eq. (11), with _Jp at q: the range-space solve."""
        Jp = self._Jp
        minv = self._mass_inverse(q)
        Q, gamma = self.eq.dynamics(q, qd, t, self.p, self.d)
        Qp = np.array(Q)[self._order]
        JM = Jp * minv
        c, lam, info = lapack.dposv(JM @ Jp.T, JM @ Qp - np.array(gamma), lower=1)
        if info != 0:
            raise IntegrationError("Phi_q M^-1 Phi_q^T is singular: a toggle (dead-point) configuration")
        return minv * (Qp - Jp.T @ lam), lam

    def solve(self, q, qd, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(qdd, lambda) of eq. (11) at a consistent state (q, qd) at time t."""
        self._kinematics(q, t)
        qdd_p, lam = self._solve_permuted(q, qd, t)
        qdd = np.empty(self.n)
        qdd[self._order] = qdd_p
        return qdd, lam

    def _state(self, t: float, y) -> tuple[list, list]:
        """(q, qd) for the integrated y at time t, the dependent part by Newton-Raphson from the
        second-order Taylor predictor of the last accepted state (_Jp then holds Phi_q at q)."""
        k = len(self.independent)
        tb, qb, qdb, qddb, _ = self._base
        dt = t - tb
        half = 0.5 * dt * dt
        guess = [a + b * dt + c * half for a, b, c in zip(qb, qdb, qddb)]
        for j, i in enumerate(self.independent):
            guess[i] = y[j]
        try:
            q = self.positions(guess, t)
            if self._sign != self._base[4]:
                raise AssemblyError("Newton-Raphson reached the other assembly branch")
        except AssemblyError:
            q = self._continuation(y[:k], t)
        return q, self.velocities(y[k:2 * k], t)

    def _continuation(self, independent: list, t: float) -> list:
        """q at (independent, t) by following the assembly branch from the last accepted state:
        the independent coordinates and time moved there in 2, 4, ... 32 equal steps, each
        solved from the previous one, on the branch of the last accepted state (the sign of the
        dependent block's determinant: it changes only through a dead point).  For a trial step
        too long for the predictor (the integrator may try one ten times its last); raises
        AssemblyError when even 32 steps do not reach it (a dead point on the way)."""
        tb, qb, _, _, sign = self._base
        start = [qb[i] for i in self.independent]
        for n in CONTINUATION_STEPS:
            q = list(qb)
            try:
                for k in range(1, n + 1):
                    s = k / n
                    for i, a, b in zip(self.independent, start, independent):
                        q[i] = a + s * (b - a)
                    q = self.positions(q, tb + s * (t - tb))
                    if self._sign != sign:
                        raise AssemblyError("the other assembly branch")
                return q
            except AssemblyError:
                continue
        raise AssemblyError(f"Phi = 0 cannot be followed from t = {tb:.9g} s to {t:.9g} s: the loop cannot be "
                            f"closed on the way (a dead point)")

    def _rhs(self, t: float, y: np.ndarray) -> np.ndarray:
        self.rhs_evaluations += 1
        if self._cap is not None and self.rhs_evaluations > self._cap[0]:
            # the bound on one advance's work, checked here so that no loop inside a Runge-Kutta
            # step (its rejections) escapes it
            t_start, t_end, max_evaluations = self._cap[1]
            raise IntegrationError(
                f"the communication step from t = {t_start:.9g} s to {t_end:.9g} s needed more than "
                f"max_evaluations = {max_evaluations:.17g} right-hand-side evaluations; it reached "
                f"t = {self._solver.t:.9g} s (raise max_evaluations, a fixed parameter, to allow more work per "
                f"step, or shorten the step)")
        yl = y.tolist()
        if self._input_poly is not None:
            self._inputs_at(t)
        try:
            q, qd = self._state(t, yl)
        except AssemblyError:
            # A trial step too long for the predictor (Newton-Raphson diverges far from the last
            # accepted state) or one that crosses a dead point: an infinite derivative makes the
            # step's error infinite, so the integrator rejects it and tries a step 5x shorter.
            self.failed_evaluations += 1
            return np.full(y.shape, np.inf)
        qdd_p, lam = self._solve_permuted(q, qd, t)
        qdd = [0.0] * self.n
        for i, v in zip(self._order, qdd_p.tolist()):
            qdd[i] = v
        self._last_eval = (t, q, qd, qdd, self._sign)
        k = len(self.independent)
        out = yl[k:2 * k] + qdd_p[self.m:].tolist()
        if self.eq.DRIVERS:
            nu = self.eq.nu(t, self.p, self.d)
            # The driver's power: its constraint force -Phi_q^T lambda times qd, i.e. -lambda nu (row d).
            out += [-float(lam[row] * nu[row]) for _, _, _, row in self.eq.DRIVERS]
        return np.array(out)

    # -- time stepping ----------------------------------------------------------------
    def start(self, first_step: float | None = None) -> None:
        """(Re)start the integrator at self.t from the consistent state in self.q, self.qd."""
        self._dense = None
        qdd, _ = self.solve(self.q, self.qd, self.t)
        lu, piv, info = lapack.dgetrf(self._Jp[:, :self.m])       # _Jp at q (solve filled it)
        self._sign = _det_sign(lu, piv)
        self._base = self._last_eval = (self.t, self.q, self.qd, qdd.tolist(), self._sign)
        if first_step is not None and first_step > self.t_bound - self.t:
            first_step = None           # scipy refuses a first step past its bound: its own choice
        kwargs = {} if first_step is None else {"first_step": first_step}
        y0 = [self.q[i] for i in self.independent] + [self.qd[i] for i in self.independent] + list(self.work)
        self._solver = INTEGRATORS[self.method](self._rhs, self.t, np.array(y0, dtype=float), self.t_bound,
                                                rtol=self.rtol, atol=self.atol, **kwargs)
        self.starts += 1

    def advance(self, t_end: float, max_evaluations: float = math.inf) -> None:
        """Integrate to ``t_end`` (s) and store the consistent state in ``q``, ``qd``.

        The integrator keeps its own step size; communication points inside an accepted step
        are read from its dense output (the points of a regular grid that fall inside the
        current step are interpolated together in one vectorised call and cached).

        The bound on the work of one call: the right-hand-side evaluation that would pass
        ``max_evaluations`` (rejected attempts and restarts included) raises IntegrationError
        naming the cap and the time reached (dae.c's dae_advance does the same).
        """
        solver = self._solver
        eps = 1e-12 * max(1.0, abs(t_end))      # a step ending within round-off reaches t_end
        rescues = 0
        t_start = self.t
        self._cap = (self.rhs_evaluations + max_evaluations, (t_start, t_end, max_evaluations))
        pending = None          # other coordinates the review of a step past t_end chose
        try:
            while solver.t < t_end - eps:
                with np.errstate(invalid="ignore", over="ignore"):     # inf from a failed evaluation
                    message = solver.step()
                failed = solver.status == "failed"
                self._dense = None
                if not failed and self._last_eval[0] == solver.t:
                    # scipy evaluates f at the end of every attempted step before its error
                    # test: after an accepted step that is the accepted state, the base of the
                    # next predictions.  Stages of rejected attempts never become a base: near a
                    # dead point one of them may have landed on the other assembly branch.
                    self._base = self._last_eval
                    if self.independent and solver.t < t_end - eps:
                        if self._review_at_accepted(solver):
                            solver = self._solver
                            continue
                    elif self.independent:
                        # a step that reaches t_end or passes it: reviewed at its end too; other
                        # coordinates take over at t_end, from the reported state (the dense
                        # output of this step serves t_end first)
                        pending = self._better_partition(self._base[1])
                if failed:
                    # The step size collapsed: the dependent block goes singular ahead (a dead
                    # point between two communication points).  Once or twice per step, restart
                    # from the last reported state with the independent coordinates the QR
                    # factorization picks.
                    if rescues < RESCUES and self._repartition():
                        rescues += 1
                        solver = self._solver
                        continue
                    raise IntegrationError(f"{self.method} failed at t = {solver.t:.9g} s: {message}")
            y = solver.y.tolist() if abs(solver.t - t_end) <= eps else self._interpolate(t_end)
            if not all(math.isfinite(v) for v in y):
                raise IntegrationError(f"{self.method} produced a non-finite state before t = {t_end:.9g} s")
            if self._input_poly is not None:
                self._inputs_at(t_end)
            q, qd = self._state(t_end, y)
        except AssemblyError as exc:
            raise IntegrationError(f"at t = {t_end:.9g} s {exc}") from None
        finally:
            self._cap = None
        self._last_step = t_end - t_start
        self.t, self.q, self.qd = float(t_end), q, qd
        k = len(self.independent)
        self.work = y[2 * k:]
        if pending is not None:
            self._restart_with(pending)

    def _review_at_accepted(self, solver) -> bool:
        """After an accepted Runge-Kutta step that ends before the communication point (_Jp
        holds Phi_q at its state, the last one evaluated): when the dependent block degrades,
        restart there with the QR's independent coordinates if they are REPARTITION_GAIN times
        better conditioned.  Checked at every step, not only at communication points: a crank
        can go from a pivot ratio of 0.15 to its dead point within one 0.01 s step, and an
        integrator that reaches a dead point in the old coordinates stops there (its rate goes
        to zero while the mechanism moves on).  Nothing else is reviewed: a step's interior
        (where communication points are interpolated) lies between two reviewed states."""
        t, q, qd, _, _ = self._base
        independent = self._better_partition(q)
        if independent is None:
            return False
        k = len(self.independent)
        self.t, self.q, self.qd, self.work = t, list(q), list(qd), solver.y.tolist()[2 * k:]
        self._set_partition(independent)
        self.repartitions += 1
        self.start(first_step=getattr(solver, "h_abs", None) or None)
        return True

    def _better_partition(self, q) -> tuple[int, ...] | None:
        """Other independent coordinates at q (_Jp holds Phi_q at q), or None to keep the current
        ones.  The declared ([start]) coordinates are kept while their velocity ratio is at most
        REPARTITION_AWAY; other coordinates in use give way to the declared ones as soon as those
        are below REPARTITION_RETURN again (hysteresis), and to the column-pivoted QR's choice when
        their own ratio exceeds REPARTITION_AWAY and that choice's is REPARTITION_GAIN times smaller."""
        declared = tuple(self.eq.INDEPENDENT)
        J = None
        if set(self.independent) == set(declared):
            ratio = _velocity_ratio(self._Jp, self.m, self._scale[list(self._order)])
            if ratio <= REPARTITION_AWAY:
                return None
        else:
            J = self.eq.jacobian(q, self.p)
            if self.velocity_ratio(J, declared) < REPARTITION_RETURN:
                return declared
            ratio = _velocity_ratio(self._Jp, self.m, self._scale[list(self._order)])
            if ratio <= REPARTITION_AWAY:
                return None
        if J is None:
            J = self.eq.jacobian(q, self.p)
        independent = choose_partition(J, len(self.independent))
        if independent == self.independent:
            return None
        return independent if self.velocity_ratio(J, independent) * REPARTITION_GAIN < ratio else None

    def velocity_ratio(self, J: np.ndarray, independent) -> float:
        """The velocity ratio (REPARTITION_AWAY) of these independent coordinates where Phi_q is J:
        the largest rate of a dependent coordinate per unit rate of the independent ones, positions
        counted in units of length_scale; inf at their dead points."""
        order = [i for i in range(self.n) if i not in independent] + list(independent)
        return _velocity_ratio(np.asfortranarray(J[:, order]), self.m, self._scale[order])

    def _repartition(self) -> bool:
        """Restart at the last reported state with the QR's independent coordinates, when they
        differ from the current ones; False when they do not (nothing to try).  Not from the
        last accepted Runge-Kutta state: that one may be right at the dead point, where the old
        independent rates no longer determine the motion."""
        independent = choose_partition(self.eq.jacobian(self.q, self.p), len(self.independent))
        if not self.independent or independent == self.independent:
            return False
        self._set_partition(independent)
        self.repartitions += 1
        self.start(first_step=getattr(self._solver, "h_abs", None) or None)
        return True

    def _restart_with(self, independent) -> None:
        """Restart at the current (reported) state with these independent coordinates: the
        choice of the review of the step that passed it."""
        self._set_partition(independent)
        self._kinematics(self.q, self.t)
        self.repartitions += 1
        self.start(first_step=getattr(self._solver, "h_abs", None) or None)

    def _interpolate(self, t_end: float) -> list:
        """y at t_end inside the last accepted step, from the dense output."""
        if self._dense is None:
            dense = self._solver.dense_output()
            table = {}
            dt = getattr(self, "_last_step", 0.0)
            if dt > 0.0:
                n = int((self._solver.t - t_end) / dt) + 1
                # Predicted grid, snapped like the master's times are (whole nanoseconds).
                grid = snap_time(t_end + dt * np.arange(n))
                keys = np.round(grid * _TICKS).astype(np.int64).tolist()
                table = dict(zip(keys, dense(grid).T.tolist()))
            self._dense = (dense, table)
        dense, table = self._dense
        y = table.get(round(t_end * _TICKS))
        return dense(t_end).tolist() if y is None else y

    def change_parameters(self, p) -> None:
        """Apply new parameters at the current time: re-assembly keeping the declared ([start])
        coordinates and their rates, whatever coordinates the integrator uses at that time; a
        driver's speed change continues from where it is.  The integrator then goes on with the
        coordinates it used (its review returns to the declared ones where they are clear of dead
        points).  Only where the declared coordinates cannot carry the re-assembly (their
        dependent block is singular, or the loop does not close with them held: at or right next
        to one of their dead points) does it keep the coordinates the integrator uses instead.

        Raises AssemblyError (state unchanged) when the new parameters cannot be assembled.
        """
        old = (self.p, self.d, self.q, self.qd, self.t)
        used = self.independent
        declared = tuple(self.eq.INDEPENDENT)
        new_p = tuple(float(v) for v in p)
        d = []
        for k, (_, _, speed, _) in enumerate(self.eq.DRIVERS):
            s_ref, t_ref, v = self.d[3 * k:3 * k + 3]
            d += [s_ref + v * (self.t - t_ref), self.t, new_p[speed] if speed >= 0 else 0.0]
        try:
            try:
                if used != declared:
                    self._set_partition(declared)
                q, qd = self._reassembled(old[0], new_p, d)
            except AssemblyError:
                if used == declared:
                    raise
                self.p, self.d = old[0], old[1]
                self._set_partition(used)
                q, qd = self._reassembled(old[0], new_p, d)
        except AssemblyError:
            self.p, self.d, self.q, self.qd, self.t = old
            self._minv = None
            if self.independent != used:
                self._set_partition(used)
            raise
        if self.independent != used:
            self._set_partition(used)
        self.q, self.qd = q, qd
        self.start(first_step=getattr(self._solver, "h_abs", None) or None)

    def set_inputs(self, u) -> None:
        """New values of the FMI inputs (``eq.INPUTS`` order) from the current time t0 on: the
        dependent coordinates re-solved (a driver's input position moves them) and the integrator
        restarted, as for a parameter change (raises AssemblyError, state unchanged, likewise).
        Held, except a driver input's position and rate, which move on with its own rate and
        acceleration inputs (u + u_d (t - t0) + u_dd (t - t0)^2 / 2, u_d + u_dd (t - t0)): held,
        the position would contradict the rate."""
        k = len(self.eq.PARAMETERS)
        u = tuple(float(v) for v in u)
        moving = []
        for j in getattr(self.eq, "INPUT_DRIVERS", ()):
            if u[j + 1] or u[j + 2]:
                moving.append((k + j, u[j], u[j + 1], u[j + 2]))
            if u[j + 2]:
                moving.append((k + j + 1, u[j + 1], u[j + 2], 0.0))
        p = self.p[:k] + u
        if p != self.p or moving or self._input_poly is not None:
            self._input_poly = (self.t, moving) if moving else None
            self.change_parameters(p)

    def _inputs_at(self, t: float) -> None:
        """The inputs that move within the step (set_inputs) at time t, into p."""
        t0, moving = self._input_poly
        p = list(self.p)
        h = t - t0
        for i, a0, a1, a2 in moving:
            p[i] = a0 + h * (a1 + 0.5 * h * a2)
        self.p = tuple(p)

    def _reassembled(self, old_p, new_p, d) -> tuple[list, list]:
        """(q, qd) at the new parameters and drivers d keeping the current partition's independent
        coordinates and rates from self.q, self.qd, on the branch they are on (leaves self.p, self.d
        at the new ones)."""
        self.p, self.d, self._minv = new_p, d, None
        lu, piv, info = lapack.dgetrf(self.eq.jacobian(self.q, old_p)[:, list(self.dependent)])
        sign = _det_sign(lu, piv) if self.dependent else 1
        try:
            q = self.positions(self.q, self.t)
            if self.dependent and self._sign != sign:
                raise AssemblyError("the other assembly branch")
        except AssemblyError:
            # A large change: follow the branch from the old parameters to the new ones.
            self.d = d
            q = self._follow(self.q, old_p, new_p, [self.q[i] for i in self.independent], self.t, sign,
                             anchor_drivers=False)
            if q is None:
                self.positions(self.q, self.t)      # raises with Newton-Raphson's reason
                raise AssemblyError("the loop cannot be closed on the way to the new parameters")
            q = self.positions(q, self.t)
        return q, self.velocities([self.qd[i] for i in self.independent], self.t)

    # -- derived outputs --------------------------------------------------------------
    def energy(self) -> float:
        """T + V (J) of the current state."""
        T, V = self.eq.energy(self.q, self.qd, self.p)
        return T + V

    def constraint_residual(self) -> float:
        """max(|Phi|, |Phi_q qd - nu|) of the current state (m, rad, m/s, rad/s)."""
        return self._residual(self._kinematics(self.q, self.t))

    def _residual(self, phi) -> float:
        """The constraint residual from Phi at the current q (_Jp at q)."""
        velocity = self._Jp @ np.array(self.qd)[self._order]
        if self.eq.DRIVERS:
            velocity -= np.array(self.eq.nu(self.t, self.p, self.d))
        return max(max(map(abs, phi)), float(np.max(np.abs(velocity))))

    def outputs(self, forces: bool = True) -> list[float]:
        """Every output of the FMU, in output order; with ``forces=False`` the outputs that need
        the multipliers (joint reactions, drivers' torques) are None (see ``force_outputs``)."""
        eq = self.eq
        residual = self._residual(self._kinematics(self.q, self.t))
        states = iter(eq.state_outputs(self.q, self.qd, self.t, self.p, self.d))
        force = iter(self.force_outputs() if forces else ())
        works = iter(eq.OUTPUT_WORKS)
        out = []
        for kind in eq.OUTPUT_KINDS:
            if kind == "state":
                out.append(float(next(states)))
            elif kind == "force":
                out.append(float(next(force)) if forces else None)
            elif kind == "work":
                out.append(float(self.work[next(works)]))
            else:
                out.append(residual)
        return out

    def force_outputs(self) -> list[float]:
        """The outputs of kind "force", in output order: eq. (11)'s multipliers at the current
        state (one range-space solve), then the reactions and drivers' torques from them."""
        self._kinematics(self.q, self.t)
        _, lam = self._solve_permuted(self.q, self.qd, self.t)
        return self.eq.force_outputs(self.q, self.qd, lam.tolist(), self.t, self.p, self.d)

"""One hypothesis, fitted: "parameter ``p`` alone changed, to ``v``, at ``t_c``" (or over a ramp).

For a step, the change's grid point ``c`` is searched (a pattern search over whole grid
points, since the FMU applies a change only between two steps) and at each ``c`` the new
value is fitted by :func:`scipy.optimize.least_squares` on the scaled residuals of every
fitted row.  All hypotheses and all ``c`` are scored on the same rows (the healthy model
before ``c``, the branch after), so their chi-squares compare directly.

The new value is fitted as the relative change ``u = v / v0 - 1``; its standard error
comes from the Jacobian at the optimum, scaled by the fit's own residual variance
(``s^2 (J'J)^-1``), so it stays honest when the noise estimate is off.

A ramp is fitted as ``(u, t_mid, duration)``: the value moves linearly from ``v0`` to
``v`` over ``[t_mid - d/2, t_mid + d/2]``, set at each grid point as the orchestrator
sets a ramp; the residual is continuous in both times, so least squares handles them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares

from .simulator import BranchFailed, Simulator

__all__ = ["Fit", "Problem", "fit_ramp", "fit_step"]

#: Relative finite-difference step for the value: large enough that the output change
#: (about 1e-5 m for a unit sensitivity) stands far above the integrator's 1e-9 noise.
_DIFF_STEP = 1e-4
#: Scaled residual given to each row when the FMU refuses a value (e.g. a linkage that
#: cannot close): far worse than any real fit, so least squares steps back.
_REFUSED = 1e3
#: Grid-point strides of the change-time search, coarse to fine.
_STRIDES = (32, 8, 2, 1)


@dataclass(frozen=True)
class Fit:
    """The best fit of one hypothesis (times in s, values in the parameter's unit)."""

    parameter: str
    kind: str                    # "step" or "ramp"
    before: float                # the healthy value (run.json)
    value: float                 # the fitted new value
    stderr: float                # standard error of the value (step) or of the rate per second (ramp)
    change_time: float           # step: the grid time of the change; ramp: its start
    end_time: float              # step: = change_time; ramp: its end
    chi2: float                  # sum of squared scaled residuals over the fitted rows
    rows: int                    # fitted rows (each has one residual per column)
    rms: float                   # RMS of the unscaled residuals, in the columns' unit
    evaluations: int             # branches simulated for this fit
    refused: str | None = None   # the FMU's message when no value could be simulated
    open_end: bool = False       # ramp: still changing at the end of the fitted rows

    @property
    def rate(self) -> float:
        """Ramp: change per second, in the parameter's unit (0 for a step)."""
        span = self.end_time - self.change_time
        return (self.value - self.before) / span if span > 0 else 0.0

    @property
    def relative_change(self) -> float:
        return self.value / self.before - 1.0 if self.before else math.nan


@dataclass
class Problem:
    """The data and model shared by every hypothesis.

    ``data`` and ``sim.healthy`` hold grid points ``sim.first .. sim.last``; rows after
    ``fit_from`` are fitted; a change may sit at grid points ``fit_from .. latest``.
    """

    sim: Simulator
    data: np.ndarray
    sigma: np.ndarray
    fit_from: int
    latest: int
    base: dict

    def __post_init__(self):
        i0 = self.fit_from - self.sim.first + 1
        self._data = self.data[i0:]
        self._healthy = self.sim.healthy[i0:]
        self.rows = self._data.shape[0]

    def scaled(self, model: np.ndarray) -> np.ndarray:
        return ((self._data - model) / self.sigma).ravel()

    def healthy_chi2(self) -> float:
        return float(np.sum(np.square(self.scaled(self._healthy))))

    def model(self, name: str, values, start: int) -> np.ndarray:
        """Fitted rows when ``name`` takes ``values`` from grid point ``start`` (healthy before)."""
        branch = self.sim.branch(name, values, start)
        k = start - self.fit_from           # healthy rows kept before the branch
        return np.vstack((self._healthy[:k], branch)) if k > 0 else branch[-k:]

    def ramp_model(self, name: str, v0: float, rate: float, t_start: float, duration: float) -> np.ndarray:
        """Fitted rows when ``name`` moves from ``v0`` at ``rate`` per s over ``[t_start, t_start + duration]``,
        set at each grid point as the orchestrator sets a ramp (the value at ``t_start`` is ``v0``)."""
        grid, last = self.sim.grid, self.sim.last
        start = max(self.fit_from, int(math.floor((t_start - grid.start) / grid.step + 1e-9)))
        if start > last - 1:
            return self._healthy
        end = min(last - 1, int(math.ceil((t_start + duration - grid.start) / grid.step - 1e-9)))
        elapsed = np.clip(grid.time(np.arange(start, max(end, start) + 1)) - t_start, 0.0, duration)
        return self.model(name, v0 + rate * elapsed, start)

    def model_of(self, fit: "Fit") -> np.ndarray:
        """Fitted rows of a fitted hypothesis."""
        if fit.kind == "ramp":
            return self.ramp_model(fit.parameter, fit.before, fit.rate, fit.change_time, fit.end_time - fit.change_time)
        return self.model(fit.parameter, [fit.value], self.sim.grid.index(fit.change_time))

    def rms(self, scaled: np.ndarray) -> float:
        unscaled = scaled.reshape(self.rows, -1) * self.sigma
        return float(np.sqrt(np.mean(np.square(unscaled))))


def _stderr(result, scale: float, dof: int, index: int = 0) -> float:
    """Standard error of parameter ``index`` from the Jacobian at a least-squares optimum."""
    jac = np.atleast_2d(result.jac)
    s2 = 2.0 * result.cost / max(dof, 1)
    try:
        cov = np.linalg.pinv(jac.T @ jac) * s2
    except np.linalg.LinAlgError:
        return math.inf
    return float(math.sqrt(max(cov[index, index], 0.0)) * abs(scale))


class _StepObjective:
    """Scaled residuals of "``name`` became ``v0 (1 + u)`` at grid point ``c``", counting calls."""

    def __init__(self, problem: Problem, name: str):
        self.problem, self.name = problem, name
        self.v0 = float(problem.base[name])
        self.calls = 0
        self.refused: str | None = None

    def __call__(self, u: np.ndarray, c: int) -> np.ndarray:
        self.calls += 1
        try:
            return self.problem.scaled(self.problem.model(self.name, [self.v0 * (1.0 + float(u[0]))], c))
        except BranchFailed as exc:
            self.refused = str(exc)
            return np.full(self.problem.rows * self.problem.sigma.size, _REFUSED)

    def first_guess(self, c: int, probe: float = 0.01) -> float:
        """The relative change a linearisation around the healthy value suggests."""
        r0 = self.problem.scaled(self.problem._healthy)
        r1 = self(np.array([probe]), c)
        d = (r1 - r0) / probe
        dd = float(d @ d)
        return float(np.clip(-(d @ r0) / dd, -0.5, 1.0)) if dd > 0 else 0.0

    def solve(self, c: int, u0: float, max_nfev: int):
        return least_squares(self, [u0], args=(c,), diff_step=_DIFF_STEP, x_scale=[0.01], bounds=([-0.9], [9.0]),
                             method="trf", xtol=1e-9, ftol=1e-10, gtol=1e-10, max_nfev=max_nfev)


def fit_step(problem: Problem, name: str, c0: int, search: bool = True) -> Fit:
    """Best step of ``name``: value by least squares at grid point ``c0`` and, with ``search``,
    at the change grid point found by a pattern search from there."""
    objective = _StepObjective(problem, name)
    lo, hi = problem.fit_from, problem.latest
    c0 = min(max(c0, lo), hi)
    solved: dict[int, object] = {}

    def profile(c: int, u0: float | None, max_nfev: int) -> float:
        guess = objective.first_guess(c) if u0 is None else u0
        solved[c] = objective.solve(c, guess, max_nfev)
        return 2.0 * solved[c].cost

    best_c = c0
    best = profile(c0, None, 40)
    for stride in _STRIDES if search else ():
        moved = True
        while moved:
            moved = False
            for c in (best_c - stride, best_c + stride):
                if lo <= c <= hi and c not in solved:
                    value = profile(c, float(solved[best_c].x[0]), 12)
                    if value < best:
                        best, best_c, moved = value, c, True
                        break
    # polish the winner (the search solved the neighbours loosely)
    if search:
        profile(best_c, float(solved[best_c].x[0]), 40)
    result = solved[best_c]
    u = float(result.x[0])
    t_c = problem.sim.grid.time(best_c)
    scaled = result.fun
    refused = objective.refused if float(np.max(np.abs(scaled))) >= _REFUSED else None
    return Fit(parameter=name, kind="step", before=objective.v0, value=objective.v0 * (1.0 + u),
               stderr=_stderr(result, objective.v0, scaled.size - 2), change_time=t_c, end_time=t_c,
               chi2=float(scaled @ scaled), rows=problem.rows, rms=problem.rms(scaled),
               evaluations=objective.calls, refused=refused)


def fit_ramp(problem: Problem, step: Fit, duration0: float = 2.0) -> Fit:
    """Best linear ramp of ``step.parameter``, started from that step's fit.

    Fitted as ``(rate, t_start, duration)`` with the rate relative to the healthy value per
    second (its standard error is the ramp's ``stderr``, in the parameter's unit per second).
    A ramp whose end is within two steps of the window's end is ``open``: still changing
    when the data end, so its end and final value are lower bounds.
    """
    grid = problem.sim.grid
    v0 = step.before
    t_lo, t_hi = grid.time(problem.fit_from), grid.time(problem.sim.last)
    calls = 0
    refused: list[str] = []

    def residuals(x: np.ndarray) -> np.ndarray:
        nonlocal calls
        calls += 1
        rate, t_s, d = float(x[0]), float(x[1]), max(float(x[2]), 0.0)
        try:
            return problem.scaled(problem.ramp_model(step.parameter, v0, v0 * rate, t_s, d))
        except BranchFailed as exc:
            refused.append(str(exc))
            return np.full(problem.rows * problem.sigma.size, _REFUSED)

    t0 = min(max(step.change_time - duration0 / 2.0, t_lo), t_hi - grid.step)
    x0 = [step.relative_change / duration0, t0, duration0]
    lower, upper = [-100.0, t_lo, 0.0], [100.0, t_hi, t_hi - t_lo]
    result = least_squares(residuals, x0, bounds=(lower, upper), x_scale=[0.01, 0.1, 0.1],
                           diff_step=[1e-3, 1e-5, 1e-3], method="trf", max_nfev=120)
    rate, t_s, d = (float(v) for v in result.x)
    scaled = result.fun
    return replace(step, kind="ramp", value=v0 * (1.0 + rate * d), stderr=_stderr(result, v0, scaled.size - 4),
                   change_time=t_s, end_time=t_s + d, chi2=float(scaled @ scaled), rms=problem.rms(scaled),
                   evaluations=calls, refused=refused[-1] if refused else None,
                   open_end=t_s + d > t_hi - 2 * grid.step)

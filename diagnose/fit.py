"""One hypothesis, fitted: "parameter ``p`` alone changed, to ``v``, at ``t_c``" (or over a ramp).

For a step, the change's grid point ``c`` is searched over whole grid points (the FMU
applies a change only between two steps) by :class:`StepSearch`: every candidate is
scored by one branch, the best are scored again finer, and the last few are fitted by
:func:`scipy.optimize.least_squares` on the scaled residuals of every fitted row.  All
hypotheses and all ``c`` are scored on the same rows (the healthy model before ``c``,
the branch after), so their chi-squares compare directly.

The new value is fitted as a change ``u`` in units of the parameter's scale
(:func:`change_scales`): the relative change ``u = v / v0 - 1`` when the healthy value
``v0`` is not zero, else ``v = u * scale`` (a parameter whose healthy value is 0, e.g. a
slider's line offset, cannot be moved by a relative change).  Its standard error comes
from the Jacobian at the optimum, scaled by the fit's own residual variance
(``s^2 (J'J)^-1``), so it stays honest when the noise estimate is off, widened by how far
the value moves over the change times the data cannot tell apart.

A ramp is fitted as ``(rate, t_start, duration)``: the value moves linearly from ``v0``
over ``[t_start, t_start + duration]``, set at each grid point as the orchestrator sets
a ramp; the residual is continuous in both times, so least squares handles them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Mapping

import numpy as np

from .simulator import BranchFailed, Simulator

__all__ = ["Fit", "Problem", "ScanPoint", "StepSearch", "change_of", "change_scales", "RESOLUTION", "correlation_time", "fit_ramp",
           "value_at"]

#: Finite-difference step for the change ``u`` (module docstring: relative to the value, or to
#: its scale when the value is 0): large enough that the output change (about 1e-5 m for a
#: unit sensitivity) stands far above the integrator's 1e-9 noise.
_DIFF_STEP = 1e-4
#: Scaled residual given to each row when the FMU refuses a value (e.g. a linkage that
#: cannot close): far worse than any real fit, so least squares steps back.
_REFUSED = 1e3
#: Change ``u`` (module docstring) of the first branch that measures a hypothesis' effect (see StepSearch.scan).
_PROBE = 0.01
#: A scan point whose probe is this close to its estimate (change u, see the module docstring) is settled.
_SETTLED = 1e-3
#: Bounds of a fitted step's change ``u``: a non-zero value stays of its sign within a factor
#: 10 (``v / v0`` in [0.1, 10]); a zero one moves up to 10 scales either way.
_BOUNDS_RELATIVE = (-0.9, 9.0)
_BOUNDS_ABSOLUTE = (-10.0, 10.0)


def change_scales(values: Mapping[str, float], units: Mapping[str, str]) -> dict[str, float]:
    """The size of a unit change ``u`` of each parameter, in the parameter's unit (positive).

    ``|v0|`` when the healthy value ``v0`` is not zero (``u`` is then the relative change);
    for a zero one, the typical size of the other parameters of the same unit among
    ``values`` (the geometric mean of their non-zero magnitudes: a slider's offset in m is
    scaled like the links' lengths); without one, 1 (one unit).
    """
    sizes: dict[str, list[float]] = {}
    for name, v in values.items():
        unit = units.get(name) or ""
        if unit and math.isfinite(v) and v != 0:
            sizes.setdefault(unit, []).append(abs(float(v)))
    scales = {}
    for name, v in values.items():
        if math.isfinite(v) and v != 0:
            scales[name] = abs(float(v))
        else:
            same = sizes.get(units.get(name) or "")
            scales[name] = float(math.exp(np.mean(np.log(same)))) if same else 1.0
    return scales


def value_at(v0: float, scale: float, u: float) -> float:
    """The value after a change ``u`` of ``v0`` (module docstring): ``v0 (1 + u)``, or ``scale u`` when ``v0`` is 0."""
    return v0 * (1.0 + u) if v0 != 0 else scale * u


def change_of(v0: float, scale: float, value: float) -> float:
    """The change ``u`` that gives ``value`` (the inverse of :func:`value_at`)."""
    return value / v0 - 1.0 if v0 != 0 else value / scale


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
    at_bound: bool = False       # step: the value ended on a bound of the search, widened as far as it goes

    @property
    def rate(self) -> float:
        """Ramp: change per second, in the parameter's unit (0 for a step)."""
        span = self.end_time - self.change_time
        return (self.value - self.before) / span if span > 0 else 0.0

    @property
    def change(self) -> float:
        """The change of the value (end of a ramp), in the parameter's unit."""
        return self.value - self.before

    @property
    def relative_change(self) -> float | None:
        """``value / before - 1``; None when the healthy value is 0 (see :attr:`change`)."""
        return self.value / self.before - 1.0 if self.before else None


@dataclass
class Problem:
    """The data and model shared by every hypothesis.

    ``data`` and ``sim.healthy`` hold grid points ``sim.first .. sim.last``; rows after
    ``fit_from`` up to ``last`` (default ``sim.last``) are fitted; a change may sit at grid
    points ``fit_from .. latest``.
    """

    sim: Simulator
    data: np.ndarray
    sigma: np.ndarray
    fit_from: int
    latest: int
    base: dict
    last: int | None = None
    scales: dict = field(default_factory=dict)   # per parameter: the size of a unit change (change_scales)

    def __post_init__(self):
        if self.last is None:
            self.last = self.sim.last
        i0 = self.fit_from - self.sim.first + 1
        i1 = self.last - self.sim.first + 1
        self._data = self.data[i0:i1]
        self._healthy = self.sim.healthy[i0:i1]
        self.rows = self._data.shape[0]

    def scale(self, name: str) -> float:
        """The size of a unit change of ``name`` (:func:`change_scales`; ``|v0|`` or 1 when not given)."""
        if name in self.scales:
            return float(self.scales[name])
        v0 = float(self.base[name])
        return abs(v0) if v0 != 0 else 1.0

    def until(self, last: int) -> "Problem":
        """The same problem fitted only up to grid point ``last``."""
        return replace(self, last=min(max(last, self.latest + 1), self.sim.last))

    def scaled(self, model: np.ndarray) -> np.ndarray:
        return ((self._data - model) / self.sigma).ravel()

    def healthy_chi2(self) -> float:
        return float(np.sum(np.square(self.scaled(self._healthy))))

    def model(self, name: str, values, start: int) -> np.ndarray:
        """Fitted rows when ``name`` takes ``values`` from grid point ``start`` (healthy before)."""
        branch = self.sim.branch(name, values, start, until=self.last)
        k = start - self.fit_from           # healthy rows kept before the branch
        return np.vstack((self._healthy[:k], branch)) if k > 0 else branch[-k:]

    def ramp_model(self, name: str, v0: float, rate: float, t_start: float, duration: float) -> np.ndarray:
        """Fitted rows when ``name`` moves from ``v0`` at ``rate`` per s over ``[t_start, t_start + duration]``,
        set at each grid point as the orchestrator sets a ramp (the value at ``t_start`` is ``v0``)."""
        grid, last = self.sim.grid, self.last
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


def _scalar_stderr(jac: np.ndarray, fun: np.ndarray, dof: int) -> float:
    """Standard error of a one-parameter least-squares fit, ``sqrt(s^2 / J'J)``, from the
    derivative ``jac`` of the residuals ``fun`` at the optimum."""
    jj = float(jac @ jac)
    if not jj > 0:
        return math.inf
    return math.sqrt(float(fun @ fun) / max(dof, 1) / jj)


#: Relative resolution of a fitted value: its standard error is never stated below this share of
#: it.  Exact data replayed by the FMU that made them are fitted to round-off, but not closer
#: than the adaptive integrator's step sequence lets: it changes with the value's last digits
#: (the drag link's g +10 % came out 3.7e-12 of it off, with residuals at 5e-13 m).
RESOLUTION = 1e-11

#: Reduced chi-square below which a fit's residual is not noise (the noise level comes from the
#: healthy rows before the window: under noise the fit's reduced chi-square is 1 within a few
#: per cent) but what is left of the replay's own integration error on exact data: its rows
#: are not independent, and the standard error is then :func:`_systematic_stderr`.
_EXACT_REDUCED = 0.25


def _systematic_stderr(jac: np.ndarray, fun: np.ndarray) -> float:
    """The change ``u`` that the residual ``fun`` could hide if all of it lay along the
    sensitivity ``jac``: ``|fun| / |jac|``.  On exact data the replay's integration error
    (1e-9 m and less at Table 1's tolerances) moves with the value in steps, as the adaptive
    integrator changes its step sequence: the drag link's L3 +10 % fitted 1.6e-9 m off with
    ``s^2 (J'J)^-1`` giving 2.2e-10 m; this bound gave 5e-9 m."""
    jj = float(jac @ jac)
    return math.sqrt(float(fun @ fun) / jj) if jj > 0 else math.inf


def correlation_time(residual: np.ndarray) -> float:
    """Rows per independent residual: ``1 + 2 sum rho_k`` of each column's autocorrelation,
    summed up to its first lag at or below zero, averaged over the columns weighted by their
    chi-square (at least 1, at most the row count).

    ``s^2 (J'J)^-1`` holds for independent residuals.  Noise is; what a replay leaves on
    noise-free data is not (the integrator's error, the replay of a run by another FMU: smooth
    over many rows), and that standard error was then 30 times too small (the quick-return's
    L4: 3.3e-8 m off, stated 1.1e-9 m).  Counting the residuals ``correlation_time`` rows
    apart as one widens the standard error by its square root; for noise it stays 1.
    """
    rows = residual.shape[0]
    if rows < 3:
        return 1.0
    total, weighted = 0.0, 0.0
    for col in np.atleast_2d(residual.T):
        power = float(col @ col)
        if not power > 0 or not math.isfinite(power):
            continue
        acf = np.correlate(col, col, mode="full")[rows:] / power       # lags 1 .. rows-1
        nonpositive = np.flatnonzero(acf <= 0.0)
        k = int(nonpositive[0]) if nonpositive.size else acf.size
        tau = 1.0 + 2.0 * float(np.sum(acf[:k]))
        total += power
        weighted += power * min(max(tau, 1.0), float(rows))
    return weighted / total if total > 0 else 1.0


class _StepObjective:
    """Scaled residuals of "``name`` became ``value_at(v0, scale, u)`` at grid point ``c``", counting calls."""

    def __init__(self, problem: Problem, name: str):
        self.problem, self.name = problem, name
        self.v0 = float(problem.base[name])
        self.scale = problem.scale(name)
        self.calls = 0
        self.refused: str | None = None     # the FMU's last refusal
        self.last_refused = False           # whether the last call was refused

    def __call__(self, u: np.ndarray, c: int) -> np.ndarray:
        self.calls += 1
        self.last_refused = False
        try:
            return self.problem.scaled(self.problem.model(self.name, [self.value(float(u[0]))], c))
        except BranchFailed as exc:
            self.refused, self.last_refused = str(exc), True
            return np.full(self.problem.rows * self.problem.sigma.size, _REFUSED)

    def value(self, u: float) -> float:
        return value_at(self.v0, self.scale, u)

    def solve(self, c: int, u0: float, max_nfev: int) -> "_Solved":
        """Least squares from ``u0`` within the bounds, widened while the fit ends on one (module
        docstring), then polished by secant steps (:meth:`_polish`)."""
        from scipy.optimize import least_squares   # here: ``fourbar-diagnose --help`` needs no scipy

        lo, hi = _BOUNDS_RELATIVE if self.v0 != 0 else _BOUNDS_ABSOLUTE
        for _ in range(_WIDEN):
            result = least_squares(self, [u0], args=(c,), diff_step=_DIFF_STEP, x_scale=[0.01], bounds=([lo], [hi]),
                                   method="trf", xtol=1e-9, ftol=1e-10, gtol=1e-10, max_nfev=max_nfev)
            u = float(result.x[0])
            edge = _at_bound(u, lo, hi)
            if edge is None:
                break
            u0 = u
            lo, hi = (lo if edge > 0 else _widen(lo, self.v0 != 0)), (hi if edge < 0 else _widen(hi, self.v0 != 0))
        jac = np.atleast_2d(result.jac)[:, 0]
        u, fun = self._polish(c, u, result.fun, jac, lo, hi)
        return _Solved(u=u, fun=fun, jac=jac, at_bound=_at_bound(u, lo, hi) is not None)

    def _polish(self, c: int, u: float, fun: np.ndarray, jac: np.ndarray, lo: float, hi: float):
        """Secant steps from least squares' answer while they lower the chi-square.

        Least squares stops at its tolerances (``xtol`` 1e-9 of the change) with a Jacobian by
        finite differences ``_DIFF_STEP`` wide; noise-free, the true value reproduces the data to
        round-off, and a few secant steps (the slope from the last two branches, which are
        nearly at the answer) take the last digits: L3 +10 % of the drag link came out 1.2e-9
        off without them, 1e-13 with."""
        best_u, best_f = u, fun
        best_chi2 = float(fun @ fun)
        slope = jac.copy()
        prev_u, prev_f = None, None
        for _ in range(_POLISH):
            ss = float(slope @ slope)
            if not ss > 0 or not math.isfinite(best_chi2) or best_chi2 == 0.0:
                break
            nxt = float(np.clip(best_u - float(slope @ best_f) / ss, lo, hi))
            if nxt == best_u:
                break
            f = self(np.array([nxt]), c)
            if self.last_refused:
                break
            chi2 = float(f @ f)
            prev_u, prev_f = best_u, best_f
            if chi2 < best_chi2:
                best_u, best_f, best_chi2 = nxt, f, chi2
                slope = (f - prev_f) / (nxt - prev_u)
            else:
                slope = (f - best_f) / (nxt - best_u)
                if chi2 > 4.0 * best_chi2:
                    break
        return best_u, best_f


@dataclass(frozen=True)
class _Solved:
    """A fitted change ``u``: its scaled residuals, their derivative in ``u``, and whether it
    ended on a bound that could not be widened further."""

    u: float
    fun: np.ndarray
    jac: np.ndarray
    at_bound: bool


#: Reduced chi-square above which a step fit is tried again from other starting values
#: (StepSearch.fit): a fit at the noise level is near 1.
_MISFIT = 1.5
#: Secant steps that polish a least-squares answer (``_StepObjective._polish``).
_POLISH = 6
#: Times a fit that ends on a bound is tried again with that bound widened (``_widen``).
_WIDEN = 3


def _at_bound(u: float, lo: float, hi: float) -> int | None:
    """-1 or +1 when ``u`` is on (within 1e-6 of the width of) the lower or upper bound, else None."""
    tol = 1e-6 * (hi - lo)
    return -1 if u <= lo + tol else 1 if u >= hi - tol else None


def _widen(bound: float, relative: bool) -> float:
    """A bound ten times further out; a relative lower one closer to -1 (the value keeps its sign)."""
    if relative and bound < 0:
        return -1.0 + (1.0 + bound) / 10.0
    return bound * 10.0


@dataclass(frozen=True)
class ScanPoint:
    """A step at grid point ``start``, scored by one branch with the change
    ``probe``: the change and chi-square of the secant through it (see ``StepSearch._score``)."""

    start: int
    change: float
    chi2: float
    probe: float

    @property
    def settled(self) -> bool:
        """Scored with (nearly) its own estimate as the probe, where the secant is (nearly) exact."""
        return abs(self.probe - self.change) <= _SETTLED or self.probe == _probe_near(self.change)


class StepSearch:
    """When, and by how much, did ``name`` step?  Scans change times, then fits the best.

    The chi-square profile over the change time is rugged: a step at a wrong grid point
    can be partly undone by a wrong value, and for a mass (which changes only the
    acceleration) the basin around the true time is a few hundredths of a second wide, with
    other local minima a few grid points away.  So no descent over the change time: every
    candidate is scored by one branch (:meth:`scan`, the secant through a probe change),
    the best are scored again until their probe is their own estimate (:meth:`settle`),
    the grid points around them are scored, and only the last few are fitted by least
    squares (:meth:`fit`).
    """

    def __init__(self, problem: Problem, name: str, scan_until: int | None = None):
        self.problem, self.name = problem, name
        self._objective = _StepObjective(problem, name)
        # scores use the rows up to scan_until only: the shorter the rows after a change, the
        # less its phase drifts and the closer to linear the residual is in the value
        self._scan = problem.until(scan_until) if scan_until is not None else problem
        self._scan_objective = _StepObjective(self._scan, name)
        self._r0 = self._scan.scaled(self._scan._healthy)
        self._points: dict[int, ScanPoint] = {}
        self._last: dict[int, tuple[float, np.ndarray]] = {}    # per grid point: the last probe and its residual

    @property
    def evaluations(self) -> int:
        return self._objective.calls + self._scan_objective.calls

    def best(self, n: int = 1) -> list[ScanPoint]:
        return sorted(self._points.values(), key=lambda p: p.chi2)[:n]

    def _score(self, c: int, probe: float) -> ScanPoint:
        """Score a step at grid point ``c`` by the branch with the change ``probe`` (``u``, module docstring).

        The residual is taken as linear in the change along the line through this branch's
        residual ``r`` and the previous one at ``c`` (the healthy residual, change 0, the
        first time): with slope ``s`` the best change is ``probe + s.r / s.s`` and its
        chi-square ``|r|^2 - (s.r)^2 / s.s``.  Scoring a point again at its estimate is
        then the secant method: the score becomes exact as the probes close in on the
        answer.  (The chord from the healthy residual alone is not enough: for a 10 %
        step of L1 its fixed point is 14 % short of the answer.)
        """
        before, r_before = self._last.get(c, (0.0, self._r0))
        r = self._scan_objective(np.array([probe]), c)
        if self._scan_objective.last_refused:          # the FMU refused the probe here
            return ScanPoint(c, 0.0, math.inf, probe)
        self._last[c] = (probe, r)
        rr = float(r @ r)
        if probe == before:
            return ScanPoint(c, probe, rr, probe)
        slope = (r_before - r) / (probe - before)
        ss = float(slope @ slope)
        if not ss > 0:
            return ScanPoint(c, probe, rr, probe)
        sr = float(slope @ r)
        return ScanPoint(c, probe + sr / ss, max(rr - sr * sr / ss, 0.0), probe)

    def scan(self, starts, probe: float = _PROBE, again: bool = False) -> None:
        """Score a step at each grid point of ``starts`` inside the search range.

        A grid point already scored is skipped, or with ``again`` scored anew and kept at
        the lower of its two scores: a probe far from the answer can miss a good point, and
        the low score flags it for :meth:`settle`, which tells a true one from a lucky one.
        """
        lo, hi = self.problem.fit_from, self.problem.latest
        for c in starts:
            if not lo <= c <= hi or (c in self._points and not again):
                continue
            point = self._score(c, probe)
            old = self._points.get(c)
            if old is None or point.chi2 < old.chi2:
                self._points[c] = point

    def survey(self, starts, keep: int = 2) -> ScanPoint | None:
        """Score the grid points ``starts`` with the first probe, then again with a probe at
        the best estimate, and settle the ``keep`` best: enough to rank the hypotheses (a
        10 % step scored with a 1 % probe only can rank below a wrong parameter).  Returns
        the best point (None when nothing could be scored)."""
        self.scan(starts)
        best = self.best()
        if best and math.isfinite(best[0].chi2) and _probe_near(best[0].change) != _PROBE:
            self.scan(starts, probe=_probe_near(best[0].change), again=True)
        self.settle(keep)
        best = self.best()
        return best[0] if best and math.isfinite(best[0].chi2) else None

    def settle(self, n: int, rounds: int = 4) -> None:
        """Score the ``n`` best again, each with its own estimate as the probe, until all
        ``n`` best are settled (the secant is then nearly exact: its error falls with the
        square of the probe's distance from the answer)."""
        for _ in range(rounds):
            unsettled = [p for p in self.best(n) if math.isfinite(p.chi2) and not p.settled]
            if not unsettled:
                return
            for point in unsettled:
                self._points[point.start] = self._score(point.start, _probe_near(point.change))

    def fit(self, starts, stride: int, keep: int = 2, max_nfev: int = 40, also: int | None = None) -> Fit:
        """The best step, after a first :meth:`scan` or :meth:`survey`.

        1. The grid points ``starts`` (``stride`` apart) and those scored before are scored
           again with a probe at the best estimate so far, and the best are settled.
        2. Every grid point within ``stride`` of the ``keep`` best is scored with a probe at
           its estimate, and the best are settled again (noise-free, neighbouring grid
           points differ by less than a probe 0.2 % off makes).
        3. The ``keep`` best, and the grid point ``also`` if given, are fitted by least
           squares.  ``also`` is the first change-time estimate: exact for a length's jump,
           where the scores can be blunt (a 10 % length change shifts the motion's phase by
           radians over the window, far from linear in the value) but least squares
           converges.
        """
        best = self.best()
        probe = _probe_near(best[0].change) if best and math.isfinite(best[0].chi2) else _PROBE
        self.scan(sorted(set(starts) | set(self._points)), probe=probe, again=True)
        self.settle(2 * keep)
        for point in self.best(keep):
            if math.isfinite(point.chi2):
                self.scan(range(point.start - stride + 1, point.start + stride), probe=_probe_near(point.change))
        self.settle(2 * keep)
        candidates = self.best(keep) or [ScanPoint(self.problem.latest, 0.0, math.inf, _PROBE)]
        if also is not None and self.problem.fit_from <= also <= self.problem.latest \
                and all(p.start != also for p in candidates):
            candidates.append(self._points.get(also) or ScanPoint(also, candidates[0].change, math.inf, _PROBE))
        fit = min((self.solve(p.start, p.change, max_nfev) for p in candidates), key=lambda f: f.chi2)
        if fit.chi2 > _MISFIT * max(fit.rows * self.problem.sigma.size - 2, 1):
            # not at the noise level: the scan's estimate may have led least squares into a
            # wrong basin of the value; try it from other starts at the same time
            c, u = self.problem.sim.grid.index(fit.change_time), change_of(fit.before, self._objective.scale, fit.value)
            starts = (0.5 * u, 2.0 * u, -u) if abs(u) >= _PROBE else (-_PROBE * 10, _PROBE * 10)
            fit = min([fit, *(self.solve(c, u0, max_nfev) for u0 in starts)], key=lambda f: f.chi2)
        return replace(fit, stderr=math.hypot(fit.stderr, self._spread(fit)))

    def _spread(self, fit: Fit) -> float:
        """How far the value moves over the change times the data cannot tell from the best one.

        Each scanned grid point's value (its estimate) differs from the one scored at the fit's
        own time by ``dv``, and its score from the best by ``dchi2``; taking the chi-square as
        quadratic in the change time, ``dv * sqrt(s^2 / dchi2)`` is how far the value moves
        over one standard deviation of the time in that direction (``s^2`` the fit's residual
        variance per residual; a point within ``s^2`` of the best counts in full).  The largest,
        in the parameter's unit, is added to the fixed-time standard error.  Noise-free no
        other grid point comes close; under noise a mass step's time is uncertain by tenths of
        a second, and its value with it: the drag link's I2 +10 % under 5 mm came out at 7.99 s
        and 0.36 % high, the true 8.00 s 1.16 s^2 worse, just outside a plain ``s^2`` cut.
        """
        s2 = fit.chi2 / max(fit.rows * self.problem.sigma.size - 2, 1)
        best = self.best()
        own = self._points.get(self.problem.sim.grid.index(fit.change_time))
        if not best or not math.isfinite(best[0].chi2) or own is None or not s2 > 0:
            return 0.0
        top = best[0].chi2

        def moved(p: ScanPoint) -> float:
            gap = p.chi2 - top
            return abs(p.change - own.change) * (1.0 if gap <= s2 else math.sqrt(s2 / gap))

        return max((moved(p) for p in self._points.values() if math.isfinite(p.chi2)),
                   default=0.0) * self.problem.scale(self.name)

    def solve(self, c: int, u0: float, max_nfev: int) -> Fit:
        """The value fitted by least squares for a step at grid point ``c``, from ``u0``."""
        objective, problem = self._objective, self.problem
        u0 = float(np.clip(u0, -0.5, 1.0)) if math.isfinite(u0) else 0.0
        solved = objective.solve(c, u0, max_nfev)
        u = solved.u
        t_c = problem.sim.grid.time(c)
        scaled = solved.fun
        refused = objective.refused if float(np.max(np.abs(scaled))) >= _REFUSED else None
        columns = problem.sigma.size
        se = _scalar_stderr(solved.jac, scaled, scaled.size - 2) * abs(objective.scale)
        se *= math.sqrt(correlation_time(scaled.reshape(-1, columns)))
        if float(scaled @ scaled) < _EXACT_REDUCED * max(scaled.size - 2, 1):
            se = max(se, _systematic_stderr(solved.jac, scaled) * abs(objective.scale))
        se = max(se, RESOLUTION * abs(objective.value(u)))
        return Fit(parameter=self.name, kind="step", before=objective.v0, value=objective.value(u),
                   stderr=se, change_time=t_c, end_time=t_c,
                   chi2=float(scaled @ scaled), rows=problem.rows, rms=problem.rms(scaled),
                   evaluations=objective.calls, refused=refused, at_bound=solved.at_bound)


def _probe_near(change: float) -> float:
    """A probe change close to an estimate, never so small that the FMU's error swamps it."""
    if not math.isfinite(change) or abs(change) < _PROBE:
        return _PROBE if not change < 0 else -_PROBE
    return float(np.clip(change, -0.5, 1.0))


def fit_ramp(problem: Problem, step: Fit, duration0: float = 2.0,
             start: tuple[float, float, float] | None = None) -> Fit:
    """Best linear ramp of ``step.parameter``, started from that step's fit (a ramp of
    ``duration0`` s centred on its change time to its value), or from ``start`` =
    ``(t_start, duration, final value)`` when given.

    Fitted as ``(rate, t_start, duration)`` with the rate in changes ``u`` per second (relative
    to the healthy value, or in units of the parameter's scale when that is 0; module
    docstring); its standard error is the ramp's ``stderr``, in the parameter's unit per second.
    A ramp whose end is within two steps of the window's end is ``open``: still changing
    when the data end, so its end and final value are lower bounds.
    """
    from scipy.optimize import least_squares

    grid = problem.sim.grid
    v0 = step.before
    scale = problem.scale(step.parameter)
    per_u = v0 if v0 != 0 else scale        # the value's change per unit change u
    t_lo, t_hi = grid.time(problem.fit_from), grid.time(problem.last)
    calls = 0
    refused: list[str] = []

    def residuals(x: np.ndarray) -> np.ndarray:
        nonlocal calls
        calls += 1
        rate, t_s, d = float(x[0]), float(x[1]), max(float(x[2]), 0.0)
        try:
            return problem.scaled(problem.ramp_model(step.parameter, v0, per_u * rate, t_s, d))
        except BranchFailed as exc:
            refused.append(str(exc))
            return np.full(problem.rows * problem.sigma.size, _REFUSED)

    if start is None:
        start = (step.change_time - duration0 / 2.0, duration0, step.value)
    t0 = min(max(start[0], t_lo), t_hi - grid.step)
    d0 = min(max(start[1], grid.step), t_hi - t0)
    x0 = [change_of(v0, scale, start[2]) / d0, t0, d0]
    lower, upper = [-100.0, t_lo, 0.0], [100.0, t_hi, t_hi - t_lo]
    result = least_squares(residuals, x0, bounds=(lower, upper), x_scale=[0.01, 0.1, 0.1],
                           diff_step=[1e-3, 1e-5, 1e-3], method="trf", max_nfev=120)
    rate, t_s, d = (float(v) for v in result.x)
    scaled = result.fun
    return replace(step, kind="ramp", value=value_at(v0, scale, rate * d), stderr=_stderr(result, scale, scaled.size - 4),
                   change_time=t_s, end_time=t_s + d, chi2=float(scaled @ scaled), rms=problem.rms(scaled),
                   evaluations=calls, refused=refused[-1] if refused else None,
                   open_end=t_s + d > t_hi - 2 * grid.step)

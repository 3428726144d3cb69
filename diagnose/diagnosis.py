"""The diagnosis of one run: :func:`diagnose` returns a :class:`Diagnosis`.

1. Window.  The change is looked for in the ``lookback`` seconds before the monitor's first
   alarm; the fit uses every row from there to ``horizon`` s after the alarm, on the
   monitored columns.  The ``noise_span`` seconds before the lookback give each column's
   noise level (the RMS of data minus the healthy model there).
2. Healthy model.  The FMU replays the run with run.json's start values; the first rows that
   leave it (a CUSUM on the scaled residual, :mod:`diagnose.changepoint`) give a first
   change time.
3. Hypotheses.  Each tunable parameter alone, as a step: change time by scoring grid
   points, value by least squares (:class:`diagnose.fit.StepSearch`, :func:`_step_fits`).
   They are ranked by chi-square on the same rows.
4. Ramp.  The best one is also fitted as a linear ramp; the ramp is kept when it lowers the
   chi-square by more than ``ramp_gain`` and lasts at least ``SHORTEST_RAMP``.
5. Sharpening.  When the best explanation is a step whose value's standard error is more
   than ``precision`` of the value (a mass step under noise: its change time trades against
   its value over a few seconds of data), that parameter alone is fitted again on a window
   twice as long after the alarm, up to ``max_horizon`` s and the end of the data, with
   every row scoring the change times within ``sharpen_span`` s of the last estimate
   (:func:`_sharpen`).  A ramp is fitted again on up to ``max_horizon`` s at once
   (:func:`_lengthen_ramp`): the first window seldom holds its end.  The ranking and the
   verdict stay those of the first window.
6. Verdict.  ``no_change`` when the best hypothesis improves on the healthy model by less
   than ``change_gain`` in chi-square (noise only); ``unexplained`` when its reduced
   chi-square (per residual) is above ``explained_limit`` (two faults at once, a change
   outside the model) and what it leaves unexplained is more than ``explained_fraction`` of
   the change's own excess chi-square over the healthy model; else ``explained``.  The
   second condition (residuals under about 3 % of the change's in RMS) keeps a fit whose
   only misfit is the replay's integration error: a run made by the pythonfmu FMU and
   replayed by the native one differs by up to millimetres over 100 s at Table 1's
   tolerances, far above the noise-free data's noise floor.  ``ambiguous`` when the best two
   steps are under ``distinct_gain`` apart (:func:`_distinct_gap`), unless the ``refine`` best,
   each searched again on windows twice as long after the alarm up to ``max_horizon`` s,
   come that far apart there (:func:`_settle`): then ``explained``, with the ``Settlement``.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from fourbar_common.contract.layout import RunFolder
from fourbar_common.contract import diagnosis as contract

from .changepoint import noise_levels, onset
from .errors import DiagnoseError
from .fit import RESOLUTION, Fit, Problem, StepSearch, change_scales, correlation_time, fit_ramp
from .inputs import RunInputs, read_inputs
from .simulator import BranchFailed, Simulator

__all__ = ["Diagnosis", "DiagnoseOptions", "Separation", "Settlement", "change_text", "diagnose",
           "diagnose_inputs", "fit_text"]

#: The smallest noise level assumed for a column, in the column's unit.  Exact (noise-free)
#: data still differ from a replay by the integrator's own error, below Table 1's absolute
#: tolerance of 1e-6 (m for the four-bar's positions).
NOISE_FLOOR = 1e-6


#: Relative size (of the fitted value) at or below which a standard error is round-off, printed
#: as "exact to round-off": the fit's resolution (:data:`diagnose.fit.RESOLUTION`, about 45000
#: units in the last place of a double), the floor of every step's standard error.  Noise-free
#: data replayed by the FMU that made them are fitted that closely.
ROUND_OFF = RESOLUTION

#: Share of the change's effect (RMS of data minus healthy model after the alarm) below which
#: the first change-time estimate ignores a residual (see diagnose_inputs).
ONSET_SHARE = 0.01
#: s: how far after the first change-time estimate the change is searched (it is late, not early).
SEARCH_AFTER = 0.2
#: s: a fitted ramp shorter than this is reported as the step it is (ten 0.01 s grid steps).
SHORTEST_RAMP = 0.1


@dataclass(frozen=True)
class DiagnoseOptions:
    lookback: float = 5.0          # s before the first alarm where the change may lie
    horizon: float = 3.0           # s of data after the first alarm in the fit
    noise_span: float = 5.0        # s before the lookback that give the noise level
    search_back: float = 2.0       # s before the first change-time estimate where every hypothesis is scored
    scan_step: float = 0.05        # s between the change times scored first
    scan_horizon: float = 1.0      # s of rows after the latest candidate change time that score them
    refine: int = 3                # best hypotheses then searched over the whole lookback, to the grid point
    ramp: bool = True              # also fit the best hypothesis as a ramp
    change_gain: float = 25.0      # chi-square gain over the healthy model that makes a change (5 sigma)
    ramp_gain: float = 25.0        # chi-square gain of the ramp over the step that makes a ramp
    distinct_gain: float = 9.0     # chi-square gap (per unit reduced chi-square) under which the best two are not told apart (3 sigma)
    explained_limit: float = 1.5   # largest reduced chi-square of an explanation ...
    explained_fraction: float = 1e-3   # ... unless it leaves less than this share of the change's chi-square
    method: str = "auto"           # branches: auto, snapshot, resimulate (diagnose.simulator)
    precision: float = 0.0025      # a step's value whose standard error is above this share of it is sharpened ...
    max_horizon: float = 12.0      # ... on up to this many s of data after the first alarm (horizon doubled each time)
    sharpen_span: float = 0.5      # s either side of the last change-time estimate scored when sharpening


#: Columns named as the ones that would tell two ambiguous explanations apart.
SEPARATING_COLUMNS = 3
#: A column whose healthy swing is below this share of its size (at least 1 unit) does not
#: move (a ground joint's position): its differences are round-off, never named as separating.
_STILL = 1e-9
#: Outputs never named as separating: not a measurement of the motion.
_NOT_MEASURED = ("constraint_residual",)


@dataclass(frozen=True)
class Separation:
    """An output column and how differently the two best explanations move it over the window:
    the RMS of the difference of their simulations (``difference``, in ``unit``) and that as a
    share of the column's own swing in the healthy replay (``share``, how far the two are apart
    in the column's terms: the ranking key)."""

    column: str
    difference: float
    unit: str
    share: float


@dataclass(frozen=True)
class Settlement:
    """The two best explanations of the first window, within ``distinct_gain`` of each other
    there (``first_gap``), fitted again on ``window`` (more rows after the alarm), where the
    runner-up's chi-square is ``gap`` above the best's (module docstring, 6)."""

    window: tuple[float, float]
    runner_up: Fit
    first_gap: float
    gap: float


@dataclass(frozen=True)
class Curves:
    """The window's rows for the plot: data, healthy replay, best explanation (grid points x columns)."""

    time: np.ndarray
    data: np.ndarray
    healthy: np.ndarray
    model: np.ndarray
    fit_from: float


@dataclass(frozen=True)
class Diagnosis:
    """What changed, by how much and when; ``verdict`` is explained, unexplained or no_change."""

    verdict: str
    message: str
    best: Fit | None
    ranking: tuple[Fit, ...]          # every step hypothesis, best first
    ramp: Fit | None                  # the best hypothesis fitted as a ramp (None when not fitted)
    alarm_time: float
    onset_time: float | None          # the first estimate (healthy-model CUSUM)
    window: tuple[float, float]       # fitted rows of the ranking: (first, last] in s
    rows: int
    columns: tuple[str, ...]
    noise: dict[str, float]           # per column, in its unit
    healthy_chi2: float
    reduced_chi2: float | None        # the best fit's chi-square per residual
    simulator: str                    # the FMU file that simulated and how it branched
    branches: int
    seconds: float
    case: str = ""
    run_id: str | None = None
    units: dict[str, str] = field(default_factory=dict)
    curves: Curves | None = None      # for the plot (not in JSON)
    value_window: tuple[float, float] | None = None   # rows that fitted best's value, when sharpened (module docstring, 5)
    first_fit: Fit | None = None      # best as fitted on ``window``, when sharpened
    separating: tuple[Separation, ...] = ()   # ambiguous: the columns where the best two differ most
    distinct_gap: float | None = None          # runner-up's chi-square excess over best's, per independent residual's variance
    settled: Settlement | None = None          # two explanations the first window could not tell apart, told apart on more rows

    @property
    def sharpened(self) -> bool:
        return self.value_window is not None

    @property
    def explained(self) -> bool:
        return self.verdict == "explained"

    @property
    def ambiguous(self) -> bool:
        return self.verdict == "ambiguous"

    @property
    def runner_up(self) -> Fit | None:
        return _runner_up(self.ranking, self.best)

    def record(self) -> contract.DiagnosisRecord:
        """diagnosis.json's content, typed (the contract's :class:`DiagnosisRecord`: what the
        file holds of this diagnosis, without the curves): every non-finite number (an infinite
        standard error, say) as None, a relative change None where the healthy value is 0."""
        def pair(p: tuple[float, float] | None) -> tuple[float, float] | None:
            return None if p is None else (_finite(p[0]), _finite(p[1]))

        return contract.DiagnosisRecord(
            case=self.case, run_id=self.run_id, verdict=self.verdict, message=self.message,
            best=_fit_record(self.best), ramp=_fit_record(self.ramp),
            ranking=tuple(_fit_record(f) for f in self.ranking), alarm_time=_finite(self.alarm_time),
            onset_time=_finite(self.onset_time), window=pair(self.window), rows=_finite(self.rows),
            columns=tuple(self.columns), units=dict(self.units), noise=_finite(dict(self.noise)),
            value_window=pair(self.value_window), first_fit=_fit_record(self.first_fit),
            separating=tuple(contract.SeparatingColumn(**_finite(asdict(c))) for c in self.separating),
            distinct_gap=_finite(self.distinct_gap),
            settled=None if self.settled is None else contract.Settlement(
                window=pair(self.settled.window), runner_up=_fit_record(self.settled.runner_up),
                first_gap=_finite(self.settled.first_gap), distinct_gap=_finite(self.settled.gap)),
            healthy_chi2=_finite(self.healthy_chi2), reduced_chi2=_finite(self.reduced_chi2),
            simulator=self.simulator, branches=_finite(self.branches), seconds=_finite(self.seconds),
        )

    def to_json(self) -> dict:
        """diagnosis.json's content as plain JSON types (:meth:`record`'s)."""
        return self.record().to_json()


def _fit_record(f: Fit | None) -> contract.DiagnosedFit | None:
    """A fit as diagnosis.json holds it: its fields and its change (non-finite numbers None)."""
    if f is None:
        return None
    return contract.DiagnosedFit(**_finite(asdict(f)), change=_finite(f.change),
                                 relative_change=_finite(f.relative_change))


def _finite(value: Any) -> Any:
    """``value`` with every NaN or infinite float (numpy's included) replaced by None, recursively."""
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def change_text(fit: Fit, unit: str = "", digits: int = 1) -> str:
    """A fit's change: relative (``+10.0%``, ``digits`` decimals) when its healthy value is not
    zero, else absolute in the parameter's unit, three significant digits (``+0.0123 m``)."""
    relative = fit.relative_change
    if relative is not None:
        return f"{relative:+.{digits}%}"
    return f"{fit.change:+.3g}{f' {unit}' if unit else ''}"


def _runner_up(ranking, best: Fit | None) -> Fit | None:
    """The best-ranked hypothesis of another parameter than ``best``'s."""
    return next((f for f in ranking if best is None or f.parameter != best.parameter), None)


def _fmt(value: float, stderr: float | None = None) -> str:
    """A fitted value with as many decimals as its standard error supports (3 to 6)."""
    digits = 3
    if stderr is not None and math.isfinite(stderr):
        digits = 6 if stderr <= 0 else min(6, max(3, 1 - int(math.floor(math.log10(stderr)))))
    return f"{value:.{digits}f}"


def _round_off(stderr: float, scale: float) -> bool:
    """True when ``stderr`` is at or below :data:`ROUND_OFF` of ``scale`` (exactly zero included)."""
    return stderr <= ROUND_OFF * abs(scale)


def _uncertainty(stderr: float, scale: float, unit: str) -> str:
    """``± 3.8e-06 m``; ``exact to round-off: ± < 3.3e-12 m`` at or below :data:`ROUND_OFF` of
    ``scale``; never ``± 0 m`` (two significant digits show any non-zero error)."""
    if not math.isfinite(stderr):
        return "uncertainty unknown"
    if _round_off(stderr, scale):
        floor = ROUND_OFF * abs(scale)
        return f"exact to round-off: ± < {floor:.2g}{unit}" if floor > 0 else "exact to round-off"
    return f"± {stderr:.2g}{unit}"


def fit_text(fit: Fit, unit: str) -> str:
    """A fit in words: ``m3 changed 1.000 → 1.100 kg (± 0.00025 kg) at t = 10.01 s``, or a ramp's."""
    u = f" {unit}" if unit else ""
    if fit.kind == "ramp":
        still = ", still changing when the fitted data end" if fit.open_end else ""
        # the rate's floor is relative to the value it changes (a rate may be near zero)
        return (f"{fit.parameter} ramped {_fmt(fit.before)} → {_fmt(fit.value)}{u} over t = {fit.change_time:.2f}.."
                f"{fit.end_time:.2f} s (a ramp, {fit.rate:+.3g}{u}/s, "
                f"{_uncertainty(fit.stderr, max(abs(fit.value), abs(fit.before)), f'{u}/s')}{still})")
    edge = ", at the edge of the search: it may lie further out" if fit.at_bound else ""
    return (f"{fit.parameter} changed {_fmt(fit.before, fit.stderr)} → {_fmt(fit.value, fit.stderr)}{u}"
            f" ({_uncertainty(fit.stderr, max(abs(fit.value), abs(fit.before)), u)}{edge}) at t = {fit.change_time:.2f} s")


def _message(verdict: str, best: Fit, runner: Fit | None, units: dict[str, str], healthy: float,
             reduced: float, floor_chi2: float, distinct_gain: float, ranked: Fit | None = None,
             horizon: float | None = None, gap: float = math.inf, separating: tuple[Separation, ...] = ()) -> str:
    """The verdict in one line.  ``ranked`` is ``best`` as fitted on the ranking's rows, which the
    runner-up is compared with, when ``best`` was sharpened on ``horizon`` s after the alarm."""
    unit = units.get(best.parameter, "")
    ranked = ranked or best
    if verdict == "no_change":
        return (f"no change found: after the alarm the data agree with the healthy model within the noise "
                f"(the best single change, {best.parameter} {change_text(best, unit, 2)}, gains only "
                f"{healthy - best.chi2:.1f} in chi-square)")
    text = fit_text(best, unit)
    if horizon is not None:
        text += f" (value fitted on {horizon:.3g} s of data after the alarm)"
    if verdict == "unexplained":
        return (f"not explained by one parameter: the best single change, {text}, leaves residuals "
                f"{math.sqrt(reduced):.1f}x the noise (RMS {best.rms:.2g})")
    if verdict == "ambiguous" and runner is not None:
        ratio = math.sqrt(max(runner.chi2, floor_chi2) / max(ranked.chi2, floor_chi2))
        columns = ", ".join(f"{c.column} ({c.difference:.2g}{' ' + c.unit if c.unit else ''} RMS apart)"
                            for c in separating)
        return (f"ambiguous: {text}, or {fit_text(runner, units.get(runner.parameter, ''))} "
                f"(residual {ratio:.4f}x the best's): the data cannot tell these two apart (chi-square "
                f"{gap:.2g} apart per independent residual, under {distinct_gain:g})"
                + (f"; the columns that would separate them: {columns}" if columns else ""))
    if runner is not None:
        ratio = math.sqrt(max(runner.chi2, floor_chi2) / max(ranked.chi2, floor_chi2))
        shown = f"{ratio:.3g}" if ratio >= 1.1 else f"{ratio:.4f}"      # 1.0004x, not 1x
        text += (f"; next best explanation: {runner.parameter} {change_text(runner, units.get(runner.parameter, ''))} "
                 f"(residual {shown}x larger)")
    return text


def _settled_message(best: Fit, settlement: Settlement, units: dict[str, str], options: DiagnoseOptions,
                     horizon: float) -> str:
    """An explanation the first window could not tell from the runner-up, told apart on more rows."""
    runner = settlement.runner_up
    return (f"{fit_text(best, units.get(best.parameter, ''))} (value fitted on {horizon:.3g} s of data after the "
            f"alarm); told apart from {runner.parameter} {change_text(runner, units.get(runner.parameter, ''))} on "
            f"{settlement.window[1] - settlement.window[0]:.3g} s of rows (chi-square {settlement.gap:.3g} apart "
            f"per independent residual; {settlement.first_gap:.2g} on the first {options.horizon:g} s after the "
            f"alarm, under {options.distinct_gain:g})")


def _survey_range(problem: Problem, c0: int, options: DiagnoseOptions) -> tuple[list[int], range, int, int]:
    """Where a step is surveyed (from ``search_back`` s before the first change-time estimate
    ``c0`` to a little after it), the whole lookback it is then searched over, their stride and
    the last row that scores the survey."""
    grid = problem.sim.grid

    def points(seconds: float) -> int:
        return int(round(seconds / grid.step))

    hi = min(problem.latest, c0 + points(SEARCH_AFTER))
    stride = max(1, points(options.scan_step))
    near = [*range(hi, max(problem.fit_from, c0 - points(options.search_back)) - 1, -stride),
            *range(c0 - stride, c0 + 1)]       # a jump (a length) is exact: its own onset row
    return near, range(hi, problem.fit_from - 1, -stride), stride, hi + points(options.scan_horizon)


def _step_fits(problem: Problem, hypotheses, c0: int, options: DiagnoseOptions) -> list[Fit]:
    """Every hypothesis fitted as a step, best first (step 3 of the module docstring).

    Every hypothesis is surveyed from ``search_back`` s before the first change-time
    estimate ``c0`` to a little after it; the ``refine`` best are searched again over the
    whole lookback, to the grid point (:class:`diagnose.fit.StepSearch`); the others are
    fitted where their survey put them.
    """
    near, whole, stride, scan_until = _survey_range(problem, c0, options)
    searches = {name: StepSearch(problem, name, scan_until) for name in hypotheses}
    surveyed = {name: search.survey(near) for name, search in searches.items()}
    order = sorted(searches, key=lambda n: surveyed[n].chi2 if surveyed[n] else math.inf)
    fits = [searches[n].fit(whole, stride, also=c0 - 1) for n in order[:options.refine]]
    for name in order[options.refine:]:
        point = surveyed[name] or next(iter(searches[name].best()), None)    # None: nothing in range
        if point is not None:
            fits.append(searches[name].solve(point.start, point.change, 8))
    return sorted(fits, key=lambda f: f.chi2)


def _step_searched(problem: Problem, name: str, c0: int, options: DiagnoseOptions) -> Fit:
    """``name`` fitted as a step searched over the whole lookback, as the ``refine`` best are by :func:`_step_fits`."""
    near, whole, stride, scan_until = _survey_range(problem, c0, options)
    search = StepSearch(problem, name, scan_until)
    search.survey(near)
    return search.fit(whole, stride, also=c0 - 1)


def _distinct_gap(problem: Problem, step: Fit, best: Fit, runner: Fit) -> float:
    """How far the runner-up's chi-square is above the best's, in units of the variance of one
    independent residual (module docstring, 6).

    Each chi-square is a sum over ``n`` residuals; two one-parameter fits on the same rows are
    told apart at 3 sigma when their difference is above 9 times one residual's variance: 1
    for noise, the best's reduced chi-square when it is above 1 (a misfit the noise does not
    explain), times its residual's :func:`~diagnose.fit.correlation_time` (a misfit is smooth:
    its rows are not independent, so one row carries less than one residual's worth of
    evidence).  ``step`` is the best step, whose residual gives that time.
    """
    try:
        r = problem.scaled(problem.model_of(step))
    except BranchFailed:
        return math.inf
    dof = max(problem.rows * problem.sigma.size - 2, 1)
    reduced = best.chi2 / dof
    variance = max(reduced * correlation_time(r.reshape(problem.rows, -1)), 1.0) if reduced > 1.0 else 1.0
    return (runner.chi2 - best.chi2) / variance


def _separating(inputs: RunInputs, w: "_Window", best: Fit, runner: Fit, scales: dict,
                options: DiagnoseOptions) -> tuple[tuple[Separation, ...], int]:
    """The output columns where the two explanations' simulations differ most over the window,
    as a share of each column's swing in the healthy replay, with the branches it took.

    Every real output of the FMU is simulated (not only the monitored columns: the point is
    which sensor to add), but for :data:`_NOT_MEASURED`."""
    fmu = inputs.simulator_fmu
    outputs = [v.name for v in fmu.model.modelVariables
               if v.causality == "output" and v.type == "Real" and v.name not in _NOT_MEASURED]
    try:
        with Simulator(fmu, inputs.parameters, outputs, inputs.grid, inputs.tolerance, w.first, w.last,
                       method=options.method, master=inputs.master) as sim:
            problem = Problem(sim=sim, data=np.zeros_like(sim.healthy), sigma=np.ones(len(outputs)),
                              fit_from=w.fit_from, latest=w.last - 1, base=inputs.parameters, scales=scales)
            a, b = problem.model_of(best), problem.model_of(runner)
            healthy = sim.healthy[w.fit_from - w.first + 1:]
            branches = sim.branches
    except BranchFailed:
        return (), 0
    difference = np.sqrt(np.mean(np.square(a - b), axis=0))
    swing = np.sqrt(np.mean(np.square(healthy - healthy.mean(axis=0)), axis=0))
    found = [Separation(column=c, difference=float(d), unit=fmu.variables[c].unit or "", share=float(d / s))
             for c, d, s, m in zip(outputs, difference, swing, np.abs(healthy).max(axis=0))
             if s > _STILL * max(1.0, m) and math.isfinite(d)]
    return tuple(sorted(found, key=lambda c: -c.share)[:SEPARATING_COLUMNS]), branches


@dataclass(frozen=True)
class _Window:
    """Grid points ``first .. last`` of the data (noise span, fitted rows), and where the fit starts."""

    first: int
    fit_from: int
    last: int
    data: np.ndarray


def _window(inputs: RunInputs, index: np.ndarray, alarm: int, options: DiagnoseOptions, horizon: float) -> _Window:
    """The rows from the noise span to ``horizon`` s after the first alarm (grid point ``alarm``)."""
    grid = inputs.grid
    fit_from = max(int(index[0]) + 1, alarm - int(round(options.lookback / grid.step)))
    first = max(int(index[0]), fit_from - int(round(options.noise_span / grid.step)))
    last = min(int(index[-1]), alarm + int(round(horizon / grid.step)))
    rows = np.searchsorted(index, np.arange(first, last + 1))
    if rows.size == 0 or rows[-1] >= index.size or not np.array_equal(index[rows], np.arange(first, last + 1)):
        raise DiagnoseError(f"{RunFolder(inputs.run_dir).exchange}: rows missing between t = {grid.time(first)} and "
                            f"{grid.time(last)} s (the diagnosis needs every grid point there)")
    return _Window(first=first, fit_from=fit_from, last=last, data=inputs.data[rows])


def _curves(grid, w: _Window, sim: Simulator, problem: Problem, best: Fit) -> Curves:
    try:
        model = np.vstack((sim.healthy[:w.fit_from - w.first + 1], problem.model_of(best)))
    except BranchFailed:        # only when every hypothesis was refused somewhere: nothing to draw
        model = np.full_like(sim.healthy, np.nan)
    return Curves(time=grid.time(np.arange(w.first, w.last + 1)), data=w.data, healthy=sim.healthy.copy(),
                  model=model, fit_from=grid.time(w.fit_from))


def _imprecise(fit: Fit, precision: float) -> bool:
    """True when a step's value is known to worse than ``precision`` of it (module docstring, 5)."""
    return fit.kind == "step" and fit.refused is None and not fit.stderr <= precision * abs(fit.value)


@dataclass(frozen=True)
class _Sharpened:
    fit: Fit
    window: tuple[float, float]
    curves: Curves
    branches: int


def _refit(inputs: RunInputs, index: np.ndarray, alarm: int, sigma: np.ndarray, scales: dict,
           options: DiagnoseOptions, horizon: float, fit_on) -> _Sharpened | None:
    """``fit_on(problem)`` on the rows up to ``horizon`` s after the first alarm; None when it was refused."""
    grid = inputs.grid
    w = _window(inputs, index, alarm, options, horizon)
    with Simulator(inputs.simulator_fmu, inputs.parameters, inputs.columns, grid, inputs.tolerance, w.first,
                   w.last, method=options.method, master=inputs.master) as sim:
        problem = Problem(sim=sim, data=w.data, sigma=sigma, fit_from=w.fit_from, latest=min(alarm, w.last - 1),
                          base=inputs.parameters, scales=scales)
        fit = fit_on(problem)
        if fit.refused is not None or not math.isfinite(fit.chi2):
            return None
        return _Sharpened(fit=fit, window=(grid.time(w.fit_from), grid.time(w.last)),
                          curves=_curves(grid, w, sim, problem, fit), branches=sim.branches)


def _more_data(inputs: RunInputs, index: np.ndarray, alarm: int, horizon: float) -> bool:
    return alarm + int(round(horizon / inputs.grid.step)) < int(index[-1])


def _step_near(problem: Problem, fit: Fit, options: DiagnoseOptions) -> Fit:
    """``fit``'s parameter fitted as a step on ``problem``'s rows, every grid point within
    ``sharpen_span`` s of ``fit``'s change time scored (SHARPEN_STEP apart first)."""
    grid = problem.sim.grid
    half = int(round(options.sharpen_span / grid.step))
    stride = max(1, int(round(SHARPEN_STEP / grid.step)))
    search = StepSearch(problem, fit.parameter)
    c = grid.index(fit.change_time)
    starts = range(min(c + half, problem.latest), max(c - half, problem.fit_from) - 1, -stride)
    search.survey(starts)
    return search.fit(starts, stride, also=c)


@dataclass(frozen=True)
class _Settled:
    best: Fit
    settlement: Settlement
    curves: Curves


def _settle(inputs: RunInputs, index: np.ndarray, alarm: int, c0: int, ranking: list[Fit], first_gap: float,
            sigma: np.ndarray, scales: dict, options: DiagnoseOptions) -> tuple[_Settled | None, int]:
    """The ``refine`` best steps of a ranking whose best two the first window cannot tell
    apart, each searched again over the whole lookback on windows twice as long after the
    alarm, up to ``max_horizon`` s and the end of the data, until the best two are
    ``distinct_gain`` apart (module docstring, 6); None when they never are.  Also the
    branches it took.

    Masses and g act only through the motion's dynamics: two of them that fit a few seconds
    equally well drift apart in phase with every period after (the quick-return's m2 and m3
    under 4 mm on five columns: 1.0000x over 3 s after the alarm).  Each is searched twice on
    each window, the better kept: afresh over the whole lookback, as on the first window (whose
    change time can be a wrong basin), and near its last fit's change time (the whole-lookback
    scan scores on 1 s of rows only: the inverted slider-crank's m3 +10 % under 4 mm on four
    columns came out +8.8 % and 46 worse in chi-square than m4 from the scan alone)."""
    grid = inputs.grid
    last = {f.parameter: f for f in ranking[:options.refine] if f.kind == "step"}
    horizon, branches = options.horizon, 0
    while horizon < options.max_horizon and _more_data(inputs, index, alarm, horizon):
        horizon = min(2.0 * horizon, options.max_horizon)
        w = _window(inputs, index, alarm, options, horizon)
        with Simulator(inputs.simulator_fmu, inputs.parameters, inputs.columns, grid, inputs.tolerance, w.first,
                       w.last, method=options.method, master=inputs.master) as sim:
            problem = Problem(sim=sim, data=w.data, sigma=sigma, fit_from=w.fit_from,
                              latest=min(alarm, w.last - 1), base=inputs.parameters, scales=scales)
            fits = sorted((min(_step_searched(problem, name, c0, options), _step_near(problem, fit, options),
                               key=lambda f: f.chi2) for name, fit in last.items()), key=lambda f: f.chi2)
            if len(fits) < 2 or fits[0].refused is not None or not math.isfinite(fits[0].chi2):
                return None, branches + sim.branches
            gap = _distinct_gap(problem, fits[0], fits[0], fits[1])
            curves = _curves(grid, w, sim, problem, fits[0]) if gap >= options.distinct_gain else None
            branches += sim.branches
        last = {f.parameter: f for f in fits}
        if curves is not None:
            window = (grid.time(w.fit_from), grid.time(w.last))
            return _Settled(best=fits[0], curves=curves,
                            settlement=Settlement(window=window, runner_up=fits[1], first_gap=first_gap,
                                                  gap=gap)), branches
    return None, branches


def _sharpen(inputs: RunInputs, index: np.ndarray, alarm: int, best: Fit, sigma: np.ndarray, scales: dict,
             options: DiagnoseOptions, start_horizon: float | None = None) -> _Sharpened | None:
    """``best``'s parameter fitted again as a step on windows twice as long after the alarm until
    its value is known to ``precision`` (step 5 of the module docstring); None when the data
    end first.

    Every row scores the change times (no ``scan_horizon``): over a few seconds a mass step
    at a wrong time is undone by a wrong value (Table 1, m3 +10 % under 5 mm: 1.120 kg at
    10.26 s and 1.104 kg at 10.00 s within 2 in chi-square of each other over 3 s), while
    the phase drift a wrong value leaves grows with every period after it.
    """
    horizon, fit, done, branches = start_horizon or options.horizon, best, None, 0
    while _imprecise(fit, options.precision) and horizon < options.max_horizon \
            and _more_data(inputs, index, alarm, horizon):
        horizon = min(2.0 * horizon, options.max_horizon)
        new = _refit(inputs, index, alarm, sigma, scales, options, horizon,
                     lambda problem, near=fit: _step_near(problem, near, options))
        if new is None:
            break
        branches += new.branches
        fit, done = new.fit, replace(new, branches=branches)
    return done


def _lengthen_ramp(inputs: RunInputs, index: np.ndarray, alarm: int, step: Fit, ramp: Fit, sigma: np.ndarray,
                   scales: dict, options: DiagnoseOptions) -> _Sharpened | None:
    """``ramp`` fitted again on up to ``max_horizon`` s after the alarm (step 5 of the module
    docstring); None without more data.

    A ramp found soon after the alarm has often not ended within the first window: over 3 s
    Case 3's 10 s ramp (5 mm/s) came out ending 2-6 s early, once at 9.6 mm/s.  On the longer
    window three starts are fitted and the best kept (each alone fell into a wrong local minimum
    on one of Case 3's three seeds): from the step fit (``step``), from ``ramp`` as it was, and
    from ``ramp`` going on at its rate to the window's end.
    """
    if options.max_horizon <= options.horizon or not _more_data(inputs, index, alarm, options.horizon):
        return None

    def best_ramp(problem: Problem) -> Fit:
        end = inputs.grid.time(problem.last)
        starts = (None, (ramp.change_time, ramp.end_time - ramp.change_time, ramp.value),
                  (ramp.change_time, end - ramp.change_time, ramp.before + ramp.rate * (end - ramp.change_time)))
        fits = [fit_ramp(problem, step, start=start) for start in starts]
        return min(fits, key=lambda f: f.chi2 if f.refused is None else math.inf)

    return _refit(inputs, index, alarm, sigma, scales, options, options.max_horizon, best_ramp)


#: s between the change times scored first when sharpening (a mass step's basin over 6-12 s of
#: data is 1-2 grid points wide; StepSearch.fit then scores every grid point around the best).
SHARPEN_STEP = 0.02


def diagnose_inputs(inputs: RunInputs, options: DiagnoseOptions = DiagnoseOptions()) -> Diagnosis:
    """The diagnosis of checked inputs (see the module docstring)."""
    wall0 = time.perf_counter()
    grid = inputs.grid
    index = np.rint((inputs.times - grid.start) / grid.step).astype(int)
    a = grid.index(inputs.alarm_time)
    w = _window(inputs, index, a, options, options.horizon)
    first, fit_from, last, data = w.first, w.fit_from, w.last, w.data
    fmu = inputs.simulator_fmu
    with Simulator(fmu, inputs.parameters, inputs.columns, grid, inputs.tolerance, first, last,
                   method=options.method, master=inputs.master) as sim:
        residual = data - sim.healthy
        k_fit = fit_from - first
        sigma = noise_levels(residual[:k_fit], NOISE_FLOOR)
        # The onset is looked for against max(noise, 1 % of the change's own size per column), so a
        # replay's slowly growing integration error (exact data, another FMU) is not taken for it.
        a_row = a - first
        size = np.sqrt(np.mean(np.square(residual[a_row:]), axis=0)) if a_row < residual.shape[0] else sigma
        found = onset(residual[k_fit:] / np.maximum(sigma, ONSET_SHARE * size))
        c0 = fit_from + found if found is not None else a
        latest = min(a, last - 1)
        units = {n: v.unit or "" for n in inputs.hypotheses for v in [fmu.variables[n]]}
        problem = Problem(sim=sim, data=data, sigma=sigma, fit_from=fit_from, latest=latest,
                          base=inputs.parameters,
                          scales=change_scales({n: float(inputs.parameters[n]) for n in inputs.hypotheses}, units))
        healthy_chi2 = problem.healthy_chi2()
        fits = _step_fits(problem, inputs.hypotheses, c0, options)
        best = fits[0]
        ramp = None
        if options.ramp:
            ramp = fit_ramp(problem, best)
            if ramp.chi2 < best.chi2 - options.ramp_gain and ramp.end_time - ramp.change_time >= SHORTEST_RAMP:
                best = ramp
        residuals = problem.rows * len(inputs.columns)
        reduced = best.chi2 / max(residuals - 2, 1)
        if healthy_chi2 - best.chi2 < options.change_gain:
            verdict = "no_change"
        elif reduced > options.explained_limit and (best.chi2 - residuals) > options.explained_fraction * (healthy_chi2 - residuals):
            verdict = "unexplained"
        else:
            verdict = "explained"
        runner = _runner_up(fits, best)
        gap = None
        if verdict == "explained" and runner is not None:
            gap = _distinct_gap(problem, fits[0], best, runner)
            if gap < options.distinct_gain:
                verdict = "ambiguous"
        curves = _curves(grid, w, sim, problem, best)
        branches, method = sim.branches, sim.method
    ranking = tuple(fits)
    separating: tuple[Separation, ...] = ()
    settled = None
    if verdict == "ambiguous" and best.kind == "step":
        settled, more = _settle(inputs, index, a, c0, fits, gap, sigma, problem.scales, options)
        branches += more
        if settled is not None:
            verdict = "explained"
    if verdict == "ambiguous":
        separating, more = _separating(inputs, w, best, runner, problem.scales, options)
        branches += more
    message = _message(verdict, best, runner, units, healthy_chi2, reduced, floor_chi2=residuals,
                       distinct_gain=options.distinct_gain, gap=gap if gap is not None else math.inf,
                       separating=separating)
    first_fit = value_window = sharp = None
    if settled is not None:
        best, first_fit, curves = settled.best, next(f for f in ranking if f.parameter == settled.best.parameter), \
            settled.curves
        value_window = settled.settlement.window
        more = _sharpen(inputs, index, a, best, sigma, problem.scales, options,
                        start_horizon=value_window[1] - inputs.alarm_time)
        if more is not None:
            branches += more.branches
            best, value_window, curves = more.fit, more.window, more.curves
        message = _settled_message(best, settled.settlement, units, options, horizon=value_window[1] - inputs.alarm_time)
    elif verdict == "explained" and best.kind == "ramp":
        step = next(f for f in ranking if f.parameter == best.parameter)
        sharp = _lengthen_ramp(inputs, index, a, step, best, sigma, problem.scales, options)
    elif verdict == "explained" and _imprecise(best, options.precision):
        sharp = _sharpen(inputs, index, a, best, sigma, problem.scales, options)
    if sharp is not None:
        first_fit, value_window, curves = best, sharp.window, sharp.curves
        branches += sharp.branches
        best = sharp.fit
        message = _message(verdict, best, _runner_up(ranking, first_fit), units, healthy_chi2, reduced,
                           floor_chi2=residuals, distinct_gain=options.distinct_gain, ranked=first_fit,
                           horizon=value_window[1] - inputs.alarm_time)
    return Diagnosis(verdict=verdict, message=message, best=best, ranking=ranking, ramp=ramp,
                     settled=None if settled is None else settled.settlement,
                     alarm_time=inputs.alarm_time, onset_time=grid.time(c0) if found is not None else None,
                     window=(grid.time(fit_from), grid.time(last)), rows=problem.rows, columns=inputs.columns,
                     noise=dict(zip(inputs.columns, map(float, sigma))), healthy_chi2=healthy_chi2,
                     reduced_chi2=reduced, simulator=f"{Path(fmu.path).name} ({method})", branches=branches,
                     seconds=time.perf_counter() - wall0, case=inputs.case, run_id=inputs.run_id,
                     units={**units, **inputs.units}, curves=curves, value_window=value_window, first_fit=first_fit,
                     separating=separating, distinct_gap=gap)


def diagnose(run_dir: str | Path, *, summary: str | Path | None = None, fmu: str | Path | None = None,
             columns=None, use_run_fmu: bool = False, candidates=None, **options: Any) -> Diagnosis:
    """Diagnose the run in ``run_dir`` (reads exchange.csv, run.json, monitor/summary.json).

    Keyword ``options`` are :class:`DiagnoseOptions` fields.  Raises
    :class:`~diagnose.errors.DiagnoseError` for bad input (:class:`~diagnose.errors.NoAlarm`
    when the monitor raised no alarm).
    """
    inputs = read_inputs(run_dir, summary=summary, fmu=fmu, columns=columns, use_run_fmu=use_run_fmu,
                         candidates=candidates)
    return diagnose_inputs(inputs, DiagnoseOptions(**options))

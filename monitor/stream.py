"""The streaming monitor: samples in, fits, evaluations and events out.

:class:`Monitor` is incremental: :meth:`Monitor.feed` takes new samples ``(t, X)`` in any
batch sizes (``X``: one column per monitored signal) and runs everything that those samples
make possible (training once the training window is complete, every evaluation whose data
are complete).  What is computed depends only on the samples, never on how they were
batched, so following a growing file and replaying the finished file give identical
evaluations, events and first-alarm times (:mod:`monitor.session`).

Two detectors (``options.detector``):

``cusum`` (default)
    Each signal's forecaster is fitted at one common period (the mechanism's), its noise
    scale learnt from held-out training data, and the residuals against the phase-locked
    forecast go through a two-sided CUSUM per signal (:mod:`monitor.sequential`).  Alarms
    latch (:class:`~monitor.detector.SequentialDetector`).
``mae``
    The paper's rule on one signal: windowed MAE against a threshold every ``every`` s
    (:class:`~monitor.detector.Detector`), with the optional refit policy.

Memory is bounded: a rolling buffer of the newest samples (an evaluation window, a refit,
or the tracker's guard band), a decimated history for the plots (``history_points``) and a
decimated series of evaluations (``evaluation_points``).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from .bounded import BoundedSeries
from .detector import Detector, Event, SequentialDetector, State, ThresholdRule, auto_threshold, fixed_threshold, \
    window_mae
from .errors import TrainingError
from .forecasters import Forecaster, fit_forecaster
from .options import MonitorOptions, check_every
from .sequential import CusumDesign, NoiseScale, ResidualCusum, design_cusum, noise_scale
from .spectrum import PeriodEstimate, dominant_period
from .tracking import PeriodicTemplate, PhaseTracker, ShapeCorrection

__all__ = ["Fit", "Monitor", "SignalFit"]


@dataclass(frozen=True)
class SignalFit:
    """One monitored signal's model under the cusum detector."""

    name: str
    estimate: PeriodEstimate          # this signal's own period estimate
    forecaster: Forecaster            # fitted at the common period
    scale: NoiseScale

    def as_dict(self) -> dict[str, Any]:
        return {"signal": self.name, "period": self.estimate.as_dict(), "model": self.forecaster.settings(),
                "noise": self.scale.as_dict()}


@dataclass
class Fit:
    """One fitted model with its alarm rule (there are several with the mae detector's ``refit="paper"``).

    ``estimate`` and ``forecaster`` are the first signal's; ``rule`` is the MAE threshold
    rule or the CUSUM design; ``signals`` lists every signal's model under cusum.
    """

    start: float
    end: float
    estimate: PeriodEstimate
    forecaster: Forecaster
    rule: ThresholdRule | CusumDesign
    seconds: float
    signals: tuple[SignalFit, ...] = ()
    period: float | None = None            # the common period (cusum)
    period_stderr: float | None = None

    def as_dict(self) -> dict[str, Any]:
        d = {"train_start": self.start, "train_end": self.end, "period": self.estimate.as_dict(),
             "model": self.forecaster.settings(), "threshold": self.rule.as_dict(), "seconds": self.seconds}
        if self.signals:
            d.update(common_period_s=self.period, common_period_stderr_s=self.period_stderr,
                     signals=[s.as_dict() for s in self.signals])
        return d


def common_period(estimates: list[PeriodEstimate]) -> tuple[float, float]:
    """Inverse-variance mean of the signals' refined periods, and its standard error."""
    err = np.array([e.period_stderr if math.isfinite(e.period_stderr) and e.period_stderr > 0 else np.inf
                    for e in estimates])
    periods = np.array([e.period for e in estimates])
    if not np.isfinite(err).any():
        return float(periods[0]), float("nan")
    w = np.where(np.isfinite(err), 1.0 / np.where(np.isfinite(err), err, 1.0) ** 2, 0.0)
    return float(w @ periods / w.sum()), float(1.0 / math.sqrt(w.sum()))


_STATE_CODE = {State.TRAINING: 0.0, State.STABLE: 1.0, State.ALARM: 2.0}
_CODE_STATE = {v: k for k, v in _STATE_CODE.items()}


class Monitor:
    """Incremental monitor of one or several signals (see the module docstring).

    ``on_event(event)`` and ``on_evaluation(time, statistic, threshold, state)`` are called
    as things happen (the CLI prints and logs from them); ``source`` names the data in
    error messages.
    """

    def __init__(self, options: MonitorOptions, *, source: str = "<data>",
                 on_event: Callable[[Event], None] | None = None,
                 on_evaluation: Callable[[float, float, float, State], None] | None = None):
        self.options = options.validated()
        self.source = source
        self.on_event = on_event
        self.on_evaluation = on_evaluation
        self.fits: list[Fit] = []
        self.events: list[Event] = []
        self.history = BoundedSeries(("time", "value", "forecast"), self.options.history_points)
        self.evaluations = BoundedSeries(("time", "statistic", "threshold", "state"), self.options.evaluation_points)
        self.timing = {"train": 0.0, "forecast": 0.0, "evaluate": 0.0}
        self.restarts = 0
        self._reset_state()

    def _reset_state(self) -> None:
        o = self.options
        if o.detector == "mae":
            self.detector: Detector | SequentialDetector = Detector(persistence=o.persistence, refit=o.refit,
                                                                    max_refits=o.max_refits)
        else:
            self.detector = SequentialDetector(clear_after=o.clear_after, emit=self._emit)
        self.engine: ResidualCusum | None = None
        self._t = np.empty(0)
        self._x = np.empty((0, len(o.signals)))
        self._f = np.empty(0)
        self._dt: float | None = None
        self._fit: Fit | None = None
        self._next_k = 0
        self._origin = 0.0
        self.n_samples = 0
        self.n_evaluations = 0
        self.first_time: float | None = None
        self.last_time: float | None = None
        self.max_ratio = 0.0

    def reset(self) -> None:
        """Forget everything (the exchange file was replaced): start training again."""
        self.restarts += 1
        self.fits.clear()
        self.events.clear()
        self.history.clear()
        self.evaluations.clear()
        self._reset_state()

    # -- properties -------------------------------------------------------------------------
    @property
    def state(self) -> State:
        return self.detector.state

    @property
    def trained(self) -> bool:
        return self._fit is not None

    @property
    def fit(self) -> Fit | None:
        return self._fit

    @property
    def buffered_samples(self) -> int:
        """Samples held in memory: the rolling buffer and the tracker's guard band."""
        return int(self._t.size + (self.engine.pending_samples if self.engine is not None else 0))

    @property
    def refits(self) -> int:
        return getattr(self.detector, "refits", 0)

    # -- feeding ----------------------------------------------------------------------------
    def _emit(self, events: list[Event]) -> None:
        for e in events:
            self.events.append(e)
            if self.on_event is not None:
                self.on_event(e)

    def feed(self, t: np.ndarray, x: np.ndarray) -> None:
        """Add samples (strictly increasing times, after any already fed) and process them.

        ``x`` has one column per signal of ``options.signal`` (a 1-D array for one signal).
        """
        t = np.asarray(t, dtype=float)
        if t.size == 0:
            return
        x = np.asarray(x, dtype=float).reshape(t.size, -1)
        self.n_samples += t.size
        if self.first_time is None:
            self.first_time = float(t[0])
        self.last_time = float(t[-1])
        if self._fit is None:
            keep = t >= self.options.train[0] - 1e-9
            self._t = np.concatenate([self._t, t[keep]])
            self._x = np.vstack([self._x, x[keep]])
            if self._t.size and self._t[-1] >= self.options.train[1] - 1e-9:
                self._train_initial()
            return
        self._process(t, x)

    def _process(self, t: np.ndarray, x: np.ndarray) -> None:
        """Samples after the training window, with a fitted model."""
        if self.engine is not None:
            start = time.perf_counter()
            f = self.engine.feed(t, x)
            self.timing["evaluate"] += time.perf_counter() - start
            self.history.extend(np.column_stack([t, x[:, 0], f[:, 0]]))
            return
        start = time.perf_counter()
        f = self._fit.forecaster.predict(t)
        self.timing["forecast"] += time.perf_counter() - start
        self._t = np.concatenate([self._t, t])
        self._x = np.vstack([self._x, x])
        self._f = np.concatenate([self._f, f])
        self.history.extend(np.column_stack([t, x[:, 0], f]))
        self._evaluate_due()
        self._trim()

    @property
    def _eps(self) -> float:
        return 1e-6 * (self._dt or 1e-3)

    def _train_initial(self) -> None:
        o = self.options
        sel = (self._t >= o.train[0] - 1e-9) & (self._t <= o.train[1] + 1e-9)
        if sel.sum() < 16:
            raise TrainingError(f"{self.source}: the training window {o.train[0]:g}–{o.train[1]:g} s holds "
                                f"{int(sel.sum())} samples of {o.signal}; at least 16 are needed")
        self._dt = float(np.median(np.diff(self._t[sel])))
        check_every(o.every, self._dt, self.source)    # before anything is written
        tt, xx = self._t[sel], self._x[sel]
        # samples before the window end are training data; they go to the history as such
        self.history.extend(np.column_stack([tt, xx[:, 0], np.full(tt.size, np.nan)]))
        rest = self._t > o.train[1] + self._eps
        if o.detector == "mae":
            # the buffer keeps the training samples: a refit may reach back into them
            self._install_fit(tt, xx[:, 0], end=o.train[1])
            self._f = np.full(self._t.size, np.nan)
            if rest.any():
                start = time.perf_counter()
                self._f[rest] = self._fit.forecaster.predict(self._t[rest])
                self.timing["forecast"] += time.perf_counter() - start
                self.history.extend(np.column_stack([self._t[rest], self._x[rest, 0], self._f[rest]]))
                self._evaluate_due()
                self._trim()
            return
        t_rest, x_rest = self._t[rest], self._x[rest]
        self._t, self._x = np.empty(0), np.empty((0, self._x.shape[1]))
        self._install_sequential(tt, xx, end=o.train[1])
        if t_rest.size:
            self._process(t_rest, x_rest)

    def _estimate(self, name: str, t: np.ndarray, x: np.ndarray, **kwargs: Any) -> PeriodEstimate:
        try:
            return dominant_period(t, x, order=self.options.order, **kwargs)
        except TrainingError as exc:
            raise TrainingError(f"{self.source}: {name} in {t[0]:g}–{t[-1]:g} s: {exc}") from exc

    # -- the cusum detector -------------------------------------------------------------------
    def _install_sequential(self, tt: np.ndarray, xx: np.ndarray, end: float) -> None:
        o = self.options
        start = time.perf_counter()
        names = o.signals
        estimates = [self._estimate(n, tt, xx[:, j]) for j, n in enumerate(names)]
        period, period_err = common_period(estimates)
        split = tt[0] + o.validation_fraction * (tt[-1] - tt[0])
        held = tt > split
        if held.sum() < 16 or (~held).sum() < 16:
            raise TrainingError(f"{self.source}: the training window {o.train[0]:g}–{o.train[1]:g} s is too short "
                                "to hold out a validation part")
        try:
            val_estimates = [dominant_period(tt[~held], xx[~held, j], order=o.order, min_cycles=1.0)
                             for j in range(len(names))]
            val_period = common_period(val_estimates)[0]
        except TrainingError:
            val_period = period
        fits, templates, info = [], [], 0.0
        for j, name in enumerate(names):
            model = fit_forecaster(o.model, tt, xx[:, j], period, order=o.order, seed=o.seed,
                                   chunk_seconds=o.chunk_seconds)
            check = fit_forecaster(o.model, tt[~held], xx[~held, j], val_period, order=o.order, seed=o.seed,
                                   chunk_seconds=o.chunk_seconds)
            scale = noise_scale(xx[held, j] - check.predict(tt[held]), estimates[j].amplitude, o.noise_floor)
            template = PeriodicTemplate(model)
            info += float(np.mean(template.slope(tt) ** 2)) / (self._dt * scale.sigma ** 2)
            fits.append(SignalFit(name, estimates[j], model, scale))
            templates.append(template)
        design = design_cusum(o.false_alarm_rate, self._dt, len(names), o.design_shift)
        rel = period_err / period if math.isfinite(period_err) else 0.0
        tracker = PhaseTracker(float(tt.mean()), rate_std=max(3.0 * rel, o.rate_prior),
                               shift_std=math.sqrt(1.0 / (info * (tt[-1] - tt[0]))),
                               noise_per_second=1.0 / info, track_time=o.track_time,
                               variance_horizon=o.guard + o.tracker_block)
        seconds = time.perf_counter() - start
        self.timing["train"] += seconds
        fit = Fit(float(tt[0]), float(end), estimates[0], fits[0].forecaster, design, seconds, tuple(fits),
                  period, period_err)
        self.fits.append(fit)
        self._fit = fit
        corrections = None
        if o.shape_time > 0:
            bins = int(np.clip(round(period / (2.0 * self._dt)), 16, 1024))
            corrections = [ShapeCorrection(period, tpl.origin, bins=bins, time_constant=o.shape_time,
                                           sample_step=self._dt) for tpl in templates]
        self.engine = ResidualCusum(names, templates, [f.scale for f in fits], design, tracker, self.detector,
                                    origin=float(end), guard=o.guard, block=o.tracker_block, every=o.every,
                                    sample_step=self._dt, on_evaluation=self._evaluated, corrections=corrections)
        info_event = {"period_fft_s": estimates[0].fft_period, "period_s": period, "period_stderr_s": period_err,
                      "model": o.model, "order": fits[0].forecaster.order,
                      "fit_seconds": sum(f.forecaster.fit_seconds for f in fits), "train_start": fit.start,
                      "train_end": fit.end, "detector": "cusum", "signals": list(names), "cusum_k": design.k,
                      "cusum_h": design.h, "arl0_hours": design.arl0_hours,
                      "noise_sigma": {f.name: f.scale.sigma for f in fits}}
        self.detector.trained(float(end), design.h, info_event)

    def _evaluated(self, t: float, statistic: float, threshold: float, state: State) -> None:
        self.n_evaluations += 1
        self.max_ratio = max(self.max_ratio, statistic / threshold)
        self.evaluations.extend(np.array([[t, statistic, threshold, _STATE_CODE[state]]]))
        if self.on_evaluation is not None:
            self.on_evaluation(t, statistic, threshold, state)

    # -- the mae detector (the paper's rule) --------------------------------------------------
    def _install_fit(self, tt: np.ndarray, xx: np.ndarray, end: float) -> None:
        o = self.options
        start = time.perf_counter()
        est = self._estimate(o.signal, tt, xx)
        model = fit_forecaster(o.model, tt, xx, est.period, order=o.order, seed=o.seed,
                               chunk_seconds=o.chunk_seconds)
        if o.threshold == "auto":
            rule = auto_threshold(tt, xx, est, model=o.model, order=o.order, window=o.window, every=o.every,
                                  k=o.auto_k, floor=o.auto_floor, z=o.auto_z,
                                  validation_fraction=o.validation_fraction, seed=o.seed)
        else:
            rule = fixed_threshold(float(o.threshold))
        seconds = time.perf_counter() - start
        self.timing["train"] += seconds
        fit = Fit(float(tt[0]), float(end), est, model, rule, seconds)
        self.fits.append(fit)
        self._fit = fit
        self._origin = float(end)
        self._next_k = int(np.ceil(o.window / o.every - 1e-9))     # first window wholly after `end`
        info = {"period_fft_s": est.fft_period, "period_s": est.period, "period_stderr_s": est.period_stderr,
                "model": o.model, "order": model.order, "fit_seconds": model.fit_seconds,
                "train_start": fit.start, "train_end": fit.end, "detector": "mae", "threshold_base": rule.base,
                "threshold_slope_per_s": rule.slope}
        if "validation_mae_max" in rule.details:
            info["validation_mae_max"] = rule.details["validation_mae_max"]
        self._emit(self.detector.trained(float(end), rule, info))

    def _evaluate_due(self) -> None:
        o = self.options
        x = self._x[:, 0]
        while True:
            assert self._fit is not None
            newest = float(self._t[-1])
            k_last = int(np.floor((newest - self._origin) / o.every + 1e-9))
            if k_last < self._next_k:
                return
            ks = np.arange(self._next_k, k_last + 1)
            times = self._origin + o.every * ks
            start = time.perf_counter()
            mae, _ = window_mae(self._t, x, self._f, times, o.window, eps=self._eps,
                                min_samples=max(1, int(round(0.5 * o.window / self._dt))))
            thr = np.asarray(self._fit.rule.at(times), dtype=float)
            self.timing["evaluate"] += time.perf_counter() - start
            refit_at = None
            for j, (tk, m, th) in enumerate(zip(times.tolist(), mae.tolist(), thr.tolist())):
                self._next_k = int(ks[j]) + 1
                if not math.isfinite(m):          # window emptied by skipped rows: no evaluation
                    continue
                events, refit = self.detector.update(tk, m, th)
                self._evaluated(tk, m, th, self.detector.state)
                if events:
                    self._emit(events)
                if refit:
                    refit_at = tk
                    break
            if refit_at is None:
                return
            self._refit(refit_at)

    def _refit(self, at: float) -> None:
        o = self.options
        sel = np.flatnonzero(self._t <= at + self._eps)[-o.refit_samples:]
        tt, xx = self._t[sel], self._x[sel, 0]
        self._install_fit(tt, xx, end=at)
        later = self._t > at + self._eps
        self._f[:] = np.nan
        if later.any():
            self._f[later] = self._fit.forecaster.predict(self._t[later])

    def _trim(self) -> None:
        o = self.options
        assert self._dt is not None
        keep_s = max(o.window + 2 * o.every, (o.refit_samples + 2) * self._dt if o.refit == "paper" else 0.0)
        cut = np.searchsorted(self._t, self._t[-1] - keep_s, side="left")
        if cut > 4096:          # trim in large steps; keeps concatenation cheap
            self._t, self._x, self._f = self._t[cut:], self._x[cut:], self._f[cut:]

    def finish(self) -> None:
        """The data ended: raise if it ended before the training window was complete."""
        if self._fit is None:
            o = self.options
            if self.last_time is None:
                raise TrainingError(f"{self.source}: no samples of {o.signal} at or after the training "
                                    f"start {o.train[0]:g} s")
            raise TrainingError(f"{self.source}: the data ends at t = {self.last_time:g} s, before the end "
                                f"of the training window {o.train[1]:g} s")

    # -- results ----------------------------------------------------------------------------
    def evaluation_frame(self) -> "Any":
        import pandas as pd

        arr = self.evaluations.array()
        return pd.DataFrame({"time": arr[:, 0], "statistic": arr[:, 1], "threshold": arr[:, 2],
                             "state": [_CODE_STATE[c].value for c in arr[:, 3]]})

    def history_frame(self) -> "Any":
        import pandas as pd

        arr = self.history.array()
        return pd.DataFrame({"time": arr[:, 0], self.options.signals[0]: arr[:, 1], "forecast": arr[:, 2]})

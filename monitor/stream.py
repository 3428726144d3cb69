"""The streaming monitor: samples in, fits, evaluations and events out.

:class:`Monitor` is incremental: :meth:`Monitor.feed` takes new samples ``(t, x)`` in any
batch sizes and runs everything that those samples make possible (training once the
training window is complete, every evaluation whose window is complete).  What is computed
depends only on the samples, never on how they were batched, so following a growing file
and replaying the finished file give identical evaluations, events and first-alarm times
(:mod:`monitor.session`).

The monitor computes each evaluation's MAE and threshold; the decision (alarm, clear,
refit) is made by :meth:`monitor.detector.Detector.update` alone.

Memory is bounded: the monitor keeps a rolling buffer of the newest samples (enough for an
evaluation window or a refit), a decimated history for the plots (``history_points``) and
a decimated series of evaluations (``evaluation_points``).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from .bounded import BoundedSeries
from .detector import Detector, Event, State, ThresholdRule, auto_threshold, fixed_threshold, window_mae
from .errors import TrainingError
from .forecasters import Forecaster, fit_forecaster
from .options import MonitorOptions
from .spectrum import PeriodEstimate, dominant_period

__all__ = ["Fit", "Monitor"]


@dataclass
class Fit:
    """One fitted model with its threshold (there are several with ``refit="paper"``)."""

    start: float
    end: float
    estimate: PeriodEstimate
    forecaster: Forecaster
    rule: ThresholdRule
    seconds: float

    def as_dict(self) -> dict[str, Any]:
        return {"train_start": self.start, "train_end": self.end, "period": self.estimate.as_dict(),
                "model": self.forecaster.settings(), "threshold": self.rule.as_dict(),
                "seconds": self.seconds}


_STATE_CODE = {State.TRAINING: 0.0, State.STABLE: 1.0, State.ALARM: 2.0}
_CODE_STATE = {v: k for k, v in _STATE_CODE.items()}


class Monitor:
    """Incremental monitor of one signal (see the module docstring).

    ``on_event(event)`` and ``on_evaluation(time, mae, threshold, state)`` are called as
    things happen (the CLI prints and logs from them); ``source`` names the data in error
    messages.
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
        self.evaluations = BoundedSeries(("time", "mae", "threshold", "state"), self.options.evaluation_points)
        self.timing = {"train": 0.0, "forecast": 0.0, "evaluate": 0.0}
        self.restarts = 0
        self._reset_state()

    def _reset_state(self) -> None:
        o = self.options
        self.detector = Detector(persistence=o.persistence, refit=o.refit, max_refits=o.max_refits)
        self._t = np.empty(0)
        self._x = np.empty(0)
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

    # -- feeding ----------------------------------------------------------------------------
    def _emit(self, events: list[Event]) -> None:
        for e in events:
            self.events.append(e)
            if self.on_event is not None:
                self.on_event(e)

    def feed(self, t: np.ndarray, x: np.ndarray) -> None:
        """Add samples (strictly increasing times, after any already fed) and process them."""
        t = np.asarray(t, dtype=float)
        x = np.asarray(x, dtype=float)
        if t.size == 0:
            return
        self.n_samples += t.size
        if self.first_time is None:
            self.first_time = float(t[0])
        self.last_time = float(t[-1])
        o = self.options
        f = np.full(t.size, np.nan)
        if self._fit is not None:
            start = time.perf_counter()
            after = t > self._fit.end + self._eps
            if after.any():
                f[after] = self._fit.forecaster.predict(t[after])
            self.timing["forecast"] += time.perf_counter() - start
        else:
            keep = t >= o.train[0] - 1e-9
            t, x, f = t[keep], x[keep], f[keep]
        self._t = np.concatenate([self._t, t])
        self._x = np.concatenate([self._x, x])
        self._f = np.concatenate([self._f, f])
        if self._fit is not None:
            self.history.extend(np.column_stack([t, x, f]))
        if self._fit is None and self._t.size and self._t[-1] >= o.train[1] - 1e-9:
            self._train_initial()
        if self._fit is not None:
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
        tt, xx = self._t[sel], self._x[sel]
        # samples before the window end are training data; they go to the history as such
        self.history.extend(np.column_stack([tt, xx, np.full(tt.size, np.nan)]))
        self._install_fit(tt, xx, end=o.train[1])
        # the samples that arrived after the training window end
        rest = self._t > o.train[1] + self._eps
        if rest.any():
            start = time.perf_counter()
            self._f[rest] = self._fit.forecaster.predict(self._t[rest])
            self.timing["forecast"] += time.perf_counter() - start
            self.history.extend(np.column_stack([self._t[rest], self._x[rest], self._f[rest]]))

    def _install_fit(self, tt: np.ndarray, xx: np.ndarray, end: float) -> None:
        o = self.options
        start = time.perf_counter()
        try:
            est = dominant_period(tt, xx, order=o.order)
        except TrainingError as exc:
            raise TrainingError(f"{self.source}: {o.signal} in {tt[0]:g}–{tt[-1]:g} s: {exc}") from exc
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
                "train_start": fit.start, "train_end": fit.end, "threshold_base": rule.base,
                "threshold_slope_per_s": rule.slope}
        if "validation_mae_max" in rule.details:
            info["validation_mae_max"] = rule.details["validation_mae_max"]
        self._emit(self.detector.trained(float(end), rule, info))

    def _evaluate_due(self) -> None:
        o = self.options
        while True:
            assert self._fit is not None
            newest = float(self._t[-1])
            k_last = int(np.floor((newest - self._origin) / o.every + 1e-9))
            if k_last < self._next_k:
                return
            ks = np.arange(self._next_k, k_last + 1)
            times = self._origin + o.every * ks
            start = time.perf_counter()
            mae, _ = window_mae(self._t, self._x, self._f, times, o.window, eps=self._eps,
                                min_samples=max(1, int(round(0.5 * o.window / self._dt))))
            thr = np.asarray(self._fit.rule.at(times), dtype=float)
            self.timing["evaluate"] += time.perf_counter() - start
            refit_at = None
            done = []
            for j, (tk, m, th) in enumerate(zip(times.tolist(), mae.tolist(), thr.tolist())):
                self._next_k = int(ks[j]) + 1
                if not math.isfinite(m):          # window emptied by skipped rows: no evaluation
                    continue
                events, refit = self.detector.update(tk, m, th)
                self.n_evaluations += 1
                if m / th > self.max_ratio:
                    self.max_ratio = m / th
                done.append((tk, m, th, _STATE_CODE[self.detector.state]))
                if self.on_evaluation is not None:
                    self.on_evaluation(tk, m, th, self.detector.state)
                if events:
                    self._emit(events)
                if refit:
                    refit_at = tk
                    break
            if done:
                self.evaluations.extend(np.array(done))
            if refit_at is None:
                return
            self._refit(refit_at)

    def _refit(self, at: float) -> None:
        o = self.options
        sel = np.flatnonzero(self._t <= at + self._eps)[-o.refit_samples:]
        tt, xx = self._t[sel], self._x[sel]
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
        return pd.DataFrame({"time": arr[:, 0], "mae": arr[:, 1], "threshold": arr[:, 2],
                             "state": [_CODE_STATE[c].value for c in arr[:, 3]]})

    def history_frame(self) -> "Any":
        import pandas as pd

        arr = self.history.array()
        return pd.DataFrame({"time": arr[:, 0], self.options.signal: arr[:, 1], "forecast": arr[:, 2]})

"""The Page–Hinkley detector (``detector="page-hinkley"``): a change in the mean of the residuals.

The residual of the monitored signal against its periodic forecast (fitted on the training
window, not phase-tracked), standardised by the noise scale learnt from held-out training
data (:func:`monitor.sequential.noise_scale`, the cusum detector's rule) widened by the
forecast's timing-error bound, is watched by a two-sided Page–Hinkley test (Page 1954,
Hinkley 1971; river's ``drift.PageHinkley``)::

    z_i = (x_i − f(t_i)) / sqrt(σ² + (f'(t_i) · PHASE_Z · σ_P/P · |t_i − t_c|)²)
    x̄_n = (1/n) Σ_{i≤n} z_i     (the running mean)
    m⁺_n = Σ_{i≤n} (z_i − x̄_i − δ)     PH⁺_n = m⁺_n − min_{j≤n} m⁺_j
    m⁻_n = Σ_{i≤n} (x̄_i − z_i − δ)     PH⁻_n = m⁻_n − min_{j≤n} m⁻_j

and an alarm is raised when ``max(PH⁺, PH⁻) > h``.  Unlike the cusum detector, which
compares the residuals with the trained model's zero mean, the test compares each residual
with the mean of the residuals seen since it (re)started: after an alarm it restarts
(running mean, sums and minima), as river's does, so it learns the new level and one
change makes one alarm episode, which clears after ``ph_clear_after`` s without a crossing.

Calibration (:func:`design_page_hinkley`)
    With the running mean settled (its error falls as 1/√n), ``PH⁺`` is a one-sided CUSUM
    with reference ``k = δ`` on N(0, 1) residuals, so its in-control average run length is
    Siegmund's approximation (:func:`monitor.cusum.arl_siegmund`), solved for ``h`` as the
    cusum detector's.  The two sides share the requested false-alarm rate (union bound);
    the rate is per hour of data time, ``ARL₀ = 2 · 3600 / (rate · dt)`` samples per side.
    The running mean only lowers the early rate (the first increments are pulled to 0).
    ``δ = 0.25`` σ by default: the cusum detector's ``k`` (a design shift of 0.5 σ).

The timing term is the auto threshold's (:mod:`monitor.threshold`): the period's standard error
``σ_P`` makes the forecast's timing error grow linearly from the training window's centre
``t_c``; where the waveform is steep (``f'`` large) that error looks like a change, so the
scale is widened there instead (sensitivity falls slowly with the time since training).

Evaluations are recorded at ``t_end + k·every`` (``t_end`` the end of the training window),
each the largest statistic of its interval; the statistic is updated at every sample, so the
result does not depend on how the samples were batched.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from .cusum import arl_siegmund, cusum_threshold
from .detector import Detector, DetectorHost, Event, Fit, State, StatisticPlot
from .errors import TrainingError
from .forecasters import Forecaster, fit_forecaster
from .option_rules import NON_NEGATIVE, RATE, DetectorSettings, option, positive
from .sequential import NoiseScale, noise_scale
from .spectrum import PeriodEstimate, dominant_period
from .tracking import PeriodicTemplate

__all__ = ["PHASE_Z", "PageHinkleyDesign", "PageHinkleyDetector", "PageHinkleySettings", "design_page_hinkley"]

#: z of the timing-error bound: the forecast's timing error after ``τ`` s is bounded by
#: ``PHASE_Z · σ_P/P · τ`` (σ_P the period's standard error), the auto threshold's ``z``.
PHASE_Z = 4.0


@dataclass(frozen=True)
class PageHinkleySettings(DetectorSettings):
    """The page-hinkley detector's own settings (σ: the learnt noise scale)."""

    design_rate = "ph_false_alarm_rate"

    ph_false_alarm_rate: float = option(0.01, RATE, "page-hinkley: false alarms per hour of data the limit h is "
                                        "designed for", flag="--ph-false-alarm-rate", group="detection")
    ph_delta: float = option(0.25, positive("in noise standard deviations"), "page-hinkley: drift allowance δ per "
                             "sample, in noise standard deviations (detects mean changes above about 2δ)",
                             flag="--ph-delta", group="detection")
    ph_clear_after: float = option(30.0, positive("of seconds"), "page-hinkley: an alarm clears after this long "
                                   "without a crossing", flag="--ph-clear-after", group="detection")
    ph_noise_floor: float = option(1e-3, NON_NEGATIVE)


@dataclass(frozen=True)
class PageHinkleyDesign:
    """The test's drift allowance ``delta`` and limit ``h`` and what they were designed for."""

    false_alarm_rate: float        # per hour of data, both sides together
    sample_step: float             # s
    delta: float                   # σ
    h: float
    statistics: int = 2            # one-sided tests

    @property
    def arl0_hours(self) -> float:
        """Bound on the mean time between false alarms of the two sides (union bound)."""
        return arl_siegmund(self.h, self.delta) * self.sample_step / self.statistics / 3600.0

    def limit_at_arl0(self, hours: float) -> float:
        """The limit designed for a mean of ``hours`` between false alarms (same δ and step)."""
        return cusum_threshold(hours * 3600.0 * self.statistics / self.sample_step, self.delta)

    def as_dict(self) -> dict[str, Any]:
        return {"rule": "two-sided Page-Hinkley test on standardised residuals",
                "false_alarm_rate_per_hour": self.false_alarm_rate, "sample_step_s": self.sample_step,
                "one_sided_statistics": self.statistics, "delta_sigma": self.delta, "h": self.h,
                "arl0_hours": self.arl0_hours}


def design_page_hinkley(false_alarm_rate: float, sample_step: float, delta: float) -> PageHinkleyDesign:
    """The ``h`` that keeps the false-alarm rate (per hour) of the two one-sided tests (module docstring)."""
    arl_each = 2 * 3600.0 / (float(false_alarm_rate) * float(sample_step))
    return PageHinkleyDesign(float(false_alarm_rate), float(sample_step), float(delta),
                             cusum_threshold(arl_each, float(delta)))


class PageHinkleyDetector(Detector):
    """Standardised residuals of one signal → two-sided Page–Hinkley test → latched alarms."""

    name = "page-hinkley"
    label = "PH"
    Settings = PageHinkleySettings
    arl0_curve = True

    def __init__(self, options: Any, host: DetectorHost):
        super().__init__(options, host)
        self.design: PageHinkleyDesign | None = None
        self.scale: NoiseScale | None = None
        self._model: Forecaster | None = None
        self._template: PeriodicTemplate | None = None
        self._drift = 0.0                    # PHASE_Z · σ_P / P: timing error per second from the window's centre
        self._t_center = 0.0
        self._origin = 0.0
        self._eps = 0.0
        self._next_eval = 1
        self._eval_max = 0.0
        self._restart(0.0)
        self._last_crossing: float | None = None

    def _restart(self, time_: float) -> None:
        """Running mean, sums and minima from scratch (after training, a crossing, a gap)."""
        self._n = 0
        self._mean = 0.0
        self._up = self._down = 0.0          # PH⁺ and PH⁻ (Lindley form of m − min m)
        self._up_zero = self._down_zero = float(time_)

    # -- training ---------------------------------------------------------------------------------
    def _estimate(self, t: np.ndarray, x: np.ndarray, **kw: Any) -> PeriodEstimate:
        try:
            return dominant_period(t, x, order=self.options.order, **kw)
        except TrainingError as exc:
            raise TrainingError(f"{self.host.source}: {self.options.signal} in {t[0]:g}–{t[-1]:g} s: {exc}") from exc

    def train(self, t: np.ndarray, X: np.ndarray, end: float, sample_step: float) -> None:
        o, c = self.options, self.settings
        start = time.perf_counter()
        x = np.asarray(X, dtype=float).reshape(t.size, -1)[:, 0]
        est = self._estimate(t, x)
        split = t[0] + o.validation_fraction * (t[-1] - t[0])
        held = t > split
        if held.sum() < 16 or (~held).sum() < 16:
            raise TrainingError(f"{self.host.source}: the training window {o.train[0]:g}–{o.train[1]:g} s is too "
                                "short to hold out a validation part")
        try:
            period_v = dominant_period(t[~held], x[~held], order=o.order, min_cycles=1.0).period
        except TrainingError:
            period_v = est.period
        model = fit_forecaster(o.model, t, x, est.period, order=o.order, seed=o.seed, chunk_seconds=o.chunk_seconds)
        check = fit_forecaster(o.model, t[~held], x[~held], period_v, order=o.order, seed=o.seed,
                               chunk_seconds=o.chunk_seconds)
        self.scale = noise_scale(x[held] - check.predict(t[held]), est.amplitude, c.ph_noise_floor)
        self.design = design_page_hinkley(c.ph_false_alarm_rate, float(sample_step), c.ph_delta)
        self._model = model
        self._template = PeriodicTemplate(model)
        rel = est.period_stderr / est.period if math.isfinite(est.period_stderr) else 0.0
        self._drift = PHASE_Z * rel
        self._t_center = float(est.t_center)
        self._origin = float(end)
        self._eps = 1e-6 * float(sample_step)
        self._restart(self._origin)
        seconds = time.perf_counter() - start
        self.host.timing["train"] += seconds
        fit = Fit(float(t[0]), float(end), est, model, self.design, seconds)
        self.host.add_fit(fit)
        info = {"period_fft_s": est.fft_period, "period_s": est.period, "period_stderr_s": est.period_stderr,
                "model": o.model, "order": model.order, "fit_seconds": model.fit_seconds, "train_start": fit.start,
                "train_end": fit.end, "detector": self.name, "signals": list(o.signals), "ph_delta": self.design.delta,
                "ph_h": self.design.h, "arl0_hours": self.design.arl0_hours,
                "noise_sigma": {o.signals[0]: self.scale.sigma}}
        self._enter(State.STABLE)
        self.host.emit([Event(float(end), "trained", State.TRAINING, None, self.design.h, "model fitted", info),
                        Event(float(end), "stable", State.STABLE, None, self.design.h,
                              "state 1: monitoring with the fitted model")])

    # -- monitoring -------------------------------------------------------------------------------
    def update(self, t: np.ndarray, X: np.ndarray) -> np.ndarray:
        assert self._model is not None and self.design is not None and self.scale is not None
        t = np.asarray(t, dtype=float)
        x = np.asarray(X, dtype=float).reshape(t.size, -1)[:, 0]
        f = self._model.predict(t)
        start = time.perf_counter()
        timing = self._template.slope(t) * self._drift * np.abs(t - self._t_center)
        sd = np.sqrt(self.scale.sigma ** 2 + timing * timing)
        self._feed(t.tolist(), ((x - f) / sd).tolist())
        self.host.timing["evaluate"] += time.perf_counter() - start
        return f

    def _feed(self, times: list[float], z: list[float]) -> None:
        h, delta, eps, every = self.design.h, self.design.delta, self._eps, self.options.every
        due = self._origin + self._next_eval * every
        for tj, zj in zip(times, z):
            while tj > due + eps:                     # evaluations that passed before this sample
                self._evaluated(due)
                due = self._origin + self._next_eval * every
            if math.isfinite(zj):
                self._n += 1
                self._mean += (zj - self._mean) / self._n
                d = zj - self._mean
                self._up += d - delta
                if self._up <= 0.0:
                    self._up, self._up_zero = 0.0, tj
                self._down += -d - delta
                if self._down <= 0.0:
                    self._down, self._down_zero = 0.0, tj
                best = max(self._up, self._down)
                if best > self._eval_max:
                    self._eval_max = best
                if best > h:
                    self._crossing(tj, best)
            if tj >= due - eps:                       # a sample at the evaluation time closes it
                self._evaluated(due)
                due = self._origin + self._next_eval * every

    def _crossing(self, time_: float, statistic: float) -> None:
        side, onset = ("+", self._up_zero) if self._up >= self._down else ("-", self._down_zero)
        self._last_crossing = time_
        if self.state is not State.ALARM:
            self.host.emit([self._raise_alarm(time_, statistic, self.design.h, reason="page-hinkley",
                                              signal=self.options.signals[0], side=side, onset=onset,
                                              episode=self.alarms + 1)])
        self._restart(time_)

    def _evaluated(self, due: float) -> None:
        """Evaluation time ``due`` has passed: clear an alarm quiet for ``ph_clear_after`` s; record."""
        clear = self.settings.ph_clear_after
        if self.state is State.ALARM and self._last_crossing is not None \
                and due - self._last_crossing >= clear - 1e-9:
            self._enter(State.STABLE)
            self.host.emit([Event(due, "clear", State.STABLE, None, None,
                                  f"no Page–Hinkley crossing for {clear:g} s: alarm episode {self.alarms} ended")])
        self.host.record(due, self._eval_max, self.design.h, self.state)
        self._eval_max = 0.0
        self._next_eval += 1

    def skip(self, start: float, end: float) -> None:
        """No samples in (``start``, ``end``): no evaluations inside the gap; the test restarts after it."""
        self._next_eval = max(self._next_eval, int(math.ceil((end - self._origin) / self.options.every - 1e-9)))
        self._restart(end)

    # -- display and rules ------------------------------------------------------------------------
    @classmethod
    def describe(cls, event: Event) -> str:
        d = event.data
        if event.kind == "trained":
            sig = ", ".join(f"{k} {v:.3g}" for k, v in d["noise_sigma"].items())
            return (f"{cls._model_text(event)}; Page–Hinkley δ {d['ph_delta']:.3g}, h {d['ph_h']:.4g} "
                    f"(≥ {d['arl0_hours']:.3g} h between false alarms); noise scale {sig}")
        if event.kind == "alarm" and d.get("reason") == "page-hinkley":
            return cls._onset_text(event)
        return ""

    @classmethod
    def settings_text(cls, options: Any) -> str:
        c = options.settings
        return f"detector page-hinkley, {c.ph_false_alarm_rate:g} false alarms/h, delta {c.ph_delta:g} sigma"

    @classmethod
    def plot_text(cls, options: Any, fit: Fit | None) -> StatisticPlot:
        return StatisticPlot(f"Page–Hinkley statistic of {options.signal} (largest of the {options.every:g} s "
                             "interval)", f"limit h ({options.settings.ph_false_alarm_rate:g} false alarms/h)",
                             "Page–Hinkley (noise σ)", floor=1e-3, shade_alarm=True, interval_maximum=True)

    @classmethod
    def option_problems(cls, options: Any) -> list[str]:
        if len(options.signals) > 1:
            return [f"signal: the page-hinkley detector watches one column, got {options.signal!r}; use "
                    "detector cusum to monitor several jointly"]
        return []

    @classmethod
    def series_text(cls, threshold: Any, limits: list[float], arl0_hours: float | None, unit: str = "") -> str:
        h = sorted({round(float(v), 4) for v in limits if v is not None and math.isfinite(float(v))})
        text = "Page–Hinkley" + (f" h {h[0]:.4g}" if len(h) == 1 else f" h {h[0]:.4g}–{h[-1]:.4g}" if h else "")
        return text + (f" (ARL0 {arl0_hours:.3g} h)" if arl0_hours else "")

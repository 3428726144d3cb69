"""The sequential detector (``detector="cusum"``, the default).

Each signal's forecaster is fitted at one common period (the mechanism's), its noise scale
learnt from held-out training data, and the residuals against the phase-locked forecast go
through a two-sided CUSUM per signal (:class:`~monitor.sequential.ResidualCusum`).  Alarms
latch (:class:`~monitor.sequential.SequentialDetector`).  The method: docs/monitor.md.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from .detector import Detector, DetectorHost, Event, Fit, State, StatisticPlot
from .errors import TrainingError
from .forecasters import Forecaster, fit_forecaster
from .sequential import NoiseScale, ResidualCusum, SequentialDetector, design_cusum, noise_scale
from .spectrum import PeriodEstimate, dominant_period
from .tracking import PeriodicTemplate, PhaseTracker, ShapeCorrection

__all__ = ["CusumDetector", "SignalFit", "common_period"]


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


def common_period(estimates: list[PeriodEstimate]) -> tuple[float, float]:
    """Inverse-variance mean of the signals' refined periods, and its standard error."""
    err = np.array([e.period_stderr if math.isfinite(e.period_stderr) and e.period_stderr > 0 else np.inf
                    for e in estimates])
    periods = np.array([e.period for e in estimates])
    if not np.isfinite(err).any():
        return float(periods[0]), float("nan")
    w = np.where(np.isfinite(err), 1.0 / np.where(np.isfinite(err), err, 1.0) ** 2, 0.0)
    return float(w @ periods / w.sum()), float(1.0 / math.sqrt(w.sum()))


class CusumDetector(Detector):
    """Phase-locked residuals of one or several signals → CUSUM per signal → latched alarms."""

    name = "cusum"
    label = "CUSUM"

    def __init__(self, options: Any, host: DetectorHost):
        super().__init__(options, host)
        self.latch = SequentialDetector(clear_after=options.clear_after, emit=host.emit)
        self.engine: ResidualCusum | None = None

    # the latch holds the state machine
    @property
    def state(self) -> State:
        return self.latch.state

    @property
    def alarms(self) -> int:
        return self.latch.alarms

    @property
    def first_alarm(self) -> Event | None:
        return self.latch.first_alarm

    @property
    def buffered_samples(self) -> int:
        """The tracker's guard band."""
        return self.engine.pending_samples if self.engine is not None else 0

    def update(self, t: np.ndarray, X: np.ndarray) -> np.ndarray:
        assert self.engine is not None
        start = time.perf_counter()
        f = self.engine.feed(t, X)          # every signal's phase-locked, shape-corrected forecast
        self.host.timing["evaluate"] += time.perf_counter() - start
        return f

    def skip(self, start: float, end: float) -> None:
        if self.engine is not None:
            self.engine.skip(start, end)

    def _estimate(self, name: str, t: np.ndarray, x: np.ndarray) -> PeriodEstimate:
        try:
            return dominant_period(t, x, order=self.options.order)
        except TrainingError as exc:
            raise TrainingError(f"{self.host.source}: {name} in {t[0]:g}–{t[-1]:g} s: {exc}") from exc

    def train(self, tt: np.ndarray, xx: np.ndarray, end: float, sample_step: float) -> None:
        o = self.options
        dt = float(sample_step)
        start = time.perf_counter()
        names = o.signals
        estimates = [self._estimate(n, tt, xx[:, j]) for j, n in enumerate(names)]
        period, period_err = common_period(estimates)
        split = tt[0] + o.validation_fraction * (tt[-1] - tt[0])
        held = tt > split
        if held.sum() < 16 or (~held).sum() < 16:
            raise TrainingError(f"{self.host.source}: the training window {o.train[0]:g}–{o.train[1]:g} s is too "
                                "short to hold out a validation part")
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
            info += float(np.mean(template.slope(tt) ** 2)) / (dt * scale.sigma ** 2)
            fits.append(SignalFit(name, estimates[j], model, scale))
            templates.append(template)
        design = design_cusum(o.false_alarm_rate, dt, len(names), o.design_shift)
        rel = period_err / period if math.isfinite(period_err) else 0.0
        tracker = PhaseTracker(float(tt.mean()), rate_std=max(3.0 * rel, o.rate_prior),
                               shift_std=math.sqrt(1.0 / (info * (tt[-1] - tt[0]))),
                               noise_per_second=1.0 / info, track_time=o.track_time,
                               variance_horizon=o.guard + o.tracker_block)
        seconds = time.perf_counter() - start
        self.host.timing["train"] += seconds
        fit = Fit(float(tt[0]), float(end), estimates[0], fits[0].forecaster, design, seconds, tuple(fits),
                  period, period_err)
        self.host.add_fit(fit)
        corrections = None
        if o.shape_time > 0:
            bins = int(np.clip(round(period / (2.0 * dt)), 16, 1024))
            corrections = [ShapeCorrection(period, tpl.origin, bins=bins, time_constant=o.shape_time,
                                           sample_step=dt) for tpl in templates]
        self.engine = ResidualCusum(names, templates, [f.scale for f in fits], design, tracker, self.latch,
                                    origin=float(end), guard=o.guard, block=o.tracker_block, every=o.every,
                                    sample_step=dt, on_evaluation=self.host.record, corrections=corrections)
        info_event = {"period_fft_s": estimates[0].fft_period, "period_s": period, "period_stderr_s": period_err,
                      "model": o.model, "order": fits[0].forecaster.order,
                      "fit_seconds": sum(f.forecaster.fit_seconds for f in fits), "train_start": fit.start,
                      "train_end": fit.end, "detector": self.name, "signals": list(names), "cusum_k": design.k,
                      "cusum_h": design.h, "arl0_hours": design.arl0_hours,
                      "noise_sigma": {f.name: f.scale.sigma for f in fits}}
        self.latch.trained(float(end), design.h, info_event)

    # -- display --------------------------------------------------------------------------------
    @classmethod
    def describe(cls, event: Event) -> str:
        d = event.data
        if event.kind == "trained":
            sig = ", ".join(f"{k} {v:.3g}" for k, v in d["noise_sigma"].items())
            return (f"{cls._model_text(event)}; CUSUM k {d['cusum_k']:.3g}, h {d['cusum_h']:.4g} (≥ {d['arl0_hours']:.3g} h between false "
                    f"alarms); noise scale {sig}")
        if event.kind == "alarm" and d.get("reason") == "cusum":
            return f" on {d['signal']} ({d['side']}), change began ≈ {d['onset']:.2f} s; episode {d['episode']}"
        return ""

    @classmethod
    def settings_text(cls, options: Any) -> str:
        return (f"detector cusum, {options.false_alarm_rate:g} false alarms/h, design shift "
                f"{options.design_shift:g} sigma")

    @classmethod
    def plot_text(cls, options: Any, fit: Fit | None) -> StatisticPlot:
        return StatisticPlot(f"CUSUM of {options.signal} (largest of the {options.every:g} s interval)",
                             f"limit h ({options.false_alarm_rate:g} false alarms/h)", "CUSUM (noise σ)",
                             floor=1e-3, shade_alarm=True, forecast="phase-locked forecast")

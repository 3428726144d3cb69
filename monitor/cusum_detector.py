"""The sequential detector (``detector="cusum"``, the default).

Each signal's forecaster is fitted at its own period, a whole fraction of the columns' common
period (:mod:`monitor.common_period`: the mechanism's fundamental), its noise scale
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
from .option_rules import NON_NEGATIVE, RATE, DetectorSettings, option, positive
from .sequential import NoiseScale, ResidualCusum, SequentialDetector, design_cusum, noise_scale
from .spectrum import PeriodEstimate, dominant_period
from .tracking import PeriodicTemplate, PhaseTracker, ShapeCorrection
from .common_period import CommonPeriod, common_period

__all__ = ["CusumDetector", "CusumSettings", "SignalFit"]


@dataclass(frozen=True)
class CusumSettings(DetectorSettings):
    """The cusum detector's own settings (units: seconds; σ = the learnt noise scale)."""

    design_rate = "false_alarm_rate"

    false_alarm_rate: float = option(0.01, RATE, "cusum: false alarms per hour of data the detector is designed for",
                                     flag="--false-alarm-rate", group="detection")
    design_shift: float = option(0.5, positive("in noise standard deviations"), "cusum: the mean shift, in noise "
                                 "standard deviations, the CUSUM is tuned to (reference k = shift/2)",
                                 flag="--design-shift", group="detection")
    noise_floor: float = option(1e-3, NON_NEGATIVE, "cusum: smallest noise scale, as a fraction of the training "
                                "amplitude (the scale of a noise-free signal)", flag="--noise-floor", group="detection")
    guard: float = option(3.0, NON_NEGATIVE, "cusum: phase tracking learns only from data at least GUARD s old "
                          "and quiet since", flag="--guard", group="detection")
    track_time: float = option(15.0, positive("of seconds"), "cusum: time constant of the phase tracker; phase "
                               "drifts slower than this are followed", flag="--track-time", group="detection")
    shape_time: float = option(60.0, NON_NEGATIVE, "cusum: time constant of the waveform-shape correction, learnt "
                               "like the phase from quiet data; shape changes slower than this are followed; 0 = "
                               "no correction", flag="--shape-time", group="detection")
    clear_after: float = option(30.0, positive("of seconds"), "cusum: a latched alarm clears after this long "
                                "without a CUSUM crossing", flag="--clear-after", group="detection")
    tracker_block: float = option(1.0, positive("of seconds"))
    rate_prior: float = option(3e-5, NON_NEGATIVE)


@dataclass(frozen=True)
class SignalFit:
    """One monitored signal's model under the cusum detector."""

    name: str
    estimate: PeriodEstimate          # this signal's own period estimate
    forecaster: Forecaster            # fitted at the common period / repeats
    scale: NoiseScale
    repeats: int = 1                  # times this signal repeats within the common period

    def as_dict(self) -> dict[str, Any]:
        return {"signal": self.name, "period": self.estimate.as_dict(), "model": self.forecaster.settings(),
                "noise": self.scale.as_dict(), "model_period_s": self.forecaster.period, "repeats": self.repeats}


def _validation_periods(common: CommonPeriod, estimates: list[PeriodEstimate]) -> tuple[float, ...]:
    """The columns' periods from the validation part's own estimates, when they give the same
    multiples as the whole window (else the whole window's)."""
    try:
        val = common_period(common.names, estimates)
    except TrainingError:
        return common.periods
    return val.periods if val.multiples == common.multiples else common.periods


class CusumDetector(Detector):
    """Phase-locked residuals of one or several signals → CUSUM per signal → latched alarms."""

    name = "cusum"
    label = "CUSUM"
    Settings = CusumSettings
    arl0_curve = True

    def __init__(self, options: Any, host: DetectorHost):
        super().__init__(options, host)
        self.latch = SequentialDetector(clear_after=self.settings.clear_after, emit=host.emit)
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
        o, c = self.options, self.settings
        dt = float(sample_step)
        start = time.perf_counter()
        names = o.signals
        estimates = [self._estimate(n, tt, xx[:, j]) for j, n in enumerate(names)]
        try:
            common = common_period(names, estimates, tt, xx)
        except TrainingError as exc:
            raise type(exc)(f"{self.host.source}: training window {tt[0]:g}–{tt[-1]:g} s: {exc}") from None
        period, period_err = common.period, common.stderr
        split = tt[0] + o.validation_fraction * (tt[-1] - tt[0])
        held = tt > split
        if held.sum() < 16 or (~held).sum() < 16:
            raise TrainingError(f"{self.host.source}: the training window {o.train[0]:g}–{o.train[1]:g} s is too "
                                "short to hold out a validation part")
        try:
            val_estimates = [dominant_period(tt[~held], xx[~held, j], order=o.order, min_cycles=1.0)
                             for j in range(len(names))]
            val_periods = _validation_periods(common, val_estimates)
        except TrainingError:
            val_periods = common.periods
        fits, templates, info = [], [], 0.0
        for j, name in enumerate(names):
            model = fit_forecaster(o.model, tt, xx[:, j], common.periods[j], order=o.order, seed=o.seed,
                                   chunk_seconds=o.chunk_seconds)
            check = fit_forecaster(o.model, tt[~held], xx[~held, j], val_periods[j], order=o.order, seed=o.seed,
                                   chunk_seconds=o.chunk_seconds)
            scale = noise_scale(xx[held, j] - check.predict(tt[held]), estimates[j].amplitude, c.noise_floor)
            template = PeriodicTemplate(model)
            info += float(np.mean(template.slope(tt) ** 2)) / (dt * scale.sigma ** 2)
            fits.append(SignalFit(name, estimates[j], model, scale, common.multiples[j]))
            templates.append(template)
        design = design_cusum(c.false_alarm_rate, dt, len(names), c.design_shift)
        rel = period_err / period if math.isfinite(period_err) else 0.0
        tracker = PhaseTracker(float(tt.mean()), rate_std=max(3.0 * rel, c.rate_prior),
                               shift_std=math.sqrt(1.0 / (info * (tt[-1] - tt[0]))),
                               noise_per_second=1.0 / info, track_time=c.track_time,
                               variance_horizon=c.guard + c.tracker_block)
        seconds = time.perf_counter() - start
        self.host.timing["train"] += seconds
        fit = Fit(float(tt[0]), float(end), estimates[0], fits[0].forecaster, design, seconds, tuple(fits),
                  period, period_err)
        self.host.add_fit(fit)
        corrections = None
        if c.shape_time > 0:
            corrections = [ShapeCorrection(tpl.period, tpl.origin, bins=int(np.clip(round(tpl.period / (2.0 * dt)), 16, 1024)),
                                           time_constant=c.shape_time, sample_step=dt) for tpl in templates]
        self.engine = ResidualCusum(names, templates, [f.scale for f in fits], design, tracker, self.latch,
                                    origin=float(end), guard=c.guard, block=c.tracker_block, every=o.every,
                                    sample_step=dt, on_evaluation=self.host.record, corrections=corrections)
        info_event = {"period_fft_s": estimates[0].fft_period, "period_s": period, "period_stderr_s": period_err,
                      "model": o.model, "order": fits[0].forecaster.order,
                      "fit_seconds": sum(f.forecaster.fit_seconds for f in fits), "train_start": fit.start,
                      "train_end": fit.end, "detector": self.name, "signals": list(names), "cusum_k": design.k,
                      "cusum_h": design.h, "arl0_hours": design.arl0_hours,
                      "noise_sigma": {f.name: f.scale.sigma for f in fits},
                      "signal_periods_s": {f.name: f.forecaster.period for f in fits}}
        self.latch.trained(float(end), design.h, info_event)

    # -- display --------------------------------------------------------------------------------
    @classmethod
    def describe(cls, event: Event) -> str:
        d = event.data
        if event.kind == "trained":
            sig = ", ".join(f"{k} {v:.3g}" for k, v in d["noise_sigma"].items())
            own = d.get("signal_periods_s") or {}
            each = ""
            if any(abs(p - d["period_s"]) > 1e-9 * d["period_s"] for p in own.values()):
                each = " (common period; each column's: " + ", ".join(f"{k} {v:.6g} s" for k, v in own.items()) + ")"
            return (f"{cls._model_text(event)}{each}; CUSUM k {d['cusum_k']:.3g}, h {d['cusum_h']:.4g} (≥ {d['arl0_hours']:.3g} h between false "
                    f"alarms); noise scale {sig}")
        if event.kind == "alarm" and d.get("reason") == "cusum":
            return cls._onset_text(event)
        return ""

    @classmethod
    def settings_text(cls, options: Any) -> str:
        c = options.settings
        return f"detector cusum, {c.false_alarm_rate:g} false alarms/h, design shift {c.design_shift:g} sigma"

    @classmethod
    def plot_text(cls, options: Any, fit: Fit | None) -> StatisticPlot:
        return StatisticPlot(f"CUSUM of {options.signal} (largest of the {options.every:g} s interval)",
                             f"limit h ({options.settings.false_alarm_rate:g} false alarms/h)", "CUSUM (noise σ)",
                             floor=1e-3, shade_alarm=True, forecast="phase-locked forecast", interval_maximum=True)

    @classmethod
    def series_text(cls, threshold: Any, limits: list[float], arl0_hours: float | None, unit: str = "") -> str:
        h = sorted({round(float(v), 4) for v in limits if v is not None and math.isfinite(float(v))})
        text = "CUSUM" + (f" h {h[0]:.4g}" if len(h) == 1 else f" h {h[0]:.4g}–{h[-1]:.4g}" if h else "")
        return text + (f" (ARL0 {arl0_hours:.3g} h)" if arl0_hours else "")

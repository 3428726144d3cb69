"""The paper's detector (``detector="mae"``): windowed MAE against a threshold.

States (the paper's Fig. 5)
    ``TRAINING``  collecting the training window, fitting; with ``refit="paper"`` also
                  while the newest model has not yet passed one evaluation.
    ``STABLE``    the paper's state '1': the forecast matches the data; no refitting.
    ``ALARM``     ``persistence`` consecutive evaluations above the threshold; the paper's
                  message is issued.  After ``persistence`` consecutive evaluations below
                  the threshold the state returns to ``STABLE`` (event ``clear``), so a
                  later fault raises a new alarm and false alarms can be counted.

Refit policy
    ``none`` (default): one fit on the training window, then ``STABLE`` at once; every
    exceedance counts.  ``paper``: after a fit the state stays ``TRAINING`` until the first
    evaluation is below the threshold (→ ``STABLE``); an evaluation above it makes the
    monitor refit on the latest ``refit_samples`` samples (1000 in the paper), at most
    ``max_refits`` times, after which it alarms ("the estimation is out of work").

The evaluation times, the windowed MAE and the auto threshold are in :mod:`monitor.threshold`.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .detector import Detector, DetectorHost, Event, Fit, State, StatisticPlot, alarm_event
from .errors import OptionError, TrainingError
from .forecasters import fit_forecaster
from .option_rules import NON_NEGATIVE, DetectorSettings, Rule, at_least, choice, is_number, option, positive
from .spectrum import PeriodEstimate, dominant_period
from .threshold import ThresholdRule, auto_threshold, fixed_threshold, window_mae

__all__ = ["MaeDetector", "MaeRule", "MaeSettings", "THRESHOLD"]

REFIT_POLICIES = ("none", "paper")


def _parse_threshold(text: str) -> float | str:
    return "auto" if text.strip().lower() == "auto" else float(text)


THRESHOLD = Rule(lambda v: v == "auto" or (is_number(v) and v > 0),
                 "a positive number in the signal's units or 'auto'", parse=_parse_threshold,
                 metavar="LEVEL|auto")


@dataclass(frozen=True)
class MaeSettings(DetectorSettings):
    """The mae detector's own settings (units: seconds and the signal's unit).

    ``auto_k``, ``auto_floor`` and ``auto_z`` parametrise the auto threshold
    (:func:`monitor.threshold.auto_threshold`).
    """

    threshold: float | str = option("auto", THRESHOLD, "mae: MAE threshold in the signal's units, or 'auto' from the "
                                    "training data", flag="--threshold", group="detection")
    window: float = option(0.5, positive("of seconds"), "mae: evaluation window: the newest WINDOW s of data",
                           flag="--window", group="detection")
    persistence: int = option(2, at_least(1), "mae: consecutive evaluations above the threshold before an alarm",
                              flag="--persistence", group="detection")
    refit: str = option("none", choice(REFIT_POLICIES), "mae: none: fit once; paper: refit on the latest "
                        "--refit-samples samples until the first evaluation passes (the paper's policy)",
                        flag="--refit", group="detection")
    refit_samples: int = option(1000, at_least(32), "mae: samples per refit", flag="--refit-samples",
                                group="detection")
    max_refits: int = option(10, at_least(0))
    auto_k: float = option(2.0, positive(""))
    auto_floor: float = option(0.01, NON_NEGATIVE)
    auto_z: float = option(4.0, positive(""))


class MaeRule:
    """The MAE rule's state machine, where its alarm is decided (:meth:`update`).

    :class:`MaeDetector` feeds it one evaluation at a time.

    Parameters
    ----------
    persistence:
        Consecutive evaluations above (below) the threshold before an alarm (a clear).
    refit:
        ``"none"`` or ``"paper"`` (see the module docstring).
    max_refits:
        With ``refit="paper"``: refits allowed before alarming.
    """

    def __init__(self, *, persistence: int = 2, refit: str = "none", max_refits: int = 10):
        if refit not in ("none", "paper"):
            raise OptionError(f"refit: expected 'none' or 'paper', got {refit!r}")
        if int(persistence) < 1:
            raise OptionError(f"persistence: expected an integer ≥ 1, got {persistence!r}")
        self.persistence = int(persistence)
        self.refit = refit
        self.max_refits = int(max_refits)
        self.state = State.TRAINING
        self.refits = 0
        self._above = 0
        self._below = 0
        self.alarms = 0
        self.first_alarm: Event | None = None

    def trained(self, time: float, rule: ThresholdRule, info: dict[str, Any] | None = None) -> list[Event]:
        """A model was fitted on data up to ``time``: TRAINING → STABLE (refit none)."""
        self._above = self._below = 0
        events = [Event(time, "trained", State.TRAINING, None, float(rule.at(time)),
                        "model fitted", dict(info or {}))]
        if self.refit == "none":
            self.state = State.STABLE
            events.append(Event(time, "stable", State.STABLE, None, float(rule.at(time)),
                                "state 1: monitoring with the fitted model"))
        else:
            self.state = State.TRAINING
        return events

    def update(self, time: float, mae: float, threshold: float) -> tuple[list[Event], bool]:
        """Process one evaluation; returns the events and whether a refit is requested."""
        events: list[Event] = []
        above = mae > threshold
        if self.state is State.TRAINING:
            if not above:
                self.state = State.STABLE
                events.append(Event(time, "stable", State.STABLE, mae, threshold,
                                    "state 1: forecast matches the data; model updates stop"))
                return events, False
            if self.refits < self.max_refits:
                self.refits += 1
                events.append(Event(time, "refit", State.TRAINING, mae, threshold,
                                    f"MAE above threshold before stable; refit {self.refits}/{self.max_refits}"))
                return events, True
            events.append(self._alarm(time, mae, threshold, reason="refit_limit"))
            return events, False
        if self.state is State.STABLE:
            self._above = self._above + 1 if above else 0
            if self._above >= self.persistence:
                events.append(self._alarm(time, mae, threshold, reason="mae"))
            return events, False
        # ALARM
        self._below = 0 if above else self._below + 1
        if self._below >= self.persistence:
            self.state = State.STABLE
            self._above = self._below = 0
            events.append(Event(time, "clear", State.STABLE, mae, threshold,
                                f"MAE below threshold for {self.persistence} evaluation(s)"))
        return events, False

    def _alarm(self, time: float, mae: float, threshold: float, reason: str) -> Event:
        self.state = State.ALARM
        self._above = self._below = 0
        self.alarms += 1
        ev = alarm_event(time, mae, threshold, reason=reason)
        if self.first_alarm is None:
            self.first_alarm = ev
        return ev


class MaeDetector(Detector):
    """The paper's rule on one signal: windowed MAE against a threshold every ``every`` s,
    decided by :class:`MaeRule`, with the optional refit policy."""

    name = "mae"
    label = "MAE"
    Settings = MaeSettings

    def __init__(self, options: Any, host: DetectorHost):
        super().__init__(options, host)
        o = self.settings
        self.rule = MaeRule(persistence=o.persistence, refit=o.refit, max_refits=o.max_refits)
        self._t = np.empty(0)
        self._x = np.empty(0)
        self._f = np.empty(0)
        self._dt = 1e-3
        self._fit: Fit | None = None
        self._next_k = 0
        self._origin = 0.0
        self._judged: np.ndarray | None = None      # the forecasts update() returns (see _refit)

    # the rule holds the state machine
    @property
    def state(self) -> State:
        return self.rule.state

    @property
    def alarms(self) -> int:
        return self.rule.alarms

    @property
    def first_alarm(self) -> Event | None:
        return self.rule.first_alarm

    @property
    def refits(self) -> int:
        return self.rule.refits

    @property
    def buffered_samples(self) -> int:
        return int(self._t.size)

    @property
    def _eps(self) -> float:
        return 1e-6 * self._dt

    def train(self, t: np.ndarray, X: np.ndarray, end: float, sample_step: float) -> None:
        self._dt = float(sample_step)
        # the buffer keeps the training samples: a refit may reach back into them
        self._t = np.asarray(t, dtype=float)
        self._x = np.asarray(X, dtype=float)[:, 0]
        self._f = np.full(self._t.size, np.nan)
        self._install_fit(self._t, self._x, end=end)

    def update(self, t: np.ndarray, X: np.ndarray) -> np.ndarray:
        start = time.perf_counter()
        f = self._fit.forecaster.predict(t)
        self.host.timing["forecast"] += time.perf_counter() - start
        self._t = np.concatenate([self._t, t])
        self._x = np.concatenate([self._x, X[:, 0]])
        self._f = np.concatenate([self._f, f])
        self._judged = f.copy()
        try:
            self._evaluate_due()
            judged = self._judged
        finally:
            self._judged = None
        self._trim()
        return judged

    def skip(self, start: float, end: float) -> None:
        """Evaluations due before ``end`` (their windows end in the gap) are not made."""
        if self._fit is None:
            return
        k_end = int(math.ceil((end - self._origin) / self.options.every - 1e-9))
        self._next_k = max(self._next_k, k_end)

    def _estimate(self, t: np.ndarray, x: np.ndarray) -> PeriodEstimate:
        try:
            return dominant_period(t, x, order=self.options.order)
        except TrainingError as exc:
            raise TrainingError(f"{self.host.source}: {self.options.signal} in {t[0]:g}–{t[-1]:g} s: {exc}") from exc

    def _install_fit(self, tt: np.ndarray, xx: np.ndarray, end: float) -> None:
        o, c = self.options, self.settings
        start = time.perf_counter()
        est = self._estimate(tt, xx)
        model = fit_forecaster(o.model, tt, xx, est.period, order=o.order, seed=o.seed,
                               chunk_seconds=o.chunk_seconds)
        if c.threshold == "auto":
            rule = auto_threshold(tt, xx, est, model=o.model, order=o.order, window=c.window, every=o.every,
                                  k=c.auto_k, floor=c.auto_floor, z=c.auto_z,
                                  validation_fraction=o.validation_fraction, seed=o.seed)
        else:
            rule = fixed_threshold(float(c.threshold))
        seconds = time.perf_counter() - start
        self.host.timing["train"] += seconds
        fit = Fit(float(tt[0]), float(end), est, model, rule, seconds)
        self.host.add_fit(fit)
        self._fit = fit
        self._origin = float(end)
        self._next_k = int(np.ceil(c.window / o.every - 1e-9))     # first window wholly after `end`
        info = {"period_fft_s": est.fft_period, "period_s": est.period, "period_stderr_s": est.period_stderr,
                "model": o.model, "order": model.order, "fit_seconds": model.fit_seconds,
                "train_start": fit.start, "train_end": fit.end, "detector": self.name, "threshold_base": rule.base,
                "threshold_slope_per_s": rule.slope}
        if "validation_mae_max" in rule.details:
            info["validation_mae_max"] = rule.details["validation_mae_max"]
        self.host.emit(self.rule.trained(float(end), rule, info))

    def _evaluate_due(self) -> None:
        o, c = self.options, self.settings
        x = self._x
        while True:
            assert self._fit is not None
            newest = float(self._t[-1])
            k_last = int(np.floor((newest - self._origin) / o.every + 1e-9))
            if k_last < self._next_k:
                return
            ks = np.arange(self._next_k, k_last + 1)
            times = self._origin + o.every * ks
            start = time.perf_counter()
            mae, _ = window_mae(self._t, x, self._f, times, c.window, eps=self._eps,
                                min_samples=max(1, int(round(0.5 * c.window / self._dt))))
            thr = np.asarray(self._fit.rule.at(times), dtype=float)
            self.host.timing["evaluate"] += time.perf_counter() - start
            refit_at = None
            for j, (tk, m, th) in enumerate(zip(times.tolist(), mae.tolist(), thr.tolist())):
                self._next_k = int(ks[j]) + 1
                if not math.isfinite(m):          # window emptied by skipped rows: no evaluation
                    continue
                events, refit = self.rule.update(tk, m, th)
                if refit:           # the refit event names the window the new model is fitted on
                    sel = self._refit_window(tk)
                    window = {"train_start": float(self._t[sel[0]]), "train_end": float(tk)}
                    events = [replace(e, data={**e.data, **window}) if e.kind == "refit" else e for e in events]
                self.host.record(tk, m, th, self.rule.state)
                if events:
                    self.host.emit(events)
                if refit:
                    refit_at = tk
                    break
            if refit_at is None:
                return
            self._refit(refit_at)

    def _refit_window(self, at: float) -> np.ndarray:
        """Indices of the samples a refit at ``at`` is fitted on: the latest ``refit_samples``."""
        return np.flatnonzero(self._t <= at + self._eps)[-self.settings.refit_samples:]

    def _refit(self, at: float) -> None:
        sel = self._refit_window(at)
        tt, xx = self._t[sel], self._x[sel]
        self._install_fit(tt, xx, end=at)
        later = self._t > at + self._eps
        self._f[:] = np.nan
        if later.any():
            self._f[later] = self._fit.forecaster.predict(self._t[later])
            # samples of the batch being processed that are newer than the refit are judged by
            # the new model: that is the forecast update() reports for them (so the history and
            # forecast.csv do not depend on how the samples were batched)
            if self._judged is not None:
                first = self._t.size - self._judged.size
                idx = np.flatnonzero(later)
                idx = idx[idx >= first]
                self._judged[idx - first] = self._f[idx]

    def _trim(self) -> None:
        o, c = self.options, self.settings
        keep_s = max(c.window + 2 * o.every, (c.refit_samples + 2) * self._dt if c.refit == "paper" else 0.0)
        cut = np.searchsorted(self._t, self._t[-1] - keep_s, side="left")
        if cut > 4096:          # trim in large steps; keeps concatenation cheap
            self._t, self._x, self._f = self._t[cut:], self._x[cut:], self._f[cut:]

    # -- display and option rules --------------------------------------------------------------
    @classmethod
    def describe(cls, event: Event) -> str:
        d = event.data
        if event.kind == "trained":
            text = f"{cls._model_text(event)}; threshold {d['threshold_base']:.4g}"
            if d.get("threshold_slope_per_s"):
                text += f" + {d['threshold_slope_per_s']:.2g}/s·|t − t_c|"
            return text
        if event.kind == "alarm" and d.get("reason") == "refit_limit":
            return " (refit limit reached)"
        return ""

    @classmethod
    def settings_text(cls, options: Any) -> str:
        c = options.settings
        return (f"detector mae, threshold {c.threshold}, window {c.window:g} s every "
                f"{options.every:g} s, persistence {c.persistence}")

    @classmethod
    def plot_text(cls, options: Any, fit: Fit | None) -> StatisticPlot:
        mode = fit.rule.mode if fit is not None else "?"
        return StatisticPlot(f"MAE over the newest {options.settings.window:g} s (every {options.every:g} s)",
                             f"threshold ({mode})", f"MAE of {options.signal}", ylabel_in_signal_units=True)

    @classmethod
    def option_problems(cls, options: Any) -> list[str]:
        if len(options.signals) > 1:
            return [f"signal: the paper's MAE rule watches one column, got {options.signal!r}; use "
                    "detector cusum to monitor several jointly"]
        return []

    @classmethod
    def alarm_persistence(cls, options: Any) -> int:
        return int(options.settings.persistence)

    @classmethod
    def series_text(cls, threshold: Any, limits: list[float], arl0_hours: float | None, unit: str = "") -> str:
        shown = threshold if threshold == "auto" or not unit else f"{threshold} {unit}"
        return f"MAE threshold {shown}"

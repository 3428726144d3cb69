"""Fault detection: windowed MAE against a threshold, states TRAINING → STABLE → ALARM.

Evaluation
    At the evaluation times ``t_k = t_fit + k·every`` (``t_fit`` the end of the data the
    model was fitted on; the first ``k`` whose window lies wholly after ``t_fit``) the
    detector takes the samples of the newest window ``(t_k − window, t_k]`` and computes
    ``MAE = mean |x − forecast|`` with :func:`sklearn.metrics.mean_absolute_error` (the
    paper's eq. 14).  The evaluation times depend only on the data, never on when the
    data arrived, so following a live file and replaying the finished file give the same
    evaluations.

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

Auto threshold (``threshold="auto"``), see :func:`auto_threshold`::

    threshold(t) = max(k · V, floor · A)  +  z · G · |t − t_c| · σ_P / P

``V``  the largest windowed MAE of a validation model (same kind, order, window and
       cadence) fitted on the first ``validation_fraction`` (2/3) of the training window
       with its own refined period, forecasting the held-out rest;
``A``  the signal's half peak-to-peak range in the training window;
``P``, ``σ_P``  the refined period and its standard error (:mod:`monitor.spectrum`);
``t_c`` the centre of the training window (where the fitted phase is anchored);
``G``  the largest windowed mean of ``|dx/dt|`` of the fitted Fourier series over one
       period: a timing error ``τ`` raises a window's MAE by at most about ``G·τ``.
Defaults ``k = 2``, ``floor = 0.01`` (1 % of the amplitude), ``z = 4``.  The first term is
the error level seen on unseen data (noise plus model error), with a factor 2 margin; the
second bounds the slow growth of the forecast error with the horizon caused by the
period's uncertainty (negligible without noise: σ_P ≈ 1e-7 s; with σ = 5 mm of noise
σ_P ≈ 2e-4 s, which after 90 s is a timing error of several ms).  A numeric threshold is
used as given, constant.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Callable

import numpy as np

from .errors import OptionError, TrainingError
from .forecasters import Forecaster, fit_forecaster
from .spectrum import PeriodEstimate, dominant_period, fourier_design, fit_fourier

__all__ = [
    "ALARM_MESSAGE",
    "Crossing",
    "Detector",
    "SequentialDetector",
    "Event",
    "State",
    "ThresholdRule",
    "auto_threshold",
    "evaluation_times",
    "fixed_threshold",
    "window_mae",
]

#: The paper's alarm message (Fig. 13).
ALARM_MESSAGE = "Undefined signal is detected or the estimation is out of work. Please check the system"


class State(str, Enum):
    TRAINING = "TRAINING"
    STABLE = "STABLE"
    ALARM = "ALARM"


@dataclass(frozen=True)
class Event:
    """A state change or alarm at simulated ``time`` (s)."""

    time: float
    kind: str                 # trained | stable | refit | alarm | clear
    state: State
    statistic: float | None = None     # the detector's statistic: the MAE (mae) or the CUSUM (cusum)
    threshold: float | None = None
    message: str = ""
    data: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        d = {"time": self.time, "event": self.kind, "state": self.state.value, "statistic": self.statistic,
             "threshold": self.threshold, "message": self.message}
        d.update(self.data)
        return d


@dataclass(frozen=True)
class ThresholdRule:
    """``threshold(t) = base + slope · |t − t_center|`` (signal units)."""

    mode: str                 # "auto" | "fixed"
    base: float
    slope: float = 0.0
    t_center: float = 0.0
    details: dict[str, Any] = field(default_factory=dict)

    def at(self, t: float | np.ndarray) -> Any:
        return self.base + self.slope * np.abs(np.asarray(t, dtype=float) - self.t_center)

    def as_dict(self) -> dict[str, Any]:
        d = {"mode": self.mode, "base": self.base, "slope_per_s": self.slope, "t_center": self.t_center}
        d.update(self.details)
        return d


def fixed_threshold(value: float) -> ThresholdRule:
    if not (np.isfinite(value) and value > 0):
        raise OptionError(f"threshold: expected a positive number in the signal's units or 'auto', got {value!r}")
    return ThresholdRule("fixed", float(value))


def evaluation_times(origin: float, first: float, last: float, every: float) -> np.ndarray:
    """``origin + k·every`` for the integers k with ``first ≤ t_k ≤ last`` (to 1e-9·every)."""
    eps = 1e-9 * every
    k0 = int(np.ceil((first - origin) / every - 1e-9))
    k1 = int(np.floor((last - origin) / every + 1e-9))
    if k1 < k0:
        return np.empty(0)
    t = origin + every * np.arange(k0, k1 + 1)
    return t[(t >= first - eps) & (t <= last + eps)]


def window_mae(t: np.ndarray, actual: np.ndarray, forecast: np.ndarray, eval_times: np.ndarray,
               window: float, *, eps: float, min_samples: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """MAE over ``(t_k − window, t_k]`` for each evaluation time (sklearn, one call per window size).

    Returns ``(mae, n)``; windows with fewer than ``min_samples`` samples get NaN.
    """
    from sklearn.metrics import mean_absolute_error

    eval_times = np.asarray(eval_times, dtype=float)
    lo = np.searchsorted(t, eval_times - window + eps, side="right")
    hi = np.searchsorted(t, eval_times + eps, side="right")
    n = hi - lo
    mae = np.full(eval_times.size, np.nan)
    for size in np.unique(n):
        if size < max(1, min_samples):
            continue
        sel = np.flatnonzero(n == size)
        idx = lo[sel][None, :] + np.arange(size)[:, None]          # (size, windows)
        mae[sel] = mean_absolute_error(actual[idx], forecast[idx], multioutput="raw_values")
    return mae, n


def _max_window_slope(t: np.ndarray, x: np.ndarray, period: float, order: int, window: float) -> float:
    """Largest mean of |dx/dt| over a window of the fitted Fourier series (one period, circular)."""
    coef, _ = fit_fourier(t, x, period, order)
    dt = float(np.median(np.diff(t)))
    n = max(int(round(period / dt)), 8)
    grid = np.arange(n) * (period / n)
    k = np.arange(1, order + 1) * (2 * np.pi / period)
    A = fourier_design(grid, period, order)
    dA = np.zeros_like(A)
    dA[:, 1::2] = -A[:, 2::2] * k           # d/dt cos = -k sin
    dA[:, 2::2] = A[:, 1::2] * k            # d/dt sin =  k cos
    speed = np.abs(dA @ coef)
    m = max(1, min(n, int(round(window / (period / n)))))
    csum = np.concatenate([[0.0], np.cumsum(np.concatenate([speed, speed[:m]]))])
    return float(np.max((csum[m:m + n] - csum[:n]) / m))


def auto_threshold(t: np.ndarray, x: np.ndarray, estimate: PeriodEstimate, *, model: str, order: int,
                   window: float, every: float, k: float = 2.0, floor: float = 0.01, z: float = 4.0,
                   validation_fraction: float = 2 / 3, seed: int = 0,
                   fit: Callable[..., Forecaster] = fit_forecaster) -> ThresholdRule:
    """Threshold from the validation error of the training data (rule in the module docstring).

    ``t, x`` is the training window and ``estimate`` its :func:`dominant_period`.  The
    validation model is fitted on the first ``validation_fraction`` of the window (its own
    refined period) and scored on the rest with windows of ``window`` s every ``every`` s.
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    split = t[0] + validation_fraction * (t[-1] - t[0])
    fit_mask = t <= split
    t_fit, x_fit = t[fit_mask], x[fit_mask]
    t_val, x_val = t[~fit_mask], x[~fit_mask]
    if t_val.size < 2 or t_fit.size < 16:
        raise TrainingError(f"training window of {t.size} samples is too short to hold out a validation part")
    details: dict[str, Any] = {}
    try:
        est_v = dominant_period(t_fit, x_fit, order=order, min_cycles=1.0)
        period_v = est_v.period
        details["validation_period_s"] = period_v
    except TrainingError as exc:        # too few cycles in the fit part: use the full-window period
        period_v = estimate.period
        details["validation_period_s"] = period_v
        details["validation_note"] = f"validation period from the full window ({exc})"
    model_v = fit(model, t_fit, x_fit, period_v, order=order, seed=seed)
    pred_v = model_v.predict(t_val)
    dt = float(np.median(np.diff(t)))
    eps = 1e-6 * dt
    held = float(t_val[-1] - split)
    w = min(window, held)
    times = evaluation_times(split, split + w, float(t_val[-1]), every)
    if times.size == 0:
        times = np.array([float(t_val[-1])])
    mae, _ = window_mae(t_val, x_val, pred_v, times, w, eps=eps)
    mae = mae[np.isfinite(mae)]
    V = float(mae.max()) if mae.size else float(np.mean(np.abs(pred_v - x_val)))
    A = estimate.amplitude
    G = _max_window_slope(t, x, estimate.period, min(order, estimate.order), window)
    base = max(k * V, floor * A)
    sigma = estimate.period_stderr if np.isfinite(estimate.period_stderr) else 0.0
    slope = z * G * sigma / estimate.period
    details.update({
        "rule": "max(k*V, floor*A) + z*G*|t - t_c|*sigma_P/P",
        "k": k, "floor": floor, "z": z, "validation_fraction": validation_fraction,
        "validation_split_s": split, "validation_windows": int(mae.size),
        "validation_mae_max": V, "validation_mae_mean": float(mae.mean()) if mae.size else V,
        "validation_fit_seconds": model_v.fit_seconds,
        "amplitude": A, "max_window_slope": G, "period_stderr_s": sigma,
        "term_validation": k * V, "term_floor": floor * A,
    })
    return ThresholdRule("auto", float(base), float(slope), float(estimate.t_center), details)


class Detector:
    """The state machine, and the one place where an alarm is decided (:meth:`update`).

    :class:`monitor.stream.Monitor` feeds it one evaluation at a time.

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
        ev = Event(time, "alarm", State.ALARM, mae, threshold, ALARM_MESSAGE, {"reason": reason})
        if self.first_alarm is None:
            self.first_alarm = ev
        return ev


@dataclass(frozen=True)
class Crossing:
    """A CUSUM statistic passed its limit: at ``time``, on ``signal``, side ``+`` or ``-``.

    ``onset`` is the CUSUM's estimate of when the change began: the last time that
    statistic was zero.
    """

    time: float
    signal: str
    side: str
    statistic: float
    threshold: float
    onset: float


class SequentialDetector:
    """Latched alarms for the sequential (CUSUM) detector: one alarm episode per fault.

    ``STABLE`` → ``ALARM`` at the first :class:`Crossing` (event ``alarm``; the statistics
    restart from zero).  The alarm latches: further crossings extend the episode.  It
    clears (event ``clear``, → ``STABLE``) at the first evaluation ``clear_after`` s after
    the episode's last crossing, i.e. after that long a stretch in which the restarted
    statistics stayed below their limit: a growing fault or a deviation seen once per cycle
    keeps re-crossing and never flaps.  ``events`` receives each event.
    """

    def __init__(self, *, clear_after: float, emit: Callable[[list[Event]], None]):
        if not (clear_after > 0):
            raise OptionError(f"clear_after: expected a positive number of seconds, got {clear_after!r}")
        self.clear_after = float(clear_after)
        self._emit = emit
        self.state = State.TRAINING
        self.alarms = 0
        self.first_alarm: Event | None = None
        self.crossings = 0
        self._last_crossing: float | None = None
        self._quiet_since = -np.inf

    def trained(self, time: float, threshold: float, info: dict[str, Any]) -> None:
        self.state = State.STABLE
        self._quiet_since = float(time)
        self._emit([Event(time, "trained", State.TRAINING, None, threshold, "model fitted", dict(info)),
                    Event(time, "stable", State.STABLE, None, threshold, "state 1: monitoring with the fitted model")])

    def crossing(self, c: Crossing) -> None:
        self.crossings += 1
        self._last_crossing = c.time
        if self.state is State.ALARM:
            return
        self.state = State.ALARM
        self.alarms += 1
        ev = Event(c.time, "alarm", State.ALARM, c.statistic, c.threshold, ALARM_MESSAGE,
                   {"reason": "cusum", "signal": c.signal, "side": c.side, "onset": c.onset,
                    "episode": self.alarms})
        if self.first_alarm is None:
            self.first_alarm = ev
        self._emit([ev])

    def tick(self, time: float) -> None:
        """An evaluation time passed: clear a latched alarm after ``clear_after`` s without a crossing."""
        if self.state is State.ALARM and self._last_crossing is not None \
                and time - self._last_crossing >= self.clear_after - 1e-9:
            self.state = State.STABLE
            self._quiet_since = float(time)
            self._emit([Event(time, "clear", State.STABLE, None, None,
                              f"no CUSUM crossing for {self.clear_after:g} s: alarm episode {self.alarms} ended")])

    def quiet_since(self, time: float) -> bool:
        """True when there has been no alarm from ``time`` until now (data there are healthy)."""
        return self.state is State.STABLE and time >= self._quiet_since - 1e-9

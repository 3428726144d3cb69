"""The mae detector's numerics: evaluation times, the windowed MAE and its threshold rule.

The state machine and the detector itself are in :mod:`monitor.mae`.

Evaluation
    At the evaluation times ``t_k = t_fit + k·every`` (``t_fit`` the end of the data the
    model was fitted on; the first ``k`` whose window lies wholly after ``t_fit``) the
    detector takes the samples of the newest window ``(t_k − window, t_k]`` and computes
    ``MAE = mean |x − forecast|`` with :func:`sklearn.metrics.mean_absolute_error` (the
    paper's eq. 14).  The evaluation times depend only on the data, never on when the
    data arrived, so following a live file and replaying the finished file give the same
    evaluations.

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
from typing import Any, Callable

import numpy as np

from .errors import OptionError, TrainingError
from .forecasters import Forecaster, fit_forecaster
from .spectrum import PeriodEstimate, dominant_period, fourier_design, fit_fourier

__all__ = [
    "ThresholdRule",
    "auto_threshold",
    "evaluation_times",
    "fixed_threshold",
    "window_mae",
]


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

"""Keeping the forecast's phase locked to the data: a periodic template and a phase tracker.

A fitted forecaster (Prophet with flat growth, or the harmonic series) is a periodic
function of time, ``f(t + P) = f(t)``.  Its period ``P`` is only known to ``σ_P``, so the
forecast slides against the data by ``(t − t_c)·σ_P/P``: after an hour with σ = 5 mm of
noise that is tenths of a second, and every detector that compares ``x`` with ``f(t)``
loses sensitivity with time.  The monitor therefore compares with ``f(t − τ(t))`` and
estimates the time shift ``τ`` from data already confirmed healthy.

:class:`PeriodicTemplate`
    The forecaster sampled once over one period (``points`` per period, one ``predict``
    call) and interpolated with a periodic cubic spline (:class:`scipy.interpolate.CubicSpline`),
    so the forecast and its slope ``f'`` are cheap at any time, on or off the sample grid.

:class:`PhaseTracker`
    A Kalman filter on the state ``(τ, τ̇)``: ``τ̇`` is the relative period error, and
    ``τ`` follows a continuous white-noise-acceleration model with intensity ``q``.
    Linearised, ``x(t) ≈ f(t − τ_u) − f'(t − τ_u)·(τ − τ_u)`` around the shift ``τ_u`` in
    use, so each sample gives a linear measurement of ``τ`` with variance ``σ²/f'²``.
    Blocks of samples are folded in at once (information form).  The prior comes from the
    training fit: ``τ = 0`` at its centre, ``τ̇ ~ N(0, (σ_P/P)²)``.

    ``q = R / T⁴`` with ``R = σ² / (mean f'² · rate)`` the measurement noise per unit time
    makes the steady-state filter a second-order loop with natural frequency ``1/T``
    (``T`` = ``track_time``), whatever the noise level: a phase drift that builds up over
    much more than ``T`` is followed (absorbed), a faster one is not.  Only a pure time
    shift can be absorbed; a change of the waveform's shape is never in the tracker's
    span.

    While the detector is in alarm the tracker is not updated (a fault must not be learnt),
    and its prediction runs on with the last healthy rate.  The variance it reports stops
    growing at ``variance_horizon`` (the longest gap between updates in healthy operation,
    ``guard + block``): otherwise, over a long alarm, the growing phase uncertainty would
    shrink the standardised residuals until the CUSUM fell quiet and the alarm cleared
    while the fault persisted.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["PeriodicTemplate", "PhaseTracker"]


class PeriodicTemplate:
    """``f(t)`` and ``f'(t)`` of a periodic forecaster, from one period of its predictions."""

    def __init__(self, forecaster, *, points: int = 8192):
        from scipy.interpolate import CubicSpline

        self.period = float(forecaster.period)
        self.origin = float(forecaster.train_start)
        phase = np.arange(points) * (self.period / points)
        values = np.asarray(forecaster.predict_direct(self.origin + phase), dtype=float)
        self._spline = CubicSpline(np.append(phase, self.period), np.append(values, values[0]),
                                   bc_type="periodic")
        self._slope = self._spline.derivative()

    def _phase(self, t: np.ndarray) -> np.ndarray:
        return np.mod(np.asarray(t, dtype=float) - self.origin, self.period)

    def value(self, t: np.ndarray) -> np.ndarray:
        return self._spline(self._phase(t))

    def slope(self, t: np.ndarray) -> np.ndarray:
        return self._slope(self._phase(t))


class PhaseTracker:
    """Kalman filter on ``(τ, τ̇)`` (see the module docstring); times in seconds."""

    def __init__(self, t_ref: float, *, rate_std: float, shift_std: float, noise_per_second: float,
                 track_time: float, variance_horizon: float = math.inf):
        self.time = float(t_ref)
        self.variance_horizon = float(variance_horizon)
        self.mean = np.zeros(2)
        self.cov = np.diag([shift_std ** 2, rate_std ** 2])
        self.track_time = float(track_time)
        self.q = float(noise_per_second) / self.track_time ** 4
        self.updates = 0

    def _propagated(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        F = np.array([[1.0, dt], [0.0, 1.0]])
        Q = self.q * np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])
        return F @ self.mean, F @ self.cov @ F.T + (Q if dt > 0 else 0.0)

    def shift(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Predicted ``τ(t)`` and its variance (grown for at most ``variance_horizon`` s) for
        times at or after the last update."""
        d = np.asarray(t, dtype=float) - self.time
        m, c = self.mean, self.cov
        e = np.clip(d, -self.variance_horizon, self.variance_horizon)
        var = c[0, 0] + 2 * c[0, 1] * e + c[1, 1] * e * e + self.q * np.abs(e) ** 3 / 3
        return m[0] + m[1] * d, var

    def update(self, t: np.ndarray, slope: np.ndarray, residual: np.ndarray, shift_used: np.ndarray,
               variance: np.ndarray) -> None:
        """Fold in samples with ``residual = x − f(t − shift_used)`` and ``slope = f'(t − shift_used)``."""
        t = np.asarray(t, dtype=float)
        if t.size == 0:
            return
        end = float(t[-1])                           # the state is kept at the newest sample's time
        mean, cov = self._propagated(end - self.time)
        y = slope * shift_used - residual            # = slope·τ(t) + noise
        H = np.column_stack([slope, slope * (t - end)])
        w = 1.0 / variance
        info = np.linalg.inv(cov) + (H * w[:, None]).T @ H
        cov_new = np.linalg.inv(info)
        mean_new = cov_new @ (np.linalg.solve(cov, mean) + (H * w[:, None]).T @ y)
        self.mean, self.cov, self.time = mean_new, 0.5 * (cov_new + cov_new.T), end
        self.updates += 1

    @property
    def rate(self) -> float:
        return float(self.mean[1])

    def as_dict(self) -> dict[str, float]:
        return {"time": self.time, "shift_s": float(self.mean[0]), "rate": float(self.mean[1]),
                "shift_std_s": math.sqrt(max(self.cov[0, 0], 0.0)), "rate_std": math.sqrt(max(self.cov[1, 1], 0.0)),
                "track_time_s": self.track_time, "updates": self.updates}

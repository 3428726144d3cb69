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

__all__ = ["PeriodicTemplate", "PhaseTracker", "ShapeCorrection"]


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
    """Kalman filter on ``(τ, τ̇, τ̈)`` (see the module docstring); times in seconds."""

    def __init__(self, t_ref: float, *, rate_std: float, shift_std: float, noise_per_second: float,
                 track_time: float, variance_horizon: float = math.inf, acceleration_std: float | None = None):
        self.time = float(t_ref)
        self.variance_horizon = float(variance_horizon)
        self.mean = np.zeros(3)
        self.track_time = float(track_time)
        if acceleration_std is None:
            acceleration_std = rate_std / self.track_time
        self.cov = np.diag([shift_std ** 2, rate_std ** 2, acceleration_std ** 2])
        # white jerk of intensity q: a third-order loop with natural frequency 1/T
        self.q = float(noise_per_second) / self.track_time ** 6
        self.updates = 0

    def _transition(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        F = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
        a = abs(dt)
        Q = self.q * np.array([[a ** 5 / 20, a ** 4 / 8, a ** 3 / 6],
                               [a ** 4 / 8, a ** 3 / 3, a ** 2 / 2],
                               [a ** 3 / 6, a ** 2 / 2, a]])
        return F, Q

    def _propagated(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        F, Q = self._transition(dt)
        return F @ self.mean, F @ self.cov @ F.T + Q

    def shift(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Predicted ``τ(t)`` and its variance (grown for at most ``variance_horizon`` s) for
        times at or after the last update."""
        d = np.asarray(t, dtype=float) - self.time
        m, c = self.mean, self.cov
        e = np.clip(d, -self.variance_horizon, self.variance_horizon)
        h = np.stack([np.ones_like(e), e, 0.5 * e * e])            # (3, n): ∂τ(t)/∂state
        var = np.einsum("in,ij,jn->n", h, c, h) + self.q * np.abs(e) ** 5 / 20
        return m[0] + m[1] * d + 0.5 * m[2] * d * d, var

    def update(self, t: np.ndarray, slope: np.ndarray, residual: np.ndarray, shift_used: np.ndarray,
               variance: np.ndarray) -> None:
        """Fold in samples with ``residual = x − f(t − shift_used)`` and ``slope = f'(t − shift_used)``."""
        t = np.asarray(t, dtype=float)
        if t.size == 0:
            return
        end = float(t[-1])                           # the state is kept at the newest sample's time
        mean, cov = self._propagated(end - self.time)
        y = slope * shift_used - residual            # = slope·τ(t) + noise
        d = t - end
        H = np.column_stack([slope, slope * d, slope * 0.5 * d * d])
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
                "acceleration_per_s": float(self.mean[2]),
                "shift_std_s": math.sqrt(max(self.cov[0, 0], 0.0)), "rate_std": math.sqrt(max(self.cov[1, 1], 0.0)),
                "track_time_s": self.track_time, "updates": self.updates}


class ShapeCorrection:
    """A slowly learnt correction of a periodic template's waveform (signal units).

    The template is fitted once on the training window; a healthy machine's waveform can
    still change slowly afterwards (a rotating crank's energy, and so its speed profile,
    drifts with the integrator's error; a real machine warms up).  The residual this leaves
    is periodic with the motion, not white, and a CUSUM with a small reference integrates
    it into a false alarm however the noise scale is set.  The correction removes it:
    ``bins`` values over one period of the template's phase, each the exponentially
    forgetting average (time constant ``time_constant`` s of data) of the residuals of
    healthy samples at that phase, with linear (hat) weights so the correction is
    continuous.  Samples are folded in by block, by the same rule as the phase tracker
    (quiet, older than the guard), so a fault is not learnt before it is detected.

    A bin's average is divided by at least the weight it holds after one time constant, so
    the correction grows from zero like an exponential average instead of starting from one
    noisy sample.  ``noise_ratio`` is the variance the correction adds to a residual, relative
    to the residual's own (``Σw²/(Σw)²`` of a bin's weights, averaged over bins, about
    ``block/(2·time_constant)`` per sample a bin gets per block): the residual's scale is
    widened by it so the CUSUM's calibration holds.
    """

    def __init__(self, period: float, origin: float, *, bins: int, time_constant: float, sample_step: float):
        self.period = float(period)
        self.origin = float(origin)
        self.bins = int(bins)
        self.time_constant = float(time_constant)
        # a bin's weight once a whole time constant of data is in: the average is divided by at
        # least this, so it starts from zero (an exponential average) instead of from one noisy sample
        self._full = self.time_constant / (float(sample_step) * self.bins)
        self._s0 = np.zeros(self.bins)     # Σ w   (decayed)
        self._s1 = np.zeros(self.bins)     # Σ w r (decayed)
        self._s2 = np.zeros(self.bins)     # Σ w²  (decayed twice as fast)
        self._values = np.zeros(self.bins)
        self.time: float | None = None
        self.updates = 0

    def _weights(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        u = np.mod(np.asarray(t, dtype=float) - self.origin, self.period) * (self.bins / self.period)
        i0 = np.floor(u).astype(np.int64) % self.bins
        w1 = u - np.floor(u)
        return i0, (i0 + 1) % self.bins, w1

    def value(self, t: np.ndarray) -> np.ndarray:
        i0, i1, w1 = self._weights(t)
        return (1.0 - w1) * self._values[i0] + w1 * self._values[i1]

    def update(self, t: np.ndarray, residual: np.ndarray) -> None:
        """Fold in residuals from the template (``x − f(t − τ)``, without the correction) at
        template times ``t`` (data time minus the phase shift used)."""
        t = np.asarray(t, dtype=float)
        r = np.asarray(residual, dtype=float)
        ok = np.isfinite(r)
        if not ok.any():
            return
        t, r = t[ok], r[ok]
        end = float(np.max(t))
        if self.time is not None and self.time_constant > 0:
            decay = math.exp(-max(end - self.time, 0.0) / self.time_constant)
            self._s0 *= decay
            self._s1 *= decay
            self._s2 *= decay * decay
        self.time = end if self.time is None else max(self.time, end)
        i0, i1, w1 = self._weights(t)
        w0 = 1.0 - w1
        n = self.bins
        self._s0 += np.bincount(i0, w0, n) + np.bincount(i1, w1, n)
        self._s1 += np.bincount(i0, w0 * r, n) + np.bincount(i1, w1 * r, n)
        self._s2 += np.bincount(i0, w0 * w0, n) + np.bincount(i1, w1 * w1, n)
        self._values = self._s1 / np.maximum(self._s0, self._full)
        self.updates += 1

    @property
    def noise_ratio(self) -> float:
        return float(np.mean(self._s2 / np.maximum(self._s0, self._full) ** 2))

    def as_dict(self) -> dict[str, float]:
        return {"bins": self.bins, "time_constant_s": self.time_constant, "updates": self.updates,
                "largest_correction": float(np.max(np.abs(self._values))), "noise_ratio": self.noise_ratio}

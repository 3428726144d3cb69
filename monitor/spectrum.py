"""Fundamental period of the training window: FFT estimate, then least-squares refinement.

1. **FFT.**  The samples are put on a uniform grid (linear interpolation, only needed when
   rows were skipped), the mean is removed, a Hann window applied and the series
   zero-padded to ``pad_factor`` times its length (at least) before ``numpy.fft.rfft``.
   The fundamental is the highest peak of the amplitude spectrum between one cycle per
   window (``1/T``) and the Nyquist frequency.  Zero-padding interpolates the spectrum but
   cannot beat the resolution ``1/T`` of a window of length ``T`` (0.11 Hz for 9 s: ±3 % on
   a 3 s period, i.e. a full period of phase error after 30 cycles).

2. **Refinement.**  For a trial period ``P`` the samples are fitted by least squares with
   a Fourier series of order ``K``::

       x(t) ≈ a0 + Σ_{k=1..K} [a_k cos(2πkt/P) + b_k sin(2πkt/P)]

   and the residual sum of squares ``S(P)`` is minimised over ``P``: first a scan of a
   low-order fit (``K = min(order, 5)``, 25 frequencies across ± one FFT bin), then
   Brent's bounded method (:func:`scipy.optimize.minimize_scalar`) on the full-order
   residual around the best scan point.  The standard error of ``P`` follows from the
   Jacobian of the nonlinear fit at the optimum (coefficients and ``P`` together),
   ``cov = s² (JᵀJ)⁻¹``, ``s² = S/(n − 2K − 2)``.

3. **Fundamental.**  The highest peak need not be the fundamental: a crank driven at 1 rev/s
   gives a motor torque whose second harmonic (0.5 s) is stronger than its first (1 s).  A
   series of period ``P`` cannot represent a signal of period ``mP``; one of period ``mP``
   represents both.  So every multiple ``mP`` (``m = 2 ..`` :data:`MAX_HARMONIC`, while the
   window holds ``min_cycles`` of it) is fitted with the same highest frequency (order
   ``mK``, as far as Nyquist and the samples allow) on the window's first
   :data:`SUBHARMONIC_SAMPLES` samples at most (the default 9 s window at 0.01 s has 901;
   the bound keeps a long training window's test to a fraction of a second), and the
   smallest ``m`` whose residual sum of squares is
   below :data:`SUBHARMONIC_GAIN` of ``S(P)`` (residual RMS halved, at least), by more
   than :data:`SUBHARMONIC_SHARE` of the signal's own sum of squares about its mean,
   becomes the period, refined by Brent's method again around ``mP``, and tested in turn.
   For a signal of period ``P`` the longer series only fits noise: ``S`` falls by the
   share of the extra coefficients, ``2(m-1)K/n`` (under half for every ``m`` the samples
   allow), so the period stays ``P``.  The second condition keeps exact data exact: there
   ``S(P)`` is the integrator's error (1e-10 of the signal's sum of squares for Table 1's
   x2), and a longer series can halve that by fitting its slow drift; a generated
   four-bar's noise-free validation window did so.  :attr:`PeriodEstimate.harmonic` says
   which harmonic the FFT's peak was.

:func:`fourier_design` and :func:`fit_fourier` are shared with the harmonic forecaster.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import TrainingError

__all__ = ["MAX_HARMONIC", "PeriodEstimate", "SUBHARMONIC_GAIN", "SUBHARMONIC_SAMPLES", "SUBHARMONIC_SHARE",
           "dominant_period", "fit_fourier", "fourier_design", "max_fourier_order"]

#: A multiple ``mP`` of the FFT's period becomes the period when its Fourier series leaves less
#: than this share of the residual sum of squares of period ``P`` (module docstring, step 3).
SUBHARMONIC_GAIN = 0.25
#: ... and when what it explains beyond ``P`` is more than this share of the signal's sum of
#: squares about its mean (a component of about 1.4 % of the signal's RMS).
SUBHARMONIC_SHARE = 1e-4
#: The largest ``m`` tried, and the most samples the test fits (module docstring, step 3).
MAX_HARMONIC = 6
SUBHARMONIC_SAMPLES = 4000


def fourier_design(t: np.ndarray, period: float, order: int) -> np.ndarray:
    """Columns ``1, cos(2πkt/P), sin(2πkt/P)`` for ``k = 1..order`` (shape ``(n, 2·order+1)``).

    The harmonics come from powers of ``exp(2πit/P)`` (complex multiplication), 3-5x faster
    than ``order`` calls of cos and sin; the rounding error grows like ``order·eps``.
    """
    t = np.asarray(t, dtype=float)
    e = np.exp((2j * np.pi / period) * t)
    powers = np.empty((t.size, order), dtype=complex)
    if order:
        powers[:, 0] = e
    for k in range(1, order):
        np.multiply(powers[:, k - 1], e, out=powers[:, k])
    out = np.empty((t.size, 2 * order + 1))
    out[:, 0] = 1.0
    out[:, 1::2] = powers.real
    out[:, 2::2] = powers.imag
    return out


def max_fourier_order(period: float, dt: float, n: int) -> int:
    """Highest usable Fourier order: harmonics below Nyquist, at least 2 samples per coefficient."""
    by_nyquist = int(np.floor(0.5 * period / dt)) - 1
    by_samples = (n // 2 - 1) // 2
    return max(1, min(by_nyquist, by_samples))


def fit_fourier(t: np.ndarray, x: np.ndarray, period: float, order: int) -> tuple[np.ndarray, float]:
    """Least-squares Fourier coefficients ``[a0, a1, b1, ...]`` and the residual sum of squares.

    Solved by the normal equations (the basis is close to orthogonal over more than a
    period, so ``AᵀA`` is well conditioned; 40x faster than an SVD here), falling back to
    ``numpy.linalg.lstsq`` when ``AᵀA`` is singular.
    """
    A = fourier_design(t, period, order)
    try:
        coef = np.linalg.solve(A.T @ A, A.T @ x)
    except np.linalg.LinAlgError:
        coef = np.linalg.lstsq(A, x, rcond=None)[0]
    r = x - A @ coef
    return coef, float(r @ r)


@dataclass(frozen=True)
class PeriodEstimate:
    """Result of :func:`dominant_period` (times in the unit of ``t``, normally seconds)."""

    fft_period: float
    period: float
    period_stderr: float
    fft_bin_width: float          # 1/T, Hz
    order: int                    # Fourier order used for the refinement
    residual_rms: float           # RMS residual of the refined fit
    amplitude: float              # half the peak-to-peak range of the samples
    t_center: float               # mean sample time: the phase is anchored here
    frequencies: np.ndarray = field(repr=False)
    spectrum: np.ndarray = field(repr=False)   # Hann-window amplitude spectrum
    harmonic: int = 1             # the FFT's highest peak is this harmonic of ``period``

    @property
    def fft_frequency(self) -> float:
        return 1.0 / self.fft_period

    @property
    def frequency(self) -> float:
        return 1.0 / self.period

    def as_dict(self) -> dict[str, float | int]:
        return {"fft_s": self.fft_period, "refined_s": self.period, "refined_stderr_s": self.period_stderr,
                "fft_bin_width_hz": self.fft_bin_width, "refine_order": self.order,
                "residual_rms": self.residual_rms, "amplitude": self.amplitude, "fft_harmonic": self.harmonic}


def _uniform(t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, float]:
    dt = float(np.median(np.diff(t)))
    n = int(round((t[-1] - t[0]) / dt)) + 1
    grid = t[0] + dt * np.arange(n)
    if n == t.size and np.allclose(grid, t, rtol=0, atol=1e-6 * dt):
        return x, dt
    return np.interp(grid, t, x), dt


def dominant_period(t: np.ndarray, x: np.ndarray, *, order: int = 30, pad_factor: int = 16,
                    min_cycles: float = 1.5) -> PeriodEstimate:
    """Estimate the fundamental period of ``x(t)`` by FFT and refine it by least squares.

    Parameters
    ----------
    t, x:
        Sample times (strictly increasing) and values of the training window.
    order:
        Fourier order of the refinement fit (capped so the highest harmonic stays below
        Nyquist and the fit has at least twice as many samples as coefficients).
    pad_factor:
        Zero-padding: the FFT length is the next power of two ≥ ``pad_factor · n``.
    min_cycles:
        The window must hold at least this many periods, else :class:`TrainingError`.
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(x, dtype=float)
    if t.shape != x.shape or t.ndim != 1:
        raise TrainingError(f"t and x must be 1-D arrays of equal length, got shapes {t.shape} and {x.shape}")
    if t.size < 16:
        raise TrainingError(f"training window has {t.size} samples; at least 16 are needed for a period")
    if np.any(np.diff(t) <= 0):
        raise TrainingError("training sample times must be strictly increasing")
    amplitude = 0.5 * float(np.ptp(x))
    if not amplitude > 1e-12 * max(1.0, float(np.max(np.abs(x)))):
        raise TrainingError(f"the signal is constant ({float(x[0])!r}) in the training window; it has no period")
    xu, dt = _uniform(t, x)
    n = xu.size
    span = n * dt
    nfft = 1 << int(np.ceil(np.log2(max(n * pad_factor, n))))
    spec = np.abs(np.fft.rfft((xu - xu.mean()) * np.hanning(n), nfft)) * (2.0 / np.hanning(n).sum())
    freqs = np.fft.rfftfreq(nfft, dt)
    band = freqs >= 1.0 / span
    if not band.any():
        raise TrainingError("training window too short for a spectrum")
    i = int(np.flatnonzero(band)[np.argmax(spec[band])])
    f_fft = float(freqs[i])
    bin_width = 1.0 / span

    from scipy.optimize import minimize_scalar

    K = min(int(order), max_fourier_order(1.0 / (f_fft + bin_width), dt, t.size))
    f_lo, f_hi = max(f_fft - bin_width, 0.5 * bin_width), f_fft + bin_width
    scan_f = np.linspace(f_lo, f_hi, 25)
    k_scan = min(K, 5)
    scan = [fit_fourier(t, x, 1.0 / f, k_scan)[1] for f in scan_f]
    j = int(np.argmin(scan))
    lo, hi = scan_f[max(j - 1, 0)], scan_f[min(j + 1, scan_f.size - 1)]
    res = minimize_scalar(lambda P: fit_fourier(t, x, P, K)[1], bounds=(1.0 / hi, 1.0 / lo),
                          method="bounded", options={"xatol": 1e-10 * (1.0 / f_fft)})
    period = float(res.x)
    harmonic = 1
    while True:          # step 3: a multiple of the period that the samples need
        m = _subharmonic(t[:SUBHARMONIC_SAMPLES], x[:SUBHARMONIC_SAMPLES], period, K, dt, min_cycles,
                         MAX_HARMONIC // harmonic)
        if m is None:
            break
        harmonic *= m
        K = min(int(order), max_fourier_order(harmonic / hi, dt, t.size))
        res = minimize_scalar(lambda P: fit_fourier(t, x, P, K)[1], bounds=(harmonic / hi, harmonic / lo),
                              method="bounded", options={"xatol": 1e-10 * (harmonic / f_fft)})
        period = float(res.x)
    if span / period < min_cycles:
        raise TrainingError(f"training window of {span:g} s holds {span / period:.2f} periods of "
                            f"{period:.4g} s; at least {min_cycles:g} are needed — lengthen the window")
    coef, sse = fit_fourier(t, x, period, K)
    stderr = _period_stderr(t, period, K, coef, sse)
    return PeriodEstimate(
        fft_period=1.0 / f_fft, period=period, period_stderr=stderr, fft_bin_width=bin_width, order=K,
        residual_rms=float(np.sqrt(sse / t.size)), amplitude=amplitude, t_center=float(t.mean()),
        frequencies=freqs, spectrum=spec, harmonic=harmonic)


def _subharmonic(t: np.ndarray, x: np.ndarray, period: float, order: int, dt: float, min_cycles: float,
                 most: int) -> int | None:
    """The smallest ``m`` in ``2 .. most`` whose period ``m * period`` explains ``x`` much better
    than ``period`` does (module docstring, step 3), or None."""
    span = t[-1] - t[0] + dt
    sse = fit_fourier(t, x, period, order)[1]
    total = float(np.sum(np.square(x - x.mean())))
    if not sse > SUBHARMONIC_SHARE * total:
        return None
    for m in range(2, min(most, int(span / (min_cycles * period))) + 1):
        k = min(m * order, max_fourier_order(m * period, dt, t.size))
        longer = fit_fourier(t, x, m * period, k)[1]
        if longer < SUBHARMONIC_GAIN * sse and sse - longer > SUBHARMONIC_SHARE * total:
            return m
    return None


def _period_stderr(t: np.ndarray, period: float, order: int, coef: np.ndarray, sse: float) -> float:
    A = fourier_design(t, period, order)
    h = 1e-7 * period
    dA = (fourier_design(t, period + h, order) - fourier_design(t, period - h, order)) / (2 * h)
    J = np.column_stack([A, dA @ coef])
    dof = max(t.size - J.shape[1], 1)
    s2 = sse / dof
    e = np.zeros(J.shape[1])
    e[-1] = 1.0
    try:
        var = s2 * np.linalg.solve(J.T @ J, e)[-1]        # last diagonal entry of s²(JᵀJ)⁻¹
    except np.linalg.LinAlgError:
        return float("nan")
    return float(np.sqrt(max(var, 0.0)))

"""Page's CUSUM on standardised residuals, designed by its false-alarm rate.

For standardised residuals ``z`` (zero mean, unit variance while healthy) the two one-sided
statistics are::

    S⁺_i = max(0, S⁺_{i−1} + z_i − k)        S⁻_i = max(0, S⁻_{i−1} − z_i − k)

and an alarm is raised when either exceeds ``h``.  ``k = δ/2`` is tuned to a mean shift of
``δ`` standard deviations (the design shift); ``h`` sets the false-alarm rate.

Calibration (:func:`cusum_threshold`)
    Siegmund's approximation of the in-control average run length of a one-sided CUSUM
    on independent N(0, 1) residuals::

        ARL₀(h) ≈ (exp(2k·b) − 2k·b − 1) / (2k²),   b = h + 1.166

    is solved for ``h`` with :func:`scipy.optimize.brentq`.  A monitor of ``m`` signals runs
    ``2m`` one-sided statistics; the requested rate is split evenly among them (a union
    bound: the rate of "any of them alarms" is at most the sum).  The rate is per hour of
    data time, converted with the sampling step: ``ARL₀ = 3600 / (rate · dt)`` samples.
    :func:`cusum_run_length` measures the run length by Monte Carlo, which the benchmark
    and the tests use to check the approximation.

:func:`cusum_path` advances the statistics over a batch with no Python loop: with
``C_i = Σ_{j≤i} w_j`` the recursion ``S_i = max(0, S_{i−1} + w_i)`` from ``S_0`` equals
``C_i − min(−S_0, min_{j≤i} C_j)`` (the Lindley form).
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["SIEGMUND_SHIFT", "arl_siegmund", "cusum_path", "cusum_run_length", "cusum_threshold"]

#: Siegmund's correction of the boundary for the overshoot of a Gaussian random walk.
SIEGMUND_SHIFT = 1.166


def arl_siegmund(h: float, k: float) -> float:
    """In-control average run length (samples) of a one-sided CUSUM with reference ``k``, limit ``h``."""
    b = 2.0 * k * (h + SIEGMUND_SHIFT)
    if k <= 0:
        return (h + SIEGMUND_SHIFT) ** 2
    return (math.expm1(b) - b) / (2.0 * k * k)


def cusum_threshold(arl0: float, k: float) -> float:
    """The limit ``h`` whose one-sided in-control ARL (Siegmund) is ``arl0`` samples."""
    from scipy.optimize import brentq

    if not arl0 > 1:
        raise ValueError(f"the in-control run length must exceed 1 sample, got {arl0!r}")
    if arl_siegmund(0.0, k) >= arl0:
        return 0.0
    high = 1.0
    while arl_siegmund(high, k) < arl0:
        high *= 2.0
    return float(brentq(lambda h: math.log(arl_siegmund(h, k)) - math.log(arl0), 0.0, high, xtol=1e-10))


def cusum_path(w: np.ndarray, start: float) -> np.ndarray:
    """``S_i = max(0, S_{i−1} + w_i)`` for every ``i`` from ``S_0 = start`` (vectorised)."""
    c = np.cumsum(np.asarray(w, dtype=float))
    return c - np.minimum(np.minimum.accumulate(c), -float(start))


def cusum_run_length(h: float, k: float, *, chains: int = 2000, max_samples: int = 200_000,
                     seed: int = 0, block: int = 4096) -> np.ndarray:
    """Monte Carlo run lengths (samples) of a one-sided CUSUM on N(0, 1) data.

    Chains still running after ``max_samples`` get ``max_samples`` (the mean is then a lower
    bound).  Used to check :func:`arl_siegmund`.
    """
    rng = np.random.default_rng(seed)
    lengths = np.full(chains, max_samples, dtype=np.int64)
    state = np.zeros(chains)
    alive = np.ones(chains, dtype=bool)
    done = 0
    while done < max_samples and alive.any():
        n = min(block, max_samples - done)
        idx = np.flatnonzero(alive)
        w = rng.standard_normal((n, idx.size)) - k
        c = np.cumsum(w, axis=0)
        s = c - np.minimum(np.minimum.accumulate(c, axis=0), -state[idx])
        over = s > h
        hit = over.any(axis=0)
        first = np.argmax(over, axis=0)
        lengths[idx[hit]] = done + first[hit] + 1
        alive[idx[hit]] = False
        state[idx[~hit]] = s[-1, ~hit]
        done += n
    return lengths

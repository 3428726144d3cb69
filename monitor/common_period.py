"""One period for several monitored columns: the fundamental every column repeats with.

Columns of one mechanism need not show the same period.  A swinging crank's ``x2`` repeats
once per swing while its ``y2`` goes up and down twice (its period is half), and a column may
repeat only every second swing (its period is twice).  Each column's own estimate
(:func:`monitor.spectrum.dominant_period`) is right for that column; the mean of such
estimates is a period of none of them (issue 37: 2.2385 s, 4.4770 s → 2.3147 s, and a
false alarm right after training).

:func:`common_period` therefore looks for the **fundamental** ``T``: the shortest time every
column repeats with, the least common multiple of the columns' periods.  Column ``j`` repeats
``m_j = T / P_j`` times in it, a whole number.

1. **Ratios.**  With ``P`` the longest column period, the multiples ``T = kP`` (``k = 1 ..``
   :data:`MAX_MULTIPLE`) are tried in turn; the first for which every ``T / P_j`` is within
   :data:`RATIO_TOLERANCE` of a whole number ``m_j`` (``1 ≤ m_j ≤`` :data:`MAX_MULTIPLE`)
   is kept.  Columns with none (a ratio that is no ratio of small whole numbers) are refused
   with :class:`PeriodMismatchError`, naming the columns and their periods.
2. **Estimate.**  Each column then estimates the same quantity, ``T ≈ m_j P_j`` with standard
   error ``m_j σ_j``: their inverse-variance mean is ``T`` and its standard error.  (An
   inverse-variance mean of periods that are not the same period is never taken.)
3. **Check.**  Each column is fitted at ``T / m_j`` with the Fourier series of its own
   refinement; its residual sum of squares may exceed the one at its own period by
   :data:`RESIDUAL_GAIN` times at most, plus :data:`~monitor.spectrum.SUBHARMONIC_SHARE` of
   the column's sum of squares about its mean (so exact data stay exact).  A column that fails
   does not repeat with ``T``: refused, naming it.

Every column's model is then fitted at its own period ``T / m_j`` (the order it needs, no
more), and the phase tracker shifts all of them by one time shift.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from .errors import TrainingError
from .spectrum import SUBHARMONIC_SHARE, PeriodEstimate, fit_fourier

__all__ = ["CommonPeriod", "MAX_MULTIPLE", "PeriodMismatchError", "RATIO_TOLERANCE", "RESIDUAL_GAIN",
           "common_period"]

#: The most times a column may repeat within the common period (and the longest common period,
#: in units of the longest column period).
MAX_MULTIPLE = 6
#: ``T / P_j`` must be within this share of ``T`` of a whole number (1 %: the resolution of a
#: 9 s window's spectrum is 11 %, a refined period's error is under 0.1 % even with noise).
RATIO_TOLERANCE = 0.01
#: A column's residual at ``T / m_j`` may be this many times the one at its own period.
RESIDUAL_GAIN = 2.0


class PeriodMismatchError(TrainingError):
    """Monitored columns that share no period (exit 2): the message names them and their periods."""


@dataclass(frozen=True)
class CommonPeriod:
    """The fundamental ``period`` of several columns; column ``j`` repeats ``multiples[j]`` times in it."""

    names: tuple[str, ...]
    period: float
    stderr: float
    multiples: tuple[int, ...]

    @property
    def periods(self) -> tuple[float, ...]:
        """Each column's own period, ``period / multiple`` (commensurate by construction)."""
        return tuple(self.period / m for m in self.multiples)

    def as_dict(self) -> dict[str, Any]:
        return {"period_s": self.period, "stderr_s": self.stderr,
                "signals": {n: {"period_s": p, "repeats": m}
                            for n, p, m in zip(self.names, self.periods, self.multiples)}}


def _listing(names: Sequence[str], estimates: Sequence[PeriodEstimate]) -> str:
    return ", ".join(f"{n} {e.period:.6g} s" for n, e in zip(names, estimates))


def _multiples(periods: np.ndarray) -> tuple[float, np.ndarray] | None:
    longest = float(periods.max())
    for k in range(1, MAX_MULTIPLE + 1):
        T = k * longest
        m = np.rint(T / periods)
        if np.all((m >= 1) & (m <= MAX_MULTIPLE)) and np.all(np.abs(m * periods - T) <= RATIO_TOLERANCE * T):
            return T, m.astype(int)
    return None


def common_period(names: Sequence[str], estimates: Sequence[PeriodEstimate], t: np.ndarray | None = None,
                  X: np.ndarray | None = None) -> CommonPeriod:
    """The fundamental of the columns ``names`` (module docstring); with the samples ``t``, ``X``
    (one column per name) each column is checked to repeat with it.  Raises
    :class:`PeriodMismatchError` when they share no period."""
    names = tuple(names)
    periods = np.array([e.period for e in estimates], dtype=float)
    found = _multiples(periods)
    if found is None:
        raise PeriodMismatchError(
            f"the columns {_listing(names, estimates)} share no period: no time up to {MAX_MULTIPLE} times the "
            f"longest holds a whole number of each period (within {RATIO_TOLERANCE:.0%}); monitor them "
            "separately (one --signal each)")
    _, m = found
    fundamentals = m * periods
    err = np.array([mj * e.period_stderr for mj, e in zip(m, estimates)], dtype=float)
    ok = np.isfinite(err) & (err > 0)
    if ok.any():
        w = np.where(ok, 1.0 / np.where(ok, err, 1.0) ** 2, 0.0)
        T, stderr = float(w @ fundamentals / w.sum()), float(1.0 / math.sqrt(w.sum()))
    else:
        T, stderr = float(fundamentals.mean()), float("nan")
    result = CommonPeriod(names, T, stderr, tuple(int(v) for v in m))
    if t is not None and X is not None and len(names) > 1:
        for j, (name, est) in enumerate(zip(names, estimates)):
            x = X[:, j]
            own = fit_fourier(t, x, est.period, est.order)[1]
            shared = fit_fourier(t, x, result.periods[j], est.order)[1]
            slack = SUBHARMONIC_SHARE * float(np.sum(np.square(x - x.mean())))
            if shared > RESIDUAL_GAIN * own + slack:
                raise PeriodMismatchError(
                    f"the columns {_listing(names, estimates)} share no period: {name} does not repeat with the "
                    f"common period {T:.6g} s ({m[j]} × {result.periods[j]:.6g} s leaves "
                    f"{math.sqrt(shared / max(own, 1e-300)):.3g}× the residual of its own {est.period:.6g} s); "
                    "monitor them separately (one --signal each)")
    return result

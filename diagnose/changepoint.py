"""When did the data leave the healthy model?  A first estimate, before any hypothesis.

The healthy residual ``r = data - healthy simulation``, scaled column by column by the
noise level, gives ``z_k = sum_c (r_kc / sigma_c)^2``, which is chi-square with one degree
of freedom per column while the model holds.  A one-sided CUSUM for an increase of its
mean by ``shift`` (in units of the column count) marks the change when it passes ``limit``;
the onset is the last grid point where it was at zero before that.  The fits then search
the change time around this onset, so it only has to be close, not exact: exact for a jump
(lengths, noise-free), somewhat late for a change that grows slowly (masses, under noise).
"""
from __future__ import annotations

import numpy as np

__all__ = ["noise_levels", "onset"]


def noise_levels(residual: np.ndarray, floor: float) -> np.ndarray:
    """Per-column noise standard deviation of a healthy residual (rows x columns), at least ``floor``.

    The RMS about zero (the healthy model has no offset to remove); ``floor`` stands for the
    integrator's own error where the data are exact.
    """
    if residual.shape[0] == 0:
        return np.full(residual.shape[1], floor)
    return np.maximum(np.sqrt(np.mean(np.square(residual), axis=0)), floor)


def onset(scaled_residual: np.ndarray, shift: float = 1.0, limit: float = 50.0) -> int | None:
    """Row index of the change's onset in ``scaled_residual`` (rows x columns, unit noise), or None.

    Returns the row after the last zero of the CUSUM before its first crossing of
    ``limit`` (in units of one column's chi-square mean), None when it never crosses.
    """
    ncol = scaled_residual.shape[1]
    z = np.sum(np.square(scaled_residual), axis=1) / ncol
    s = 0.0
    last_zero = -1
    for i, zi in enumerate(z):
        s = max(0.0, s + zi - 1.0 - shift / 2.0)
        if s == 0.0:
            last_zero = i
        elif s > limit:
            return last_zero + 1
    return None

"""The sympy function a block expression's ``round`` builds: round half away from zero (C's
``round``), whose derivative is zero wherever it is defined (the Jacobians of a quantiser)."""
from __future__ import annotations

import math

import sympy as sp

__all__ = ["Round"]


class Round(sp.Function):
    """round(x): the nearest integer, halves away from zero; d/dx = 0 (almost everywhere)."""

    nargs = 1

    @classmethod
    def eval(cls, x):
        if x.is_Number:
            return sp.Integer(int(math.copysign(math.floor(abs(float(x)) + 0.5), float(x))))
        return None

    def fdiff(self, argindex=1):
        return sp.S.Zero

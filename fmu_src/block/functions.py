"""The sympy functions a block expression's ``round`` and ``quantise`` build: round half away
from zero (C's ``round``), whose derivative is zero wherever it is defined (the Jacobians of a
quantiser), and ``quantise(x, step)``: ``step round(x / step)``, or ``x`` itself when the step is 0
(no quantisation)."""
from __future__ import annotations

import math

import sympy as sp

__all__ = ["Round", "Quantise", "quantise_value"]


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


def quantise_value(x: float, step: float) -> float:
    """``step round(x / step)`` (halves away from zero), or ``x`` when ``step`` is 0."""
    if step == 0:
        return x
    v = x / step
    return step * math.copysign(math.floor(abs(v) + 0.5), v)


class Quantise(sp.Function):
    """quantise(x, step): x on the grid of ``step`` (step round(x / step)), or x when step = 0.
    d/dx = 0 on the grid (almost everywhere), 1 without one; d/dstep = round(x / step)."""

    nargs = 2

    @classmethod
    def eval(cls, x, step):
        if x.is_Number and step.is_Number:
            return sp.Float(quantise_value(float(x), float(step))) if step != 0 else x
        return None

    def fdiff(self, argindex=1):
        x, step = self.args
        if argindex == 1:
            return sp.Piecewise((sp.S.One, sp.Eq(step, 0)), (sp.S.Zero, True))
        return sp.Piecewise((sp.S.Zero, sp.Eq(step, 0)), (Round(x / step), True))

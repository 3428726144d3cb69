"""How a time is written in a message a user reads.

A grid time is computed as ``start + k*step`` in binary floating point, so its ``repr``
can carry round-off digits that mean nothing: ``189 * 0.01`` is ``1.8900000000000001``.
:func:`format_time` writes it with 12 significant digits, which drops that round-off
(about 1e-16 of the value, four orders of magnitude below the 12th digit) and still tells
every two grid times apart as long as the run has fewer than 1e11 steps (a run writes at
most 10,000,000 rows unless asked for more): ``1.89``, ``0.0001``, ``1000.0001``.
Rounding to the step's decimals would need the step wherever a time is printed; a fixed
number of significant digits does not.  Files keep the exact ``repr`` (exchange.csv,
run.json): this is for messages only.
"""
from __future__ import annotations

__all__ = ["TIME_DIGITS", "format_time"]

TIME_DIGITS = 12    # significant digits of a time in a message


def format_time(t: float) -> str:
    """``t`` in s as a user reads it: ``1.89`` for ``1.8900000000000001``, ``12`` for ``12.0``."""
    return f"{t:.{TIME_DIGITS}g}"

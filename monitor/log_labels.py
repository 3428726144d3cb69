"""Log-axis tick labels in plain text: ``10⁻³`` where matplotlib writes the mathtext ``$10^{-3}$``.

A log or symlog axis labels its ticks with :class:`~matplotlib.ticker.LogFormatterSciNotation`,
whose labels are mathtext.  The first mathtext a process draws builds matplotlib's mathtext parser
(pyparsing), about 0.15 s of CPU: a tenth of what the monitor's three figures cost a fresh
``fourbar-monitor``.  :func:`plain_log_labels` gives an axis the same formatter, its settings and
so its choice of ticks and labels, with each label written in Unicode (superscript digits, ``×``,
``−``), which the font draws like any text.  A label it cannot write so is left in mathtext.

Imports matplotlib: import this module only where figures are drawn.
"""
from __future__ import annotations

import re
from typing import Any

from matplotlib.ticker import LogFormatterSciNotation

__all__ = ["PlainLogFormatter", "plain_label", "plain_log_labels"]

_MATHTEXT = re.compile(r"\$\\mathdefault\{(.*)\}\$")
_POWER = re.compile(r"\^\{(-?[0-9]+)\}")
_SUPERSCRIPT = str.maketrans("0123456789-", "⁰¹²³⁴⁵⁶⁷⁸⁹⁻")


def plain_label(label: str) -> str:
    """``label`` (a :class:`LogFormatterSciNotation` label) in plain text: ``$\\mathdefault{10^{-3}}$``
    -> ``10⁻³``, ``$\\mathdefault{2\\times10^{4}}$`` -> ``2×10⁴``, ``$\\mathdefault{0}$`` -> ``0``;
    a minus as mathtext draws it (``−``); anything else is returned unchanged."""
    whole = _MATHTEXT.fullmatch(label)
    if whole is None:
        return label
    text = _POWER.sub(lambda m: m.group(1).translate(_SUPERSCRIPT), whole.group(1).replace(r"\times", "×"))
    if any(c in text for c in "\\{}^_$"):
        return label                      # more than powers and products: mathtext draws it
    return text.replace("-", "−")


class PlainLogFormatter(LogFormatterSciNotation):
    """:class:`LogFormatterSciNotation` whose labels are plain text (:func:`plain_label`)."""

    def __call__(self, x: float, pos: int | None = None) -> str:
        return plain_label(super().__call__(x, pos))


def plain_log_labels(axis: Any) -> None:
    """Label ``axis`` (a matplotlib Axis whose scale is set) in plain text: each of its major and
    minor formatters that is a :class:`LogFormatterSciNotation` (as log and symlog scales set
    them) is replaced by a :class:`PlainLogFormatter` with the same state."""
    for formatter, use in ((axis.get_major_formatter(), axis.set_major_formatter),
                           (axis.get_minor_formatter(), axis.set_minor_formatter)):
        if type(formatter) is LogFormatterSciNotation:
            plain = PlainLogFormatter.__new__(PlainLogFormatter)
            plain.__dict__.update(vars(formatter))          # base, linthresh, labelOnlyBase, ...
            use(plain)

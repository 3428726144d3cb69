"""How an option is declared and checked: :class:`Rule`, :func:`option` and :class:`Checked`.

A setting is a field of a frozen dataclass carrying a :class:`Rule` in its metadata: the
check (one message "<name>: expected <expected>, got <value>"), the parser of a
command-line value, and, for the settings the command line exposes, the flag, the help text
and the argument group.  :class:`~monitor.options.MonitorOptions` (what every detector
shares) and each detector's own settings class (``Detector.Settings``, a
:class:`DetectorSettings`) are declared this way, so :func:`monitor.options.add_arguments`
builds ``fourbar-monitor``'s arguments from the registered detectors' own declarations.
"""
from __future__ import annotations

import argparse
import math
from dataclasses import asdict, dataclass, field, fields
from typing import Any, Callable, ClassVar

from .errors import OptionError

__all__ = ["Checked", "DetectorSettings", "FRACTION", "NON_NEGATIVE", "RATE", "Rule", "at_least", "choice",
           "is_number", "option", "positive"]


def is_number(value: Any) -> bool:
    """A finite int or float (not a bool)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


@dataclass(frozen=True)
class Rule:
    """What one option accepts.

    ``accepts(value)`` decides; ``expected`` is the phrase of the message ("expected
    <expected>, got <value>"); ``parse`` turns command-line text into a value (it may raise
    ``ValueError``); ``choices`` lists the accepted values of a choice.
    """

    accepts: Callable[[Any], bool]
    expected: str
    parse: Callable[[str], Any] = float
    choices: tuple[str, ...] | Callable[[], tuple[str, ...]] | None = None    # a callable: asked when used
    metavar: str | None = None

    def problem(self, name: str, value: Any) -> str | None:
        return None if self.accepts(value) else f"{name}: expected {self.expected}, got {value!r}"

    def argparse_type(self) -> Callable[[str], Any]:
        """An argparse ``type``: the message names the value once; argparse adds the flag."""
        def convert(text: str) -> Any:
            try:
                value = self.parse(text)
            except ValueError:
                value = None
            if value is None or not self.accepts(value):
                raise argparse.ArgumentTypeError(f"expected {self.expected}, got {text!r}")
            return value
        return convert


def positive(unit: str) -> Rule:
    return Rule(lambda v: is_number(v) and v > 0, f"a positive number {unit}".rstrip())


def at_least(low: int) -> Rule:
    return Rule(lambda v: isinstance(v, int) and not isinstance(v, bool) and v >= low,
                f"an integer ≥ {low}", parse=int)


def choice(values: tuple[str, ...] | Callable[[], tuple[str, ...]]) -> Rule:
    """One of ``values`` (a callable: the values registered when asked, e.g. the models)."""
    def names() -> tuple[str, ...]:
        return values() if callable(values) else values

    class _Phrase:
        def __str__(self) -> str:
            return f"one of {', '.join(names())}"

    return Rule(lambda v: v in names(), _Phrase(), parse=str, choices=values)  # type: ignore[arg-type]


RATE = Rule(lambda v: is_number(v) and 1e-6 <= v <= 100, "a rate per hour in [1e-6, 100]")
NON_NEGATIVE = Rule(lambda v: is_number(v) and v >= 0, "a number ≥ 0")
FRACTION = Rule(lambda v: isinstance(v, float) and 0.2 <= v <= 0.9, "a fraction in [0.2, 0.9]")


def option(default: Any, rule: Rule, help: str = "", *, flag: str | None = None, group: str = "") -> Any:
    """A dataclass field with its rule; ``flag`` exposes it on the command line in argument ``group``."""
    return field(default=default, metadata={"rule": rule, "help": help, "flag": flag, "group": group})


@dataclass(frozen=True)
class Checked:
    """A frozen dataclass of :func:`option` fields that checks itself."""

    _what = "options"

    def problems(self) -> list[str]:
        """One message per field whose value its rule refuses."""
        return [p for f in fields(self) if "rule" in f.metadata
                and (p := f.metadata["rule"].problem(f.name, getattr(self, f.name)))]

    def validated(self):
        """Check every field; raise one :class:`OptionError` listing all problems."""
        problems = self.problems()
        if problems:
            raise OptionError(f"invalid {self._what}:\n  " + "\n  ".join(problems))
        return self._normalised()

    def _normalised(self):
        return self

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


@dataclass(frozen=True)
class DetectorSettings(Checked):
    """A detector's own settings (``Detector.Settings``): its constructor's arguments.

    A subclass declares each setting with :func:`option` (``group="detection"`` and a flag
    for those the command line exposes; start the help with ``"<detector>: "``).  The
    monitor builds it from the options given (:attr:`MonitorOptions.settings
    <monitor.options.MonitorOptions.settings>`); a setting given while another detector
    runs is refused unless left at its default.  A detector with no settings keeps this class.
    """

    #: the setting that is the designed false-alarm rate per hour, if the detector is designed by
    #: one (the contract suite then checks that rate on white noise); None: not designed so
    design_rate: ClassVar[str | None] = None
    _what = "monitor options"

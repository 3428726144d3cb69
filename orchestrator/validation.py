"""The toolkit shared by the validators of case files (:mod:`orchestrator.config`) and
sweep files (:mod:`sweep.config`).

A validator reads one raw TOML dict, collects *every* problem it finds as a line
``field = value: what was expected`` and raises one :class:`ConfigError` listing them all.
The helpers here are the checks both file kinds need: tables and unknown keys (with a
"did you mean"), numbers, integers, booleans, names, and the communication grid.

Standard library only.
"""
from __future__ import annotations

import difflib
import json
import math
import re
import tomllib
import unicodedata
from pathlib import Path
from typing import Any

from fourbar_common.files import NotRegularFileError, open_regular

__all__ = [
    "GRID_TOLERANCE",
    "MAX_TOML_BYTES",
    "ConfigError",
    "ProblemReporter",
    "grid_steps",
    "is_number",
    "kind_of",
    "name_from_file",
    "read_toml",
    "show_value",
]

#: A time is on the grid ``start + k*step`` when ``(time - start)/step`` is within this of
#: a whole number ``k``.
GRID_TOLERANCE = 1e-6
#: The largest case or sweep file read (bytes): the shipped ones are 1-3 kB; a larger file is
#: not one a person wrote, and reading it whole would cost memory for nothing.
MAX_TOML_BYTES = 1 << 20
_NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


class ConfigError(ValueError):
    """A file (or an override of it) is invalid; ``problems`` lists every problem.

    ``str(error)`` is the complete report: one line per problem, each starting with the
    file's name.
    """

    #: What kind of file the report is about ("invalid case <file>: ...").
    subject = "case"

    def __init__(self, source: str | None, problems: list[str] | tuple[str, ...]):
        self.source = source
        self.problems = tuple(problems)
        prefix = f"{source}: " if source else ""
        count = len(self.problems)
        head = f"invalid {self.subject} {source or '(no file)'}: {count} problem{'s' if count != 1 else ''}"
        super().__init__("\n".join([head] + [f"  {prefix}{p}" for p in self.problems]))


def show_value(value: Any) -> str:
    """A value as it would be written in TOML (long tables and arrays shortened)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (dict, list, tuple)):
        text = json.dumps(value, default=str)
        return text if len(text) <= 60 else text[:57] + "..."
    return repr(value)


def kind_of(value: Any) -> str:
    """'a string', 'an integer', 'a table', ... : the TOML kind of ``value``, for messages."""
    return {bool: "a boolean", int: "an integer", float: "a float", str: "a string",
            dict: "a table", list: "an array"}.get(type(value), type(value).__name__)


def is_number(value: Any) -> bool:
    """A finite TOML integer or float (booleans are not numbers)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def grid_steps(span: float, step: float) -> int | None:
    """``span/step`` as a whole number of steps, or None when it is not one (within
    :data:`GRID_TOLERANCE` of a step)."""
    count = span / step
    if not math.isfinite(count):      # a step of 5e-324 s: no whole number of them
        return None
    k = round(count)
    return k if abs(count - k) <= GRID_TOLERANCE else None


def name_from_file(path: Path) -> str | None:
    """The name a file without a ``name`` key gets: its file name without the extension, made
    a folder name of letters, digits, '_', '-', '.' (see :meth:`ProblemReporter.identifier`).

    Accents are dropped (``casé.toml`` -> ``case``) and each run of other characters (spaces,
    ``#``, ...) becomes one '_' (``my case.toml`` -> ``my_case``); None when nothing usable is
    left (a name with no Latin letter or digit, e.g. ``案例.toml``).  A file name that is
    already such a name is kept as it is.
    """
    if _NAME_PATTERN.match(path.stem):
        return path.stem
    plain = "".join(c for c in unicodedata.normalize("NFKD", path.stem) if not unicodedata.combining(c))
    name = re.sub(r"[^A-Za-z0-9_.-]+", "_", plain).strip("_.-")
    return name if _NAME_PATTERN.match(name) else None


def read_toml(path: Path, what: str, error: type[ConfigError] = ConfigError) -> dict:
    """Parse the TOML file ``path`` (a ``what``, e.g. "case file"); raise ``error`` naming the
    file when it is missing, unreadable or not TOML."""
    label = str(path)
    try:
        with open_regular(path) as handle:     # a FIFO or a device is refused, never read for ever
            data = handle.read(MAX_TOML_BYTES + 1)
        text = data.decode("utf-8")
    except FileNotFoundError:
        raise error(label, [f"{what} not found"]) from None
    except NotRegularFileError as exc:
        raise error(label, [f"{exc.strerror.removeprefix(label + ': ')}; expected a {what} (TOML)"]) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(label, [f"cannot read the {what}: {exc}"]) from None
    if len(data) > MAX_TOML_BYTES:
        raise error(label, [f"larger than {MAX_TOML_BYTES} bytes; a {what} is a few kilobytes"])
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(label, [f"not valid TOML: {exc}"]) from None
    except (RecursionError, MemoryError):    # tomllib recurses once per level of nested arrays/tables
        raise error(label, [f"nested too deeply to be a {what}"]) from None


class ProblemReporter:
    """Checks values of one raw TOML dict and collects the problems found.

    A subclass sets ``raw`` (the parsed file) and ``problems = []``, and may override
    :meth:`field` to say where a key came from (e.g. ``(from --set L2)``).  Every check
    returns the checked value, or None after recording a problem, so a validator goes on
    and reports everything at once.
    """

    raw: dict
    problems: list[str]

    # -- reporting ------------------------------------------------------------------------
    def field(self, name: str) -> str:
        return name

    def problem(self, name: str, value: Any, expected: str) -> None:
        self.problems.append(f"{self.field(name)} = {show_value(value)}: {expected}")

    def missing(self, name: str, expected: str) -> None:
        self.problems.append(f"{self.field(name)}: missing; expected {expected}")

    def unknown_keys(self, table: dict, allowed: tuple[str, ...], where: str) -> None:
        for key in table:
            if key not in allowed:
                close = difflib.get_close_matches(key, allowed, n=1)
                hint = f"did you mean {close[0]!r}? " if close else ""
                place = f"{where}.{key}" if where else key
                self.problems.append(f"{place}: unknown key; {hint}expected one of: {', '.join(allowed)}")

    # -- checks ---------------------------------------------------------------------------
    def table(self, name: str, required: bool = False) -> dict | None:
        """The top-level table ``[name]``; None when absent (a problem if ``required``) or
        not a table."""
        value = self.raw.get(name)
        if value is None:
            if required:
                self.missing(name, f"a [{name}] table")
            return None
        if not isinstance(value, dict):
            self.problem(name, value, f"expected a [{name}] table, got {kind_of(value)}")
            return None
        return value

    def number(self, name: str, value: Any, unit: str = "", *, minimum: float | None = None,
               positive: bool = False) -> float | None:
        """A finite float (TOML integers accepted), optionally ``> 0`` or ``>= minimum``."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.problem(name, value, f"expected a number{unit and ' in ' + unit}, got {kind_of(value)}")
            return None
        value = float(value)
        if not math.isfinite(value):
            self.problem(name, value, "expected a finite number")
            return None
        if positive and value <= 0.0:
            self.problem(name, value, f"expected a number > 0{unit and ' ' + unit}")
            return None
        if minimum is not None and value < minimum:
            self.problem(name, value, f"expected a number >= {minimum:g}{unit and ' ' + unit}")
            return None
        return value

    def integer(self, name: str, value: Any, *, minimum: int = 0) -> int | None:
        """A TOML integer ``>= minimum`` (booleans and floats are refused)."""
        if isinstance(value, bool) or not isinstance(value, int):
            self.problem(name, value, f"expected an integer >= {minimum}, got {kind_of(value)}")
            return None
        if value < minimum:
            self.problem(name, value, f"expected an integer >= {minimum}")
            return None
        return value

    def boolean(self, name: str, value: Any) -> bool | None:
        if not isinstance(value, bool):
            self.problem(name, value, f"expected true or false, got {kind_of(value)}")
            return None
        return value

    def text(self, name: str, value: Any) -> str | None:
        if not isinstance(value, str):
            self.problem(name, value, f"expected a string, got {kind_of(value)}")
            return None
        return value

    def identifier(self, name: str, value: Any, names_what: str) -> str | None:
        """A name usable as a folder name: letters, digits, '_', '-', '.'; ``names_what``
        says what it names (e.g. "the output directory out/<name>")."""
        if not isinstance(value, str) or not _NAME_PATTERN.match(value):
            self.problem(name, value, f"expected a non-empty string of letters, digits, '_', '-', '.' "
                                      f"(it names {names_what})")
            return None
        return value

    def whole_steps(self, name: str, value: float, span: float, step: float, what: str, *,
                    step_name: str | None = None) -> int | None:
        """``span/step`` as a whole number (at least one) of communication steps, else a problem
        on ``name`` (``value`` is quoted; ``what`` names the ratio, e.g. "(stop - start)/step").

        A span shorter than one step is reported on ``step_name`` (quoting ``step``) when
        given: the step is what is too long.  (A ratio such as 12/1e9 = 1.2e-8 is within
        :data:`GRID_TOLERANCE` of the whole number 0, so :func:`grid_steps` alone accepts it.)
        """
        count = span / step
        if not count >= 1.0 - GRID_TOLERANCE:
            where, shown = (step_name, step) if step_name else (name, value)
            self.problem(where, shown, f"{what} = {count:.9g} is less than one step: the span is {span!r} s; "
                                       f"expected a step that divides the span into a whole number (>= 1) of steps")
            return None
        k = grid_steps(span, step)
        if k is None:
            self.problem(name, value, f"{what} = {span / step:.9g} is not a whole number of steps of {step!r} s")
        return k

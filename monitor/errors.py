"""Exceptions raised by the monitor.

Every message names the file (or option), the field, the value and what was expected, so
the CLI can print it as is (exit code 2) instead of a traceback.
"""
from __future__ import annotations

from typing import Iterable

from fourbar_common.contract.problems import Problem

__all__ = [
    "MonitorError",
    "ExchangeFormatError",
    "ExchangeMissingError",
    "OptionError",
    "OutputDirError",
    "OutputWriteError",
    "RunJsonError",
    "TrainingError",
]


class MonitorError(Exception):
    """Base class of every error the monitor raises for bad input or options."""


class ExchangeFormatError(MonitorError, ValueError):
    """The exchange file cannot be used: empty, header only, missing column, bad encoding."""


class ExchangeMissingError(MonitorError, FileNotFoundError):
    """The exchange file does not exist (replay), or did not appear in time (follow)."""


class OptionError(MonitorError, ValueError):
    """An option of the monitor has an invalid value; the message names the option.

    :attr:`problems` are the same complaints, structured: one :class:`Problem` per option
    (``field`` the option's name, ``message`` what is wrong with its value), so a caller that
    shows them its own way (the sweep names ``monitor.<option>`` and the value in its file)
    needs no parsing of the text.  Raise one with :meth:`listing`, or with the message alone
    in the form every option error has (``"<option>: <what is wrong>"``, or a first line and
    then one such line per problem), from which the problems are taken.
    """

    def __init__(self, message: str, problems: Iterable[Problem] | None = None):
        super().__init__(message)
        self.problems: tuple[Problem, ...] = (tuple(problems) if problems is not None
                                              else _problems_of(message))

    def __reduce__(self):
        # pickled (a Dask worker's error) with its problems as given
        return self.__class__, (str(self), self.problems)

    @classmethod
    def listing(cls, what: str, problems: Iterable[Problem]) -> "OptionError":
        """``invalid <what>:`` then one indented line ``<option>: <message>`` per problem."""
        problems = tuple(problems)
        return cls(f"invalid {what}:\n  " + "\n  ".join(str(p) for p in problems), problems)


def _problems_of(message: str) -> tuple[Problem, ...]:
    """The problems of an option error's text: its lines ``<option>: <message>`` (the lines
    after the first when there are several; the text itself when it is one line)."""
    lines = message.splitlines()[1:] or [message]
    problems = []
    for line in lines:
        name, _, rest = line.strip().partition(":")
        problems.append(Problem(name, rest.strip()))
    return tuple(problems)


class TrainingError(MonitorError, ValueError):
    """The training window cannot give a model: too few samples, constant signal, no period."""


class OutputDirError(MonitorError, ValueError):
    """The output folder cannot be used (the default one holds files the monitor did not write)."""


class RunJsonError(MonitorError, ValueError):
    """The run.json beside the exchange file is not a run record (empty, not JSON, nested too
    deeply, not a regular file, a field of the wrong type): the fault time and the grid it
    holds are unknown, so the data are not judged."""


class OutputWriteError(MonitorError, OSError):
    """An output file could not be written (disk full, read-only folder); the message names it.
    The session removes the partial outputs and ends with exit status 4."""

"""Exceptions raised by the monitor.

Every message names the file (or option), the field, the value and what was expected, so
the CLI can print it as is (exit code 2) instead of a traceback.
"""
from __future__ import annotations

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
    """An option of the monitor has an invalid value; the message names the option."""


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

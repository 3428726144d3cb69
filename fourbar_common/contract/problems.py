"""The one error of a contract file that cannot be read: :class:`ContractError`, with its problems.

A reader checks the whole file before it gives up and reports every problem found, each as a
:class:`Problem` naming the field (a dotted path such as ``detector.threshold`` or
``rows[3].time``) and what is wrong with it, so that one message tells the user everything to
fix.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable

__all__ = ["ContractError", "Problem"]


@dataclass(frozen=True)
class Problem:
    """One thing wrong with one field of a file."""

    field: str
    message: str

    def __str__(self) -> str:
        return f"{self.field}: {self.message}" if self.field else self.message


class ContractError(ValueError):
    """``source`` (a file path or a name) cannot be used; :attr:`problems` says why, field by field."""

    def __init__(self, source: str, problems: Iterable[Problem]):
        self.source = str(source)
        self.problems: tuple[Problem, ...] = tuple(problems) or (Problem("", "unreadable"),)
        super().__init__(f"{self.source}: " + "; ".join(str(p) for p in self.problems))

    def __reduce__(self):
        # pickled (a Dask worker's error) with its source and problems, not its message alone
        return self.__class__, (self.source, self.problems)

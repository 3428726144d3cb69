"""Small helpers that every part of fourbar-cosim needs, so each has one home.

The three parts (``fmu_src``, ``orchestrator``, ``monitor``) never import each other; they
may all import this package, which imports nothing of theirs and only the standard library.
The run folder's files (run.json and the others) have their typed homes in
:mod:`fourbar_common.contract`.
"""
from __future__ import annotations

from .drawing import Drawing, DrawingError, DrawnBody, DrawnJoint
from .events import Event, RampEvent, StepEvent, Value
from .files import output_folder_problem, replace_atomically, write_json_atomic
from .version import package_version

__all__ = [
    "Drawing",
    "DrawingError",
    "DrawnBody",
    "DrawnJoint",
    "Event",
    "RampEvent",
    "StepEvent",
    "Value",
    "output_folder_problem",
    "package_version",
    "replace_atomically",
    "write_json_atomic",
]

"""Small helpers that every part of fourbar-cosim needs, so each has one home.

The three parts (``fmu_src``, ``orchestrator``, ``monitor``) never import each other; they
may all import this package, which imports nothing of theirs and only the standard library.
The run folder's files (run.json and the others) have their typed homes in
:mod:`fourbar_common.contract`.
"""
from __future__ import annotations

from .lazy import lazy_names

#: Where each public name lives; imported on first use (PEP 562), so ``from fourbar_common
#: import package_version`` (every command's ``--version``) does not load the XML drawing.
_HOMES = {
    "Drawing": "drawing", "DrawingError": "drawing", "DrawnBody": "drawing", "DrawnJoint": "drawing",
    "Event": "events", "RampEvent": "events", "StepEvent": "events", "Value": "events",
    "output_folder_problem": "files", "replace_atomically": "files", "write_json_atomic": "files",
    "package_version": "version",
}
__getattr__, __dir__ = lazy_names(__name__, _HOMES)

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

"""Small helpers that every part of fourbar-cosim needs, so each has one home.

The three parts (``fmu_src``, ``orchestrator``, ``monitor``) never import each other; they
may all import this package, which imports nothing of theirs and only the standard library.
The run folder's files (run.json and the others) have their typed homes in
:mod:`fourbar_common.contract`.
"""
from __future__ import annotations

from importlib import import_module
from typing import Any

#: Where each public name lives; imported on first use (PEP 562), so ``from fourbar_common
#: import package_version`` (every command's ``--version``) does not load the XML drawing.
_HOMES = {
    "Drawing": "drawing", "DrawingError": "drawing", "DrawnBody": "drawing", "DrawnJoint": "drawing",
    "Event": "events", "RampEvent": "events", "StepEvent": "events", "Value": "events",
    "output_folder_problem": "files", "replace_atomically": "files", "write_json_atomic": "files",
    "package_version": "version",
}


def __getattr__(name: str) -> Any:
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f".{home}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


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

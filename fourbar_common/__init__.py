"""Small helpers that every part of fourbar-cosim needs, so each has one home.

The three parts (``fmu_src``, ``orchestrator``, ``monitor``) never import each other; they
may all import this package, which imports nothing of theirs and only the standard library.
"""
from __future__ import annotations

from importlib import import_module
from typing import Any

#: Where each public name lives; imported on first use (PEP 562), so ``from fourbar_common
#: import package_version`` (every command's ``--version``) loads neither the XML drawing nor
#: the run record.
_HOMES = {
    "Drawing": "drawing", "DrawingError": "drawing", "DrawnBody": "drawing", "DrawnJoint": "drawing",
    "Event": "events", "RampEvent": "events", "StepEvent": "events", "Value": "events",
    "output_folder_problem": "files", "replace_atomically": "files", "write_json_atomic": "files",
    "PARAMETER_SOURCES": "run_record", "SCHEMA_VERSION": "run_record", "ParameterStart": "run_record",
    "RecordedExchange": "run_record", "RecordedExperiment": "run_record", "RecordedFmu": "run_record",
    "RecordedNoise": "run_record", "RecordedWriter": "run_record", "RunRecord": "run_record",
    "RunRecordError": "run_record", "read_run_record": "run_record", "write_run_record": "run_record",
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
    "PARAMETER_SOURCES",
    "ParameterStart",
    "RecordedExchange",
    "RecordedExperiment",
    "RecordedFmu",
    "RecordedNoise",
    "RecordedWriter",
    "RunRecord",
    "RampEvent",
    "RunRecordError",
    "SCHEMA_VERSION",
    "StepEvent",
    "Value",
    "output_folder_problem",
    "package_version",
    "read_run_record",
    "replace_atomically",
    "write_json_atomic",
    "write_run_record",
]

"""Small helpers that every part of fourbar-cosim needs, so each has one home.

The three parts (``fmu_src``, ``orchestrator``, ``monitor``) never import each other; they
may all import this package, which imports nothing of theirs and only the standard library.
"""
from __future__ import annotations

from .drawing import Drawing, DrawingError, DrawnBody, DrawnJoint
from .events import Event, RampEvent, StepEvent, Value
from .files import output_folder_problem, replace_atomically, write_json_atomic
from .run_record import (PARAMETER_SOURCES, SCHEMA_VERSION, ParameterStart, RecordedExchange, RecordedExperiment,
                         RecordedFmu, RecordedNoise, RecordedWriter, RunRecord, RunRecordError, read_run_record,
                         write_run_record)
from .version import package_version

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

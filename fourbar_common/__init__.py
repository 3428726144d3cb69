"""Small helpers that every part of fourbar-cosim needs, so each has one home.

The three parts (``fmu_src``, ``orchestrator``, ``monitor``) never import each other; they
may all import this package, which imports nothing of theirs and only the standard library.
"""
from __future__ import annotations

from .files import replace_atomically, write_json_atomic
from .run_record import (PARAMETER_SOURCES, SCHEMA_VERSION, ParameterStart, RecordedEvent, RecordedExchange,
                         RecordedExperiment, RecordedFmu, RecordedNoise, RecordedRamp, RecordedStep, RecordedWriter,
                         RunRecord, RunRecordError, read_run_record, write_run_record)
from .version import package_version

__all__ = [
    "PARAMETER_SOURCES",
    "ParameterStart",
    "RecordedEvent",
    "RecordedExchange",
    "RecordedExperiment",
    "RecordedFmu",
    "RecordedNoise",
    "RecordedRamp",
    "RecordedStep",
    "RecordedWriter",
    "RunRecord",
    "RunRecordError",
    "SCHEMA_VERSION",
    "package_version",
    "read_run_record",
    "replace_atomically",
    "write_json_atomic",
    "write_run_record",
]

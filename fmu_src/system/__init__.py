"""Systems of FMUs (issue 40): system files (systems/<name>.toml) built into SSP 1.0 files.

``build_fmu.py --system NAME|PATH`` calls :func:`build_system`; docs/systems.md describes the
file format and the .ssp layout.
"""
from __future__ import annotations

from .build import ComponentBuildError, ComponentFmu, SystemBuildResult, build_system, component_fmu, write_ssp
from .description import (ComponentSpec, ConnectionSpec, Experiment, SystemDescription, SystemFileError,
                          load_system, parse_system, resolve_system, shipped_systems)
from .interface import FmuInterface, Port, check_system, read_interface
from .ssd import schema_problems, ssd_bytes

__all__ = ["ComponentBuildError", "ComponentFmu", "SystemBuildResult", "build_system", "component_fmu", "write_ssp",
           "ComponentSpec", "ConnectionSpec", "Experiment", "SystemDescription", "SystemFileError", "load_system",
           "parse_system", "resolve_system", "shipped_systems", "FmuInterface", "Port", "check_system", "read_interface",
           "schema_problems", "ssd_bytes"]

"""fourbar-view: the run folder seen live in a browser, and as an animation for reports.

An integration package like ``sweep``: it reads a run folder's files only (exchange.csv,
run.json, the monitor's outputs, diagnosis.json) and imports none of the three parts'
internals; the shared schemas come from :mod:`fourbar_common`.
"""
from __future__ import annotations

from importlib import import_module
from typing import Any

#: Where each public name lives; imported on first use (PEP 562: pandas, numpy), so
#: ``fourbar-view --help`` loads neither.
_HOMES = {"BodyShape": "geometry", "Frame": "geometry", "Geometry": "geometry", "Scene": "geometry",
          "faulted_bodies": "geometry", "Diagnosis": "sources", "MonitorEvent": "sources", "RunFolder": "sources",
          "RunFolderError": "sources", "Update": "sources", "check_run_folder": "sources"}


def __getattr__(name: str) -> Any:
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f".{home}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


__all__ = ["BodyShape", "Diagnosis", "Frame", "Geometry", "MonitorEvent", "RunFolder", "RunFolderError", "Scene",
           "Update", "check_run_folder", "faulted_bodies"]

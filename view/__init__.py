"""fourbar-view: the run folder seen live in a browser, and as an animation for reports.

An integration package like ``sweep``: it reads a run folder's files only (exchange.csv,
run.json, the monitor's outputs, diagnosis.json) and imports none of the three parts'
internals; the shared schemas come from :mod:`fourbar_common`.
"""
from __future__ import annotations

from fourbar_common.lazy import lazy_names

#: Where each public name lives; imported on first use (PEP 562: pandas, numpy), so
#: ``fourbar-view --help`` loads neither.
_HOMES = {"BodyShape": "geometry", "Frame": "geometry", "Geometry": "geometry", "Scene": "geometry",
          "faulted_bodies": "geometry", "Diagnosis": "sources", "MonitorEvent": "sources", "RunFolder": "sources",
          "RunFolderError": "sources", "Update": "sources", "check_run_folder": "sources"}
__getattr__, __dir__ = lazy_names(__name__, _HOMES)

__all__ = ["BodyShape", "Diagnosis", "Frame", "Geometry", "MonitorEvent", "RunFolder", "RunFolderError", "Scene",
           "Update", "check_run_folder", "faulted_bodies"]

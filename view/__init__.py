"""fourbar-view: the run folder seen live in a browser, and as an animation for reports.

An integration package like ``sweep``: it reads a run folder's files only (exchange.csv,
run.json, the monitor's outputs, diagnosis.json) and imports none of the three parts'
internals; the shared schemas come from :mod:`fourbar_common`.
"""
from __future__ import annotations

from .geometry import BodyShape, Frame, Geometry, Scene, faulted_bodies
from .sources import Diagnosis, MonitorEvent, RunFolder, RunFolderError, Update, check_run_folder

__all__ = ["BodyShape", "Diagnosis", "Frame", "Geometry", "MonitorEvent", "RunFolder", "RunFolderError", "Scene",
           "Update", "check_run_folder", "faulted_bodies"]

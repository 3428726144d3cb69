"""diagnose: after the monitor's alarm, which parameter changed, to what, and when.

An integration package (like ``sweep``): it reads a run folder (the orchestrator's
``exchange.csv`` and ``run.json``, the monitor's ``summary.json``) and replays the run's FMU
through the orchestrator's FMI wrapper.  The monitor knows nothing of it.

    diagnose(run_dir, **options) -> Diagnosis        # .verdict, .best, .ranking, .message

Command: ``fourbar-diagnose RUN_DIR`` (:mod:`diagnose.cli`).  Method: docs/diagnose.md.
"""
from __future__ import annotations

from importlib import import_module
from typing import Any

from .errors import DiagnoseError, NoAlarm

__all__ = ["DiagnoseError", "DiagnoseOptions", "Diagnosis", "Fit", "NoAlarm", "RunInputs", "diagnose",
           "diagnose_inputs", "read_inputs"]

#: Loaded on first use (scipy, FMPy: seconds), so ``fourbar-diagnose`` installs its Ctrl-C and
#: SIGTERM handling, and answers ``--help``, before they load.
_LAZY = {"Diagnosis": "diagnosis", "DiagnoseOptions": "diagnosis", "diagnose": "diagnosis",
         "diagnose_inputs": "diagnosis", "Fit": "fit", "RunInputs": "inputs", "read_inputs": "inputs"}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

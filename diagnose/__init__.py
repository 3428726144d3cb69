"""diagnose: after the monitor's alarm, which parameter changed, to what, and when.

An integration package (like ``sweep``): it reads a run folder (the orchestrator's
``exchange.csv`` and ``run.json``, the monitor's ``summary.json``) and replays the run's FMU
through the orchestrator's FMI wrapper.  The monitor knows nothing of it.

    diagnose(run_dir, **options) -> Diagnosis        # .verdict, .best, .ranking, .message

Command: ``fourbar-diagnose RUN_DIR`` (:mod:`diagnose.cli`).  Method: docs/diagnose.md.
"""
from __future__ import annotations

from .diagnosis import Diagnosis, DiagnoseOptions, diagnose, diagnose_inputs
from .errors import DiagnoseError, NoAlarm
from .fit import Fit
from .inputs import RunInputs, read_inputs

__all__ = ["DiagnoseError", "DiagnoseOptions", "Diagnosis", "Fit", "NoAlarm", "RunInputs", "diagnose",
           "diagnose_inputs", "read_inputs"]

"""sweep: fault-scenario sweeps on Dask -- the one package that uses both orchestrator and monitor.

``load_sweep`` reads and validates a sweep file (TOML) into a frozen :class:`Sweep`;
``plan_scenarios`` lists its scenarios with stable ids; ``run_sweep`` runs those not yet in
the results on a Dask cluster (each one ``orchestrator.run_case`` + ``monitor.replay`` in
a worker process) and writes the results table, summary and plots; ``fourbar-sweep`` is
the command line (``sweep.cli:main``).  Importing this package imports only the standard
library; Dask, FMPy, pandas and matplotlib are loaded when a sweep is read or run.
"""
from .config import Range, Sweep, SweepError, load_sweep
from .plan import Scenario, plan_scenarios
from .results import COLUMNS, RUNTIME_COLUMNS, ResultsError
from .runner import ClusterError, SweepInterrupted, SweepResult, open_client, run_sweep
from .scenario import run_scenario, score

__all__ = [
    "COLUMNS",
    "ClusterError",
    "RUNTIME_COLUMNS",
    "Range",
    "ResultsError",
    "Scenario",
    "Sweep",
    "SweepError",
    "SweepInterrupted",
    "SweepResult",
    "load_sweep",
    "open_client",
    "plan_scenarios",
    "run_scenario",
    "run_sweep",
    "score",
]

"""orchestrator: drive an FMI 2.0 or 3.0 FMU (co-simulation or model exchange, FMPy) through a case file.

``load_case`` reads and validates a case file (TOML) into a frozen :class:`Case`;
``run_case`` runs it and writes ``exchange.csv`` and ``run.json``; ``fourbar-run`` is the
command line (``orchestrator.cli:main``).  ``install_pythonfmu_exit_guard`` is for other
programs that load pythonfmu FMUs (see :mod:`orchestrator.pythonfmu_workarounds`).  Importing this package imports only the
standard library; FMPy and numpy are loaded when a case is read or run.
"""
from .case import Case, ExchangeSettings, Experiment, FmuDescription, Noise, RampEvent, StepEvent
from .config import apply_overrides, load_case
from .validation import ConfigError
from .pythonfmu_workarounds import install_exit_guard as install_pythonfmu_exit_guard
from .run import RunInterrupted, RunResult, run_case

__all__ = [
    "Case",
    "ConfigError",
    "ExchangeSettings",
    "Experiment",
    "FmuDescription",
    "Noise",
    "RampEvent",
    "RunInterrupted",
    "RunResult",
    "StepEvent",
    "apply_overrides",
    "install_pythonfmu_exit_guard",
    "load_case",
    "run_case",
]

"""orchestrator: drive an FMI 2.0 co-simulation FMU (FMPy) through a case file.

``load_case`` reads and validates a case file (TOML) into a frozen :class:`Case`;
``run_case`` runs it and writes ``exchange.csv`` and ``run.json``; ``fourbar-run`` is the
command line (``orchestrator.cli:main``).  Importing this package imports only the
standard library; FMPy and numpy are loaded when a case is read or run.
"""
from .config import (Case, ConfigError, ExchangeSettings, Experiment, Noise, RampEvent, StepEvent,
                     apply_overrides, load_case)
from .run import RunInterrupted, RunResult, run_case

__all__ = [
    "Case",
    "ConfigError",
    "ExchangeSettings",
    "Experiment",
    "Noise",
    "RampEvent",
    "RunInterrupted",
    "RunResult",
    "StepEvent",
    "apply_overrides",
    "load_case",
    "run_case",
]

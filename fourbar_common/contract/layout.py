"""Where each file of a run folder and of a sweep folder lives: the one place their names are spelled.

A run folder, as ``fourbar-run`` writes it and the monitor, the diagnosis and the view read it::

    <run>/exchange.csv              the signals (orchestrator; read while it grows)
    <run>/run.json                  the run's record
    <run>/monitor/events.jsonl      the monitor's events, one JSON object per line
    <run>/monitor/evaluations.csv   the detector's statistic and threshold, per evaluation
    <run>/monitor/forecast.csv      the forecast beside the measured signal
    <run>/monitor/summary.json      the monitor's summary
    <run>/diagnosis/diagnosis.json  fourbar-diagnose's verdict

A sweep folder holds ``sweep.json``, ``results.csv``, ``summary.json`` and one run folder per
scenario under ``runs/<scenario id>/``.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

__all__ = ["DIAGNOSIS", "DIAGNOSIS_FOLDER", "EVALUATIONS", "EVENTS", "EXCHANGE", "FORECAST", "MONITOR_FOLDER",
           "RUN_RECORD", "RunFolder", "SUMMARY", "SWEEP_RECORD", "SWEEP_RESULTS", "SWEEP_RUNS", "SWEEP_SUMMARY",
           "SweepFolder", "monitor_folder_for"]

EXCHANGE = "exchange.csv"
RUN_RECORD = "run.json"
MONITOR_FOLDER = "monitor"
EVENTS = "events.jsonl"
EVALUATIONS = "evaluations.csv"
FORECAST = "forecast.csv"
SUMMARY = "summary.json"
DIAGNOSIS_FOLDER = "diagnosis"
DIAGNOSIS = "diagnosis.json"
SWEEP_RECORD = "sweep.json"
SWEEP_RESULTS = "results.csv"
SWEEP_SUMMARY = "summary.json"
SWEEP_RUNS = "runs"


def monitor_folder_for(exchange: str | os.PathLike[str]) -> Path:
    """The monitor's output folder for an exchange file when none is given.

    ``<dir>/monitor`` for a run folder's ``<dir>/exchange.csv``; ``<dir>/<stem>.monitor`` for any
    other file (``case2_libcosim.csv`` -> ``case2_libcosim.monitor``): a name with a dot, which no
    Python package (so none of this project's source folders) can have.
    """
    path = Path(exchange)
    return path.parent / (MONITOR_FOLDER if path.name == EXCHANGE else f"{path.stem}.monitor")


@dataclass(frozen=True)
class RunFolder:
    """The paths of one run folder's files (nothing is read or checked here)."""

    root: Path

    def __post_init__(self) -> None:
        object.__setattr__(self, "root", Path(self.root))

    @property
    def exchange(self) -> Path:
        return self.root / EXCHANGE

    @property
    def run_record(self) -> Path:
        return self.root / RUN_RECORD

    @property
    def monitor(self) -> Path:
        return self.root / MONITOR_FOLDER

    @property
    def events(self) -> Path:
        return self.monitor / EVENTS

    @property
    def evaluations(self) -> Path:
        return self.monitor / EVALUATIONS

    @property
    def forecast(self) -> Path:
        return self.monitor / FORECAST

    @property
    def summary(self) -> Path:
        return self.monitor / SUMMARY

    @property
    def diagnosis_folder(self) -> Path:
        return self.root / DIAGNOSIS_FOLDER

    @property
    def diagnosis(self) -> Path:
        return self.diagnosis_folder / DIAGNOSIS


@dataclass(frozen=True)
class SweepFolder:
    """The paths of one sweep folder's files."""

    root: Path

    def __post_init__(self) -> None:
        object.__setattr__(self, "root", Path(self.root))

    @property
    def record(self) -> Path:
        return self.root / SWEEP_RECORD

    @property
    def results(self) -> Path:
        return self.root / SWEEP_RESULTS

    @property
    def summary(self) -> Path:
        return self.root / SWEEP_SUMMARY

    def run(self, scenario_id: int | str) -> RunFolder:
        """The run folder of one scenario."""
        return RunFolder(self.root / SWEEP_RUNS / str(scenario_id))

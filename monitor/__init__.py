"""The monitor: the paper's analysis part (FFT period → Prophet forecast → MAE vs threshold).

It reads only an exchange file (``time,x2,...``) and, if present, the ``run.json`` beside
it; it imports nothing from ``orchestrator`` or ``fmu_src``.  Importing this package is
light (numpy); Prophet, scikit-learn, scipy, pandas and matplotlib are imported when used.

Public API::

    read_exchange(path) -> pandas.DataFrame
    dominant_period(t, x) -> PeriodEstimate
    fit_forecaster(kind, t, x, period, ...) -> Forecaster      # .predict(t) -> ndarray
    detect(t, x, forecaster, rule, start=...) -> Detection
    replay(exchange_path, **options) -> MonitorResult         # a finished file
    follow(exchange_path, **options) -> MonitorResult         # a growing file

Command: ``fourbar-monitor`` (:mod:`monitor.cli`).  Method and options: docs/monitor.md.
"""
from __future__ import annotations

from .detector import (ALARM_MESSAGE, Detection, Detector, Event, State, ThresholdRule, auto_threshold,
                       detect, fixed_threshold)
from .engine import Monitor, MonitorOptions, MonitorResult, follow, replay
from .errors import ExchangeFormatError, ExchangeMissingError, MonitorError, OptionError, TrainingError
from .forecasters import Forecaster, fit_forecaster
from .reader import ExchangeReader, ExchangeWarning, RunInfo, read_exchange, read_run_info
from .spectrum import PeriodEstimate, dominant_period

__all__ = [
    "ALARM_MESSAGE",
    "Detection",
    "Detector",
    "Event",
    "ExchangeFormatError",
    "ExchangeMissingError",
    "ExchangeReader",
    "ExchangeWarning",
    "Forecaster",
    "Monitor",
    "MonitorError",
    "MonitorOptions",
    "MonitorResult",
    "OptionError",
    "PeriodEstimate",
    "RunInfo",
    "State",
    "ThresholdRule",
    "TrainingError",
    "auto_threshold",
    "detect",
    "dominant_period",
    "fit_forecaster",
    "fixed_threshold",
    "follow",
    "read_exchange",
    "read_run_info",
    "replay",
]

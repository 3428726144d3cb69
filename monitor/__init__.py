"""The monitor: the paper's analysis part (FFT period → Prophet forecast → MAE vs threshold).

It reads only an exchange file (``time,x2,...``) and, if present, the ``run.json`` beside
it; it imports nothing from ``orchestrator`` or ``fmu_src``.  Importing this package is
light (numpy); Prophet, scikit-learn, scipy, pandas and matplotlib are imported when used.

Public API::

    read_exchange(path) -> pandas.DataFrame
    dominant_period(t, x) -> PeriodEstimate
    fit_forecaster(kind, t, x, period, ...) -> Forecaster      # .predict(t) -> ndarray
    Monitor(MonitorOptions(...)).feed(t, x)                   # the streaming monitor
    replay(exchange_path, **options) -> MonitorResult         # a finished file
    follow(exchange_path, **options) -> MonitorResult         # a growing file
    score_alarms(alarm_times, fault_time) -> FaultScore       # false alarms, latency

Modules: ``options`` (the settings every detector shares), ``option_rules`` (how a setting
is declared and checked), ``reader`` (exchange file, run.json), ``spectrum`` (period),
``forecasters`` (and their registry), ``detector`` (the detectors' interface), ``detectors``
(their registry), ``mae`` and ``threshold`` (the paper's rule), ``cusum_detector``,
``sequential``, ``tracking`` and ``cusum`` (the default sequential detector), ``page_hinkley``
(the Page–Hinkley detector), ``stream`` (the streaming monitor), ``summary`` (typed results, fault scoring), ``session``
(replay/follow), ``outputs`` (files and plots), ``cli``.

Command: ``fourbar-monitor`` (:mod:`monitor.cli`).  Method and options: docs/monitor.md.
"""
from __future__ import annotations

from .detector import ALARM_MESSAGE, Detector, Event, State
from .detectors import register
from .threshold import ThresholdRule, auto_threshold, fixed_threshold
from .options import FollowOptions, MonitorOptions
from .session import follow, replay
from .stream import Monitor
from .summary import FaultScore, MonitorResult, Summary, score_alarms
from .errors import (ExchangeFormatError, ExchangeMissingError, MonitorError, OptionError, OutputWriteError,
                     RunJsonError, TrainingError)
from .forecasters import Forecaster, fit_forecaster
from .reader import ExchangeReader, ExchangeWarning, RunInfo, read_exchange, read_run_info
from .spectrum import PeriodEstimate, dominant_period

__all__ = [
    "ALARM_MESSAGE",
    "FaultScore",
    "FollowOptions",
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
    "OutputWriteError",
    "RunJsonError",
    "PeriodEstimate",
    "RunInfo",
    "State",
    "Summary",
    "ThresholdRule",
    "TrainingError",
    "auto_threshold",
    "dominant_period",
    "fit_forecaster",
    "fixed_threshold",
    "follow",
    "read_exchange",
    "read_run_info",
    "register",
    "replay",
    "score_alarms",
]

"""The monitor: the paper's analysis part (FFT period → Prophet forecast → MAE vs threshold).

It reads only an exchange file (``time,x2,...``) and, if present, the ``run.json`` beside
it; it imports nothing from ``orchestrator`` or ``fmu_src``.  Importing this package imports
nothing more (its names load on first use); Prophet, scikit-learn, scipy, pandas and
matplotlib are imported when used.

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

from fourbar_common.lazy import lazy_names

#: Where each public name lives.  They are imported on first use (PEP 562), so that
#: ``fourbar-monitor --help`` and ``from monitor.cli import main`` load none of the modules
#: the command does not need; ``from monitor import replay`` works as before.
_HOMES = {
    "ALARM_MESSAGE": "detector", "Detector": "detector", "Event": "detector", "State": "detector",
    "register": "detectors",
    "ThresholdRule": "threshold", "auto_threshold": "threshold", "fixed_threshold": "threshold",
    "FollowOptions": "options", "MonitorOptions": "options",
    "follow": "session", "replay": "session",
    "Monitor": "stream",
    "FaultScore": "summary", "MonitorResult": "summary", "Summary": "summary", "score_alarms": "summary",
    "ExchangeFormatError": "errors", "ExchangeMissingError": "errors", "MonitorError": "errors",
    "OptionError": "errors", "OutputWriteError": "errors", "RunJsonError": "errors", "TrainingError": "errors",
    "Forecaster": "forecasters", "fit_forecaster": "forecasters",
    "ExchangeReader": "reader", "ExchangeWarning": "reader", "RunInfo": "reader", "read_exchange": "reader",
    "read_run_info": "reader",
    "PeriodEstimate": "spectrum", "dominant_period": "spectrum",
}
__getattr__, __dir__ = lazy_names(__name__, _HOMES)

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

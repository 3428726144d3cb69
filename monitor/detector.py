"""The detectors' common interface: states, events, fits, and the :class:`Detector` base class.

A detector turns the samples after the training window into evaluations and events.  The
:class:`~monitor.stream.Monitor` drives it only through this interface::

    det = cls(options, host)          # cls = options.detector_class (monitor.detectors)
    det.settings                      # its own settings: a cls.Settings (options.settings)
    det.state                         # State.TRAINING until det.train(...) succeeded
    det.train(t, X, end, step)        # the training window's samples; fits, host.add_fit(...)
    F = det.update(t, X)              # newer samples; returns the forecasts they were judged by
    det.alarms, det.refits, det.buffered_samples

Everything the detector produces goes to its :class:`DetectorHost`: events (``emit``),
evaluations (``record``: time, statistic, limit, state) and fitted models (``add_fit``).
What only one detector does (the MAE rule's refits, the CUSUM's phase tracker) stays in its
class.  How its results are shown comes from the class too: ``label`` (the statistic's
name), :meth:`Detector.describe` (one event as a line of text), :meth:`Detector.settings_text`
and :meth:`Detector.plot_text`; how a sweep labels and scores it from the class as well
(:meth:`Detector.series_text`, :meth:`Detector.designed_arl0_hours`,
:meth:`Detector.alarm_persistence`, ``arl0_curve``).  Its own settings are its ``Settings``
class (a frozen :class:`~monitor.option_rules.DetectorSettings`: each setting's default, check,
flag and help), which the command line, :class:`~monitor.options.MonitorOptions` and sweep
files read.  A new detector is one subclass, registered with
:func:`monitor.detectors.register` (docs/monitor.md, "Adding a detector").
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Callable, ClassVar

import numpy as np

from .forecasters import Forecaster
from .option_rules import DetectorSettings
from .spectrum import PeriodEstimate

__all__ = ["ALARM_MESSAGE", "Detector", "DetectorHost", "Event", "Fit", "State", "StatisticPlot", "alarm_event"]

#: The paper's alarm message (Fig. 13).
ALARM_MESSAGE = "Undefined signal is detected or the estimation is out of work. Please check the system"


class State(str, Enum):
    TRAINING = "TRAINING"
    STABLE = "STABLE"
    ALARM = "ALARM"


@dataclass(frozen=True)
class Event:
    """A state change or alarm at simulated ``time`` (s)."""

    time: float
    kind: str                 # trained | stable | refit | alarm | clear
    state: State
    statistic: float | None = None     # the detector's statistic: the MAE (mae) or the CUSUM (cusum)
    threshold: float | None = None
    message: str = ""
    data: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        d = {"time": self.time, "event": self.kind, "state": self.state.value, "statistic": self.statistic,
             "threshold": self.threshold, "message": self.message}
        d.update(self.data)
        return d


def alarm_event(time: float, statistic: float, threshold: float, **data: Any) -> Event:
    """The one constructor of alarm events: state ALARM, the paper's message, ``data`` (e.g. ``reason``)."""
    return Event(time, "alarm", State.ALARM, statistic, threshold, ALARM_MESSAGE, dict(data))


@dataclass
class Fit:
    """One fitted model with its alarm rule (the mae detector's ``refit="paper"`` makes several).

    ``estimate`` and ``forecaster`` are the first signal's; ``rule`` is the detector's limit
    (a :class:`~monitor.threshold.ThresholdRule`, a :class:`~monitor.sequential.CusumDesign`,
    or any object with ``as_dict()``); ``signals`` lists every signal's model when the
    detector fits several (:class:`~monitor.cusum_detector.SignalFit`).
    """

    start: float
    end: float
    estimate: PeriodEstimate
    forecaster: Forecaster
    rule: Any
    seconds: float
    signals: tuple[Any, ...] = ()
    period: float | None = None            # the common period (several signals)
    period_stderr: float | None = None

    def as_dict(self) -> dict[str, Any]:
        d = {"train_start": self.start, "train_end": self.end, "period": self.estimate.as_dict(),
             "model": self.forecaster.settings(), "threshold": self.rule.as_dict(), "seconds": self.seconds}
        if self.signals:
            d.update(common_period_s=self.period, common_period_stderr_s=self.period_stderr,
                     signals=[s.as_dict() for s in self.signals])
        return d


@dataclass(frozen=True)
class DetectorHost:
    """What a detector reports to (the :class:`~monitor.stream.Monitor` provides it).

    ``emit(events)`` publishes events; ``record(time, statistic, threshold, state)`` one
    evaluation; ``add_fit(fit)`` a fitted model; ``timing`` accumulates seconds under
    ``train``, ``forecast`` and ``evaluate``; ``source`` names the data in error messages.
    """

    source: str
    timing: dict[str, float]
    emit: Callable[[list[Event]], None]
    record: Callable[[float, float, float, State], None]
    add_fit: Callable[[Fit], None]


@dataclass(frozen=True)
class StatisticPlot:
    """How statistic.png shows a detector's statistic (:meth:`Detector.plot_text`)."""

    what: str                 # legend of the statistic's line
    limit: str                # legend of the limit's line
    ylabel: str
    ylabel_in_signal_units: bool = False
    floor: float = 1e-12      # smallest value drawn on the log axis
    shade_alarm: bool = False  # shade the evaluations in state ALARM (latched alarms)
    forecast: str = "forecast"  # the history plot's name for the forecast line
    interval_maximum: bool = False  # the statistic at t is the largest of (t − every, t]: drawn as steps


class Detector(ABC):
    """The interface every detector implements (module docstring).

    Class attributes: ``name`` (the value of the ``detector`` option, the registry's key),
    ``label`` (the statistic's display name, e.g. ``"CUSUM"``), ``Settings`` (its own
    settings class; ``self.settings`` is the instance it runs with) and ``arl0_curve`` (True
    when its fitted rule, ``Fit.rule``, offers ``h`` and ``limit_at_arl0(hours)``: a sweep then
    records the delay the run would have had at other false-alarm levels).  ``state``, ``alarms``
    (alarm episodes so far) and ``first_alarm`` are read-only; a simple detector changes
    them with :meth:`_enter` and :meth:`_raise_alarm`, one with its own state machine
    overrides the three properties.
    """

    name: ClassVar[str] = ""
    label: ClassVar[str] = ""
    Settings: ClassVar[type[DetectorSettings]] = DetectorSettings
    arl0_curve: ClassVar[bool] = False

    def __init__(self, options: Any, host: DetectorHost):
        self.options = options
        self.settings = options.settings
        self.host = host
        self._state = State.TRAINING
        self._alarms = 0
        self._first_alarm: Event | None = None

    @property
    def state(self) -> State:
        return self._state

    @property
    def alarms(self) -> int:
        return self._alarms

    @property
    def first_alarm(self) -> Event | None:
        return self._first_alarm

    def _enter(self, state: State) -> None:
        self._state = state

    def _raise_alarm(self, time: float, statistic: float, threshold: float, **data: Any) -> Event:
        """Enter ALARM and count it; returns the alarm event (the caller emits it)."""
        self._state = State.ALARM
        self._alarms += 1
        event = alarm_event(time, statistic, threshold, **data)
        if self._first_alarm is None:
            self._first_alarm = event
        return event

    # -- what the Monitor calls ----------------------------------------------------------------
    @abstractmethod
    def train(self, t: np.ndarray, X: np.ndarray, end: float, sample_step: float) -> None:
        """Fit on the training window: samples ``t`` (one column of ``X`` per signal) up to ``end``.

        ``sample_step`` is the window's median step.  Must call ``host.add_fit`` and emit the
        ``trained`` event (and ``stable`` when monitoring starts at once); raise
        :class:`~monitor.errors.TrainingError` when the data cannot be fitted.
        """

    @abstractmethod
    def update(self, t: np.ndarray, X: np.ndarray) -> np.ndarray:
        """Process samples after the training window (any batch sizes, increasing times).

        Returns the forecast each sample was compared with, one column per signal (shape
        ``(len(t), signals)``; a 1-D array is the first signal's, the others then have none):
        the history and ``forecast.csv`` show it.  The result must depend only on the samples,
        never on how they were batched.
        """

    def skip(self, start: float, end: float) -> None:
        """No samples will come in the open span (``start``, ``end``) s: a gap of the grid
        (:mod:`monitor.grid`) longer than the evaluation interval.  A detector that evaluates
        on a clock advances it past the gap here instead of evaluating the empty span point
        by point (a +1e6 s jump must cost no more than a few rows); the default does nothing."""

    @property
    def refits(self) -> int:
        return 0

    @property
    def buffered_samples(self) -> int:
        """Samples the detector holds in memory."""
        return 0

    # -- how it is shown --------------------------------------------------------------------------
    @classmethod
    def describe(cls, event: Event) -> str:
        """Console text: what a ``trained`` event fitted, or an ``alarm`` event's cause (appended
        to the statistic and its limit; may be empty)."""
        return event.message if event.kind == "trained" else ""

    @staticmethod
    def _model_text(event: Event) -> str:
        """The fitted period and model of a ``trained`` event that carries the built-ins' keys."""
        d = event.data
        # the FFT's highest peak can be a harmonic of the period (monitor.spectrum, step 3)
        harmonic = round(d["period_s"] / d["period_fft_s"]) if d["period_fft_s"] > 0 else 1
        of = f": harmonic {harmonic}" if harmonic > 1 else ""
        return (f"period {d['period_s']:.6g} s (FFT {d['period_fft_s']:.4g} s{of}); {d['model']} order {d['order']} "
                f"fitted in {d['fit_seconds']:.2f} s")

    @staticmethod
    def _onset_text(event: Event) -> str:
        """An alarm event's signal, side, estimated onset and episode (the sequential detectors' keys)."""
        d = event.data
        return f" on {d['signal']} ({d['side']}), change began ≈ {d['onset']:.2f} s; episode {d['episode']}"

    @classmethod
    def settings_text(cls, options: Any) -> str:
        """The settings that matter, for the console's first line."""
        return f"detector {cls.name}"

    @classmethod
    def plot_text(cls, options: Any, fit: Fit | None) -> StatisticPlot:
        return StatisticPlot(f"{cls.label} of {options.signal}", "limit", cls.label)

    # -- rules about options and scoring -----------------------------------------------------------
    @classmethod
    def option_problems(cls, options: Any) -> list[str]:
        """Problems of ``options`` under this detector (one message each; none by default)."""
        return []

    @classmethod
    def alarm_persistence(cls, options: Any) -> int:
        """Consecutive evaluations above the limit that make an alarm (for scoring statistic series)."""
        return 1

    @classmethod
    def designed_arl0_hours(cls, settings: Any) -> float | None:
        """The mean hours between false alarms the detector is designed for: 1 / the rate its
        ``Settings.design_rate`` names (None: not designed so)."""
        field = cls.Settings.design_rate
        return None if field is None else 1.0 / float(getattr(settings, field))

    @classmethod
    def series_text(cls, threshold: Any, limits: list[float], arl0_hours: float | None, unit: str = "") -> str:
        """A sweep's label of a series run with this detector: ``threshold`` the series' threshold
        axis value, ``limits`` the runs' limits (``threshold_base``), ``arl0_hours`` the design."""
        return f"{cls.name}, threshold {threshold}"

"""The streaming monitor: samples in, fits, evaluations and events out.

:class:`Monitor` is incremental: :meth:`Monitor.feed` takes new samples ``(t, X)`` in any
batch sizes (``X``: one column per monitored signal) and runs everything that those samples
make possible (training once the training window is complete, every evaluation whose data
are complete).  What is computed depends only on the samples, never on how they were
batched, so following a growing file and replaying the finished file give identical
evaluations, events and first-alarm times (:mod:`monitor.session`).

The detector (``options.detector``, decoded once: ``options.detector_class``) is driven only
through the :class:`~monitor.detector.Detector` interface: the monitor collects the training
window, checks the cadence against the sample step, hands the window to ``train`` and every
later batch to ``update``, and records what the detector reports (events, evaluations,
fits).  The built-in detectors: ``cusum`` (:mod:`monitor.cusum_detector`, the default) and
``mae`` (:mod:`monitor.mae`, the paper's rule).

Memory is bounded: the detector's buffer (an evaluation window, a refit, or the tracker's
guard band), a decimated history for the plots (``history_points``) and a
decimated series of evaluations (``evaluation_points``).
"""
from __future__ import annotations

from typing import Any, Callable

import numpy as np

from .bounded import BoundedSeries
from .detector import DetectorHost, Event, Fit, State
from .errors import TrainingError
from .options import MonitorOptions, check_every

__all__ = ["Fit", "Monitor"]


_STATE_CODE = {State.TRAINING: 0.0, State.STABLE: 1.0, State.ALARM: 2.0}
_CODE_STATE = {v: k for k, v in _STATE_CODE.items()}


class Monitor:
    """Incremental monitor of one or several signals (see the module docstring).

    ``on_event(event)`` and ``on_evaluation(time, statistic, threshold, state)`` are called
    as things happen (the CLI prints and logs from them).  ``on_samples(t, X, F)`` receives
    every judged sample once, in time order: ``X`` the values as fed (one column per
    signal), ``F`` the forecast the detector compared each with when it judged it (NaN for
    the training window's samples, which come when the training ends, and for a signal a
    detector gives no forecast of); the history is made of the same rows.  ``source`` names
    the data in error messages.
    """

    def __init__(self, options: MonitorOptions, *, source: str = "<data>",
                 on_event: Callable[[Event], None] | None = None,
                 on_evaluation: Callable[[float, float, float, State], None] | None = None,
                 on_samples: Callable[[np.ndarray, np.ndarray, np.ndarray], None] | None = None):
        self.options = options.validated()
        self.source = source
        self.on_event = on_event
        self.on_evaluation = on_evaluation
        self.on_samples = on_samples
        self.fits: list[Fit] = []
        self.events: list[Event] = []
        self.history = BoundedSeries(("time", "value", "forecast"), self.options.history_points)
        self.evaluations = BoundedSeries(("time", "statistic", "threshold", "state"), self.options.evaluation_points)
        self.timing = {"train": 0.0, "forecast": 0.0, "evaluate": 0.0}
        self.restarts = 0
        self._reset_state()

    def _reset_state(self) -> None:
        o = self.options
        host = DetectorHost(self.source, self.timing, self._emit, self._evaluated, self._add_fit)
        self.detector = o.detector_class(o, host)
        self._t = np.empty(0)
        self._x = np.empty((0, len(o.signals)))
        self._dt: float | None = None
        self._fit: Fit | None = None
        self.n_samples = 0
        self.n_evaluations = 0
        self.first_time: float | None = None
        self.last_time: float | None = None
        self.max_ratio = 0.0

    def reset(self) -> None:
        """Forget everything (the exchange file was replaced): start training again."""
        self.restarts += 1
        self.fits.clear()
        self.events.clear()
        self.history.clear()
        self.evaluations.clear()
        self._reset_state()

    # -- properties -------------------------------------------------------------------------
    @property
    def state(self) -> State:
        return self.detector.state

    @property
    def trained(self) -> bool:
        return self._fit is not None

    @property
    def fit(self) -> Fit | None:
        return self._fit

    @property
    def buffered_samples(self) -> int:
        """Samples held in memory: the training window's until it is complete, then the detector's."""
        return int(self._t.size + self.detector.buffered_samples)

    @property
    def refits(self) -> int:
        return self.detector.refits

    # -- feeding ----------------------------------------------------------------------------
    def _add_fit(self, fit: Fit) -> None:
        self.fits.append(fit)
        self._fit = fit

    def _emit(self, events: list[Event]) -> None:
        for e in events:
            self.events.append(e)
            if self.on_event is not None:
                self.on_event(e)

    def feed(self, t: np.ndarray, x: np.ndarray) -> None:
        """Add samples (strictly increasing times, after any already fed) and process them.

        ``x`` has one column per signal of ``options.signal`` (a 1-D array for one signal).
        """
        t = np.asarray(t, dtype=float)
        if t.size == 0:
            return
        x = np.asarray(x, dtype=float).reshape(t.size, -1)
        self.n_samples += t.size
        if self.first_time is None:
            self.first_time = float(t[0])
        self.last_time = float(t[-1])
        if self._fit is None:
            keep = t >= self.options.train[0] - 1e-9
            self._t = np.concatenate([self._t, t[keep]])
            self._x = np.vstack([self._x, x[keep]])
            if self._t.size and self._t[-1] >= self.options.train[1] - 1e-9:
                self._train_initial()
            return
        self._process(t, x)

    def skip(self, start: float, end: float) -> None:
        """No samples will come in (``start``, ``end``) s (a gap of the grid): the detector
        moves its evaluation clock past it (:meth:`Detector.skip`).  Before the training
        the session decides (a gap in the training window leaves nothing to fit)."""
        if self._fit is not None:
            self.detector.skip(float(start), float(end))

    def _process(self, t: np.ndarray, x: np.ndarray) -> None:
        """Samples after the training window, with a fitted model."""
        f = np.asarray(self.detector.update(t, x), dtype=float)
        if f.ndim == 1:             # the first signal's only (the interface allows it)
            first, f = f, np.full(x.shape, np.nan)
            f[:, 0] = first
        self._judged(t, x, f.reshape(x.shape))

    def _judged(self, t: np.ndarray, x: np.ndarray, f: np.ndarray) -> None:
        """Samples judged (``f``: their forecasts, NaN in training): into the history and to ``on_samples``."""
        self.history.extend(np.column_stack([t, x[:, 0], f[:, 0]]))
        if self.on_samples is not None:
            self.on_samples(t, x, f)

    def _train_initial(self) -> None:
        o = self.options
        sel = (self._t >= o.train[0] - 1e-9) & (self._t <= o.train[1] + 1e-9)
        if sel.sum() < 16:
            raise TrainingError(f"{self.source}: the training window {o.train[0]:g}–{o.train[1]:g} s holds "
                                f"{int(sel.sum())} samples of {o.signal}; at least 16 are needed")
        self._dt = float(np.median(np.diff(self._t[sel])))
        check_every(o.every, self._dt, self.source)    # before anything is written
        tt, xx = self._t[sel], self._x[sel]
        rest = self._t > o.train[1] + 1e-6 * self._dt
        t_rest, x_rest = self._t[rest], self._x[rest]
        self._t, self._x = np.empty(0), np.empty((0, self._x.shape[1]))
        self.detector.train(tt, xx, float(o.train[1]), self._dt)
        if self._fit is None:
            raise RuntimeError(f"detector {o.detector}: train() reported no fit (it must call host.add_fit)")
        # samples up to the window's end are training data: judged without a forecast
        self._judged(tt, xx, np.full(xx.shape, np.nan))
        if t_rest.size:
            self._process(t_rest, x_rest)

    def _evaluated(self, t: float, statistic: float, threshold: float, state: State) -> None:
        self.n_evaluations += 1
        self.max_ratio = max(self.max_ratio, statistic / threshold)
        self.evaluations.extend(np.array([[t, statistic, threshold, _STATE_CODE[state]]]))
        if self.on_evaluation is not None:
            self.on_evaluation(t, statistic, threshold, state)

    def finish(self) -> None:
        """The data ended: raise if it ended before the training window was complete."""
        if self._fit is None:
            o = self.options
            if self.last_time is None:
                raise TrainingError(f"{self.source}: no samples of {o.signal} at or after the training "
                                    f"start {o.train[0]:g} s")
            raise TrainingError(f"{self.source}: the data ends at t = {self.last_time:g} s, before the end "
                                f"of the training window {o.train[1]:g} s")

    # -- results ----------------------------------------------------------------------------
    def evaluation_frame(self) -> "Any":
        import pandas as pd

        arr = self.evaluations.array()
        return pd.DataFrame({"time": arr[:, 0], "statistic": arr[:, 1], "threshold": arr[:, 2],
                             "state": [_CODE_STATE[c].value for c in arr[:, 3]]})

    def history_frame(self) -> "Any":
        import pandas as pd

        arr = self.history.array()
        return pd.DataFrame({"time": arr[:, 0], self.options.signals[0]: arr[:, 1], "forecast": arr[:, 2]})

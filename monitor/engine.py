"""The monitor itself: rows in, model, evaluations and events out — for a live or a finished file.

:class:`Monitor` is incremental: :meth:`Monitor.feed` takes new samples ``(t, x)`` in any
batch sizes and runs everything that those samples make possible (training once the
training window is complete, every evaluation whose window is complete).  Because what is
computed depends only on the samples and never on how they were batched, :func:`follow`
(a growing file, polled) and :func:`replay` (a finished file) give identical evaluations,
events and first-alarm times.

Memory is bounded: the monitor keeps a rolling buffer of the newest samples (enough for an
evaluation window or a refit), a decimated history for the plots (``history_points``) and
a decimated series of evaluations (``evaluation_points``).
"""
from __future__ import annotations

import math
import os
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np

from .detector import (ALARM_MESSAGE, Detector, Event, State, ThresholdRule, auto_threshold, fixed_threshold,
                       window_mae)
from .errors import ExchangeFormatError, ExchangeMissingError, OptionError, TrainingError
from .forecasters import MODELS, Forecaster, fit_forecaster
from .reader import ExchangeReader, RunInfo, read_run_info
from .spectrum import PeriodEstimate, dominant_period

__all__ = ["BoundedSeries", "Monitor", "MonitorOptions", "MonitorResult", "follow", "replay", "warm_up"]

SCHEMA = 1
REFIT_POLICIES = ("none", "paper")


@dataclass(frozen=True)
class MonitorOptions:
    """Every setting of the monitor (units: seconds and the signal's unit).

    ``threshold`` is a positive number or ``"auto"``; ``refit`` ``"none"`` or ``"paper"``.
    ``auto_k``, ``auto_floor``, ``auto_z`` and ``validation_fraction`` parametrise the auto
    threshold (:func:`monitor.detector.auto_threshold`).
    """

    signal: str = "x2"
    train: tuple[float, float] = (0.0, 9.0)
    model: str = "prophet"
    order: int = 30
    threshold: float | str = "auto"
    window: float = 0.5
    every: float = 0.1
    persistence: int = 2
    refit: str = "none"
    refit_samples: int = 1000
    max_refits: int = 10
    seed: int = 0
    auto_k: float = 2.0
    auto_floor: float = 0.01
    auto_z: float = 4.0
    validation_fraction: float = 2 / 3
    chunk_seconds: float = 20.0
    history_points: int = 20000
    evaluation_points: int = 20000

    def validated(self) -> "MonitorOptions":
        """Check every option; raise one :class:`OptionError` listing all problems."""
        problems = []

        def positive(name: str, value: Any) -> None:
            if not (isinstance(value, (int, float)) and not isinstance(value, bool)
                    and math.isfinite(value) and value > 0):
                problems.append(f"{name}: expected a positive number, got {value!r}")

        if not isinstance(self.signal, str) or not self.signal or self.signal == "time":
            problems.append(f"signal: expected a column name other than 'time', got {self.signal!r}")
        train = tuple(self.train) if isinstance(self.train, (tuple, list)) else None
        if (train is None or len(train) != 2
                or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in train)
                or not train[1] > train[0]):
            problems.append(f"train: expected START END with END > START (seconds), got {self.train!r}")
        if self.model not in MODELS:
            problems.append(f"model: expected one of {', '.join(MODELS)}, got {self.model!r}")
        if not isinstance(self.order, int) or self.order < 1:
            problems.append(f"order: expected an integer ≥ 1, got {self.order!r}")
        if self.threshold != "auto":
            if isinstance(self.threshold, bool) or not isinstance(self.threshold, (int, float)) \
                    or not math.isfinite(self.threshold) or self.threshold <= 0:
                problems.append(f"threshold: expected a positive number in the signal's units or 'auto', "
                                f"got {self.threshold!r}")
        for name in ("window", "every", "chunk_seconds", "auto_k", "auto_z"):
            positive(name, getattr(self, name))
        if not (isinstance(self.auto_floor, (int, float)) and self.auto_floor >= 0):
            problems.append(f"auto_floor: expected a number ≥ 0, got {self.auto_floor!r}")
        if not (isinstance(self.validation_fraction, float) and 0.2 <= self.validation_fraction <= 0.9):
            problems.append(f"validation_fraction: expected a fraction in [0.2, 0.9], got {self.validation_fraction!r}")
        for name, low in (("persistence", 1), ("refit_samples", 32), ("max_refits", 0),
                          ("history_points", 100), ("evaluation_points", 100)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                problems.append(f"{name}: expected an integer ≥ {low}, got {value!r}")
        if self.refit not in REFIT_POLICIES:
            problems.append(f"refit: expected one of {', '.join(REFIT_POLICIES)}, got {self.refit!r}")
        if problems:
            raise OptionError("invalid monitor options:\n  " + "\n  ".join(problems))
        return replace(self, train=(float(self.train[0]), float(self.train[1])))

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["train"] = list(self.train)
        return d


class BoundedSeries:
    """Rows of floats kept up to ``capacity``; when full, every other row is dropped and only
    every ``stride``-th new row is kept (so the series always spans the whole run)."""

    def __init__(self, names: tuple[str, ...], capacity: int):
        self.names = names
        self.capacity = int(capacity)
        self._data = np.empty((self.capacity, len(names)))
        self._n = 0
        self._seen = 0
        self.stride = 1

    def __len__(self) -> int:
        return self._n

    def extend(self, rows: np.ndarray) -> None:
        rows = np.asarray(rows, dtype=float).reshape(-1, len(self.names))
        idx = self._seen + np.arange(len(rows))
        self._seen += len(rows)
        while True:
            keep = rows[idx % self.stride == 0]
            if self._n + len(keep) <= self.capacity:
                self._data[self._n:self._n + len(keep)] = keep
                self._n += len(keep)
                return
            half = self._data[:self._n:2].copy()     # kept rows are multiples of stride: keep 2·stride
            self._n = len(half)
            self._data[:self._n] = half
            self.stride *= 2

    def array(self) -> np.ndarray:
        return self._data[:self._n].copy()

    def column(self, name: str) -> np.ndarray:
        return self._data[:self._n, self.names.index(name)].copy()

    def clear(self) -> None:
        self._n = 0
        self._seen = 0
        self.stride = 1


@dataclass
class Fit:
    """One fitted model with its threshold (there are several with ``refit="paper"``)."""

    start: float
    end: float
    estimate: PeriodEstimate
    forecaster: Forecaster
    rule: ThresholdRule
    seconds: float

    def as_dict(self) -> dict[str, Any]:
        return {"train_start": self.start, "train_end": self.end, "period": self.estimate.as_dict(),
                "model": self.forecaster.settings(), "threshold": self.rule.as_dict(),
                "seconds": self.seconds}


_STATE_CODE = {State.TRAINING: 0.0, State.STABLE: 1.0, State.ALARM: 2.0}
_CODE_STATE = {v: k for k, v in _STATE_CODE.items()}


class Monitor:
    """Incremental monitor of one signal (see the module docstring).

    ``on_event(event)`` and ``on_evaluation(time, mae, threshold, state)`` are called as
    things happen (the CLI prints and logs from them); ``source`` names the data in error
    messages.
    """

    def __init__(self, options: MonitorOptions, *, source: str = "<data>",
                 on_event: Callable[[Event], None] | None = None,
                 on_evaluation: Callable[[float, float, float, State], None] | None = None):
        self.options = options.validated()
        self.source = source
        self.on_event = on_event
        self.on_evaluation = on_evaluation
        self.fits: list[Fit] = []
        self.events: list[Event] = []
        self.history = BoundedSeries(("time", "value", "forecast"), self.options.history_points)
        self.evaluations = BoundedSeries(("time", "mae", "threshold", "state"), self.options.evaluation_points)
        self.timing = {"train": 0.0, "forecast": 0.0, "evaluate": 0.0}
        self.restarts = 0
        self._reset_state()

    def _reset_state(self) -> None:
        o = self.options
        self.detector = Detector(persistence=o.persistence, refit=o.refit, max_refits=o.max_refits)
        self._t = np.empty(0)
        self._x = np.empty(0)
        self._f = np.empty(0)
        self._dt: float | None = None
        self._fit: Fit | None = None
        self._next_k = 0
        self._origin = 0.0
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

    # -- feeding ----------------------------------------------------------------------------
    def _emit(self, events: list[Event]) -> None:
        for e in events:
            self.events.append(e)
            if self.on_event is not None:
                self.on_event(e)

    def feed(self, t: np.ndarray, x: np.ndarray) -> None:
        """Add samples (strictly increasing times, after any already fed) and process them."""
        t = np.asarray(t, dtype=float)
        x = np.asarray(x, dtype=float)
        if t.size == 0:
            return
        self.n_samples += t.size
        if self.first_time is None:
            self.first_time = float(t[0])
        self.last_time = float(t[-1])
        o = self.options
        f = np.full(t.size, np.nan)
        if self._fit is not None:
            start = time.perf_counter()
            after = t > self._fit.end + self._eps
            if after.any():
                f[after] = self._fit.forecaster.predict(t[after])
            self.timing["forecast"] += time.perf_counter() - start
        else:
            keep = t >= o.train[0] - 1e-9
            t, x, f = t[keep], x[keep], f[keep]
        self._t = np.concatenate([self._t, t])
        self._x = np.concatenate([self._x, x])
        self._f = np.concatenate([self._f, f])
        if self._fit is not None:
            self.history.extend(np.column_stack([t, x, f]))
        if self._fit is None and self._t.size and self._t[-1] >= o.train[1] - 1e-9:
            self._train_initial()
        if self._fit is not None:
            self._evaluate_due()
            self._trim()

    @property
    def _eps(self) -> float:
        return 1e-6 * (self._dt or 1e-3)

    def _train_initial(self) -> None:
        o = self.options
        sel = (self._t >= o.train[0] - 1e-9) & (self._t <= o.train[1] + 1e-9)
        if sel.sum() < 16:
            raise TrainingError(f"{self.source}: the training window {o.train[0]:g}–{o.train[1]:g} s holds "
                                f"{int(sel.sum())} samples of {o.signal}; at least 16 are needed")
        self._dt = float(np.median(np.diff(self._t[sel])))
        tt, xx = self._t[sel], self._x[sel]
        # samples before the window end are training data; they go to the history as such
        self.history.extend(np.column_stack([tt, xx, np.full(tt.size, np.nan)]))
        self._install_fit(tt, xx, end=o.train[1])
        # the samples that arrived after the training window end
        rest = self._t > o.train[1] + self._eps
        if rest.any():
            start = time.perf_counter()
            self._f[rest] = self._fit.forecaster.predict(self._t[rest])
            self.timing["forecast"] += time.perf_counter() - start
            self.history.extend(np.column_stack([self._t[rest], self._x[rest], self._f[rest]]))

    def _install_fit(self, tt: np.ndarray, xx: np.ndarray, end: float) -> None:
        o = self.options
        start = time.perf_counter()
        try:
            est = dominant_period(tt, xx, order=o.order)
        except TrainingError as exc:
            raise TrainingError(f"{self.source}: {o.signal} in {tt[0]:g}–{tt[-1]:g} s: {exc}") from exc
        model = fit_forecaster(o.model, tt, xx, est.period, order=o.order, seed=o.seed,
                               chunk_seconds=o.chunk_seconds)
        if o.threshold == "auto":
            rule = auto_threshold(tt, xx, est, model=o.model, order=o.order, window=o.window, every=o.every,
                                  k=o.auto_k, floor=o.auto_floor, z=o.auto_z,
                                  validation_fraction=o.validation_fraction, seed=o.seed)
        else:
            rule = fixed_threshold(float(o.threshold))
        seconds = time.perf_counter() - start
        self.timing["train"] += seconds
        fit = Fit(float(tt[0]), float(end), est, model, rule, seconds)
        self.fits.append(fit)
        self._fit = fit
        self._origin = float(end)
        self._next_k = int(np.ceil(o.window / o.every - 1e-9))     # first window wholly after `end`
        info = {"period_fft_s": est.fft_period, "period_s": est.period, "period_stderr_s": est.period_stderr,
                "model": o.model, "order": model.order, "fit_seconds": model.fit_seconds,
                "train_start": fit.start, "train_end": fit.end, "threshold_base": rule.base,
                "threshold_slope_per_s": rule.slope}
        if "validation_mae_max" in rule.details:
            info["validation_mae_max"] = rule.details["validation_mae_max"]
        self._emit(self.detector.trained(float(end), rule, info))

    def _evaluate_due(self) -> None:
        o = self.options
        while True:
            assert self._fit is not None
            newest = float(self._t[-1])
            k_last = int(np.floor((newest - self._origin) / o.every + 1e-9))
            if k_last < self._next_k:
                return
            ks = np.arange(self._next_k, k_last + 1)
            times = self._origin + o.every * ks
            start = time.perf_counter()
            mae, _ = window_mae(self._t, self._x, self._f, times, o.window, eps=self._eps,
                                min_samples=max(1, int(round(0.5 * o.window / self._dt))))
            thr = np.asarray(self._fit.rule.at(times), dtype=float)
            self.timing["evaluate"] += time.perf_counter() - start
            refit_at = None
            done = []
            for j, (tk, m, th) in enumerate(zip(times.tolist(), mae.tolist(), thr.tolist())):
                self._next_k = int(ks[j]) + 1
                if not math.isfinite(m):          # window emptied by skipped rows: no evaluation
                    continue
                events, refit = self.detector.update(tk, m, th)
                self.n_evaluations += 1
                if m / th > self.max_ratio:
                    self.max_ratio = m / th
                done.append((tk, m, th, _STATE_CODE[self.detector.state]))
                if self.on_evaluation is not None:
                    self.on_evaluation(tk, m, th, self.detector.state)
                if events:
                    self._emit(events)
                if refit:
                    refit_at = tk
                    break
            if done:
                self.evaluations.extend(np.array(done))
            if refit_at is None:
                return
            self._refit(refit_at)

    def _refit(self, at: float) -> None:
        o = self.options
        sel = np.flatnonzero(self._t <= at + self._eps)[-o.refit_samples:]
        tt, xx = self._t[sel], self._x[sel]
        self._install_fit(tt, xx, end=at)
        later = self._t > at + self._eps
        self._f[:] = np.nan
        if later.any():
            self._f[later] = self._fit.forecaster.predict(self._t[later])

    def _trim(self) -> None:
        o = self.options
        assert self._dt is not None
        keep_s = max(o.window + 2 * o.every, (o.refit_samples + 2) * self._dt if o.refit == "paper" else 0.0)
        cut = np.searchsorted(self._t, self._t[-1] - keep_s, side="left")
        if cut > 4096:          # trim in large steps; keeps concatenation cheap
            self._t, self._x, self._f = self._t[cut:], self._x[cut:], self._f[cut:]

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
        return pd.DataFrame({"time": arr[:, 0], "mae": arr[:, 1], "threshold": arr[:, 2],
                             "state": [_CODE_STATE[c].value for c in arr[:, 3]]})

    def history_frame(self) -> "Any":
        import pandas as pd

        arr = self.history.array()
        return pd.DataFrame({"time": arr[:, 0], self.options.signal: arr[:, 1], "forecast": arr[:, 2]})


@dataclass
class MonitorResult:
    """What :func:`replay` and :func:`follow` return (and what ``summary.json`` records)."""

    exchange_path: Path
    options: MonitorOptions
    status: str                       # finished | run_failed | run_interrupted | timeout | interrupted
    summary: dict[str, Any]
    events: list[dict[str, Any]]
    evaluations: Any                  # DataFrame time, mae, threshold, state
    history: Any                      # DataFrame time, <signal>, forecast (decimated when long)
    fits: list[Fit]
    warnings: list[str] = field(default_factory=list)
    run_info: RunInfo | None = None
    error: str | None = None

    @property
    def first_alarm_time(self) -> float | None:
        return self.summary.get("first_alarm_time")

    @property
    def alarmed(self) -> bool:
        return self.summary.get("alarms", 0) > 0

    @property
    def fault_time(self) -> float | None:
        return self.summary.get("fault_time")

    @property
    def detection_latency(self) -> float | None:
        return self.summary.get("detection_latency_s")

    @property
    def false_alarms(self) -> int | None:
        return self.summary.get("false_alarms_before_fault")

    @property
    def period(self) -> PeriodEstimate | None:
        return self.fits[0].estimate if self.fits else None

    @property
    def exit_code(self) -> int:
        """0 no alarm, 1 alarm or failed run, 130 interrupted."""
        if self.status == "interrupted":
            return 130
        return 1 if (self.alarmed or self.status == "run_failed") else 0


# ------------------------------------------------------------------------------------------
class _Session:
    """Shared plumbing of replay and follow: reader, monitor, output files, warnings."""

    def __init__(self, path: Path, options: MonitorOptions, out_dir: str | os.PathLike[str] | None,
                 on_event: Callable[[Event], None] | None,
                 on_evaluation: Callable[[float, float, float, State], None] | None,
                 on_warning: Callable[[str], None] | None):
        self.path = path
        self.options = options.validated()
        self.out_dir = None if out_dir is None else Path(out_dir)
        self.on_warning = on_warning
        self.warnings: list[str] = []
        self.started = time.perf_counter()
        self.read_seconds = 0.0
        self.reads_with_rows = 0
        self._writers = None
        if self.out_dir is not None:
            from .report import OutputWriters

            self._writers = OutputWriters(self.out_dir)

        def event_cb(e: Event) -> None:
            if self._writers is not None:
                self._writers.event(e)
            if on_event is not None:
                on_event(e)

        def eval_cb(t: float, m: float, th: float, s: State) -> None:
            if self._writers is not None:
                self._writers.evaluation(t, m, th, s)
            if on_evaluation is not None:
                on_evaluation(t, m, th, s)

        self.monitor = Monitor(self.options, source=str(path), on_event=event_cb, on_evaluation=eval_cb)
        self.reader = ExchangeReader(path, [self.options.signal])

    def warn(self, message: str) -> None:
        self.warnings.append(message)
        if self.on_warning is not None:
            self.on_warning(message)

    def poll(self) -> tuple[int, bool, bool]:
        """One poll: feed new rows.  Returns (rows, progressed, missing)."""
        start = time.perf_counter()
        before = self.reader.offset
        batch = self.reader.poll()
        self.read_seconds += time.perf_counter() - start
        if batch.restarted:
            self.warn(f"{self.path}: the file was replaced or truncated; starting again from its beginning")
            self.monitor.reset()
            if self._writers is not None:
                self._writers.restart()
        for issue in batch.issues:
            self.warn(issue.message)
        if len(batch):
            self.reads_with_rows += 1
        self.monitor.feed(batch.time, batch.values[self.options.signal])
        progressed = batch.restarted or self.reader.offset != before
        return len(batch), progressed, batch.missing

    def close(self) -> None:
        self.reader.close()
        if self._writers is not None:
            self._writers.close()

    def result(self, status: str, run: RunInfo | None, error: str | None = None,
               plots: bool = True) -> MonitorResult:
        mon = self.monitor
        total = time.perf_counter() - self.started
        summary = build_summary(self, status, run, total, error)
        result = MonitorResult(self.path, self.options, status, summary,
                               [e.as_dict() for e in mon.events], mon.evaluation_frame(), mon.history_frame(),
                               list(mon.fits), list(self.warnings), run, error)
        if self._writers is not None:
            self._writers.finish(result, plots=plots)
        return result


def build_summary(session: _Session, status: str, run: RunInfo | None, total: float,
                  error: str | None) -> dict[str, Any]:
    mon = session.monitor
    o = session.options
    alarms = [e for e in mon.events if e.kind == "alarm"]
    fault = run.fault_time if run is not None else None
    first = alarms[0] if alarms else None
    if run is None:
        false_alarms = None
        latency = None
    elif fault is None:
        false_alarms = len(alarms)
        latency = None
    else:
        # the row at the fault time still shows the old state (the change is visible from the
        # next row on), so an alarm at t <= fault cannot be caused by the fault: a false alarm
        false_alarms = sum(1 for e in alarms if e.time <= fault + 1e-9)
        after = [e for e in alarms if e.time > fault + 1e-9]
        latency = round(after[0].time - fault, 9) if after else None
    ev = mon.evaluation_frame()
    pre = ev[ev["time"] <= fault + 1e-9] if fault is not None else ev
    fit = mon.fits[0] if mon.fits else None
    timing = dict(mon.timing)
    timing.update({"read": session.read_seconds, "total": total,
                   "per_evaluation": (mon.timing["evaluate"] / mon.n_evaluations) if mon.n_evaluations else None})
    if mon.first_time is not None and mon.last_time is not None and total > 0:
        timing["simulated_span"] = mon.last_time - mon.first_time
        timing["realtime_factor"] = (mon.last_time - mon.first_time) / total
    return {
        "schema": SCHEMA,
        "status": status,
        "error": error,
        "exchange": str(session.path),
        "signal": o.signal,
        "options": o.as_dict(),
        "rows": session.reader.stats.as_dict(),
        "reads_with_rows": session.reads_with_rows,
        "restarts": mon.restarts,
        "samples": mon.n_samples,
        "last_time": mon.last_time,
        "period": fit.estimate.as_dict() if fit else None,
        "model": fit.forecaster.settings() if fit else None,
        "fit_seconds": fit.forecaster.fit_seconds if fit else None,
        "train_seconds": fit.seconds if fit else None,
        "validation_mae": fit.rule.details.get("validation_mae_max") if fit else None,
        "threshold": fit.rule.as_dict() if fit else None,
        "fits": [f.as_dict() for f in mon.fits],
        "refits": mon.detector.refits,
        "final_state": mon.state.value,
        "evaluations": mon.n_evaluations,
        "max_mae_over_threshold": mon.max_ratio if mon.n_evaluations else None,
        "max_mae_before_fault": float(pre["mae"].max()) if len(pre) else None,
        "alarms": len(alarms),
        "alarm_times": [e.time for e in alarms[:1000]],
        "first_alarm_time": first.time if first else None,
        "first_alarm_mae": first.mae if first else None,
        "first_alarm_threshold": first.threshold if first else None,
        "message": ALARM_MESSAGE if first else None,
        "run_status": run.status if run else None,
        "run_error": run.error if run else None,
        "fault_time": fault,
        "detection_latency_s": latency,
        "false_alarms_before_fault": false_alarms,
        "timing_s": timing,
        "warnings": len(session.warnings),
    }


def warm_up(model: str) -> None:
    """Import the heavy libraries the monitor will need (so a live monitor reacts at once)."""
    import pandas  # noqa: F401
    import scipy.optimize  # noqa: F401
    import sklearn.metrics  # noqa: F401

    if model == "prophet":
        from .forecasters import quiet_prophet

        with quiet_prophet():
            import prophet  # noqa: F401


def _options(options: MonitorOptions | None, kwargs: dict[str, Any]) -> MonitorOptions:
    base = options or MonitorOptions()
    unknown = sorted(set(kwargs) - set(MonitorOptions.__dataclass_fields__))
    if unknown:
        raise OptionError(f"unknown monitor option(s): {', '.join(unknown)}; known: "
                          f"{', '.join(MonitorOptions.__dataclass_fields__)}")
    if "train" in kwargs and kwargs["train"] is not None:
        kwargs["train"] = tuple(kwargs["train"])
    return replace(base, **kwargs).validated()


def replay(exchange_path: str | os.PathLike[str], *, options: MonitorOptions | None = None,
           out_dir: str | os.PathLike[str] | None = None, plots: bool = True,
           on_event: Callable[[Event], None] | None = None,
           on_evaluation: Callable[[float, float, float, State], None] | None = None,
           on_warning: Callable[[str], None] | None = None, **settings: Any) -> MonitorResult:
    """Monitor a finished exchange file; return a :class:`MonitorResult` (prints nothing).

    ``settings`` are :class:`MonitorOptions` fields (``signal="x2"``, ``model="harmonic"``,
    ``threshold=0.01``, ``train=(0, 9)``, ...), applied over ``options``.  With ``out_dir``
    the files ``events.jsonl``, ``evaluations.csv``, ``summary.json`` and (``plots``) the
    PNG figures are written there; without it nothing is written.

    Raises :class:`~monitor.errors.ExchangeMissingError`,
    :class:`~monitor.errors.ExchangeFormatError` (empty, header only, missing column, no
    valid row), :class:`~monitor.errors.TrainingError` (data ends before the training
    window, constant signal) and :class:`~monitor.errors.OptionError`.
    """
    opts = _options(options, settings)
    path = Path(exchange_path)
    if not path.exists():
        raise ExchangeMissingError(f"{path}: exchange file not found (use --follow to wait for it)")
    if path.is_dir():
        raise ExchangeMissingError(f"{path}: is a directory, expected an exchange CSV file")
    run = read_run_info(path)
    session = _Session(path, opts, out_dir, on_event, on_evaluation, on_warning)
    try:
        if run is not None and run.status == "unreadable":
            session.warn(f"{run.error}; fault time unknown")
        elif run is not None and run.status == "running":
            session.warn(f"{run.path}: the run is still running; replaying the rows written so far "
                         "(use --follow to follow it)")
        while True:
            _, progressed, missing = session.poll()
            if missing:
                raise ExchangeMissingError(f"{path}: the exchange file disappeared while being read")
            if not progressed:
                break
        session.reader.check_finished()
        note = session.reader.skip_summary()
        if note:
            session.warn(note)
        status = "finished"
        error = None
        if run is not None and run.status == "failed":
            status = "run_failed"
            error = f"the run failed: {run.error or 'no message in run.json'}"
            session.warn(f"{run.path}: {error}")
        if status == "finished" or session.monitor.trained:
            session.monitor.finish()
        elif not session.monitor.trained:
            session.warn(f"{path}: the run failed before the training window was complete; nothing monitored")
        return session.result(status, run, error, plots=plots)
    finally:
        session.close()


def follow(exchange_path: str | os.PathLike[str], *, options: MonitorOptions | None = None,
           out_dir: str | os.PathLike[str] | None = None, plots: bool = True, poll: float = 0.2,
           timeout: float = 60.0, on_event: Callable[[Event], None] | None = None,
           on_evaluation: Callable[[float, float, float, State], None] | None = None,
           on_warning: Callable[[str], None] | None = None, on_wait: Callable[[str], None] | None = None,
           sleep: Callable[[float], None] = time.sleep, **settings: Any) -> MonitorResult:
    """Follow a growing exchange file until its run ends; return a :class:`MonitorResult`.

    Waits for the file to appear (at most ``timeout`` s), reads new complete rows every
    ``poll`` s, and stops when ``run.json`` says the run ``finished``, ``failed`` or was
    ``interrupted`` (after reading every row), or when no new row came for ``timeout`` s
    (``timeout=0``: wait for ever).  A replaced or truncated file restarts the monitor.
    Ctrl-C ends it with status ``interrupted`` (the outputs are still written).
    """
    opts = _options(options, settings)
    if not (isinstance(poll, (int, float)) and poll > 0):
        raise OptionError(f"poll: expected a positive number of seconds, got {poll!r}")
    if not (isinstance(timeout, (int, float)) and timeout >= 0):
        raise OptionError(f"timeout: expected a number of seconds ≥ 0 (0 = no limit), got {timeout!r}")
    path = Path(exchange_path)
    if path.is_dir():
        raise ExchangeMissingError(f"{path}: is a directory, expected an exchange CSV file")
    warm_up(opts.model)
    session = _Session(path, opts, out_dir, on_event, on_evaluation, on_warning)
    seen = False
    waiting_said = False
    last_progress = time.monotonic()
    run: RunInfo | None = None
    status = "finished"
    error = None
    try:
        try:
            while True:
                run = read_run_info(path)          # read before the rows: rows precede the status
                rows, progressed, missing = session.poll()
                while progressed and not missing:  # drain everything available now
                    last_progress = time.monotonic()
                    seen = True
                    r, progressed, missing = session.poll()
                if missing and not waiting_said and on_wait is not None:
                    on_wait(f"waiting for {path} to appear")
                    waiting_said = True
                if not missing:
                    seen = True
                if run is not None and run.ended and not missing:
                    if run.status == "failed":
                        status = "run_failed"
                        error = f"the run failed: {run.error or 'no message in run.json'}"
                        session.warn(f"{run.path}: {error}")
                    elif run.status == "interrupted":
                        status = "run_interrupted"
                        session.warn(f"{run.path}: the run was interrupted; stopping")
                    break
                idle = time.monotonic() - last_progress
                if timeout and idle > timeout:
                    if not seen:
                        raise ExchangeMissingError(f"{path}: the exchange file did not appear within "
                                                   f"{timeout:g} s (--timeout)")
                    if session.reader.header is None:
                        raise ExchangeFormatError(f"{path}: no complete header line within {timeout:g} s")
                    status = "timeout"
                    session.warn(f"{path}: no new rows for {timeout:g} s and run.json does not say the run "
                                 "ended; stopping (--timeout 0 waits for ever)")
                    break
                sleep(poll)
        except KeyboardInterrupt:
            status = "interrupted"
        note = session.reader.skip_summary()
        if note:
            session.warn(note)
        if status in ("finished", "timeout"):
            if session.reader.header is None or session.reader.stats.rows == 0:
                session.reader.check_finished()
            session.monitor.finish()
        elif not session.monitor.trained:
            what = "monitoring was interrupted" if status == "interrupted" else f"the run ended ({status})"
            session.warn(f"{path}: {what} before the training window was complete; nothing monitored")
        return session.result(status, run, error, plots=plots)
    finally:
        session.close()

"""A new detector is one class in one file: this module defines a toy Page–Hinkley detector,
registers it, and runs the monitor's library API with it, changing no other file.

The toy watches the residual of a harmonic forecast (fitted on the training window) with a
one-sided Page–Hinkley test: ``m_n = Σ (r_i − r̄ − δ)``, alarm when ``m_n − min m > λ``.
It is deliberately minimal (no clear, no refit); it is not a product detector.
"""
from __future__ import annotations

import numpy as np
import pytest

from monitor import (Detector, Event, Monitor, MonitorOptions, OptionError, State, dominant_period, fit_forecaster,
                     fixed_threshold, register, replay)
from monitor.detector import Fit
from monitor.detectors import detector_names, unregister

PERIOD = 2.2            # s, no multiple of the step
DT = 0.01
STEP_TIME = 20.0        # s: the signal steps up by STEP here
STEP = 0.5
NOISE = 0.01            # σ of the added noise, in the signal's unit (amplitude 1)


class PageHinkley(Detector):
    name = "toy-page-hinkley"
    label = "PH"
    delta = 0.05        # drift allowance per sample: 5 σ of the noise, so healthy residuals pull m_n down
    limit = 5.0         # λ: a 0.5 step adds ≈ 0.45 per sample, so it is crossed ≈ 12 samples after the step

    def __init__(self, options, host):
        super().__init__(options, host)
        self._model = None
        self._mean = 0.0
        self._sum = 0.0
        self._min = 0.0

    def train(self, t, X, end, sample_step):
        x = X[:, 0]
        estimate = dominant_period(t, x, order=5)
        self._model = fit_forecaster("harmonic", t, x, estimate.period, order=5)
        self._mean = float(np.mean(x - self._model.predict(t)))
        self.host.add_fit(Fit(float(t[0]), float(end), estimate, self._model, fixed_threshold(self.limit), 0.0))
        self._enter(State.STABLE)
        self.host.emit([Event(end, "trained", State.TRAINING, None, self.limit, "model fitted"),
                        Event(end, "stable", State.STABLE, None, self.limit, "monitoring")])

    def update(self, t, X):
        f = self._model.predict(t)
        for ti, r in zip(t.tolist(), (X[:, 0] - f).tolist()):
            self._sum += r - self._mean - self.delta
            self._min = min(self._min, self._sum)
            statistic = self._sum - self._min
            if self.state is State.STABLE and statistic > self.limit:
                self.host.emit([self._raise_alarm(ti, statistic, self.limit, reason="page-hinkley")])
            self.host.record(ti, statistic, self.limit, self.state)
        return f

    @classmethod
    def describe(cls, event):
        return " (Page–Hinkley)" if event.kind == "alarm" else f"harmonic model; PH limit {cls.limit:g}"


@pytest.fixture
def toy():
    register(PageHinkley)
    yield PageHinkley
    unregister(PageHinkley.name)


def step_signal(stop: float = 30.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    t = np.round(np.arange(0.0, stop + DT / 2, DT), 10)
    x = np.sin(2 * np.pi * t / PERIOD) + 0.3 * np.sin(4 * np.pi * t / PERIOD + 0.4)
    x = x + np.random.default_rng(seed).normal(0.0, NOISE, t.size) + np.where(t >= STEP_TIME, STEP, 0.0)
    return t, x


def test_a_registered_detector_runs_in_the_monitor_and_alarms_on_the_step(toy):
    assert toy.name in detector_names()
    options = MonitorOptions(detector=toy.name, model="harmonic", order=5)
    assert options.validated().detector_class is toy
    t, x = step_signal()
    mon = Monitor(options)
    for i in range(0, t.size, 137):                 # batches of an odd size
        mon.feed(t[i:i + 137], x[i:i + 137])
    mon.finish()
    assert isinstance(mon.detector, toy) and mon.trained
    alarms = [e for e in mon.events if e.kind == "alarm"]
    # one alarm (the toy latches), after the step and within 0.5 s of it: ≈ 12 samples are
    # expected (module constants); 0.5 s leaves a factor 4 for the fit's residual error
    assert len(alarms) == 1 and STEP_TIME <= alarms[0].time <= STEP_TIME + 0.5, alarms
    assert alarms[0].data == {"reason": "page-hinkley"} and alarms[0].state is State.ALARM
    ev = mon.evaluation_frame()
    before = ev["time"] < STEP_TIME
    # not before: on the healthy 11 s the statistic stays below a tenth of the limit
    assert before.sum() > 1000 and ev.loc[before, "statistic"].max() < 0.1 * toy.limit
    assert mon.state is State.ALARM and mon.detector.alarms == 1


def test_a_registered_detector_runs_through_replay(toy, tmp_path):
    t, x = step_signal()
    path = tmp_path / "exchange.csv"
    path.write_text("time,x2\n" + "".join(f"{a:.2f},{b:.9f}\n" for a, b in zip(t, x)))
    result = replay(path, detector=toy.name, model="harmonic", order=5, out_dir=tmp_path / "out", plots=False)
    s = result.summary
    assert s.first_alarm_time is not None and STEP_TIME <= s.first_alarm_time <= STEP_TIME + 0.5
    assert s.alarms == 1 and s.as_json()["detector"] == toy.name
    assert (tmp_path / "out" / "evaluations.csv").is_file()


def test_an_unregistered_detector_is_refused(toy):
    unregister(toy.name)
    with pytest.raises(OptionError, match="detector: expected one of cusum, mae"):
        MonitorOptions(detector=toy.name).validated()

"""The contract every registered detector keeps (river's ``check_estimator`` idea), run over each.

On a synthetic periodic signal (two harmonics, σ = 0.01 white noise, a 10 σ step at 25 s)
monitored with the harmonic model:

- batch-size invariance: samples fed in batches of 1, 7 and all at once give the same events
  and the same evaluations (the statistic to 1e-12 relative: a vectorised sum's order);
- event order: times never decrease; the run starts trained → stable;
- latched alarm: the step is alarmed, nothing before it; an alarm holds (every evaluation
  until its clear is in state ALARM, no second alarm inside an episode);
- the designed false-alarm rate on white noise (detectors designed by a rate);
- its events written to events.jsonl read back through the contract
  (:mod:`fourbar_common.contract.monitor_events`) to the same bytes, typed.

A detector registered later is checked by the same tests without a new line here.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from fourbar_common.contract.monitor_events import EVENT_KINDS, MonitorEvent, OtherPayload, read_events
from monitor import Monitor, MonitorOptions, replay
from monitor.detectors import detector_class, detector_names

PERIOD = 2.2            # s, no multiple of the step
DT = 0.01               # s
NOISE = 0.01            # σ of the white noise (signal amplitude ≈ 1.3)
STEP_TIME = 25.0        # s
STEP = 0.1              # 10 σ
STOP = 40.0             # s

DETECTORS = detector_names()


def signal(stop: float, seed: int, step: float) -> tuple[np.ndarray, np.ndarray]:
    t = np.round(np.arange(0.0, stop + DT / 2, DT), 10)
    x = np.sin(2 * np.pi * t / PERIOD) + 0.3 * np.sin(4 * np.pi * t / PERIOD + 0.4)
    return t, x + np.random.default_rng(seed).normal(0.0, NOISE, t.size) + np.where(t >= STEP_TIME, step, 0.0)


def monitored(name: str, batch: int | None, **settings) -> Monitor:
    t, x = signal(STOP, 0, STEP)
    mon = Monitor(MonitorOptions(detector=name, model="harmonic", order=5, **settings).validated())
    size = batch or t.size
    for i in range(0, t.size, size):
        mon.feed(t[i:i + size], x[i:i + size])
    mon.finish()
    return mon


def comparable(events) -> list[dict]:
    """The events without the fit's wall-clock seconds (the only field that may differ between
    runs), numbers to 11 significant digits (the statistic's round-off, below)."""
    return [{k: float(f"{v:.11g}") if isinstance(v, float) else v for k, v in e.as_dict().items()
             if k != "fit_seconds"} for e in events]


@pytest.fixture(scope="module")
def runs():
    cache: dict = {}

    def get(name: str, batch: int | None) -> Monitor:
        if (name, batch) not in cache:
            cache[(name, batch)] = monitored(name, batch)
        return cache[(name, batch)]
    return get


@pytest.mark.parametrize("name", DETECTORS)
def test_batch_size_does_not_change_events_or_evaluations(runs, name):
    whole = runs(name, None)
    for batch in (1, 7):
        other = runs(name, batch)
        assert [(e.time, e.kind, e.state) for e in other.events] == [(e.time, e.kind, e.state) for e in whole.events]
        assert comparable(other.events) == comparable(whole.events), batch
        a, b = other.evaluation_frame(), whole.evaluation_frame()
        np.testing.assert_array_equal(a.time, b.time)
        assert (a.state == b.state).all()
        # the statistic to round-off: a vectorised pass (the CUSUM's Lindley form, a cumulative
        # sum) adds in a batch-dependent order; measured 2e-14 relative, bounded at 1e-12
        np.testing.assert_allclose(a.statistic, b.statistic, rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(a.threshold, b.threshold)


@pytest.mark.parametrize("name", DETECTORS)
def test_events_come_in_time_order(runs, name):
    events = runs(name, None).events
    times = [e.time for e in events]
    assert times == sorted(times)
    assert [e.kind for e in events[:2]] == ["trained", "stable"]
    assert {e.kind for e in events} <= set(EVENT_KINDS)


@pytest.mark.parametrize("name", DETECTORS)
def test_an_alarm_latches_until_it_clears(runs, name):
    mon = runs(name, None)
    alarms = [e for e in mon.events if e.kind == "alarm"]
    # a 10 σ step is alarmed within 1 s (every built-in needs a few samples: docs/detection.md)
    # and nothing before it
    assert alarms and STEP_TIME <= alarms[0].time <= STEP_TIME + 1.0, [(e.kind, e.time) for e in mon.events]
    changes = [e for e in mon.events if e.kind in ("alarm", "clear")]
    assert all(a.kind != b.kind for a, b in zip(changes, changes[1:])), "a second alarm inside an episode"
    ev = mon.evaluation_frame()
    for k, alarm in enumerate(changes):
        if alarm.kind != "alarm":
            continue
        end = changes[k + 1].time if k + 1 < len(changes) else np.inf
        held = ev[(ev.time >= alarm.time) & (ev.time < end - 1e-9)]
        assert len(held) and (held.state == "ALARM").all(), alarm


@pytest.mark.parametrize("name", DETECTORS)
def test_false_alarms_on_white_noise_stay_within_the_design(name):
    """A healthy signal with white noise, 340 s monitored after a 60 s training window (long
    enough that the period's error does not grow into the residual over the run).

    Designed detectors run at their highest rate, 100 false alarms per hour, so the design
    expects μ = 9.4 in 340 s; the number of alarm episodes must not exceed Poisson(μ)'s 99.9 %
    quantile (20).  Only this upper bound is the contract: latching merges crossings into one
    episode and the noise scale is raised to its upper confidence limit, so a detector is
    meant to be conservative.  A detector not designed by a rate raises no alarm at all.
    """
    from scipy.stats import poisson

    cls = detector_class(name)
    rate_field = cls.Settings.design_rate
    settings = {rate_field: 100.0} if rate_field else {}
    t, x = signal(400.0, 7, 0.0)
    mon = Monitor(MonitorOptions(detector=name, model="harmonic", order=5, train=(0.0, 60.0), **settings).validated())
    mon.feed(t, x)
    mon.finish()
    episodes = sum(e.kind == "alarm" for e in mon.events)
    if rate_field is None:
        assert episodes == 0
        return
    hours = (t[-1] - 60.0) / 3600.0
    assert cls.designed_arl0_hours(mon.options.settings) == pytest.approx(0.01)
    mu = 100.0 * hours
    assert episodes <= poisson.ppf(0.999, mu), (episodes, mu)


@pytest.mark.parametrize("name", DETECTORS)
def test_events_round_trip_through_the_events_contract(name, tmp_path):
    t, x = signal(STOP, 0, STEP)
    path = tmp_path / "exchange.csv"
    path.write_text("time,x2\n" + "".join(f"{a:.2f},{b:.17g}\n" for a, b in zip(t, x)))
    result = replay(path, detector=name, model="harmonic", order=5, out_dir=tmp_path / "m", plots=False)
    lines = (tmp_path / "m" / "events.jsonl").read_text().splitlines()
    events = read_events("\n".join(lines))
    assert [(e.time, e.event) for e in events] == [(e["time"], e["event"]) for e in result.events]
    for line, event in zip(lines, events):
        assert event.to_json() == line                           # the same bytes back
        assert not isinstance(event.payload, OtherPayload), line  # a built-in's payload is typed
        assert MonitorEvent.from_json(event.to_json()) == event
    assert any(e.event == "alarm" and e.payload.reason for e in events)


def test_a_line_that_is_not_an_event_names_every_bad_field():
    from fourbar_common.contract.problems import ContractError

    with pytest.raises(ContractError) as info:
        MonitorEvent.from_json('{"time": "soon", "event": "boom", "state": "?", "statistic": "big"}', "e.jsonl:3")
    assert [p.field for p in info.value.problems] == ["time", "event", "state", "statistic"]
    assert str(info.value).startswith("e.jsonl:3: time: expected a number of seconds, got 'soon'")
    with pytest.raises(ContractError, match="cusum_h: missing"):     # a typed payload checks its fields
        MonitorEvent.from_dict({"time": 9.0, "event": "trained", "state": "TRAINING", "detector": "cusum",
                                "period_fft_s": 3.0, "period_s": 3.0, "period_stderr_s": None, "model": "harmonic",
                                "order": 30, "fit_seconds": 0.1, "train_start": 0.0, "train_end": 9.0,
                                "signals": ["x2"], "cusum_k": 0.25, "arl0_hours": 100.0, "noise_sigma": {"x2": 1e-3},
                                "signal_periods_s": {"x2": 3.0}}, strict=True)
    with pytest.raises(ContractError, match="not JSON"):
        MonitorEvent.from_json('{"time": 2.0')

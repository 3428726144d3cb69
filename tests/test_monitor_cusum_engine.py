"""The CUSUM engine's two passes agree: vectorised while the statistics stay below their
limit, sample by sample right after a crossing (monitor/sequential.py, ``_cusum_scalar``).

Fed the same data whole, the engine runs the scalar pass through every stretch of repeated
crossings; fed one sample at a time, every sample goes through the vectorised pass.  The
results must be the same: the same alarm and clear events at the same times with the same
onsets, and evaluations equal up to the round-off of summing in another order.
"""
from __future__ import annotations

import numpy as np
import pytest

from monitor import Monitor, MonitorOptions

DT = 0.01
PERIOD = 2.2


def _run(t: np.ndarray, x: np.ndarray, batch: int):
    mon = Monitor(MonitorOptions(model="harmonic", clear_after=2.0, every=0.1))
    for i in range(0, t.size, batch):
        mon.feed(t[i:i + batch], x[i:i + batch])
    events = [(round(e.time, 9), e.kind, e.data.get("onset"), e.data.get("side")) for e in mon.events]
    return events, mon.evaluation_frame()


def test_the_scalar_and_vectorised_passes_give_the_same_result():
    rng = np.random.default_rng(7)
    t = np.round(np.arange(0.0, 60.0 + DT / 2, DT), 10)
    x = np.cos(2 * np.pi * t / PERIOD) + 0.002 * rng.standard_normal(t.size)
    # a fault from 20 to 30 s, large enough that the restarted statistics cross at almost every
    # sample (the scalar pass), then gone: the alarm clears after 2 s and a second one at 45 s
    x += np.where((t > 20.0) & (t <= 30.0), 0.05, 0.0) + np.where(t > 45.0, -0.05, 0.0)
    whole_events, whole = _run(t, x, t.size)
    single_events, single = _run(t, x, 1)
    kinds = [e[1] for e in whole_events]
    assert kinds.count("alarm") == 2 and kinds.count("clear") == 1, whole_events   # the scenario is exercised
    assert whole_events == single_events
    assert whole.shape == single.shape
    np.testing.assert_array_equal(whole["time"], single["time"])
    # the same recursion S = max(0, S + w) summed sample by sample or through a cumulative sum:
    # the statistic (up to ~h = 31) agrees to a few ulps of its size, 1e-12 relative leaves room
    np.testing.assert_allclose(whole["statistic"], single["statistic"], rtol=1e-12, atol=1e-12)
    assert (whole["state"] == single["state"]).all()

"""Unit tests of the monitor's parts on synthetic signals with known answers."""
from __future__ import annotations

import logging

import numpy as np
import pytest

from monitor import (Monitor, MonitorOptions, OptionError, State, TrainingError, auto_threshold,
                     dominant_period, fit_forecaster, fixed_threshold, replay)
from monitor.bounded import BoundedSeries
from monitor.mae import MaeRule
from monitor.threshold import evaluation_times, window_mae
from monitor.spectrum import fourier_design
from test_monitor_support import orchestrated

P_TRUE = 2.718281828          # s, a period that is no multiple of the sampling step
DT = 0.01


def signal(t: np.ndarray) -> np.ndarray:
    """Non-sinusoidal periodic signal (5 harmonics), amplitude ~0.5."""
    w = 2 * np.pi * t / P_TRUE
    return 0.4 * np.cos(w) + 0.12 * np.sin(2 * w + 0.3) + 0.05 * np.cos(3 * w) + 0.02 * np.sin(5 * w) + 0.1


@pytest.fixture(scope="module")
def grid():
    return np.round(np.arange(0, 30.0 + DT / 2, DT), 10)


# -- spectrum -------------------------------------------------------------------------------------
def test_fourier_design_matches_cos_sin():
    t = np.linspace(0, 100, 1001)
    A = fourier_design(t, 3.05, 30)
    k = np.arange(1, 31)
    w = 2 * np.pi * np.multiply.outer(t, k) / 3.05
    np.testing.assert_allclose(A[:, 1::2], np.cos(w), rtol=0, atol=1e-11)   # recurrence: ~order·eps·phase
    np.testing.assert_allclose(A[:, 2::2], np.sin(w), rtol=0, atol=1e-11)
    assert (A[:, 0] == 1).all()


def test_dominant_period_refines_the_fft(grid):
    t = grid[grid <= 9.0]
    est = dominant_period(t, signal(t))
    assert abs(est.fft_period - P_TRUE) < 0.1 * P_TRUE                 # FFT: within a bin or so
    assert abs(est.fft_period - P_TRUE) > 1e-4                          # ... but not precise
    assert abs(est.period - P_TRUE) < 1e-8                              # exact model: round-off only
    assert est.fft_bin_width == pytest.approx(1 / 9.01, rel=1e-6)
    assert est.amplitude == pytest.approx(0.5 * np.ptp(signal(t)))
    assert est.residual_rms < 1e-7


def test_dominant_period_with_noise_and_gaps(grid):
    rng = np.random.default_rng(3)
    t = grid[grid <= 9.0]
    keep = rng.random(t.size) > 0.05                                    # 5 % of the rows skipped
    t = t[keep]
    x = signal(t) + rng.normal(0, 0.01, t.size)
    est = dominant_period(t, x, order=10)
    assert abs(est.period - P_TRUE) < 4 * est.period_stderr            # the standard error is honest
    assert 1e-5 < est.period_stderr < 1e-3


def test_dominant_period_errors(grid):
    t = grid[grid <= 9.0]
    with pytest.raises(TrainingError, match="constant"):
        dominant_period(t, np.full(t.size, 0.3))
    with pytest.raises(TrainingError, match="at least 16"):
        dominant_period(t[:10], signal(t[:10]))
    short = t[t <= 3.0]                                                 # 1.1 periods
    with pytest.raises(TrainingError, match="at least 1.5 are needed"):
        dominant_period(short, signal(short))


# -- forecasters ------------------------------------------------------------------------------------
def test_harmonic_forecaster(grid):
    t = grid[grid <= 9.0]
    f = fit_forecaster("harmonic", t, signal(t), P_TRUE, order=8)
    np.testing.assert_allclose(f.predict(grid), signal(grid), rtol=0, atol=1e-10)   # exact model
    off = grid[:50] + 0.003                                            # off the sample grid
    np.testing.assert_allclose(f.predict(off), signal(off), rtol=0, atol=1e-10)
    # the value at a time does not depend on what else was asked for (bit-identical)
    parts = np.concatenate([f.predict(grid[:1234]), f.predict(grid[1234:2001]), f.predict(grid[2001:])])
    assert np.array_equal(parts, f.predict(grid))
    with pytest.raises(OptionError, match="model: 'arima'"):
        fit_forecaster("arima", t, signal(t), P_TRUE)
    assert fit_forecaster("harmonic", t, signal(t), P_TRUE, order=500).order == 134   # capped: Nyquist


def test_prophet_forecaster(grid, capfd):
    cmdstan = logging.getLogger("cmdstanpy")
    level = cmdstan.level
    t = grid[grid <= 9.0]
    rng = np.random.default_rng(11)
    x = signal(t) + rng.normal(0, 1e-4, t.size)       # a sensor-like floor (a noise-free exact fit
    f = fit_forecaster("prophet", t, x, P_TRUE, order=10, chunk_seconds=5.0)   # is capped: max_iter)
    s = f.settings()
    assert s["growth"] == "flat" and s["builtin_seasonalities"] is False and s["uncertainty_samples"] == 0
    assert s["seasonality"] == {"name": "cycle", "period_days": P_TRUE / 86400, "fourier_order": 10}
    assert f.model.seasonalities.keys() == {"cycle"}
    y = f.predict(grid)
    np.testing.assert_allclose(y, signal(grid), rtol=0, atol=2e-4)     # MAP fit, 21 s beyond the data
    harmonic = fit_forecaster("harmonic", t, x, P_TRUE, order=10)
    np.testing.assert_allclose(y, harmonic.predict(grid), rtol=0, atol=2e-5)   # the same model
    assert f.predict_calls <= 8                                         # chunks, not one call per sample
    assert np.array_equal(f.predict_direct(grid[1500:1600]), y[1500:1600])
    assert cmdstan.level == level                                       # logging restored after the fit
    printed = capfd.readouterr()
    assert "cmdstanpy" not in printed.err and "Chain" not in printed.err and "plotly" not in printed.err


# -- detector ----------------------------------------------------------------------------------------
def test_evaluation_times_have_no_drift():
    t = evaluation_times(9.0, 9.5, 100.0, 0.1)
    assert t.size == 906 and t[0] == 9.5 and t[-1] == 100.0
    np.testing.assert_allclose(np.diff(t), 0.1, rtol=0, atol=1e-12)


def test_window_mae_uses_the_newest_window():
    t = np.round(np.arange(0, 2.0 + DT / 2, DT), 10)
    actual = np.zeros(t.size)
    forecast = np.where(t > 1.0, 0.2, 0.0)
    mae, n = window_mae(t, actual, forecast, np.array([1.0, 1.02, 1.05, 1.5]), 0.05, eps=1e-8)
    assert list(n) == [5, 5, 5, 5]                                     # (t - 0.05, t]
    np.testing.assert_allclose(mae, [0.0, 0.08, 0.2, 0.2], rtol=0, atol=1e-15)


def test_detector_persistence_and_clear():
    det = MaeRule(persistence=2)
    det.trained(9.0, fixed_threshold(1.0))
    assert det.state is State.STABLE
    seq = [(9.5, 0.5), (9.6, 1.5), (9.7, 0.5), (9.8, 1.5), (9.9, 2.0), (10.0, 0.5), (10.1, 3.0), (10.2, 0.1),
           (10.3, 0.2)]
    kinds = []
    for t, m in seq:
        events, refit = det.update(t, m, 1.0)
        assert not refit
        kinds += [(e.kind, e.time) for e in events]
    assert kinds == [("alarm", 9.9), ("clear", 10.3)]
    assert det.alarms == 1 and det.first_alarm.statistic == 2.0 and det.state is State.STABLE


def test_detector_paper_refit_policy():
    det = MaeRule(refit="paper", max_refits=2)
    det.trained(9.0, fixed_threshold(1.0))
    assert det.state is State.TRAINING
    assert det.update(9.5, 2.0, 1.0)[1] is True                        # above before stable: refit
    det.trained(9.5, fixed_threshold(1.0))
    events, refit = det.update(10.0, 0.5, 1.0)
    assert not refit and events[0].kind == "stable" and det.state is State.STABLE
    det = MaeRule(refit="paper", max_refits=1)
    det.trained(9.0, fixed_threshold(1.0))
    assert det.update(9.5, 2.0, 1.0)[1]
    det.trained(9.5, fixed_threshold(1.0))
    events, refit = det.update(10.0, 2.0, 1.0)                          # out of refits
    assert not refit and events[0].kind == "alarm" and events[0].data["reason"] == "refit_limit"


def test_auto_threshold_rule(grid):
    t = grid[grid <= 9.0]
    clean = auto_threshold(t, signal(t), dominant_period(t, signal(t)), model="harmonic", order=10,
                           window=0.5, every=0.1)
    # clean data: the validation error is ~0, the floor (1 % of the amplitude) decides
    assert clean.base == pytest.approx(0.01 * 0.5 * np.ptp(signal(t)))
    assert clean.slope < 1e-6 and clean.details["validation_mae_max"] < 1e-6
    rng = np.random.default_rng(5)
    x = signal(t) + rng.normal(0, 0.01, t.size)
    est = dominant_period(t, x)
    noisy = auto_threshold(t, x, est, model="harmonic", order=10, window=0.5, every=0.1)
    V = noisy.details["validation_mae_max"]
    assert 0.006 < V < 0.015                                           # E|N(0, 0.01)| = 0.008
    assert noisy.base == pytest.approx(2 * V)
    G = noisy.details["max_window_slope"]
    assert noisy.slope == pytest.approx(4 * G * est.period_stderr / est.period)
    assert noisy.at(est.t_center + 100) == pytest.approx(noisy.base + 100 * noisy.slope)


def test_monitor_finds_a_step_change(grid):
    t = grid
    x = signal(t) + np.where(t > 15.0, 0.05, 0.0)
    mon = Monitor(MonitorOptions(model="harmonic", detector="mae", threshold=0.01, window=0.5, every=0.1,
                                 persistence=2))
    for i in range(0, t.size, 37):                      # in uneven batches, as a follower reads
        mon.feed(t[i:i + 37], x[i:i + 37])
    alarms = [e.time for e in mon.events if e.kind == "alarm"]
    assert alarms[0] == pytest.approx(15.2)     # MAE 0.01 at 15.1 (not above), 0.02 at 15.2: 2 above
    ev = mon.evaluation_frame()
    assert ev["time"].iloc[0] == pytest.approx(9.5)      # the first window wholly after the training end
    assert ev["statistic"][ev["time"] <= 15.0 + 1e-9].max() < 1e-6


# -- engine pieces ---------------------------------------------------------------------------------
def test_bounded_series_decimates():
    s = BoundedSeries(("a",), 100)
    for start in range(0, 1000, 7):
        s.extend(np.arange(start, min(start + 7, 1000), dtype=float)[:, None])
    a = s.column("a")
    assert len(a) <= 100 and a[0] == 0 and s.stride == 16
    assert (np.diff(a) == s.stride).all()          # every stride-th row of the whole stream


def test_options_are_checked_together():
    with pytest.raises(OptionError) as info:
        MonitorOptions(window=-1, persistence=0, refit="sometimes", threshold="high").validated()
    text = str(info.value)
    for name in ("window:", "persistence:", "refit:", "threshold:"):
        assert name in text
    with pytest.raises(OptionError, match="unknown monitor option"):
        replay("x.csv", windw=0.3)


def test_paper_refit_policy_end_to_end(tmp_path_factory, fourbar_fmu):
    exchange = orchestrated(tmp_path_factory, fourbar_fmu, "case2")
    r = replay(exchange, model="harmonic", detector="mae", refit="paper")
    kinds = [e["event"] for e in r.events[:3]]
    assert kinds == ["trained", "stable", "alarm"]           # stable at the first evaluation (9.5 s)
    assert r.events[1]["time"] == 9.5 and r.first_alarm_time == pytest.approx(10.3)
    # a threshold no model can meet: refit on the latest 1000 samples, then give up and alarm
    r = replay(exchange, model="harmonic", detector="mae", refit="paper", threshold=1e-9, max_refits=2)
    kinds = [e["event"] for e in r.events]
    assert kinds[:5] == ["trained", "refit", "trained", "refit", "trained"]
    assert r.events[5]["event"] == "alarm" and r.events[5]["reason"] == "refit_limit"
    assert r.summary.fits[1].end == 9.5 and r.summary.fits[1].forecaster.settings()["n_train"] == 951


def test_the_default_signal_is_the_runs_first_output(tmp_path, capsys):
    """No --signal: the run's first output column (x2 for the four-bar), not a four-bar name."""
    from monitor.cli import main

    t = np.round(np.arange(0.0, 12.0 + 0.005, 0.01), 10)
    theta = np.sin(2 * np.pi * t / 1.7)
    path = tmp_path / "exchange.csv"
    path.write_text("time,theta,omega\n" + "".join(f"{a:.2f},{b:.17g},{c:.17g}\n"
                                                    for a, b, c in zip(t, theta, np.cos(2 * np.pi * t / 1.7))))
    result = replay(path, model="harmonic", plots=False)
    assert result.options.signal == "theta" and result.summary.fit is not None
    assert main([str(path), "--model", "harmonic", "--no-plots", "--out", str(tmp_path / "m")]) == 0
    assert "(signal theta, model harmonic" in capsys.readouterr().out

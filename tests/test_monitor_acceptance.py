"""Acceptance criteria of the monitor (issue 4) on exchange files written by fourbar-run.

The issue-4 figures are the paper's rule's (``detector="mae"``): they must still hold, so
the fixture replays with it.  The command test at the end runs the default (cusum).

- Case 1 (100 s): no alarm, with both models.
- Case 2 (L2 1.0 → 1.1 m at 10 s): first alarm ≤ 0.5 s after the fault, both models,
  default settings (the paper needed 4 s).
- σ = 5 mm sensor noise on x2: Case 1 no alarm; Case 2 alarm ≤ 1.0 s after the fault.
- The command's outputs: the paper's message with time, MAE and threshold; summary.json,
  events.jsonl, evaluations.csv and the three figures.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from monitor import ALARM_MESSAGE, dominant_period, read_exchange, replay
from monitor.cli import main
from test_monitor_support import orchestrated

pytestmark = pytest.mark.slow    # real orchestrated runs with Prophet; `make check` leaves them out

MODELS = ("prophet", "harmonic")


@pytest.fixture(scope="module")
def results(tmp_path_factory, fourbar_fmu):
    """replay() of each orchestrated run with each model, default settings otherwise."""
    out = {}
    for run in ("case1", "case2", "noise1", "noise2"):
        path = orchestrated(tmp_path_factory, fourbar_fmu, run)
        for model in MODELS:
            out[run, model] = replay(path, model=model, detector="mae")
    return out


@pytest.mark.parametrize("model", MODELS)
def test_case1_has_no_alarm(results, model):
    r = results["case1", model]
    s = r.summary
    assert r.status == "finished" and r.exit_code == 0
    assert s.alarms == 0 and s.first_alarm_time is None
    assert s.false_alarms == 0 and s.fault_time is None
    assert s.evaluations == 906                          # 9.5 .. 100 s every 0.1 s
    # margin: clean data stays far below the threshold
    assert s.max_statistic_over_threshold < 0.3


@pytest.mark.parametrize("model", MODELS)
def test_case2_alarms_within_half_a_second(results, model):
    r = results["case2", model]
    s = r.summary
    assert r.exit_code == 1
    assert s.fault_time == 10.0
    assert s.false_alarms == 0
    assert 10.0 <= s.first_alarm_time <= 10.5
    assert 0.0 <= s.detection_latency <= 0.5
    assert s.max_statistic_before_fault < 0.1 * s.fit.rule.base     # STABLE well before the fault
    first = next(e for e in r.events if e["event"] == "alarm")
    assert first["message"] == ALARM_MESSAGE and first["statistic"] > first["threshold"]


@pytest.mark.parametrize("model", MODELS)
def test_noise_case1_has_no_alarm(results, model):
    s = results["noise1", model].summary
    assert s.alarms == 0
    assert s.max_statistic_over_threshold < 0.8
    # the validation term sees the noise: MAE of N(0, σ) is σ·sqrt(2/π) ≈ 4 mm
    assert 0.003 < s.validation_mae < 0.008


@pytest.mark.parametrize("model", MODELS)
def test_noise_case2_alarms_within_one_second(results, model):
    s = results["noise2", model].summary
    assert s.false_alarms == 0
    assert 0.0 <= s.detection_latency <= 1.0


def test_models_agree(results):
    """Prophet's flat-trend seasonal model and the least-squares Fourier series are the same model."""
    p = results["case2", "prophet"].history
    h = results["case2", "harmonic"].history
    after = p["time"] > 9.0
    np.testing.assert_allclose(p["forecast"][after], h["forecast"][after], rtol=0,
                               atol=2e-4)  # Stan's optimiser vs exact least squares, 91 s ahead


def test_refined_period_is_accurate(tmp_path_factory, fourbar_fmu):
    """The 9 s FFT is 0.11 Hz coarse; the refinement gets the period of the whole 100 s run."""
    df = read_exchange(orchestrated(tmp_path_factory, fourbar_fmu, "case1"))
    t, x = df["time"].to_numpy(), df["x2"].to_numpy()
    est = dominant_period(t[t <= 9.0], x[t <= 9.0])
    reference = dominant_period(t, x)       # 32 cycles
    assert abs(est.fft_period - reference.period) > 0.01                     # FFT alone: ~1 % off
    # Refined: within 5e-5 s (1.6e-5 relative), 700 times closer than the FFT alone.  The bound
    # is not tighter because the reference carries its own error: at Table 1's atol = 1e-6 the
    # 100 s run drifts by millimetres with the round-off (the same FMU gave a whole-run period
    # of 3.0573563 s with the numpy/scipy of before and 3.0573263 s with numpy 2.4 / scipy 1.17,
    # while the 9 s estimate stayed 3.057353 s).
    assert abs(est.period - reference.period) < 5e-5
    assert est.period_stderr < 1e-6


def test_command_reports_the_alarm_and_writes_outputs(tmp_path_factory, fourbar_fmu, tmp_path, capsys):
    exchange = orchestrated(tmp_path_factory, fourbar_fmu, "case2")
    out_dir = tmp_path / "monitor"
    code = main([str(exchange), "--out", str(out_dir)])           # default: prophet, cusum
    printed = capsys.readouterr()
    assert code == 1
    assert ALARM_MESSAGE in printed.out
    alarm_line = next(line for line in printed.out.splitlines() if "ALARM  " in line and "CUSUM" in line)
    assert "t=   10.01 s" in alarm_line and "on x2" in alarm_line and "episode 1" in alarm_line
    assert "detected 0.01 s after it" in printed.out
    assert "Traceback" not in printed.err
    assert len(printed.out.splitlines()) < 40          # a 100 s replay prints a screenful, not 900 lines

    summary = json.loads((out_dir / "summary.json").read_text())
    assert summary["period"]["fft_s"] != summary["period"]["refined_s"]
    assert summary["model"]["kind"] == "prophet" and summary["model"]["growth"] == "flat"
    assert summary["model"]["seasonality"]["period_days"] == pytest.approx(summary["period"]["refined_s"] / 86400)
    assert summary["model"]["order"] == 30 and summary["model"]["uncertainty_samples"] == 0
    assert summary["fit_seconds"] > 0 and summary["detector"] == "cusum"
    assert summary["threshold"]["k"] == 0.25 and summary["threshold"]["arl0_hours"] >= 100 - 1e-9
    assert summary["first_alarm_time"] == pytest.approx(10.01)
    assert summary["fault_time"] == 10.0 and summary["detection_latency_s"] == pytest.approx(0.01)
    assert summary["alarms"] == 1 and summary["alarm_episodes"][0]["signal"] == "x2"
    assert summary["false_alarms_before_fault"] == 0
    events = [json.loads(line) for line in (out_dir / "events.jsonl").read_text().splitlines()]
    assert [e["event"] for e in events[:3]] == ["trained", "stable", "alarm"]
    assert {"time", "statistic", "threshold", "state", "message", "signal", "onset"} <= set(events[2])
    evaluations = (out_dir / "evaluations.csv").read_text().splitlines()
    assert evaluations[0] == "time,statistic,threshold,state" and len(evaluations) == 911   # 9.1 .. 100 s
    for name in ("history.png", "statistic.png", "spectrum.png"):
        data = (out_dir / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000


def test_command_exit_0_without_alarm(tmp_path_factory, fourbar_fmu, tmp_path, capsys):
    exchange = orchestrated(tmp_path_factory, fourbar_fmu, "case1")
    code = main([str(exchange), "--model", "harmonic", "--out", str(tmp_path / "m"), "--no-plots", "--quiet"])
    printed = capsys.readouterr()
    assert code == 0
    assert printed.out.strip().startswith("verdict: no alarm")
    assert not list((tmp_path / "m").glob("*.png"))

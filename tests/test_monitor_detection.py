"""The sequential (CUSUM) detector on real runs, and its false-alarm calibration.

Runs are made by ``fourbar-run`` with the native FMU (fast: an hour of simulation in a few
seconds); the monitor reads only the exchange files.  Tolerances are stated where used.
"""
from __future__ import annotations

import subprocess

import numpy as np
import pytest

from monitor import replay
from monitor.cusum import arl_siegmund, cusum_run_length, cusum_threshold
from support import FOURBAR_RUN, case_file


# -- calibration of the limit h -------------------------------------------------------------------
@pytest.mark.parametrize("k, arl0", [(0.25, 1000.0), (0.5, 2000.0)])
def test_siegmund_limit_matches_monte_carlo(k, arl0):
    """h from Siegmund's approximation gives the requested in-control ARL on N(0, 1) data.

    4000 chains: the standard error of the mean run length is ~1.6 %; 10 % allows for it and
    for the approximation's own error (~2 % here)."""
    h = cusum_threshold(arl0, k)
    assert arl_siegmund(h, k) == pytest.approx(arl0, rel=1e-9)
    lengths = cusum_run_length(h, k, chains=4000, max_samples=50 * int(arl0), seed=3)
    assert lengths.max() < 50 * arl0                       # every chain ended: the mean is not truncated
    assert lengths.mean() == pytest.approx(arl0, rel=0.10)


def _run(tmp_path, native_fmu, name: str, *, stop: float, extra: str = "", case: str = "case1_normal"):
    path = case_file(case, native_fmu, tmp_path / f"{name}.toml", name=name, extra=extra)
    subprocess.run([FOURBAR_RUN, str(path), "--out", str(tmp_path / name), "--stop", repr(stop), "--quiet"],
                   check=True, timeout=600)
    return tmp_path / name / "exchange.csv"


NOISE = "\n[noise]\nseed = {seed}\nstd = {{ {cols} }}\n"


@pytest.mark.slow
def test_an_hour_of_healthy_noisy_data_raises_no_alarm(tmp_path, native_fmu):
    """σ = 5 mm on x2 for 3600 s at the default 0.01 false alarms/h: no alarm, bounded memory."""
    exchange = _run(tmp_path, native_fmu, "hour", stop=3600.0, extra=NOISE.format(seed=21, cols="x2 = 0.005"))
    r = replay(exchange, model="harmonic", plots=False)
    s = r.summary
    assert s.alarms == 0 and s.false_alarms == 0
    assert s.fit.rule.arl0_hours >= 100 - 1e-9                  # the design: ≤ 1 false alarm per 100 h
    assert s.max_statistic_over_threshold < 1.0
    # the held-out residuals measure the sensor's σ: 300 samples give a 4 % standard error, 15 %
    # allows 3.5 of them; the scale used is never below it (long-run and confidence factors ≥ 1)
    scale = s.fit.signals[0].scale
    assert scale.held_out_std == pytest.approx(0.005, rel=0.15)
    assert scale.sigma >= scale.held_out_std


@pytest.mark.slow
def test_case3_ramp_is_one_alarm_episode_within_two_seconds(tmp_path, native_fmu):
    """Case 3 (L2 ramp over 20–30 s, σ = 5 mm): the alarm latches: one episode, ≤ 2 s after the ramp starts.

    The paper's MAE rule on the same file alarms more than once (it clears between swings)."""
    exchange = _run(tmp_path, native_fmu, "case3", stop=100.0, case="case3_ramp_noise")
    r = replay(exchange, model="harmonic", plots=False)
    s = r.summary
    assert s.false_alarms == 0 and s.alarms == 1
    assert 0 < s.detection_latency <= 2.0
    assert s.final_state.value == "ALARM"                       # the deformation stays: the alarm stays
    paper = replay(exchange, model="harmonic", detector="mae", plots=False).summary
    assert paper.alarms > 1


@pytest.mark.slow
def test_several_signals_are_monitored_jointly(tmp_path, native_fmu):
    """A 1 % L4 step with σ = 3 mm on every column: x2 alone is slower than x2, x3, x4 jointly.

    Measured 1.19 s on x2 alone and 0.75 s with all six columns (seed 3); the assertion
    only needs joint ≤ x2 alone and both within the issue's 2 s."""
    cols = ", ".join(f"{c} = 0.003" for c in ("x2", "y2", "x3", "y3", "x4", "y4"))
    extra = NOISE.format(seed=3, cols=cols) + '\n[[events]]\ntype = "step"\ntime = 10.0\nvariable = "L4"\nvalue = 2.525\n'
    exchange = _run(tmp_path, native_fmu, "l4", stop=30.0, extra=extra)
    alone = replay(exchange, model="harmonic", plots=False).summary
    joint = replay(exchange, model="harmonic", signal="x2,x3,x4", plots=False).summary
    assert alone.false_alarms == 0 and joint.false_alarms == 0
    assert alone.alarms == 1 and joint.alarms == 1
    assert joint.detection_latency <= alone.detection_latency <= 2.0
    assert len(joint.fit.signals) == 3 and joint.fit.rule.statistics == 6
    # one period for the mechanism: every signal's model uses the common period
    assert {f.forecaster.period for f in joint.fit.signals} == {joint.fit.period}
    episode = joint.alarm_events[0].data
    assert episode["signal"] in ("x2", "x3", "x4") and 9.0 <= episode["onset"] <= joint.first_alarm_time


def _step(time: float, value: float) -> str:
    return f'\n[[events]]\ntype = "step"\ntime = {time!r}\nvariable = "L2"\nvalue = {value!r}\n'


@pytest.mark.slow
def test_a_late_fault_is_seen_as_fast_as_an_early_one_and_a_persisting_fault_stays_one_alarm(tmp_path, native_fmu):
    """L2 +2 % with σ = 5 mm on x2, at 10 s and ~500 s later at the same phase of the swing.

    Without phase locking the forecast slides against the data and the late fault is seen
    seconds later (a +3 % step took ~10 s at 500 s before the tracker); here the latencies
    must agree within 20 % (the issue's target) plus one evaluation step (0.1 s, the
    latency's resolution).  The early fault's run goes on for 790 s after the fault: the
    alarm must hold as one episode (before the tracker's variance was capped, the growing
    phase uncertainty silenced a long alarm and it cleared, then re-alarmed)."""
    noise = NOISE.format(seed=5, cols="x2 = 0.005")
    early = replay(_run(tmp_path, native_fmu, "early", stop=800.0, extra=noise + _step(10.0, 1.02)),
                   model="harmonic", plots=False).summary
    assert early.false_alarms == 0 and early.alarms == 1 and early.final_state.value == "ALARM"
    period = early.fit.period
    late_time = round(10.0 + round(490.0 / period) * period, 2)         # same phase, on the 0.01 s grid
    late = replay(_run(tmp_path, native_fmu, "late", stop=late_time + 15.0, extra=noise + _step(late_time, 1.02)),
                  model="harmonic", plots=False).summary
    assert late.false_alarms == 0 and late.alarms == 1
    assert 0 < early.detection_latency <= 2.0
    assert abs(late.detection_latency - early.detection_latency) <= 0.2 * early.detection_latency + 0.1

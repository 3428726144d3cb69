"""The detector beyond Table 1's swing: a crank that turns all the way round (issue 23).

Table 1's geometry released at 75° with 2 rad/s turns fully (period 1.85 s).  Its energy, and
so its period and waveform, drift slowly with the integrator's error: the phase shift grows
quadratically (about 0.1 s after 300 s at Table 1's tolerances), which the earlier
two-state phase tracker lagged behind until the CUSUM alarmed at 29 s of a healthy run.

The case files name only the start angle and rate, as a user's minimal case would, plus
Table 1's tolerances, rtol 1e-9 and atol 1e-6 (the FMU's defaults, 1e-10, all but remove the
drift): the drift is what the tracker must follow here.  Native FMU runs (0.7 s per 300 s), harmonic model (the
forecaster is not the point here; the detector is).
"""
from __future__ import annotations

import json
import math
import subprocess
from pathlib import Path

import numpy as np
import pytest

from monitor.tracking import PhaseTracker, ShapeCorrection
from support import BIN, FOURBAR_MONITOR, FOURBAR_RUN

THETA0 = math.radians(75.0)
OMEGA0 = 2.0          # rad/s: enough energy to carry the crank over the top


def _case(path: Path, fmu: Path, *, stop: float, noise: float | None = None, fault: str = "") -> Path:
    text = (f'name = "{path.stem}"\nfmu = {json.dumps(fmu.as_posix())}\n'
            f"[experiment]\nstop = {stop}\nstep = 0.01\n"
            f"[parameters]\ntheta2_start = {THETA0!r}\nomega2_start = {OMEGA0!r}\n"
            "rtol = 1e-9\natol = 1e-6\n")
    if noise is not None:
        text += f"[noise]\nseed = 3\nstd = {{ x2 = {noise!r} }}\n"
    path.write_text(text + fault, encoding="utf-8")
    return path


def _run_and_monitor(tmp_path: Path, fmu: Path, name: str, **kwargs) -> tuple[Path, dict]:
    case = _case(tmp_path / f"{name}.toml", fmu, **kwargs)
    out = tmp_path / name
    run = subprocess.run([FOURBAR_RUN, "-q", str(case), "--out", str(out)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    mon = subprocess.run([FOURBAR_MONITOR, str(out / "exchange.csv"), "--model", "harmonic"],
                         capture_output=True, text=True)
    assert mon.returncode in (0, 1), mon.stderr      # 0 no alarm, 1 alarm; anything else is an error
    assert "Traceback" not in mon.stderr
    return out, json.loads((out / "monitor" / "summary.json").read_text())


@pytest.mark.slow
@pytest.mark.parametrize("noise", [None, 0.003], ids=["clean", "sigma3mm"])
def test_rotating_crank_has_no_false_alarm_in_300_s(tmp_path, native_fmu, noise):
    out, summary = _run_and_monitor(tmp_path, native_fmu, "healthy", stop=300.0, noise=noise)
    period = summary["period"]["refined_s"]
    # the crank turns fully: one period of x2 = (L2/2)·cos θ2 is one turn, 1.85 s at this energy
    # (a swing from 75° at rest would have a period above 2.5 s)
    assert 1.80 < period < 1.90, period
    assert summary["alarms"] == 0, summary["alarm_episodes"]
    # the statistic stays clear of the limit, not just under it: measured 0.19 (clean) and 0.34
    # (3 mm) of the limit; 0.8 leaves room for another seed, and fails if the drift is not followed
    # (the two-state tracker reached the limit at 29 s)
    assert summary["max_statistic_over_threshold"] < 0.8


@pytest.mark.slow
@pytest.mark.parametrize("noise", [None, 0.003], ids=["clean", "sigma3mm"])
def test_rotating_crank_length_step_is_detected_and_diagnosed(tmp_path, native_fmu, noise):
    fault = '[[events]]\ntype = "step"\ntime = 30.0\nvariable = "L2"\nvalue = 1.01\n'
    out, summary = _run_and_monitor(tmp_path, native_fmu, "l2_step", stop=60.0, noise=noise, fault=fault)
    assert summary["false_alarms_before_fault"] == 0
    # issue 12's bound for a +1 % length step is 2 s; measured 0.10 s clean, 0.47 s with 3 mm
    assert summary["detection_latency_s"] is not None and 0.0 < summary["detection_latency_s"] <= 2.0
    diag = subprocess.run([str(BIN / "fourbar-diagnose"), str(out)], capture_output=True, text=True)
    assert diag.returncode == 0, diag.stdout + diag.stderr
    best = json.loads((out / "diagnosis" / "diagnosis.json").read_text())["best"]
    assert best["parameter"] == "L2"
    # value: noise-free the fit is exact to round-off; with 3 mm, 0.1 % of 1.01 m (measured 0.006 %)
    assert best["value"] == pytest.approx(1.01, rel=1e-6 if noise is None else 1e-3)
    # time: noise-free on the grid point; with 3 mm the change time is uncertain by a fraction of
    # a period (measured 0.13 s early), 0.5 s is a quarter of one turn
    assert abs(best["change_time"] - 30.0) <= (0.011 if noise is None else 0.5)


#: A configuration tests/test_generated_cases.py drew: another geometry whose crank turns at
#: 5 rad/s (period 1.27 s).  At Table 1's tolerances its period jumps by up to 4e-4 (relative)
#: at moments set by the integrator's step sequence (measured from the zero crossings of x2),
#: and a noise-free run alarmed at 63 s.  (Table 1's rtol alone, 1e-9, is enough for one step near
#: a fast passage to shift another rotating crank's energy by 1e-5, relative: benchmarks/robustness.py.)
FAST_CRANK = ("L1 = 4.433940965250276\nL2 = 0.9498464619813408\nL3 = 4.092154791316043\nL4 = 3.2224987761768293\n"
              "m2 = 1.5\nm3 = 0.8534693985463977\nm4 = 0.946613138952734\ntheta2_start = 0.0\n"
              "omega2_start = 5.033086486742323\n")


def _fast_crank(tmp_path: Path, fmu: Path, name: str, tolerance: str, noise: str) -> dict:
    case = tmp_path / f"{name}.toml"
    case.write_text(f'fmu = {json.dumps(fmu.as_posix())}\n[experiment]\nstop = 240.0\nstep = 0.01\n'
                    f"[parameters]\n{FAST_CRANK}{tolerance}{noise}", encoding="utf-8")
    out = tmp_path / name
    run = subprocess.run([FOURBAR_RUN, "-q", str(case), "--out", str(out)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    mon = subprocess.run([FOURBAR_MONITOR, str(out / "exchange.csv"), "--model", "harmonic", "--quiet"],
                         capture_output=True, text=True)
    assert mon.returncode in (0, 1) and "Traceback" not in mon.stderr, mon.stderr
    return json.loads((out / "monitor" / "summary.json").read_text())


@pytest.mark.slow
def test_the_fmus_default_tolerance_keeps_a_fast_crank_healthy(tmp_path, native_fmu):
    """The reason the FMU's default tolerances are 1e-10, not Table 1's (docs/monitor.md, Limitations)."""
    noisy = "[noise]\nseed = 2339\nstd = { x2 = 0.003 }\n"
    clean = _fast_crank(tmp_path, native_fmu, "default", "", "")
    with_noise = _fast_crank(tmp_path, native_fmu, "default_noisy", "", noisy)
    coarse = _fast_crank(tmp_path, native_fmu, "table1_tolerances", "rtol = 1e-9\natol = 1e-6\n", "")
    # at the default: no alarm, and the statistic well clear of the limit (measured 0.00 clean,
    # 0.29 with 3 mm; 0.8 leaves room and fails if the integrator's jumps came back)
    assert clean["alarms"] == 0 and clean["max_statistic_over_threshold"] < 0.8, clean["alarm_episodes"]
    assert with_noise["alarms"] == 0 and with_noise["max_statistic_over_threshold"] < 0.8, with_noise["alarm_episodes"]
    # at Table 1's tolerances the integrator's error shows in the same healthy motion: the statistic
    # rises well above the default's (with the closed-form FMUs it alarmed at 63 s; with the
    # generic ones, whose round-off differs, the step sequence and so the error differ: 13.8 of
    # the limit on one build, no alarm on another).  Whether it crosses the limit is luck of the
    # step sequence; that it is far above the default's (0.00) is not
    print(f"fast crank, healthy: statistic / limit {clean['max_statistic_over_threshold']:.2f} at the default "
          f"tolerances, {coarse['max_statistic_over_threshold']:.2f} at Table 1's ({coarse['alarms']} alarm(s))")
    assert coarse["max_statistic_over_threshold"] > clean["max_statistic_over_threshold"] + 0.2


def test_phase_tracker_follows_a_quadratic_phase_drift():
    """A period that drifts linearly makes τ(t) = a·t²: the acceleration state follows it without lag."""
    period, dt = 1.85, 0.01
    omega = 2 * math.pi / period
    a = 1e-6                                          # s⁻¹: the rotating crank's measured drift
    tracker = PhaseTracker(0.0, rate_std=1e-5, shift_std=1e-5, noise_per_second=1e-12, track_time=15.0)
    for block in range(300):
        t = block + dt * np.arange(1, 101)
        used, _ = tracker.shift(t)                     # as the engine does: linearised at the shift in use
        x = np.cos(omega * (t - a * t * t))
        slope = -omega * np.sin(omega * (t - used))
        residual = x - np.cos(omega * (t - used))
        tracker.update(t, slope, residual, used, np.full(t.size, 1e-8))
    shift, _ = tracker.shift(np.array([303.0]))       # 3 s ahead, the guard's horizon
    # a two-state loop with T = 15 s would lag by τ̈·T² = 4.5e-4 s; 5e-5 s is a tenth of that
    assert shift[0] == pytest.approx(a * 303.0 ** 2, abs=5e-5)
    assert tracker.mean[2] == pytest.approx(2 * a, rel=0.05)


def test_shape_correction_learns_a_periodic_offset_and_reports_its_noise():
    period, dt, tc = 2.0, 0.01, 60.0
    corr = ShapeCorrection(period, 0.0, bins=100, time_constant=tc, sample_step=dt)
    rng = np.random.default_rng(0)
    shape = lambda t: 1e-3 * np.sin(2 * np.pi * t / period) ** 3     # a waveform change, not a sinusoid
    for block in range(600):
        t = block + dt * np.arange(1, 101)
        corr.update(t, shape(t) + 1e-3 * rng.standard_normal(t.size))
    grid = np.linspace(0, period, 400, endpoint=False)
    err = corr.value(grid) - shape(grid)
    # after 10 time constants the average holds ~tc/(dt·bins) = 60 samples of weight per bin:
    # noise std 1e-3/sqrt(2·60) ≈ 1e-4 per bin; 4e-4 is four of those
    assert np.max(np.abs(err)) < 4e-4
    # Σw²/(Σw)² of an exponential average: a bin gets weight 1 per second (100 samples over 100
    # bins), Σw² gets 2/3 of that (hat weights) and decays twice as fast: (2/3)/(2·60) = 1/180;
    # ±30 % for the random phases of the samples
    assert corr.noise_ratio == pytest.approx(1 / 180, rel=0.3)

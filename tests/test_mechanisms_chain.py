"""fourbar-run -> fourbar-monitor -> fourbar-diagnose on mechanisms other than Table 1's four-bar (issue 24).

Each chain runs the three commands as a user does (subprocesses, nothing but the run folder
between them) on a case shipped in cases/, with the FMU of its mechanism from the session
fixture ``mechanism_fmus`` (the native FMU: a 20 s run takes well under a second, and it
saves its state, so the diagnosis branches from snapshots in seconds; the pythonfmu FMU
alone makes every branch re-simulate from t = 0, minutes).

The runs are shorter than the shipped 100 s cases: a fault run stops at 20 s (training
0-9 s, the fault at 10 s, and the diagnosis reads 5 s before the first alarm to 3 s after
it, so 20 s holds its window with the latency bound to spare); a healthy run lasts 60 s,
51 s of monitoring after training.  The data are noise-free, as the cases ship them.

- slider-crank (fmu_src/mechanisms/slider_crank.toml): the connecting rod L3 4.0 -> 3.96 m
  at 10 s, the monitor at its defaults (x2, the crank's centre);
- driven four-bar (fmu_src/mechanisms/fourbar_driven.toml): the coupler mass m3 1.0 ->
  1.1 kg at 10 s, the monitor on the motor's torque (its period, 1 s, is the crank's turn,
  although the torque's second harmonic is the stronger: monitor.spectrum step 3);
- Watt six-bar (fmu_src/mechanisms/watt_sixbar.toml): the second loop's coupler L5 3.0 ->
  2.97 m at 10 s, the monitor at its defaults (x2: the crank feels the other loop through the
  dynamics alone);
- five-bar (fmu_src/mechanisms/fivebar.toml, two degrees of freedom): on the periodic orbit
  of its slower normal mode (scripts/periodic_orbit.py), the right crank L5 1.5 -> 1.485 m at
  10 s, the monitor at its defaults.
"""
from __future__ import annotations

import json
import math
import re
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from support import BIN, FOURBAR_MONITOR, FOURBAR_RUN, REPO, case_file, file_key, shared_result

FOURBAR_DIAGNOSE = str(BIN / "fourbar-diagnose")
FAULT_STOP = 20.0       # s (module docstring)
HEALTHY_STOP = 60.0     # s


@dataclass(frozen=True)
class Chain:
    """One shipped case and what the chain must find in it."""

    mechanism: str                  # fmu_src/mechanisms/<mechanism>.toml
    case: str                       # cases/<case>.toml
    signal: str | None              # --signal (None: the monitor's default, x2)
    parameter: str
    before: float                   # the parameter's healthy value, its unit
    after: float                    # its value after the fault
    fault_time: float               # s
    latency_bound: float            # s (reason in ``why``)
    why: str
    period: float                   # s, the monitored signal's period in the healthy run


SLIDER = Chain("slider_crank", "slider_crank_fault_L3", None, "L3", 4.0, 3.96, 10.0, 2.0,
               "x2 (the crank) feels the shorter rod only through the dynamics: its departure grows from 0 "
               "like t^2 (0.8 s measured); 2 s is the issue-12 target for a 1 % length step",
               2.905)
DRIVEN = Chain("fourbar_driven", "fourbar_driven_fault_m3", "motor_torque", "m3", 1.0, 1.1, 10.0, 0.05,
               "the motion is imposed, so the torque is algebraic in it and jumps at once (by 3.0 N m at the "
               "first row after the fault, 34 times the monitor's noise scale of 0.09 N m, one sample over the "
               "CUSUM limit): five grid steps allow for a one-sample delay in the monitor, no more",
               1.0)

WATT = Chain("watt_sixbar", "watt_sixbar_fault_L5", None, "L5", 3.0, 2.97, 10.0, 2.0,
             "x2 (the crank) feels the second loop's shorter coupler only through the dynamics of both "
             "loops: its departure grows from 0 (0.98 s measured); 2 s is the issue-12 target for a 1 % "
             "length step", 3.3634)
FIVEBAR = Chain("fivebar", "fivebar_fault_L5", None, "L5", 1.5, 1.485, 10.0, 2.0,
                "x2 (the left crank) feels the right crank's length through the couplers and the dynamics "
                "(0.59 s measured); 2 s is the issue-12 target for a 1 % length step", 1.8889)


@dataclass
class Walls:
    """Wall time of each command, s (reported in failure messages and by -s)."""

    seconds: dict = field(default_factory=dict)

    def run(self, step: str, args: list[str], timeout: float) -> subprocess.CompletedProcess:
        start = time.perf_counter()
        proc = subprocess.run(args, capture_output=True, text=True, timeout=timeout)
        self.seconds[step] = time.perf_counter() - start
        return proc


def _without_events(path: Path) -> Path:
    """The case file with its [[events]] tables removed: the healthy run of the same case."""
    text = re.sub(r"(?ms)^\[\[events\]\].*?(?=^\[)", "", path.read_text(encoding="utf-8"))
    assert "[[events]]" not in text and "variable =" not in text
    healthy = path.with_name(f"{path.stem}_healthy.toml")
    healthy.write_text(text, encoding="utf-8")
    return healthy


def _no_traceback(proc: subprocess.CompletedProcess) -> None:
    assert "Traceback" not in proc.stderr, proc.stderr


def _json(path: Path) -> dict:
    """A JSON file read strictly: NaN or Infinity in it (not JSON) fail the test."""
    def refuse(constant: str):
        raise AssertionError(f"{path}: {constant} in a JSON file")

    return json.loads(path.read_text(encoding="utf-8"), parse_constant=refuse)


@dataclass
class Outcome:
    chain: Chain
    fault_dir: Path
    healthy_dir: Path
    monitor: subprocess.CompletedProcess
    healthy_monitor: subprocess.CompletedProcess
    diagnose: subprocess.CompletedProcess
    walls: Walls
    healthy_walls: Walls


def _monitor_args(chain: Chain, run_dir: Path) -> list[str]:
    signal = ["--signal", chain.signal] if chain.signal else []
    return [FOURBAR_MONITOR, str(run_dir / "exchange.csv"), "--quiet", "--no-plots", *signal]


@pytest.fixture(scope="module", params=[SLIDER, DRIVEN, WATT, FIVEBAR], ids=lambda c: c.mechanism)
def outcome(request, mechanism_fmus, tmp_path_factory, shared_folder) -> Outcome:
    """The chain on the case's fault (to ``FAULT_STOP``) and on the same case without it (``HEALTHY_STOP``).
    Made once per test session (~12 s of CPU each), also when both xdist workers run this
    mechanism's tests (support.shared_result)."""
    chain: Chain = request.param
    fmu = mechanism_fmus.get(chain.mechanism, "native")

    def run_chain() -> Outcome:
        tmp = tmp_path_factory.mktemp(chain.mechanism)
        case = case_file(chain.case, fmu, tmp)
        walls, healthy_walls = Walls(), Walls()
        fault_dir, healthy_dir = tmp / "fault", tmp / "healthy"

        run = walls.run("fourbar-run", [FOURBAR_RUN, str(case), "--out", str(fault_dir), "--stop", repr(FAULT_STOP),
                                        "--quiet"], timeout=300)
        assert run.returncode == 0, run.stdout + run.stderr
        monitor = walls.run("fourbar-monitor", _monitor_args(chain, fault_dir), timeout=300)
        diagnose = walls.run("fourbar-diagnose", [FOURBAR_DIAGNOSE, str(fault_dir)], timeout=600)

        run = healthy_walls.run("fourbar-run", [FOURBAR_RUN, str(_without_events(case)), "--out", str(healthy_dir),
                                                "--stop", repr(HEALTHY_STOP), "--quiet"], timeout=300)
        assert run.returncode == 0, run.stdout + run.stderr
        healthy_monitor = healthy_walls.run("fourbar-monitor", _monitor_args(chain, healthy_dir), timeout=300)
        print(f"\n{chain.mechanism}: fault chain {walls.seconds}, healthy {healthy_walls.seconds}")
        return Outcome(chain, fault_dir, healthy_dir, monitor, healthy_monitor, diagnose, walls, healthy_walls)

    key = file_key(fmu, REPO / "cases" / f"{chain.case}.toml") + repr((chain, FAULT_STOP, HEALTHY_STOP)).encode()
    return shared_result(shared_folder, "mechanism-chain", key, run_chain)


@pytest.mark.slow
def test_the_fault_is_detected_within_its_bound(outcome):
    chain, proc = outcome.chain, outcome.monitor
    _no_traceback(proc)
    assert proc.returncode == 1, proc.stdout + proc.stderr          # 1: an alarm
    summary = _json(outcome.fault_dir / "monitor" / "summary.json")
    assert summary["fault_time"] == chain.fault_time                   # from run.json
    assert summary["false_alarms_before_fault"] == 0
    latency = summary["detection_latency_s"]
    assert latency is not None and 0 < latency <= chain.latency_bound, (latency, chain.why)


@pytest.mark.slow
def test_the_diagnosis_names_the_parameter_its_value_and_time(outcome):
    chain, proc = outcome.chain, outcome.diagnose
    _no_traceback(proc)
    assert proc.returncode == 0, proc.stdout + proc.stderr          # 0: explained
    d = _json(outcome.fault_dir / "diagnosis" / "diagnosis.json")
    best = d["best"]
    assert d["verdict"] == "explained" and best["parameter"] == chain.parameter and best["kind"] == "step"
    assert best["before"] == chain.before
    # Noise-free data replayed by the FMU that made them: the fit is exact to the integrator's
    # error (1e-12 of the change measured); 1e-3 of the change is the 0.1 % noise-free target
    # taken on the change, not on the value (0.1 % of L3 would be a tenth of its 1 % step).
    change = chain.after - chain.before
    assert best["value"] == pytest.approx(chain.after, abs=1e-3 * abs(change))
    assert best["relative_change"] == pytest.approx(change / chain.before, abs=1e-3 * abs(change / chain.before))
    # A step is applied between two steps: the fault's own grid point (half a step either way).
    assert best["change_time"] == pytest.approx(chain.fault_time, abs=0.005)
    # No other parameter comes close: its residual is over 10x larger (measured 244x for the
    # slider-crank, 5.9e5x for the driven four-bar, 165x for the Watt six-bar, 197x for the
    # five-bar).
    runner = next(f for f in d["ranking"] if f["parameter"] != chain.parameter)
    assert runner["rms"] > 10 * best["rms"]
    # The stated ± covers the error (at 3 of them) and, on exact data, stays at 1e-6 of the value
    # at worst (issue 37: on a two-loop quick-return they were 30x their ±).  These four shipped
    # fault cases are not diagnosed again in tests/test_diagnose_shipped.py: this is its check.
    error = best["value"] - chain.after
    print(f"{chain.case}: {best['parameter']} {best['value']!r} error {error:.2g} stated ± {best['stderr']:.2g}: "
          f"{d['message']}")       # pytest -s: the figures docs/diagnose.md quotes
    assert abs(error) <= 3 * best["stderr"], (error, best["stderr"], d["message"])
    assert best["stderr"] <= 1e-6 * abs(chain.after), (best["stderr"], d["message"])
    assert proc.stdout.startswith(f"diagnosis: {chain.parameter} changed {chain.before:.6f} → {chain.after:.6f}")
    assert "(snapshot)" in d["simulator"]            # the native FMU saves its state: seconds, not minutes


@pytest.mark.slow
def test_a_healthy_run_raises_no_alarm(outcome):
    chain, proc = outcome.chain, outcome.healthy_monitor
    _no_traceback(proc)
    assert proc.returncode == 0, proc.stdout + proc.stderr          # 0: no alarm
    summary = _json(outcome.healthy_dir / "monitor" / "summary.json")
    assert summary["first_alarm_time"] is None and summary["fault_time"] is None
    assert summary["max_statistic_over_threshold"] < 1.0
    # The monitor found the signal's true period (the motor torque's is the crank's turn, 1 s,
    # not its stronger second harmonic; the five-bar's, its periodic orbit's 1.8889 s from
    # scripts/periodic_orbit.py's shooting).  1e-3 s: the refined period of noise-free data is
    # exact to far better; the periods are quoted to 4 or 5 digits only.
    assert summary["period"]["refined_s"] == pytest.approx(chain.period, abs=1e-3)


# -- a parameter whose healthy value is 0 -----------------------------------------------------------

@pytest.mark.slow
def test_a_zero_valued_parameter_is_diagnosed_with_an_absolute_change(mechanism_fmus, tmp_path):
    """The slider's line offset e is 0 m: a relative change cannot move it.  A step to 5 cm is
    named, valued and timed, the relative change is null (never NaN) in diagnosis.json, and
    the verdict gives the change in m."""
    fmu = mechanism_fmus.get("slider_crank", "native")
    case = case_file("slider_crank_fault_L3", fmu, tmp_path)
    text = case.read_text(encoding="utf-8")
    text = re.sub(r'(?m)^variable = "L3"', 'variable = "e"', text)
    text, count = re.subn(r"(?m)^value = 3\.96 ", "value = 0.05 ", text)
    assert count == 1
    case.write_text(text, encoding="utf-8")
    run_dir = tmp_path / "run"
    subprocess.run([FOURBAR_RUN, str(case), "--out", str(run_dir), "--stop", repr(FAULT_STOP), "--quiet"],
                   check=True, timeout=300)
    monitor = subprocess.run([FOURBAR_MONITOR, str(run_dir / "exchange.csv"), "--quiet", "--no-plots"],
                             capture_output=True, text=True, timeout=300)
    assert monitor.returncode == 1, monitor.stdout + monitor.stderr
    proc = subprocess.run([FOURBAR_DIAGNOSE, str(run_dir), "--no-plot"], capture_output=True, text=True, timeout=600)
    _no_traceback(proc)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    d = _json(run_dir / "diagnosis" / "diagnosis.json")
    best = d["best"]
    assert best["parameter"] == "e" and best["before"] == 0.0
    assert best["value"] == pytest.approx(0.05, abs=5e-5)          # 1e-3 of the change, as above
    assert best["change"] == pytest.approx(0.05, abs=5e-5)
    assert best["relative_change"] is None
    assert best["change_time"] == pytest.approx(10.0, abs=0.005)
    assert proc.stdout.startswith("diagnosis: e changed 0.000000 → 0.050000 m")
    assert re.search(r"(?m)^  e +0\.05 +\+0\.05 m ", proc.stdout), proc.stdout    # the table: absolute change


def test_change_scales_and_a_diagnosis_with_no_number_json_cannot_hold():
    """Without an FMU: the scale of a unit change, and diagnosis.json with non-finite numbers."""
    from diagnose.diagnosis import Diagnosis, change_text
    from diagnose.fit import Fit, change_of, change_scales, value_at

    values = {"L2": 1.0, "L3": 4.0, "e": 0.0, "m2": 1.0, "k": 0.0, "g": -9.81}
    units = {"L2": "m", "L3": "m", "e": "m", "m2": "kg", "k": "N/m", "g": "m/s2"}
    scales = change_scales(values, units)
    assert scales["e"] == pytest.approx(2.0, rel=1e-15)       # geometric mean of L2 and L3
    assert scales["k"] == 1.0                                  # no other parameter in N/m: one unit
    assert scales["g"] == 9.81 and scales["L3"] == 4.0         # |v0|
    for v0, scale in ((4.0, 4.0), (-9.81, 9.81), (0.0, 2.0)):
        assert value_at(v0, scale, change_of(v0, scale, 0.3)) == pytest.approx(0.3, rel=1e-14)
    assert value_at(4.0, 4.0, -0.01) == 4.0 * (1.0 - 0.01)     # a non-zero value: exactly the relative change

    fit = Fit(parameter="e", kind="step", before=0.0, value=0.05, stderr=math.inf, change_time=10.0,
              end_time=10.0, chi2=1.0, rows=800, rms=0.0, evaluations=1)
    assert fit.relative_change is None and fit.change == 0.05
    assert change_text(fit, "m") == "+0.05 m"
    d = Diagnosis(verdict="explained", message="", best=fit, ranking=(fit,), ramp=None, alarm_time=10.3,
                  onset_time=None, window=(5.3, 13.3), rows=800, columns=("x2",), noise={"x2": math.nan},
                  healthy_chi2=math.inf, reduced_chi2=None, simulator="", branches=0, seconds=0.0)
    text = json.dumps(d.to_json(), allow_nan=False)            # raises on NaN or infinity
    back = json.loads(text)
    assert back["best"]["stderr"] is None and back["noise"]["x2"] is None and back["healthy_chi2"] is None
    assert back["best"]["relative_change"] is None and back["best"]["change"] == 0.05


# -- the monitor's period on a signal whose strongest harmonic is not the first -------------------

def test_the_period_is_the_fundamental_when_a_harmonic_is_stronger():
    """A driven crank's torque: second harmonic twice the first.  The FFT's peak is at 0.5 s;
    the period is 1 s.  A signal of period 0.5 s under noise keeps 0.5 s (the longer series
    only fits noise: monitor.spectrum step 3).  Tolerances: noise-free, 1e-8 s (the residual
    is flat, quadratic, at its minimum, so round-off limits the period to about the square
    root of the double's precision; as in test_monitor_units); under noise, four standard errors."""
    from monitor import dominant_period

    t = np.arange(0.0, 9.0 + 1e-9, 0.01)
    w = 2 * np.pi * t
    torque = 20 * np.sin(w + 0.3) + 40 * np.sin(2 * w) + 5 * np.cos(3 * w)
    est = dominant_period(t, torque)
    assert est.fft_period == pytest.approx(0.5, abs=0.02) and est.harmonic == 2
    assert est.period == pytest.approx(1.0, abs=1e-8)

    rng = np.random.default_rng(5)
    half = 40 * np.sin(2 * w) + 8 * np.cos(4 * w) + rng.normal(0, 2.0, t.size)
    est = dominant_period(t, half)
    assert est.harmonic == 1 and abs(est.period - 0.5) < 4 * est.period_stderr


# -- which FMU replays a run, and a sweep on a zero-valued parameter -------------------------------

@pytest.mark.slow
def test_the_native_fmu_beside_a_pythonfmu_run_replays_it(mechanism_fmus, tmp_path):
    """A run of the pythonfmu FMU alone in its folder re-simulates every branch (the command says
    so before it starts: minutes); with the same mechanism's native FMU beside it, that one
    replays the run.  Another mechanism's native FMU beside it is not taken for it."""
    import shutil

    from diagnose import read_inputs

    folder = tmp_path / "build"
    folder.mkdir()
    fmu = Path(shutil.copy(mechanism_fmus.get("slider_crank", "pythonfmu"), folder / "SliderCrank.fmu"))
    case = case_file("slider_crank_fault_L3", fmu, tmp_path)
    run_dir = tmp_path / "run"
    subprocess.run([FOURBAR_RUN, str(case), "--out", str(run_dir), "--stop", "14.0", "--quiet"], check=True,
                   timeout=300)
    subprocess.run([FOURBAR_MONITOR, str(run_dir / "exchange.csv"), "--quiet", "--no-plots", "--signal", "x4"],
                   timeout=300)
    assert read_inputs(run_dir).resimulates
    # the command says so before its minutes begin (stopped then: SIGTERM, exit 143, nothing written)
    proc = subprocess.Popen([FOURBAR_DIAGNOSE, str(run_dir)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        note = proc.stderr.readline()
    finally:
        proc.terminate()
        _, rest = proc.communicate(timeout=60)
    assert note.startswith("fourbar-diagnose: note: SliderCrank.fmu cannot save its state") and "minutes" in note
    assert proc.returncode == 143 and "Traceback" not in rest and not (run_dir / "diagnosis").exists()
    shutil.copy(mechanism_fmus.get("fourbar_driven", "native"), folder / "FourBarDrivenNative.fmu")
    assert read_inputs(run_dir).resimulates                   # another mechanism: not a stand-in
    shutil.copy(mechanism_fmus.get("slider_crank", "native"), folder / "SliderCrankNative.fmu")
    inputs = read_inputs(run_dir)
    assert not inputs.resimulates and inputs.simulator_fmu.path.name == "SliderCrankNative.fmu"


def test_a_sweep_of_a_zero_valued_parameter_is_refused_with_the_reason(mechanism_fmus, tmp_path):
    """The sweep's sizes are relative changes: e = 0 m has none, so the sweep file is refused
    (exit 2, nothing run) with the parameter, its value and what to do instead."""
    fmu = mechanism_fmus.get("slider_crank", "native")
    case = _without_events(case_file("slider_crank_fault_L3", fmu, tmp_path))
    for size in ("relative = [0.01]", "value = [0.05]"):
        sweep = tmp_path / "e.toml"
        sweep.write_text(f'name = "e"\ncase = "{case.name}"\nstop = 20.0\n\n[fault]\nvariable = "e"\n{size}\n'
                         f'time = 10.0\n', encoding="utf-8")
        proc = subprocess.run([str(BIN / "fourbar-sweep"), str(sweep), "--dry-run", "--out", str(tmp_path / "out")],
                              capture_output=True, text=True, timeout=120)
        assert proc.returncode == 2, proc.stdout + proc.stderr
        assert "fault.variable: e is 0 m in the base case" in proc.stderr and "fourbar-diagnose" in proc.stderr
        _no_traceback(proc)
        assert not (tmp_path / "out").exists()

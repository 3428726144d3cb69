"""fourbar-diagnose on real runs: the right parameter, value and time; honest when it cannot.

Runs are made by ``fourbar-run`` (native FMU unless a test says otherwise) and monitored by
the monitor's replay; the diagnosis reads only the run folder.  Tolerances are the issue's
targets unless stated: a value within 0.1 % noise-free and 1 % with noise, a change time
within 0.02 s noise-free.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Callable

import numpy as np
import pandas as pd
import pytest

from monitor import replay
from support import FOURBAR_RUN, case_file

FOURBAR_DIAGNOSE = str(Path(sys.executable).parent / "fourbar-diagnose")
ALL = "x2,y2,x3,y3,x4,y4"


def _step(variable: str, value: float, time: float = 10.0) -> str:
    return f'\n[[events]]\ntype = "step"\ntime = {time}\nvariable = "{variable}"\nvalue = {value!r}\n'


def _noise(sigma: float, columns: str, seed: int = 7) -> str:
    cols = ", ".join(f"{c} = {sigma}" for c in columns.split(","))
    return f"\n[noise]\nseed = {seed}\nstd = {{ {cols} }}\n"


def _monitored(tmp_path: Path, fmu: Path, name: str, *, stop: float, extra: str = "", case: str = "case1_normal",
               signal: str = ALL, edit: Callable[[Path], None] | None = None, **monitor) -> Path:
    """A run folder: fourbar-run, ``edit`` of its exchange.csv if given, then the monitor
    (harmonic model) on ``signal``."""
    path = case_file(case, fmu, tmp_path / f"{name}.toml", name=name, extra=extra)
    subprocess.run([FOURBAR_RUN, str(path), "--out", str(tmp_path / name), "--stop", repr(stop), "--quiet"],
                   check=True, timeout=600)
    if edit is not None:
        edit(tmp_path / name / "exchange.csv")
    replay(tmp_path / name / "exchange.csv", out_dir=tmp_path / name / "monitor", model="harmonic", signal=signal,
           plots=False, **monitor)
    return tmp_path / name


def _diagnose_cli(run_dir: Path, *args: str) -> tuple[subprocess.CompletedProcess, dict | None]:
    proc = subprocess.run([FOURBAR_DIAGNOSE, str(run_dir), "--no-plot", *args], capture_output=True, text=True,
                          timeout=300)
    out = run_dir / "diagnosis" / "diagnosis.json"
    return proc, (json.loads(out.read_text()) if out.exists() else None)


@pytest.mark.slow
def test_case2_is_l2_to_1_1_m_at_10_s(tmp_path, fourbar_fmu):
    """The paper's Case 2 (pythonfmu FMU, x2 monitored, as in `make demo`), diagnosed on the native FMU beside it."""
    if not (fourbar_fmu.parent / "FourBarNative.fmu").exists():
        pytest.skip("the native FMU is not built beside FourBar.fmu (python build_fmu.py builds both)")
    run = _monitored(tmp_path, fourbar_fmu, "case2", case="case2_fault_L2", stop=16.0, signal="x2")
    proc, d = _diagnose_cli(run)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert d["verdict"] == "explained" and "FourBarNative.fmu (snapshot)" in d["simulator"]
    best = d["best"]
    assert best["parameter"] == "L2" and best["kind"] == "step"
    assert best["value"] == pytest.approx(1.1, rel=1e-3)
    assert best["change_time"] == pytest.approx(10.0, abs=0.005)          # the grid point itself
    # The runner-up is far worse: x2 jumps by dL2/2*cos(theta2) at once, which no other parameter does.
    assert d["ranking"][1]["chi2"] > 100 * max(best["chi2"], d["rows"])
    assert proc.stdout.startswith("diagnosis: L2 changed 1.000")


@pytest.mark.slow
def test_a_coupler_step_under_noise_and_a_mass_step_are_named(tmp_path, native_fmu):
    """L4 +2 % with σ = 5 mm on all six columns, and m2 +10 % noise-free: the right parameter and value."""
    noisy = _monitored(tmp_path, native_fmu, "l4", stop=16.0, extra=_step("L4", 2.55) + _noise(0.005, ALL))
    proc, d = _diagnose_cli(noisy)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert d["best"]["parameter"] == "L4"
    assert d["best"]["value"] == pytest.approx(2.55, rel=0.01)
    # the stated uncertainty covers the error (4 standard errors)
    assert abs(d["best"]["value"] - 2.55) < 4 * d["best"]["stderr"] + 1e-9
    assert d["noise"]["x2"] == pytest.approx(0.005, rel=0.2)               # 500 rows: a 3 % standard error

    exact = _monitored(tmp_path, native_fmu, "m2", stop=16.0, extra=_step("m2", 1.1))
    proc, d = _diagnose_cli(exact)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert d["best"]["parameter"] == "m2" and d["best"]["kind"] == "step"
    assert d["best"]["value"] == pytest.approx(1.1, rel=1e-3)
    assert d["best"]["change_time"] == pytest.approx(10.0, abs=0.02)


@pytest.mark.slow
@pytest.mark.parametrize("variable, value", [("L1", 3.3), ("m3", 1.1)])
def test_a_large_step_is_timed_to_its_grid_point(tmp_path, native_fmu, variable, value):
    """+10 % of L1 or m3 at 11 s, noise-free: the change time's chi-square profile is rugged
    (a pattern search over it named m2 for this m3 step; a scan every 0.05 s alone misses
    L1's basin, one grid point wide), so this checks the search lands on the grid point and
    the value within 0.1 %."""
    run = _monitored(tmp_path, native_fmu, variable, stop=15.0, extra=_step(variable, value, time=11.0))
    proc, d = _diagnose_cli(run)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert d["best"]["parameter"] == variable and d["best"]["kind"] == "step"
    assert d["best"]["value"] == pytest.approx(value, rel=1e-3)
    assert d["best"]["change_time"] == pytest.approx(11.0, abs=0.005)       # the grid point itself
    _check_printed_uncertainty(proc.stdout, d["best"], "kg" if variable.startswith("m") else "m")


def _check_printed_uncertainty(stdout: str, best: dict, unit: str) -> None:
    """The verdict line states the value's standard error as it is: ``± 1.6e-10 kg`` (two
    significant digits of a non-zero error), or ``exact to round-off: ± < B`` when it is at
    most 1e-11 of the value (B: the fit's resolution, the floor of every standard error).
    Noise-free, L1 +10 % is fitted exactly (standard error 0), which was printed ``± 0 m``."""
    import re

    first = stdout.splitlines()[0]
    assert "± 0 " not in first, first
    shown = re.search(rf"\((?:± (\S+)|exact to round-off: ± < (\S+)) {unit}\)", first)
    assert shown is not None, first
    stderr, scale = best["stderr"], max(abs(best["value"]), abs(best["before"]))
    if shown.group(1) is not None:
        assert float(shown.group(1)) == pytest.approx(stderr, rel=0.05)     # 2 significant digits
        assert stderr > 1e-11 * scale
    else:
        bound = float(shown.group(2))
        assert stderr <= bound <= 1.05e-11 * scale                          # the floor, to its 2 digits


@pytest.mark.slow
def test_a_mass_step_under_noise_is_sharpened_on_a_longer_window(tmp_path, native_fmu):
    """m3 +10 % at 10 s under 5 mm on six columns (seed 1): over the first 3 s after the alarm a
    step at 10.26 s to 1.120 kg fitted as well as the true one (within 2 in chi-square; 1.8 % off,
    ± 1.1 %, with the build that found it); fitted again on a longer window it is within issue
    13's 1 % and known to 0.25 %."""
    run = _monitored(tmp_path, native_fmu, "m3", stop=25.0, extra=_step("m3", 1.1) + _noise(0.005, ALL, 1))
    proc, d = _diagnose_cli(run)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    best, first = d["best"], d["first_fit"]
    assert best["parameter"] == "m3" and best["kind"] == "step"
    assert first is not None and first["parameter"] == "m3"
    assert first["stderr"] > 0.0025 * first["value"]            # loose over the first window: hence fitted again
    assert best["value"] == pytest.approx(1.1, rel=0.01)        # issue 13's target with 5 mm of noise
    assert best["change_time"] == pytest.approx(10.0, abs=0.05)
    assert best["stderr"] <= 0.0025 * best["value"]             # the precision it was sharpened to (the default)
    assert d["value_window"][1] > d["window"][1] and d["value_window"][0] == d["window"][0]
    assert best["rows"] > d["rows"]
    assert "value fitted on" in d["message"] and "fitted again over" in proc.stdout
    # never: --max-horizon equal to --horizon keeps the first window's value
    proc, d = _diagnose_cli(run, "--max-horizon", "3")
    assert proc.returncode == 0 and d["first_fit"] is None and d["best"]["value"] == pytest.approx(first["value"])


@pytest.mark.slow
def test_two_masses_the_data_cannot_tell_apart_are_said_to_be(tmp_path, native_fmu):
    """m4 +1 % under 5 mm on six columns: m2 -0.85 % fits as well (only mass ratios act, and
    m3 matters little), so the verdict is ``ambiguous`` (exit 3), naming both and the outputs
    where their simulations differ most."""
    run = _monitored(tmp_path, native_fmu, "m4", stop=16.5, extra=_step("m4", 1.01, time=11.0) + _noise(0.005, ALL, 1))
    proc, d = _diagnose_cli(run)
    assert proc.returncode == 3, proc.stdout + proc.stderr
    assert d["verdict"] == "ambiguous"
    first, second = d["ranking"][0], d["ranking"][1]
    assert {first["parameter"], second["parameter"]} == {"m2", "m4"}
    assert "cannot tell these two apart" in d["message"] and d["distinct_gap"] < 9
    assert d["separating"] and all(c["column"] in d["message"] for c in d["separating"])


@pytest.mark.slow
def test_two_parameters_at_once_are_not_explained_by_one(tmp_path, native_fmu):
    """L2 +5 % and L4 +5 % at the same time: no single parameter fits; exit 1 and the message says so."""
    run = _monitored(tmp_path, native_fmu, "two", stop=14.0, extra=_step("L2", 1.05) + _step("L4", 2.625))
    proc, d = _diagnose_cli(run)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert d["verdict"] == "unexplained"
    assert "not explained by one parameter" in proc.stdout
    assert d["reduced_chi2"] > 100                     # residuals 10x the noise floor at least


def test_a_sensor_offset_is_a_change_outside_the_model(tmp_path, native_fmu):
    """A healthy run whose x2 sensor reads 10 mm high from 10 s on (written into the exchange
    file after the run, so the FMU never saw it): no parameter moves x2 alone, so the best
    single change must leave residuals far above the noise floor; exit 1, "not explained"."""
    def offset_x2(exchange: Path) -> None:
        rows = pd.read_csv(exchange)
        rows.loc[rows["time"] >= 10.0, "x2"] += 0.010
        rows.to_csv(exchange, index=False, float_format="%.17g")

    run = _monitored(tmp_path, native_fmu, "offset", stop=16.0, edit=offset_x2)
    proc, d = _diagnose_cli(run)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert d["verdict"] == "unexplained" and "not explained by one parameter" in proc.stdout
    # a 10 mm offset against a 1e-6 m noise floor: the best fit stays orders of magnitude off
    assert d["reduced_chi2"] > 100


@pytest.mark.slow
def test_a_ramp_is_identified_as_a_ramp(tmp_path, native_fmu):
    """Case 3 (L2 ramp 1.0 -> 1.05 m over 20-30 s, σ = 5 mm on x2), noise seed 3, run to 32 s: the
    first 3 s after the alarm cannot hold the ramp's end (they gave 20.83-22.61 s at 9.6 mm/s
    with one build's round-off, 5.3 mm/s with another's); fitted again on the 10 s after the
    alarm that the run holds, it is the whole ramp."""
    path = case_file("case3_ramp_noise", native_fmu, tmp_path / "case3.toml", name="case3", seed=3)
    subprocess.run([FOURBAR_RUN, str(path), "--out", str(tmp_path / "case3"), "--stop", "32", "--quiet"],
                   check=True, timeout=600)
    run = tmp_path / "case3"
    replay(run / "exchange.csv", out_dir=run / "monitor", model="harmonic", signal="x2", plots=False)
    proc, d = _diagnose_cli(run)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    best, first = d["best"], d["first_fit"]

    def rate(f: dict) -> float:
        return (f["value"] - f["before"]) / (f["end_time"] - f["change_time"])

    assert best["parameter"] == "L2" and best["kind"] == "ramp"
    # the first window ends 3 s after the alarm (about 25 s): it cannot hold the ramp's end at 30 s
    assert first["kind"] == "ramp" and first["end_time"] <= d["window"][1] < 28.0
    # truth: 20-30 s at 5 mm/s, measured by 5 mm noise on x2; tolerances a few of the stated
    # standard errors (0.04 mm/s on the rate) and a tenth of a period on the times
    assert best["change_time"] == pytest.approx(20.0, abs=0.3)
    assert best["end_time"] == pytest.approx(30.0, abs=0.3)
    assert rate(best) == pytest.approx(0.005, rel=0.05)
    assert best["value"] == pytest.approx(1.05, abs=0.002)
    assert d["value_window"][1] == pytest.approx(32.0)


@pytest.mark.slow
def test_a_false_alarm_is_found_to_be_noise_only(tmp_path, native_fmu):
    """A healthy run under 5 mm noise, monitored by the paper's MAE rule on x2 with a threshold
    (3 mm) below the noise's own mean absolute error (sigma * sqrt(2/pi) = 4.0 mm, +- 0.4 mm
    over a 0.5 s window), so that it alarms on noise; the diagnosis fits all six columns: no
    single change beats the healthy model by the 5-sigma gain, so the verdict is no_change
    and the exit 1.  (The CUSUM designed for 100 false alarms per hour, used before, alarmed
    here only while the monitor took the y columns' second harmonic for their period; with
    their period it expects 0.2 false alarms in these 8 s.)"""
    run = _monitored(tmp_path, native_fmu, "noise", stop=17.0, extra=_noise(0.005, ALL, 3), signal="x2",
                     detector="mae", threshold=0.003)
    alarm = json.loads((run / "monitor" / "summary.json").read_text())["first_alarm_time"]
    assert alarm is not None and alarm < 14.0, "the test needs the monitor to alarm on noise"
    proc, d = _diagnose_cli(run, "--columns", ALL)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert d["verdict"] == "no_change" and proc.stdout.startswith("diagnosis: no change found")
    assert d["healthy_chi2"] - d["best"]["chi2"] < 25.0


def test_a_healthy_run_has_no_fault_to_classify(tmp_path, native_fmu):
    run = _monitored(tmp_path, native_fmu, "healthy", stop=12.0)
    proc, d = _diagnose_cli(run)
    assert proc.returncode == 2
    assert "no fault to classify" in proc.stderr and "Traceback" not in proc.stderr
    assert d is None and not (run / "diagnosis").exists()


def test_bad_run_folders_exit_2_with_the_reason(tmp_path, native_fmu):
    run = _monitored(tmp_path, native_fmu, "bad", stop=11.0, extra=_step("L3", 4.2))
    summary = (run / "monitor" / "summary.json").read_text()
    run_json = (run / "run.json").read_text()

    (run / "monitor" / "summary.json").unlink()
    proc, _ = _diagnose_cli(run)
    assert proc.returncode == 2 and "fourbar-monitor" in proc.stderr and "Traceback" not in proc.stderr
    (run / "monitor" / "summary.json").write_text(summary)

    info = json.loads(run_json)
    info["fmu"]["guid"] = "00000000-0000-0000-0000-000000000000"
    (run / "run.json").write_text(json.dumps(info))
    proc, _ = _diagnose_cli(run)
    assert proc.returncode == 2 and "GUID" in proc.stderr and "Traceback" not in proc.stderr

    info = json.loads(run_json)
    info["run_id"] = "another-run"
    (run / "run.json").write_text(json.dumps(info))
    proc, _ = _diagnose_cli(run)
    assert proc.returncode == 2 and "run again" in proc.stderr

    (run / "run.json").write_text(run_json)
    proc, _ = _diagnose_cli(run, "--horizon", "-1")
    assert proc.returncode == 2 and "--horizon" in proc.stderr
    proc, _ = _diagnose_cli(run, "--columns", "x9")
    assert proc.returncode == 2 and "x9" in proc.stderr

    exchange = (run / "exchange.csv").read_bytes()          # cut mid-line before the alarm
    (run / "exchange.csv").write_bytes(exchange[:3000])
    proc, _ = _diagnose_cli(run)
    assert proc.returncode == 2 and "does not contain the alarm" in proc.stderr
    assert "warning: " in proc.stderr and "incomplete last line" in proc.stderr and "Traceback" not in proc.stderr
    (run / "exchange.csv").write_bytes(exchange)
    assert not (run / "diagnosis").exists()          # nothing written for any of these


def test_snapshots_and_resimulation_branch_alike(native_fmu):
    """The two ways to start a branch give the same outputs (1e-12 m: the native FMU's
    integrator does not depend on the communication steps, so only round-off may differ)."""
    from diagnose.simulator import Grid, Simulator
    from orchestrator.case import describe_fmu

    d = describe_fmu(native_fmu)
    params = dict(L1=3.0, L2=1.0, L3=4.0, L4=2.5, m2=1.0, m3=1.0, m4=1.0, g=9.81)
    out = {}
    for method in ("snapshot", "resimulate"):
        with Simulator(d, params, ("x2", "y4"), Grid(0.0, 0.01), 1e-9, 150, 400, method=method) as sim:
            out[method] = (sim.healthy, sim.branch("L2", [1.1], 250), sim.branch("m3", np.linspace(1, 1.2, 50), 200))
    for a, b in zip(out["snapshot"], out["resimulate"]):
        assert np.max(np.abs(a - b)) < 1e-12
    # and a branch differs from the healthy run only after its start (row 250 is the last healthy one)
    healthy, l2, _ = out["snapshot"]
    assert np.abs(l2[0] - healthy[101]).max() > 1e-3


def test_an_uncertainty_is_never_printed_as_zero():
    """The verdict's ± for a step and a ramp: a small non-zero error keeps two significant
    digits, one at most 1e-11 of the value is "exact to round-off", none reads "± 0"."""
    from diagnose.diagnosis import fit_text
    from diagnose.fit import Fit

    def fit(kind: str, stderr: float, end: float = 10.0) -> Fit:
        return Fit(parameter="L1", kind=kind, before=3.0, value=3.3, stderr=stderr, change_time=10.0,
                   end_time=end, chi2=0.0, rows=800, rms=0.0, evaluations=1)

    assert "(± 3.2e-09 m)" in fit_text(fit("step", 3.2e-9), "m")
    for exact in (0.0, 3.2e-11):        # 3.2e-11 < 1e-11 * 3.3 m
        assert "(exact to round-off: ± < 3.3e-11 m)" in fit_text(fit("step", exact), "m")
    assert "± 0 " not in fit_text(fit("ramp", 0.0, end=12.0), "m")
    assert "+0.15 m/s, exact to round-off: ± < 3.3e-11 m/s" in fit_text(fit("ramp", 0.0, end=12.0), "m")
    assert "+0.15 m/s, ± 4e-05 m/s" in fit_text(fit("ramp", 4e-5, end=12.0), "m")
    assert "(uncertainty unknown)" in fit_text(fit("step", float("inf")), "m")


def test_another_mechanisms_fmu_is_named_as_such(tmp_path, native_fmu, mechanism_fmus):
    """`--fmu SliderCrankNative.fmu` on a four-bar run said "the FMU was rebuilt after the run",
    which is not what happened: the message names both mechanisms and GUIDs as recorded."""
    path = case_file("case1_normal", native_fmu, tmp_path / "run.toml", name="fb")
    subprocess.run([FOURBAR_RUN, str(path), "--out", str(tmp_path / "fb"), "--stop", "2", "--quiet"],
                   check=True, timeout=300)
    info = json.loads((tmp_path / "fb" / "run.json").read_text())
    # the diagnosis refuses the FMU before it reads the alarm's rows: a summary naming one is enough
    summary = tmp_path / "summary.json"
    summary.write_text(json.dumps({"run_id": info["run_id"], "first_alarm_time": 1.0, "signal": "x2"}))
    slider = mechanism_fmus.get("slider_crank", "native")
    proc = subprocess.run([FOURBAR_DIAGNOSE, str(tmp_path / "fb"), "--summary", str(summary), "--fmu", str(slider),
                           "--no-plot"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert "rebuilt" not in proc.stderr, proc.stderr
    assert "another mechanism's FMU" in proc.stderr, proc.stderr
    for shown in ("SliderCrankNative", info["fmu"]["model_name"], info["fmu"]["guid"]):
        assert shown in proc.stderr, (shown, proc.stderr)


def test_a_value_on_the_edge_of_the_search_says_so():
    """A step fit that still ends on a bound after widening (``Fit.at_bound``) is said to be
    at the edge of the search, not stated as a found value."""
    from diagnose.diagnosis import fit_text
    from diagnose.fit import Fit

    fit = Fit(parameter="m2", kind="step", before=1.0, value=1000.0, stderr=1.0, change_time=10.0, end_time=10.0,
              chi2=1e4, rows=800, rms=0.1, evaluations=50, at_bound=True)
    assert "at the edge of the search" in fit_text(fit, "kg")
    assert "edge" not in fit_text(Fit(**{**fit.__dict__, "at_bound": False}), "kg")


def test_a_bound_the_fit_ends_on_is_widened():
    """The bounds of a step's change widen ten times out (a relative lower bound towards -1,
    keeping the value's sign) and an answer on one is seen as such."""
    from diagnose.fit import _at_bound, _widen

    assert _widen(9.0, True) == 90.0 and _widen(-0.9, True) == pytest.approx(-0.99)
    assert _widen(-10.0, False) == -100.0
    assert _at_bound(-0.9, -0.9, 9.0) == -1 and _at_bound(9.0, -0.9, 9.0) == 1 and _at_bound(0.1, -0.9, 9.0) is None


def test_correlation_time_is_one_for_noise_and_large_for_a_smooth_misfit():
    """The factor that widens a standard error and the ambiguity test's variance: rows per
    independent residual.  White noise (2000 rows, two columns): 1 within 0.2 (its estimate's
    spread is about 0.05 at this size); a slow sine over the rows: above 50."""
    from diagnose.fit import correlation_time

    rng = np.random.default_rng(1)
    assert correlation_time(rng.standard_normal((2000, 2))) == pytest.approx(1.0, abs=0.2)
    t = np.linspace(0.0, 1.0, 2000)
    assert correlation_time(np.column_stack((np.sin(2 * np.pi * t), np.cos(2 * np.pi * t)))) > 50

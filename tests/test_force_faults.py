"""A worn bearing and a weak spring, run -> monitor -> diagnose end to end (issue 39, item 5).

fmu_src/mechanisms/fourbar_press.toml is Table 1's four-bar with its crank driven at 1 rev/s, a
return spring-damper on the rocker and Coulomb friction in its two ground bearings.  Its motion
is imposed, so a fault shows only in what the motor must give: the monitor watches
``motor_torque``.  The two shipped cases change one force coefficient each at t = 30 s:

- cases/fourbar_press_worn_bearing.toml: the rocker bearing's friction T4 2.0 -> 3.0 N.m (+50 %);
- cases/fourbar_press_weak_spring.toml: the return spring's stiffness k 20 -> 16 N/m (-20 %).

Each runs as a user runs it (the three commands as subprocesses, nothing but the run folder
between them) on the mechanism's native FMU, cut to ``FAULT_STOP`` (training 0-9 s, 21 s of
monitoring before the fault, the diagnosis's window of 5 s before the first alarm to 3 s after
it); the same case without its fault runs ``HEALTHY_STOP`` s (one run: the two cases differ only
in their fault).  Noise-free data, as the cases ship them.  About 30 s of CPU in all: slow.
"""
from __future__ import annotations

import json
import math
import re
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pandas as pd
import pytest

from support import BIN, FOURBAR_MONITOR, FOURBAR_RUN, REPO, case_file, file_key, shared_result

FOURBAR_DIAGNOSE = str(BIN / "fourbar-diagnose")
MECHANISM = "fourbar_press"
SIGNAL = "motor_torque"
FAULT_TIME = 30.0       # s, both cases
FAULT_STOP = 40.0       # s (module docstring)
HEALTHY_STOP = 60.0     # s: 51 s of monitoring after training
#: s after the fault: the torque is algebraic in the imposed motion, so it changes at the first
#: row after the fault, by up to 0.80 N.m (worn bearing) or 5.1 N.m (weak spring); the monitor's
#: CUSUM then needs a few rows to cross its limit (measured 0.09 s and 0.04 s).  A quarter of a
#: crank turn allows for the smaller change falling where the rocker's drag is least, no more.
LATENCY_BOUND = 0.25
#: The issue's bound on the diagnosed value: within 1 % of the value set (noise-free, the fit
#: is exact to the integrator's error: measured 3e-11 N.m and < 2e-10 N/m).
VALUE_REL = 0.01
#: Start times (s) of the crank turns whose motor work is compared: three before the fault, three after.
TURNS = (27.0, 28.0, 29.0, 30.0, 31.0, 32.0)
#: J: the work of one turn repeats to the integrator's error: rtol = atol = 1e-10 on ~1000 J of
#: accumulated work allows ~1e-7 J a step, and a step across one of the rocker's reversals, where
#: the bearings' tanh(w / v_s) turns over within ~0.01 s, can leave more (measured: turns agree
#: within 5e-9 J, one in six off by 3.4e-6 J, since the work and the dissipated energy are both
#: integrated states weighed by the step control).  Far below the 2.27 J a worn bearing adds.
TURN_REPEAT = 1e-5
#: J: the worn bearing's extra work per turn against its closed form, which takes Coulomb's
#: sign(w); tanh(w / v_s) drags less near each of the rocker's two reversals a turn (measured
#: 2.1e-4 J less).
TURN_REGULARISED = 1e-3


@dataclass(frozen=True)
class ForceFault:
    case: str               # cases/<case>.toml
    parameter: str
    before: float           # the parameter's healthy value, its unit
    after: float            # its value after the fault


WORN_BEARING = ForceFault("fourbar_press_worn_bearing", "T4", 2.0, 3.0)
WEAK_SPRING = ForceFault("fourbar_press_weak_spring", "k", 20.0, 16.0)


@dataclass(frozen=True)
class Chain:
    """What the three commands left: their exit codes and output, and the JSON files they wrote."""

    monitor_code: int
    monitor_out: str
    summary: dict
    diagnose_code: int
    diagnose_out: str
    diagnosis: dict | None
    turn_work: tuple[float, ...]    # motor_work gained over each crank turn [TURNS[k], TURNS[k] + 1] s, J


def _json(path: Path) -> dict:
    """A JSON file read strictly: NaN or Infinity in it (not JSON) fail the test."""
    def refuse(constant: str):
        raise AssertionError(f"{path}: {constant} in a JSON file")

    return json.loads(path.read_text(encoding="utf-8"), parse_constant=refuse)


def _chain(case: Path, run_dir: Path, stop: float, diagnose: bool) -> Chain:
    run = subprocess.run([FOURBAR_RUN, str(case), "--out", str(run_dir), "--stop", repr(stop), "--quiet"],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    monitor = subprocess.run([FOURBAR_MONITOR, str(run_dir / "exchange.csv"), "--quiet", "--no-plots",
                              "--signal", SIGNAL], capture_output=True, text=True, timeout=300)
    diagnosis = subprocess.run([FOURBAR_DIAGNOSE, str(run_dir), "--no-plot"], capture_output=True, text=True,
                               timeout=600) if diagnose else None
    exchange = pd.read_csv(run_dir / "exchange.csv")
    work = dict(zip(exchange["time"].round(6), exchange["motor_work"]))
    return Chain(monitor.returncode, monitor.stdout + monitor.stderr, _json(run_dir / "monitor" / "summary.json"),
                 diagnosis.returncode if diagnosis else 0, diagnosis.stdout + diagnosis.stderr if diagnosis else "",
                 _json(run_dir / "diagnosis" / "diagnosis.json") if diagnosis and diagnosis.returncode == 0 else None,
                 tuple(float(work[t + 1.0] - work[t]) for t in TURNS))


@pytest.fixture(scope="module", params=[WORN_BEARING, WEAK_SPRING], ids=lambda f: f.parameter)
def fault(request, mechanism_fmus, tmp_path_factory, shared_folder) -> tuple[ForceFault, Chain]:
    """The chain on one case, to FAULT_STOP (made once per session, ~13 s of CPU)."""
    spec: ForceFault = request.param
    fmu = mechanism_fmus.get(MECHANISM, "native")

    def compute() -> Chain:
        tmp = tmp_path_factory.mktemp(spec.case)
        return _chain(case_file(spec.case, fmu, tmp), tmp / "run", FAULT_STOP, diagnose=True)

    key = file_key(fmu, REPO / "cases" / f"{spec.case}.toml") + repr((spec, FAULT_STOP)).encode()
    return spec, shared_result(shared_folder, "force-fault", key, compute)


@pytest.fixture(scope="module")
def healthy(mechanism_fmus, tmp_path_factory, shared_folder) -> Chain:
    """The worn-bearing case without its [[events]] (the weak-spring case's healthy run is the same)."""
    fmu = mechanism_fmus.get(MECHANISM, "native")

    def compute() -> Chain:
        tmp = tmp_path_factory.mktemp("fourbar_press_healthy")
        case = case_file(WORN_BEARING.case, fmu, tmp)
        text = re.sub(r"(?ms)^\[\[events\]\].*?(?=^\[)", "", case.read_text(encoding="utf-8"))
        assert "[[events]]" not in text and "variable =" not in text
        case.write_text(text, encoding="utf-8")
        return _chain(case, tmp / "run", HEALTHY_STOP, diagnose=False)

    key = file_key(fmu, REPO / "cases" / f"{WORN_BEARING.case}.toml") + repr(HEALTHY_STOP).encode()
    return shared_result(shared_folder, "force-fault-healthy", key, compute)


def test_both_cases_change_a_force_coefficient_of_the_shipped_mechanism():
    """The case files say what the tests below check: one step of one [parameters] entry at 30 s."""
    import tomllib

    from fmu_src.mechanism.description import load_mechanism

    mechanism = load_mechanism(MECHANISM)
    values = {p.name: p.value for p in mechanism.parameters}
    for spec in (WORN_BEARING, WEAK_SPRING):
        case = tomllib.loads((REPO / "cases" / f"{spec.case}.toml").read_text(encoding="utf-8"))
        (event,) = case["events"]
        assert (event["type"], event["variable"], event["time"], event["value"]) == \
            ("step", spec.parameter, FAULT_TIME, spec.after)
        assert values[spec.parameter] == spec.before
    assert WORN_BEARING.after == pytest.approx(1.5 * WORN_BEARING.before, rel=1e-15)     # +50 %
    assert WEAK_SPRING.after == pytest.approx(0.8 * WEAK_SPRING.before, rel=1e-15)       # -20 %


@pytest.mark.slow
def test_the_fault_is_detected_within_its_bound_and_not_before(fault):
    spec, chain = fault
    assert "Traceback" not in chain.monitor_out, chain.monitor_out
    assert chain.monitor_code == 1, chain.monitor_out                  # 1: an alarm
    summary = chain.summary
    assert summary["fault_time"] == FAULT_TIME                           # from run.json
    assert summary["false_alarms_before_fault"] == 0
    latency = summary["detection_latency_s"]
    print(f"{spec.case}: detected {latency} s after the fault")
    assert latency is not None and 0 < latency <= LATENCY_BOUND, latency


@pytest.mark.slow
def test_the_diagnosis_names_the_parameter_its_value_and_time(fault):
    spec, chain = fault
    assert "Traceback" not in chain.diagnose_out, chain.diagnose_out
    assert chain.diagnose_code == 0, chain.diagnose_out                 # 0: explained
    d = chain.diagnosis
    best = d["best"]
    print(f"{spec.case}: {best['parameter']} {best['value']!r} ± {best['stderr']}")
    assert d["verdict"] == "explained" and best["parameter"] == spec.parameter and best["kind"] == "step"
    assert best["before"] == spec.before
    assert abs(best["value"] - spec.after) <= VALUE_REL * abs(spec.after), best
    # A step is applied between two steps: the fault's own grid point (half a step either way).
    assert best["change_time"] == pytest.approx(FAULT_TIME, abs=0.005)
    # No other coefficient explains it: the runner-up's residual is over 10x larger (measured
    # 9.6e4x for the worn bearing, c the runner-up; 5.1e5x for the weak spring, l0).
    runner = next(f for f in d["ranking"] if f["parameter"] != spec.parameter)
    assert runner["rms"] > 10 * best["rms"]
    assert chain.diagnose_out.startswith(f"diagnosis: {spec.parameter} changed {spec.before:.6f} → {spec.after:.6f}")


def _rocker_swing(values: dict[str, float]) -> float:
    """The rocker's swing (rad) of a Grashof crank-rocker: its two extremes are where crank and
    coupler line up, |O2 B| = L3 + L2 and L3 - L2 (the law of cosines in the triangle O2 O4 B)."""
    L1, L2, L3, L4 = (values[n] for n in ("L1", "L2", "L3", "L4"))
    angle = [math.acos((L1**2 + L4**2 - d**2) / (2 * L1 * L4)) for d in (L3 + L2, L3 - L2)]
    return angle[0] - angle[1]


@pytest.mark.slow
def test_the_motor_work_per_turn_shows_what_changed(fault):
    """The motion is periodic (1 s a turn), so over a turn the motor gives exactly what the
    bearings and the damper dissipate: a worn rocker bearing takes Delta T4 more at each of the
    rocker's two sweeps of its swing, 2 Delta T4 swing per turn; a weaker spring, conservative,
    changes the torque's shape but not the work of a turn."""
    from fmu_src.mechanism.description import load_mechanism

    spec, chain = fault
    values = {p.name: p.value for p in load_mechanism(MECHANISM).parameters}
    before, after = chain.turn_work[:3], chain.turn_work[3:]
    print(f"{spec.case}: work per turn {before} -> {after} J")
    assert max(before) - min(before) <= TURN_REPEAT and max(after) - min(after) <= TURN_REPEAT, chain.turn_work
    if spec.parameter == "T4":
        extra = (spec.after - spec.before) * 2 * _rocker_swing(values)         # 2.2747 J
        assert after[0] - before[-1] == pytest.approx(extra, abs=TURN_REGULARISED)
    else:
        assert abs(after[0] - before[-1]) <= TURN_REPEAT


@pytest.mark.slow
def test_the_healthy_run_raises_no_alarm(healthy):
    assert "Traceback" not in healthy.monitor_out, healthy.monitor_out
    assert healthy.monitor_code == 0, healthy.monitor_out               # 0: no alarm
    summary = healthy.summary
    assert summary["first_alarm_time"] is None and summary["fault_time"] is None
    assert summary["max_statistic_over_threshold"] < 1.0
    # The monitor's period is the crank's turn, 1 s (the torque's second harmonic is the
    # stronger one, as for fourbar_driven); 1e-3 s, as tests/test_mechanisms_chain.py.
    assert summary["period"]["refined_s"] == pytest.approx(1.0, abs=1e-3)

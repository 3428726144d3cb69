"""The three system fault cases pass run -> monitor -> diagnose (issue 40, point 6).

The bench (systems/motor_fourbar.toml: conftest's bench_ssp, built once per session) runs
the cases of cases/motor_fourbar_*.toml as they ship, but for the .ssp's path: a worn bearing
(fourbar.T4 2 -> 3 N.m), a winding fault (motor.R 1 -> 1.5 ohm), a sensor bias (sensor.bias
0 -> 0.2 rad/s), each at t = 30 s, and a healthy run of the same length.  Each run is
monitored as docs/systems.md ("Fault cases") says (fourbar-monitor --signal
motor.current,sensor.measured --train 10 25 --model harmonic) and diagnosed with the
candidates and windows given there.  ``pytest -s`` prints the figures the docs quote.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from fourbar_common.contract.exchange import read_exchange
from fourbar_common.contract.layout import RunFolder
from fourbar_common.contract.summary import read_summary

REPO = Path(__file__).resolve().parents[1]
CASES = {"healthy": None, "worn_bearing": ("fourbar.T4", 3.0), "winding": ("motor.R", 1.5),
         "sensor_bias": ("sensor.bias", 0.2)}
FAULT_TIME = 30.0
#: The monitor's options for every case (docs/systems.md, "Fault cases").
MONITOR = ["--signal", "motor.current,sensor.measured", "--train", "10", "25", "--model", "harmonic", "--no-plots",
           "--quiet"]
#: The diagnosis' options (docs/systems.md): one candidate per component's likely fault and the
#: controller's gain; 0.3 s either side of the alarm (it comes under 0.1 s after the fault) and a
#: scan of the change time over the lookback only, which keep the system branches few and short
#: (a system replays at its 1 ms macro step).
DIAGNOSE = dict(candidates=("fourbar.T4", "motor.R", "sensor.bias", "controller.Kp"), lookback=0.3, horizon=0.3,
                max_horizon=0.3, noise_span=2.0, ramp=False, search_back=0.3, scan_step=0.02, refine=2)
#: s: the documented bound on the detection delay (measured: under 0.1 s in every case).
DETECTION_BOUND = 0.5


@pytest.fixture(scope="session")
def bench(bench_ssp) -> Path:
    return bench_ssp


@pytest.fixture(scope="session")
def runs(bench, tmp_path_factory) -> dict[str, Path]:
    """Each case run and monitored once: its run folder."""
    from monitor.cli import main as monitor
    from orchestrator import run_case

    folder = tmp_path_factory.mktemp("system_faults")
    made = {}
    for name in CASES:
        text = (REPO / "cases" / f"motor_fourbar_{name}.toml").read_text(encoding="utf-8")
        case = folder / f"{name}.toml"
        case.write_text(re.sub(r'(?m)^system = ".*"$', f"system = {str(bench)!r}".replace("'", '"'), text),
                        encoding="utf-8")
        result = run_case(case, folder / name)
        assert result.status == "finished", result.error
        assert monitor([str(folder / name), *MONITOR]) in (0, 1)
        made[name] = folder / name
    return made


@pytest.fixture(scope="session")
def diagnoses(runs):
    from diagnose.diagnosis import diagnose

    return {name: diagnose(runs[name], **DIAGNOSE) for name in CASES if CASES[name]}


def _first_alarm(run: Path) -> float | None:
    return read_summary(RunFolder(run).summary).first_alarm_time


@pytest.mark.slow
def test_the_monitor_alarms_after_each_fault_and_never_before(runs):
    assert _first_alarm(runs["healthy"]) is None, "a false alarm in the healthy run"
    for name, fault in CASES.items():
        if fault is None:
            continue
        alarm = _first_alarm(runs[name])
        print(f"\n{name}: first alarm at t = {alarm:.3f} s ({alarm - FAULT_TIME:.3f} s after the fault)")
        assert alarm is not None and FAULT_TIME <= alarm <= FAULT_TIME + DETECTION_BOUND


@pytest.mark.slow
def test_the_worn_bearing_shows_in_the_current_and_hardly_in_the_speed(runs):
    rows = read_exchange(RunFolder(runs["worn_bearing"]).exchange, ["motor.current", "sensor.measured"])
    healthy = read_exchange(RunFolder(runs["healthy"]).exchange, ["motor.current", "sensor.measured"])
    late = rows.time >= FAULT_TIME + 3.0        # whole turns (1 s each) after the controller settled
    change = {c: np.mean(rows.values[c][late]) / np.mean(healthy.values[c][late]) - 1 for c in rows.values}
    print(f"\nworn bearing, mean over t = 33..36 s against the healthy run: motor.current {100 * change['motor.current']:+.1f} %, "
          f"sensor.measured {100 * change['sensor.measured']:+.3f} %")
    # the PI controller's integral holds the mean speed, so the rocker bearing's extra 1 N.m
    # (reaching the crank through the linkage's varying ratio) must come from the motor:
    # measured +6.3 % of the mean current; the speed's mean moves less than 1 % of that
    assert change["motor.current"] > 0.03
    assert abs(change["sensor.measured"]) < 0.01 * change["motor.current"]


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n, f in CASES.items() if f])
def test_the_diagnosis_names_the_component_parameter_value_and_time(diagnoses, name):
    parameter, value = CASES[name]
    d = diagnoses[name]
    print(f"\n{name}: {d.message} ({d.branches} branches, {d.seconds:.0f} s)")
    assert d.explained and d.best.parameter == parameter
    # the runs are noise-free and the replay is the run's own master: the value comes back to
    # round-off of the fit (1e-6 relative), the time to the grid point; but the sensor rounds its
    # reading to its resolution, 0.01 rad/s, so biases a fraction of that apart read alike: a
    # bias within a tenth of the resolution
    tolerance = 1e-3 if parameter == "sensor.bias" else 1e-6 * abs(value)
    assert abs(d.best.value - value) <= tolerance
    assert d.best.change_time == pytest.approx(FAULT_TIME, abs=0.5e-3)

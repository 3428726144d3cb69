"""Noise-free diagnoses of every shipped fault case (cases/*fault*.toml) on its mechanism's
native FMU: the right parameter at its grid point, and the value exact to round-off or within
its stated ± (issue 37: on a two-loop quick-return they were 30x their ±).

Each case runs to 4 s past its fault (at 10 s; the force faults of fourbar_press at 30 s) with no noise; the diagnosis is called
in-process on a summary that puts the first alarm 0.25 s after the fault, on the column the
case's own comments monitor (the monitor is not what is tested here: its timing is its tests').

The fault cases of the slider-crank, the driven four-bar, the Watt six-bar and the five-bar
(``CHAINED``) are run, monitored and diagnosed, noise-free, by tests/test_mechanisms_chain.py's
chains (the monitor's own alarm instead of one 0.25 s after the fault), whose diagnosis test
makes this file's checks too: they are not run a second time here.
"""
from __future__ import annotations

import json
import subprocess
import tomllib

import pytest

from diagnose import diagnose
from support import FOURBAR_RUN, REPO, case_file

#: case -> (mechanism, monitored column)
CASES = {
    "case2_fault_L2": ("fourbar", "x2"),
    "fourbar_press_weak_spring": ("fourbar_press", "motor_torque"),
    "fourbar_press_worn_bearing": ("fourbar_press", "motor_torque"),
}
#: Diagnosed with these checks by tests/test_mechanisms_chain.py (module docstring).
CHAINED = ("fivebar_fault_L5", "fourbar_driven_fault_m3", "slider_crank_fault_L3", "watt_sixbar_fault_L5")


def test_every_shipped_fault_case_is_listed():
    shipped = {p.stem for p in (REPO / "cases").glob("*.toml") if "[[events]]" in p.read_text()
               and 'type = "step"' in p.read_text()
               and "\nsystem = " not in p.read_text()}      # system cases: tests/test_system_faults.py
    assert shipped == set(CASES) | set(CHAINED)
    chains = (REPO / "tests" / "test_mechanisms_chain.py").read_text(encoding="utf-8")
    assert all(f'"{case}"' in chains for case in CHAINED), "a chained case is no longer in a chain"


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
def test_a_shipped_fault_is_diagnosed_exactly_noise_free(tmp_path, mechanism_fmus, case):
    mechanism, column = CASES[case]
    fmu = mechanism_fmus.get(mechanism, "native")
    event = tomllib.loads((REPO / "cases" / f"{case}.toml").read_text())["events"][0]
    path = case_file(case, fmu, tmp_path / "case.toml", name=case)
    subprocess.run([FOURBAR_RUN, str(path), "--out", str(tmp_path / case), "--stop", repr(event["time"] + 4.0),
                    "--quiet"], check=True, timeout=300)
    run = tmp_path / case
    run_id = json.loads((run / "run.json").read_text())["run_id"]
    (run / "summary.json").write_text(json.dumps({"run_id": run_id, "first_alarm_time": event["time"] + 0.25,
                                                  "signal": column}))
    d = diagnose(run, summary=run / "summary.json")
    best = d.best
    error = best.value - event["value"]
    print(f"{case}: {best.parameter} {best.value!r} error {error:.2g} stated ± {best.stderr:.2g}: {d.message}")
    assert d.verdict == "explained", d.message
    assert best.parameter == event["variable"] and best.kind == "step", d.message
    assert best.change_time == pytest.approx(event["time"], abs=0.005), d.message
    assert abs(error) <= 3 * best.stderr, (error, best.stderr, d.message)     # the ± covers the error
    assert best.stderr <= 1e-6 * abs(event["value"]), d.message               # and stays small: exact data

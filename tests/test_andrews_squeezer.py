"""Andrews' squeezing mechanism (fmu_src/mechanisms/andrews_squeezer.toml) against its published
reference solution (issue 39 item 4).

The reference, the constants and their sources (Hairer & Wanner, Solving ODEs II, Sec. VII.7;
Mazzia, Magherini & Iavernaro, Test Set for IVP Solvers, problem "andrews", whose reference was
computed with PSIDE at rtol = atol = 1e-14) are in tests/data/andrews_reference.toml.  Both FMUs
(pythonfmu and native), each built once per session, run to t = 0.03 s at rtol = atol = 1e-12;
the seven outputs named after the paper's coordinates (``[outputs.expressions]``) must match the
published values within 1e-8 rad, the issue's target (measured: 1.5e-9 rad in both FMUs, the
same at 1e-10, so the remaining gap is below the target by a factor 7).
"""
from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
from fmpy import simulate_fmu

REPO = Path(__file__).resolve().parents[1]
REFERENCE = tomllib.loads((REPO / "tests" / "data" / "andrews_reference.toml").read_text())
NAMES = ("beta", "Theta", "gamma", "Phi", "delta", "Omega", "epsilon")
TIGHT = 1e-12
#: the issue's target for the seven coordinates at t = 0.03 s [rad]
TARGET = 1e-8


@pytest.fixture(scope="module", params=["pythonfmu", "native"])
def result(request, mechanism_fmus):
    fmu = mechanism_fmus.get("andrews_squeezer", request.param)
    return simulate_fmu(str(fmu), stop_time=REFERENCE["reference"]["t"], output_interval=1e-3,
                        output=list(NAMES) + ["omega1", "energy", "motor_power"],
                        start_values={"rtol": TIGHT, "atol": TIGHT})


def test_the_start_is_the_published_consistent_initial_state(result):
    for name in NAMES:
        assert abs(result[name][0] - REFERENCE["initial"][name]) <= 1e-12, name


def test_the_seven_coordinates_reach_the_published_values_at_t_0_03(result):
    assert result["time"][-1] == pytest.approx(REFERENCE["reference"]["t"], abs=1e-12)
    errors = {n: abs(result[n][-1] - REFERENCE["reference"][n]) for n in NAMES}
    assert max(errors.values()) <= TARGET, errors
    # the crank turns several times: the comparison is not of a mechanism at rest
    assert abs(result["beta"][-1] - result["beta"][0]) > 10


def test_the_crank_rate_is_the_published_one(result):
    # the rates are not the issue's target; beta' ~ 1140 rad/s, matched to 1e-8 relative
    assert result["omega1"][-1] == pytest.approx(REFERENCE["reference"]["rates"]["beta"], rel=1e-8)


def test_the_motor_power_is_its_torque_times_the_crank_rate(result):
    mom = 33e-3          # the file's and the paper's torque [N.m]
    assert abs(result["motor_power"] - mom * result["omega1"]).max() <= 1e-9 * abs(result["motor_power"]).max()

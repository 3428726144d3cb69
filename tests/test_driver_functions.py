"""A driver whose position is a function of time (docs/mechanisms.md, ``[[drivers]]``).

tests/mechanisms/sine_driven_crank.toml swings fourbar_driven's crank by
``theta2 = theta2_start + A*sin(w*t)``; the driver's rate and acceleration (Phi_t, Phi_tt of
eq. 11) come from sympy.  Both FMUs (pythonfmu and native), each built once per session, run
4 s (two periods) at rtol = atol = 1e-10 (the native one also in model exchange): the crank's
angle is the prescribed function at every output time, the motor's work balances the energy, a parameter changed mid-run takes effect
from then on (the function stays one of absolute time), and a bad expression is refused with
the file and the field named.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from support import REPO, build_fmu_refusal
from fmpy import simulate_fmu

from fmu_src.mechanism.description import MechanismError, load_mechanism

MECHANISM = REPO / "tests" / "mechanisms" / "sine_driven_crank.toml"
TH0, A, W = math.radians(30), 0.5, math.pi      # the file's theta2_start, A and w
TIGHT = 1e-10
STOP, STEP = 4.0, 0.01
#: The dependent coordinates come from Phi = 0 by Newton-Raphson to round-off, and the driver's
#: row is theta2 - f(t) itself: the angle is f(t) to a few ulps of 1 rad (measured <= 8.9e-16
#: in both FMUs).
ANGLE_TOL = 1e-9
#: energy - motor_work: the work is integrated with the state at rtol = atol = 1e-10; over 4 s
#: its spread is 4.8e-10 J in both FMUs (energy 20.1 to 29.3 J, the motor's work spanning 9.1 J):
#: 1e-8 J leaves a factor 20 for other compilers and libm.
BALANCE_TOL = 1e-8


def prescribed(t, a=A):
    return TH0 + a * np.sin(W * np.asarray(t))


@pytest.fixture(scope="module", params=["pythonfmu", "native"])
def fmu(request, mechanism_fmus) -> Path:
    return mechanism_fmus.get(str(MECHANISM), request.param)


def _run(fmu: Path, **kwargs):
    return simulate_fmu(str(fmu), stop_time=STOP, output_interval=STEP, output=["theta2", "energy", "motor_work"],
                        start_values={"rtol": TIGHT, "atol": TIGHT}, **kwargs)


def test_the_driven_angle_is_the_function_and_the_work_balances_the_energy(fmu):
    result = _run(fmu)
    t = result["time"]
    assert len(t) == round(STOP / STEP) + 1
    error = np.abs(result["theta2"] - prescribed(t))
    assert error.max() <= ANGLE_TOL, error.max()
    balance = result["energy"] - result["motor_work"]
    assert np.ptp(balance) <= BALANCE_TOL, np.ptp(balance)
    # the motor does work: the balance is not trivially a constant energy
    assert np.ptp(result["motor_work"]) > 1.0


def test_a_mid_run_amplitude_change_follows_the_function_of_absolute_time(fmu):
    change = 1.0          # an amplitude 0.2 rad from t = 1 s: sin(w t) = 0 there, so no jump
    signal = np.array([(0.0, A), (change, A), (change, 0.2)], dtype=[("time", np.float64), ("A", np.float64)])
    result = simulate_fmu(str(fmu), stop_time=2.0, output_interval=STEP, output=["theta2"],
                          start_values={"rtol": TIGHT, "atol": TIGHT}, input=signal)
    t = result["time"]
    after = t > change + 1e-9
    expected = np.where(after, prescribed(t, 0.2), prescribed(t))
    assert np.abs(result["theta2"] - expected).max() <= ANGLE_TOL


def _edited(tmp_path: Path, position: str) -> Path:
    text = MECHANISM.read_text()
    old = 'position = "theta2_start + A*sin(w*t)"'
    assert old in text
    path = tmp_path / "bad_driver.toml"
    path.write_text(text.replace(old, f'position = "{position}"'))     # no '"' in the test's texts
    return path


@pytest.mark.parametrize("position, words", [
    ("theta2_start + A*sin(w*tau)", ["tau", "parameters and t"]),
    ("__import__('os').system('id')", ["__import__"]),
    ("A*sin(w*t", []),
], ids=["unknown name", "code", "syntax"])
def test_a_bad_position_is_refused_naming_the_file_and_field(tmp_path, position, words):
    path = _edited(tmp_path, position)
    with pytest.raises(MechanismError) as info:
        load_mechanism(str(path))
    message = str(info.value)
    assert str(path) in message and "drivers[0] 'motor'.position" in message, message
    assert all(word in message for word in words), message


def test_t_is_a_name_only_in_a_driver_position(tmp_path):
    path = tmp_path / "t_elsewhere.toml"
    path.write_text(MECHANISM.read_text().replace('length = "L2"', 'length = "L2 + t"'))
    with pytest.raises(MechanismError, match=r"length.*uses t"):
        load_mechanism(str(path))


def test_position_with_start_and_speed_is_refused(tmp_path):
    path = tmp_path / "both.toml"
    path.write_text(MECHANISM.read_text().replace('position = "', 'start = "theta2_start"\nposition = "'))
    with pytest.raises(MechanismError, match=r"drivers\[0\] 'motor'.*'position' and 'start'"):
        load_mechanism(str(path))


def test_build_fmu_exits_2_on_a_bad_position(tmp_path):
    path = _edited(tmp_path, "theta2_start + A*sin(w*tau)")
    proc = build_fmu_refusal(path, tmp_path)
    out = proc.out
    assert proc.returncode == 2, proc
    assert "Traceback" not in proc.stderr and str(path) in proc.stderr, proc.stderr
    assert "drivers[0] 'motor'.position" in proc.stderr, proc.stderr
    assert not out.exists() or not any(out.iterdir())


def test_model_exchange_gives_the_same_angle_and_balance(mechanism_fmus):
    """The native FMU's model exchange (FMPy's CVode integrates motor_work, the only state)."""
    fmu = mechanism_fmus.get(str(MECHANISM), "native")
    result = simulate_fmu(str(fmu), fmi_type="ModelExchange", stop_time=STOP, output_interval=STEP,
                          relative_tolerance=TIGHT, output=["theta2", "energy", "motor_work"])
    assert np.abs(result["theta2"] - prescribed(result["time"])).max() <= ANGLE_TOL
    # CVode's own error control at rtol = 1e-10: measured spread 4.6e-8 J; 1e-6 J leaves a factor 20
    assert np.ptp(result["energy"] - result["motor_work"]) <= 1e-6

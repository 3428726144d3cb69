"""Applied loads (docs/mechanisms.md, ``[[loads]]``): a constant torque on a body and a constant
force at a body point, in the global or the body's frame.

tests/mechanisms/loaded_pendulum.toml: a rod pinned at its tail under gravity, with a torque, a
force at its tip fixed in its frame (perpendicular to it) and a global force at its centre.
Each load is constant in its own frame, so its work since the start is in closed form (the
file's header); both FMUs (pythonfmu and native), each built once per session, run 3 s at
rtol = atol = 1e-10: ``energy - work`` stays constant, each ``<name>_power`` is its closed
form, a torque changed mid-run takes effect, and a bad load is refused naming file and field.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from support import REPO, build_fmu_refusal
from fmpy import simulate_fmu

from fmu_src.mechanism.description import MechanismError, load_mechanism

MECHANISM = REPO / "tests" / "mechanisms" / "loaded_pendulum.toml"
L, TAU, FB, FX, FY = 1.0, 3.0, -1.5, 4.0, 2.0      # the file's values
TH0 = math.radians(-45)
X0, Y0 = L / 2 * math.cos(TH0), L / 2 * math.sin(TH0)
TIGHT = 1e-10
STOP, STEP = 3.0, 0.01
OUTPUTS = ["x1", "y1", "theta1", "omega1", "energy", "motor_power", "push_power", "pull_power"]
#: energy - work at rtol = atol = 1e-10 over 3 s (energy swings over tens of J): the integration
#: error of the state; measured spreads are printed by the assertion; 1e-7 J leaves a margin.
BALANCE_TOL = 1e-7
#: a power output against its closed form from the same reported state: round-off only.
POWER_TOL = 1e-9


def work(r, tau=TAU):
    dtheta = r["theta1"] - TH0
    return tau * dtheta + FB * L * dtheta + FX * (r["x1"] - X0) + FY * (r["y1"] - Y0)


@pytest.fixture(scope="module", params=["pythonfmu", "native"])
def fmu(request, mechanism_fmus) -> Path:
    return mechanism_fmus.get(str(MECHANISM), request.param)


def _run(fmu: Path, **kwargs):
    return simulate_fmu(str(fmu), stop_time=STOP, output_interval=STEP, output=OUTPUTS,
                        start_values={"rtol": TIGHT, "atol": TIGHT}, **kwargs)


def test_energy_minus_the_loads_work_is_constant(fmu):
    r = _run(fmu)
    balance = r["energy"] - work(r)
    assert np.ptp(balance) <= BALANCE_TOL, np.ptp(balance)
    assert np.ptp(work(r)) > 1.0            # the loads do work: the balance is not trivial
    assert np.ptp(r["energy"]) > 1.0


def test_each_power_output_is_its_closed_form(fmu):
    r = _run(fmu)
    w = r["omega1"]
    assert np.abs(r["motor_power"] - TAU * w).max() <= POWER_TOL
    assert np.abs(r["push_power"] - FB * L * w).max() <= POWER_TOL
    vx, vy = -L / 2 * np.sin(r["theta1"]) * w, L / 2 * np.cos(r["theta1"]) * w
    assert np.abs(r["pull_power"] - (FX * vx + FY * vy)).max() <= POWER_TOL * 10


def test_a_torque_changed_mid_run_takes_effect(fmu):
    change, new = 1.0, 0.0
    signal = np.array([(0.0, TAU), (change, TAU), (change, new)], dtype=[("time", np.float64), ("tau", np.float64)])
    r = _run(fmu, input=signal)
    after = r["time"] > change + 1e-9
    w_before = work(r)
    # the torque's work stops growing at the change: energy - work is constant with tau's work frozen
    frozen = np.interp(change, r["time"], r["theta1"])
    w = np.where(after, w_before - TAU * (r["theta1"] - frozen), w_before)
    assert np.ptp(r["energy"] - w) <= BALANCE_TOL, np.ptp(r["energy"] - w)
    assert np.abs(r["motor_power"][after]).max() == 0.0


def _edited(tmp_path: Path, old: str, new: str) -> Path:
    text = MECHANISM.read_text()
    assert old in text
    path = tmp_path / "bad_load.toml"
    path.write_text(text.replace(old, new))
    return path


@pytest.mark.parametrize("old, new, words", [
    ('torque = "tau"', 'torque = "tau2"', ["loads[0] 'motor'.torque", "tau2"]),
    ('body = "rod"\ntorque', 'body = "arm"\ntorque', ["loads[0] 'motor'.body", "'arm'"]),
    ('frame = "body"', 'frame = "local"', ["loads[1] 'push'.frame", "'local'"]),
    ('point = "rod.tip"', 'point = "rod.nose"', ["loads[1] 'push'.point", "nose"]),
    ('force = ["Fx", "Fy"]', 'force = ["Fx"]', ["loads[2] 'pull'.force"]),
    ('name = "pull"', 'name = "O"', ["loads[2] 'O'", "a joint"]),
    ('torque = "tau"', 'torque = "tau"\nforce = [1, 2]', ["loads[0] 'motor'", "not both"]),
], ids=["unknown parameter", "unknown body", "bad frame", "unknown point", "one component", "name taken", "both"])
def test_a_bad_load_is_refused_naming_the_file_and_field(tmp_path, old, new, words):
    path = _edited(tmp_path, old, new)
    with pytest.raises(MechanismError) as info:
        load_mechanism(str(path))
    message = str(info.value)
    assert str(path) in message and all(w in message for w in words), message


def test_build_fmu_exits_2_on_a_bad_load(tmp_path):
    path = _edited(tmp_path, 'frame = "body"', 'frame = "local"')
    proc = build_fmu_refusal(path, tmp_path)
    out = proc.out
    assert proc.returncode == 2, proc
    assert "Traceback" not in proc.stderr and str(path) in proc.stderr, proc.stderr
    assert "loads[1] 'push'.frame" in proc.stderr, proc.stderr
    assert not out.exists() or not any(out.iterdir())

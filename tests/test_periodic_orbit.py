"""scripts/periodic_orbit.py: a mechanism's equilibrium, normal modes and a periodic swing.

The five-bar (two degrees of freedom) is the case: ``cases/fivebar_fault_L5.toml`` starts on
the periodic orbit of its slower mode, which the script finds.  The checks are physical:
the accelerations vanish at the equilibrium; a tiny swing's period and start tend to the
linear mode's (an independent route: shooting on the nonlinear motion against the eigen-
decomposition of the directional derivatives); the FMU released at the printed start is back
at it, at rest, after whole periods; the shipped case holds those start values.
"""
from __future__ import annotations

import importlib.util
import math
import re
import subprocess
import sys

import numpy as np
import pytest
from fmpy import simulate_fmu

from support import REPO

SCRIPT = [sys.executable, str(REPO / "scripts" / "periodic_orbit.py")]
NEAR = ["--near", "-90", "-90"]          # deg: both cranks hanging down


def _module():
    """scripts/periodic_orbit.py as a module, for its results at full precision."""
    spec = importlib.util.spec_from_file_location("periodic_orbit", REPO / "scripts" / "periodic_orbit.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("periodic_orbit", module)     # its dataclasses look their module up there
    spec.loader.exec_module(sys.modules["periodic_orbit"])
    return sys.modules["periodic_orbit"]


def _run(*args, check_exit: int | None = 0) -> subprocess.CompletedProcess:
    proc = subprocess.run([*SCRIPT, *map(str, args)], capture_output=True, text=True, timeout=300)
    assert "Traceback" not in proc.stderr, proc.stderr
    if check_exit is not None:
        assert proc.returncode == check_exit, proc.stdout + proc.stderr
    return proc


def _orbit(out: str) -> tuple[dict[str, float], float]:
    starts = {m[0]: float(m[1]) for m in re.findall(r"^(\w+)_start = (\S+)", out, flags=re.M)}
    period = float(re.search(r"periodic orbit of mode \d: period (\S+) s", out)[1])
    return starts, period


def _mode_periods(out: str) -> list[float]:
    return [float(p) for p in re.findall(r"^mode \d: period (\S+) s", out, flags=re.M)]


@pytest.fixture(scope="module")
def fivebar(mechanism_fmus):
    return mechanism_fmus.get("fivebar", "native")


def _numbers_and_words(text: str) -> tuple[list[float], list[str]]:
    number = re.compile(r"[-+]?\d+\.\d+(?:e[-+]?\d+)?")
    return [float(x) for x in number.findall(text)], number.sub("#", text).split()


@pytest.mark.slow
def test_the_shipped_case_starts_on_the_orbit_and_the_swing_repeats(fivebar):
    out = _run(fivebar, *NEAR, "--mode", "1", "--amplitude", "0.136").stdout
    starts, period = _orbit(out)
    # docs/mechanisms.md shows this output: the same words, the same numbers to 1e-8 relative
    # (the last digits of a shooting's result may differ with another machine's libm)
    page = (REPO / "docs" / "mechanisms.md").read_text(encoding="utf-8")
    shown = re.search(r"```\n\$ python scripts/periodic_orbit\.py build/FiveBarNative\.fmu --near -90 -90 --mode 1 "
                      r"--amplitude 0\.136\n(.*?)```", page, flags=re.S)[1]
    (shown_numbers, shown_words), (numbers, words) = _numbers_and_words(shown), _numbers_and_words(out)
    assert shown_words == words
    # 3e-10 rad/s, the rates half a period later, is round-off itself: compared to 1e-9 absolute
    assert np.allclose(shown_numbers, numbers, rtol=1e-8, atol=1e-9)
    case = (REPO / "cases" / "fivebar_fault_L5.toml").read_text(encoding="utf-8")
    for name in ("theta2", "theta5"):
        quoted = float(re.search(rf"^{name}_start = (\S+)", case, flags=re.M)[1])
        # the shooting converges to rates of 1e-10 rad/s; 1e-9 rad allows for another
        # machine's round-off in the runs it iterates on
        assert quoted == pytest.approx(starts[name], abs=1e-9), name
    # Ten periods later the linkage is back where it started, at rest.  1e-6: the shooting's
    # residual rates (1e-10 rad/s) and the period's rounding to 1e-10 s grow along the orbit,
    # which is stable but not asymptotically so.
    values = {f"{n}_start": v for n, v in starts.items()} | {"rtol": 1e-12, "atol": 1e-12}
    names = ["theta2", "theta5", "omega2", "omega5"]
    result = simulate_fmu(str(fivebar), stop_time=10 * period, output_interval=period / 100, start_values=values,
                          output=names)
    for k in range(1, 11):
        row = result[100 * k]
        assert row["time"] == pytest.approx(k * period, abs=1e-9)
        assert row["theta2"] == pytest.approx(starts["theta2"], abs=1e-6), k
        assert row["theta5"] == pytest.approx(starts["theta5"], abs=1e-6), k
        assert abs(row["omega2"]) < 1e-6 and abs(row["omega5"]) < 1e-6, k
    # and it swings: halfway, the left crank is on the other side of the equilibrium
    assert result[50]["theta2"] < math.radians(-98.84) < starts["theta2"]


@pytest.mark.slow
def test_a_small_swing_has_the_linear_modes_period_and_shape(fivebar, tmp_path):
    """As the amplitude A goes to 0 the periodic orbit tends to the linear mode: its period to
    2 pi / sqrt(-eigenvalue) and its start to the equilibrium + A x the mode shape (both from
    the directional derivatives; the orbit from shooting on the nonlinear motion).  The
    differences shrink with A (measured, slower mode): at 0.136 rad the period is 3.8e-3 longer
    and the offset / A is 0.04 off the shape (largest entry 1); at A = 1e-3, 2e-7 and 1.3e-4.
    So 1e-5 and 5e-3 leave room, and would catch a wrong eigenvalue or a wrong shape."""
    orbit_module = _module()
    fmu = orbit_module.MechanismFMU(fivebar, tmp_path, {})
    try:
        modes = orbit_module.normal_modes(fmu, np.radians([-90.0, -90.0]))
        for mode in (1, 2):
            amplitude = 1e-3
            orbit = orbit_module.periodic_orbit(fmu, modes, mode, amplitude)
            assert orbit.period == pytest.approx(modes.periods[mode - 1], rel=1e-5), mode
            offset = (orbit.start - modes.equilibrium) / amplitude
            assert np.allclose(offset, modes.shapes[:, mode - 1], rtol=0, atol=5e-3), (mode, offset)
    finally:
        fmu.close()


def test_the_equilibrium_is_at_rest_and_stable(fivebar, tmp_path):
    orbit_module = _module()
    fmu = orbit_module.MechanismFMU(fivebar, tmp_path, {})
    try:
        modes = orbit_module.normal_modes(fmu, np.radians([-90.0, -90.0]))
        # the accelerations vanish there (Newton-Raphson stops below 1e-12 rad; g / L ~ 10 s^-2)
        assert np.max(np.abs(fmu.accelerations(modes.equilibrium))) < 1e-10
        equilibrium = modes.equilibrium
    finally:
        fmu.close()
    assert np.all(modes.eigenvalues < 0) and modes.periods[0] > modes.periods[1] > 0     # stable, slowest first
    # released there at rest it stays: 1e-9 rad over 5 s (a start 1e-12 rad off swings 1e-12 rad
    # about it; the integrator at 1e-12 adds its own error, far below 1e-9)
    result = simulate_fmu(str(fivebar), stop_time=5.0, output_interval=0.01, output=["theta2", "theta5"],
                          start_values={"theta2_start": equilibrium[0], "theta5_start": equilibrium[1],
                                        "rtol": 1e-12, "atol": 1e-12})
    assert np.max(np.abs(result["theta2"] - equilibrium[0])) < 1e-9
    assert np.max(np.abs(result["theta5"] - equilibrium[1])) < 1e-9


def test_what_it_cannot_do_is_said(fivebar, mechanism_fmus, tmp_path):
    proc = _run(fivebar, check_exit=1)         # from the start configuration: a saddle
    assert "not stable" in proc.stderr and "--near" in proc.stderr
    proc = _run(fivebar, *NEAR, "--mode", "3", check_exit=2)
    assert "2 mode(s)" in proc.stderr
    proc = _run(fivebar, "--near", "-90", check_exit=2)
    assert "2 angle(s) expected" in proc.stderr
    proc = _run(mechanism_fmus.get("fourbar_driven", "native"), check_exit=2)
    assert "no free coordinate" in proc.stderr
    proc = _run(mechanism_fmus.get("fourbar", "pythonfmu"), check_exit=2)
    assert "model exchange" in proc.stderr
    proc = _run(fivebar, "--set", "L9=1", check_exit=2)
    assert "L9" in proc.stderr
    proc = _run(tmp_path / "missing.fmu", check_exit=2)
    assert "no such file" in proc.stderr
    for args, words in ((["--amplitude", "0"], "nonzero amplitude"), (["--near", "nan", "nan"], "not a finite number"),
                        (["--set", "L5=nan"], "finite number"), (["--set", "theta2=1"], "not a parameter"),
                        (["--mode", "0"], "a mode number")):
        proc = _run(fivebar, *args, check_exit=2)
        assert words in proc.stderr, (args, proc.stderr)
    proc = _run(fivebar, *NEAR, "--set", "L5=-1", check_exit=2)      # the FMU's own reason
    assert "L5 = -1.0 m: must be a finite positive number" in proc.stderr

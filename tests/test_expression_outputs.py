"""Outputs a mechanism file defines as expressions of the state (``[outputs.expressions]``).

tests/mechanisms/relative_angles.toml is Table 1's four-bar with three such outputs: a relative
angle ``Theta = theta3 - theta2``, a relative rate ``Omega = omega4 - omega3`` and
``tip_gap = sqrt((x3 - x2)**2 + (y3 - y2)**2) - L2/2`` (coordinates and a parameter).  Both FMUs
run it; each defined output must equal the same expression computed from the FMU's other outputs
at every row.  A bad expression is refused naming the file and the field (build_fmu.py: exit 2).
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description, simulate_fmu

from fmu_src.mechanism.description import MechanismError, load_mechanism
from fmu_src.mechanism.derivation import derive

REPO = Path(__file__).resolve().parents[1]
MECHANISM = REPO / "tests" / "mechanisms" / "relative_angles.toml"
#: |defined output - the expression of the other outputs|: the same state, evaluated by two
#: sympy-printed formulas (CSE in one, the outputs' own in the other): round-off of numbers
#: of order 1 (rad, rad/s, m), ~1e-15; 1e-12 leaves room and still catches any wrong term.
ROUND_OFF = 1e-12
#: Run length (s) and tolerance: the crank swings from 30 deg at rest, Theta moves by ~1 rad.
STOP = 2.0
TOL = 1e-10


def _run(fmu: Path) -> tuple[np.ndarray, float]:
    # a pythonfmu FMU's slave module is cached by name in this interpreter (PythonFMU #228; the
    # project's workaround, as in tests/test_mechanism_fmus.py)
    import shutil

    from fmpy import extract

    from orchestrator.pythonfmu_workarounds import forget_other_fmu_modules

    unzipped = extract(str(fmu))
    try:
        forget_other_fmu_modules(unzipped)
        rows = simulate_fmu(unzipped, stop_time=STOP, output_interval=0.01, start_values={"rtol": TOL, "atol": TOL})
    finally:
        shutil.rmtree(unzipped, ignore_errors=True)
    L2 = next(float(v.start) for v in read_model_description(str(fmu)).modelVariables if v.name == "L2")
    return rows, L2


@pytest.fixture(scope="module", params=["pythonfmu", "native"])
def run(request, mechanism_fmus):
    return _run(mechanism_fmus.get(str(MECHANISM), request.param))


def test_defined_outputs_are_their_expressions_of_the_other_outputs(run):
    rows, L2 = run
    assert len(rows) == int(round(STOP / 0.01)) + 1
    theta = rows["theta3"] - rows["theta2"]
    omega = rows["omega4"] - rows["omega3"]
    gap = np.hypot(rows["x3"] - rows["x2"], rows["y3"] - rows["y2"]) - L2 / 2
    assert np.ptp(rows["Theta"]) > 0.1 and np.ptp(rows["Omega"]) > 0.1   # they move: the check is not vacuous
    assert np.max(np.abs(rows["Theta"] - theta)) <= ROUND_OFF
    assert np.max(np.abs(rows["Omega"] - omega)) <= ROUND_OFF
    assert np.max(np.abs(rows["tip_gap"] - gap)) <= ROUND_OFF


@pytest.mark.parametrize("kind", ["pythonfmu", "native"])
def test_defined_outputs_come_after_the_listed_ones_with_their_units(kind, mechanism_fmus):
    md = read_model_description(str(mechanism_fmus.get(str(MECHANISM), kind)))
    outputs = [v for v in md.modelVariables if v.causality == "output"]
    assert [v.name for v in outputs][:14] == ["x2", "y2", "x3", "y3", "theta2", "theta3", "theta4", "omega2",
                                               "omega3", "omega4", "A_Fx", "Theta", "Omega", "tip_gap"]
    unit = {v.name: v.unit or (v.declaredType.unit if v.declaredType else None) for v in outputs}
    assert (unit["Theta"], unit["Omega"], unit["tip_gap"]) == ("rad", "rad/s", "m"), unit


def _edited(tmp_path: Path, old: str, new: str) -> Path:
    text = MECHANISM.read_text()
    assert old in text, f"the test mechanism changed: {old!r} not found"
    path = tmp_path / "mine.toml"
    path.write_text(text.replace(old, new))
    return path


THETA = 'Theta = { expression = "theta3 - theta2"'
BAD = [
    ("unknown name", f'Theta = {{ expression = "theta9 - theta2"',
     ["outputs.expressions.Theta.expression", "'theta9 - theta2'", "uses theta9",
      "parameters, coordinates and rates", "theta3", "omega2"]),
    ("code in the text", "Theta = { expression = \"__import__('os').system('id')\"",
     ["outputs.expressions.Theta.expression", "contains \"'\""]),
    ("outside the grammar", 'Theta = { expression = "theta3 if theta2 else 0"',
     ["outputs.expressions.Theta.expression", "theta3 if theta2 else 0"]),
    ("the name of an output", 'theta4 = { expression = "theta3 - theta2"',
     ["outputs.expressions.theta4", "has the name of an output"]),
    ("the name of a parameter", 'L1 = { expression = "theta3 - theta2"',
     ["outputs.expressions.L1", "has the name of a parameter"]),
]


@pytest.mark.parametrize("case", BAD, ids=[b[0] for b in BAD])
def test_a_bad_defined_output_is_refused_naming_the_file_and_field(case, tmp_path):
    _, new, words = case
    path = _edited(tmp_path, THETA, new)
    with pytest.raises(MechanismError) as info:
        derive(load_mechanism(str(path)))
    message = str(info.value)
    assert str(path) in message, message
    for word in words:
        assert word in message, message


def test_build_fmu_exits_2_on_an_unknown_name_and_writes_nothing(tmp_path):
    path = _edited(tmp_path, THETA, 'Theta = { expression = "theta3 - thetaX"')
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "build_fmu.py", "--mechanism", str(path), "--out", str(out / "a.fmu"),
                           "--native-out", str(out / "b.fmu")], cwd=REPO, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 2, proc
    assert "Traceback" not in proc.stderr and proc.stderr.startswith("build_fmu.py: error: "), proc.stderr
    assert f"{path}: outputs.expressions.Theta.expression: 'theta3 - thetaX' uses thetaX" in proc.stderr, proc.stderr
    assert not out.exists() or not any(out.iterdir())


def test_the_short_form_is_an_expression_with_unit_1_and_itself_as_description(tmp_path):
    path = _edited(tmp_path, 'Theta = { expression = "theta3 - theta2", unit = "rad", description = '
                             '"Coupler angle relative to the crank [rad]" }', 'Theta = "theta3 - theta2"')
    (theta,) = [o for o in load_mechanism(str(path)).expression_outputs if o.name == "Theta"]
    assert (theta.unit, theta.description, str(theta.expression)) == ("1", "Theta = theta3 - theta2",
                                                                     "-theta2 + theta3")

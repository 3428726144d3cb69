"""A mechanism file with a mistake: a message naming the item, exit 2, no traceback.

Each case edits a shipped file (fourbar.toml or slider_crank.toml) the way a user's mistake
would, and checks what `build_fmu.py --mechanism FILE` (and the loader behind it) says.
"""
from __future__ import annotations

import subprocess
import sys

import pytest
from support import REPO

from fmu_src.mechanism.check import prepare_mechanism
from fmu_src.mechanism.description import MECHANISM_DIR, MechanismError

FOURBAR = (MECHANISM_DIR / "fourbar.toml").read_text()
SLIDER = (MECHANISM_DIR / "slider_crank.toml").read_text()

# (id, base text, (old, new) replacements, words the message must contain)
MISTAKES = [
    ("unknown body", FOURBAR, [('connects = ["crank.tip", "coupler.tail"]', 'connects = ["crank.tip", "coupel.tail"]')],
     ["joints[1] 'A'", "no body named 'coupel'", "coupler"]),
    ("point that does not exist", FOURBAR, [('connects = ["coupler.tip", "rocker.tip"]',
                                             'connects = ["coupler.end", "rocker.tip"]')],
     ["joints[2] 'B'", "body 'coupler' has no point 'end'", "tail, tip"]),
    ("ground point that does not exist", FOURBAR, [('connects = ["ground.O4", "rocker.tail"]',
                                                    'connects = ["ground.O3", "rocker.tail"]')],
     ["joints[3] 'O4'", "the ground has no point 'O3'"]),
    ("body without a joint", SLIDER, [('connects = ["rod.tip", "slider.pin"]', 'connects = ["rod.tip", "ground.E"]'),
                                      ('connects = ["ground.E", "slider.pin"]', 'connects = ["ground.O2", "crank.centre"]')],
     ["body 'slider'", "no joint connects it", "missing constraints"]),
    ("missing constraints", FOURBAR, [('[[joints]]\nname = "B"\ntype = "revolute"\nconnects = ["coupler.tip", "rocker.tip"]\n', ''),
                                      ('"B_Fx", "B_Fy", ', '')],
     ["missing constraints", "3 degrees of freedom", "theta2"]),
    ("redundant constraints", FOURBAR, [('[start]', '[[joints]]\nname = "B2"\ntype = "revolute"\n'
                                                    'connects = ["rocker.tip", "coupler.tip"]\n\n[start]')],
     ["redundant constraints", "B"]),
    ("driver on a joint that does not exist", FOURBAR,
     [('[start]', '[[drivers]]\nname = "motor"\njoint = "O3"\nstart = "theta2_start"\nspeed = "w"\n\n[start]')],
     ["drivers[0] 'motor'", "drives joint 'O3', which does not exist", "O2, A, B, O4"]),
    ("cannot be assembled", FOURBAR, [('L4 = { value = 2.5,', 'L4 = { value = 0.5,')],
     ["cannot be assembled at its start values", "theta2 = 0.523599", "cannot be closed"]),
    ("unknown parameter in an expression", FOURBAR, [('O4 = ["L1", 0]', 'O4 = ["L9", 0]')],
     ["ground.points.O4[0]", "'L9'", "not a parameter"]),
    ("a rod without length", FOURBAR, [('length = "L3"\n', '')], ["bodies[1] 'coupler'", "a rod needs 'length'"]),
    ("a misspelt key", SLIDER, [('rotates = false', 'rotate = false')], ["bodies[2] 'slider'", "unknown key 'rotate'"]),
    ("a unit that is not one", FOURBAR, [('unit = "kg", positive = true, description = "Crank', 'unit = "kilo", positive = true, description = "Crank')],
     ["parameters.m2", "unit 'kilo'"]),
    ("not TOML", FOURBAR, [('[mechanism]', '[mechanism')], ["not valid TOML"]),
    ("an output that does not exist", SLIDER, [('"P_Fy"]', '"P_Fy", "x9"]')], ["[outputs]", "'x9'", "not an output"]),
]


def _edit(text: str, replacements) -> str:
    for old, new in replacements:
        assert old in text, f"the shipped file changed: {old!r} not found"
        text = text.replace(old, new)
    return text


@pytest.mark.parametrize("case", MISTAKES, ids=[m[0] for m in MISTAKES])
def test_a_mistake_is_named(case, tmp_path):
    _, base, replacements, words = case
    path = tmp_path / "mine.toml"
    path.write_text(_edit(base, replacements))
    with pytest.raises(MechanismError) as info:
        prepare_mechanism(str(path))
    message = str(info.value)
    assert str(path) in message, message
    for word in words:
        assert word in message, message


@pytest.mark.parametrize("case", [MISTAKES[0], MISTAKES[5], MISTAKES[7]], ids=["unknown body", "redundant", "unassemblable"])
def test_build_fmu_exits_2_with_the_message_and_writes_nothing(case, tmp_path):
    _, base, replacements, words = case
    path = tmp_path / "mine.toml"
    path.write_text(_edit(base, replacements))
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "build_fmu.py", "--mechanism", str(path), "--out", str(out / "a.fmu"),
                           "--native-out", str(out / "b.fmu")], cwd=REPO, capture_output=True, text=True)
    assert proc.returncode == 2, proc
    assert "Traceback" not in proc.stderr and proc.stderr.startswith("build_fmu.py: error: "), proc.stderr
    assert all(word in proc.stderr for word in words), proc.stderr
    assert not out.exists() or not any(out.iterdir())


def test_an_unknown_mechanism_name_lists_the_shipped_ones():
    proc = subprocess.run([sys.executable, "build_fmu.py", "--mechanism", "sliderkrank"], cwd=REPO,
                          capture_output=True, text=True)
    assert proc.returncode == 2 and "unknown mechanism 'sliderkrank'" in proc.stderr and "slider_crank" in proc.stderr


def test_every_shipped_mechanism_is_valid():
    from fmu_src.mechanism.description import shipped_mechanisms
    names = shipped_mechanisms()
    assert {"fourbar", "slider_crank", "fourbar_driven", "fivebar"} <= set(names)
    dofs = {name: prepare_mechanism(name).degrees_of_freedom for name in names}
    assert dofs["fourbar"] == dofs["slider_crank"] == 1 and dofs["fourbar_driven"] == 0 and dofs["fivebar"] == 2

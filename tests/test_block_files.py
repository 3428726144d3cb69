"""Block files read as untrusted data (fmu_src/block/description.py): every mistake is refused by
``build_fmu.py --component`` with exit status 2, one message naming the file, the field and the
value, no traceback, and nothing written."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from fmu_src.block.description import BlockError, load_block, shipped_components

REPO = Path(__file__).resolve().parent.parent
MOTOR = REPO / "fmu_src" / "components" / "dc_motor.toml"
PI = REPO / "fmu_src" / "components" / "pi_controller.toml"

#: (case, file, old text, new text, what the message must name: field, value, why); "uses" runs
#: along a cycle: error uses voltage_limited, which uses voltage_demand, which uses error
MISTAKES = {
    "unknown symbol": (MOTOR, 'derivative = "(V - R*i - k*omega_m)/L"', 'derivative = "(V - R*i - kk*omega_m)/L"',
                       ("[states.i] derivative", "(V - R*i - kk*omega_m)/L", "kk")),
    "state without derivative": (MOTOR, 'derivative = "omega_m/N - omega_load"\n', "\n",
                                 ("[states.phi] derivative", "missing")),
    "output of an unknown name": (MOTOR, 'expression = "omega_m"', 'expression = "omega_rotor"',
                                  ("[outputs.omega_motor] expression", "omega_rotor")),
    "cycle among intermediates": (PI, 'expression = "setpoint - measured"', 'expression = "voltage_limited - measured"',
                                  ("[intermediates.", "cycle", "error -> voltage_limited -> voltage_demand -> error")),
    "duplicate name": (MOTOR, "[outputs.current]", "[outputs.L]", ("[outputs.L]", "'L'", "duplicate name")),
    "unknown unit": (MOTOR, 'unit = "ohm"', 'unit = "ohms"', ("[parameters.R] unit", "'ohms'", "unknown unit")),
    "unsafe identifier": (MOTOR, "[states.phi]", '[states."phi-1"]', ("[states.phi-1]", "'phi-1'", "identifier")),
    "C keyword": (MOTOR, "[parameters.b]", "[parameters.double]", ("[parameters.double]", "'double'", "keyword")),
}


def _edited(tmp_path: Path, case: str) -> tuple[Path, tuple[str, ...]]:
    source, old, new, named = MISTAKES[case]
    text = source.read_text()
    assert text.count(old) >= 1, (case, old)       # the edit applies to the shipped file as it is
    text = text.replace(old, new, 1)
    path = tmp_path / source.name
    path.write_text(text)
    return path, named


def test_the_shipped_components_load():
    assert shipped_components() == ("dc_motor", "pi_controller", "speed_profile", "speed_sensor")
    names = {load_block(n).name for n in shipped_components()}
    assert names == {"DCMotor", "PIController", "SpeedProfile", "SpeedSensor"}


@pytest.mark.parametrize("case", sorted(MISTAKES))
def test_a_mistake_is_refused_naming_file_field_and_value(case, tmp_path):
    path, named = _edited(tmp_path, case)
    with pytest.raises(BlockError) as info:
        load_block(path)
    message = str(info.value)
    assert message.startswith(str(path)), message
    for part in named:
        assert part in message, (case, part, message)


@pytest.mark.parametrize("case", ["unknown symbol", "cycle among intermediates", "unknown unit", "unsafe identifier"])
def test_build_fmu_refuses_it_with_exit_2_and_writes_nothing(case, tmp_path):
    path, named = _edited(tmp_path, case)
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "build_fmu.py", "--component", str(path), "--out", str(out / "c.fmu")],
                          cwd=REPO, capture_output=True, text=True, timeout=600)   # a hang guard only
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and proc.stdout == ""
    assert proc.stderr.startswith(f"build_fmu.py: error: {path}"), proc.stderr
    for part in named:
        assert part in proc.stderr, (part, proc.stderr)
    assert not out.exists()


def test_an_expression_is_never_run(tmp_path):
    """The whitelist parser refuses a call that is not a function of the grammar (no eval)."""
    path = tmp_path / "evil.toml"
    path.write_text(MOTOR.read_text().replace('expression = "i"', 'expression = "__import__(\'os\').getcwd()"', 1))
    with pytest.raises(BlockError, match=r"\[outputs.current\] expression"):
        load_block(path)


def test_an_unknown_component_name_lists_the_shipped_ones():
    with pytest.raises(BlockError, match="dc_motor, pi_controller, speed_profile, speed_sensor"):
        load_block("no_such_block")


def test_every_mistake_of_a_file_is_listed_at_once(tmp_path):
    """Three independent mistakes (a unit, a symbol, a parameter's value): one BlockError, one
    line each naming the field and the value, so one edit fixes them all."""
    text = MOTOR.read_text()
    for old, new in (('unit = "ohm"', 'unit = "ohms"'),
                     ('derivative = "(V - R*i - k*omega_m)/L"', 'derivative = "(V - R*i - kk*omega_m)/L"'),
                     ("value = 0.01", 'value = "0.01"')):
        assert text.count(old) >= 1, old
        text = text.replace(old, new, 1)
    path = tmp_path / "three.toml"
    path.write_text(text)
    with pytest.raises(BlockError) as info:
        load_block(path)
    lines = str(info.value).splitlines()
    assert lines[0] == f"{path}: 3 problems:", lines
    assert any("[parameters.R] unit = 'ohms'" in line and "unknown unit" in line for line in lines[1:]), lines
    assert any("[states.i] derivative" in line and "kk" in line for line in lines[1:]), lines
    assert any("[parameters.L] value = '0.01'" in line and "expected a number" in line for line in lines[1:]), lines


def test_the_sensor_file_accepts_resolution_zero_and_refuses_a_negative_one(tmp_path):
    """resolution = 0 means no quantisation (docs/components.md); below 0 is outside min = 0."""
    sensor = REPO / "fmu_src" / "components" / "speed_sensor.toml"
    text = sensor.read_text()
    assert text.count("value = 0.01") == 1
    zero, negative = tmp_path / "zero.toml", tmp_path / "negative.toml"
    zero.write_text(text.replace("value = 0.01", "value = 0.0"))
    negative.write_text(text.replace("value = 0.01", "value = -0.01"))
    block = load_block(zero)
    assert {p.name: p.value for p in block.parameters}["resolution"] == 0.0
    with pytest.raises(BlockError, match=r"\[parameters.resolution\] value = -0.01: outside \[0.0, None\]"):
        load_block(negative)

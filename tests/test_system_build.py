"""System files built into SSP 1.0 files (issue 40: fmu_src/system/, build_fmu.py --system).

The builder is tested on tests/systems/fourbar_follower.toml, made of mechanisms only: the
bench's four-bar (fmu_src/mechanisms/fourbar_motor.toml) turned by a constant torque bound to
its unconnected input, and a driven four-bar (tests/mechanisms/input_driven_crank.toml) whose
crank follows the first one's.  The component FMUs are the session's (conftest.mechanism_fmus:
build/'s when fresh), passed to build_system as ``prebuilt``; one slow test builds the whole
system through the command line and checks it gives the same bytes.
"""
from __future__ import annotations

import json
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import numpy as np
import pytest

from fmu_src.system import (SystemFileError, build_system, check_system, load_system, parse_system, read_interface,
                            schema_problems, ssd_bytes, write_ssp)
from fmu_src.system.description import SYSTEM_DIR
from support import REPO

SYSTEM = REPO / "tests" / "systems" / "fourbar_follower.toml"
FOLLOWER = (REPO / "tests" / "mechanisms" / "input_driven_crank.toml").resolve()
STEP = 1e-3          # s: the macro step of the runs below
STOP = 0.2           # s


@pytest.fixture(scope="session")
def follower_fmus(mechanism_fmus) -> dict[str, Path]:
    """The native FMI 2.0 FMUs of the test system's components, by ComponentSpec.reference."""
    return {"fourbar_motor": mechanism_fmus.get("fourbar_motor", "native"),
            str(FOLLOWER): mechanism_fmus.get(str(FOLLOWER), "native")}


@pytest.fixture(scope="session")
def follower_ssp(follower_fmus, tmp_path_factory):
    out = tmp_path_factory.mktemp("system") / "FourBarFollower.ssp"
    return build_system(SYSTEM, out, prebuilt=follower_fmus)


@pytest.fixture(scope="session")
def interfaces(follower_fmus):
    return {"fourbar": read_interface(follower_fmus["fourbar_motor"]),
            "follower": read_interface(follower_fmus[str(FOLLOWER)])}


def _ssd(path: Path) -> bytes:
    with zipfile.ZipFile(path) as z:
        return z.read("SystemStructure.ssd")


def _bindings(path: Path) -> dict[str, dict[str, float]]:
    """The values in each component's inline parameter set, read with FMPy's SSP reader."""
    from fmpy.ssp.ssd import read_ssd
    ssd = read_ssd(str(path))      # validates against FMPy's SSP 1.0 schema too
    return {c.name: {p.name: float(p.value) for b in c.parameterBindings for s in b.parameterValues
                     for p in s.parameters} for c in ssd.system.elements}


# -- the .ssp ---------------------------------------------------------------------------------

def test_the_ssd_follows_the_ssp_schema_and_fmpy_reads_it(follower_ssp):
    assert follower_ssp.problems == ()
    ssd = _ssd(follower_ssp.path)
    assert schema_problems(ssd) == ()
    from fmpy.ssp.ssd import read_ssd
    system = read_ssd(str(follower_ssp.path)).system
    assert [c.name for c in system.elements] == ["fourbar", "follower"]
    assert [(c.startElement, c.startConnector, c.endElement, c.endConnector) for c in system.connections] == \
        [("fourbar", "theta2", "follower", "crank"), ("fourbar", "omega2", "follower", "crank_d")]
    with zipfile.ZipFile(follower_ssp.path) as z:
        assert z.namelist() == ["SystemStructure.ssd", "resources/FourBarMotorNative.fmu",
                                "resources/InputDrivenCrankNative.fmu"]
    for component, element in zip(follower_ssp.components, system.elements):
        assert element.source == component.resource
    # the check can fail: a component without its source is refused by the schema
    broken = ssd.replace(b' source="resources/FourBarMotorNative.fmu"', b"", 1)
    assert any("source" in problem for problem in schema_problems(broken))


def test_the_bound_values_are_in_the_ssd_as_in_the_system_file(follower_ssp):
    assert _bindings(follower_ssp.path) == {"fourbar": {"crank_torque": 12.0, "T4": 1.5, "c2": 0.2},
                                            "follower": {"m3": 2.0}}
    from fmpy.ssp.ssd import read_ssd
    connectors = {c.name: {k.name: k.kind for k in c.connectors}
                  for c in read_ssd(str(follower_ssp.path)).system.elements}
    # a bound parameter is a parameter connector; a bound unconnected input is not a connector
    # (FMPy's simulate_ssp sets every input connector before each step, 0 when unconnected)
    assert connectors["fourbar"]["T4"] == "parameter" and "crank_torque" not in connectors["fourbar"]
    assert connectors["follower"]["crank"] == "input" and connectors["follower"]["theta2"] == "output"


def test_the_ssp_bytes_depend_only_on_the_system_and_the_fmus(follower_ssp, follower_fmus, interfaces, tmp_path):
    system = load_system(SYSTEM)
    # the same FMUs, re-zipped with other dates: the .ssp does not change
    redated = {}
    for key, fmu in follower_fmus.items():
        copy = tmp_path / fmu.name
        with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(copy, "w") as dst:
            for info in src.infolist():
                info.date_time = (2031, 7, 4, 12, 0, 0)
                dst.writestr(info, src.read(info))
        redated[key] = copy
    again = {"fourbar": read_interface(redated["fourbar_motor"]), "follower": read_interface(redated[str(FOLLOWER)])}
    write_ssp(tmp_path / "again.ssp", ssd_bytes(system, again),
              {f"resources/{i.path.name}": i.path for i in again.values()})
    assert (tmp_path / "again.ssp").read_bytes() == follower_ssp.path.read_bytes()


# -- the .ssp in other masters (engineer D's module compares them in full) ---------------------

def _libcosim_run(path: Path) -> dict[str, dict[str, float]]:
    pytest.importorskip("libcosimpy", reason="libcosimpy is not installed (pip install libcosimpy)")
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver
    log_output_level(CosimLogLevel.WARNING)
    execution = CosimExecution.from_ssp_file(str(path), round(STEP * 1e9))
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    assert execution.simulate_until(round(STOP * 1e9))
    values = {}
    for slave in execution.slave_infos():
        refs = {v.name.decode(): v.reference for v in execution.slave_variables(slave.index)
                if v.type == CosimVariableType.REAL.value}
        names = sorted(refs)
        values[slave.name.decode()] = dict(zip(names, observer.last_real_values(slave.index,
                                                                                 [refs[n] for n in names])))
    return values


def _fmpy_run(path: Path):
    """FMPy's simulate_ssp with the .ssd's bindings: it reads them but applies only the
    parameter_set it is given, its names "component.variable"."""
    from fmpy.ssp.simulation import simulate_ssp
    from fmpy.ssp.ssd import Parameter, ParameterSet
    bindings = ParameterSet(name="bindings")
    for component, values in _bindings(path).items():
        bindings.parameters += [Parameter(name=f"{component}.{k}", type="Real", value=v) for k, v in values.items()]
    return simulate_ssp(str(path), stop_time=STOP, step_size=STEP, parameter_set=bindings)


def test_libcosim_and_fmpy_load_and_run_the_ssp_with_its_bindings(follower_ssp):
    cosim = _libcosim_run(follower_ssp.path)
    fourbar, follower = cosim["fourbar"], cosim["follower"]
    # libcosim applies the inline bindings: the parameters and the unconnected input
    assert (fourbar["crank_torque"], fourbar["T4"], fourbar["c2"], follower["m3"]) == (12.0, 1.5, 0.2, 2.0)
    assert fourbar["T2"] == 0.5     # an unbound parameter keeps the FMU's start value
    # 12 N.m exceeds what gravity holds at 30 deg: the crank, at rest at the start, turns
    # counter-clockwise (0.022 rad in 0.2 s)
    assert fourbar["theta2"] > np.radians(30) + 0.01
    result = _fmpy_run(follower_ssp.path)
    # the same Jacobi step (every FMU steps from the inputs of the last exchange) as libcosim:
    # the same floating-point operations in the FMUs, so the same numbers up to round-off
    assert abs(result["fourbar.theta2"][-1] - fourbar["theta2"]) <= 1e-12
    assert abs(result["follower.theta2"][-1] - follower["theta2"]) <= 1e-12
    # the follower's driver input moves on with its rate over the step: its crank ends at the
    # four-bar's angle one exchange earlier plus that rate times the step (up to the assembly's
    # Newton-Raphson tolerance, 1e-10 rad)
    np.testing.assert_allclose(result["follower.theta2"][1:],
                               result["fourbar.theta2"][:-1] + STEP * result["fourbar.omega2"][:-1],
                               rtol=0, atol=1e-9)


def test_ecos_loads_and_runs_the_ssp_and_applies_the_named_bindings(follower_ssp):
    pytest.importorskip("ecospy", reason="ecospy is not installed (pip install ecospy)")
    from ecospy import EcosSimulation
    from fmu_src.system.ssd import PARAMETER_SET
    values = {}
    for parameter_set in (None, PARAMETER_SET):
        simulation = EcosSimulation(step_size=STEP, ssp_path=str(follower_ssp.path))
        try:
            simulation.init(parameter_set=parameter_set)
            simulation.step_until(STOP)
            values[parameter_set] = [simulation.get_real(name) for name in
                                     ("fourbar::crank_torque", "fourbar::T4", "fourbar::c2", "follower::m3")]
        finally:
            simulation.terminate()
            simulation.free()
    # Ecos applies a parameter set only when init names it: every component's has one name
    assert values[None] == [0.0, 2.0, 0.1, 1.0]
    assert values[PARAMETER_SET] == [12.0, 1.5, 0.2, 2.0]


# -- mistakes in a system file -----------------------------------------------------------------

def _edited(tmp_path: Path, edit) -> Path:
    data = tomllib.loads(SYSTEM.read_text(encoding="utf-8"))
    edit(data)
    path = tmp_path / "edited" / "system.toml"
    path.parent.mkdir(exist_ok=True)
    (tmp_path / "mechanisms").mkdir(exist_ok=True)
    (tmp_path / "mechanisms" / FOLLOWER.name).write_bytes(FOLLOWER.read_bytes())
    path.write_text(_toml(data), encoding="utf-8")
    return path


def _toml_value(value) -> str:
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + " }"
    return repr(value)                  # numbers (nan and inf are TOML too)


def _toml(data: dict) -> str:
    """The edited system file as TOML: its tables and arrays of tables, values inline."""
    lines = []
    for key, value in data.items():
        for table in (value if isinstance(value, list) else [value]):
            lines.append(f"[[{key}]]" if isinstance(value, list) else f"[{key}]")
            lines += [f"{k} = {_toml_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


def _connection(index, **changes):
    def edit(data):
        data["connections"][index].update(changes)
    return edit


def _parameter(component, **changes):
    def edit(data):
        data["components"][component].setdefault("parameters", {}).update(changes)
    return edit


def _add_connection(source, target):
    def edit(data):
        data["connections"].append({"from": source, "to": target})
    return edit


MISTAKES = {
    "unknown variable": (_connection(0, to="follower.crnak"),
                         "connections[0] 'fourbar.theta2' -> 'follower.crnak': to: follower.crnak: "
                         "InputDrivenCrankNative.fmu has no input 'crnak'; did you mean 'crank'?"),
    "from an input": (_connection(1, **{"from": "follower.crank_dd", "to": "fourbar.crank_torque"}),
                      "follower.crank_dd is 'input', not an output"),
    "to an output": (_connection(1, to="follower.theta3"), "follower.theta3 is 'output', not an input"),
    "units differ": (_connection(0, **{"from": "fourbar.omega2", "to": "follower.crank"}),
                     "units differ: fourbar.omega2 is in rad/s, follower.crank in rad"),
    "two sources": (_add_connection("fourbar.theta3", "follower.crank"),
                    "connections[2].to: 'follower.crank' is already fed by 'fourbar.theta2': an input has one source"),
    "unknown component": (_connection(0, **{"from": "fourbr.theta2"}),
                          "connections[0].from: 'fourbr.theta2': no component named 'fourbr'; did you mean 'fourbar'?"),
    "not component.variable": (_connection(0, to="follower"), "connections[0].to: 'follower' is not 'component.variable'"),
    "unknown parameter": (_parameter(0, T5=1.0), "components 'fourbar'.parameters.T5 = 1.0: fourbar.T5: "
                          "FourBarMotorNative.fmu has no parameter 'T5'"),
    "bound connected input": (_parameter(1, crank=1.0), "follower.crank is a connected input"),
    "bound output": (_parameter(0, theta3=1.0), "fourbar.theta3 is an output"),
    "out of range": (_parameter(0, T4=-1.0), "components 'fourbar'.parameters.T4 = -1.0: outside fourbar.T4's range "
                     "[0.0, inf] N.m"),
    "not a number": (_parameter(0, T4="big"), "components[0] 'fourbar'.parameters.T4: 'big' is not a number"),
    "block and mechanism": (lambda d: d["components"][0].update(block="dc_motor"),
                            "components[0] 'fourbar': give exactly one of 'block'"),
    "same name twice": (lambda d: d["components"][1].update(name="fourbar"),
                        "components[1].name: 'fourbar' is already the name of another component"),
    "no system name": (lambda d: d["system"].pop("name"), "system.name: None is not a name"),
    "misspelt field": (lambda d: d["connections"][0].update(too="follower.crank"),
                       "connections[0]: unknown field 'too'; did you mean 'to'?"),
    "missing mechanism file": (lambda d: d["components"][1].update(mechanism="../nowhere.toml"),
                               "components[1] 'follower'.mechanism: '../nowhere.toml': no such file"),
}


@pytest.mark.parametrize("mistake", MISTAKES)
def test_a_mistake_in_a_system_file_is_refused_naming_file_field_and_value(mistake, interfaces, tmp_path):
    edit, expected = MISTAKES[mistake]
    path = _edited(tmp_path, edit)
    with pytest.raises(SystemFileError) as error:
        check_system(load_system(path), interfaces)
    message = str(error.value)
    assert message.startswith(f"{path}: ") and expected in message, message


def test_the_unedited_system_passes_the_same_checks(interfaces, tmp_path):
    check_system(load_system(_edited(tmp_path, lambda d: None)), interfaces)


def test_a_system_its_fmus_refuse_leaves_an_earlier_ssp_as_it_was(follower_ssp, follower_fmus, tmp_path):
    path = _edited(tmp_path, _connection(0, **{"from": "fourbar.omega2", "to": "follower.crank"}))
    out = tmp_path / "out" / "FourBarFollower.ssp"
    out.parent.mkdir()
    out.write_bytes(follower_ssp.path.read_bytes())
    copied = str((tmp_path / "mechanisms" / FOLLOWER.name).resolve())
    with pytest.raises(SystemFileError, match="units differ"):
        build_system(path, out, prebuilt={**follower_fmus, copied: follower_fmus[str(FOLLOWER)]})
    assert out.read_bytes() == follower_ssp.path.read_bytes() and list(out.parent.iterdir()) == [out]


def test_every_problem_is_listed_at_once(tmp_path):
    data = tomllib.loads(SYSTEM.read_text(encoding="utf-8"))
    data["connections"][0]["from"] = "nobody.theta2"
    data["components"][0]["parameters"]["T4"] = float("nan")
    with pytest.raises(SystemFileError) as error:
        parse_system(data, tmp_path / "x.toml")
    assert "no component named 'nobody'" in str(error.value) and "T4: nan is not finite" in str(error.value)


def _build_cli(*args, cwd=REPO):
    return subprocess.run([sys.executable, str(REPO / "build_fmu.py"), *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=900)   # a hang guard only


@pytest.mark.parametrize("text, expected", [
    ("[system\n", "not valid TOML"),
    ('[system]\nname = "X"\ndescription = "d"\n[[components]]\nname = "a"\nmechanism = "fourbar_motr"\n',
     "components 'a'.mechanism: unknown mechanism 'fourbar_motr'"),
    ('[system]\nname = "X"\ndescription = "d"\n[[components]]\nname = "a"\nmechanism = "fourbar_motor"\n'
     '[[connections]]\nfrom = "a.omega2"\nto = "b.omega"\n', "connections[0].to: 'b.omega': no component named 'b'"),
])
def test_the_command_refuses_a_bad_system_file_and_writes_nothing(text, expected, follower_ssp, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(text, encoding="utf-8")
    out = tmp_path / "out" / "X.ssp"
    out.parent.mkdir()
    out.write_bytes(follower_ssp.path.read_bytes())        # an earlier build, to keep
    proc = _build_cli("--system", bad, "--out", out)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith(f"build_fmu.py: error: {bad}") and expected in proc.stderr, proc.stderr
    assert "Traceback" not in proc.stderr
    assert out.read_bytes() == follower_ssp.path.read_bytes() and list(out.parent.iterdir()) == [out]


def test_the_command_refuses_options_that_do_not_apply_and_an_unknown_system():
    proc = _build_cli("--system", SYSTEM, "--only", "native")
    assert proc.returncode == 2 and "--only does not apply" in proc.stderr
    proc = _build_cli("--system", "motor_fourbr")
    assert proc.returncode == 2 and "unknown system 'motor_fourbr': did you mean 'motor_fourbar'?" in proc.stderr


@pytest.mark.slow
def test_the_command_builds_the_same_bytes(follower_ssp, tmp_path):
    """The whole build (the component FMUs compiled again, in another process) gives the bytes of
    the session's build: the compiled FMUs are deterministic too (~25 s: two native builds)."""
    out = tmp_path / "FourBarFollower.ssp"
    proc = _build_cli("--system", SYSTEM, "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert "SSP 1.0 schema: no problems" in proc.stdout
    assert out.read_bytes() == follower_ssp.path.read_bytes()


# -- the bench's mechanism ---------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["pythonfmu", "native"])
def test_the_bench_fourbar_turns_under_a_constant_torque_doing_its_work(kind, mechanism_fmus):
    """FourBarMotor with crank_torque held at 2 N.m, started at 1 rev/s: the crank keeps turning
    (the torque's mean exceeds the bearings' mean drag), the input's work is the torque times the
    crank's angle, and energy - work + dissipated stays constant."""
    from fmpy import simulate_fmu
    fmu = mechanism_fmus.get("fourbar_motor", kind)
    torque, stop = 2.0, 3.0
    r = simulate_fmu(str(fmu), stop_time=stop, step_size=0.01, start_values={"crank_torque": torque,
                                                                              "omega2_start": 2 * np.pi},
                     output=["theta2", "omega2", "energy", "crank_torque_work", "dissipated"])
    turned = np.unwrap(r["theta2"]) - np.radians(30)
    assert turned[-1] > 2 * 2 * np.pi and np.all(r["omega2"] > 0)      # more than two turns, never back
    # the work of a constant torque: tau times the angle (the integrator's rtol 1e-10 over ~15 rad)
    np.testing.assert_allclose(r["crank_torque_work"], torque * turned, rtol=0, atol=1e-6)
    balance = r["energy"] - r["crank_torque_work"] + r["dissipated"]
    assert np.ptp(balance) < 1e-6 * np.ptp(r["crank_torque_work"])    # rtol 1e-10 steps over 3 s


def test_the_bench_fourbar_is_left_out_of_the_per_mechanism_loops():
    from fmu_src.mechanism.description import SYSTEM_MECHANISMS, shipped_mechanisms
    assert "fourbar_motor" in shipped_mechanisms(systems=True)
    assert "fourbar_motor" not in shipped_mechanisms()
    assert all((REPO / path).is_file() for path in SYSTEM_MECHANISMS.values())


# -- the shipped bench -------------------------------------------------------------------------

# The shipped bench (systems/motor_fourbar.toml) is tests/test_system_bench.py's: built once
# there and run in every master.

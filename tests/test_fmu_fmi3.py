"""The native FMUs in FMI 3.0 (issue 26): <Name>Native3.fmu, the same C model behind
fmu_src/native/fmi3/fmi3Functions.c, in FMPy and fmusim, co-simulation and model exchange.

- `fmpy validate` is clean for every shipped mechanism's FMI 3.0 FMU; its model description
  declares both interfaces, the independent variable `time`, the derivatives by value reference
  and the drawing as an FMI 3.0 annotation; it exports every function the FMI 3.0 headers declare.
- FMPy (co-simulation, and model exchange with CVode) and fmusim (the Reference-FMUs' host, both
  interfaces) agree with the FMI 2.0 co-simulation FMU to <= 1e-9 m.
- The paper's Case 2 (L2 1.0 -> 1.1 m at 10 s) in FMI 3.0 co-simulation equals FMI 2.0's.
- A few of the layer's refusals through ctypes: a NULL instance, a call in the wrong state, an
  unknown value reference, a type the FMU has no variables of -> fmi3Error with a message, and
  nothing changed.  (The full C harness is tests/native_host/fmi3_strict_host.c:
  tests/test_fmu_fmi3_strict.py.)
- binaries/x86_64-linux needs no glibc symbol version newer than 2.17.
"""
from __future__ import annotations

import ctypes
import math
import re
import sys
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave
from fmpy.fmi3 import FMU3Slave
from fmpy.validation import validate_fmu

from fmu_src import fmi_hosts   # the hosts' runners: one home
from fmu_src.mechanism.description import load_mechanism
from support import (COSIM_TOL, CVODE_RTOL, FLAVOUR_AGREE, REPO, RESIDUAL, flavour_span,
                     fmusim_or_skip, lengths_and_angles, swept_mechanisms)


MECHANISMS = swept_mechanisms()   # support.BENCHMARK_MECHANISMS: tested in their own files
GLIBC_BASELINE = (2, 17)        # manylinux2014, as the FMI 2.0 binary
FMI3_HEADERS = Path(__import__("fmpy").__file__).resolve().parent / "c-code"


def _worst(a, b, names) -> float:
    return max(float(np.max(np.abs(np.asarray(a[n]) - np.asarray(b[n])))) for n in names)


def _fmi2_reference(mechanism_fmus, mechanism, names, stop):
    return simulate_fmu(str(mechanism_fmus.get(mechanism, "native")), fmi_type="CoSimulation", stop_time=stop,
                        output_interval=0.01, start_values={"rtol": COSIM_TOL, "atol": COSIM_TOL}, output=names)


# -- the FMU ---------------------------------------------------------------------------------
@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_fmpy_validate_is_clean_and_the_description_is_fmi3(mechanism, mechanism_fmus):
    fmu = mechanism_fmus.get(mechanism, "native3")
    assert validate_fmu(str(fmu)) == []
    md = read_model_description(str(fmu))
    assert md.fmiVersion == "3.0" and md.coSimulation and md.modelExchange
    assert md.coSimulation.modelIdentifier == md.modelExchange.modelIdentifier == f"{load_mechanism(mechanism).name}Native3"
    assert re.fullmatch(r"\{[0-9a-f-]{36}\}", md.instantiationToken)
    fmi2 = read_model_description(str(mechanism_fmus.get(mechanism, "native")))
    by_vr = {v.valueReference: v for v in md.modelVariables}
    # the FMI 2.0 variables, same value references, then `time` (value reference N)
    for v in fmi2.modelVariables:
        w = by_vr[v.valueReference]
        assert (w.name, w.causality, w.variability, w.unit) == (v.name, v.causality, v.variability, v.unit)
        assert w.type == ("Float64" if v.type == "Real" else v.type)
    time = by_vr[len(fmi2.modelVariables)]
    assert (time.name, time.causality, time.type) == ("time", "independent", "Float64")
    # derivatives: der(x) names x by value reference
    assert len(md.derivatives) == len(fmi2.derivatives) > 0
    for d in md.derivatives:
        assert d.variable.name == f"der({d.variable.derivative.name})"
    with zipfile.ZipFile(fmu) as z:
        names = z.namelist()
        root = ET.fromstring(z.read("modelDescription.xml"))
        fmi2_root = ET.fromstring(zipfile.ZipFile(mechanism_fmus.get(mechanism, "native")).read("modelDescription.xml"))
    assert f"binaries/x86_64-linux/{md.coSimulation.modelIdentifier}.so" in names or not sys.platform.startswith("linux")
    assert "sources/buildDescription.xml" in names and "sources/fmi3Functions.c" in names
    assert "sources/fmi2Functions.c" not in names
    # the drawing: FMI 3.0's annotation form, the same <Drawing> as FMI 2.0's vendor annotation
    drawing = root.find("./Annotations/Annotation[@type='fourbar-cosim']/Drawing")
    fmi2_drawing = fmi2_root.find("./VendorAnnotations/Tool[@name='fourbar-cosim']/Drawing")
    assert drawing is not None and ET.tostring(drawing).strip() == ET.tostring(fmi2_drawing).strip()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads the ELF binary")
def test_every_fmi3_function_is_exported_and_no_other(mechanism_fmus, tmp_path):
    """FMI 3.0 requires every function of fmi3Functions.h in the binary (unused ones refuse)."""
    fmu = mechanism_fmus.get("fourbar", "native3")
    declared = set(re.findall(r"^FMI3_Export\s+\w+\s+(fmi3\w+);", (FMI3_HEADERS / "fmi3Functions.h").read_text(),
                              re.M))
    assert len(declared) > 70
    library = Path(extract(str(fmu), unzipdir=str(tmp_path))) / "binaries" / "x86_64-linux" / "FourBarNative3.so"
    lib = ctypes.CDLL(str(library))
    missing = sorted(n for n in declared if not hasattr(lib, n))
    assert not missing
    assert not hasattr(lib, "fmi2DoStep") and not hasattr(lib, "model_do_step")   # nothing else exported


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the FMU's binary here is x86_64-linux")
def test_linux_binary_needs_no_glibc_newer_than_2_17(mechanism_fmus, tmp_path):
    from test_fmu_native_strict import glibc_versions_needed   # one ELF reader

    library = Path(extract(str(mechanism_fmus.get("fourbar", "native3")), unzipdir=str(tmp_path))) / "binaries" / "x86_64-linux" / \
        "FourBarNative3.so"
    needed = glibc_versions_needed(library)
    assert needed, "no GLIBC version found: the ELF reader is broken"
    newer = sorted(n for n in needed if tuple(map(int, n[6:].split("."))) > GLIBC_BASELINE)
    assert not newer, f"needs {newer}: it will not load on glibc 2.17"


# -- FMPy ------------------------------------------------------------------------------------
@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_fmpy_co_simulation_equals_fmi2(mechanism, mechanism_fmus):
    fmu = mechanism_fmus.get(mechanism, "native3")
    names = lengths_and_angles(fmu)
    stop = flavour_span(mechanism)
    ref = _fmi2_reference(mechanism_fmus, mechanism, names, stop)
    cs = simulate_fmu(str(fmu), fmi_type="CoSimulation", stop_time=stop, output_interval=0.01,
                      start_values={"rtol": COSIM_TOL, "atol": COSIM_TOL}, output=names)
    assert np.array_equal(cs["time"], ref["time"])
    assert _worst(cs, ref, names) <= FLAVOUR_AGREE
    # the same C model, the same arithmetic: the layers only read it (measured: bit for bit)
    assert _worst(cs, ref, names) == 0.0


@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_fmpy_model_exchange_agrees_with_fmi2_co_simulation(mechanism, mechanism_fmus):
    fmu = mechanism_fmus.get(mechanism, "native3")
    names = lengths_and_angles(fmu)
    stop = flavour_span(mechanism)
    ref = _fmi2_reference(mechanism_fmus, mechanism, names, stop)
    me = simulate_fmu(str(fmu), fmi_type="ModelExchange", solver="CVode", relative_tolerance=CVODE_RTOL,
                      stop_time=stop, output_interval=0.01, output=names + ["constraint_residual"])
    assert np.array_equal(me["time"], ref["time"])
    assert _worst(me, ref, names) <= FLAVOUR_AGREE, (mechanism, _worst(me, ref, names))
    assert float(np.max(me["constraint_residual"])) <= RESIDUAL


# -- fmusim ----------------------------------------------------------------------------------
@pytest.mark.parametrize("interface", ["CoSimulation", "ModelExchange"])
@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_fmusim_runs_fmi3_and_agrees_with_fmi2_co_simulation(mechanism, interface, mechanism_fmus,
                                                             tmp_path):
    """fmusim (Reference-FMUs v0.0.39 here), its own CVode for model exchange; skipped without fmusim."""
    fmusim = fmusim_or_skip()
    fmu = mechanism_fmus.get(mechanism, "native3")
    names = tuple(lengths_and_angles(fmu))
    stop = flavour_span(mechanism)
    me = interface == "ModelExchange"
    experiment = fmi_hosts.Experiment(stop=stop, rtol=COSIM_TOL, atol=COSIM_TOL)
    run = fmi_hosts.run_fmusim(fmusim, fmu, names, experiment, tmp_path,
                               model_exchange_tolerance=CVODE_RTOL if me else None)
    assert run.exit_code == 0 and run.values is not None, run.message
    ref = _fmi2_reference(mechanism_fmus, mechanism, list(names), stop)
    assert run.values.shape == (len(ref), len(names))
    assert np.allclose(run.time, ref["time"], rtol=0, atol=1e-12)     # fmusim prints 16 digits
    worst = max(float(np.max(np.abs(run.values[:, k] - ref[n]))) for k, n in enumerate(names))
    assert worst <= FLAVOUR_AGREE, (mechanism, interface, worst)


# -- Case 2: a parameter changed mid-run -------------------------------------------------------
def _case2(fmu: Path, tmp: Path, fmi_version: int, fault: bool = True) -> np.ndarray:
    """x2, y3 every 0.01 s over 16 s; L2 1.0 -> 1.1 m set before the step that starts at 10 s."""
    md = read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    unzip = extract(str(fmu), unzipdir=str(tmp))
    common = dict(unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier, instanceName="case2")
    rows = []
    if fmi_version == 2:
        slave = FMU2Slave(guid=md.guid, **common)
        slave.instantiate()
        slave.setReal([vr["rtol"], vr["atol"]], [1e-12, 1e-12])
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        get, set_ = slave.getReal, slave.setReal
    else:
        slave = FMU3Slave(guid=md.instantiationToken, **common)          # FMPy names the token guid
        slave.instantiate()
        slave.setFloat64([vr["rtol"], vr["atol"]], [1e-12, 1e-12])
        slave.enterInitializationMode(startTime=0.0)
        slave.exitInitializationMode()
        get, set_ = slave.getFloat64, slave.setFloat64
    try:
        rows.append(get([vr["x2"], vr["y3"]]))
        for k in range(1600):
            t = k * 0.01
            if fault and k == 1000:
                set_([vr["L2"]], [1.1])
            slave.doStep(currentCommunicationPoint=t, communicationStepSize=0.01)
            rows.append(get([vr["x2"], vr["y3"]]))
        slave.terminate()
    finally:
        slave.freeInstance()
    return np.array(rows, dtype=float)


def test_case2_parameter_change_mid_run_equals_fmi2(mechanism_fmus, native_fmu, tmp_path):
    fmi3 = _case2(mechanism_fmus.get("fourbar", "native3"), tmp_path / "3", 3)
    fmi2 = _case2(native_fmu, tmp_path / "2", 2)
    healthy = _case2(mechanism_fmus.get("fourbar", "native3"), tmp_path / "h", 3, fault=False)
    assert fmi3.shape == fmi2.shape == (1601, 2)
    # the same model and the same steps: equal to round-off (measured: bit for bit)
    assert float(np.max(np.abs(fmi3 - fmi2))) <= 1e-12
    # and the fault happened: from 10 s the linkage leaves the healthy run (by centimetres)
    assert float(np.max(np.abs(fmi3[:1001] - healthy[:1001]))) == 0.0
    assert float(np.max(np.abs(fmi3[1001:] - healthy[1001:]))) > 1e-2


# -- strictness through ctypes ------------------------------------------------------------------
class _Lib:
    """The FMI 3.0 binary loaded with ctypes, and the messages its logger received."""

    LOG = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_char_p)

    def __init__(self, fmu: Path, tmp: Path):
        md = read_model_description(str(fmu))
        self.token = md.instantiationToken.encode()
        self.vr = {v.name: v.valueReference for v in md.modelVariables}
        unzip = Path(extract(str(fmu), unzipdir=str(tmp)))
        self.lib = ctypes.CDLL(str(unzip / "binaries" / "x86_64-linux" / f"{md.coSimulation.modelIdentifier}.so"))
        self.messages: list[tuple[int, str]] = []
        self._logger = self.LOG(lambda env, status, category, message:
                                self.messages.append((status, message.decode())))
        f = self.lib
        f.fmi3InstantiateCoSimulation.restype = ctypes.c_void_p
        f.fmi3InstantiateCoSimulation.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_char_p, ctypes.c_bool,
                                                  ctypes.c_bool, ctypes.c_bool, ctypes.c_bool, ctypes.c_void_p,
                                                  ctypes.c_size_t, ctypes.c_void_p, self.LOG, ctypes.c_void_p]
        f.fmi3InstantiateModelExchange.restype = ctypes.c_void_p
        f.fmi3InstantiateModelExchange.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_char_p, ctypes.c_bool,
                                                   ctypes.c_bool, ctypes.c_void_p, self.LOG]
        f.fmi3FreeInstance.argtypes = [ctypes.c_void_p]
        f.fmi3EnterInitializationMode.argtypes = [ctypes.c_void_p, ctypes.c_bool, ctypes.c_double, ctypes.c_double,
                                                  ctypes.c_bool, ctypes.c_double]
        for name in ("fmi3ExitInitializationMode", "fmi3Terminate", "fmi3EnterContinuousTimeMode",
                     "fmi3EnterStepMode"):
            getattr(f, name).argtypes = [ctypes.c_void_p]
        f.fmi3GetFloat64.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint32), ctypes.c_size_t,
                                     ctypes.POINTER(ctypes.c_double), ctypes.c_size_t]
        f.fmi3SetFloat64.argtypes = f.fmi3GetFloat64.argtypes
        f.fmi3GetInt32.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_uint32), ctypes.c_size_t,
                                   ctypes.POINTER(ctypes.c_int32), ctypes.c_size_t]
        f.fmi3DoStep.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_bool,
                                 ctypes.POINTER(ctypes.c_bool), ctypes.POINTER(ctypes.c_bool),
                                 ctypes.POINTER(ctypes.c_bool), ctypes.POINTER(ctypes.c_double)]
        f.fmi3GetContinuousStateDerivatives.argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_double),
                                                        ctypes.c_size_t]

    def co_simulation(self, token: bytes | None = None, event_mode: bool = False):
        return self.lib.fmi3InstantiateCoSimulation(b"cs", token or self.token, None, False, False, event_mode,
                                                    False, None, 0, None, self._logger, None)

    def model_exchange(self):
        return self.lib.fmi3InstantiateModelExchange(b"me", self.token, None, False, False, None, self._logger)

    def get(self, instance, names_or_vrs, n_values=None) -> tuple[int, list[float]]:
        vrs = [self.vr[x] if isinstance(x, str) else x for x in names_or_vrs]
        refs = (ctypes.c_uint32 * len(vrs))(*vrs)
        values = (ctypes.c_double * len(vrs))()
        status = self.lib.fmi3GetFloat64(instance, refs, len(vrs), values, len(vrs) if n_values is None else n_values)
        return status, list(values)

    def do_step(self, instance, t: float, h: float) -> tuple[int, float]:
        flags = [ctypes.c_bool(True) for _ in range(3)]
        last = ctypes.c_double(-1.0)
        status = self.lib.fmi3DoStep(instance, t, h, False, *(ctypes.byref(x) for x in flags), ctypes.byref(last))
        if status == FMI3_OK:                           # a refused call writes nothing
            assert not any(x.value for x in flags)      # no event, no termination, no early return
        return status, last.value

    def last_error(self) -> str:
        return next((text for status, text in reversed(self.messages) if status == FMI3_ERROR), "")


FMI3_OK, FMI3_ERROR = 0, 3


@pytest.fixture()
def lib(mechanism_fmus, tmp_path):
    if not sys.platform.startswith("linux"):
        pytest.skip("loads the x86_64-linux binary")
    return _Lib(mechanism_fmus.get("fourbar", "native3"), tmp_path)


def test_refusals_are_errors_with_a_message_and_change_nothing(lib):
    f = lib.lib
    # a NULL instance: fmi3Error (no logger to reach), no crash
    assert f.fmi3ExitInitializationMode(None) == FMI3_ERROR
    assert lib.get(None, ["x2"])[0] == FMI3_ERROR
    f.fmi3FreeInstance(None)
    # instantiation: a token of another build, event mode asked, Scheduled Execution -> NULL with a message
    assert lib.co_simulation(token=b"{00000000-0000-0000-0000-000000000000}") is None
    assert "does not match this binary's" in lib.last_error()
    assert lib.co_simulation(event_mode=True) is None and "eventModeUsed" in lib.last_error()
    cs = lib.co_simulation()
    assert cs
    try:
        # instantiated: the start values can be read (FMI 3.0, 2.3.2), no doStep before initialization
        status, starts = lib.get(cs, ["L2", "time"])
        assert status == FMI3_OK and starts == [1.0, 0.0]
        # and the outputs those start values give (theta2 has no start attribute: not 0.0 but
        # the start angle, 30 deg; x2 the crank's centre there), equal to initialization's
        status, previewed = lib.get(cs, ["theta2", "x2"])
        assert status == FMI3_OK and previewed[0] == pytest.approx(math.radians(30.0), abs=1e-15)
        assert previewed[1] == pytest.approx(0.5 * math.cos(math.radians(30.0)), abs=1e-15)
        assert lib.do_step(cs, 0.0, 0.01)[0] == FMI3_ERROR and "fmi3DoStep is not allowed" in lib.last_error()
        assert f.fmi3EnterInitializationMode(cs, False, 0.0, 0.0, False, 0.0) == FMI3_OK
        assert f.fmi3ExitInitializationMode(cs) == FMI3_OK                       # -> stepMode
        status, before = lib.get(cs, ["x2", "L2", "time"])
        assert status == FMI3_OK and before[2] == 0.0
        # unknown value reference, nValues not the count, a type without variables, time not settable
        assert lib.get(cs, [100000])[0] == FMI3_ERROR and "unknown value reference 100000" in lib.last_error()
        assert lib.get(cs, ["x2", "y3"], n_values=1)[0] == FMI3_ERROR and "1 values" in lib.last_error()
        ints = (ctypes.c_int32 * 1)()
        assert f.fmi3GetInt32(cs, (ctypes.c_uint32 * 1)(0), 1, ints, 1) == FMI3_ERROR
        assert "no Int32 variables" in lib.last_error()
        value = (ctypes.c_double * 1)(5.0)
        assert f.fmi3SetFloat64(cs, (ctypes.c_uint32 * 1)(lib.vr["time"]), 1, value, 1) == FMI3_ERROR
        assert "independent variable" in lib.last_error()
        assert f.fmi3SetFloat64(cs, (ctypes.c_uint32 * 1)(lib.vr["theta2_start"]), 1, value, 1) == FMI3_ERROR
        assert "fixed parameter" in lib.last_error()
        # a model-exchange call on a co-simulation instance; event mode never entered in co-simulation
        assert f.fmi3GetContinuousStateDerivatives(cs, (ctypes.c_double * 2)(), 2) == FMI3_ERROR
        assert "model exchange function" in lib.last_error() or "not allowed" in lib.last_error()
        assert f.fmi3EnterStepMode(cs) == FMI3_ERROR
        # none of that changed anything: the values are as before, and a step works
        assert lib.get(cs, ["x2", "L2", "time"]) == (FMI3_OK, before)
        status, last = lib.do_step(cs, 0.0, 0.01)
        assert status == FMI3_OK and last == pytest.approx(0.01, abs=1e-12)
        assert lib.get(cs, ["time"])[1][0] == pytest.approx(0.01, abs=1e-12)
        # a failed step (the model is at 0.01 s, not 5 s): fmi3Error, the error state, no value read there
        assert lib.do_step(cs, 5.0, 0.01)[0] == FMI3_ERROR
        assert lib.get(cs, ["x2"])[0] == FMI3_ERROR and "not allowed in state error" in lib.last_error()
    finally:
        f.fmi3FreeInstance(cs)
    me = lib.model_exchange()
    assert me
    try:
        assert lib.do_step(me, 0.0, 0.01)[0] == FMI3_ERROR                       # co-simulation only
        assert f.fmi3EnterInitializationMode(me, False, 0.0, 0.0, False, 0.0) == FMI3_OK
        assert f.fmi3ExitInitializationMode(me) == FMI3_OK                       # -> eventMode
        assert f.fmi3GetContinuousStateDerivatives(me, (ctypes.c_double * 3)(), 3) == FMI3_ERROR
        assert "3 derivatives given" in lib.last_error()
        assert f.fmi3EnterContinuousTimeMode(me) == FMI3_OK
        dx = (ctypes.c_double * 2)()
        assert f.fmi3GetContinuousStateDerivatives(me, dx, 2) == FMI3_OK and dx[0] == 0.0 and dx[1] != 0.0
    finally:
        f.fmi3FreeInstance(me)
    assert all(text.startswith(("cs: ", "me: ")) for _, text in lib.messages)    # FMI 3.0 passes no name


def test_the_fmi3_layer_names_no_mechanism():
    """As test_fmu_native.py's check of fmu_src/native/: the FMI 3.0 layer is generic too."""
    words = re.compile(r"\b(theta\d|omega\d|[xy][2-9]|L[1-9]|m[2-9]|crank|coupler|rocker|slider|four_?bar|FB_BRANCH)\b",
                       re.I)
    code = re.sub(r"/\*.*?\*/|//[^\n]*", " ", (REPO / "fmu_src" / "native" / "fmi3" / "fmi3Functions.c").read_text(),
                  flags=re.S)
    assert not sorted({m.group(0) for m in words.finditer(code)})

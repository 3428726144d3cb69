"""The FMUs bound the work of one call and refuse what they cannot use (issue 36, the FMU side).

- ``max_evaluations`` ends a doStep that would run away (case 1 at omega2_start = 1e15 sat in one
  doStep for ever) with an error status and a message naming the cap, the time reached and how
  to raise it: native FMI 2.0 and 3.0 (fmi2Error/fmi3Error), pythonfmu (fmi2Discard: pythonfmu
  0.7 reports a step's failure so).
- Steps that cannot be taken as given (inf, NaN, 0, negative, too short for the 1 ns grid, a
  non-finite communication point) are refused, never fmi2OK without advancing; a non-finite
  parameter value is refused by the setter; model exchange refuses non-finite states and returns
  an error, not NaN with OK, at states of no physical size.
- Crafted FMU states (tests/native_host/fmi2_strict_host.c and fmi3_strict_host.c, the cases
  "crafted FMU states") are refused or survive, with the FMU and the hosts built with
  ``-fsanitize=address,undefined -fno-sanitize-recover=all``: a sanitizer report fails the case.

Every FMU call runs in a child process with a generous hang guard (HANG_GUARD): a call that never
returns fails the test instead of hanging it; no test measures time (benchmarks/fmu_step_work.py
does).
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
HOSTS = HERE / "native_host"
#: A child's time limit: the capped runaway step takes ~0.1 s natively; a hang is for ever.
HANG_GUARD = 120
#: The sanitizers' options: a report aborts (a crash is a failed case in the hosts); leaks are
#: valgrind's business (benchmarks/native_valgrind.py), and LeakSanitizer fails under ptrace.
SANITIZER_ENV = {"ASAN_OPTIONS": "detect_leaks=0:abort_on_error=1", "UBSAN_OPTIONS": "halt_on_error=1:abort_on_error=1"}
SANITIZE = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer", "-g", "-O1"]

# The child's helpers: an FMI 2.0 or 3.0 co-simulation instance of an FMU with a logger that keeps
# every message, and a call that reports its status instead of raising.
_PRELUDE = textwrap.dedent('''
    import json, math, sys
    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from orchestrator import install_pythonfmu_exit_guard
    install_pythonfmu_exit_guard()      # a pythonfmu FMU may abort the process at exit (PythonFMU #228)
    MESSAGES = []
    def slave(path, kind="cs", start=None):
        md = read_model_description(path)
        vr = {v.name: v.valueReference for v in md.modelVariables}
        where = extract(path)
        if md.fmiVersion == "3.0":
            from fmpy.fmi3 import FMU3Slave, FMU3Model
            cls = FMU3Model if kind == "me" else FMU3Slave
            s = cls(guid=md.guid, unzipDirectory=where, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="bounds")
            s.instantiate(loggingOn=True, logMessage=lambda env, status, category, message:
                          MESSAGES.append(message.decode(errors="replace")))
            s.enterInitializationMode(startTime=0.0)
            if start: s.setFloat64([vr[k] for k in start], list(start.values()))
        else:
            from fmpy.fmi2 import (FMU2Slave, FMU2Model, defaultCallbacks, fmi2CallbackFunctions,
                                   fmi2CallbackLoggerTYPE)
            cb = fmi2CallbackFunctions()
            cb.logger = fmi2CallbackLoggerTYPE(lambda c, i, status, category, message:
                                               MESSAGES.append(message.decode(errors="replace")))
            cb.allocateMemory, cb.freeMemory = defaultCallbacks.allocateMemory, defaultCallbacks.freeMemory
            from ctypes import byref
            from fmpy.logging import addLoggerProxy
            addLoggerProxy(byref(cb))       # formats the message's "%s" arguments
            model = md.modelExchange if kind == "me" else md.coSimulation
            cls = FMU2Model if kind == "me" else FMU2Slave
            s = cls(guid=md.guid, unzipDirectory=where, modelIdentifier=model.modelIdentifier, instanceName="bounds")
            s.instantiate(loggingOn=True, callbacks=cb)
            s.setupExperiment(startTime=0.0)
            s.enterInitializationMode()
            if start: s.setReal([vr[k] for k in start], list(start.values()))
        s.exitInitializationMode()
        return s, vr
    def status(call, *args):
        try:
            call(*args)
            return 0
        except FMICallException as exc:
            return int(exc.status)
    def report(**kw):
        print(json.dumps(dict(kw, messages=MESSAGES)))
''')


def _child(code: str) -> dict:
    """Run `code` (after _PRELUDE) in a fresh interpreter within HANG_GUARD; its report()."""
    proc = subprocess.run([sys.executable, "-c", _PRELUDE + textwrap.dedent(code)], capture_output=True, text=True,
                          timeout=HANG_GUARD)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def native3_fmu(mechanism_fmus) -> Path:
    return mechanism_fmus.get("fourbar", "native3")


# -- the cap on one doStep's work ---------------------------------------------------------
@pytest.mark.parametrize("flavour", ["native", "native3"])
def test_the_cap_ends_a_runaway_step_with_an_error(flavour, native_fmu, native3_fmu):
    fmu = native_fmu if flavour == "native" else native3_fmu
    got = _child(f'''
        s, vr = slave({str(fmu)!r}, start={{"omega2_start": 1e15}})
        code = status(s.doStep, 0.0, 0.01)
        report(status=code)
    ''')
    assert got["status"] == 3, got            # fmi2Error / fmi3Error
    text = " ".join(got["messages"])
    assert "needed more than max_evaluations = 100000 right-hand-side evaluations" in text, text
    assert "it reached t = " in text and "raise max_evaluations" in text, text


def test_the_cap_ends_a_runaway_step_of_the_pythonfmu_fmu(fourbar_fmu):
    """The same semantics; a cap of 2000 because at the default the pythonfmu FMU's failing
    evaluations (continuations that do not close the loop) take about a minute.  pythonfmu 0.7
    reports a step that returns False as fmi2Discard."""
    got = _child(f'''
        s, vr = slave({str(fourbar_fmu)!r}, start={{"omega2_start": 1e15, "max_evaluations": 2000.0}})
        code = status(s.doStep, 0.0, 0.01)
        report(status=code)
    ''')
    assert got["status"] == 2, got
    text = " ".join(got["messages"])
    assert "needed more than max_evaluations = 2000 right-hand-side evaluations" in text, text


@pytest.mark.parametrize("flavour", ["native", "pythonfmu"])
def test_the_cap_is_a_parameter_of_both_fmus_with_the_same_default(flavour, native_fmu, fourbar_fmu):
    from fmpy import read_model_description

    md = read_model_description(str(native_fmu if flavour == "native" else fourbar_fmu))
    var = next(v for v in md.modelVariables if v.name == "max_evaluations")
    assert (var.causality, var.variability, var.type, float(var.start)) == ("parameter", "fixed", "Real", 1e5)


def test_a_capped_run_that_needs_less_is_unchanged(native_fmu):
    """A healthy second of case 1 at a cap of 200 evaluations per 0.01 s step (it needs far fewer)
    gives the default's numbers bit for bit: the cap only counts."""
    got = _child(f'''
        rows = []
        for cap in (200.0, 1e5):
            s, vr = slave({str(native_fmu)!r}, start={{"max_evaluations": cap}})
            for k in range(100):
                s.doStep(k * 0.01, 0.01)
            rows.append(s.getReal([vr["x2"], vr["omega2"]]))
        report(rows=rows)
    ''')
    assert got["rows"][0] == got["rows"][1]


# -- steps, values and states that cannot be used ---------------------------------------
BAD_STEPS = [("inf", 0.0, "math.inf"), ("nan", 0.0, "math.nan"), ("zero", 0.0, "0.0"), ("negative", 0.0, "-0.01"),
             ("1e-12", 0.0, "1e-12"), ("t = inf", "math.inf", "0.01")]


@pytest.mark.parametrize("flavour", ["native", "native3"])
@pytest.mark.parametrize("label,t,h", BAD_STEPS, ids=[b[0] for b in BAD_STEPS])
def test_a_step_that_cannot_be_taken_is_refused(flavour, label, t, h, native_fmu, native3_fmu):
    fmu = native_fmu if flavour == "native" else native3_fmu
    got = _child(f'''
        s, vr = slave({str(fmu)!r})
        code = status(s.doStep, {t}, {h})
        report(status=code)
    ''')
    assert got["status"] == 3, got
    text = " ".join(got["messages"])
    assert "DoStep" in text and ("step size" in text or "cannot advance" in text or "communication point" in text)


@pytest.mark.parametrize("label,t,h", BAD_STEPS, ids=[b[0] for b in BAD_STEPS])
def test_the_pythonfmu_fmu_refuses_the_same_steps(label, t, h, fourbar_fmu):
    got = _child(f'''
        s, vr = slave({str(fourbar_fmu)!r})
        code = status(s.doStep, {t}, {h})
        report(status=code)
    ''')
    assert got["status"] == 2, got            # pythonfmu 0.7: a step returning False is fmi2Discard
    assert any("do_step:" in m for m in got["messages"]), got


def test_a_nanosecond_step_advances(native_fmu):
    got = _child(f'''
        from fmpy.fmi2 import fmi2LastSuccessfulTime
        s, vr = slave({str(native_fmu)!r})
        s.doStep(0.0, 1e-9)
        report(time=s.getRealStatus(fmi2LastSuccessfulTime))
    ''')
    assert got["time"] == 1e-9


@pytest.mark.parametrize("flavour", ["native", "native3"])
@pytest.mark.parametrize("value", ["math.nan", "math.inf", "-math.inf"])
def test_a_non_finite_parameter_value_is_refused_by_the_setter(flavour, value, native_fmu, native3_fmu):
    fmu = native_fmu if flavour == "native" else native3_fmu
    got = _child(f'''
        s, vr = slave({str(fmu)!r})
        setter = s.setFloat64 if hasattr(s, "setFloat64") else s.setReal
        getter = s.getFloat64 if hasattr(s, "getFloat64") else s.getReal
        code = status(setter, [vr["L2"]], [{value}])
        report(status=code, L2=getter([vr["L2"]])[0])
    ''')
    assert got["status"] == 3 and got["L2"] == 1.0, got
    assert any("L2 = " in m and "must be finite" in m for m in got["messages"]), got


@pytest.mark.parametrize("flavour", ["native", "native3"])
def test_model_exchange_refuses_non_finite_states_and_derivatives(flavour, native_fmu, native3_fmu):
    """NaN states are refused naming the state; at (1e308, -1e308) the derivatives are not finite:
    an error with a message, not NaN with OK."""
    fmu = native_fmu if flavour == "native" else native3_fmu
    got = _child(f'''
        s, vr = slave({str(fmu)!r}, kind="me")
        three = hasattr(s, "updateDiscreteStates")
        if three:
            s.updateDiscreteStates()
        else:
            s.newDiscreteStates()
        s.enterContinuousTimeMode()
        from ctypes import c_double
        nan = status(s.setContinuousStates, (c_double * 2)(math.nan, 0.0), 2)
        huge = status(s.setContinuousStates, (c_double * 2)(1e308, -1e308), 2)
        get = s.getContinuousStateDerivatives if three else s.getDerivatives
        derivatives = status(get, (c_double * 2)(), 2)
        report(nan=nan, huge=huge, derivatives=derivatives)
    ''')
    assert got["nan"] == 3 and got["huge"] == 0 and got["derivatives"] == 3, got
    text = " ".join(got["messages"])
    assert "theta2 = nan: must be finite" in text, text
    assert "is not finite at the states the host set" in text, text


# -- crafted FMU states under the sanitizers ---------------------------------------------
def _sanitizers_work(cc: str, tmp: Path) -> str | None:
    """None when `cc` builds and runs a program with the sanitizers; else why not."""
    src = tmp / "probe.c"
    src.write_text("int main(void) { return 0; }\n")
    build = subprocess.run([cc, *SANITIZE, "-o", str(tmp / "probe"), str(src)], capture_output=True, text=True)
    if build.returncode != 0:
        return f"{cc} cannot build with -fsanitize=address,undefined: {build.stderr.strip()[:200]}"
    run = subprocess.run([str(tmp / "probe")], capture_output=True, text=True, env={**os.environ, **SANITIZER_ENV})
    if run.returncode != 0:
        return f"a sanitized program does not run here: {run.stderr.strip()[:200]}"
    return None


def _sanitized_library(fmu: Path, cc: str, dest: Path) -> Path:
    """The FMU's shipped sources compiled with the sanitizers into a shared library."""
    with zipfile.ZipFile(fmu) as z:
        z.extractall(dest)
    sources = sorted(str(p) for p in (dest / "sources").glob("*.c"))
    library = dest / "sanitized.so"
    subprocess.run([cc, "-std=c99", *SANITIZE, "-shared", "-fPIC", "-I", str(dest / "sources"), "-o", str(library),
                    *sources, "-lm"], check=True, capture_output=True, text=True)
    return library


@pytest.fixture(scope="module")
def sanitizing_cc(tmp_path_factory) -> str:
    cc = shutil.which("gcc")
    if cc is None:
        pytest.skip("no gcc: the sanitizer run needs it")
    why = _sanitizers_work(cc, tmp_path_factory.mktemp("probe"))
    if why:
        pytest.skip(why)
    return cc


def _check_sanitized_run(proc: subprocess.CompletedProcess) -> None:
    report = proc.stdout + proc.stderr
    assert "runtime error" not in report and "AddressSanitizer" not in report, report[-4000:]
    assert proc.returncode == 0, report[-4000:]
    for kind in ("co-simulation", "model exchange"):
        assert f"crafted states ({kind}): " in proc.stdout, proc.stdout[-2000:]


def test_crafted_fmi2_states_are_refused_with_no_sanitizer_report(sanitizing_cc, native_fmu, tmp_path):
    from native_host.strict_host import fmi_header_dir, unpack

    target = unpack(native_fmu, tmp_path / "unpacked")
    library = _sanitized_library(native_fmu, sanitizing_cc, tmp_path / "sanitized")
    host = tmp_path / "fmi2_strict_host"
    subprocess.run([sanitizing_cc, "-std=c99", *SANITIZE, "-I", str(fmi_header_dir()), "-o", str(host),
                    str(HOSTS / "fmi2_strict_host.c"), "-ldl"], check=True, capture_output=True, text=True)
    proc = subprocess.run([str(host), "--only", "crafted FMU states", str(library), target.guid,
                           *map(str, target.value_references), str(target.states)],
                          capture_output=True, text=True, timeout=600, env={**os.environ, **SANITIZER_ENV})
    _check_sanitized_run(proc)


def test_crafted_fmi3_states_are_refused_with_no_sanitizer_report(sanitizing_cc, native3_fmu, tmp_path, monkeypatch):
    import dataclasses

    from native_host import strict_host3

    target = strict_host3.unpack(native3_fmu, tmp_path / "unpacked")
    target = dataclasses.replace(target, library=_sanitized_library(native3_fmu, sanitizing_cc, tmp_path / "sanitized"))
    host = tmp_path / "fmi3_strict_host"
    subprocess.run([sanitizing_cc, "-std=c99", *SANITIZE, "-I", str(strict_host3.fmi_header_dir()), "-o", str(host),
                    str(HOSTS / "fmi3_strict_host.c"), "-ldl", "-lm"], check=True, capture_output=True, text=True)
    for name, value in SANITIZER_ENV.items():
        monkeypatch.setenv(name, value)
    run = strict_host3.run_host(host, target, only="crafted FMU states", twin=False)
    _check_sanitized_run(subprocess.CompletedProcess(run.command, run.returncode, run.stdout, run.stderr))

"""The native FMUs' FMI 3.0 C layer, fmu_src/native/fmi3/fmi3Functions.c, held to the FMI 3.0 standard.

- tests/native_host/fmi3_strict_host.c, compiled here (-Werror) against FMPy's FMI 3.0 headers, runs
  on every shipped mechanism's <Name>Native3.fmu, with its FMI 2.0 twin <Name>Native.fmu loaded in
  the same process: every one of the 70 functions with an instance in the 13 states a co-simulation
  or model-exchange instance reaches, with a NULL instance and with NULL arguments; gets and sets of
  every variable kind in every state; instantiation's refusals, logging, impossible parameter values
  and the way back from them, the paper's Case 2 (the tunable parameter +10 % at 10 s) and a
  model-exchange run with a parameter change in event mode, both bit for bit against the FMI 2.0
  twin, FMU-state round trips replaying a run bit for bit, fmi3Reset and fmi3FreeInstance in every
  state; every allocation given back.  Each of its cases is a test here, per mechanism.  The cases
  the layer fails for a known, reported deviation from the standard
  (native_host/strict_host3.py: KNOWN_DEVIATIONS) are strict expected failures.
- The harness fails on layers that break a rule (mutants of fmi3Functions.c or fmi_layer.c, compiled here with the
  FMU's other shipped sources).
- The FMU's shipped sources build with -Wall -Wextra -Werror as their buildDescription.xml lists
  them, and that build passes the harness as the shipped binary does.
- Under valgrind (when installed): no invalid access, no uninitialised value used, nothing lost.
"""
from __future__ import annotations

import dataclasses
import platform
import shutil
import subprocess
import sys
import tempfile
from functools import cache
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest

from native_host.strict_host3 import (KNOWN_DEVIATIONS, HostRun, Target, compile_host, deviation_of, find_cc,
                                      list_cases, run_host, unpack)
from support import swept_mechanisms

MECHANISMS = swept_mechanisms()   # support.BENCHMARK_MECHANISMS: tested in their own files
linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the host dlopens the x86_64-linux binary")
_HOST_DIR = tempfile.TemporaryDirectory(prefix="fmi3_strict_host_")    # removed at exit


@cache
def _host() -> Path | None:
    """The host, compiled once per session (None without a C compiler or off Linux)."""
    compiler = find_cc()
    if compiler is None or not sys.platform.startswith("linux"):
        return None
    return compile_host(Path(_HOST_DIR.name), compiler)


def _labels() -> tuple[str, ...]:
    host = _host()
    return list_cases(host) if host else ()


def _case_params():
    """(mechanism, label) for every case of the host, a known deviation marked as a strict xfail."""
    labels = _labels()
    if not labels:
        return [pytest.param(m, "", marks=pytest.mark.skip(reason="no C compiler, or not Linux"), id=m)
                for m in MECHANISMS]
    params = []
    for mechanism in MECHANISMS:
        for label in labels:
            deviation = deviation_of(label)
            marks = [pytest.mark.xfail(strict=True, reason=f"known deviation (strict_host3.KNOWN_DEVIATIONS): "
                                                           f"{deviation.name}")] if deviation else []
            params.append(pytest.param(mechanism, label, marks=marks, id=f"{mechanism}-{label}"))
    return params


@pytest.fixture(scope="module")
def host() -> Path:
    host = _host()
    if host is None:
        pytest.skip("no C compiler to build the strict FMI 3.0 host, or not Linux")
    return host


@pytest.fixture(scope="module")
def targets(mechanism_fmus, tmp_path_factory):
    """Each mechanism's unpacked FMI 3.0 FMU with its FMI 2.0 twin, on first use."""
    made: dict[str, Target] = {}

    def get(mechanism: str) -> Target:
        if mechanism not in made:
            made[mechanism] = unpack(mechanism_fmus.get(mechanism, "native3"), tmp_path_factory.mktemp(mechanism),
                                     mechanism_fmus.get(mechanism, "native"))
        return made[mechanism]
    return get


@pytest.fixture(scope="module")
def runs(host, targets):
    """The host's run on each mechanism, each case in a forked child (a crash is a failed case)."""
    done: dict[str, HostRun] = {}

    def get(mechanism: str) -> HostRun:
        if mechanism not in done:
            done[mechanism] = run_host(host, targets(mechanism))
        return done[mechanism]
    return get


# -- the harness's cases ----------------------------------------------------------------------
@linux_only
@pytest.mark.parametrize(("mechanism", "label"), _case_params())
def test_case(mechanism, label, runs):
    run = runs(mechanism)
    by_label = {case.label: case for case in run.cases}
    assert label in by_label, f"the host never reached this case (exit {run.returncode}): {run.stderr[-2000:]}"
    assert not by_label[label].failures, "\n".join(by_label[label].failures)


@linux_only
@pytest.mark.parametrize("mechanism", MECHANISMS)
def test_the_host_ran_every_case_with_every_check(mechanism, runs, host):
    """All cases ran (none lost to a crash of the host itself), the per-case heap check was on, the FMI
    2.0 twin was loaded, and the only failures are the known deviations."""
    run = runs(mechanism)
    labels = list_cases(host)
    assert [case.label for case in run.cases] == list(labels), run.stderr[-2000:]
    # 70 functions x 13 states, 70 with a NULL instance, 64 NULL arguments, get and set of 6 variable
    # kinds x 13 states, fmi3Reset and fmi3FreeInstance x 13 states, 17 sequences: fewer would mean
    # the list lost cases
    assert len(labels) >= 1243
    assert "against the FMI 2.0 twin" in run.summary, run.summary
    # the per-case heap check counts glibc's heap (tests/native_host/fmi3_strict_host.c: heap_in_use)
    assert run.heap_checked or platform.libc_ver()[0] != "glibc", run.summary
    unexpected = [f for case in run.cases if deviation_of(case.label) is None for f in case.failures]
    assert not unexpected, "\n".join(unexpected)
    assert run.returncode == (1 if any(case.failures for case in run.cases) else 0), run.stderr[-2000:]


def test_every_known_deviation_names_cases_of_the_host(host):
    """A deviation whose pattern matches no case would hide nothing and prove nothing: each must match."""
    labels = list_cases(host)
    for deviation in KNOWN_DEVIATIONS:
        assert any(deviation_of(label) is deviation for label in labels), deviation.pattern


# -- the harness fails on broken layers -----------------------------------------------------------
@pytest.fixture(scope="module")
def fourbar_build(targets, tmp_path_factory):
    """The four-bar's shipped sources (buildDescription.xml's list), compiled with -Werror, one object
    each, to link a mutant of one of them with the others' objects; and the library from all of them."""
    compiler = find_cc()
    target = targets("fourbar")
    src = target.root / "sources"
    root = ET.fromstring((src / "buildDescription.xml").read_bytes())
    files = [e.get("name") for e in root.iter("SourceFile")]
    assert "fmi3Functions.c" in files and len(files) >= 5, files
    out = tmp_path_factory.mktemp("fourbar_build")
    objects = {}
    for name in files:
        obj = out / f"{Path(name).stem}.o"
        subprocess.run([compiler, "-std=c99", "-O1", "-fPIC", "-fvisibility=hidden", "-Wall", "-Wextra", "-Werror",
                        "-I", str(src), "-c", str(src / name), "-o", str(obj)], check=True, capture_output=True,
                       text=True)
        objects[name] = obj

    def link(layer: Path, output: Path) -> Path:
        """The library from ``layer`` (a source named as one of the shipped ones) and the others' objects."""
        others = [str(obj) for name, obj in objects.items() if name != layer.name]
        subprocess.run([compiler, "-std=c99", "-O1", "-fPIC", "-shared", "-fvisibility=hidden", "-Wall", "-Wextra",
                        "-Werror", "-I", str(src), "-o", str(output), str(layer), *others, "-lm"],
                       check=True, capture_output=True, text=True)
        return output
    return target, src, link


@linux_only
def test_the_shipped_sources_build_with_werror_and_pass(host, fourbar_build, tmp_path):
    """What a host that builds the FMU from its sources/ gets passes the harness as the binary does."""
    target, src, link = fourbar_build
    library = link(src / "fmi3Functions.c", tmp_path / "FourBarNative3.so")
    run = run_host(host, dataclasses.replace(target, library=library))
    unexpected = [f for case in run.cases if deviation_of(case.label) is None for f in case.failures]
    assert not unexpected and len(run.cases) == len(list_cases(host)), "\n".join(unexpected) or run.stderr[-2000:]


# Each mutant breaks one rule in the FMI 3.0 layer (fmi3Functions.c, or the state table and checks it
# shares with the FMI 2.0 layer: fmi_layer.c); the host must say so in the case named.
MUTANTS = {
    "an FMU state never freed": (
        "fmi3Functions.c",
        "    free(p);   /* p == NULL: nothing to free */",
        "    (void)p;   /* not freed */",
        "fmi3GetFMUState in state stepMode", "taken from the heap during the case were not given back"),
    "information logged with loggingOn false": (
        "fmi3Functions.c",
        "    if (status == MODEL_OK && !m->logging_on) return;\n",
        "",
        "fmi3Terminate in state stepMode", "a message below fmi3Error with loggingOn false"),
    "messages without the instance name": (
        "fmi3Functions.c",
        'used = snprintf(text, sizeof text, "%s: ", m->instance_name ? m->instance_name : "");',
        "used = 0;",
        "fmi3DoStep in state instantiated", "does not start with the instance name"),
    "a NULL instance reaches the logger": (
        "fmi_layer.c",
        "    if (!m) return 0;\n    if (m->state.mode & states)",
        "    if (m->state.mode & states)",
        "fmi3DoStep with a NULL instance", "crashed"),
    "states settable in event mode": (
        "fmi_layer.c",
        "[CALL_SET_STATES]           = {{MODE_CONTINUOUS,            MODE_CONTINUOUS},",
        "[CALL_SET_STATES]           = {{MODE_CONTINUOUS,            MODE_EVENT | MODE_CONTINUOUS},",
        "fmi3SetContinuousStates in state eventMode", "returned fmi3OK, expected fmi3Error"),
    "values readable in the error state": (
        "fmi_layer.c",
        "#define FMI3_READABLE (MODE_INITIALIZATION | MODE_STEP_COMPLETE",
        "#define FMI3_READABLE (MODE_ERROR | MODE_INITIALIZATION | MODE_STEP_COMPLETE",
        "fmi3GetFloat64 in state error after a failed fmi3DoStep", "returned fmi3OK, expected fmi3Error"),
    "an event update that says the states changed": (
        "fmi3Functions.c",
        "*valuesOfContinuousStatesChanged = fmi3False;   /* a re-assembly keeps the states */",
        "*valuesOfContinuousStatesChanged = fmi3True;",
        "a model-exchange run with an event changing a parameter", "valuesOfContinuousStatesChanged 1"),
    "model-exchange time off by 1e-12 s (only the FMI 2.0 twin tells)": (
        "fmi_layer.c",
        "    model_me_set_time(m, time);",
        "    model_me_set_time(m, time + 1e-12);",
        "a model-exchange run with an event changing a parameter", "against the FMI 2.0 twin"),
    "no lastSuccessfulTime after a step": (
        "fmi3Functions.c",
        "    *lastSuccessfulTime = m->state.t;\n    return fmi3OK;",
        "    return fmi3OK;",
        "Case 2 in co-simulation", "lastSuccessfulTime 0 s"),
}


@linux_only
@pytest.mark.parametrize("mutant", sorted(MUTANTS))
def test_the_harness_catches_a_layer_that_breaks_a_rule(host, fourbar_build, mutant, tmp_path):
    name, before, after, case, says = MUTANTS[mutant]
    target, src, link = fourbar_build
    text = (src / name).read_text()
    assert text.count(before) == 1, f"the mutant's target text is no longer in {name}: {before!r}"
    layer = tmp_path / name
    layer.write_text(text.replace(before, after))
    run = run_host(host, dataclasses.replace(target, library=link(layer, tmp_path / "mutant.so")), only=case)
    assert run.returncode == 1, run.stdout[-2000:]
    assert any(says in f for f in run.failures), "\n".join(run.failures) or run.stdout[-2000:]


# -- valgrind -------------------------------------------------------------------------------------
@linux_only
@pytest.mark.skipif(shutil.which("valgrind") is None,
                    reason="valgrind is not installed (apt-get install valgrind); benchmarks/native_valgrind.py "
                           "runs the same check")
@pytest.mark.parametrize("mechanism", ["fourbar"])
def test_harness_under_valgrind_finds_no_invalid_access_or_leak(mechanism, host, targets):
    """Every case in one process under memcheck (benchmarks/native_valgrind.py --fmi 3 runs every mechanism)."""
    run = run_host(host, targets(mechanism), valgrind=shutil.which("valgrind"))
    report = run.valgrind
    unexpected = [f for case in run.cases if deviation_of(case.label) is None for f in case.failures]
    assert not unexpected and len(run.cases) == len(list_cases(host)), "\n".join(unexpected) or run.stderr[-3000:]
    assert report.errors == 0 and report.invalid_accesses == 0, run.stderr[-3000:]
    assert report.definitely_lost == 0, run.stderr[-3000:]


"""The native FMUs' FMI 2.0 C layer is as strict as the Reference-FMUs (issue 23, item 6).

- tests/native_host/fmi2_strict_host.c, compiled here against FMPy's FMI 2.0 headers, calls
  every exported fmi2* function (co-simulation's and model exchange's) with a NULL instance,
  with NULL arguments and in every state a co-simulation or a model-exchange instance can
  reach (the error state after a failed initialization, step or event update included), and
  checks each status, each message and every allocation; it runs a short model-exchange
  integration with an event too.  It must pass, and it must fail on layers that break a rule
  (six mutants of fmi2Functions.c or fmi_layer.c, compiled here).  It passes on other mechanisms' FMUs (the
  slider-crank's, and the driven four-bar's, whose only state is its driver's work) too.
- What an FMI host gets after a failed initialization, through FMPy: fmi2Error from every read.
- binaries/linux64 needs no glibc symbol version newer than 2.17 (read from the ELF file).
- Under valgrind (when installed): no invalid access, nothing definitely lost.
"""
from __future__ import annotations

import dataclasses
import platform
import re
import shutil
import struct
import subprocess
import sys
from pathlib import Path

import pytest

from native_host.strict_host import compile_host, find_cc, run_host, unpack
from support import logged_callbacks

REPO = Path(__file__).resolve().parents[1]
GLIBC_BASELINE = (2, 17)        # manylinux2014
linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the FMU's binary here is linux64")


@pytest.fixture(scope="module")
def host(tmp_path_factory) -> Path:
    compiler = find_cc()
    if compiler is None:
        pytest.skip("no C compiler to build the strict host")
    return compile_host(tmp_path_factory.mktemp("strict_host"), compiler)


@pytest.fixture(scope="module")
def target(native_fmu, tmp_path_factory):
    return unpack(native_fmu, tmp_path_factory.mktemp("native_unpacked"))


# -- the harness ---------------------------------------------------------------------------
@linux_only
def test_every_entry_point_is_null_safe_and_follows_the_state_machine(host, target):
    run = run_host(host, target)
    assert run.returncode == 0 and not run.failures, "\n".join(run.failures) or run.stderr[-2000:]
    # 40 functions x 13 states (6 of a co-simulation instance, 7 of a model-exchange one), 40 with
    # a NULL instance, 44 NULL arguments and 12 sequences (616 cases): fewer would mean the host
    # stopped early.
    assert run.cases is not None and run.cases >= 616, run.stdout[-2000:]


@linux_only
@pytest.mark.parametrize("mechanism", ["slider_crank", "fourbar_driven"])
def test_the_layer_is_as_strict_for_another_mechanism(host, tmp_path, mechanism, mechanism_fmus):
    """The FMI layer and the model behind it are the same C for every mechanism (only the
    generated sizes and tables differ): the harness passes on the slider-crank's FMU and on the
    driven four-bar's (no independent coordinate: one continuous state, the driver's work).
    The FMU: build/'s when it is newer than every source, else built once per session."""
    fmu = mechanism_fmus.get(mechanism, "native")
    target = unpack(fmu, tmp_path / "unpacked")
    run = run_host(host, target)
    assert run.returncode == 0 and not run.failures, "\n".join(run.failures) or run.stderr[-2000:]
    assert run.cases is not None and run.cases >= 616, run.stdout[-2000:]
    assert target.states == {"slider_crank": 2, "fourbar_driven": 1}[mechanism]


# Each mutant breaks one rule in the FMI 2.0 layer (fmi2Functions.c, or the state table and checks it
# shares with the FMI 3.0 layer: fmi_layer.c); the host must name the broken call.
MUTANTS = {
    "outputs readable in the error state": (
        "fmi_layer.c",
        "#define FMI2_READABLE (MODE_INITIALIZATION | FMI2_INITIALIZED)",
        "#define FMI2_READABLE (MODE_INITIALIZATION | FMI2_INITIALIZED | MODE_ERROR)",
        "FAIL fmi2GetReal in state error after a failed fmi2ExitInitializationMode: "
        "fmi2GetReal returned fmi2OK, expected fmi2Error"),
    "a NULL instance reaches the logger": (
        "fmi_layer.c",
        "    if (!m) return 0;\n    if (m->state.mode & states)",
        "    if (m->state.mode & states)",
        "FAIL fmi2CancelStep with a NULL instance: crashed"),
    "a status that is not what the log says": (
        "fmi2Functions.c",
        'model_log(m, MODEL_DISCARD, "logStatusDiscard", "%s(%s): no such status',
        'model_log(m, MODEL_ERROR, "logStatusError", "%s(%s): no such status',
        "FAIL fmi2GetStatus in state stepComplete: fmi2GetStatus returned fmi2Discard but logged fmi2Error"),
    "a co-simulation status answered by a model-exchange instance": (
        "fmi_layer.c",
        "[CALL_GET_STATUS]           = {{FMI2_STATUS,                0},                         CS},",
        "[CALL_GET_STATUS]           = {{FMI2_STATUS,                0},                         BOTH},",
        "FAIL fmi2GetRealStatus in state terminated (model exchange): fmi2GetRealStatus returned fmi2OK, "
        "expected fmi2Error"),
    "states settable in event mode": (
        "fmi_layer.c",
        "[CALL_SET_STATES]           = {{MODE_CONTINUOUS,            MODE_CONTINUOUS},",
        "[CALL_SET_STATES]           = {{MODE_EVENT | MODE_CONTINUOUS, MODE_CONTINUOUS},",
        "FAIL fmi2SetContinuousStates in state eventMode: fmi2SetContinuousStates returned fmi2OK, expected fmi2Error"),
    "an event update that says the states changed": (
        "fmi2Functions.c",
        "fmi2eventInfo->valuesOfContinuousStatesChanged = fmi2False;",
        "fmi2eventInfo->valuesOfContinuousStatesChanged = fmi2True;",
        "FAIL a healthy model-exchange run: Euler steps, saved and replayed, an event changing a parameter: "
        "fmi2NewDiscreteStates after initialization"),
}


def _compile_fmu_sources(unpacked: Path, output: Path, extra=()) -> None:
    """The FMU's shipped C sources compiled into ``output`` as build_fmu.py does (-O0: faster)."""
    src = unpacked / "sources"
    c_files = sorted(str(p) for p in src.glob("*.c"))
    subprocess.run([find_cc(), "-std=c99", "-O0", "-fPIC", "-shared", "-fvisibility=hidden", *extra,
                    "-I", str(src), "-o", str(output), *c_files, "-lm"], check=True, capture_output=True, text=True)


@linux_only
@pytest.mark.parametrize("mutant", sorted(MUTANTS))
def test_the_harness_catches_a_layer_that_breaks_a_rule(host, target, mutant, tmp_path):
    name, before, after, expected = MUTANTS[mutant]
    mutated = tmp_path / "unpacked"
    shutil.copytree(target.root / "sources", mutated / "sources")
    layer = mutated / "sources" / name
    text = layer.read_text()
    assert text.count(before) == 1, f"the mutant's target text is no longer in {name}: {before!r}"
    layer.write_text(text.replace(before, after))
    library = tmp_path / "mutant.so"
    _compile_fmu_sources(mutated, library)
    run = run_host(host, dataclasses.replace(target, library=library))
    assert run.returncode == 1, run.stdout[-2000:]
    assert any(line.startswith(expected) for line in run.failures), "\n".join(run.failures)


# -- what a host gets -----------------------------------------------------------------------
@linux_only
def test_after_a_failed_initialization_every_read_is_an_error(native_fmu, target):
    """docs/fmi_hosts.md: fmi2ExitInitializationMode -> fmi2Error, then the instance is in the
    error state: fmi2GetReal, fmi2DoStep and fmi2Terminate give fmi2Error with a message that
    says so; fmi2Reset makes it usable again."""
    from fmpy import read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave

    log: list[tuple[int, str]] = []
    callbacks = logged_callbacks(lambda status, text: log.append((status, text)))
    md = read_model_description(str(native_fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    slave = FMU2Slave(guid=md.guid, unzipDirectory=str(target.root), modelIdentifier="FourBarNative",
                      instanceName="failed")
    slave.instantiate(callbacks=callbacks)
    try:
        slave.setupExperiment(startTime=0.0, stopTime=1.0)
        slave.setReal([vr["L2"]], [-1.0])
        slave.enterInitializationMode()
        with pytest.raises(FMICallException) as failed:
            slave.exitInitializationMode()
        assert failed.value.status == 3 and any("L2 = -1.0 m" in m for _, m in log), log
        for call in (lambda: slave.getReal([vr["x2"]]), lambda: slave.doStep(0.0, 0.01), slave.terminate):
            log.clear()
            with pytest.raises(FMICallException) as refused:
                call()
            assert refused.value.status == 3                  # fmi2Error, never fmi2OK with made-up values
            assert log and log[-1][0] == 3 and "is not allowed in state error" in log[-1][1], log
        slave.reset()
        slave.setupExperiment(startTime=0.0, stopTime=1.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        slave.doStep(0.0, 0.01)
        assert slave.getReal([vr["x2"]])[0] != 0.0
    finally:
        slave.freeInstance()


# -- glibc ----------------------------------------------------------------------------------
def glibc_versions_needed(library: Path) -> set[str]:
    """The GLIBC_x.y versions an ELF64 little-endian shared object requires: its
    SHT_GNU_verneed entries, which the dynamic loader checks when it loads the library."""
    data = library.read_bytes()
    if data[:4] != b"\x7fELF" or data[4] != 2 or data[5] != 1:
        raise ValueError(f"{library}: not a 64-bit little-endian ELF file")
    shoff, = struct.unpack_from("<Q", data, 0x28)
    shentsize, shnum = struct.unpack_from("<HH", data, 0x3A)
    sections = [struct.unpack_from("<IIQQQQIIQQ", data, shoff + i * shentsize) for i in range(shnum)]
    names = set()
    for _, sh_type, _, _, offset, _, link, info, _, _ in sections:
        if sh_type != 0x6FFFFFFE:                       # SHT_GNU_verneed
            continue
        strings = sections[link][4]
        for _ in range(info):                           # Elf64_Verneed entries
            _, count, _, aux, next_entry = struct.unpack_from("<HHIII", data, offset)
            a = offset + aux
            for _ in range(count):                      # Elf64_Vernaux entries
                _, _, _, name, next_aux = struct.unpack_from("<IHHII", data, a)
                names.add(data[strings + name:data.index(b"\0", strings + name)].decode())
                a += next_aux
            offset += next_entry
    return {n for n in names if n.startswith("GLIBC_")}


def _version(name: str) -> tuple[int, ...]:
    return tuple(int(x) for x in name.removeprefix("GLIBC_").split("."))


@linux_only
def test_linux_binary_needs_no_glibc_newer_than_2_17(target):
    needed = glibc_versions_needed(target.library)
    assert needed, "no GLIBC version found: the ELF reader is broken"
    newer = sorted(n for n in needed if _version(n) > GLIBC_BASELINE)
    assert not newer, f"{target.library.name} needs {newer}: it will not load on glibc 2.17 (manylinux2014)"
    objdump = shutil.which("objdump")
    if objdump:   # binutils' reading of the same file agrees
        dump = subprocess.run([objdump, "-T", str(target.library)], capture_output=True, text=True, check=True)
        assert set(re.findall(r"\((GLIBC_[\d.]+)\)", dump.stdout)) == needed


@linux_only
def test_without_the_pinning_header_this_glibc_would_require_more(target, tmp_path):
    """The check above can fail: the same sources built without glibc_compat.h need pow@GLIBC_2.29
    on a glibc >= 2.29 (this machine's, when it is one)."""
    libc, version = platform.libc_ver()
    if libc != "glibc" or _version(version) < (2, 29):
        pytest.skip(f"this machine's C library ({libc} {version}) has no libm symbols newer than 2.17")
    unpinned, pinned = tmp_path / "unpinned.so", tmp_path / "pinned.so"
    _compile_fmu_sources(target.root, unpinned)
    _compile_fmu_sources(target.root, pinned, extra=("-include", str(target.root / "sources" / "glibc_compat.h")))
    assert max(map(_version, glibc_versions_needed(unpinned))) >= (2, 29)
    assert max(map(_version, glibc_versions_needed(pinned))) <= GLIBC_BASELINE


# -- valgrind ---------------------------------------------------------------------------------
@linux_only
@pytest.mark.skipif(shutil.which("valgrind") is None,
                    reason="valgrind is not installed (apt-get install valgrind); benchmarks/native_valgrind.py "
                           "runs the same check")
def test_harness_under_valgrind_finds_no_invalid_access_or_leak(host, target):
    run = run_host(host, target, valgrind=shutil.which("valgrind"))
    report = run.valgrind
    assert run.returncode == 0 and not run.failures, "\n".join(run.failures) or run.stderr[-3000:]
    assert report.errors == 0 and report.invalid_accesses == 0, run.stderr[-3000:]
    assert report.definitely_lost == 0, run.stderr[-3000:]


def test_valgrind_benchmark_without_valgrind_says_how_to_install_it(tmp_path):
    proc = subprocess.run([sys.executable, str(REPO / "benchmarks" / "native_valgrind.py")],
                          capture_output=True, text=True, timeout=60, env={"PATH": str(tmp_path)})
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "valgrind not found: apt-get install valgrind" in proc.stdout

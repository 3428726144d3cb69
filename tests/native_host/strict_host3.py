"""Build and run the strict FMI 3.0 host (``fmi3_strict_host.c`` beside this file) on a native FMU.

The FMI 3.0 twin of ``strict_host.py``: one home for what ``tests/test_fmu_fmi3_strict.py`` and
``benchmarks/native_valgrind.py`` both do.  The host is compiled once (``-Werror``) against FMPy's
FMI 2.0 and 3.0 headers; what it needs to know of an FMU (its variables and their kinds, its
continuous states, its instantiation token) comes from the FMU's modelDescription.xml, read here and
passed on the command line, so one compiled host serves every mechanism.  Optionally the FMU's FMI
2.0 twin (``<Name>Native.fmu``, the same model behind fmi2Functions.c) is loaded in the same process
for the bit-for-bit comparisons.
"""
from __future__ import annotations

import os
import re
import subprocess
import zipfile
from dataclasses import dataclass
from pathlib import Path

from native_host.strict_host import VALGRIND_OPTIONS, ValgrindReport, _valgrind_report, find_cc, fmi_header_dir

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "fmi3_strict_host.c"
#: The variables the host drives, by name: a tunable Float64 parameter that must be positive (-1
#: makes initialization, a step and an event update fail) and a Float64 output.
DRIVEN = ("L2", "x2")
#: The host's per-case heap check needs glibc's thread cache off (freed blocks stay counted there).
HEAP_CHECK_ENV = {"GLIBC_TUNABLES": "glibc.malloc.tcache_count=0"}
_KINDS = {("parameter", "tunable"): "t", ("parameter", "fixed"): "f", ("output", None): "o",
          ("local", None): "l", ("independent", None): "i"}

__all__ = ["SOURCE", "DRIVEN", "KNOWN_DEVIATIONS", "Deviation", "DescriptionError", "HostBuildError", "Target",
           "Twin", "CaseResult", "HostRun", "compile_host", "list_cases", "unpack", "run_host", "deviation_of",
           "find_cc"]


@dataclass(frozen=True)
class Deviation:
    """A known way fmu_src/native/fmi3/fmi3Functions.c departs from the FMI 3.0 standard: the host's
    cases it fails (``pattern``, a regular expression matched at the start of the case's label), what
    the layer does and what the standard says.  Reported to the layer's owner; the test marks these
    cases as expected failures (strict: a fixed layer makes them pass, and this entry must go)."""

    name: str                    # short, for a test's xfail reason and the benchmark's summary
    pattern: str
    does: str
    standard: str


#: One home for them: tests/test_fmu_fmi3_strict.py and benchmarks/native_valgrind.py read it.
KNOWN_DEVIATIONS: tuple[Deviation, ...] = ()
# (four were found by this harness and fixed in fmi3Functions.c and model.c: getters refused in
# instantiated, fmi3EnterEventMode accepted in eventMode, directional derivatives refused in
# initializationMode, fmi3DoStep past a defined stop time)


def deviation_of(label: str) -> Deviation | None:
    """The known deviation a case's failure is, or None."""
    return next((d for d in KNOWN_DEVIATIONS if re.match(d.pattern, label)), None)


class HostBuildError(RuntimeError):
    """The host does not compile (with -Werror) here."""


class DescriptionError(ValueError):
    """The model description has something the host cannot drive (a variable type or causality)."""


@dataclass(frozen=True)
class Twin:
    """The FMI 2.0 twin's binary and GUID."""

    library: Path
    guid: str


@dataclass(frozen=True)
class Target:
    """An unpacked FMI 3.0 FMU's binary and what the host needs to know about it."""

    root: Path                   # where the FMU was unpacked (sources/ is there)
    library: Path
    token: str                   # instantiationToken
    variables: str               # "vr:kind[:start];..." (see fmi3_strict_host.c's usage)
    states: str                  # "state_vr:derivative_vr;..."
    tunable: int                 # value references of DRIVEN
    output: int
    n_states: int
    twin: Twin | None = None


@dataclass(frozen=True)
class CaseResult:
    """One case of the host: its label and its failed checks (none when it passed)."""

    label: str
    failures: tuple[str, ...]


@dataclass(frozen=True)
class HostRun:
    """One run of the host: its exit status, its cases, its summary, valgrind's report."""

    command: tuple[str, ...]
    returncode: int
    cases: tuple[CaseResult, ...]
    summary: str                 # the host's last line ("" when it did not get there)
    stdout: str
    stderr: str
    valgrind: ValgrindReport | None

    @property
    def failures(self) -> tuple[str, ...]:
        return tuple(f for case in self.cases for f in case.failures)

    @property
    def heap_checked(self) -> bool:
        return "heap check on" in self.summary


def compile_host(dest_dir: Path, compiler: str) -> Path:
    """Compile the host into ``dest_dir``; raises HostBuildError with the compiler's output."""
    exe = Path(dest_dir) / "fmi3_strict_host"
    command = [compiler, "-std=c99", "-O1", "-g", "-Wall", "-Wextra", "-Werror", "-I", str(fmi_header_dir()),
               "-o", str(exe), str(SOURCE), "-ldl", "-lm"]
    proc = subprocess.run(command, capture_output=True, text=True)
    if proc.returncode != 0:
        raise HostBuildError(f"compiling {SOURCE.name} failed ({' '.join(command)}):\n{proc.stderr.strip()}")
    return exe


def list_cases(exe: Path) -> tuple[str, ...]:
    """The labels of the host's cases, in order (they do not depend on the FMU)."""
    proc = subprocess.run([str(exe), "--list"], capture_output=True, text=True, check=True, timeout=60)
    return tuple(line[5:] for line in proc.stdout.splitlines() if line.startswith("case "))


def _spec(md) -> tuple[str, str]:
    items = []
    for v in md.modelVariables:
        if v.type == "String" and (v.causality, v.variability) == ("parameter", "fixed"):
            if ";" in (v.start or ""):
                raise DescriptionError(f"{v.name}: a start value with ';' cannot be passed to the host")
            items.append(f"{v.valueReference}:s:{v.start}")
            continue
        kind = _KINDS.get((v.causality, v.variability if v.causality == "parameter" else None))
        if v.type != "Float64" or kind is None:
            raise DescriptionError(f"{v.name}: a {v.type} {v.causality} ({v.variability}) variable; the host drives "
                                   f"Float64 parameters, outputs, locals and the independent variable, and one "
                                   f"fixed String parameter")
        items.append(f"{v.valueReference}:{kind}" + (f":{float(v.start)!r}" if kind in "tf" else ""))
    states = ";".join(f"{d.variable.derivative.valueReference}:{d.variable.valueReference}" for d in md.derivatives)
    return ";".join(items), states


def unpack(fmu: Path, dest_dir: Path, twin_fmu: Path | None = None) -> Target:
    """Unpack ``fmu`` (and ``twin_fmu``, its FMI 2.0 twin) into ``dest_dir``; raises KeyError when the FMU
    has no variable named as in DRIVEN, DescriptionError for a variable the host cannot drive."""
    from fmpy import read_model_description

    dest_dir = Path(dest_dir)
    root = dest_dir / "fmi3"
    with zipfile.ZipFile(fmu) as z:
        z.extractall(root)
    md = read_model_description(str(root / "modelDescription.xml"))
    if md.fmiVersion != "3.0" or md.coSimulation is None or md.modelExchange is None:
        raise DescriptionError(f"{fmu}: not an FMI 3.0 FMU with co-simulation and model exchange")
    by_name = {v.name: v.valueReference for v in md.modelVariables}
    variables, states = _spec(md)
    library = root / "binaries" / "x86_64-linux" / f"{md.coSimulation.modelIdentifier}.so"
    twin = None
    if twin_fmu is not None:
        twin_root = dest_dir / "fmi2"
        with zipfile.ZipFile(twin_fmu) as z:
            z.extractall(twin_root)
        md2 = read_model_description(str(twin_root / "modelDescription.xml"))
        twin = Twin(twin_root / "binaries" / "linux64" / f"{md2.coSimulation.modelIdentifier}.so", md2.guid)
    return Target(root=root, library=library, token=md.instantiationToken, variables=variables, states=states,
                  tunable=by_name[DRIVEN[0]], output=by_name[DRIVEN[1]], n_states=len(md.derivatives), twin=twin)


def _cases(stdout: str) -> tuple[CaseResult, ...]:
    """Each "case LABEL" line and the "FAIL LABEL: ..." lines after it (a forked case's, and its parent's
    "crashed" line)."""
    cases: list[tuple[str, list[str]]] = []
    for line in stdout.splitlines():
        if line.startswith("case "):
            cases.append((line[5:], []))
        elif line.startswith("FAIL ") and cases and line.startswith(f"FAIL {cases[-1][0]}: "):
            cases[-1][1].append(line)
        elif line.startswith("FAIL "):                  # setup or teardown
            cases.append((line[5:].split(":", 1)[0], [line]))
    return tuple(CaseResult(label, tuple(failures)) for label, failures in cases)


def run_host(exe: Path, target: Target, in_process: bool = False, valgrind: str | None = None,
             only: str | None = None, twin: bool = True, timeout: float = 600.0) -> HostRun:
    """Run the host on ``target``: each case in a forked child, or all in one process (``in_process``;
    always so under ``valgrind``, the path of a valgrind executable); ``only``: the cases whose label
    contains it; ``twin``: load the FMI 2.0 twin when the target has one."""
    command = [str(exe), *(["--in-process"] if in_process or valgrind else []), *(["--only", only] if only else []),
               str(target.library), target.token, target.variables, target.states, str(target.tunable),
               str(target.output)]
    if twin and target.twin is not None:
        command += [str(target.twin.library), target.twin.guid]
    if valgrind:
        command = [valgrind, *VALGRIND_OPTIONS, *command]
    env = {**os.environ, **({} if valgrind else HEAP_CHECK_ENV)}
    proc = subprocess.run(command, capture_output=True, text=True, timeout=timeout, env=env)
    summary = re.search(r"^fmi3_strict_host: \d+ cases.*$", proc.stdout, re.M)
    return HostRun(command=tuple(command), returncode=proc.returncode, cases=_cases(proc.stdout),
                   summary=summary.group(0) if summary else "", stdout=proc.stdout, stderr=proc.stderr,
                   valgrind=_valgrind_report(proc.stderr) if valgrind else None)

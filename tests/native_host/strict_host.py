"""Build and run the strict FMI 2.0 host (``fmi2_strict_host.c`` beside this file) on a native FMU.

One home for what ``tests/test_fmu_native_strict.py`` and ``benchmarks/native_valgrind.py``
both do: compile the host with the system C compiler against FMPy's FMI 2.0 headers, unpack
an FMU, and run the host on its binary, plain or under valgrind, into a typed result.
"""
from __future__ import annotations

import re
import shutil
import subprocess
import zipfile
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "fmi2_strict_host.c"
#: The variables the host drives, by name: a tunable Real parameter that must be positive
#: (-1 makes initialization and a step fail), a Real output, a fixed String parameter.
VARIABLES = ("L2", "x2", "integrator")
VALGRIND_OPTIONS = ("--leak-check=full", "--show-leak-kinds=definite,indirect",
                    "--errors-for-leak-kinds=definite,indirect", "--error-exitcode=99")


@dataclass(frozen=True)
class Target:
    """An unpacked FMU's binary and what the host needs to know about it."""

    root: Path                                # where the FMU was unpacked (sources/ is there)
    library: Path
    guid: str
    value_references: tuple[int, int, int]    # of VARIABLES, in that order
    states: int                               # continuous states: the <Derivatives> unknowns (model exchange)


@dataclass(frozen=True)
class ValgrindReport:
    """What memcheck said about one run."""

    errors: int                    # "ERROR SUMMARY: N errors"
    invalid_accesses: int          # "Invalid read/write/free" reports
    definitely_lost: int           # bytes
    heap_summary: str              # "total heap usage: ..." line


@dataclass(frozen=True)
class HostRun:
    """One run of the host: its exit status, its FAIL lines and case count, valgrind's report."""

    command: tuple[str, ...]
    returncode: int
    cases: int | None              # None when the host did not reach its summary line
    failures: tuple[str, ...]
    stdout: str
    stderr: str
    valgrind: ValgrindReport | None


def fmi_header_dir() -> Path:
    import fmpy

    return Path(fmpy.__file__).resolve().parent / "c-code"


def find_cc() -> str | None:
    return shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")


def compile_host(dest_dir: Path, compiler: str) -> Path:
    """Compile the host into ``dest_dir``; raises CalledProcessError with the compiler's output."""
    exe = Path(dest_dir) / "fmi2_strict_host"
    subprocess.run([compiler, "-std=c99", "-O1", "-g", "-Wall", "-Wextra", "-I", str(fmi_header_dir()),
                    "-o", str(exe), str(SOURCE), "-ldl"], check=True, capture_output=True, text=True)
    return exe


def unpack(fmu: Path, dest_dir: Path, variables: tuple[str, str, str] = VARIABLES) -> Target:
    """Unpack ``fmu`` into ``dest_dir``; its linux64 binary, GUID, the value references of
    ``variables`` (default VARIABLES; a component's: benchmarks/native_valgrind.py --component)
    and its number of continuous states."""
    from fmpy import read_model_description

    dest_dir = Path(dest_dir)
    with zipfile.ZipFile(fmu) as z:
        z.extractall(dest_dir)
    md = read_model_description(str(dest_dir / "modelDescription.xml"))
    by_name = {v.name: v.valueReference for v in md.modelVariables}
    library = dest_dir / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
    return Target(root=dest_dir, library=library, guid=md.guid,
                  value_references=tuple(by_name[name] for name in variables),  # type: ignore[arg-type]
                  states=len(md.derivatives))


def _valgrind_report(stderr: str) -> ValgrindReport:
    errors = re.search(r"ERROR SUMMARY: (\d+) errors", stderr)
    lost = re.search(r"definitely lost: ([\d,]+) bytes", stderr)
    heap = re.search(r"total heap usage: [^\n]*", stderr)
    return ValgrindReport(
        errors=int(errors.group(1)) if errors else -1,
        invalid_accesses=len(re.findall(r"Invalid (?:read|write|free)", stderr)),
        definitely_lost=int(lost.group(1).replace(",", "")) if lost else 0,
        heap_summary=heap.group(0) if heap else "")


def run_host(exe: Path, target: Target, in_process: bool = False, valgrind: str | None = None,
             timeout: float = 300.0) -> HostRun:
    """Run the host on ``target``: each case in a forked child, or all in one process
    (``in_process``; always so under ``valgrind``, the path of a valgrind executable)."""
    command = [str(exe), *(["--in-process"] if in_process or valgrind else []), str(target.library), target.guid,
               *(str(vr) for vr in target.value_references), str(target.states)]
    if valgrind:
        command = [valgrind, *VALGRIND_OPTIONS, *command]
    proc = subprocess.run(command, capture_output=True, text=True, timeout=timeout)
    summary = re.search(r"fmi2_strict_host: (\d+) cases", proc.stdout)
    return HostRun(command=tuple(command), returncode=proc.returncode,
                   cases=int(summary.group(1)) if summary else None,
                   failures=tuple(line for line in proc.stdout.splitlines() if line.startswith("FAIL ")),
                   stdout=proc.stdout, stderr=proc.stderr,
                   valgrind=_valgrind_report(proc.stderr) if valgrind else None)

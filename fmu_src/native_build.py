"""Build ``<Name>Native.fmu``: a mechanism's derivation compiled to C, an FMU that needs no Python.

Steps: derive and check the mechanism (``mechanism.check.prepare_mechanism``, as the pythonfmu
build does), print its equations, tables, variables and the Runge-Kutta tableaus as C
(``c_codegen``), put them next to the hand-written, mechanism-agnostic C (``fmu_src/native/``:
the FMI layer, the DAE algorithm, the Runge-Kutta driver, small linear algebra), write the
model description from the variable table the pythonfmu FMU also uses, compile a shared
library with the system's C compiler (C standard library and libm only), and zip the lot with
its sources (``sources/`` and ``<SourceFiles>``), so that a user on another platform can
compile it with ``fmpy compile``.  A mingw-w64 cross-compiler, when installed, adds
``binaries/win64``.

The model identifier is ``<Name>Native`` (``FourBarNative`` for fmu_src/mechanisms/fourbar.toml).
The GUID is a hash of everything that goes into the binary: rebuilding unchanged sources gives
the same FMU identity, any change (of the mechanism or of the C) gives a new one.
"""
from __future__ import annotations

import hashlib
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import uuid
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping
from xml.etree import ElementTree as ET

from fourbar_common import replace_atomically

from .build import unit_definitions
from .c_codegen import GENERATED_FILES, generate_c_sources
from .mechanism.check import prepare_mechanism
from .mechanism.derivation import MechanismEquations
from .mechanism.description import Mechanism
from .mechanism.drawing import drawing_of
from .mechanism.table import model_exchange_states, native_variable_table

__all__ = ["NativeBuildResult", "CompilerNotFound", "build_native_fmu", "find_compiler", "model_identifier",
           "native_sources", "MODEL_IDENTIFIER", "HAND_WRITTEN", "GENERATED"]

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
#: The four-bar's model identifier (the default mechanism's); any mechanism's is model_identifier().
MODEL_IDENTIFIER = "FourBarNative"
#: The hand-written C: FMI layer, the slave behind it, the DAE algorithm, the Runge-Kutta driver,
#: linear algebra, and the header that pins glibc symbol versions for binaries/linux64
#: (force-included there only).  None of it knows a mechanism.
HAND_WRITTEN = ("fmi2Functions.c", "model.c", "model.h", "dae.c", "dae.h", "linalg.h", "rk.c", "rk.h",
                "glibc_compat.h")
#: Force-included in the linux64 build: libm symbols bound to versions glibc 2.17 has.
GLIBC_COMPAT = "glibc_compat.h"
#: The generated C (``c_codegen``), per mechanism.
GENERATED = GENERATED_FILES
#: The standard FMI 2.0 headers (2-clause BSD), as FMPy ships them.
FMI_HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
_C_FLAGS = ("-std=c99", "-O3", "-fPIC", "-shared", "-fvisibility=hidden", "-Wall", "-Wextra")
#: Link-time optimisation, when the compiler can: the generated equations (equations.c) inline
#: into the run-time that calls them at every evaluation (dae.c).  Measured in-process, 100 s at
#: rtol = atol = 1e-10: 12-23 % less time per shipped mechanism (-O2 -> -O3: 5 % more), the
#: numbers bit-identical (C99 mode: no contraction, no reassociation).  A compiler that refuses
#: it builds without.
_LTO_FLAGS = ("-flto",)
_WIN64_COMPILER = "x86_64-w64-mingw32-gcc"
#: Copies of the generated C for editors (model.c includes equations.h), written by builds whose
#: FMU goes into the repository (build_fmu.py's): build/ is gitignored.
EDITOR_COPIES = REPO / "build" / "generated"


class CompilerNotFound(RuntimeError):
    """No C compiler on PATH (set CC, or install gcc/clang)."""


@dataclass(frozen=True)
class NativeBuildResult:
    """Where the native FMU went, its GUID, its binaries and what ``fmpy validate`` found."""

    path: Path
    guid: str
    platforms: tuple[str, ...]
    problems: tuple[str, ...]
    model_identifier: str = MODEL_IDENTIFIER


def find_compiler() -> str | None:
    """The C compiler to use: $CC, else cc, gcc or clang on PATH; None when there is none."""
    candidates = [os.environ["CC"]] if os.environ.get("CC") else ["cc", "gcc", "clang"]
    for name in candidates:
        found = shutil.which(name)
        if found:
            return found
    return None


def model_identifier(eqs: MechanismEquations) -> str:
    """``<Name>Native``: the native FMU's model identifier (and its library's name)."""
    return f"{eqs.mechanism.name}Native"


def _fmi_header_dir() -> Path:
    import fmpy

    return Path(fmpy.__file__).resolve().parent / "c-code"


def native_sources(eqs: MechanismEquations, guid: str, replace: Mapping[str, bytes] | None = None) -> dict[str, bytes]:
    """Every file of the FMU's ``sources/``: generated, hand-written and the FMI headers."""
    files = {name: text.encode() for name, text in generate_c_sources(eqs, guid, model_identifier(eqs)).items()}
    for name in HAND_WRITTEN:
        files[name] = (HERE / "native" / name).read_bytes()
    headers = _fmi_header_dir()
    for name in FMI_HEADERS:
        files[name] = (headers / name).read_bytes()
    files.update(replace or {})
    return files


def _guid(eqs: MechanismEquations, replace: Mapping[str, bytes] | None = None) -> str:
    """A stable GUID: a hash of the sources (with a placeholder GUID), the variable table and the
    drawing annotation."""
    digest = hashlib.sha256()
    for name, data in sorted(native_sources(eqs, "GUID", replace).items()):
        digest.update(name.encode() + b"\0" + data + b"\0")
    digest.update(repr(native_variable_table(eqs)).encode())
    digest.update(ET.tostring(drawing_of(eqs.mechanism).to_annotation()))
    return str(uuid.UUID(bytes=digest.digest()[:16], version=5))


def model_description(eqs: MechanismEquations, guid: str, source_files) -> bytes:
    """The native FMU's modelDescription.xml, from the mechanism's variable table, with the
    drawing annotation (``mechanism.drawing``) between DefaultExperiment and ModelVariables."""
    mech = eqs.mechanism
    identifier = model_identifier(eqs)
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": identifier, "guid": guid,
        "description": f"{mech.description}: Lagrange-multiplier DAE derived with sympy and printed as C, "
                       f"coordinate partitioning, DOP853/RK45 in C (co-simulation) or the host's solver (model "
                       f"exchange), parameters tunable for fault injection; needs no Python",
        "author": "fourbar-cosim developers", "license": "MIT", "version": "0.2.0",
        "generationTool": "fourbar-cosim build_fmu.py (sympy C printer)",
        "variableNamingConvention": "structured", "numberOfEventIndicators": "0"})
    cs = ET.SubElement(root, "CoSimulation", {
        "modelIdentifier": identifier, "needsExecutionTool": "false",
        "canHandleVariableCommunicationStepSize": "true", "canInterpolateInputs": "false",
        "maxOutputDerivativeOrder": "0", "canRunAsynchronuously": "false",
        "canBeInstantiatedOnlyOncePerProcess": "false", "canNotUseMemoryManagementFunctions": "false",
        "canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true",
        "providesDirectionalDerivative": "false"})
    me = ET.SubElement(root, "ModelExchange", {
        "modelIdentifier": identifier, "needsExecutionTool": "false", "completedIntegratorStepNotNeeded": "false",
        "canBeInstantiatedOnlyOncePerProcess": "false", "canNotUseMemoryManagementFunctions": "false",
        "canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true", "providesDirectionalDerivative": "false"})
    for element in (cs, me):
        files = ET.SubElement(element, "SourceFiles")
        for name in source_files:
            ET.SubElement(files, "File", {"name": name})
    root.append(unit_definitions())
    categories = ET.SubElement(root, "LogCategories")
    for name, text in (("logStatusWarning", "Messages with fmi2Warning status."),
                       ("logStatusDiscard", "Messages with fmi2Discard status."),
                       ("logStatusError", "Messages with fmi2Error status: failed steps, invalid parameters."),
                       ("logStatusFatal", "Messages with fmi2Fatal status."),
                       ("logAll", "Every message, including applied parameter changes.")):
        ET.SubElement(categories, "Category", {"name": name, "description": text})
    ET.SubElement(root, "DefaultExperiment", {"startTime": "0.0", "stopTime": "100.0", "stepSize": "0.01",
                                              "tolerance": "1e-09"})
    root.append(drawing_of(mech).to_annotation())
    variables = ET.SubElement(root, "ModelVariables")
    table = native_variable_table(eqs)
    index = {var.name: vr + 1 for vr, var in enumerate(table)}          # ScalarVariable indices (1-based)
    states = [name for name, _, _ in model_exchange_states(eqs)]
    outputs, initial = [], []
    for vr, var in enumerate(table):
        sv = ET.SubElement(variables, "ScalarVariable", {
            "name": var.name, "valueReference": str(vr), "description": var.description,
            "causality": var.causality, "variability": var.variability})
        attrs = {}
        if var.name.startswith("der(") and var.name[4:-1] in index:
            attrs["derivative"] = str(index[var.name[4:-1]])
        if var.start is not None:
            attrs["start"] = repr(float(var.start)) if var.type == "Real" else str(var.start)
        if var.unit:
            attrs["unit"] = var.unit
        if var.minimum is not None:
            attrs["min"] = repr(var.minimum)
        if var.maximum is not None:
            attrs["max"] = repr(var.maximum)
        if var.display_unit:
            attrs["displayUnit"] = var.display_unit
        ET.SubElement(sv, var.type, attrs)
        if var.causality == "output":
            outputs.append(vr + 1)
        if var.causality == "output" or var.name in states or var.name.startswith("der("):
            initial.append(vr + 1)
    structure = ET.SubElement(root, "ModelStructure")
    group = ET.SubElement(structure, "Outputs")
    for i in outputs:
        ET.SubElement(group, "Unknown", {"index": str(i)})
    # A coordinate's derivative is its rate, exactly; a rate's (and a driver's power) depends on every state.
    group = ET.SubElement(structure, "Derivatives")
    n_coordinates = len(eqs.mechanism.independent)
    for k, name in enumerate(states):
        attrs = {"index": str(index[f"der({name})"])}
        if k < n_coordinates:
            attrs.update(dependencies=str(index[states[n_coordinates + k]]), dependenciesKind="fixed")
        ET.SubElement(group, "Unknown", attrs)
    group = ET.SubElement(structure, "InitialUnknowns")
    for i in initial:
        ET.SubElement(group, "Unknown", {"index": str(i)})
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _compile(compiler: str, source_dir: Path, sources: list[str], output: Path, extra=()) -> None:
    def command(lto):
        return [compiler, *_C_FLAGS, *lto, *extra, "-I", str(source_dir), "-o", str(output),
                *[str(source_dir / s) for s in sources], "-lm"]
    proc = subprocess.run(command(_LTO_FLAGS), capture_output=True, text=True)
    if proc.returncode != 0:                                    # no link-time optimisation here
        proc = subprocess.run(command(()), capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"compiling the native FMU failed ({' '.join(command(()))}):\n{proc.stderr.strip()}")


def _platform() -> tuple[str, str]:
    """FMI 2.0 binary folder and library suffix of this machine."""
    if sys.platform.startswith("linux"):
        return "linux64", ".so"
    if sys.platform == "darwin":
        return "darwin64", ".dylib"
    if sys.platform == "win32":
        return "win64", ".dll"
    raise RuntimeError(f"no FMI 2.0 platform folder for {sys.platform}")


def _write_editor_copies(identifier: str, files: Mapping[str, bytes]) -> None:
    """The generated C in build/generated/<ModelIdentifier>/, so that an editor opening
    fmu_src/native/ with that folder on its include path resolves the includes.  Best effort: a
    folder that cannot be written is skipped (the FMU does not need the copies)."""
    folder = EDITOR_COPIES / identifier
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for name in GENERATED:
            path = folder / name
            if not path.exists() or path.read_bytes() != files[name]:
                replace_atomically(path, lambda tmp, data=files[name]: tmp.write_bytes(data))
    except OSError:
        pass


def build_native_fmu(dest: str | Path | None = None, mechanism: str | Path | Mechanism | None = "fourbar",
                     validate: bool = True, compiler: str | None = None,
                     replace: Mapping[str, bytes] | None = None) -> NativeBuildResult:
    """Generate, compile and package a mechanism's native FMU at ``dest``; validate it with FMPy.

    ``mechanism`` is a shipped name (fmu_src/mechanisms/NAME.toml), a path or a Mechanism
    (default: the four-bar); ``dest`` defaults to build/<Name>Native.fmu.  ``replace`` swaps
    source files by name (the benchmarks' floor FMU replaces ``model.c``).  Raises
    MechanismError for a description with a mistake, :class:`CompilerNotFound` when no C
    compiler can be found, RuntimeError when compiling fails, OSError when ``dest`` cannot be
    written (``dest`` is then as it was, and no temporary file is left).
    """
    compiler = compiler or find_compiler()
    if not compiler:
        if os.environ.get("CC"):
            raise CompilerNotFound(f"no C compiler found: CC={os.environ['CC']} names no executable file or "
                                   f"command on PATH; set CC to an installed C compiler, or unset it to use "
                                   f"cc, gcc or clang")
        raise CompilerNotFound("no C compiler found (set CC, or install gcc or clang)")
    eqs = prepare_mechanism(mechanism if mechanism is not None else "fourbar").equations
    identifier = model_identifier(eqs)
    dest = Path(dest if dest is not None else Path("build") / f"{identifier}.fmu").resolve()
    guid = _guid(eqs, replace)
    files = native_sources(eqs, guid, replace)
    if not replace and dest.is_relative_to(REPO):       # a build for the repository, not a test's
        _write_editor_copies(identifier, files)
    c_files = sorted(name for name in files if name.endswith(".c"))
    platforms = []
    with tempfile.TemporaryDirectory(prefix="fourbar_native_") as tmp:
        stage = Path(tmp)
        src = stage / "sources"
        src.mkdir()
        for name, data in files.items():
            (src / name).write_bytes(data)
        folder, suffix = _platform()
        library = stage / (identifier + suffix)
        pin_glibc = folder == "linux64" and platform.libc_ver()[0] == "glibc"
        _compile(compiler, src, c_files, library, extra=("-include", str(src / GLIBC_COMPAT)) if pin_glibc else ())
        binaries = [(f"binaries/{folder}/{identifier}{suffix}", library)]
        platforms.append(folder)
        cross = shutil.which(_WIN64_COMPILER)
        if cross and folder != "win64":
            dll = stage / (identifier + ".dll")
            _compile(cross, src, c_files, dll, extra=("-static-libgcc",))
            binaries.append((f"binaries/win64/{identifier}.dll", dll))
            platforms.append("win64")

        def write(tmp_dest: Path) -> None:
            with zipfile.ZipFile(tmp_dest, "w", zipfile.ZIP_DEFLATED) as z:
                z.writestr("modelDescription.xml", model_description(eqs, guid, c_files))
                for arcname, path in binaries:
                    z.write(path, arcname)
                for name in sorted(files):
                    z.writestr(f"sources/{name}", files[name])

        # A uniquely named temporary file beside dest, renamed over it when complete and
        # removed on any failure or interrupt: dest is the old FMU or the new one, never a
        # part of either, and nothing is left beside it.
        replace_atomically(dest, write)
    problems: tuple[str, ...] = ()
    if validate:
        from fmpy.validation import validate_fmu
        problems = tuple(validate_fmu(str(dest)))
    return NativeBuildResult(path=dest, guid=guid, platforms=tuple(platforms), problems=problems,
                             model_identifier=identifier)

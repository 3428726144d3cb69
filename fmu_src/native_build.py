"""Build ``FourBarNative.fmu``: the same derivation compiled to C, an FMU that needs no Python.

Steps: print the equations, tableaus and variable table as C (``c_codegen``), put them next
to the hand-written FMI layer and Runge-Kutta driver (``fmu_src/native/``), write the model
description from the variable table the pythonfmu FMU also uses, compile a shared library
with the system's C compiler (C standard library and libm only), and zip the lot with its
sources (``sources/`` and ``<SourceFiles>``), so that a user on another platform can compile
it with ``fmpy compile``.  A mingw-w64 cross-compiler, when installed, adds ``binaries/win64``.

The GUID is a hash of everything that goes into the binary: rebuilding unchanged sources
gives the same FMU identity, any change gives a new one.
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
from .c_codegen import generate_c_sources
from .codegen import write_if_changed
from .fourbar_model.variables import VARIABLES

__all__ = ["NativeBuildResult", "CompilerNotFound", "build_native_fmu", "find_compiler", "MODEL_IDENTIFIER"]

HERE = Path(__file__).resolve().parent
MODEL_IDENTIFIER = "FourBarNative"
#: The hand-written C: FMI layer, model behind it, Runge-Kutta driver, and the header that
#: pins glibc symbol versions for binaries/linux64 (force-included there only).
HAND_WRITTEN = ("fmi2Functions.c", "model.c", "model.h", "rk.c", "rk.h", "glibc_compat.h")
#: Force-included in the linux64 build: libm symbols bound to versions glibc 2.17 has.
GLIBC_COMPAT = "glibc_compat.h"
#: The generated C (``c_codegen``); also written to fmu_src/native/ (gitignored).
GENERATED = ("fourbar_equations.c", "fourbar_equations.h", "rk_tableaus.c", "fourbar_variables.h")
#: The standard FMI 2.0 headers (2-clause BSD), as FMPy ships them.
FMI_HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
_C_FLAGS = ("-std=c99", "-O2", "-fPIC", "-shared", "-fvisibility=hidden", "-Wall", "-Wextra")
_WIN64_COMPILER = "x86_64-w64-mingw32-gcc"


class CompilerNotFound(RuntimeError):
    """No C compiler on PATH (set CC, or install gcc/clang)."""


@dataclass(frozen=True)
class NativeBuildResult:
    """Where the native FMU went, its GUID, its binaries and what ``fmpy validate`` found."""

    path: Path
    guid: str
    platforms: tuple[str, ...]
    problems: tuple[str, ...]


def find_compiler() -> str | None:
    """The C compiler to use: $CC, else cc, gcc or clang on PATH; None when there is none."""
    candidates = [os.environ["CC"]] if os.environ.get("CC") else ["cc", "gcc", "clang"]
    for name in candidates:
        found = shutil.which(name)
        if found:
            return found
    return None


def _fmi_header_dir() -> Path:
    import fmpy

    return Path(fmpy.__file__).resolve().parent / "c-code"


def _sources(guid: str, replace: Mapping[str, bytes] | None = None) -> dict[str, bytes]:
    """Every file of ``sources/``: generated, hand-written and the FMI headers."""
    files = {name: text.encode() for name, text in generate_c_sources(guid, MODEL_IDENTIFIER).items()}
    for name in HAND_WRITTEN:
        files[name] = (HERE / "native" / name).read_bytes()
    headers = _fmi_header_dir()
    for name in FMI_HEADERS:
        files[name] = (headers / name).read_bytes()
    files.update(replace or {})
    return files


def _guid(replace: Mapping[str, bytes] | None = None) -> str:
    """A stable GUID: a hash of the sources (with a placeholder GUID) and the variable table."""
    digest = hashlib.sha256()
    for name, data in sorted(_sources("GUID", replace).items()):
        digest.update(name.encode() + b"\0" + data + b"\0")
    digest.update(repr(VARIABLES).encode())
    return str(uuid.UUID(bytes=digest.digest()[:16], version=5))


def model_description(guid: str, source_files) -> bytes:
    """The native FMU's modelDescription.xml, from the shared variable table."""
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": MODEL_IDENTIFIER, "guid": guid,
        "description": "Planar four-bar linkage (Table 1 of Park's integrated engineering education model): "
                       "Lagrange-multiplier DAE derived with sympy and printed as C, DOP853/RK45 in C, "
                       "lengths and masses tunable for fault injection; needs no Python",
        "author": "fourbar-cosim developers", "license": "MIT", "version": "0.1.0",
        "generationTool": "fourbar-cosim build_fmu.py (sympy C printer)",
        "variableNamingConvention": "structured", "numberOfEventIndicators": "0"})
    cs = ET.SubElement(root, "CoSimulation", {
        "modelIdentifier": MODEL_IDENTIFIER, "needsExecutionTool": "false",
        "canHandleVariableCommunicationStepSize": "true", "canInterpolateInputs": "false",
        "maxOutputDerivativeOrder": "0", "canRunAsynchronuously": "false",
        "canBeInstantiatedOnlyOncePerProcess": "false", "canNotUseMemoryManagementFunctions": "false",
        "canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true",
        "providesDirectionalDerivative": "false"})
    files = ET.SubElement(cs, "SourceFiles")
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
    variables = ET.SubElement(root, "ModelVariables")
    outputs = []
    for vr, var in enumerate(VARIABLES):
        sv = ET.SubElement(variables, "ScalarVariable", {
            "name": var.name, "valueReference": str(vr), "description": var.description,
            "causality": var.causality, "variability": var.variability})
        attrs = {}
        if var.start is not None:
            attrs["start"] = repr(float(var.start)) if var.type == "Real" else str(var.start)
        if var.unit:
            attrs["unit"] = var.unit
        if var.minimum is not None:
            attrs["min"] = repr(var.minimum)
        if var.display_unit:
            attrs["displayUnit"] = var.display_unit
        ET.SubElement(sv, var.type, attrs)
        if var.causality == "output":
            outputs.append(vr + 1)
    structure = ET.SubElement(root, "ModelStructure")
    for tag in ("Outputs", "InitialUnknowns"):
        group = ET.SubElement(structure, tag)
        for index in outputs:
            ET.SubElement(group, "Unknown", {"index": str(index)})
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _compile(compiler: str, source_dir: Path, sources: list[str], output: Path, extra=()) -> None:
    command = [compiler, *_C_FLAGS, *extra, "-I", str(source_dir), "-o", str(output),
               *[str(source_dir / s) for s in sources], "-lm"]
    proc = subprocess.run(command, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"compiling the native FMU failed ({' '.join(command)}):\n{proc.stderr.strip()}")


def _platform() -> tuple[str, str]:
    """FMI 2.0 binary folder and library suffix of this machine."""
    if sys.platform.startswith("linux"):
        return "linux64", ".so"
    if sys.platform == "darwin":
        return "darwin64", ".dylib"
    if sys.platform == "win32":
        return "win64", ".dll"
    raise RuntimeError(f"no FMI 2.0 platform folder for {sys.platform}")


def build_native_fmu(dest: str | Path = "build/FourBarNative.fmu", validate: bool = True,
                     compiler: str | None = None, replace: Mapping[str, bytes] | None = None) -> NativeBuildResult:
    """Generate, compile and package the native FMU at ``dest``; validate it with FMPy.

    ``replace`` swaps source files by name (the benchmarks' floor FMU replaces ``model.c``).
    Raises :class:`CompilerNotFound` when no C compiler can be found, RuntimeError when
    compiling fails, OSError when ``dest`` cannot be written (``dest`` is then as it was,
    and no temporary file is left).
    """
    compiler = compiler or find_compiler()
    if not compiler:
        if os.environ.get("CC"):
            raise CompilerNotFound(f"no C compiler found: CC={os.environ['CC']} names no executable file or "
                                   f"command on PATH; set CC to an installed C compiler, or unset it to use "
                                   f"cc, gcc or clang")
        raise CompilerNotFound("no C compiler found (set CC, or install gcc or clang)")
    dest = Path(dest).resolve()
    guid = _guid(replace)
    files = _sources(guid, replace)
    if not replace:
        # The generated C also goes beside the hand-written C (gitignored), so that editors
        # resolve model.c's #include "fourbar_equations.h".
        for name in GENERATED:
            write_if_changed(HERE / "native" / name, files[name].decode())
    c_files = sorted(name for name in files if name.endswith(".c"))
    platforms = []
    with tempfile.TemporaryDirectory(prefix="fourbar_native_") as tmp:
        stage = Path(tmp)
        src = stage / "sources"
        src.mkdir()
        for name, data in files.items():
            (src / name).write_bytes(data)
        folder, suffix = _platform()
        library = stage / (MODEL_IDENTIFIER + suffix)
        pin_glibc = folder == "linux64" and platform.libc_ver()[0] == "glibc"
        _compile(compiler, src, c_files, library, extra=("-include", str(src / GLIBC_COMPAT)) if pin_glibc else ())
        binaries = [(f"binaries/{folder}/{MODEL_IDENTIFIER}{suffix}", library)]
        platforms.append(folder)
        cross = shutil.which(_WIN64_COMPILER)
        if cross and folder != "win64":
            dll = stage / (MODEL_IDENTIFIER + ".dll")
            _compile(cross, src, c_files, dll, extra=("-static-libgcc",))
            binaries.append((f"binaries/win64/{MODEL_IDENTIFIER}.dll", dll))
            platforms.append("win64")

        def write(tmp_dest: Path) -> None:
            with zipfile.ZipFile(tmp_dest, "w", zipfile.ZIP_DEFLATED) as z:
                z.writestr("modelDescription.xml", model_description(guid, c_files))
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
    return NativeBuildResult(path=dest, guid=guid, platforms=tuple(platforms), problems=problems)

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
from typing import Callable, Mapping
from xml.etree import ElementTree as ET

from fourbar_common import replace_atomically
from fourbar_common.drawing import TOOL_NAME

from .build import unit_definitions
from .c_codegen import GENERATED_FILES, generate_c_sources
from .mechanism.check import prepare_mechanism
from .mechanism.derivation import MechanismEquations
from .mechanism.description import Mechanism
from .mechanism.drawing import drawing_of
from .mechanism.table import (derivative_dependencies, model_exchange_states, native_variable_table,
                              output_dependencies)

__all__ = ["NativeBuildResult", "CompilerNotFound", "build_native_fmu", "find_compiler", "model_identifier",
           "native_sources", "model_description", "fmi3_model_description", "build_description", "MODEL_IDENTIFIER",
           "HAND_WRITTEN", "HAND_WRITTEN_FMI3", "GENERATED", "FMI_VERSIONS", "fmi2_interfaces", "fmi2_variables",
           "fmi3_interfaces", "fmi3_variables", "build_description_of", "package_native_fmu"]

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
#: The four-bar's model identifier (the default mechanism's); any mechanism's is model_identifier().
MODEL_IDENTIFIER = "FourBarNative"
#: The hand-written C: FMI layer, what it shares with the FMI 3.0 layer (fmi_layer: the state table
#: and the calls' work; fmi_calls.h: the entry points both standards define alike), the slave behind
#: it, the DAE algorithm, the Runge-Kutta driver, linear algebra, and the header that pins glibc
#: symbol versions for binaries/linux64 (force-included there only).  None of it knows a mechanism.
HAND_WRITTEN = ("fmi2Functions.c", "fmi_calls.h", "fmi_layer.c", "fmi_layer.h", "model.c", "model.h", "model_types.h",
                "model_api.h", "model_checks.c", "saved_state.c", "state_check.c", "dae.c", "dae.h", "linalg.h", "rk.c",
                "rk.h", "glibc_compat.h")
#: The FMI 3.0 FMU's: the same model, behind the FMI 3.0 layer (fmu_src/native/fmi3/fmi3Functions.c: a
#: folder of its own, so that fmu_src/native/ holds exactly the FMI 2.0 FMU's hand-written C).
HAND_WRITTEN_FMI3 = tuple("fmi3/fmi3Functions.c" if name == "fmi2Functions.c" else name for name in HAND_WRITTEN)
#: Force-included in the linux64 build: libm symbols bound to versions glibc 2.17 has.
GLIBC_COMPAT = "glibc_compat.h"
#: The generated C (``c_codegen``), per mechanism.
GENERATED = GENERATED_FILES
#: The standard FMI 2.0 headers (2-clause BSD), as FMPy ships them.
FMI_HEADERS = ("fmi2Functions.h", "fmi2FunctionTypes.h", "fmi2TypesPlatform.h")
#: The standard FMI 3.0 headers (2-clause BSD), as FMPy ships them.
FMI3_HEADERS = ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")
#: The FMI versions a native FMU is built for (``build_native_fmu``'s ``fmi_version``).
FMI_VERSIONS = (2, 3)
_C_FLAGS = ("-std=c99", "-O3", "-fPIC", "-shared", "-fvisibility=hidden", "-Wall", "-Wextra")
#: Link-time optimisation, when the compiler can: the generated equations (equations.c) inline
#: into the run-time that calls them at every evaluation (dae.c).  Measured in-process, 100 s at
#: rtol = atol = 1e-10: 12-23 % less time per shipped mechanism (-O2 -> -O3: 5 % more), the
#: numbers bit-identical (C99 mode: no contraction, no reassociation).  A compiler that refuses
#: it builds without.
_LTO_FLAGS = ("-flto",)
_WIN64_COMPILER = "x86_64-w64-mingw32-gcc"
#: The binaries go into the FMU uncompressed (the FMI standard allows "store" beside "deflate"):
#: a host extracts them at every load (FMPy's simulate_fmu extracts binaries/ at every call),
#: and inflating them was most of the load.  Measured on the Watt six-bar's FMU with FMPy's
#: extract as simulate_fmu calls it: 5.5 -> 0.7 ms (the FMU 412 -> 624 kB).  The model
#: description and sources, which simulate_fmu does not extract, stay deflated.
BINARY_COMPRESSION = zipfile.ZIP_STORED
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
    fmi_version: int = 2


def find_compiler() -> str | None:
    """The C compiler to use: $CC, else cc, gcc or clang on PATH; None when there is none."""
    candidates = [os.environ["CC"]] if os.environ.get("CC") else ["cc", "gcc", "clang"]
    for name in candidates:
        found = shutil.which(name)
        if found:
            return found
    return None


@dataclass(frozen=True)
class _Flavour:
    """Everything that differs between the FMI 2.0 and the FMI 3.0 native FMU's build (the model
    and the rest of the C are the same): one of ``_FLAVOURS``, by FMI version."""

    version: int
    identifier_suffix: str                   # the model identifier's, after <Name>Native
    hand_written: tuple[str, ...]            # the hand-written C, under fmu_src/native/
    headers: tuple[str, ...]                 # the standard's headers, as FMPy ships them
    #: the binary folder by sys.platform's prefix ({machine}: "x86_64" or "aarch64"); "win32"'s is the
    #: cross-compiled DLL's
    platform_folders: Mapping[str, str]
    #: the model description: (equations, GUID or token, the .c files) -> modelDescription.xml
    describe: Callable[[MechanismEquations, str, list], bytes]
    braced_token: bool                       # the GUID written in braces (FMI 3.0's instantiation token)
    build_description: bool                  # sources/buildDescription.xml (FMI 3.0)
    editor_copies: bool                      # writes build/generated/ (one flavour does: the same files)


def _flavour(fmi_version: int) -> _Flavour:
    if fmi_version not in _FLAVOURS:
        raise ValueError(f"fmi_version = {fmi_version!r}: must be one of {', '.join(map(str, FMI_VERSIONS))}")
    return _FLAVOURS[fmi_version]


def model_identifier(eqs: MechanismEquations, fmi_version: int = 2) -> str:
    """``<Name>Native`` (FMI 2.0) or ``<Name>Native3`` (FMI 3.0): the native FMU's model identifier,
    its library's name and its file's (``build/<identifier>.fmu``)."""
    return f"{eqs.mechanism.name}Native" + _flavour(fmi_version).identifier_suffix


def _fmi_header_dir() -> Path:
    import fmpy

    return Path(fmpy.__file__).resolve().parent / "c-code"


def native_sources(eqs: MechanismEquations, guid: str, replace: Mapping[str, bytes] | None = None,
                   fmi_version: int = 2) -> dict[str, bytes]:
    """Every file of the FMU's ``sources/``: generated, hand-written and the FMI headers (the
    FMI 2.0 layer and headers, or the FMI 3.0 ones, over the same model).  ``guid`` is what
    variables.h's FMU_GUID holds: the FMI 2.0 GUID or the FMI 3.0 instantiation token."""
    flavour = _flavour(fmi_version)
    files = {name: text.encode()
             for name, text in generate_c_sources(eqs, guid, model_identifier(eqs, fmi_version)).items()}
    for name in flavour.hand_written:
        files[Path(name).name] = (HERE / "native" / name).read_bytes()     # sources/ is flat
    headers = _fmi_header_dir()
    for name in flavour.headers:
        files[name] = (headers / name).read_bytes()
    files.update(replace or {})
    return files


def _guid(eqs: MechanismEquations, replace: Mapping[str, bytes] | None = None, fmi_version: int = 2) -> str:
    """A stable GUID: a hash of the sources (with a placeholder GUID), the variable table and the
    drawing annotation.  FMI 3.0's instantiation token is the GUID of its own sources, in braces
    (as the Reference-FMUs write theirs)."""
    digest = hashlib.sha256()
    for name, data in sorted(native_sources(eqs, "GUID", replace, fmi_version).items()):
        digest.update(name.encode() + b"\0" + data + b"\0")
    digest.update(repr(native_variable_table(eqs)).encode())
    digest.update(ET.tostring(drawing_of(eqs.mechanism).to_annotation()))
    guid = str(uuid.UUID(bytes=digest.digest()[:16], version=5))
    return "{" + guid + "}" if _flavour(fmi_version).braced_token else guid


@dataclass(frozen=True)
class _Structure:
    """What both model descriptions declare, by value reference: each output and each state's
    derivative with the states and inputs it depends on (``mechanism.table.output_dependencies``,
    ``derivative_dependencies``; ``constant``: a coordinate's derivative, exactly its rate) and
    the initial unknowns."""

    outputs: tuple[tuple[int, tuple[int, ...]], ...]
    derivatives: tuple[tuple[int, tuple[int, ...], bool], ...]
    initial: tuple[int, ...]
    state_of: dict[int, int]             # der(x)'s value reference -> x's


def _structure(eqs: MechanismEquations) -> _Structure:
    table = native_variable_table(eqs)
    vr = {var.name: k for k, var in enumerate(table)}
    states = [name for name, _, _ in model_exchange_states(eqs)]

    def knowns(dependencies) -> tuple[int, ...]:
        return tuple(sorted(vr[name] for name in dependencies.states + dependencies.inputs))

    outputs = tuple((vr[d.unknown], knowns(d)) for d in output_dependencies(eqs))
    derivatives = tuple((vr[d.unknown], knowns(d), d.constant) for d in derivative_dependencies(eqs))
    initial = tuple(k for k, var in enumerate(table)
                    if var.causality == "output" or var.name in states or var.name.startswith("der("))
    state_of = {vr[f"der({name})"]: vr[name] for name in states}
    return _Structure(outputs, derivatives, initial, state_of)


def _description_text(eqs: MechanismEquations) -> str:
    return (f"{eqs.mechanism.description}: Lagrange-multiplier DAE derived with sympy and printed as C, "
            f"coordinate partitioning, DOP853/RK45 in C (co-simulation) or the host's solver (model "
            f"exchange), parameters tunable for fault injection; needs no Python")


_HEADER_ATTRIBUTES = {"author": "fourbar-cosim developers", "license": "MIT", "version": "0.2.0",
                      "generationTool": "fourbar-cosim build_fmu.py (sympy C printer)",
                      "variableNamingConvention": "structured"}
_LOG_CATEGORIES = (("logStatusWarning", "Messages with {v}Warning status."),
                   ("logStatusDiscard", "Messages with {v}Discard status."),
                   ("logStatusError", "Messages with {v}Error status: failed steps, invalid parameters."),
                   ("logStatusFatal", "Messages with {v}Fatal status."),
                   ("logAll", "Every message, including applied parameter changes."))
_DEFAULT_EXPERIMENT = {"startTime": "0.0", "stopTime": "100.0", "stepSize": "0.01", "tolerance": "1e-09"}


def _log_categories(prefix: str) -> ET.Element:
    categories = ET.Element("LogCategories")
    for name, text in _LOG_CATEGORIES:
        ET.SubElement(categories, "Category", {"name": name, "description": text.format(v=prefix)})
    return categories


def _variable_attributes(var) -> dict[str, str]:
    """unit, min, max, displayUnit of a variable (both FMI versions write them alike)."""
    attrs = {}
    if var.unit:
        attrs["unit"] = var.unit
    if var.minimum is not None:
        attrs["min"] = repr(var.minimum)
    if var.maximum is not None:
        attrs["max"] = repr(var.maximum)
    if var.display_unit:
        attrs["displayUnit"] = var.display_unit
    return attrs


def model_description(eqs: MechanismEquations, guid: str, source_files, fmi_version: int = 2) -> bytes:
    """The native FMU's modelDescription.xml (FMI 2.0, or FMI 3.0: ``fmi3_model_description``),
    from the mechanism's variable table, with the drawing annotation (``mechanism.drawing``)."""
    return _flavour(fmi_version).describe(eqs, guid, source_files)


def fmi2_interfaces(root: ET.Element, identifier: str, source_files, *, has_inputs: bool,
                    completed_step_needed: bool) -> None:
    """FMI 2.0's <ModelExchange> and <CoSimulation> of a native FMU (a mechanism's or a
    component's), each with <SourceFiles>.  FMI 2.0 orders them ModelExchange, then CoSimulation
    (FMI Library, and the FMU Compliance Checker built on it, skip a ModelExchange that comes
    second: 'not an ME FMU')."""
    me = ET.SubElement(root, "ModelExchange", {
        "modelIdentifier": identifier, "needsExecutionTool": "false",
        "completedIntegratorStepNotNeeded": "false" if completed_step_needed else "true",
        "canBeInstantiatedOnlyOncePerProcess": "false", "canNotUseMemoryManagementFunctions": "false",
        "canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true", "providesDirectionalDerivative": "true"})
    cs = ET.SubElement(root, "CoSimulation", {
        "modelIdentifier": identifier, "needsExecutionTool": "false",
        "canHandleVariableCommunicationStepSize": "true",
        "canInterpolateInputs": "true" if has_inputs else "false",
        "maxOutputDerivativeOrder": "0", "canRunAsynchronuously": "false",
        "canBeInstantiatedOnlyOncePerProcess": "false", "canNotUseMemoryManagementFunctions": "false",
        "canGetAndSetFMUstate": "true", "canSerializeFMUstate": "true",
        "providesDirectionalDerivative": "false"})
    for element in (me, cs):
        files = ET.SubElement(element, "SourceFiles")
        for name in source_files:
            ET.SubElement(files, "File", {"name": name})


def fmi2_variables(variables: ET.Element, table, state_of: Mapping[int, int]) -> None:
    """FMI 2.0's <ScalarVariable>s of a variable table (value reference = row), ``derivative``
    naming the state's ScalarVariable index (1-based) for each row in ``state_of``."""
    for vr, var in enumerate(table):
        sv = ET.SubElement(variables, "ScalarVariable", {
            "name": var.name, "valueReference": str(vr), "description": var.description,
            "causality": var.causality, "variability": var.variability})
        attrs = {}
        if vr in state_of:
            attrs["derivative"] = str(state_of[vr] + 1)       # ScalarVariable indices (1-based)
        if var.start is not None:
            attrs["start"] = repr(float(var.start)) if var.type == "Real" else str(var.start)
        attrs.update(_variable_attributes(var))
        ET.SubElement(sv, var.type, attrs)


def fmi3_interfaces(root: ET.Element, identifier: str, *, completed_step_needed: bool) -> None:
    """FMI 3.0's <ModelExchange> and <CoSimulation> of a native FMU: directional derivatives in
    model exchange only."""
    common = {"modelIdentifier": identifier, "needsExecutionTool": "false",
              "canBeInstantiatedOnlyOncePerProcess": "false", "canGetAndSetFMUState": "true",
              "canSerializeFMUState": "true", "providesDirectionalDerivatives": "false",
              "providesAdjointDerivatives": "false", "providesPerElementDependencies": "false"}
    ET.SubElement(root, "ModelExchange", {**common, "providesDirectionalDerivatives": "true",
                                          "needsCompletedIntegratorStep": "true" if completed_step_needed else "false",
                                          "providesEvaluateDiscreteStates": "false"})
    ET.SubElement(root, "CoSimulation", {**common, "canHandleVariableCommunicationStepSize": "true",
                                         "maxOutputDerivativeOrder": "0", "providesIntermediateUpdate": "false",
                                         "mightReturnEarlyFromDoStep": "false",
                                         "canReturnEarlyAfterIntermediateUpdate": "false", "hasEventMode": "false",
                                         "providesEvaluateDiscreteStates": "false"})


def fmi3_variables(variables: ET.Element, table, state_of: Mapping[int, int]) -> None:
    """FMI 3.0's variables: the independent ``time`` (value reference len(table), as
    fmi3Functions.c reads it), then the table's as Float64 (Real) and String; ``derivative`` names
    the state's value reference."""
    ET.SubElement(variables, "Float64", {"name": "time", "valueReference": str(len(table)),
                                         "description": "Simulation time", "causality": "independent",
                                         "variability": "continuous", "unit": "s"})
    for vr, var in enumerate(table):
        attrs = {"name": var.name, "valueReference": str(vr), "description": var.description,
                 "causality": var.causality, "variability": var.variability}
        if var.type == "String":
            element = ET.SubElement(variables, "String", attrs)
            ET.SubElement(element, "Start", {"value": str(var.start)})
            continue
        if vr in state_of:
            attrs["derivative"] = str(state_of[vr])
        if var.start is not None:
            attrs["start"] = repr(float(var.start))
        attrs.update(_variable_attributes(var))
        ET.SubElement(variables, "Float64", attrs)


def _fmi2_model_description(eqs: MechanismEquations, guid: str, source_files) -> bytes:
    """FMI 2.0's, the drawing annotation between DefaultExperiment and ModelVariables."""
    mech = eqs.mechanism
    identifier = model_identifier(eqs)
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": identifier, "guid": guid, "description": _description_text(eqs),
        **_HEADER_ATTRIBUTES, "numberOfEventIndicators": "0"})
    fmi2_interfaces(root, identifier, source_files, has_inputs=bool(eqs.inputs), completed_step_needed=True)
    root.append(unit_definitions())
    root.append(_log_categories("fmi2"))
    ET.SubElement(root, "DefaultExperiment", _DEFAULT_EXPERIMENT)
    root.append(drawing_of(mech).to_annotation())
    variables = ET.SubElement(root, "ModelVariables")
    table = native_variable_table(eqs)
    structure = _structure(eqs)
    fmi2_variables(variables, table, structure.state_of)
    element = ET.SubElement(root, "ModelStructure")
    group = ET.SubElement(element, "Outputs")
    for vr, depends in structure.outputs:
        ET.SubElement(group, "Unknown", {"index": str(vr + 1), "dependencies": " ".join(str(d + 1) for d in depends)})
    group = ET.SubElement(element, "Derivatives")
    for der, depends, constant in structure.derivatives:
        attrs = {"index": str(der + 1), "dependencies": " ".join(str(d + 1) for d in depends)}
        if constant:
            attrs["dependenciesKind"] = "constant"
        ET.SubElement(group, "Unknown", attrs)
    group = ET.SubElement(element, "InitialUnknowns")
    for vr in structure.initial:
        ET.SubElement(group, "Unknown", {"index": str(vr + 1)})
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def fmi3_model_description(eqs: MechanismEquations, token: str) -> bytes:
    """The FMI 3.0 FMU's modelDescription.xml: the same variables with the same value references
    as Float64 (Real) and String (``integrator``), the independent variable ``time`` after them
    (value reference FMU_N_VARIABLES, as fmi3Functions.c reads it), ``derivative`` naming the
    state's value reference, ``<ModelStructure>`` by value reference, and the drawing as an FMI 3.0
    annotation (``<Annotations><Annotation type="fourbar-cosim">``, the same ``<Drawing>`` inside)."""
    mech = eqs.mechanism
    identifier = model_identifier(eqs, 3)
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "3.0", "modelName": identifier, "instantiationToken": token,
        "description": _description_text(eqs), **_HEADER_ATTRIBUTES})
    fmi3_interfaces(root, identifier, completed_step_needed=True)
    root.append(unit_definitions())
    root.append(_log_categories("fmi3"))
    ET.SubElement(root, "DefaultExperiment", _DEFAULT_EXPERIMENT)
    variables = ET.SubElement(root, "ModelVariables")
    table = native_variable_table(eqs)
    structure = _structure(eqs)
    fmi3_variables(variables, table, structure.state_of)
    element = ET.SubElement(root, "ModelStructure")
    for vr, depends in structure.outputs:
        ET.SubElement(element, "Output", {"valueReference": str(vr), "dependencies": " ".join(map(str, depends))})
    for der, depends, constant in structure.derivatives:
        attrs = {"valueReference": str(der), "dependencies": " ".join(map(str, depends))}
        if constant:
            attrs["dependenciesKind"] = "constant"
        ET.SubElement(element, "ContinuousStateDerivative", attrs)
    for vr in structure.initial:
        ET.SubElement(element, "InitialUnknown", {"valueReference": str(vr)})
    annotations = ET.SubElement(root, "Annotations")
    annotation = ET.SubElement(annotations, "Annotation", {"type": TOOL_NAME})
    tool = drawing_of(mech).to_annotation().find("Tool")        # FMI 2.0's <VendorAnnotations><Tool>
    annotation.extend(list(tool))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def build_description(eqs: MechanismEquations, source_files) -> bytes:
    """FMI 3.0's sources/buildDescription.xml: how ``fmpy compile`` (or any importer) builds the
    binary from sources/ (C99, the .c files; on linux the glibc pinning header is optional)."""
    return build_description_of(model_identifier(eqs, 3), source_files)


def build_description_of(identifier: str, source_files) -> bytes:
    """buildDescription.xml for the FMI 3.0 FMU ``identifier`` (a mechanism's or a component's)."""
    root = ET.Element("fmiBuildDescription", {"fmiVersion": "3.0"})
    config = ET.SubElement(root, "BuildConfiguration", {"modelIdentifier": identifier})
    files = ET.SubElement(config, "SourceFileSet", {"language": "C99"})
    for name in source_files:
        ET.SubElement(files, "SourceFile", {"name": name})
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


#: The shared library's suffix by sys.platform's prefix.
_LIBRARY_SUFFIXES = {"linux": ".so", "darwin": ".dylib", "win32": ".dll"}
_FLAVOURS = {
    2: _Flavour(version=2, identifier_suffix="", hand_written=HAND_WRITTEN, headers=FMI_HEADERS,
                platform_folders={"linux": "linux64", "darwin": "darwin64", "win32": "win64"},
                describe=_fmi2_model_description, braced_token=False, build_description=False,
                editor_copies=True),
    3: _Flavour(version=3, identifier_suffix="3", hand_written=HAND_WRITTEN_FMI3, headers=FMI3_HEADERS,
                platform_folders={"linux": "{machine}-linux", "darwin": "{machine}-darwin", "win32": "x86_64-windows"},
                describe=lambda eqs, token, source_files: fmi3_model_description(eqs, token),
                braced_token=True, build_description=True, editor_copies=False),
}


def _platform(fmi_version: int = 2) -> tuple[str, str]:
    """The binary folder (FMI 2.0's, or FMI 3.0's platform tuple) and library suffix of this machine."""
    machine = "aarch64" if platform.machine().lower() in ("arm64", "aarch64") else "x86_64"
    for prefix, folder in _flavour(fmi_version).platform_folders.items():
        if sys.platform.startswith(prefix):
            return folder.format(machine=machine), _LIBRARY_SUFFIXES[prefix]
    raise RuntimeError(f"no FMI {fmi_version}.0 platform folder for {sys.platform}")


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
                     replace: Mapping[str, bytes] | None = None, fmi_version: int = 2) -> NativeBuildResult:
    """Generate, compile and package a mechanism's native FMU at ``dest``; validate it with FMPy.

    ``mechanism`` is a shipped name (fmu_src/mechanisms/NAME.toml), a path or a Mechanism
    (default: the four-bar); ``dest`` defaults to build/<Name>Native.fmu, or for ``fmi_version``
    3 build/<Name>Native3.fmu (FMI 3.0: fmi3Functions.c over the same model; binaries in the
    platform-tuple folder, e.g. x86_64-linux; sources/buildDescription.xml).  ``replace`` swaps
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
    flavour = _flavour(fmi_version)
    eqs = prepare_mechanism(mechanism if mechanism is not None else "fourbar").equations
    identifier = model_identifier(eqs, fmi_version)
    dest = Path(dest if dest is not None else Path("build") / f"{identifier}.fmu").resolve()
    guid = _guid(eqs, replace, fmi_version)
    files = native_sources(eqs, guid, replace, fmi_version)
    if not replace and dest.is_relative_to(REPO) and flavour.editor_copies:   # for the repository, not a test
        _write_editor_copies(identifier, files)
    platforms = package_native_fmu(dest, identifier, files, fmi_version=fmi_version, compiler=compiler,
                                   describe=lambda c_files: model_description(eqs, guid, c_files, fmi_version))
    problems: tuple[str, ...] = ()
    if validate:
        from fmpy.validation import validate_fmu
        problems = tuple(validate_fmu(str(dest)))
    return NativeBuildResult(path=dest, guid=guid, platforms=tuple(platforms), problems=problems,
                             model_identifier=identifier, fmi_version=fmi_version)


def package_native_fmu(dest: Path, identifier: str, files: Mapping[str, bytes], *, fmi_version: int, compiler: str,
                       describe: Callable[[list[str]], bytes], cross_compile: bool = True) -> tuple[str, ...]:
    """Compile ``files`` (the FMU's flat sources/) and zip the FMU at ``dest`` (a mechanism's or a
    component's): modelDescription.xml from ``describe(c_files)``, the binary for this platform (and,
    with ``cross_compile`` and a MinGW-w64 compiler, for win64), sources/ (FMI 3.0: with
    buildDescription.xml).  Returns the platform folders.  dest is written atomically: a uniquely
    named temporary file beside it, renamed over it when complete and removed on any failure or
    interrupt, so dest is the old FMU or the new one, never a part of either."""
    flavour = _flavour(fmi_version)
    c_files = sorted(name for name in files if name.endswith(".c"))
    platforms = []
    with tempfile.TemporaryDirectory(prefix="fourbar_native_") as tmp:
        stage = Path(tmp)
        src = stage / "sources"
        src.mkdir()
        for name, data in files.items():
            (src / name).write_bytes(data)
        folder, suffix = _platform(fmi_version)
        library = stage / (identifier + suffix)
        pin_glibc = sys.platform.startswith("linux") and platform.libc_ver()[0] == "glibc"
        _compile(compiler, src, c_files, library, extra=("-include", str(src / GLIBC_COMPAT)) if pin_glibc else ())
        binaries = [(f"binaries/{folder}/{identifier}{suffix}", library)]
        platforms.append(folder)
        cross = shutil.which(_WIN64_COMPILER) if cross_compile else None
        windows = flavour.platform_folders["win32"]
        if cross and folder != windows:
            dll = stage / (identifier + ".dll")
            # -s: no symbol table (the exports stay): 563 -> 285 kB for the Watt six-bar
            _compile(cross, src, c_files, dll, extra=("-static-libgcc", "-s"))
            binaries.append((f"binaries/{windows}/{identifier}.dll", dll))
            platforms.append(windows)
        sources = dict(files)
        if flavour.build_description:
            sources["buildDescription.xml"] = build_description_of(identifier, c_files)
        description = describe(c_files)

        def write(tmp_dest: Path) -> None:
            with zipfile.ZipFile(tmp_dest, "w", zipfile.ZIP_DEFLATED) as z:
                z.writestr("modelDescription.xml", description)
                for arcname, path in binaries:     # stored: see BINARY_COMPRESSION
                    z.write(path, arcname, compress_type=BINARY_COMPRESSION)
                for name in sorted(sources):
                    z.writestr(f"sources/{name}", sources[name])

        replace_atomically(dest, write)
    return tuple(platforms)

"""Build a component's native FMUs (FMI 2.0 and 3.0, CS and ME) from its block file.

``<Name>Native.fmu`` (FMI 2.0) and ``<Name>Native3.fmu`` (FMI 3.0), each co-simulation and model
exchange, from a block file (docs/components.md).

The block is read and derived (``block.derivation``), printed as C (``block.c_code``) and put next
to the FMI layers and the Runge-Kutta driver the mechanisms' native FMUs use (fmu_src/native/:
the same files, unchanged) and the block model (fmu_src/native/block/: its model.h replaces the
mechanism's); compiled, zipped with its sources and validated as native_build does.  The model
description declares each output's and derivative's dependencies on the inputs and states
(<ModelStructure>, from the sympy expressions).
"""
from __future__ import annotations

import hashlib
import uuid
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree as ET

from .block.c_code import block_variable_table, generate_block_sources
from .block.derivation import BlockEquations, derive_block
from .block.units import BLOCK_UNITS
from .native_build import (FMI3_HEADERS, FMI_HEADERS, CompilerNotFound, _DEFAULT_EXPERIMENT, _fmi_header_dir,
                           _HEADER_ATTRIBUTES, _log_categories, find_compiler, fmi2_interfaces, fmi2_variables,
                           fmi3_interfaces, fmi3_variables, package_native_fmu)

__all__ = ["BlockBuildResult", "build_block_fmu", "block_identifier", "block_sources", "BLOCK_HAND_WRITTEN"]

HERE = Path(__file__).resolve().parent
#: The hand-written C of a block FMU: the shared FMI layers and integrator (fmu_src/native/) and the
#: block model (fmu_src/native/block/); FMI 3.0 swaps fmi2Functions.c for fmi3/fmi3Functions.c.
BLOCK_HAND_WRITTEN = ("fmi2Functions.c", "fmi_calls.h", "fmi_layer.c", "fmi_layer.h", "rk.c", "rk.h",
                      "glibc_compat.h", "model_types.h", "model_api.h", "model_checks.c", "saved_state.c",
                      "block/model.h", "block/block.c")


@dataclass(frozen=True)
class BlockBuildResult:
    """Where the FMU went, its GUID (FMI 3.0: instantiation token), binaries and fmpy validate's findings."""

    path: Path
    guid: str
    platforms: tuple[str, ...]
    problems: tuple[str, ...]
    model_identifier: str
    fmi_version: int


def block_identifier(eqs: BlockEquations, fmi_version: int = 2) -> str:
    """``<Name>Native`` (FMI 2.0) or ``<Name>Native3`` (FMI 3.0)."""
    return f"{eqs.block.name}Native" + ("3" if fmi_version == 3 else "")


def block_sources(eqs: BlockEquations, guid: str, fmi_version: int = 2) -> dict[str, bytes]:
    """Every file of the FMU's flat ``sources/``."""
    files = {name: text.encode() for name, text in
             generate_block_sources(eqs, guid, block_identifier(eqs, fmi_version)).items()}
    for name in BLOCK_HAND_WRITTEN:
        if fmi_version == 3 and name == "fmi2Functions.c":
            name = "fmi3/fmi3Functions.c"
        files[Path(name).name] = (HERE / "native" / name).read_bytes()
    headers = _fmi_header_dir()
    for name in (FMI3_HEADERS if fmi_version == 3 else FMI_HEADERS):
        files[name] = (headers / name).read_bytes()
    return files


def _guid(eqs: BlockEquations, fmi_version: int) -> str:
    digest = hashlib.sha256()
    for name, data in sorted(block_sources(eqs, "GUID", fmi_version).items()):
        digest.update(name.encode() + b"\0" + data + b"\0")
    digest.update(repr(block_variable_table(eqs)).encode())
    guid = str(uuid.UUID(bytes=digest.digest()[:16], version=5))
    return "{" + guid + "}" if fmi_version == 3 else guid


def _units(table) -> ET.Element:
    units = ET.Element("UnitDefinitions")
    for name in sorted({v.unit for v in table if v.unit} | {"s"}):     # "s": FMI 3.0's time
        unit = ET.SubElement(units, "Unit", {"name": name})
        base, displays = BLOCK_UNITS[name]
        ET.SubElement(unit, "BaseUnit", base)
        for dname, factor in displays:
            ET.SubElement(unit, "DisplayUnit", {"name": dname, "factor": repr(factor)})
    return units


@dataclass(frozen=True)
class _Structure:
    """By value reference: each output and derivative with the inputs and states it depends on."""

    outputs: tuple[tuple[int, tuple[int, ...]], ...]
    derivatives: tuple[tuple[int, tuple[int, ...]], ...]
    initial: tuple[int, ...]
    state_of: dict[int, int]


def _structure(eqs: BlockEquations) -> _Structure:
    table = block_variable_table(eqs)
    vr = {v.name: k for k, v in enumerate(table)}
    b = eqs.block
    outputs = tuple((vr[o.name], tuple(vr[n] for n in deps)) for o, deps in zip(b.outputs, eqs.output_dependencies))
    derivatives = tuple((vr[f"der({s.name})"], tuple(vr[n] for n in deps))
                        for s, deps in zip(b.states, eqs.derivative_dependencies))
    initial = tuple(k for k, v in enumerate(table) if v.causality in ("output", "local"))
    return _Structure(outputs, derivatives, initial, {vr[f"der({s.name})"]: vr[s.name] for s in b.states})


def _description(eqs: BlockEquations) -> str:
    return (f"{eqs.block.description}: block file {eqs.block.source.name} derived with sympy and printed as C; "
            f"Runge-Kutta in C (co-simulation) or the host's solver (model exchange); needs no Python")


def _fmi2_description(eqs: BlockEquations, guid: str, source_files) -> bytes:
    identifier = block_identifier(eqs)
    table = block_variable_table(eqs)
    has_inputs = bool(eqs.block.inputs)
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "2.0", "modelName": identifier, "guid": guid, "description": _description(eqs),
        **_HEADER_ATTRIBUTES, "numberOfEventIndicators": "0"})
    fmi2_interfaces(root, identifier, source_files, has_inputs=has_inputs, completed_step_needed=False)
    root.append(_units(table))
    root.append(_log_categories("fmi2"))
    ET.SubElement(root, "DefaultExperiment", {**_DEFAULT_EXPERIMENT, "stopTime": "1.0", "stepSize": "0.001"})
    variables = ET.SubElement(root, "ModelVariables")
    structure = _structure(eqs)
    fmi2_variables(variables, table, structure.state_of)
    element = ET.SubElement(root, "ModelStructure")
    for tag, rows in (("Outputs", structure.outputs), ("Derivatives", structure.derivatives)):
        if not rows:
            continue
        group = ET.SubElement(element, tag)
        for k, deps in rows:
            ET.SubElement(group, "Unknown", {"index": str(k + 1), "dependencies": " ".join(str(d + 1) for d in deps)})
    group = ET.SubElement(element, "InitialUnknowns")
    for k in structure.initial:
        ET.SubElement(group, "Unknown", {"index": str(k + 1)})
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _fmi3_description(eqs: BlockEquations, token: str) -> bytes:
    identifier = block_identifier(eqs, 3)
    table = block_variable_table(eqs)
    root = ET.Element("fmiModelDescription", {
        "fmiVersion": "3.0", "modelName": identifier, "instantiationToken": token,
        "description": _description(eqs), **_HEADER_ATTRIBUTES})
    fmi3_interfaces(root, identifier, completed_step_needed=False)
    root.append(_units(table))
    root.append(_log_categories("fmi3"))
    ET.SubElement(root, "DefaultExperiment", {**_DEFAULT_EXPERIMENT, "stopTime": "1.0", "stepSize": "0.001"})
    variables = ET.SubElement(root, "ModelVariables")
    structure = _structure(eqs)
    fmi3_variables(variables, table, structure.state_of)
    element = ET.SubElement(root, "ModelStructure")
    for tag, rows in (("Output", structure.outputs), ("ContinuousStateDerivative", structure.derivatives)):
        for k, deps in rows:
            attrs = {"valueReference": str(k)}
            if deps:
                attrs["dependencies"] = " ".join(str(d) for d in deps)
            else:
                attrs["dependencies"] = ""
            ET.SubElement(element, tag, attrs)
    for k in structure.initial:
        ET.SubElement(element, "InitialUnknown", {"valueReference": str(k)})
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def build_block_fmu(source: str | Path, out: Path | None = None, *, fmi_version: int = 2, validate: bool = True,
                    compiler: str | None = None) -> Path:
    """Build a component's native FMU at ``out`` (default build/<Name>Native.fmu, or
    build/<Name>Native3.fmu for FMI 3.0) from a shipped name (fmu_src/components/NAME.toml) or a
    block file's path; returns the FMU's path.  Raises BlockError for a mistake in the file,
    CompilerNotFound without a C compiler, RuntimeError when compiling fails or fmpy validate
    finds a problem, OSError when ``out`` cannot be written (nothing is written then)."""
    return build_block_fmu_result(source, out, fmi_version=fmi_version, validate=validate, compiler=compiler).path


def build_block_fmu_result(source: str | Path, out: Path | None = None, *, fmi_version: int = 2,
                           validate: bool = True, compiler: str | None = None) -> BlockBuildResult:
    """build_block_fmu, returning the :class:`BlockBuildResult` (GUID, platforms, problems)."""
    if fmi_version not in (2, 3):
        raise ValueError(f"fmi_version = {fmi_version!r}: must be 2 or 3")
    eqs = derive_block(source)
    compiler = compiler or find_compiler()
    if not compiler:
        raise CompilerNotFound("no C compiler found (set CC, or install gcc or clang)")
    identifier = block_identifier(eqs, fmi_version)
    dest = Path(out if out is not None else Path("build") / f"{identifier}.fmu").resolve()
    guid = _guid(eqs, fmi_version)
    files = block_sources(eqs, guid, fmi_version)
    dest.parent.mkdir(parents=True, exist_ok=True)

    def describe(c_files: list[str]) -> bytes:
        return _fmi3_description(eqs, guid) if fmi_version == 3 else _fmi2_description(eqs, guid, c_files)

    platforms = package_native_fmu(dest, identifier, files, fmi_version=fmi_version, compiler=compiler,
                                   describe=describe, cross_compile=False)
    problems: tuple[str, ...] = ()
    if validate:
        from fmpy.validation import validate_fmu
        problems = tuple(validate_fmu(str(dest)))
    return BlockBuildResult(dest, guid, platforms, problems, identifier, fmi_version)

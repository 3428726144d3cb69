"""Build ``FourBar.fmu``: derive, generate, package with pythonfmu, complete and validate.

pythonfmu writes no units and no ``<InitialUnknowns>`` (its issues #131/#193), so
``fmpy validate`` rejects its FMUs as they come.  ``build_fmu`` rewrites the model
description with unit definitions, units on every Real variable and the initial
unknowns FMI 2.0 requires (every output, whose ``initial`` defaults to calculated),
then validates the result with FMPy.

The GUID is a hash of the FMU's content (every file, the model description with its GUID
and generation time left out), as the native FMU's is a hash of its sources: rebuilding
unchanged sources gives the same GUID, so a run recorded before a rebuild still matches
its FMU; any change to the model, the slave or pythonfmu gives a new one.  (pythonfmu
writes a random ``uuid1``; its binary does not compare the GUID at fmi2Instantiate, so
rewriting it in the model description is all it takes.)
"""
from __future__ import annotations

import hashlib
import shutil
import subprocess
import sys
import tempfile
import uuid
import zipfile
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree as ET

from .codegen import write_module
from .fourbar_model.variables import BY_NAME, UNITS, VARIABLES

__all__ = ["BuildResult", "build_fmu", "content_guid", "RUNTIME_REQUIREMENTS"]

HERE = Path(__file__).resolve().parent
#: Run-time needs of the FMU's Python code (``pythonfmu deploy`` installs these).
RUNTIME_REQUIREMENTS = ("numpy>=1.26", "scipy>=1.11")

@dataclass(frozen=True)
class BuildResult:
    """Where the FMU went, its GUID and the problems ``fmpy validate`` found (empty = valid)."""

    path: Path
    guid: str
    problems: tuple[str, ...]


def unit_definitions() -> ET.Element:
    """``<UnitDefinitions>`` for every unit of the variable table."""
    units = ET.Element("UnitDefinitions")
    for name, (base, displays) in UNITS.items():
        unit = ET.SubElement(units, "Unit", {"name": name})
        ET.SubElement(unit, "BaseUnit", base)
        for dname, factor in displays:
            ET.SubElement(unit, "DisplayUnit", {"name": dname, "factor": repr(factor)})
    return units


def _complete_model_description(xml: bytes) -> bytes:
    """Add units and <InitialUnknowns> to pythonfmu's model description.

    Also checks that pythonfmu numbered the variables as the shared table does
    (``fourbar_model/variables.py``): the native FMU relies on the same value references.
    """
    root = ET.fromstring(xml)
    # Unit definitions go right after the <CoSimulation> element (schema order).
    position = list(root).index(root.find("CoSimulation")) + 1
    root.insert(position, unit_definitions())

    variables = root.find("ModelVariables")
    outputs = []
    written = [(sv.get("name"), int(sv.get("valueReference"))) for sv in variables.findall("ScalarVariable")]
    expected = [(v.name, vr) for vr, v in enumerate(VARIABLES)]
    if written != expected:
        raise RuntimeError(f"pythonfmu numbered the variables {written}, the shared table expects {expected}")
    for index, sv in enumerate(variables.findall("ScalarVariable"), start=1):
        var = BY_NAME[sv.get("name")]
        real = sv.find("Real")
        if real is not None and var.minimum is not None:
            real.set("min", repr(var.minimum))
        if real is not None and var.unit:
            real.set("unit", var.unit)
            if var.display_unit:
                real.set("displayUnit", var.display_unit)
        if sv.get("causality") == "output":
            outputs.append(index)

    structure = root.find("ModelStructure")
    for old in structure.findall("InitialUnknowns"):
        structure.remove(old)
    if outputs:
        initial = ET.SubElement(structure, "InitialUnknowns")
        for index in outputs:
            ET.SubElement(initial, "Unknown", {"index": str(index)})
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _with_guid(xml: bytes, guid: str | None) -> bytes:
    """The model description with ``guid`` as its GUID; with None, the GUID and the generation
    time removed (what the GUID is computed from)."""
    root = ET.fromstring(xml)
    if guid is None:
        root.attrib.pop("guid", None)
        root.attrib.pop("generationDateAndTime", None)
    else:
        root.set("guid", guid)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def content_guid(files: dict[str, bytes]) -> str:
    """A GUID from an FMU's files (archive name -> bytes): SHA-256 over the sorted names and
    contents, the model description without its GUID and generation time."""
    digest = hashlib.sha256()
    for name in sorted(files):
        data = _with_guid(files[name], None) if name == "modelDescription.xml" else files[name]
        digest.update(name.encode() + b"\0" + data + b"\0")
    return str(uuid.UUID(bytes=digest.digest()[:16], version=5))


def _stage(stage: Path) -> Path:
    """Copy the slave and its run-time package into ``stage``, the equations generated first.

    The generated module is written in place, ``fmu_src/fourbar_model/equations.py``
    (gitignored), so that editors and readers can follow slave -> dae -> equations.
    """
    write_module(HERE / "fourbar_model" / "equations.py")
    shutil.copy2(HERE / "fourbar_slave.py", stage / "fourbar_slave.py")
    shutil.copytree(HERE / "fourbar_model", stage / "fourbar_model",
                    ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    (stage / "requirements.txt").write_text("\n".join(RUNTIME_REQUIREMENTS) + "\n")
    return stage / "fourbar_slave.py"


def build_fmu(dest: str | Path = "build/FourBar.fmu", validate: bool = True) -> BuildResult:
    """Derive the equations, build the FMU at ``dest`` and validate it.

    pythonfmu imports the slave script to write the model description; that import
    runs in a child process so that the caller's ``sys.modules`` never holds the
    staged modules (a later FMU load in this process would otherwise reuse them).
    """
    dest = Path(dest).resolve()
    dest.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="fourbar_stage_") as tmp:
        stage = Path(tmp)
        script = _stage(stage)
        raw = stage / "raw.fmu"
        code = ("import sys; from pythonfmu.builder import FmuBuilder; "
                "FmuBuilder.build_FMU(sys.argv[1], dest=sys.argv[2], "
                "project_files=[sys.argv[3], sys.argv[4]])")
        proc = subprocess.run(
            [sys.executable, "-c", code, str(script), str(raw),
             str(stage / "fourbar_model"), str(stage / "requirements.txt")],
            cwd=stage, capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"pythonfmu could not build the FMU:\n{proc.stderr.strip()}")
        with zipfile.ZipFile(raw) as zin:
            items = zin.infolist()
            files = {item.filename: zin.read(item.filename) for item in items}
        files["modelDescription.xml"] = _complete_model_description(files["modelDescription.xml"])
        guid = content_guid(files)
        files["modelDescription.xml"] = _with_guid(files["modelDescription.xml"], guid)
        tmp_dest = dest.with_name(f".{dest.name}.tmp")
        try:
            with zipfile.ZipFile(tmp_dest, "w", zipfile.ZIP_DEFLATED) as zout:
                for item in items:
                    zout.writestr(item, files[item.filename])
            tmp_dest.replace(dest)
        finally:
            tmp_dest.unlink(missing_ok=True)     # a failure or Ctrl-C leaves nothing behind
    problems: tuple[str, ...] = ()
    if validate:
        from fmpy.validation import validate_fmu
        problems = tuple(validate_fmu(str(dest)))
    return BuildResult(path=dest, guid=guid, problems=problems)

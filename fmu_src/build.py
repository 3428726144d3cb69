"""Build a mechanism's pythonfmu FMU (``FourBar.fmu`` by default): derive, generate, package
with pythonfmu, complete and validate.

The FMU ships a copy of the run-time package ``mechanism_model`` (numpy and scipy only),
named after the mechanism (``fourbar_model``: see ``runtime_package``), with the mechanism's
generated ``equations.py`` in it, and a short script defining the slave class named after the
mechanism (``FourBar``, ``SliderCrank``...).

pythonfmu writes no units and no ``<InitialUnknowns>`` (its issues #131/#193), so
``fmpy validate`` rejects its FMUs as they come.  ``build_fmu`` rewrites the model
description with unit definitions, units on every Real variable and the initial
unknowns FMI 2.0 requires (every output, whose ``initial`` defaults to calculated),
adds the drawing annotation (``<VendorAnnotations>``, ``mechanism.drawing``), then
validates the result with FMPy.

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

from .mechanism.check import CheckedMechanism, prepare_mechanism
from .mechanism.description import Mechanism
from fourbar_common.drawing import Drawing

from .mechanism.drawing import drawing_of, insert_vendor_annotations
from .mechanism.quoting import comment_text
from .mechanism.table import output_dependencies, variable_table
from .mechanism_model.variables import UNITS

__all__ = ["BuildResult", "build_fmu", "content_guid", "default_destination", "unit_definitions",
           "RUNTIME_REQUIREMENTS"]

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


def _complete_model_description(xml: bytes, table, drawing: Drawing,
                                dependencies: dict[str, tuple[str, ...]] | None = None) -> bytes:
    """Add units, ranges, the outputs' dependencies, <InitialUnknowns> and the drawing
    annotation (``mechanism.drawing``) to pythonfmu's model description.

    ``dependencies``: per output, the inputs it depends on directly (a co-simulation FMU has no
    continuous states to list: ``mechanism.table.output_dependencies``' inputs); an output left
    out keeps pythonfmu's entry, with no list (depending on every input).

    Also checks that pythonfmu numbered the variables as the mechanism's table does
    (``mechanism.table``): the native FMU relies on the same value references.
    """
    root = ET.fromstring(xml)
    # Unit definitions go right after the <CoSimulation> element (schema order).
    position = list(root).index(root.find("CoSimulation")) + 1
    root.insert(position, unit_definitions())
    insert_vendor_annotations(root, drawing)

    variables = root.find("ModelVariables")
    outputs = []
    written = [(sv.get("name"), int(sv.get("valueReference"))) for sv in variables.findall("ScalarVariable")]
    expected = [(v.name, vr) for vr, v in enumerate(table)]
    if written != expected:
        raise RuntimeError(f"pythonfmu numbered the variables {written}, the shared table expects {expected}")
    by_name = {v.name: v for v in table}
    for index, sv in enumerate(variables.findall("ScalarVariable"), start=1):
        var = by_name[sv.get("name")]
        real = sv.find("Real")
        if real is not None and var.minimum is not None:
            real.set("min", repr(var.minimum))
        if real is not None and var.maximum is not None:
            real.set("max", repr(var.maximum))
        if real is not None and var.unit:
            real.set("unit", var.unit)
            if var.display_unit:
                real.set("displayUnit", var.display_unit)
        if sv.get("causality") == "output":
            outputs.append(index)

    structure = root.find("ModelStructure")
    index_of = {v.name: vr + 1 for vr, v in enumerate(table)}
    for unknown in structure.findall("Outputs/Unknown"):
        name = table[int(unknown.get("index")) - 1].name
        if dependencies is not None and name in dependencies:
            unknown.set("dependencies", " ".join(str(index_of[n]) for n in dependencies[name]))
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


#: The run-time package's hand-written modules (the generated ``equations.py`` joins them).
RUNTIME_MODULES = ("__init__.py", "dae.py", "slave.py", "variables.py")


#: pythonfmu 0.7.0's binary, at every fmi2Instantiate, finds the slave class by running the
#: script again in its module's namespace and then releases a reference it does not own: the
#: module's globals dict (``Py_DECREF`` of the borrowed ``PyModule_GetDict``).  A script whose
#: globals few objects refer to (one class, no functions) loses them at the first instance, and
#: the next fmi2Instantiate in the process fails ("module has no attribute ...") or crashes.
#: The generated script keeps this many references to its own globals (one list, 0.8 MB), so a
#: process may instantiate the FMU that many times (tests/test_fmu_build.py instantiates it 200
#: times).  Where the old hand-written slave lived in the script, each of its methods held such
#: a reference, which hid the problem for a dozen instances.
PYTHONFMU_INSTANCES = 100_000


def runtime_package(mechanism: Mechanism) -> str:
    """The name the FMU gives its copy of ``mechanism_model`` (with the mechanism's equations):
    one per mechanism, ``fourbar_model`` for FourBar.  pythonfmu FMUs share one interpreter in a
    host process, so two mechanisms' FMUs loaded together must not share a package name, or the
    second would run the first one's equations."""
    return f"{mechanism.name.lower()}_model"


def _script(checked: CheckedMechanism) -> str:
    mech = checked.mechanism
    package = runtime_package(mech)
    return (f'"""{mech.name}: {comment_text(mech.description)}.\n\nThe pythonfmu script of the FMU, generated by '
            f'fmu_src/build.py from {comment_text(Path(mech.source).name)}; the slave is {package}.slave."""\n'
            f"from {package}.slave import MechanismSlave\n\n"
            f"# pythonfmu 0.7.0 releases one reference to this module's globals at every fmi2Instantiate\n"
            f"# (fmu_src/build.py, PYTHONFMU_INSTANCES): these keep them alive.\n"
            f"_PYTHONFMU_GLOBALS_REFERENCES = [globals()] * {PYTHONFMU_INSTANCES}\n\n\n"
            f"class {mech.name}(MechanismSlave):\n"
            f"    description = {mech.description!r}\n")


def _stage(stage: Path, checked: CheckedMechanism) -> Path:
    """Write the slave script and the run-time package, with the generated equations, into ``stage``."""
    package = stage / runtime_package(checked.mechanism)
    package.mkdir()
    for name in RUNTIME_MODULES:
        shutil.copy2(HERE / "mechanism_model" / name, package / name)
    (package / "equations.py").write_text(checked.source, encoding="utf-8", newline="\n")
    script = stage / f"{checked.mechanism.name.lower()}_slave.py"
    script.write_text(_script(checked), encoding="utf-8", newline="\n")
    (stage / "requirements.txt").write_text("\n".join(RUNTIME_REQUIREMENTS) + "\n")
    return script


def default_destination(mechanism: str | Path | Mechanism = "fourbar") -> Path:
    """build/<Name>.fmu for a mechanism."""
    return Path("build") / f"{prepare_mechanism(mechanism).mechanism.name}.fmu"


def build_fmu(dest: str | Path | None = None, validate: bool = True,
              mechanism: str | Path | Mechanism = "fourbar") -> BuildResult:
    """Derive the mechanism's equations, build its FMU at ``dest`` and validate it.

    ``mechanism`` is a shipped name (fmu_src/mechanisms/NAME.toml), a path or a Mechanism;
    ``dest`` defaults to build/<Name>.fmu.  Raises MechanismError for a description with a
    mistake.  pythonfmu imports the slave script to write the model description; that import
    runs in a child process so that the caller's ``sys.modules`` never holds the staged
    modules (a later FMU load in this process would otherwise reuse them).
    """
    checked = prepare_mechanism(mechanism)
    table = variable_table(checked.equations)
    dest = Path(dest if dest is not None else default_destination(mechanism)).resolve()
    dest.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="fourbar_stage_") as tmp:
        stage = Path(tmp)
        script = _stage(stage, checked)
        raw = stage / "raw.fmu"
        code = ("import sys; from pythonfmu.builder import FmuBuilder; "
                "FmuBuilder.build_FMU(sys.argv[1], dest=sys.argv[2], "
                "project_files=[sys.argv[3], sys.argv[4]])")
        proc = subprocess.run(
            [sys.executable, "-c", code, str(script), str(raw),
             str(stage / runtime_package(checked.mechanism)), str(stage / "requirements.txt")],
            cwd=stage, capture_output=True, text=True)
        if proc.returncode != 0:
            raise RuntimeError(f"pythonfmu could not build the FMU:\n{proc.stderr.strip()}")
        with zipfile.ZipFile(raw) as zin:
            items = zin.infolist()
            files = {item.filename: zin.read(item.filename) for item in items}
        inputs = {d.unknown: d.inputs for d in output_dependencies(checked.equations)}
        files["modelDescription.xml"] = _complete_model_description(files["modelDescription.xml"], table,
                                                                     drawing_of(checked.mechanism), inputs)
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

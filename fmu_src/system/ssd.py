"""The SSP 1.0 system structure description (SystemStructure.ssd) of a system, and its check.

Layout (docs/systems.md, *The SSP file*): one ``ssd:System`` named after the system, its
``ssd:Elements`` one ``ssd:Component`` per instance (type ``application/x-fmu-sharedlibrary``,
source ``resources/<Model>.fmu``) with its ``ssd:Connectors`` (every output, every connected
input and every bound parameter, each ``ssc:Real`` with its FMU unit) and, when the system file
binds values, one ``ssd:ParameterBinding`` holding an inline ``ssv:ParameterSet`` named
``initialValues`` (:data:`PARAMETER_SET`; the names in it relative to the component);
``ssd:Connections``; ``ssd:Units`` (each unit used, with its SI base-unit exponents from the
FMU); ``ssd:DefaultExperiment``.  An unconnected input with a bound value is
in the parameter set but not among the connectors: FMPy's ``simulate_ssp`` sets every input
connector before each step (0 when unconnected), which would undo the binding.

The bytes depend on the system and the FMUs' interfaces only (no date, no tool version), in the
file's order: the same system gives the same .ssd.
"""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from .description import SystemDescription
from .interface import FmuInterface

__all__ = ["SSD", "SSC", "SSV", "FMU_TYPE", "PARAMETER_SET", "ssd_bytes", "schema_problems", "resource_name"]

SSD = "http://ssp-standard.org/SSP1/SystemStructureDescription"
SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"
SSV = "http://ssp-standard.org/SSP1/SystemStructureParameterValues"
#: The component type SSP 1.0 gives an FMU.
FMU_TYPE = "application/x-fmu-sharedlibrary"
#: The name of every component's parameter set.  libcosim applies every inline set whatever its
#: name; Ecos applies the sets of the name given to ``EcosSimulation.init(parameter_set=...)``
#: (none without one), so one name for all of them makes one call apply them all.
PARAMETER_SET = "initialValues"
_SCHEMA = "SystemStructureDescription.xsd"


def resource_name(interface: FmuInterface) -> str:
    """Where a component's FMU goes in the .ssp: resources/<file name of the built FMU>."""
    return f"resources/{interface.path.name}"


def _number(value: float) -> str:
    return repr(float(value))    # shortest text that reads back to the same double


def ssd_bytes(system: SystemDescription, interfaces: dict[str, FmuInterface]) -> bytes:
    """SystemStructure.ssd of ``system`` whose components' FMUs have ``interfaces`` (checked
    beforehand by :func:`fmu_src.system.interface.check_system`)."""
    for prefix, uri in (("ssd", SSD), ("ssc", SSC), ("ssv", SSV)):
        ET.register_namespace(prefix, uri)
    root = ET.Element(f"{{{SSD}}}SystemStructureDescription", {"version": "1.0", "name": system.name})
    node = ET.SubElement(root, f"{{{SSD}}}System", {"name": system.name, "description": system.description})
    elements = ET.SubElement(node, f"{{{SSD}}}Elements")
    connected_inputs = {(c.target_component, c.target_variable) for c in system.connections}
    used_units: dict[str, object] = {}
    for spec in system.components:
        interface = interfaces[spec.name]
        component = ET.SubElement(elements, f"{{{SSD}}}Component",
                                  {"name": spec.name, "type": FMU_TYPE, "source": resource_name(interface)})
        bound = {name for name, _ in spec.parameters}
        connectors = ET.SubElement(component, f"{{{SSD}}}Connectors")
        for port in interface.ports:
            if port.type != "Real":
                continue
            if port.causality == "output" or (port.causality == "input" and (spec.name, port.name) in connected_inputs):
                kind = port.causality
            elif port.causality == "parameter" and port.name in bound:
                kind = "parameter"
            else:
                continue
            connector = ET.SubElement(connectors, f"{{{SSD}}}Connector", {"name": port.name, "kind": kind})
            ET.SubElement(connector, f"{{{SSC}}}Real", {"unit": port.unit} if port.unit else {})
            if port.unit:
                used_units.setdefault(port.unit, next((u for u in interface.units if u.name == port.unit), None))
        if spec.parameters:
            bindings = ET.SubElement(component, f"{{{SSD}}}ParameterBindings")
            binding = ET.SubElement(bindings, f"{{{SSD}}}ParameterBinding")
            values = ET.SubElement(binding, f"{{{SSD}}}ParameterValues")
            parameter_set = ET.SubElement(values, f"{{{SSV}}}ParameterSet", {"version": "1.0", "name": PARAMETER_SET})
            parameters = ET.SubElement(parameter_set, f"{{{SSV}}}Parameters")
            for name, value in spec.parameters:
                parameter = ET.SubElement(parameters, f"{{{SSV}}}Parameter", {"name": name})
                ET.SubElement(parameter, f"{{{SSV}}}Real", {"value": _number(value)})
    if system.connections:
        connections = ET.SubElement(node, f"{{{SSD}}}Connections")
        for c in system.connections:
            ET.SubElement(connections, f"{{{SSD}}}Connection",
                          {"startElement": c.source_component, "startConnector": c.source_variable,
                           "endElement": c.target_component, "endConnector": c.target_variable})
    if used_units:
        units = ET.SubElement(root, f"{{{SSD}}}Units")
        for name in sorted(used_units):
            definition = used_units[name]
            unit = ET.SubElement(units, f"{{{SSC}}}Unit", {"name": name})
            base = {} if definition is None else {key: str(exp) for key, exp in definition.exponents}
            if definition is not None and definition.factor != 1.0:
                base["factor"] = _number(definition.factor)
            if definition is not None and definition.offset != 0.0:
                base["offset"] = _number(definition.offset)
            ET.SubElement(unit, f"{{{SSC}}}BaseUnit", base)
    experiment = {"startTime": _number(system.experiment.start)}
    if system.experiment.stop is not None:
        experiment["stopTime"] = _number(system.experiment.stop)
    ET.SubElement(root, f"{{{SSD}}}DefaultExperiment", experiment)
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True) + b"\n"


def schema_problems(ssd: bytes) -> tuple[str, ...]:
    """What FMPy's shipped SSP 1.0 schema (fmpy/ssp/schema/SystemStructureDescription.xsd, with
    the common and parameter-value schemas it imports) finds wrong in ``ssd``: empty when valid."""
    from lxml import etree
    import fmpy.ssp

    schema = etree.XMLSchema(file=str(Path(fmpy.ssp.__file__).parent / "schema" / _SCHEMA))
    document = etree.fromstring(ssd)
    if schema.validate(document):
        return ()
    return tuple(f"line {e.line}: {e.message}" for e in schema.error_log)

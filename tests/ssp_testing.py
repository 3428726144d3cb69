"""A small test-only SSP 1.0 writer: an ``.ssp`` from FMUs, connectors, connections and bindings.

Only what tests/test_ssp_masters.py needs, until the project's system builder (issue 40, the
``build_fmu.py --system`` of fmu_src/) is merged: one flat system of FMI 2.0 co-simulation
components, Real connectors, plain connections and each component's parameter values bound
in one of SSP 1.0's two forms:

* ``"inline"``: ``ssd:ParameterBinding`` holding ``ssd:ParameterValues/ssv:ParameterSet``;
* ``"ssv"``: ``ssd:ParameterBinding source="resources/<component>.ssv"``, the set in its own
  file in the archive.

The archive is checked against FMPy's copy of the SSP 1.0 schema (SystemStructureDescription.xsd
and, for the ``.ssv`` files, SystemStructureParameterValues.xsd) before it is returned.
"""
from __future__ import annotations

import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import quoteattr

__all__ = ["TestComponent", "write_ssp"]

_NS = ('xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
       'xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
       'xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"')


@dataclass(frozen=True)
class TestComponent:
    """One component: instance ``name``, its FMU, its connectors and the parameter values bound."""
    __test__ = False                    # not a pytest test class

    name: str
    fmu: Path
    inputs: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()
    parameters: dict[str, float] = field(default_factory=dict)


def _parameter_set(name: str, values: dict[str, float], *, namespaces: bool) -> str:
    params = "".join(f'<ssv:Parameter name={quoteattr(k)}><ssv:Real value="{float(v)!r}"/></ssv:Parameter>'
                     for k, v in values.items())
    ns = f" {_NS}" if namespaces else ""
    return f'<ssv:ParameterSet{ns} version="1.0" name={quoteattr(name)}><ssv:Parameters>{params}</ssv:Parameters></ssv:ParameterSet>'


def write_ssp(path: Path, name: str, components: list[TestComponent],
              connections: list[tuple[str, str]], *, bindings: str = "inline",
              stop_time: float | None = None, set_name: str | None = "parameters",
              parameter_connectors: bool = False) -> Path:
    """Write ``path`` (an .ssp); ``connections`` are ("a.out", "b.in") pairs; ``bindings`` is
    "inline", "ssv" or "none" (no ParameterBindings at all, whatever the components hold).
    Every component's ssv:ParameterSet is named ``set_name`` (None: after its component), the
    one name Ecos is told to apply (fmu_src/ssp_masters.py).  ``parameter_connectors``: each
    bound parameter is also a connector of kind "parameter" (as the project's system builder
    writes them)."""
    if bindings not in ("inline", "ssv", "none"):
        raise ValueError(f"bindings: {bindings!r}")
    resources: dict[str, bytes] = {}
    elements = []
    for c in components:
        connectors = "".join(f'<ssd:Connector name={quoteattr(n)} kind="input"><ssc:Real/></ssd:Connector>'
                             for n in c.inputs)
        connectors += "".join(f'<ssd:Connector name={quoteattr(n)} kind="output"><ssc:Real/></ssd:Connector>'
                              for n in c.outputs)
        if parameter_connectors:
            connectors += "".join(f'<ssd:Connector name={quoteattr(n)} kind="parameter"><ssc:Real/></ssd:Connector>'
                                  for n in c.parameters)
        binding = ""
        if c.parameters and bindings == "inline":
            binding = ("<ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>"
                       + _parameter_set(set_name or c.name, c.parameters, namespaces=False)
                       + "</ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>")
        elif c.parameters and bindings == "ssv":
            ssv = f"resources/{c.name}.ssv"
            resources[ssv] = ('<?xml version="1.0" encoding="UTF-8"?>\n'
                              + _parameter_set(set_name or c.name, c.parameters, namespaces=True)).encode()
            binding = f'<ssd:ParameterBindings><ssd:ParameterBinding source="{ssv}"/></ssd:ParameterBindings>'
        source = f"resources/{c.name}.fmu"
        resources[source] = Path(c.fmu).read_bytes()
        elements.append(f'<ssd:Component name={quoteattr(c.name)} type="application/x-fmu-sharedlibrary" '
                        f'source="{source}"><ssd:Connectors>{connectors}</ssd:Connectors>{binding}</ssd:Component>')
    links = []
    for start, end in connections:
        (se, sc), (ee, ec) = start.split(".", 1), end.split(".", 1)
        links.append(f'<ssd:Connection startElement={quoteattr(se)} startConnector={quoteattr(sc)} '
                     f'endElement={quoteattr(ee)} endConnector={quoteattr(ec)}/>')
    experiment = f'<ssd:DefaultExperiment startTime="0.0" stopTime="{stop_time!r}"/>' if stop_time else ""
    ssd = ('<?xml version="1.0" encoding="UTF-8"?>\n'
           f'<ssd:SystemStructureDescription {_NS} version="1.0" name={quoteattr(name)}>'
           f'<ssd:System name={quoteattr(name)}><ssd:Elements>{"".join(elements)}</ssd:Elements>'
           + (f'<ssd:Connections>{"".join(links)}</ssd:Connections>' if links else "")
           + f'</ssd:System>{experiment}'
           '</ssd:SystemStructureDescription>\n')
    _validate(ssd.encode(), "SystemStructureDescription.xsd")
    for member, data in resources.items():
        if member.endswith(".ssv"):
            _validate(data, "SystemStructureParameterValues.xsd")
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("SystemStructure.ssd", ssd)
        for member, data in resources.items():
            z.writestr(member, data)
    return path


def _validate(xml: bytes, schema: str) -> None:
    """Checks ``xml`` against FMPy's copy of the SSP 1.0 schema ``schema``."""
    from lxml import etree

    import fmpy.ssp

    folder = Path(fmpy.ssp.__file__).parent / "schema"
    validator = etree.XMLSchema(etree.parse(str(folder / schema)))
    doc = etree.fromstring(xml)
    if not validator.validate(doc):
        raise AssertionError(f"not valid against SSP 1.0 {schema}: {validator.error_log}")

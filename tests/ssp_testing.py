"""The tests' SSP 1.0 writer: an ``.ssp`` from FMUs, connectors, connections and bindings.

For the tests of systems that need an SSD the project's system builder (fmu_src/system/, which
writes one layout only) does not write: test systems of test mechanisms (tests/test_ssp_masters.py,
tests/test_run_system.py), every form of binding, and broken or hostile archives
(tests/test_ssp_read.py).  One flat system of FMI co-simulation components
(``resources/<component>.fmu``), Real connectors, plain connections, and parameter values bound

* per component (``TestComponent.parameters``, names relative to the component), in one of
  SSP 1.0's two forms, ``bindings``: ``"inline"`` (``ssd:ParameterBinding`` holding
  ``ssd:ParameterValues/ssv:ParameterSet``) or ``"ssv"`` (``source="resources/<component>.ssv"``,
  the set in its own file), or ``"none"``;
* on the system itself (names ``component.variable``): ``system_parameters`` inline and/or
  ``system_ssv`` in ``resources/bound.ssv``.

:func:`write_ssp` checks what it generates against FMPy's copy of the SSP 1.0 schema
(SystemStructureDescription.xsd, SystemStructureParameterValues.xsd); an SSD given as text
(``ssd=``, e.g. :func:`ssd_text` with a hostile ``preamble``) and ``extra`` members are written
as they are.
"""
from __future__ import annotations

import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import quoteattr

__all__ = ["TestComponent", "ssd_text", "ssv_text", "write_ssp"]

_NS = ('xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
       'xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
       'xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"')
#: The archive member holding ``system_ssv``'s values.
SYSTEM_SSV = "resources/bound.ssv"


@dataclass(frozen=True)
class TestComponent:
    """One component: instance ``name``, its FMU (None: the caller writes the member), its
    connectors (inputs first, then outputs, in the SSD's order) and the parameter values bound."""
    __test__ = False                    # not a pytest test class

    name: str
    fmu: Path | None = None
    inputs: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()
    parameters: dict[str, float] = field(default_factory=dict)


def _parameter_set(name: str, values: dict[str, float], *, namespaces: bool) -> str:
    params = "".join(f'<ssv:Parameter name={quoteattr(k)}><ssv:Real value="{float(v)!r}"/></ssv:Parameter>'
                     for k, v in values.items())
    ns = f" {_NS}" if namespaces else ""
    return f'<ssv:ParameterSet{ns} version="1.0" name={quoteattr(name)}><ssv:Parameters>{params}</ssv:Parameters></ssv:ParameterSet>'


def ssv_text(values: dict[str, float], *, set_name: str = "bound") -> str:
    """An .ssv file: one ssv:ParameterSet named ``set_name`` holding ``values``."""
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + _parameter_set(set_name, values, namespaces=True)


def _inline(set_name: str, values: dict[str, float]) -> str:
    return ("<ssd:ParameterBinding><ssd:ParameterValues>" + _parameter_set(set_name, values, namespaces=False)
            + "</ssd:ParameterValues></ssd:ParameterBinding>")


def ssd_text(name: str, components: list[TestComponent], connections: list[tuple[str, str]], *,
             bindings: str = "inline", set_name: str | None = "parameters", parameter_connectors: bool = False,
             system_parameters: dict[str, float] | None = None, system_ssv_source: str | None = None,
             stop_time: float | None = None, preamble: str = "") -> str:
    """The SSD text.  ``connections`` are ("a.out", "b.in") pairs.  Every component's
    ssv:ParameterSet is named ``set_name`` (None: after its component), the one name Ecos is told
    to apply (fmu_src/ssp_masters.py); ``parameter_connectors``: each bound parameter is also a
    connector of kind "parameter" (as the project's system builder writes them).  System-level
    bindings: ``system_parameters`` inline (set "bound"), ``system_ssv_source`` an archive member.
    ``preamble`` goes right after the XML declaration (a DOCTYPE, for the hostile-input tests)."""
    if bindings not in ("inline", "ssv", "none"):
        raise ValueError(f"bindings: {bindings!r}")
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
            binding = f"<ssd:ParameterBindings>{_inline(set_name or c.name, c.parameters)}</ssd:ParameterBindings>"
        elif c.parameters and bindings == "ssv":
            binding = (f'<ssd:ParameterBindings><ssd:ParameterBinding source="resources/{c.name}.ssv"/>'
                       "</ssd:ParameterBindings>")
        elements.append(f'<ssd:Component name={quoteattr(c.name)} type="application/x-fmu-sharedlibrary" '
                        f'source="resources/{c.name}.fmu"><ssd:Connectors>{connectors}</ssd:Connectors>{binding}'
                        "</ssd:Component>")
    links = []
    for start, end in connections:
        (se, sc), (ee, ec) = start.split(".", 1), end.split(".", 1)
        links.append(f'<ssd:Connection startElement={quoteattr(se)} startConnector={quoteattr(sc)} '
                     f'endElement={quoteattr(ee)} endConnector={quoteattr(ec)}/>')
    system_bindings = ""
    if system_parameters or system_ssv_source:
        system_bindings = ("<ssd:ParameterBindings>"
                           + (_inline("bound", system_parameters) if system_parameters else "")
                           + (f'<ssd:ParameterBinding source="{system_ssv_source}"/>' if system_ssv_source else "")
                           + "</ssd:ParameterBindings>")
    experiment = f'<ssd:DefaultExperiment startTime="0.0" stopTime="{stop_time!r}"/>' if stop_time else ""
    return (f'<?xml version="1.0" encoding="UTF-8"?>{preamble}\n'
            f'<ssd:SystemStructureDescription {_NS} version="1.0" name={quoteattr(name)}>'
            f'<ssd:System name={quoteattr(name)}>{system_bindings}<ssd:Elements>{"".join(elements)}</ssd:Elements>'
            + (f'<ssd:Connections>{"".join(links)}</ssd:Connections>' if links else "")
            + f'</ssd:System>{experiment}'
            '</ssd:SystemStructureDescription>\n')


def write_ssp(path: Path, name: str, components: list[TestComponent], connections: list[tuple[str, str]], *,
              bindings: str = "inline", set_name: str | None = "parameters", parameter_connectors: bool = False,
              system_parameters: dict[str, float] | None = None, system_ssv: dict[str, float] | None = None,
              stop_time: float | None = None, ssd: str | None = None, extra: dict[str, bytes] | None = None) -> Path:
    """Write the archive ``path`` (module docstring; the options are :func:`ssd_text`'s, and
    ``system_ssv`` is written to resources/bound.ssv and bound on the system).  ``ssd`` replaces
    the generated SSD text (not checked against the schema); ``extra`` adds members as they are."""
    resources: dict[str, bytes] = {}
    for c in components:
        if c.parameters and bindings == "ssv":
            resources[f"resources/{c.name}.ssv"] = ssv_text(c.parameters, set_name=set_name or c.name).encode()
        if c.fmu is not None:
            resources[f"resources/{c.name}.fmu"] = Path(c.fmu).read_bytes()
    if system_ssv:
        resources[SYSTEM_SSV] = ssv_text(system_ssv).encode()
    if ssd is None:
        ssd = ssd_text(name, components, connections, bindings=bindings, set_name=set_name,
                       parameter_connectors=parameter_connectors, system_parameters=system_parameters,
                       system_ssv_source=SYSTEM_SSV if system_ssv else None, stop_time=stop_time)
        _validate(ssd.encode(), "SystemStructureDescription.xsd")
        for member, data in resources.items():
            if member.endswith(".ssv"):
                _validate(data, "SystemStructureParameterValues.xsd")
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("SystemStructure.ssd", ssd)
        for member, data in resources.items():
            z.writestr(member, data)
        for member, data in (extra or {}).items():
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

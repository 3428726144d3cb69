"""Writing small SSP 1.0 archives from existing FMUs, for the tests of systems (tests/test_run_system.py,
tests/test_ssp_read.py).

:func:`write_ssp` writes ``SystemStructure.ssd`` (valid against FMPy's shipped SSP 1.0 schema)
and ``resources/<component>.fmu`` for each component; ``extra`` adds members as they are
(e.g. a ``../evil`` name, or an .ssv file).
"""
from __future__ import annotations

import zipfile
from pathlib import Path
from xml.sax.saxutils import quoteattr

__all__ = ["write_ssp", "ssd_text"]

_NS = ('xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
       'xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
       'xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"')


def _parameter_set(values: dict[str, float]) -> str:
    rows = "".join(f'<ssv:Parameter name={quoteattr(n)}><ssv:Real value="{v!r}"/></ssv:Parameter>'
                   for n, v in values.items())
    return f'<ssv:ParameterSet version="1.0" name="bound"><ssv:Parameters>{rows}</ssv:Parameters></ssv:ParameterSet>'


def ssd_text(components: dict[str, dict[str, str]], connections: list[tuple[str, str]],
             parameters: dict[str, float] | None = None, ssv: str | None = None, name: str = "TestSystem",
             preamble: str = "") -> str:
    """The SSD: ``components`` maps a name to its connectors {variable: kind}; ``connections``
    are ("a.out", "b.in"); ``parameters`` ("comp.var" = value) are bound inline, ``ssv`` names an
    .ssv member bound as well."""
    elements = []
    for comp, connectors in components.items():
        rows = "".join(f'<ssd:Connector name={quoteattr(v)} kind="{k}"><ssc:Real/></ssd:Connector>'
                       for v, k in connectors.items())
        elements.append(f'<ssd:Component name="{comp}" type="application/x-fmu-sharedlibrary" '
                        f'source="resources/{comp}.fmu"><ssd:Connectors>{rows}</ssd:Connectors></ssd:Component>')
    links = "".join(f'<ssd:Connection startElement="{a.split(".")[0]}" startConnector="{a.split(".", 1)[1]}" '
                    f'endElement="{b.split(".")[0]}" endConnector="{b.split(".", 1)[1]}"/>' for a, b in connections)
    bindings = ""
    if parameters or ssv:
        inline = (f'<ssd:ParameterBinding><ssd:ParameterValues>{_parameter_set(parameters)}</ssd:ParameterValues>'
                  f'</ssd:ParameterBinding>') if parameters else ""
        external = f'<ssd:ParameterBinding source="{ssv}"/>' if ssv else ""
        bindings = f"<ssd:ParameterBindings>{inline}{external}</ssd:ParameterBindings>"
    return (f'<?xml version="1.0" encoding="UTF-8"?>{preamble}\n<ssd:SystemStructureDescription {_NS} version="1.0" '
            f'name="{name}"><ssd:System name="{name}">{bindings}<ssd:Elements>{"".join(elements)}</ssd:Elements>'
            f'<ssd:Connections>{links}</ssd:Connections></ssd:System></ssd:SystemStructureDescription>\n')


def ssv_text(values: dict[str, float]) -> str:
    return f'<?xml version="1.0" encoding="UTF-8"?>\n' + _parameter_set(values).replace(
        "<ssv:ParameterSet ", f'<ssv:ParameterSet {_NS} ', 1)


def write_ssp(path: Path, fmus: dict[str, Path], components: dict[str, dict[str, str]],
              connections: list[tuple[str, str]], *, parameters: dict[str, float] | None = None,
              ssv: dict[str, float] | None = None, ssd: str | None = None,
              extra: dict[str, bytes] | None = None) -> Path:
    """Write the archive at ``path`` (module docstring); ``ssd`` replaces the generated SSD text."""
    text = ssd if ssd is not None else ssd_text(components, connections, parameters,
                                                "resources/bound.ssv" if ssv else None)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("SystemStructure.ssd", text)
        for comp, fmu in fmus.items():
            z.write(fmu, f"resources/{comp}.fmu")
        if ssv:
            z.writestr("resources/bound.ssv", ssv_text(ssv))
        for name, data in (extra or {}).items():
            z.writestr(name, data)
    return path

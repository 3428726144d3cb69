"""orchestrator.ssp: an .ssp read as untrusted input, into typed dataclasses (no FMU is run:
the components' FMU members are placeholders, which read_ssp does not open)."""
from __future__ import annotations

import zipfile
from pathlib import Path

import pytest

from ssp_testing import TestComponent, ssd_text, ssv_text

from orchestrator.ssp import SspConnection, SspError, read_ssp

COMPONENTS = [TestComponent("motor", inputs=("V",), outputs=("torque",)),
              TestComponent("load", inputs=("tau",), outputs=("omega",))]
CONNECTIONS = [("motor.torque", "load.tau"), ("load.omega", "motor.V")]


def archive(path: Path, ssd: str, members: dict[str, bytes] | None = None) -> Path:
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("SystemStructure.ssd", ssd)
        for c in COMPONENTS:
            z.writestr(f"resources/{c.name}.fmu", b"placeholder")
        for name, data in (members or {}).items():
            z.writestr(name, data)
    return path


def test_components_connections_and_both_kinds_of_binding(tmp_path):
    ssd = ssd_text("TestSystem", COMPONENTS, CONNECTIONS, system_parameters={"motor.R": 1.5, "load.m": 2.0},
                   system_ssv_source="resources/p.ssv")
    system = read_ssp(archive(tmp_path / "S.ssp", ssd, {"resources/p.ssv": ssv_text({"motor.R": 2.5}).encode()}))
    assert system.name == "TestSystem" and system.component_names == ("motor", "load")
    assert system.component("motor").source == "resources/motor.fmu"
    assert [(c.name, c.kind, c.type) for c in system.component("load").connectors] == [("tau", "input", "Real"),
                                                                                      ("omega", "output", "Real")]
    assert system.connections == (SspConnection("motor", "torque", "load", "tau"),
                                  SspConnection("load", "omega", "motor", "V"))
    bound = system.bindings("motor")
    assert bound["R"].value == 2.5 and bound["R"].origin == "resources/p.ssv"    # the later binding wins
    assert system.bindings("load")["m"].origin == "SystemStructure.ssd"
    assert len(system.sha256) == 64


@pytest.mark.parametrize("member, why", [("../evil", "path traversal"), ("/abs", "absolute path"),
                                         ("a\\b", "backslash")])
def test_unsafe_member_names_refuse_the_archive(tmp_path, member, why):
    path = archive(tmp_path / "S.ssp", ssd_text("TestSystem", COMPONENTS, CONNECTIONS), {member: b"x"})
    with pytest.raises(SspError, match=why) as info:
        read_ssp(path)
    assert str(path) in str(info.value) and repr(member) in str(info.value)


def test_billion_laughs_refused_before_expansion(tmp_path):
    laughs = ('<!DOCTYPE l [<!ENTITY a "ha"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">'
              '<!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;">]>')
    ssd = ssd_text("TestSystem", COMPONENTS, CONNECTIONS, preamble=laughs).replace('name="TestSystem"', 'name="&c;"')
    with pytest.raises(SspError, match="document type declaration"):
        read_ssp(archive(tmp_path / "S.ssp", ssd))


def test_dtd_in_a_bound_ssv_refused(tmp_path):
    ssv = ssv_text({"motor.R": 1.0}).replace("?>", '?><!DOCTYPE p SYSTEM "http://example.com/p.dtd">', 1)
    ssd = ssd_text("TestSystem", COMPONENTS, CONNECTIONS, system_ssv_source="resources/p.ssv")
    with pytest.raises(SspError, match=r"resources/p\.ssv: has a document type declaration"):
        read_ssp(archive(tmp_path / "S.ssp", ssd, {"resources/p.ssv": ssv.encode()}))


@pytest.mark.parametrize("edit, message", [
    (lambda s: s.replace('startConnector="torque"', 'startConnector="torq"'),
     "attribute 'startConnector' = 'torq': component 'motor' declares no such connector"),
    (lambda s: s.replace('source="resources/load.fmu"', 'source="resources/none.fmu"'),
     "attribute 'source' = 'resources/none.fmu': the archive has no such member"),
    (lambda s: s.replace(' source="resources/load.fmu"', ''), "lacks the attribute 'source'"),
    (lambda s: s.replace('<ssd:Component name="load"', '<ssd:Component name="load.x"'),
     "attribute 'name' = 'load.x': expected letters, digits and '_'"),
    (lambda s: s.replace(' version="1.0" name=', ' version="2.0" name=', 1), "expected SSP version 1.0"),
    (lambda s: s.replace('startElement="motor" ', ''), "connection to the system's own connectors"),
    (lambda s: s.replace("<ssd:Elements>", '<ssd:Elements><ssd:System name="inner"/>'), "a nested <ssd:System>"),
    (lambda s: s.replace('<ssv:Real value="1.0"/>', '<ssv:Real value="one"/>'), "attribute 'value' = 'one': not a Real"),
    (lambda s: s.replace('name="motor.R"', 'name="pump.R"'), "expected a name component.variable"),
    (lambda s: s.replace("</ssd:Connections>", "", 1), "not well-formed XML"),
])
def test_problems_name_element_and_attribute(tmp_path, edit, message):
    ssd = edit(ssd_text("TestSystem", COMPONENTS, CONNECTIONS, system_parameters={"motor.R": 1.0}))
    with pytest.raises(SspError) as info:
        read_ssp(archive(tmp_path / "S.ssp", ssd))
    assert message in str(info.value)
    assert str(info.value).startswith(str(tmp_path / "S.ssp"))


def test_not_a_zip(tmp_path):
    path = tmp_path / "S.ssp"
    path.write_text("not a zip", encoding="utf-8")
    with pytest.raises(SspError, match="not an SSP archive"):
        read_ssp(path)


# ---------------------------------------------------------------------------------- Gauss-Seidel order

def _system(names, connections, feedthrough: set[str]):
    """A system description of fake components: each has input ``u`` and output ``y``; ``y``
    depends directly on ``u`` for the components in ``feedthrough``, on nothing for the others."""
    from types import SimpleNamespace

    from orchestrator.ssp import SspComponent, SspSystem
    from orchestrator.system_description import ComponentDescription, SystemDescription

    components = []
    for name in names:
        u = SimpleNamespace(name="u", causality="input")
        y = SimpleNamespace(name="y", causality="output")
        model = SimpleNamespace(modelVariables=[u, y], fmiVersion="2.0",
                                outputs=[SimpleNamespace(variable=y, dependencies=[u] if name in feedthrough else [])])
        components.append(ComponentDescription(name=name, source=f"resources/{name}.fmu", sha256="0", model=model))
    links = tuple(SspConnection(a, "y", b, "u") for a, b in connections)
    ssp = SspSystem(path=Path("S.ssp"), sha256="0", name="S",
                    components=tuple(SspComponent(n, f"resources/{n}.fmu") for n in names), connections=links,
                    parameters=())
    return SystemDescription(path=Path("S.ssp"), stamp=(0, 0), ssp=ssp, components=tuple(components))


def test_gauss_seidel_order_follows_the_connections():
    from orchestrator.system_order import gauss_seidel_order

    chain = _system(["c3", "c1", "c2"], [("c1", "c2"), ("c2", "c3")], feedthrough={"c1", "c2", "c3"})
    assert gauss_seidel_order(chain) == ("c1", "c2", "c3")


def test_a_loop_is_broken_where_no_output_feeds_through():
    from orchestrator.system_order import gauss_seidel_order

    loop = [("ctrl", "plant"), ("plant", "ctrl")]
    assert gauss_seidel_order(_system(["ctrl", "plant"], loop, feedthrough={"ctrl"})) == ("plant", "ctrl")
    assert gauss_seidel_order(_system(["ctrl", "plant"], loop, feedthrough={"ctrl", "plant"})) == ("ctrl", "plant")
    # a loop behind a component feeding it: the feeder first, then the loop's break
    fed = _system(["a", "b", "src"], [("src", "a"), ("a", "b"), ("b", "a")], feedthrough={"a"})
    assert gauss_seidel_order(fed) == ("src", "b", "a")

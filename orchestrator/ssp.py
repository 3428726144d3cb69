"""Reading an SSP 1.0 archive (``.ssp``): its ``SystemStructure.ssd`` into typed, frozen dataclasses.

An ``.ssp`` file is untrusted input, as a case file is:

- The archive is a zip read without extracting anything it does not name: a member whose
  name is absolute, holds a ``..`` part or a backslash refuses the whole archive (a tool that
  extracts it all would write outside its folder); the SSD, every ``.ssv`` it binds and every
  component's FMU are read by name, each at most :data:`MAX_MEMBER_BYTES` (the size the zip
  declares and the bytes actually read), the archive at most :data:`MAX_MEMBERS` members.
- The SSD and ``.ssv`` files are XML parsed with a document type declaration refused (no DTD,
  no entity: nothing expands and nothing external is fetched), then read element by element;
  a problem names the file, the element and the attribute.
- What this reader does not support is refused with a message naming it, rather than
  silently ignored: nested systems, signal dictionaries, parameter mappings, connection
  transformations, connections to the system's own connectors, components that are not
  FMUs.

The result, :class:`SspSystem`, lists the components (name, FMU path in the archive, declared
connectors), the connections and the parameter bindings (inline ``ssv:ParameterValues`` and
``resources/*.ssv`` files; system-level names are ``component.variable``, component-level
names the variable's own, each after the binding's ``prefix``).  Standard library only.
"""
from __future__ import annotations

import hashlib
import re
import xml.etree.ElementTree as ET
import xml.parsers.expat
import zipfile
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

__all__ = ["MAX_MEMBERS", "MAX_MEMBER_BYTES", "SSD_NAME", "SspComponent", "SspConnection", "SspConnector",
           "SspError", "SspParameter", "SspSystem", "component_bytes", "read_member", "read_ssp"]

#: The system structure's file name inside the archive (SSP 1.0, 5.1).
SSD_NAME = "SystemStructure.ssd"
#: Most bytes of one member read from an archive (an FMU, the SSD, an .ssv).
MAX_MEMBER_BYTES = 256 * 1024 * 1024
#: Most members an archive may list.
MAX_MEMBERS = 10_000

_SSD = "{http://ssp-standard.org/SSP1/SystemStructureDescription}"
_SSC = "{http://ssp-standard.org/SSP1/SystemStructureCommon}"
_SSV = "{http://ssp-standard.org/SSP1/SystemStructureParameterValues}"
_FMU_TYPE = "application/x-fmu-sharedlibrary"
_TYPES = ("Real", "Integer", "Boolean", "String", "Enumeration")
#: A component's name addresses its variables as ``component.variable`` in cases and columns.
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


class SspError(ValueError):
    """An ``.ssp`` file cannot be run: the message names the file, and the element and
    attribute when the problem is in the SSD."""


@dataclass(frozen=True)
class SspConnector:
    """A connector a component declares: ``kind`` input | output | parameter | calculatedParameter
    | inout; ``type`` its ssc type element (Real, Integer, ...), None when it declares none."""

    name: str
    kind: str
    type: str | None = None


@dataclass(frozen=True)
class SspComponent:
    """One ``ssd:Component``: its name, the FMU's path inside the archive, its connectors."""

    name: str
    source: str
    connectors: tuple[SspConnector, ...] = ()


@dataclass(frozen=True)
class SspConnection:
    """``start_component.start_connector -> end_component.end_connector``."""

    start_component: str
    start_connector: str
    end_component: str
    end_connector: str

    @property
    def source(self) -> str:
        return f"{self.start_component}.{self.start_connector}"

    @property
    def target(self) -> str:
        return f"{self.end_component}.{self.end_connector}"

    def __str__(self) -> str:
        return f"{self.source} -> {self.target}"


@dataclass(frozen=True)
class SspParameter:
    """One bound parameter value: component, variable, value (float, int, bool or str), its
    ssv type, and where it came from (``SystemStructure.ssd`` or the .ssv file's path)."""

    component: str
    variable: str
    value: float | int | bool | str
    type: str
    origin: str

    @property
    def name(self) -> str:
        return f"{self.component}.{self.variable}"


@dataclass(frozen=True)
class SspSystem:
    """What :func:`read_ssp` read: the archive's path and SHA-256, the system's name, its
    components (in the SSD's order), connections and parameter bindings (in binding order:
    a later binding of the same variable wins, as SSP 1.0 says)."""

    path: Path
    sha256: str
    name: str
    components: tuple[SspComponent, ...]
    connections: tuple[SspConnection, ...]
    parameters: tuple[SspParameter, ...]

    def component(self, name: str) -> SspComponent | None:
        return next((c for c in self.components if c.name == name), None)

    @property
    def component_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.components)

    def bindings(self, component: str) -> dict[str, SspParameter]:
        """The effective bound value of each variable of ``component`` (the last binding wins)."""
        return {p.variable: p for p in self.parameters if p.component == component}


# ---------------------------------------------------------------------------------- the archive

def _unsafe(name: str) -> str | None:
    """Why a member name could write outside an extraction folder, None when it cannot."""
    if "\\" in name:
        return "holds a backslash"
    if name.startswith("/") or re.match(r"[A-Za-z]:", name):
        return "is an absolute path"
    if ".." in PurePosixPath(name).parts:
        return "holds a '..' part (path traversal)"
    return None


def _open_archive(path: Path) -> zipfile.ZipFile:
    try:
        archive = zipfile.ZipFile(path)
    except FileNotFoundError:
        raise SspError(f"{path}: file not found") from None
    except (OSError, zipfile.BadZipFile) as exc:
        raise SspError(f"{path}: not an SSP archive (a zip file): {exc}") from None
    infos = archive.infolist()
    if len(infos) > MAX_MEMBERS:
        archive.close()
        raise SspError(f"{path}: holds {len(infos)} members, more than {MAX_MEMBERS}; not read")
    for info in infos:
        why = _unsafe(info.filename)
        if why is not None:
            archive.close()
            raise SspError(f"{path}: member {info.filename!r} {why}; the archive is refused")
    return archive


def read_member(path: Path, member: str, archive: zipfile.ZipFile | None = None) -> bytes:
    """The bytes of ``member`` of the archive at ``path`` (at most :data:`MAX_MEMBER_BYTES`)."""
    own = archive is None
    archive = _open_archive(path) if own else archive
    try:
        try:
            info = archive.getinfo(member)
        except KeyError:
            raise SspError(f"{path}: has no member {member!r}") from None
        if info.file_size > MAX_MEMBER_BYTES:
            raise SspError(f"{path}: member {member!r} is {info.file_size} bytes, more than {MAX_MEMBER_BYTES}")
        try:
            with archive.open(info) as stream:
                data = stream.read(MAX_MEMBER_BYTES + 1)
        except (OSError, zipfile.BadZipFile, RuntimeError, NotImplementedError) as exc:
            raise SspError(f"{path}: member {member!r} cannot be read: {exc}") from None
        if len(data) > MAX_MEMBER_BYTES:
            raise SspError(f"{path}: member {member!r} holds more than {MAX_MEMBER_BYTES} bytes")
        return data
    finally:
        if own:
            archive.close()


# ---------------------------------------------------------------------------------- XML

def _parse_xml(data: bytes, where: str) -> ET.Element:
    """Parse untrusted XML: a document type declaration (DTD, entities) is refused first."""
    def refuse(*_args) -> None:
        raise SspError(f"{where}: has a document type declaration (<!DOCTYPE ...>); DTDs and entities are "
                       f"refused in SSP files")

    checker = xml.parsers.expat.ParserCreate()
    checker.StartDoctypeDeclHandler = refuse
    checker.EntityDeclHandler = refuse
    try:
        checker.Parse(data, True)
    except xml.parsers.expat.ExpatError as exc:
        raise SspError(f"{where}: not well-formed XML: {exc}") from None
    try:
        return ET.fromstring(data)
    except ET.ParseError as exc:
        raise SspError(f"{where}: not well-formed XML: {exc}") from None


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _require(element: ET.Element, attribute: str, where: str) -> str:
    value = element.get(attribute)
    if value is None or not value.strip():
        raise SspError(f"{where}: element <{_local(element.tag)}> lacks the attribute {attribute!r}")
    return value


# ---------------------------------------------------------------------------------- the SSD

def read_ssp(path: str | Path) -> SspSystem:
    """Read the ``.ssp`` at ``path`` (module docstring); :class:`SspError` when it cannot be run."""
    path = Path(path)
    try:
        with open(path, "rb") as stream:
            digest = hashlib.file_digest(stream, "sha256").hexdigest()
    except FileNotFoundError:
        raise SspError(f"{path}: file not found") from None
    except OSError as exc:
        raise SspError(f"{path}: cannot read: {exc}") from None
    with _open_archive(path) as archive:
        ssd_where = f"{path}: {SSD_NAME}"
        if SSD_NAME not in archive.namelist():
            raise SspError(f"{path}: has no {SSD_NAME}; expected an SSP 1.0 archive")
        root = _parse_xml(read_member(path, SSD_NAME, archive), ssd_where)
        return _Ssd(path, archive, ssd_where).system(root, digest)


class _Ssd:
    def __init__(self, path: Path, archive: zipfile.ZipFile, where: str):
        self.path, self.archive, self.where = path, archive, where

    def at(self, element: ET.Element, name: str | None = None) -> str:
        return f"{self.where}: <{_local(element.tag)}{f' name={name!r}' if name else ''}>"

    def unsupported(self, element: ET.Element, what: str) -> SspError:
        return SspError(f"{self.at(element, element.get('name'))}: {what} is not supported by fourbar-run's SSP reader")

    def system(self, root: ET.Element, digest: str) -> SspSystem:
        if root.tag != f"{_SSD}SystemStructureDescription":
            raise SspError(f"{self.where}: the root element is <{root.tag}>; expected "
                           f"<ssd:SystemStructureDescription> (namespace {_SSD[1:-1]})")
        version = root.get("version")
        if version not in ("1.0", "1.0.1"):
            raise SspError(f"{self.where}: <SystemStructureDescription version={version!r}>: expected SSP version 1.0")
        system = root.find(f"{_SSD}System")
        if system is None:
            raise SspError(f"{self.where}: <SystemStructureDescription> has no <ssd:System>")
        name = _require(system, "name", self.where)
        for tag, what in (("SignalDictionaries", "a signal dictionary"),):
            found = system.find(f"{_SSD}{tag}")
            if found is not None and len(found):
                raise self.unsupported(found, what)
        components = self.components(system)
        connectors = {c.name: {k.name: k for k in c.connectors} for c in components}
        connections = self.connections(system, connectors)
        parameters = list(self.bindings(system, None, connectors))
        for element in self.elements(system):
            parameters.extend(self.bindings(element, element.get("name"), connectors))
        return SspSystem(path=self.path, sha256=digest, name=name, components=tuple(components),
                         connections=tuple(connections), parameters=tuple(parameters))

    def elements(self, system: ET.Element) -> list[ET.Element]:
        holder = system.find(f"{_SSD}Elements")
        return list(holder) if holder is not None else []

    def components(self, system: ET.Element) -> list[SspComponent]:
        components: list[SspComponent] = []
        for element in self.elements(system):
            kind = _local(element.tag)
            if kind == "System":
                raise self.unsupported(element, "a nested <ssd:System>")
            if kind != "Component":
                raise self.unsupported(element, f"an element <{kind}>")
            name = _require(element, "name", self.at(element))
            where = self.at(element, name)
            if not _NAME.match(name):
                raise SspError(f"{where}: attribute 'name' = {name!r}: expected letters, digits and '_' (not starting "
                               f"with a digit): a component's name addresses its variables as component.variable")
            if name in (c.name for c in components):
                raise SspError(f"{where}: attribute 'name' = {name!r}: a second component of that name")
            kind_attr = element.get("type", _FMU_TYPE)
            if kind_attr != _FMU_TYPE:
                raise SspError(f"{where}: attribute 'type' = {kind_attr!r}: only FMUs ({_FMU_TYPE}) are supported")
            source = _require(element, "source", where)
            if "://" in source or source.startswith("#"):
                raise SspError(f"{where}: attribute 'source' = {source!r}: only a path inside the archive is supported")
            why = _unsafe(source)
            if why is not None:
                raise SspError(f"{where}: attribute 'source' = {source!r} {why}")
            if source not in self.archive.namelist():
                raise SspError(f"{where}: attribute 'source' = {source!r}: the archive has no such member")
            components.append(SspComponent(name=name, source=source, connectors=self.connectors(element, where)))
        if not components:
            raise SspError(f"{self.where}: the system lists no component (<ssd:Elements> is empty or missing)")
        return components

    def connectors(self, element: ET.Element, where: str) -> tuple[SspConnector, ...]:
        holder = element.find(f"{_SSD}Connectors")
        result: list[SspConnector] = []
        for connector in holder if holder is not None else ():
            name = _require(connector, "name", f"{where} <Connectors>")
            kind = _require(connector, "kind", f"{where} <Connector name={name!r}>")
            types = [_local(child.tag) for child in connector if _local(child.tag) in _TYPES]
            result.append(SspConnector(name=name, kind=kind, type=types[0] if types else None))
        return tuple(result)

    def connections(self, system: ET.Element, connectors: dict) -> list[SspConnection]:
        holder = system.find(f"{_SSD}Connections")
        result: list[SspConnection] = []
        for i, element in enumerate(holder if holder is not None else ()):
            where = f"{self.where}: <Connection> {i + 1}"
            if element.get("startElement") is None or element.get("endElement") is None:
                raise SspError(f"{where}: a connection to the system's own connectors (no startElement or endElement) "
                               f"is not supported by fourbar-run's SSP reader")
            if len(element):
                raise SspError(f"{where}: a connection with <{_local(element[0].tag)}> (a transformation) is not "
                               f"supported by fourbar-run's SSP reader")
            ends = [(_require(element, f"{side}Element", where), _require(element, f"{side}Connector", where))
                    for side in ("start", "end")]
            for (component, connector), side in zip(ends, ("start", "end")):
                if component not in connectors:
                    raise SspError(f"{where}: attribute '{side}Element' = {component!r}: no component of that name "
                                   f"(components: {', '.join(connectors)})")
                if connector not in connectors[component]:
                    raise SspError(f"{where}: attribute '{side}Connector' = {connector!r}: component {component!r} "
                                   f"declares no such connector (it declares: "
                                   f"{', '.join(connectors[component]) or 'none'})")
            result.append(SspConnection(ends[0][0], ends[0][1], ends[1][0], ends[1][1]))
        return result

    # -- parameter bindings ---------------------------------------------------------
    def bindings(self, element: ET.Element, component: str | None, connectors: dict):
        holder = element.find(f"{_SSD}ParameterBindings")
        for binding in holder if holder is not None else ():
            where = self.at(binding)
            if binding.find(f"{_SSD}ParameterMapping") is not None:
                raise self.unsupported(binding, "a <ParameterMapping>")
            prefix = binding.get("prefix", "")
            source = binding.get("source")
            if source is not None:
                if "://" in source or source.startswith("#"):
                    raise SspError(f"{where}: attribute 'source' = {source!r}: only a path inside the archive is supported")
                why = _unsafe(source)
                if why is not None:
                    raise SspError(f"{where}: attribute 'source' = {source!r} {why}")
                if source not in self.archive.namelist():
                    raise SspError(f"{where}: attribute 'source' = {source!r}: the archive has no such member")
                origin = source
                values = _parse_xml(read_member(self.path, source, self.archive), f"{self.path}: {source}")
            else:
                origin = SSD_NAME
                inline = binding.find(f"{_SSD}ParameterValues")
                if inline is None:
                    raise SspError(f"{where}: has neither a 'source' attribute nor <ssd:ParameterValues>")
                values = inline.find(f"{_SSV}ParameterSet")
                if values is None:
                    raise SspError(f"{where}: <ParameterValues> has no <ssv:ParameterSet>")
            yield from self.parameter_set(values, prefix, component, connectors,
                                          f"{self.path}: {origin}" if source else where, origin)

    def parameter_set(self, root: ET.Element, prefix: str, component: str | None, connectors: dict,
                      where: str, origin: str):
        if root.tag != f"{_SSV}ParameterSet":
            raise SspError(f"{where}: the root element is <{root.tag}>; expected <ssv:ParameterSet>")
        holder = root.find(f"{_SSV}Parameters")
        for parameter in holder if holder is not None else ():
            name = _require(parameter, "name", f"{where} <Parameter>")
            at = f"{where} <Parameter name={name!r}>"
            full = prefix + name
            if component is None:
                owner, _, variable = full.partition(".")
                if not variable or owner not in connectors:
                    raise SspError(f"{at}: expected a name component.variable (after the binding's prefix "
                                   f"{prefix!r}) with a component of the system ({', '.join(connectors)})")
            else:
                owner, variable = component, full
            typed = [child for child in parameter if _local(child.tag) in _TYPES]
            if len(typed) != 1:
                raise SspError(f"{at}: expected one value element (ssv:Real, Integer, Boolean, String)")
            yield SspParameter(component=owner, variable=variable, value=_value(typed[0], at),
                               type=_local(typed[0].tag), origin=origin)


def _value(element: ET.Element, where: str) -> float | int | bool | str:
    kind = _local(element.tag)
    text = _require(element, "value", f"{where} <{kind}>")
    try:
        if kind == "Real":
            return float(text)
        if kind in ("Integer", "Enumeration"):
            return int(text)
        if kind == "Boolean":
            if text.strip() not in ("true", "false", "1", "0"):
                raise ValueError(text)
            return text.strip() in ("true", "1")
    except ValueError:
        raise SspError(f"{where} <{kind}>: attribute 'value' = {text!r}: not a {kind}") from None
    return text


def component_bytes(system: SspSystem, name: str) -> bytes:
    """The FMU file of component ``name``, read from the archive."""
    component = system.component(name)
    return read_member(system.path, component.source)


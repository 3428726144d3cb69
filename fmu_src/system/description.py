"""System files (systems/<name>.toml, docs/systems.md): components, parameter values, connections.

A system file is untrusted data, read into frozen dataclasses by :func:`load_system`, which
collects every problem of the file's form and raises one :class:`SystemFileError` listing them
(each naming the file, the field and the value).  What needs the components' FMUs (does the
variable exist, is it an input, do the units fit) is checked by
:func:`fmu_src.system.interface.check_system` once they are built.
"""
from __future__ import annotations

import difflib
import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

__all__ = ["SYSTEM_DIR", "SystemFileError", "ComponentSpec", "ConnectionSpec", "Experiment", "SystemDescription",
           "load_system", "parse_system", "resolve_system", "shipped_systems"]

#: Where the shipped system files live (``--system NAME`` looks here).
SYSTEM_DIR = Path(__file__).resolve().parent.parent.parent / "systems"
#: An instance or variable name: what SSP connectors and the exchange's "component.variable" hold.
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
#: A system's name: it names build/<Name>.ssp.
_MODEL_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,63}\Z")
_KEYS = {"system": {"name", "description"},
         "component": {"name", "block", "mechanism", "parameters", "description"},
         "connection": {"from", "to"},
         "experiment": {"start", "stop"}}
_TOP = {"system", "components", "connections", "experiment"}
#: Longest description, characters.
MAX_TEXT = 2000


class SystemFileError(ValueError):
    """A system file that cannot be used; the message names the file, the field and the value."""


@dataclass(frozen=True)
class ComponentSpec:
    """One component instance: ``kind`` "block" (fmu_src/components/) or "mechanism"
    (fmu_src/mechanisms/), ``source`` the shipped name or the path as written (a relative path
    is taken from the system file's folder: :attr:`source_path`), and the values its parameters
    (or unconnected inputs) are bound to, SI, in file order."""

    name: str
    kind: str
    source: str
    parameters: tuple[tuple[str, float], ...]
    source_path: Path | None = None

    @property
    def reference(self) -> str:
        """What the builders take: the shipped name, or the resolved path as a string."""
        return str(self.source_path) if self.source_path is not None else self.source


@dataclass(frozen=True)
class ConnectionSpec:
    """An output of one component feeding an input of another."""

    source_component: str
    source_variable: str
    target_component: str
    target_variable: str

    @property
    def source(self) -> str:
        return f"{self.source_component}.{self.source_variable}"

    @property
    def target(self) -> str:
        return f"{self.target_component}.{self.target_variable}"


@dataclass(frozen=True)
class Experiment:
    """The SSD's DefaultExperiment (s): a suggestion masters may ignore."""

    start: float = 0.0
    stop: float | None = None


@dataclass(frozen=True)
class SystemDescription:
    name: str
    description: str
    path: Path
    components: tuple[ComponentSpec, ...]
    connections: tuple[ConnectionSpec, ...]
    experiment: Experiment

    def component(self, name: str) -> ComponentSpec:
        return next(c for c in self.components if c.name == name)


def shipped_systems() -> tuple[str, ...]:
    """Names of the system files in systems/."""
    return tuple(sorted(p.stem for p in SYSTEM_DIR.glob("*.toml")))


def resolve_system(name_or_path: str | Path) -> Path:
    """The file of a shipped system name (``motor_fourbar``) or a path to a .toml file."""
    text = str(name_or_path)
    path = Path(text)
    if path.suffix == ".toml" or path.parent != Path("."):
        if not path.is_file():
            raise SystemFileError(f"{text}: no such system file")
        return path
    shipped = SYSTEM_DIR / f"{text}.toml"
    if not shipped.is_file():
        names = shipped_systems()
        close = difflib.get_close_matches(text, names, n=1)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise SystemFileError(f"unknown system {text!r}: {hint}the shipped ones are {', '.join(names) or 'none'}; "
                              f"or give the path of a .toml file")
    return shipped


def load_system(name_or_path: str | Path) -> SystemDescription:
    """Read and check a system file (a shipped name or a path)."""
    path = resolve_system(name_or_path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise SystemFileError(f"{path}: not valid TOML: {exc}") from None
    except (RecursionError, MemoryError) as exc:
        raise SystemFileError(f"{path}: not usable TOML: nested too deeply ({type(exc).__name__})") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SystemFileError(f"{path}: cannot be read: {exc}") from None
    except ValueError as exc:          # tomllib: an integer of more than 4300 digits
        raise SystemFileError(f"{path}: not usable TOML: {exc}") from None
    return parse_system(data, path)


def _unknown_keys(table: dict, allowed: set[str], where: str, problems: list[str]) -> None:
    for key in table:
        if key not in allowed:
            close = difflib.get_close_matches(str(key), sorted(allowed), n=1)
            hint = f"did you mean {close[0]!r}? " if close else ""
            problems.append(f"{where}: unknown field {str(key)!r}; {hint}expected {', '.join(sorted(allowed))}")


def _text(value, where: str, problems: list[str], *, required: bool = True) -> str:
    if value is None and not required:
        return ""
    if not isinstance(value, str) or (required and not value.strip()):
        problems.append(f"{where}: {value!r} is not a non-empty string")
        return ""
    if len(value) > MAX_TEXT or any(ord(ch) < 32 and ch not in "\t\n" for ch in value):
        problems.append(f"{where}: longer than {MAX_TEXT} characters or with control characters")
        return ""
    return value


def _number(value, where: str, problems: list[str]) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        problems.append(f"{where}: {value!r} is not a number (SI units)")
        return None
    number = float(value)
    if not math.isfinite(number):
        problems.append(f"{where}: {value!r} is not finite")
        return None
    return number


def _variable_ref(value, where: str, problems: list[str]) -> tuple[str, str] | None:
    if not isinstance(value, str) or value.count(".") != 1 \
            or not all(_NAME.match(part) for part in value.split(".")):
        problems.append(f"{where}: {value!r} is not 'component.variable'")
        return None
    component, variable = value.split(".")
    return component, variable


def _component(table, index: int, folder: Path, problems: list[str]) -> ComponentSpec | None:
    where = f"components[{index}]"
    if not isinstance(table, dict):
        problems.append(f"{where}: {table!r} is not a table ([[components]])")
        return None
    name = table.get("name")
    if not isinstance(name, str) or not _NAME.match(name):
        problems.append(f"{where}.name: {name!r} is not a name (a letter, then letters, digits or _)")
        return None
    where = f"components[{index}] {name!r}"
    _unknown_keys(table, _KEYS["component"], where, problems)
    _text(table.get("description"), f"{where}.description", problems, required=False)
    kinds = [kind for kind in ("block", "mechanism") if kind in table]
    if len(kinds) != 1:
        problems.append(f"{where}: give exactly one of 'block' (a component in fmu_src/components/ or a path) "
                        f"or 'mechanism' (a mechanism in fmu_src/mechanisms/ or a path); it has "
                        f"{' and '.join(kinds) or 'neither'}")
        return None
    kind = kinds[0]
    source = table[kind]
    if not isinstance(source, str) or not source.strip():
        problems.append(f"{where}.{kind}: {source!r} is not a name or a path")
        return None
    source_path = None
    if source.endswith(".toml") or "/" in source or "\\" in source:
        source_path = (folder / source).resolve()
        if not source_path.is_file():
            problems.append(f"{where}.{kind}: {source!r}: no such file ({source_path})")
            return None
    elif not _NAME.match(source):
        problems.append(f"{where}.{kind}: {source!r} is not a shipped name or a path ending in .toml")
        return None
    parameters = table.get("parameters", {})
    bound: list[tuple[str, float]] = []
    if not isinstance(parameters, dict):
        problems.append(f"{where}.parameters: {parameters!r} is not a table of name = value")
    else:
        for key, value in parameters.items():
            if not _NAME.match(str(key)):
                problems.append(f"{where}.parameters: {str(key)!r} is not a variable name")
                continue
            number = _number(value, f"{where}.parameters.{key}", problems)
            if number is not None:
                bound.append((str(key), number))
    return ComponentSpec(name=name, kind=kind, source=source, parameters=tuple(bound), source_path=source_path)


def parse_system(data: dict, path: str | Path) -> SystemDescription:
    """The typed system of a parsed TOML document; raises SystemFileError listing every problem
    of form (names, types, duplicates, connections naming no component)."""
    path = Path(path)
    problems: list[str] = []
    _unknown_keys(data, _TOP, "top level", problems)
    system = data.get("system")
    name, description = "", ""
    if not isinstance(system, dict):
        problems.append("[system]: missing (a table with name and description)")
    else:
        _unknown_keys(system, _KEYS["system"], "system", problems)
        name = system.get("name")
        if not isinstance(name, str) or not _MODEL_NAME.match(name):
            problems.append(f"system.name: {name!r} is not a name (a letter, then up to 63 letters, digits or _; "
                            f"it names build/<name>.ssp)")
            name = ""
        description = _text(system.get("description"), "system.description", problems)
    experiment = Experiment()
    if "experiment" in data:
        table = data["experiment"]
        if not isinstance(table, dict):
            problems.append(f"[experiment]: {table!r} is not a table")
        else:
            _unknown_keys(table, _KEYS["experiment"], "experiment", problems)
            start = _number(table.get("start", 0.0), "experiment.start", problems)
            stop = _number(table["stop"], "experiment.stop", problems) if "stop" in table else None
            if start is not None and stop is not None and stop <= start:
                problems.append(f"experiment.stop: {stop!r} is not after experiment.start = {start!r}")
            experiment = Experiment(start=start if start is not None else 0.0, stop=stop)
    raw_components = data.get("components")
    components: list[ComponentSpec] = []
    if not isinstance(raw_components, list) or not raw_components:
        problems.append("[[components]]: missing (at least one component)")
    else:
        for index, table in enumerate(raw_components):
            spec = _component(table, index, path.parent, problems)
            if spec is None:
                continue
            if any(c.name == spec.name for c in components):
                problems.append(f"components[{index}].name: {spec.name!r} is already the name of another component")
                continue
            components.append(spec)
    names = [c.name for c in components]
    raw_connections = data.get("connections", [])
    connections: list[ConnectionSpec] = []
    if not isinstance(raw_connections, list):
        problems.append(f"[[connections]]: {raw_connections!r} is not an array of tables")
        raw_connections = []
    for index, table in enumerate(raw_connections):
        where = f"connections[{index}]"
        if not isinstance(table, dict):
            problems.append(f"{where}: {table!r} is not a table ([[connections]])")
            continue
        _unknown_keys(table, _KEYS["connection"], where, problems)
        ends = []
        for key in ("from", "to"):
            ref = _variable_ref(table.get(key), f"{where}.{key}", problems)
            if ref is not None and ref[0] not in names and raw_components:
                close = difflib.get_close_matches(ref[0], names, n=1)
                hint = f"did you mean {close[0]!r}? " if close else ""
                problems.append(f"{where}.{key}: {table[key]!r}: no component named {ref[0]!r}; "
                                f"{hint}the components are {', '.join(names)}")
                ref = None
            ends.append(ref)
        if None in ends:
            continue
        (sc, sv), (tc, tv) = ends
        if sc == tc:
            problems.append(f"{where}: {table['from']!r} -> {table['to']!r} connects a component to itself")
            continue
        connection = ConnectionSpec(sc, sv, tc, tv)
        earlier = next((c for c in connections if c.target == connection.target), None)
        if earlier is not None:
            problems.append(f"{where}.to: {connection.target!r} is already fed by {earlier.source!r}: "
                            f"an input has one source")
            continue
        connections.append(connection)
    if problems:
        raise SystemFileError(f"{path}: " + ("\n  ".join([""] + problems) if len(problems) > 1 else problems[0]))
    return SystemDescription(name=name, description=description, path=path, components=tuple(components),
                             connections=tuple(connections), experiment=experiment)

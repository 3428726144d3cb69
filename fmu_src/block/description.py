"""A component's block file (docs/components.md), read as untrusted data into a :class:`Block`.

The file is TOML: ``[component]`` (name, description), then tables of named entries:
``[parameters.NAME]`` (value, unit, description, min, max, positive), ``[inputs.NAME]`` (unit,
start, description), ``[states.NAME]`` (unit, start, derivative, description),
``[intermediates.NAME]`` and ``[outputs.NAME]`` (expression, unit, description).  Every
expression goes through the mechanisms' whitelist parser (``mechanism.expressions``: never
``eval``), with three functions more (``min``, ``max``, ``round``: BLOCK_FUNCTIONS).  Every
mistake is a :class:`BlockError` naming the file, the field and the value.
"""
from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

from ..mechanism.expressions import FUNCTIONS, CONSTANTS, ExpressionError, ExpressionFunction, check_expression
from .units import BLOCK_UNITS

__all__ = ["BlockError", "BlockParameter", "BlockInput", "BlockState", "BlockExpression", "Block", "load_block",
           "shipped_components", "COMPONENTS_DIR", "BLOCK_FUNCTIONS", "RESERVED_NAMES"]

#: The shipped components' folder: ``build_fmu.py --component NAME`` reads NAME.toml there.
COMPONENTS_DIR = Path(__file__).resolve().parent.parent / "components"


def _round_half_away(x: float) -> float:
    return math.copysign(math.floor(abs(x) + 0.5), x)


def _build(name: str):
    def build(*args):
        from . import functions
        return getattr(functions, name)(*args)
    return build


#: The functions a block expression may call: the mechanisms' and min, max (two arguments) and
#: round (half away from zero, as C's round()).
BLOCK_FUNCTIONS = {
    **FUNCTIONS,
    "min": ExpressionFunction("Min", min, 2),
    "max": ExpressionFunction("Max", max, 2),
    "round": ExpressionFunction("round", _round_half_away, 1, build=_build("Round")),
}

#: Names the FMU itself uses (its solver parameters, FMI 3.0's time) or an expression reads
#: otherwise (functions, constants): no entry may take them.
RESERVED_NAMES = frozenset({"rtol", "atol", "integrator", "max_evaluations", "time", *BLOCK_FUNCTIONS, *CONSTANTS})
_C_KEYWORDS = frozenset(
    "auto break case char const continue default do double else enum extern float for goto if inline int long "
    "register restrict return short signed sizeof static struct switch typedef union unsigned void volatile "
    "while _Bool _Complex _Imaginary".split())
_IDENTIFIER = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,62}\Z")
_SECTIONS = ("component", "parameters", "inputs", "states", "intermediates", "outputs")
_KEYS = {
    "parameters": {"value", "unit", "description", "min", "max", "positive"},
    "inputs": {"unit", "start", "description"},
    "states": {"unit", "start", "derivative", "description"},
    "intermediates": {"expression", "unit", "description"},
    "outputs": {"expression", "unit", "description"},
}


class BlockError(ValueError):
    """A block file that cannot be used; the message names the file, the field and the value."""


@dataclass(frozen=True)
class BlockParameter:
    """A tunable parameter, SI units; ``positive``: must be > 0 (it divides)."""

    name: str
    value: float
    unit: str
    description: str
    minimum: float | None = None
    maximum: float | None = None
    positive: bool = False


@dataclass(frozen=True)
class BlockInput:
    name: str
    start: float
    unit: str
    description: str


@dataclass(frozen=True)
class BlockState:
    """A continuous state, its start value (the FMU's fixed parameter ``<name>_start``) and the
    text of its time derivative."""

    name: str
    start: float
    unit: str
    description: str
    derivative: str


@dataclass(frozen=True)
class BlockExpression:
    """An intermediate or an output: a name for an expression."""

    name: str
    expression: str
    unit: str
    description: str


@dataclass(frozen=True)
class Block:
    """A component as its file describes it; intermediates in an order where each uses only
    those before it."""

    name: str
    description: str
    source: Path
    parameters: tuple[BlockParameter, ...]
    inputs: tuple[BlockInput, ...]
    states: tuple[BlockState, ...]
    intermediates: tuple[BlockExpression, ...]
    outputs: tuple[BlockExpression, ...]


def shipped_components() -> tuple[str, ...]:
    """The names ``build_fmu.py --component`` accepts besides paths (fmu_src/components/*.toml)."""
    return tuple(sorted(p.stem for p in COMPONENTS_DIR.glob("*.toml")))


def _resolve(source: str | Path) -> Path:
    text = str(source)
    if isinstance(source, Path) or text.endswith(".toml") or "/" in text or "\\" in text:
        return Path(source)
    path = COMPONENTS_DIR / f"{text}.toml"
    if not path.exists():
        raise BlockError(f"{text}: no such component (shipped: {', '.join(shipped_components())}; or give the "
                         f"path of a block file)")
    return path


class _Reader:
    """Reads one file's tables, raising BlockError with the file and field named."""

    def __init__(self, path: Path):
        self.path = path

    def error(self, field: str, value, why: str) -> BlockError:
        shown = repr(value)
        if len(shown) > 80:
            shown = shown[:77] + "..."
        return BlockError(f"{self.path}: {field} = {shown}: {why}")

    def text(self, field: str, value, default: str | None = None) -> str:
        if value is None and default is not None:
            return default
        if not isinstance(value, str):
            raise self.error(field, value, "expected a text (in quotes)")
        return value

    def number(self, field: str, value, default: float | None = None) -> float:
        if value is None and default is not None:
            return default
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(field, value, "expected a number")
        if not math.isfinite(value):
            raise self.error(field, value, "must be finite")
        return float(value)

    def unit(self, field: str, value) -> str:
        unit = self.text(field, value, "1")
        if unit not in BLOCK_UNITS:
            raise self.error(field, value, f"unknown unit (known: {', '.join(BLOCK_UNITS)})")
        return unit


def load_block(source: str | Path) -> Block:
    """The :class:`Block` of a shipped component's name (fmu_src/components/NAME.toml) or a
    block file's path; raises :class:`BlockError` for any mistake, naming file, field and value."""
    path = _resolve(source)
    r = _Reader(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise BlockError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise BlockError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except tomllib.TOMLDecodeError as exc:
        raise BlockError(f"{path}: not a valid TOML file ({exc})") from None
    for key in data:
        if key not in _SECTIONS:
            raise r.error(f"[{key}]", data[key] if not isinstance(data[key], dict) else key,
                          f"unknown table (a block file has {', '.join(f'[{s}]' for s in _SECTIONS)})")
    component = data.get("component")
    if not isinstance(component, dict):
        raise r.error("[component]", component, "missing or not a table: give [component] with name = \"...\"")
    for key in component:
        if key not in ("name", "description"):
            raise r.error(f"[component] {key}", component[key], "unknown field (name, description)")
    name = r.text("[component] name", component.get("name"))
    if not _IDENTIFIER.match(name) or name in _C_KEYWORDS:
        raise r.error("[component] name", name, "not a C and FMI model identifier (a letter, then letters, digits "
                      "or _; at most 63 characters): it names the FMU's library")
    description = r.text("[component] description", component.get("description"), name)

    seen: dict[str, str] = {}
    entries: dict[str, list[tuple[str, dict]]] = {}
    for section in _SECTIONS[1:]:
        table = data.get(section, {})
        if not isinstance(table, dict):
            raise r.error(f"[{section}]", table, "expected a table of named entries")
        entries[section] = []
        for entry_name, entry in table.items():
            field = f"[{section}.{entry_name}]"
            if not _IDENTIFIER.match(entry_name) or entry_name in _C_KEYWORDS:
                raise r.error(field, entry_name, "not a C and FMI-safe identifier (a letter, then letters, digits "
                              "or _; at most 63 characters; not a C keyword)")
            if entry_name in RESERVED_NAMES:
                raise r.error(field, entry_name, f"reserved (the FMU's own variables and the expressions' functions "
                              f"and constants: {', '.join(sorted(RESERVED_NAMES))})")
            if entry_name in seen:
                raise r.error(field, entry_name, f"duplicate name: already declared in [{seen[entry_name]}]")
            seen[entry_name] = section
            if not isinstance(entry, dict):
                raise r.error(field, entry, "expected a table (e.g. { unit = \"V\", ... })")
            for key in entry:
                if key not in _KEYS[section]:
                    raise r.error(f"{field} {key}", entry[key],
                                  f"unknown field (a {section[:-1]} has {', '.join(sorted(_KEYS[section]))})")
            entries[section].append((entry_name, entry))
    for state_name, _ in entries["states"]:
        if f"{state_name}_start" in seen:
            raise r.error(f"[{seen[f'{state_name}_start']}.{state_name}_start]", f"{state_name}_start",
                          f"reserved: the FMU names state {state_name}'s start value so")

    parameters = []
    for pname, e in entries["parameters"]:
        f = f"[parameters.{pname}]"
        if "value" not in e:
            raise r.error(f"{f} value", None, "missing: a parameter needs a value")
        value = r.number(f"{f} value", e["value"])
        lo = r.number(f"{f} min", e["min"]) if "min" in e else None
        hi = r.number(f"{f} max", e["max"]) if "max" in e else None
        positive = e.get("positive", False)
        if not isinstance(positive, bool):
            raise r.error(f"{f} positive", positive, "expected true or false")
        if positive and not value > 0:
            raise r.error(f"{f} value", e["value"], "must be > 0 (positive = true)")
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise r.error(f"{f} value", e["value"], f"outside [{lo}, {hi}]")
        parameters.append(BlockParameter(pname, value, r.unit(f"{f} unit", e.get("unit")),
                                         r.text(f"{f} description", e.get("description"), pname), lo, hi, positive))
    inputs = tuple(BlockInput(n, r.number(f"[inputs.{n}] start", e.get("start"), 0.0),
                              r.unit(f"[inputs.{n}] unit", e.get("unit")),
                              r.text(f"[inputs.{n}] description", e.get("description"), n))
                   for n, e in entries["inputs"])
    states = []
    for sname, e in entries["states"]:
        f = f"[states.{sname}]"
        if "derivative" not in e:
            raise r.error(f"{f} derivative", None, "missing: every state needs its time derivative (an expression)")
        states.append(BlockState(sname, r.number(f"{f} start", e.get("start"), 0.0), r.unit(f"{f} unit", e.get("unit")),
                                 r.text(f"{f} description", e.get("description"), sname),
                                 r.text(f"{f} derivative", e["derivative"])))

    def expressions(section: str) -> list[BlockExpression]:
        out = []
        for n, e in entries[section]:
            f = f"[{section}.{n}]"
            if "expression" not in e:
                raise r.error(f"{f} expression", None, "missing: give its expression")
            out.append(BlockExpression(n, r.text(f"{f} expression", e["expression"]), r.unit(f"{f} unit", e.get("unit")),
                                       r.text(f"{f} description", e.get("description"), n)))
        return out

    intermediates = expressions("intermediates")
    outputs = expressions("outputs")
    if not outputs:
        raise r.error("[outputs]", {}, "a component needs at least one output")

    # values at the start (parameters, inputs' and states' starts) to check each expression at
    values = {p.name: p.value for p in parameters}
    values.update({u.name: u.start for u in inputs})
    values.update({s.name: s.start for s in states})
    ordered = _order_intermediates(r, intermediates, set(values))
    for item in ordered:
        values[item.name] = _checked(r, f"[intermediates.{item.name}] expression", item.expression, values)
    for s in states:
        _checked(r, f"[states.{s.name}] derivative", s.derivative, values)
    for o in outputs:
        _checked(r, f"[outputs.{o.name}] expression", o.expression, values)
    return Block(name, description, path, tuple(parameters), inputs, tuple(states), tuple(ordered), tuple(outputs))


def _checked(r: _Reader, field: str, text: str, values: dict[str, float]) -> float:
    try:
        return check_expression(text, values, "parameters, inputs, states and intermediates", BLOCK_FUNCTIONS)
    except ExpressionError as exc:
        raise r.error(field, text, str(exc)) from None


def _names_in(text: str) -> set[str]:
    return set(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", text))


def _order_intermediates(r: _Reader, items: list[BlockExpression], known: set[str]) -> list[BlockExpression]:
    """The intermediates in an order where each uses only known names and those before it; a
    cycle among them is refused naming it."""
    by_name = {i.name: i for i in items}
    uses = {i.name: _names_in(i.expression) & set(by_name) for i in items}
    ordered, done, visiting = [], set(), []

    def visit(name: str) -> None:
        if name in done:
            return
        if name in visiting:
            cycle = visiting[visiting.index(name):] + [name]
            raise r.error(f"[intermediates.{cycle[0]}] expression", by_name[cycle[0]].expression,
                          f"the intermediates use each other in a cycle: {' -> '.join(cycle)}")
        visiting.append(name)
        for other in sorted(uses[name]):
            visit(other)
        visiting.pop()
        done.add(name)
        ordered.append(by_name[name])

    for item in items:
        visit(item.name)
    return ordered

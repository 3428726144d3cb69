"""A component's block file (docs/components.md), read as untrusted data into a :class:`Block`.

The file is TOML: ``[component]`` (name, description), then tables of named entries:
``[parameters.NAME]`` (value, unit, description, min, max, positive), ``[inputs.NAME]`` (unit,
start, description), ``[states.NAME]`` (unit, start, derivative, description),
``[intermediates.NAME]`` and ``[outputs.NAME]`` (expression, unit, description).  Every
expression goes through the mechanisms' whitelist parser (``mechanism.expressions``: never
``eval``), with four functions more (``min``, ``max``, ``round``, ``quantise``: BLOCK_FUNCTIONS).
Every mistake is named in one :class:`BlockError` (all of a readable file's at once, one a
line), each with the file, the field and the value.
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


def _quantise(x: float, step: float) -> float:
    from .functions import quantise_value
    return quantise_value(x, step)


#: The functions a block expression may call: the mechanisms' and min, max (two arguments),
#: round (half away from zero, as C's round()) and quantise(x, step) (step round(x / step), or x
#: when step is 0: no quantisation).
BLOCK_FUNCTIONS = {
    **FUNCTIONS,
    "min": ExpressionFunction("Min", min, 2),
    "max": ExpressionFunction("Max", max, 2),
    "round": ExpressionFunction("round", _round_half_away, 1, build=_build("Round")),
    "quantise": ExpressionFunction("quantise", _quantise, 2, build=_build("Quantise")),
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
    """Reads one file's tables, noting each problem with the file's field and value named
    (``problems``); the readers return a stand-in after a problem so that reading goes on and
    every mistake of the file is listed at once (:meth:`raise_problems`)."""

    def __init__(self, path: Path):
        self.path = path
        self.problems: list[str] = []

    def error(self, field: str, value, why: str) -> BlockError:
        return BlockError(f"{self.path}: {self._text(field, value, why)}")

    @staticmethod
    def _text(field: str, value, why: str) -> str:
        shown = repr(value)
        if len(shown) > 80:
            shown = shown[:77] + "..."
        return f"{field} = {shown}: {why}"

    def problem(self, field: str, value, why: str) -> None:
        self.problems.append(self._text(field, value, why))

    def raise_problems(self) -> None:
        """One BlockError naming the file and listing every problem noted (one a line)."""
        if len(self.problems) == 1:
            raise BlockError(f"{self.path}: {self.problems[0]}")
        if self.problems:
            raise BlockError(f"{self.path}: {len(self.problems)} problems:" + "".join(f"\n  {p}" for p in self.problems))

    def text(self, field: str, value, default: str | None = None) -> str:
        if value is None and default is not None:
            return default
        if not isinstance(value, str):
            self.problem(field, value, "expected a text (in quotes)")
            return default if default is not None else ""
        return value

    def number(self, field: str, value, default: float | None = None) -> float | None:
        """The value as a float; None (after noting why) when it is not a finite number."""
        if value is None and default is not None:
            return default
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.problem(field, value, "expected a number")
            return None
        if not math.isfinite(value):
            self.problem(field, value, "must be finite")
            return None
        return float(value)

    def unit(self, field: str, value) -> str:
        unit = self.text(field, value, "1")
        if unit not in BLOCK_UNITS:
            self.problem(field, value, f"unknown unit (known: {', '.join(BLOCK_UNITS)})")
            return "1"
        return unit


#: The value an entry whose own value is refused stands at while the rest of the file is checked.
_STAND_IN = 1.0


def load_block(source: str | Path) -> Block:
    """The :class:`Block` of a shipped component's name (fmu_src/components/NAME.toml) or a
    block file's path; raises :class:`BlockError` for any mistake, naming file, field and value:
    every mistake of a readable file at once, one a line (as mechanism and system files do)."""
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
    except (RecursionError, MemoryError) as exc:
        raise BlockError(f"{path}: not usable TOML: nested too deeply ({type(exc).__name__})") from None
    except ValueError as exc:          # tomllib: an integer of more than 4300 digits
        raise BlockError(f"{path}: not usable TOML: {exc}") from None
    for key in data:
        if key not in _SECTIONS:
            r.problem(f"[{key}]", data[key] if not isinstance(data[key], dict) else key,
                      f"unknown table (a block file has {', '.join(f'[{s}]' for s in _SECTIONS)})")
    component = data.get("component")
    name, description = "Block", ""
    if not isinstance(component, dict):
        r.problem("[component]", component, "missing or not a table: give [component] with name = \"...\"")
    else:
        for key in component:
            if key not in ("name", "description"):
                r.problem(f"[component] {key}", component[key], "unknown field (name, description)")
        name = r.text("[component] name", component.get("name"))
        if name and (not _IDENTIFIER.match(name) or name in _C_KEYWORDS):
            r.problem("[component] name", name, "not a C and FMI model identifier (a letter, then letters, digits "
                      "or _; at most 63 characters): it names the FMU's library")
        description = r.text("[component] description", component.get("description"), name or "Block")

    seen: dict[str, str] = {}
    entries: dict[str, list[tuple[str, dict]]] = {}
    for section in _SECTIONS[1:]:
        table = data.get(section, {})
        entries[section] = []
        if not isinstance(table, dict):
            r.problem(f"[{section}]", table, "expected a table of named entries")
            continue
        for entry_name, entry in table.items():
            field = f"[{section}.{entry_name}]"
            if not _IDENTIFIER.match(entry_name) or entry_name in _C_KEYWORDS:
                r.problem(field, entry_name, "not a C and FMI-safe identifier (a letter, then letters, digits "
                          "or _; at most 63 characters; not a C keyword)")
                continue
            if entry_name in RESERVED_NAMES:
                r.problem(field, entry_name, f"reserved (the FMU's own variables and the expressions' functions "
                          f"and constants: {', '.join(sorted(RESERVED_NAMES))})")
                continue
            if entry_name in seen:
                r.problem(field, entry_name, f"duplicate name: already declared in [{seen[entry_name]}]")
                continue
            seen[entry_name] = section
            if not isinstance(entry, dict):
                r.problem(field, entry, "expected a table (e.g. { unit = \"V\", ... })")
                continue
            for key in entry:
                if key not in _KEYS[section]:
                    r.problem(f"{field} {key}", entry[key],
                              f"unknown field (a {section[:-1]} has {', '.join(sorted(_KEYS[section]))})")
            entries[section].append((entry_name, entry))
    for state_name, _ in entries["states"]:
        if f"{state_name}_start" in seen:
            r.problem(f"[{seen[f'{state_name}_start']}.{state_name}_start]", f"{state_name}_start",
                      f"reserved: the FMU names state {state_name}'s start value so")

    parameters = []
    for pname, e in entries["parameters"]:
        f = f"[parameters.{pname}]"
        if "value" not in e:
            r.problem(f"{f} value", None, "missing: a parameter needs a value")
        value = r.number(f"{f} value", e["value"]) if "value" in e else None
        lo = r.number(f"{f} min", e["min"]) if "min" in e else None
        hi = r.number(f"{f} max", e["max"]) if "max" in e else None
        positive = e.get("positive", False)
        if not isinstance(positive, bool):
            r.problem(f"{f} positive", positive, "expected true or false")
            positive = False
        if value is not None and positive and not value > 0:
            r.problem(f"{f} value", e["value"], "must be > 0 (positive = true)")
        if value is not None and ((lo is not None and value < lo) or (hi is not None and value > hi)):
            r.problem(f"{f} value", e["value"], f"outside [{lo}, {hi}]")
        parameters.append(BlockParameter(pname, _STAND_IN if value is None else value, r.unit(f"{f} unit", e.get("unit")),
                                         r.text(f"{f} description", e.get("description"), pname), lo, hi, positive))

    def start(field: str, value) -> float:
        number = r.number(field, value, 0.0)
        return _STAND_IN if number is None else number

    inputs = tuple(BlockInput(n, start(f"[inputs.{n}] start", e.get("start")),
                              r.unit(f"[inputs.{n}] unit", e.get("unit")),
                              r.text(f"[inputs.{n}] description", e.get("description"), n))
                   for n, e in entries["inputs"])
    states = []
    for sname, e in entries["states"]:
        f = f"[states.{sname}]"
        if "derivative" not in e:
            r.problem(f"{f} derivative", None, "missing: every state needs its time derivative (an expression)")
        states.append(BlockState(sname, start(f"{f} start", e.get("start")), r.unit(f"{f} unit", e.get("unit")),
                                 r.text(f"{f} description", e.get("description"), sname),
                                 r.text(f"{f} derivative", e["derivative"]) if "derivative" in e else "0"))

    def expressions(section: str) -> list[BlockExpression]:
        out = []
        for n, e in entries[section]:
            f = f"[{section}.{n}]"
            if "expression" not in e:
                r.problem(f"{f} expression", None, "missing: give its expression")
            out.append(BlockExpression(n, r.text(f"{f} expression", e["expression"]) if "expression" in e else "0",
                                       r.unit(f"{f} unit", e.get("unit")),
                                       r.text(f"{f} description", e.get("description"), n)))
        return out

    intermediates = expressions("intermediates")
    outputs = expressions("outputs")
    if not outputs and not any(p.startswith("[outputs") for p in r.problems):
        r.problem("[outputs]", {}, "a component needs at least one output")

    # values at the start (parameters, inputs' and states' starts) to check each expression at
    values = {p.name: p.value for p in parameters}
    values.update({u.name: u.start for u in inputs})
    values.update({s.name: s.start for s in states})
    ordered = _order_intermediates(r, intermediates, set(values))
    if ordered is None:                # a cycle: the intermediates stand in, the rest is checked
        ordered = intermediates
        values.update({item.name: _STAND_IN for item in intermediates})
    else:
        for item in ordered:
            values[item.name] = _checked(r, f"[intermediates.{item.name}] expression", item.expression, values)
    for s in states:
        _checked(r, f"[states.{s.name}] derivative", s.derivative, values)
    for o in outputs:
        _checked(r, f"[outputs.{o.name}] expression", o.expression, values)
    r.raise_problems()
    return Block(name, description, path, tuple(parameters), inputs, tuple(states), tuple(ordered), tuple(outputs))


def _checked(r: _Reader, field: str, text: str, values: dict[str, float]) -> float:
    """The expression's value at ``values``; a stand-in after noting why it is refused."""
    try:
        return check_expression(text, values, "parameters, inputs, states and intermediates", BLOCK_FUNCTIONS)
    except ExpressionError as exc:
        r.problem(field, text, str(exc))
        return _STAND_IN


def _names_in(text: str) -> set[str]:
    return set(re.findall(r"[A-Za-z_][A-Za-z0-9_]*", text))


def _order_intermediates(r: _Reader, items: list[BlockExpression], known: set[str]) -> list[BlockExpression] | None:
    """The intermediates in an order where each uses only known names and those before it; a
    cycle among them is refused naming it (None, after noting it)."""
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

    try:
        for item in items:
            visit(item.name)
    except BlockError as exc:
        r.problems.append(str(exc).removeprefix(f"{r.path}: "))
        return None
    return ordered

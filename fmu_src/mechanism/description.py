"""A planar mechanism described in a TOML file: loading and checking (build time only).

The file format is taught in docs/mechanisms.md, with fmu_src/mechanisms/slider_crank.toml as
the worked example.  This module turns a file into a :class:`Mechanism` (typed, immutable) or
raises :class:`MechanismError` with a message that names the file and the item at fault.
What needs numbers (is the mechanism assembled at its start values? are its constraints
independent?) is checked by ``fmu_src.mechanism.check``, after the derivation.

Conventions, stated once:
- every body has its centre of mass at its own origin; a point of a body is given in the
  body's frame (x along the body's axis, angles counter-clockwise from the global +x);
- lengths, masses and rates are in SI units; angles in the file (guesses, start values,
  prismatic directions) are in degrees unless a parameter says ``unit = "rad"``;
- gravity acts along -y.
"""
from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

from typing import TYPE_CHECKING

from .expressions import MAX_MAGNITUDE, ExpressionError, check_expression, parse_expression

if TYPE_CHECKING:      # sympy is imported once every expression of the file has passed its checks
    import sympy as sp

__all__ = ["Mechanism", "Parameter", "Body", "PointRef", "Joint", "Driver", "Spring", "Friction", "Load", "Input", "StartValue", "ExpressionOutput",
           "MechanismError", "load_mechanism", "parse_mechanism", "MECHANISM_DIR", "resolve_mechanism",
           "shipped_mechanisms", "PUBLISHED_BENCHMARKS", "SYSTEM_MECHANISMS", "RATE_PREFIX", "POSITIVE"]

#: Where the shipped mechanism files live (``--mechanism NAME`` looks here).
MECHANISM_DIR = Path(__file__).resolve().parent.parent / "mechanisms"
#: The smallest positive normal double: as an (inclusive) FMI min it says "greater than zero".
POSITIVE = 2.2250738585072014e-308
#: A coordinate's rate: theta2 -> omega2, x4 -> vx4, y4 -> vy4.
RATE_PREFIX = {"theta": "omega", "x": "vx", "y": "vy"}
_UNITS = {"m", "kg", "kg.m2", "m/s2", "rad", "deg", "rad/s", "m/s", "1", "N", "N.m", "J", "s", "W",
          "N/m", "N.s/m", "N.m/rad", "N.m.s/rad"}
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
#: Longest description, characters.
MAX_TEXT = 2000
_RESERVED = {"t", "rtol", "atol", "integrator", "energy", "constraint_residual", "ground", "pi", "E", "I"}


class MechanismError(ValueError):
    """A mechanism file that cannot be used; the message names the file and the item."""


@dataclass(frozen=True)
class Parameter:
    """A model parameter of the FMU (tunable unless ``fixed``), in SI units."""

    name: str
    value: float
    unit: str                 # the FMU's unit ("rad" for a parameter given in degrees)
    description: str
    minimum: float | None = None
    maximum: float | None = None
    fixed: bool = False
    display_unit: str | None = None   # "deg" when the file gave degrees


@dataclass(frozen=True)
class PointRef:
    """A named point of a body ("ground" for the fixed frame)."""

    body: str
    point: str

    def __str__(self) -> str:
        return f"{self.body}.{self.point}"


@dataclass(frozen=True)
class Body:
    """A rigid body: a slender rod (I = m L^2/12) or a block with a given inertia."""

    name: str
    label: str                          # its variables are x<label>, y<label>, theta<label>
    kind: str                           # "rod" or "block"
    mass: sp.Expr
    inertia: sp.Expr                    # about the centre of mass
    rotates: bool                       # False: no angle coordinate (a block that only translates)
    points: dict[str, tuple[sp.Expr, sp.Expr]]   # name -> (x, y) in the body frame
    guess: tuple[float, float, float]   # (x, y, angle in rad) where assembly starts
    description: str
    length: sp.Expr | None = None

    @property
    def coordinates(self) -> tuple[str, ...]:
        return (f"x{self.label}", f"y{self.label}") + ((f"theta{self.label}",) if self.rotates else ())


@dataclass(frozen=True)
class Joint:
    """A revolute joint (two points coincide) or a prismatic one (the second point stays on
    a line through the first, fixed in the first body; if the second body rotates, its angle
    equals the first body's: the slider's frame turns with the guide's)."""

    name: str
    type: str                      # "revolute" or "prismatic"
    first: PointRef
    second: PointRef
    angle: float = 0.0             # prismatic: the line's direction in the first body's frame, rad


@dataclass(frozen=True)
class Driver:
    """A joint coordinate prescribed in time: constant speed from a start value, or a function
    of time.

    Revolute joint: the second body's angle relative to the first's; prismatic joint: the
    second point's position along the line.  Either ``start`` and ``speed`` name parameters
    (``position`` None), or ``position`` is the coordinate as a sympy expression of the
    parameters and the absolute time ``t`` (``start`` and ``speed`` None).
    """

    name: str
    joint: str
    start: str | None
    speed: str | None
    position: sp.Expr | None = None
    input: str | None = None        # the [[inputs]] entry whose variables give the position


@dataclass(frozen=True)
class Spring:
    """A spring-damper on a coordinate s of the mechanism: point-to-point (``first``,
    ``second``: s the distance between the points, a force) or rotational at a revolute joint
    (``joint``: s its second body's angle minus its first's, a torque).  What it exerts,
    ``preload + stiffness (s - length) + damping ds/dt``, is positive when it pulls the points
    together or turns the second body back towards the first (clockwise on it for s > length);
    every coefficient an expression of the parameters."""

    name: str
    first: PointRef | None      # point-to-point: the two points
    second: PointRef | None
    stiffness: sp.Expr          # N/m or N.m/rad
    damping: sp.Expr            # N.s/m or N.m.s/rad
    length: sp.Expr             # free length (m) or free angle (rad)
    preload: sp.Expr            # N or N.m at s = length
    joint: str | None = None    # rotational: the revolute joint


@dataclass(frozen=True)
class Friction:
    """Friction at a revolute or prismatic joint, on its coordinate s (the relative angle,
    second body minus first, or the position along the line) and its rate v = ds/dt:
    ``viscous v + coulomb tanh(v / velocity_scale)``, a torque (N.m) or force (N) opposing v
    (the Coulomb part regularised, see docs/mechanisms.md); every coefficient an expression of
    the parameters."""

    name: str
    joint: str
    kind: str                   # "revolute" or "prismatic"
    viscous: sp.Expr            # N.m.s/rad or N.s/m
    coulomb: sp.Expr            # N.m or N
    velocity_scale: sp.Expr     # rad/s or m/s, > 0


@dataclass(frozen=True)
class Load:
    """An applied load of constant size (an expression of the parameters, so tunable): a torque
    on a body (``torque``, N.m, counter-clockwise positive) or a force at a body point
    (``force``, N, its x and y components in the global frame or in the body's frame)."""

    name: str
    body: str                              # the body it acts on
    torque: sp.Expr | None = None
    force: tuple[sp.Expr, sp.Expr] | None = None
    point: PointRef | None = None          # force: where it acts
    frame: str = "global"                  # force: "global" or "body"


@dataclass(frozen=True)
class InputVariable:
    """One FMI input variable (``causality="input"``, ``variability="continuous"``)."""

    name: str
    unit: str
    start: float
    description: str


#: An input's kinds: what its value is, and its unit (a position's: that of its joint).
INPUT_KINDS = ("torque", "force", "position")


@dataclass(frozen=True)
class Input:
    """An ``[[inputs]]`` entry: what an FMI input variable pushes or moves.

    - ``torque`` on a ``body`` (N.m, counter-clockwise positive), or at a revolute ``joint``
      (on its second body, minus on its first: virtual work u d(theta2 - theta1));
    - ``force`` at a prismatic ``joint`` (N, along its line, on the second body, minus on the
      first), or at a ``point`` along a unit ``direction`` in the ``frame`` "global" or "body";
    - ``position`` of a ``joint``: a driver (named like the input) whose joint coordinate is the
      input ``name`` (rad or m), with its rate ``name_d`` and acceleration ``name_dd`` inputs too.
    """

    name: str
    kind: str                                  # one of INPUT_KINDS
    start: float
    description: str
    body: str | None = None                    # torque on a body
    joint: str | None = None                   # torque (revolute), force (prismatic), position
    joint_type: str | None = None              # the joint's type
    point: PointRef | None = None              # force at a point
    direction: tuple[float, float] | None = None   # its unit direction
    frame: str = "global"                      # the direction's frame: "global" or "body"

    @property
    def variables(self) -> tuple[InputVariable, ...]:
        """Its FMI input variables: one, or three for a position (value, rate, acceleration)."""
        if self.kind == "torque":
            return (InputVariable(self.name, "N.m", self.start, self.description),)
        if self.kind == "force":
            return (InputVariable(self.name, "N", self.start, self.description),)
        unit = "rad" if self.joint_type == "revolute" else "m"
        return (InputVariable(self.name, unit, self.start, self.description),
                InputVariable(f"{self.name}_d", f"{unit}/s", 0.0,
                              f"Rate of {self.name}, its first time derivative [{unit}/s]"),
                InputVariable(f"{self.name}_dd", f"{unit}/s2", 0.0,
                              f"Acceleration of {self.name}, its second time derivative [{unit}/s2]"))


@dataclass(frozen=True)
class StartValue:
    """The start value of an independent coordinate or of its rate (a fixed FMU parameter
    named ``<coordinate>_start``)."""

    coordinate: str
    value: float               # SI (rad, m, rad/s, m/s)
    unit: str
    description: str
    display_unit: str | None = None

    @property
    def parameter(self) -> str:
        return f"{self.coordinate}_start"


@dataclass(frozen=True)
class ExpressionOutput:
    """An output the file defines as an expression (``[outputs.expressions]``) of the parameters,
    the body coordinates (``theta3``: the symbol of q) and their rates (``omega3``: the symbol
    ``theta3_d`` of qd), e.g. a relative angle ``theta3 - theta2``."""

    name: str
    expression: sp.Expr
    unit: str                      # SI ("rad" for an output given in "deg")
    description: str
    display_unit: str | None = None


@dataclass(frozen=True)
class Mechanism:
    """A mechanism description, checked for consistency of its names (see the module doc)."""

    name: str                      # the FMU's model name (a C identifier)
    description: str
    source: str                    # the file it came from
    gravity: str | None            # parameter name of g (acting along -y), or None
    parameters: tuple[Parameter, ...]
    ground: dict[str, tuple[sp.Expr, sp.Expr]]
    bodies: tuple[Body, ...]
    joints: tuple[Joint, ...]
    drivers: tuple[Driver, ...]
    start: tuple[StartValue, ...]  # per independent coordinate: its value, then its rate
    outputs: tuple[str, ...] | None    # None: every output (see derivation.available_outputs)
    expression_outputs: tuple[ExpressionOutput, ...] = ()   # after ``outputs``, in file order
    springs: tuple[Spring, ...] = ()
    friction: tuple[Friction, ...] = ()
    loads: tuple[Load, ...] = ()
    inputs: tuple[Input, ...] = ()

    @property
    def independent(self) -> tuple[str, ...]:
        """The independent coordinates whose start values the file gives, in file order."""
        return tuple(s.coordinate for s in self.start[::2])

    @property
    def coordinates(self) -> tuple[str, ...]:
        return tuple(c for b in self.bodies for c in b.coordinates)

    def body(self, name: str) -> Body:
        return next(b for b in self.bodies if b.name == name)


#: Shipped mechanisms that reproduce a published benchmark, with the span (s) their publication
#: gives a reference solution for.  Andrews' squeezer is driven by a constant torque with nothing
#: to stop it: its crank reaches ~1.2e4 rad/s by 1 s and ~5.5e4 rad/s by 5 s (native FMU at
#: rtol = atol = 1e-12: 2 s and 36 s of CPU), so runs of several seconds say nothing about it and
#: cost minutes.  Loops over the shipped machines for such runs (tests and benchmarks) leave these
#: out (``shipped_mechanisms(benchmarks=False)``); each has its own test against its publication.
#: The IFToMM simple pendulum (A01) is cheap but its reference spans 2000 s: its test runs that.
PUBLISHED_BENCHMARKS = {"andrews_squeezer": 0.03, "iftomm_pendulum": 2000.0}
#: Shipped mechanisms made to be a component of a system (systems/, docs/systems.md), each with
#: the system file that uses it: an input another FMU sets drives them (a free crank turned by a
#: motor's torque), so they have no case of their own; tests/test_system_build.py builds and
#: runs them, the loops over the shipped mechanisms leave them out.
SYSTEM_MECHANISMS = {"fourbar_motor": "systems/motor_fourbar.toml"}


def shipped_mechanisms(*, benchmarks: bool = True, systems: bool = False) -> tuple[str, ...]:
    """Names of the mechanism files in fmu_src/mechanisms/ (without the PUBLISHED_BENCHMARKS
    when ``benchmarks`` is false; with the SYSTEM_MECHANISMS only when ``systems`` is true)."""
    names = sorted(p.stem for p in MECHANISM_DIR.glob("*.toml"))
    return tuple(n for n in names if (benchmarks or n not in PUBLISHED_BENCHMARKS)
                 and (systems or n not in SYSTEM_MECHANISMS))


def resolve_mechanism(name_or_path: str) -> Path:
    """The file of a shipped mechanism name (``slider_crank``) or a path to a .toml file."""
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.parent != Path("."):
        if not path.is_file():
            raise MechanismError(f"{name_or_path}: no such mechanism file")
        return path
    shipped = MECHANISM_DIR / f"{name_or_path}.toml"
    if not shipped.is_file():
        raise MechanismError(f"unknown mechanism {name_or_path!r}: the shipped ones are "
                             f"{', '.join(shipped_mechanisms(systems=True))}; or give the path of a .toml file")
    return shipped


def load_mechanism(name_or_path: str | Path) -> Mechanism:
    """Read and check a mechanism file (a shipped name or a path)."""
    path = resolve_mechanism(str(name_or_path))
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise MechanismError(f"{path}: not valid TOML: {exc}") from None
    except (RecursionError, MemoryError) as exc:    # arrays or tables nested thousands deep
        raise MechanismError(f"{path}: not usable TOML: nested too deeply ({type(exc).__name__})") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise MechanismError(f"{path}: cannot be read: {exc}") from None
    except ValueError as exc:          # tomllib: an integer of more than 4300 digits
        raise MechanismError(f"{path}: not usable TOML: {exc}") from None
    return parse_mechanism(data, str(path))


class _Reader:
    """Typed access to the TOML tables, each error naming the file and the item."""

    def __init__(self, source: str):
        self.source = source

    def fail(self, where: str, message: str) -> MechanismError:
        return MechanismError(f"{self.source}: {where}: {message}")

    def table(self, data, key: str, where: str, required: bool = True) -> dict:
        value = data.get(key)
        if value is None:
            if required:
                raise self.fail(where, f"missing '{key}'")
            return {}
        if not isinstance(value, dict):
            raise self.fail(where, f"'{key}' must be a table, got {type(value).__name__}")
        return value

    def string(self, data, key: str, where: str, default: str | None = None) -> str:
        value = data.get(key, default)
        if value is None:
            raise self.fail(where, f"missing '{key}'")
        if not isinstance(value, str) or not value:
            raise self.fail(where, f"'{key}' must be a non-empty string, got {value!r}")
        return value

    def text(self, data, key: str, where: str, default: str) -> str:
        """A free text (a description): a string of printable characters, at most MAX_TEXT long
        (it goes into the model description's XML, where control characters are not allowed,
        and into comments of the generated code)."""
        value = data.get(key, default)
        if not isinstance(value, str):
            raise self.fail(where, f"'{key}' must be a string, got {type(value).__name__}")
        if len(value) > MAX_TEXT:
            raise self.fail(where, f"'{key}' is {len(value)} characters long; at most {MAX_TEXT}")
        bad = next((c for c in value if not c.isprintable()), None)
        if bad is not None:
            raise self.fail(where, f"'{key}' contains the control or separator character U+{ord(bad):04X} "
                                   f"(printable characters only: no line breaks or tabs)")
        return value

    def number(self, data, key: str, where: str, default: float | None = None) -> float:
        value = data.get(key, default)
        if value is None:
            raise self.fail(where, f"missing '{key}'")
        if isinstance(value, int) and not isinstance(value, bool) and abs(value) > MAX_MAGNITUDE:
            raise self.fail(where, f"'{key}' must be at most {MAX_MAGNITUDE:g} in magnitude, got a number of "
                                   f"{len(str(abs(value)))} digits")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.fail(where, f"'{key}' must be a finite number, got {value!r}")
        return float(value)

    def unknown_keys(self, data: dict, allowed: set, where: str) -> None:
        extra = sorted(set(data) - allowed)
        if extra:
            raise self.fail(where, f"unknown key{'s' if len(extra) > 1 else ''} {', '.join(map(repr, extra))} "
                                   f"(allowed: {', '.join(sorted(allowed))})")


@dataclass(frozen=True)
class _Scope:
    """What an expression may name: the parameters' symbols and their values (SI) in the file."""

    symbols: dict[str, sp.Symbol]
    values: dict[str, float]


def _shown(text: str) -> str:
    """``text`` as a message quotes it: repr, cut after 80 characters (its length then said)."""
    return repr(text) if len(text) <= 80 else f"{text[:80]!r}... ({len(text)} characters)"


def _expression(reader: _Reader, value, where: str, scope: _Scope) -> sp.Expr:
    """A number, or a string expression over the parameters (e.g. "L1", "-L2/2"), read by
    ``expressions.parse_expression`` (a whitelist parser: the text is data, never run)."""
    import sympy as sp

    if isinstance(value, bool):
        raise reader.fail(where, f"expected a number or an expression of parameters, got {value!r}")
    if isinstance(value, (int, float)):
        if isinstance(value, int) and abs(value) > MAX_MAGNITUDE:
            raise reader.fail(where, f"must be at most {MAX_MAGNITUDE:g} in magnitude, got a number of "
                                     f"{len(str(abs(value)))} digits")
        if not math.isfinite(value) or abs(value) > MAX_MAGNITUDE:
            raise reader.fail(where, f"must be finite and at most {MAX_MAGNITUDE:g} in magnitude, got {value!r}")
        return sp.Float(value) if isinstance(value, float) else sp.Integer(value)
    if not isinstance(value, str):
        raise reader.fail(where, f"expected a number or an expression of parameters, got {_shown(repr(value))}")
    try:
        return parse_expression(value, scope.symbols, scope.values)
    except ExpressionError as exc:
        raise reader.fail(where, f"{_shown(value)} {exc}") from None


def _parameters(reader: _Reader, table: dict) -> tuple[Parameter, ...]:
    out = []
    for name, spec in table.items():
        where = f"parameters.{name}"
        if not _NAME.match(name) or name in _RESERVED:
            raise reader.fail(where, f"{name!r} cannot be a parameter name (letters, digits and _, starting "
                                     f"with a letter; not one of {', '.join(sorted(_RESERVED))})")
        if not isinstance(spec, dict):
            raise reader.fail(where, "must be a table, e.g. { value = 1.0, unit = \"m\", description = \"...\" }")
        reader.unknown_keys(spec, {"value", "unit", "description", "min", "max", "positive", "fixed"}, where)
        unit = reader.string(spec, "unit", where, "1")
        if unit not in _UNITS:
            raise reader.fail(where, f"unit {unit!r} is not one of {', '.join(sorted(_UNITS))}")
        value = reader.number(spec, "value", where)
        minimum = reader.number(spec, "min", where) if "min" in spec else None
        maximum = reader.number(spec, "max", where) if "max" in spec else None
        positive = spec.get("positive", False)
        if not isinstance(positive, bool):
            raise reader.fail(where, f"'positive' must be true or false, got {positive!r}")
        fixed = spec.get("fixed", False)
        if not isinstance(fixed, bool):
            raise reader.fail(where, f"'fixed' must be true or false, got {fixed!r}")
        display = None
        if unit == "deg":
            unit, display = "rad", "deg"
            value = math.radians(value)
            minimum = None if minimum is None else math.radians(minimum)
            maximum = None if maximum is None else math.radians(maximum)
        if positive:
            minimum = POSITIVE if minimum is None else max(minimum, POSITIVE)
        if (minimum is not None and value < minimum) or (maximum is not None and value > maximum) \
                or (positive and not value > 0.0):
            raise reader.fail(where, f"value {value!r} is outside its own range "
                                     f"[{minimum if minimum is not None else '-inf'}, "
                                     f"{maximum if maximum is not None else 'inf'}]")
        out.append(Parameter(name, value, unit, reader.text(spec, "description", where, name),
                             minimum, maximum, fixed, display))
    if not out:
        raise reader.fail("parameters", "a mechanism needs at least one parameter (its lengths and masses)")
    return tuple(out)


def _point_pair(reader: _Reader, value, where: str, scope: _Scope) -> tuple[sp.Expr, sp.Expr]:
    if not isinstance(value, list) or len(value) != 2:
        raise reader.fail(where, f"a point is [x, y] (numbers or parameter expressions), got {value!r}")
    return (_expression(reader, value[0], f"{where}[0]", scope),
            _expression(reader, value[1], f"{where}[1]", scope))


def _check_expressions(reader: _Reader, data: dict, values: dict[str, float]) -> None:
    """Every expression of the file checked (``expressions.check_expression``, no sympy) before
    anything is built: a refusal does not wait for sympy's import (about 0.7 s of CPU).  Only
    what has the expected shape is checked; the main pass reports the rest, with the same
    field names."""
    def check(value, where: str) -> None:
        if isinstance(value, str):
            try:
                check_expression(value, values)
            except ExpressionError as exc:
                raise reader.fail(where, f"{_shown(value)} {exc}") from None

    def pair(value, where: str) -> None:
        if isinstance(value, list) and len(value) == 2:
            check(value[0], f"{where}[0]")
            check(value[1], f"{where}[1]")

    ground = data.get("ground")
    if isinstance(ground, dict) and isinstance(ground.get("points"), dict):
        for name, value in ground["points"].items():
            pair(value, f"ground.points.{name}")
    bodies = data.get("bodies")
    for k, spec in enumerate(bodies if isinstance(bodies, list) else ()):
        if not isinstance(spec, dict) or not isinstance(spec.get("name"), str) or not spec["name"]:
            continue
        where = f"bodies[{k}] '{spec['name']}'"
        for key in ("mass", "length", "inertia"):
            check(spec.get(key), f"{where}.{key}")
        if isinstance(spec.get("points"), dict):
            for name, value in spec["points"].items():
                pair(value, f"{where}.points.{name}")
    springs = data.get("springs")
    for k, spec in enumerate(springs if isinstance(springs, list) else ()):
        if not isinstance(spec, dict) or not isinstance(spec.get("name"), str) or not spec["name"]:
            continue
        for key in ("stiffness", "damping", "length", "angle", "preload"):
            check(spec.get(key), f"springs[{k}] '{spec['name']}'.{key}")
    friction = data.get("friction")
    for k, spec in enumerate(friction if isinstance(friction, list) else ()):
        if not isinstance(spec, dict) or not isinstance(spec.get("name"), str) or not spec["name"]:
            continue
        for key in ("viscous", "coulomb", "velocity_scale"):
            check(spec.get(key), f"friction[{k}] '{spec['name']}'.{key}")


def _bodies(reader: _Reader, items, scope: _Scope) -> tuple[Body, ...]:
    import sympy as sp

    if not isinstance(items, list) or not items:
        raise reader.fail("bodies", "a mechanism needs at least one [[bodies]] entry")
    bodies, labels = [], {}
    for k, spec in enumerate(items):
        where = f"bodies[{k}]"
        if not isinstance(spec, dict):
            raise reader.fail(where, "must be a table")
        name = reader.string(spec, "name", where)
        where = f"bodies[{k}] '{name}'"
        reader.unknown_keys(spec, {"name", "label", "kind", "length", "mass", "inertia", "rotates", "points",
                                   "angle", "x", "y", "description"}, where)
        if not _NAME.match(name) or name == "ground":
            raise reader.fail(where, "a body name is letters, digits and _, starting with a letter, and not 'ground'")
        if any(b.name == name for b in bodies):
            raise reader.fail(where, "a second body with this name")
        label = str(spec.get("label", name))
        if not re.fullmatch(r"[A-Za-z0-9_]+", label):
            raise reader.fail(where, f"label {label!r}: letters, digits and _ only (it names x{label}, theta{label})")
        if label in labels:
            raise reader.fail(where, f"label {label!r} is already the label of body '{labels[label]}'")
        labels[label] = name
        kind = reader.string(spec, "kind", where)
        mass = _expression(reader, spec.get("mass"), f"{where}.mass", scope) if "mass" in spec else None
        if mass is None:
            raise reader.fail(where, "missing 'mass'")
        rotates = spec.get("rotates", True)
        if not isinstance(rotates, bool):
            raise reader.fail(where, f"'rotates' must be true or false, got {rotates!r}")
        points: dict[str, tuple[sp.Expr, sp.Expr]] = {"centre": (sp.Integer(0), sp.Integer(0))}
        length = None
        if kind == "rod":
            if "inertia" in spec:
                raise reader.fail(where, "a rod's inertia is m L^2/12; give 'inertia' only for kind = \"block\"")
            if not rotates:
                raise reader.fail(where, "a rod rotates; use kind = \"block\" for a body that only translates")
            length = _expression(reader, spec.get("length"), f"{where}.length", scope) if "length" in spec else None
            if length is None:
                raise reader.fail(where, "a rod needs 'length'")
            inertia = mass * length**2 / 12
            points["tail"] = (-length / 2, sp.Integer(0))
            points["tip"] = (length / 2, sp.Integer(0))
        elif kind == "block":
            if "length" in spec:
                raise reader.fail(where, "'length' is for rods; a block's points are given in 'points'")
            if rotates:
                if "inertia" not in spec:
                    raise reader.fail(where, "a block that rotates needs 'inertia' (kg.m2 about its centre of mass)")
                inertia = _expression(reader, spec["inertia"], f"{where}.inertia", scope)
            else:
                if "inertia" in spec:
                    raise reader.fail(where, "a block with rotates = false has no inertia to give")
                inertia = sp.Integer(0)
        else:
            raise reader.fail(where, f"kind {kind!r} is not \"rod\" or \"block\"")
        extra = spec.get("points", {})
        if not isinstance(extra, dict):
            raise reader.fail(where, "'points' must be a table of name = [x, y]")
        for pname, value in extra.items():
            if pname in points:
                raise reader.fail(where, f"point {pname!r} is predefined for a {kind}")
            if not _NAME.match(pname):
                raise reader.fail(where, f"point name {pname!r}: letters, digits and _, starting with a letter")
            points[pname] = _point_pair(reader, value, f"{where}.points.{pname}", scope)
        guess = (reader.number(spec, "x", where, 0.0), reader.number(spec, "y", where, 0.0),
                 math.radians(reader.number(spec, "angle", where, 0.0)))
        bodies.append(Body(name, label, kind, mass, inertia, rotates, points, guess,
                           reader.text(spec, "description", where, name), length))
    return tuple(bodies)


def _point_ref(reader: _Reader, value, where: str, bodies: dict[str, Body], ground: dict) -> PointRef:
    if not isinstance(value, str) or value.count(".") != 1:
        raise reader.fail(where, f"a point is written 'body.point' (e.g. 'crank.tip', 'ground.O'), got {value!r}")
    body, point = value.split(".")
    if body == "ground":
        if point not in ground:
            raise reader.fail(where, f"{value!r}: the ground has no point {point!r} "
                                     f"(ground points: {', '.join(ground) or 'none'})")
    elif body not in bodies:
        raise reader.fail(where, f"{value!r}: no body named {body!r} (bodies: {', '.join(bodies)}; or 'ground')")
    elif point not in bodies[body].points:
        raise reader.fail(where, f"{value!r}: body {body!r} has no point {point!r} "
                                 f"(its points: {', '.join(bodies[body].points)})")
    return PointRef(body, point)


def _joints(reader: _Reader, items, bodies: tuple[Body, ...], ground) -> tuple[Joint, ...]:
    if not isinstance(items, list) or not items:
        raise reader.fail("joints", "a mechanism needs at least one [[joints]] entry")
    by_name = {b.name: b for b in bodies}
    joints = []
    for k, spec in enumerate(items):
        where = f"joints[{k}]"
        if not isinstance(spec, dict):
            raise reader.fail(where, "must be a table")
        name = reader.string(spec, "name", where)
        where = f"joints[{k}] '{name}'"
        reader.unknown_keys(spec, {"name", "type", "connects", "angle"}, where)
        if not _NAME.match(name):
            raise reader.fail(where, "a joint name is letters, digits and _, starting with a letter")
        if any(j.name == name for j in joints):
            raise reader.fail(where, "a second joint with this name")
        kind = reader.string(spec, "type", where)
        if kind not in ("revolute", "prismatic"):
            raise reader.fail(where, f"type {kind!r} is not \"revolute\" or \"prismatic\" (planar joints only)")
        connects = spec.get("connects")
        if not isinstance(connects, list) or len(connects) != 2:
            raise reader.fail(where, "'connects' must name two points, e.g. [\"ground.O\", \"crank.tail\"]")
        first, second = (_point_ref(reader, v, f"{where}.connects", by_name, ground) for v in connects)
        if first.body == second.body:
            raise reader.fail(where, f"connects two points of the same body ({first.body!r})")
        angle = 0.0
        if kind == "prismatic":
            angle = math.radians(reader.number(spec, "angle", where, 0.0))
            guide_turns = first.body != "ground" and by_name[first.body].rotates
            if second.body != "ground" and not by_name[second.body].rotates and guide_turns:
                raise reader.fail(where, f"body {second.body!r} does not rotate, but slides on a guide of "
                                         f"{first.body!r}, which does: give {second.body!r} rotates = true")
            if second.body == "ground":
                raise reader.fail(where, "the sliding point (second) must be on a body; put the guide "
                                         "(first) on the ground")
        elif "angle" in spec:
            raise reader.fail(where, "'angle' is the line of a prismatic joint; a revolute joint has none")
        joints.append(Joint(name, kind, first, second, angle))
    connected = {r.body for j in joints for r in (j.first, j.second)}
    for body in bodies:
        if body.name not in connected:
            raise reader.fail(f"body '{body.name}'", "no joint connects it (missing constraints)")
    return tuple(joints)


def _drivers(reader: _Reader, items, joints, parameters, symbols: dict[str, sp.Symbol]) -> tuple[Driver, ...]:
    if items is None:
        return ()
    if not isinstance(items, list):
        raise reader.fail("drivers", "use [[drivers]] entries")
    params = {p.name: p for p in parameters}
    drivers = []
    for k, spec in enumerate(items):
        where = f"drivers[{k}]"
        if not isinstance(spec, dict):
            raise reader.fail(where, "must be a table")
        name = reader.string(spec, "name", where)
        where = f"drivers[{k}] '{name}'"
        reader.unknown_keys(spec, {"name", "joint", "start", "speed", "position"}, where)
        if not _NAME.match(name):
            raise reader.fail(where, "a driver name is letters, digits and _, starting with a letter")
        joint = reader.string(spec, "joint", where)
        if joint not in {j.name for j in joints}:
            raise reader.fail(where, f"drives joint {joint!r}, which does not exist "
                                     f"(joints: {', '.join(j.name for j in joints)})")
        if any(d.joint == joint for d in drivers):
            raise reader.fail(where, f"joint {joint!r} already has a driver")
        if "position" in spec:
            drivers.append(Driver(name, joint, None, None, _driver_position(reader, spec, where, parameters,
                                                                           symbols)))
            continue
        start, speed = reader.string(spec, "start", where), reader.string(spec, "speed", where)
        for role, pname in (("start", start), ("speed", speed)):
            if pname not in params:
                raise reader.fail(where, f"{role} {pname!r} is not a parameter (add it to [parameters])")
        if not params[start].fixed:
            raise reader.fail(where, f"start {start!r} must be a fixed parameter (fixed = true): it only "
                                     f"applies at the start")
        drivers.append(Driver(name, joint, start, speed))
    return tuple(drivers)


def _driver_position(reader: _Reader, spec: dict, where: str, parameters, symbols: dict[str, sp.Symbol]) -> sp.Expr:
    """A driver's ``position``: an expression of the parameters and the absolute time ``t``, read
    by the whitelist parser (checked at the parameters' values and t = 0), without start and speed."""
    import sympy as sp

    both = [k for k in ("start", "speed") if k in spec]
    if both:
        raise reader.fail(where, f"gives 'position' and {' and '.join(map(repr, both))}: a driver is either "
                                 f"start and speed (constant speed) or position (a function of t)")
    text = spec["position"]
    if not isinstance(text, str):
        raise reader.fail(f"{where}.position", f"must be text, an expression of the parameters and t, e.g. "
                                               f"\"theta2_start + A*sin(2*pi*f*t)\", got {_shown(repr(text))}")
    values = {p.name: p.value for p in parameters} | {"t": 0.0}
    scope = dict(symbols) | {"t": sp.Symbol("t", real=True)}
    try:
        check_expression(text, values, "parameters and t")
        return parse_expression(text, scope, values, "parameters and t")
    except ExpressionError as exc:
        raise reader.fail(f"{where}.position", f"{_shown(text)} {exc}") from None


def _springs(reader: _Reader, items, bodies: tuple[Body, ...], ground, joints, drivers, scope: _Scope
             ) -> tuple[Spring, ...]:
    """The [[springs]] entries: names unique among springs, joints and drivers (they name
    outputs), points that exist, coefficients that are expressions of the parameters whose
    values in the file are not negative (a free length, a stiffness, a damping)."""
    import sympy as sp

    if items is None:
        return ()
    if not isinstance(items, list):
        raise reader.fail("springs", "use [[springs]] entries")
    by_name = {b.name: b for b in bodies}
    taken = {j.name: "a joint" for j in joints} | {d.name: "a driver" for d in drivers}
    springs: list[Spring] = []
    for k, spec in enumerate(items):
        where = f"springs[{k}]"
        if not isinstance(spec, dict):
            raise reader.fail(where, "must be a table")
        name = reader.string(spec, "name", where)
        where = f"springs[{k}] '{name}'"
        reader.unknown_keys(spec, {"name", "connects", "joint", "stiffness", "damping", "length", "angle",
                                   "preload"}, where)
        if not _NAME.match(name):
            raise reader.fail(where, "a spring name is letters, digits and _, starting with a letter")
        if name in taken or any(s.name == name for s in springs):
            raise reader.fail(where, f"{taken.get(name, 'a spring')} already has this name (it names outputs)")
        if ("connects" in spec) == ("joint" in spec):
            raise reader.fail(where, "give either 'connects' (two points: a spring along the line between "
                                     "them) or 'joint' (a revolute joint: a rotational spring), not both")
        first = second = joint = None
        if "joint" in spec:
            joint = reader.string(spec, "joint", where)
            revolute = [j.name for j in joints if j.type == "revolute"]
            if joint not in revolute:
                raise reader.fail(f"{where}.joint", f"{joint!r} is not a revolute joint (revolute joints: "
                                                    f"{', '.join(revolute) or 'none'})")
            free = "angle"
            if "length" in spec:
                raise reader.fail(where, "a rotational spring has a free 'angle', not a 'length'")
        else:
            connects = spec.get("connects")
            if not isinstance(connects, list) or len(connects) != 2:
                raise reader.fail(where, "'connects' must name two points, e.g. [\"ground.A\", \"block.centre\"]")
            first, second = (_point_ref(reader, v, f"{where}.connects", by_name, ground) for v in connects)
            if first.body == second.body:
                raise reader.fail(where, f"connects two points of the same body ({first.body!r})")
            free = "length"
            if "angle" in spec:
                raise reader.fail(where, "a point-to-point spring has a free 'length', not an 'angle'")
        values = {}
        for key, default in (("stiffness", None), ("damping", 0), (free, None if free == "length" else 0),
                             ("preload", 0)):
            if key not in spec and default is None:
                raise reader.fail(where, f"missing '{key}'")
            value = spec.get(key, default)
            if key == "angle" and isinstance(value, (int, float)) and not isinstance(value, bool):
                value = math.radians(reader.number(spec, "angle", where, 0.0))    # a number: degrees
            expr = _expression(reader, value, f"{where}.{key}", scope)
            if key not in ("preload", "angle"):
                value = float(expr.subs({scope.symbols[n]: v for n, v in scope.values.items()}))
                if value < 0:
                    raise reader.fail(f"{where}.{key}", f"{_shown(str(spec[key]))} is {value:g} at the "
                                                         f"parameters' values; a {key} cannot be negative")
            values[key] = sp.sympify(expr)
        springs.append(Spring(name, first, second, values["stiffness"], values["damping"], values[free],
                              values["preload"], joint))
    return tuple(springs)


def _friction(reader: _Reader, items, joints, drivers, springs, scope: _Scope) -> tuple[Friction, ...]:
    """The [[friction]] entries: names unique among friction entries, springs, joints and
    drivers (they name outputs), a revolute or prismatic joint, coefficients that are
    expressions of the parameters, not negative at the parameters' values (the velocity scale
    positive)."""
    import sympy as sp

    if items is None:
        return ()
    if not isinstance(items, list):
        raise reader.fail("friction", "use [[friction]] entries")
    taken = ({j.name: "a joint" for j in joints} | {d.name: "a driver" for d in drivers}
             | {s.name: "a spring" for s in springs})
    kinds = {j.name: j.type for j in joints}
    out: list[Friction] = []
    for k, spec in enumerate(items):
        where = f"friction[{k}]"
        if not isinstance(spec, dict):
            raise reader.fail(where, "must be a table")
        name = reader.string(spec, "name", where)
        where = f"friction[{k}] '{name}'"
        reader.unknown_keys(spec, {"name", "joint", "viscous", "coulomb", "velocity_scale"}, where)
        if not _NAME.match(name):
            raise reader.fail(where, "a friction name is letters, digits and _, starting with a letter")
        if name in taken or any(f.name == name for f in out):
            raise reader.fail(where, f"{taken.get(name, 'a friction entry')} already has this name (it names outputs)")
        joint = reader.string(spec, "joint", where)
        if kinds.get(joint) not in ("revolute", "prismatic"):
            raise reader.fail(f"{where}.joint", f"{joint!r} is not a revolute or prismatic joint (joints: "
                                                f"{', '.join(kinds) or 'none'})")
        if "viscous" not in spec and "coulomb" not in spec:
            raise reader.fail(where, "give 'viscous' or 'coulomb' (or both)")
        if "coulomb" in spec and "velocity_scale" not in spec:
            raise reader.fail(where, "a Coulomb friction needs 'velocity_scale' (v_s of tanh(v/v_s))")
        values = {}
        for key, default in (("viscous", 0), ("coulomb", 0), ("velocity_scale", 1)):
            expr = _expression(reader, spec.get(key, default), f"{where}.{key}", scope)
            value = float(expr.subs({scope.symbols[n]: v for n, v in scope.values.items()}))
            if value < 0 or (key == "velocity_scale" and value <= 0):
                rule = "it must be positive" if key == "velocity_scale" else "a friction coefficient cannot be negative"
                raise reader.fail(f"{where}.{key}", f"{_shown(str(spec[key]))} is {value:g} at the parameters' "
                                                     f"values; {rule}")
            values[key] = sp.sympify(expr)
        out.append(Friction(name, joint, kinds[joint], values["viscous"], values["coulomb"], values["velocity_scale"]))
    return tuple(out)


def _loads(reader: _Reader, items, bodies: tuple[Body, ...], ground, taken: dict[str, str], scope: _Scope
           ) -> tuple[Load, ...]:
    """The [[loads]] entries: a constant torque on a body or a constant force at a body point,
    each an expression of the parameters; names unique among joints, drivers, springs and loads
    (they name outputs)."""
    import sympy as sp

    if items is None:
        return ()
    if not isinstance(items, list):
        raise reader.fail("loads", "use [[loads]] entries")
    by_name = {b.name: b for b in bodies}
    loads: list[Load] = []
    for k, spec in enumerate(items):
        where = f"loads[{k}]"
        if not isinstance(spec, dict):
            raise reader.fail(where, "must be a table")
        name = reader.string(spec, "name", where)
        where = f"loads[{k}] '{name}'"
        reader.unknown_keys(spec, {"name", "torque", "body", "force", "point", "frame"}, where)
        if not _NAME.match(name):
            raise reader.fail(where, "a load name is letters, digits and _, starting with a letter")
        if name in taken or any(x.name == name for x in loads):
            raise reader.fail(where, f"{taken.get(name, 'a load')} already has this name (it names outputs)")
        if ("torque" in spec) == ("force" in spec):
            raise reader.fail(where, "give either 'torque' (with 'body') or 'force' (with 'point'), not both")
        if "torque" in spec:
            for key in ("point", "frame"):
                if key in spec:
                    raise reader.fail(f"{where}.{key}", "a torque acts on a 'body', not at a point")
            body = reader.string(spec, "body", where)
            if body not in by_name:
                raise reader.fail(f"{where}.body", f"{body!r}: no body named so (bodies: {', '.join(by_name)})")
            if not by_name[body].rotates:
                raise reader.fail(f"{where}.body", f"{body!r} does not rotate: a torque on it does no work")
            torque = sp.sympify(_expression(reader, spec["torque"], f"{where}.torque", scope))
            loads.append(Load(name, body, torque=torque))
            continue
        if "body" in spec:
            raise reader.fail(f"{where}.body", "a force acts at a 'point' (e.g. \"crank.tip\"), not on a 'body'")
        value = spec["force"]
        if not isinstance(value, list) or len(value) != 2:
            raise reader.fail(f"{where}.force", f"must be [fx, fy] (numbers or expressions), got "
                                                f"{_shown(repr(value))}")
        force = tuple(sp.sympify(_expression(reader, v, f"{where}.force", scope)) for v in value)
        if "point" not in spec:
            raise reader.fail(where, "missing 'point' (where the force acts, e.g. \"crank.tip\")")
        point = _point_ref(reader, spec["point"], f"{where}.point", by_name, ground)
        if point.body == "ground":
            raise reader.fail(f"{where}.point", f"{spec['point']!r} is on the ground: a force there does no work")
        frame = reader.string(spec, "frame", where, "global")
        if frame not in ("global", "body"):
            raise reader.fail(f"{where}.frame", f"{frame!r}: expected 'global' or 'body'")
        if frame == "body" and not by_name[point.body].rotates:
            frame = "global"                # a body that does not turn: its frame is the global one
        loads.append(Load(name, point.body, force=force, point=point, frame=frame))
    return tuple(loads)


_INPUT_KEYS = {"name", "kind", "body", "joint", "point", "direction", "frame", "start", "description"}


def _inputs(reader: _Reader, items, bodies: tuple[Body, ...], ground, joints: tuple[Joint, ...],
            drivers: tuple[Driver, ...], taken: dict[str, str]) -> tuple[Input, ...]:
    """The [[inputs]] entries (see :class:`Input`): names unique among every named element and
    every variable the mechanism makes (they name FMI variables and outputs), the body, joint or
    point they act on existing, a position's joint without another driver."""
    if items is None:
        return ()
    if not isinstance(items, list):
        raise reader.fail("inputs", "use [[inputs]] entries")
    by_name = {b.name: b for b in bodies}
    by_joint = {j.name: j for j in joints}
    driven = {d.joint: d.name for d in drivers}
    inputs: list[Input] = []
    names: dict[str, str] = {}
    for k, spec in enumerate(items):
        where = f"inputs[{k}]"
        if not isinstance(spec, dict):
            raise reader.fail(where, "must be a table")
        name = reader.string(spec, "name", where)
        where = f"inputs[{k}] '{name}'"
        reader.unknown_keys(spec, _INPUT_KEYS, where)
        kind = reader.string(spec, "kind", where)
        if kind not in INPUT_KINDS:
            raise reader.fail(f"{where}.kind", f"{kind!r}: expected one of {', '.join(INPUT_KINDS)}")
        start = reader.number(spec, "start", where, 0.0)
        given = {key for key in ("body", "joint", "point") if key in spec}
        allowed = {"torque": ({"body"}, {"joint"}), "force": ({"joint"}, {"point"}), "position": ({"joint"},)}[kind]
        if given not in allowed:
            choices = " or ".join(repr(next(iter(a))) for a in allowed)
            raise reader.fail(where, f"a {kind} input acts through {choices} (one of them), got "
                                     f"{', '.join(map(repr, sorted(given))) or 'none'}")
        for key in ("direction", "frame"):
            if key in spec and given != {"point"}:
                raise reader.fail(f"{where}.{key}", "only a force at a 'point' has a direction and a frame")
        body = joint = joint_type = point = direction = None
        frame = "global"
        if "body" in given:
            body = reader.string(spec, "body", where)
            if body not in by_name:
                raise reader.fail(f"{where}.body", f"{body!r}: no body named so (bodies: {', '.join(by_name)})")
            if not by_name[body].rotates:
                raise reader.fail(f"{where}.body", f"{body!r} does not rotate: a torque on it does no work")
        elif "joint" in given:
            joint = reader.string(spec, "joint", where)
            if joint not in by_joint:
                raise reader.fail(f"{where}.joint", f"{joint!r}: no joint named so (joints: {', '.join(by_joint)})")
            joint_type = by_joint[joint].type
            need = {"torque": "revolute", "force": "prismatic"}.get(kind)
            if need and joint_type != need:
                raise reader.fail(f"{where}.joint", f"{joint!r} is a {joint_type} joint: a {kind} input acts at a "
                                                    f"{need} joint (or give a {'body' if kind == 'torque' else 'point'})")
            if kind == "position" and joint in driven:
                raise reader.fail(f"{where}.joint", f"joint {joint!r} already has a driver ({driven[joint]!r})")
            if kind == "position":
                driven[joint] = name
        else:
            point = _point_ref(reader, spec["point"], f"{where}.point", by_name, ground)
            if point.body == "ground":
                raise reader.fail(f"{where}.point", f"{spec['point']!r} is on the ground: a force there does no work")
            value = spec.get("direction")
            if (not isinstance(value, list) or len(value) != 2
                    or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
                    or not all(math.isfinite(v) and abs(v) <= MAX_MAGNITUDE for v in value)
                    or math.hypot(*value) == 0.0):
                raise reader.fail(f"{where}.direction", f"must be [dx, dy], two finite numbers not both zero (the "
                                                        f"force's direction), got {_shown(repr(value))}")
            norm = math.hypot(*value)
            direction = (value[0] / norm, value[1] / norm)
            frame = reader.string(spec, "frame", where, "global")
            if frame not in ("global", "body"):
                raise reader.fail(f"{where}.frame", f"{frame!r}: expected 'global' or 'body'")
            if frame == "body" and not by_name[point.body].rotates:
                frame = "global"
        unit = {"torque": "N.m", "force": "N"}.get(kind) or ("rad" if joint_type == "revolute" else "m")
        on = body or joint or f"{point.body}.{point.point}"
        default = {"torque": f"Input torque on {on}, counter-clockwise positive [N.m]" if body else
                   f"Input torque at joint {on}, on its second body (minus on its first) [N.m]",
                   "force": f"Input force at joint {on}, along its line on the second body [N]" if joint else
                   f"Input force at {on} along ({direction[0]:.6g}, {direction[1]:.6g}) in the {frame} frame [N]"
                   if direction else "",
                   "position": f"Input position of joint {on}: its coordinate (driver {name}) [{unit}]"}[kind]
        entry = Input(name, kind, start, reader.text(spec, "description", where, default), body, joint, joint_type,
                      point, direction, frame)
        for var in entry.variables:
            if not _NAME.match(var.name) or var.name in _RESERVED or var.name in _GENERATED_NAMES:
                raise reader.fail(where, f"{var.name!r} cannot be an input's name (letters, digits and _, starting "
                                         f"with a letter; not one of {', '.join(sorted(_RESERVED | _GENERATED_NAMES))})")
            clash = taken.get(var.name) or names.get(var.name)
            if clash:
                raise reader.fail(where, f"its variable {var.name!r} would have the name of {clash}; rename the input")
            names[var.name] = f"input {name!r}"
        inputs.append(entry)
    return tuple(inputs)


#: Names the generated code uses beside the file's: an input may not take them.
_GENERATED_NAMES = {"array", "tanh", "sqrt", "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "exp", "log",
                    "max_evaluations", "q", "qd", "p", "d", "lam"}


def _start(reader: _Reader, table: dict, bodies: tuple[Body, ...]) -> tuple[StartValue, ...]:
    coordinates = {c: b for b in bodies for c in b.coordinates}
    rates = {}
    for b in bodies:
        for c in b.coordinates:
            prefix = c[: len(c) - len(b.label)]
            rates[RATE_PREFIX[prefix] + b.label] = c
    given = {}
    for key, spec in table.items():
        where = f"start.{key}"
        if isinstance(spec, (int, float)) and not isinstance(spec, bool):
            spec = {"value": spec}
        if not isinstance(spec, dict):
            raise reader.fail(where, "must be a number or { value = ..., unit = ..., description = ... }")
        reader.unknown_keys(spec, {"value", "unit", "description"}, where)
        if key not in coordinates and key not in rates:
            raise reader.fail(where, f"{key!r} is not a coordinate or a rate of one (coordinates: "
                                     f"{', '.join(coordinates)}; rates: {', '.join(rates)})")
        given[key] = spec
    out = []
    for key, spec in given.items():
        if key not in coordinates:
            continue
        is_angle = key.startswith("theta")
        rate = next(r for r, c in rates.items() if c == key)
        for name, default_unit, si_units in ((key, "deg" if is_angle else "m", ("rad", "deg") if is_angle else ("m",)),
                                             (rate, "rad/s" if is_angle else "m/s",
                                              ("rad/s",) if is_angle else ("m/s",))):
            where = f"start.{name}"
            s = given.get(name, {"value": 0.0})
            unit = s.get("unit", default_unit)
            if unit not in si_units:
                raise reader.fail(where, f"unit {unit!r}: expected {' or '.join(si_units)}")
            value = reader.number(s, "value", where)
            display = None
            if unit == "deg":
                value, unit, display = math.radians(value), "rad", "deg"
            what = "angle" if name == key and is_angle else ("position" if name == key else "rate")
            description = reader.text(s, "description", where,
                                      f"Initial {what} {name} of body '{coordinates[key].name}'")
            out.append(StartValue(name, value, unit, str(description), display))
    for key in given:
        if key in rates and rates[key] not in given:
            raise reader.fail(f"start.{key}", f"a start rate needs its coordinate {rates[key]!r} in [start] too")
    return tuple(out)


def parse_mechanism(data: dict, source: str = "<mechanism>") -> Mechanism:
    """A :class:`Mechanism` from the TOML tables (``source`` names the file in messages)."""
    reader = _Reader(source)
    reader.unknown_keys(data, {"mechanism", "parameters", "ground", "bodies", "joints", "drivers", "springs",
                               "friction", "loads", "inputs", "start", "outputs"}, "top level")
    head = reader.table(data, "mechanism", "top level")
    reader.unknown_keys(head, {"name", "description", "gravity"}, "[mechanism]")
    name = reader.string(head, "name", "[mechanism]")
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", name) or name.endswith("Native"):
        raise reader.fail("[mechanism]", f"name {name!r} must be a C identifier (it names the FMU) and not end "
                                         f"in 'Native' (the native FMU is <name>Native)")
    parameters = _parameters(reader, reader.table(data, "parameters", "top level"))
    _check_expressions(reader, data, {p.name: p.value for p in parameters})
    import sympy as sp

    symbols = {p.name: sp.Symbol(p.name, real=True) for p in parameters}
    scope = _Scope(symbols, {p.name: p.value for p in parameters})
    gravity = head.get("gravity")
    if gravity is not None and (not isinstance(gravity, str) or gravity not in symbols):
        raise reader.fail("[mechanism]", f"gravity {gravity!r} must name a parameter (acceleration along -y)")
    ground_table = reader.table(data, "ground", "top level", required=False)
    reader.unknown_keys(ground_table, {"points"}, "[ground]")
    ground_points = ground_table.get("points", {})
    if not isinstance(ground_points, dict):
        raise reader.fail("[ground]", "'points' must be a table of name = [x, y]")
    ground = {k: _point_pair(reader, v, f"ground.points.{k}", scope) for k, v in ground_points.items()}
    bodies = _bodies(reader, data.get("bodies"), scope)
    joints = _joints(reader, data.get("joints"), bodies, ground)
    drivers = _drivers(reader, data.get("drivers"), joints, parameters, symbols)
    springs = _springs(reader, data.get("springs"), bodies, ground, joints, drivers, scope)
    friction = _friction(reader, data.get("friction"), joints, drivers, springs, scope)
    loads = _loads(reader, data.get("loads"), bodies, ground, {j.name: "a joint" for j in joints}
                   | {d.name: "a driver" for d in drivers} | {s.name: "a spring" for s in springs}
                   | {f.name: "a friction entry" for f in friction}, scope)
    start = _start(reader, reader.table(data, "start", "top level", required=False), bodies)
    taken = {j.name: "a joint" for j in joints} | {d.name: "a driver" for d in drivers} \
        | {s.name: "a spring" for s in springs} | {f.name: "a friction entry" for f in friction} \
        | {x.name: "a load" for x in loads} | {p.name: "a parameter" for p in parameters} \
        | {s.parameter: "a start-value parameter" for s in start} \
        | {c: "a coordinate" for b in bodies for c in b.coordinates} \
        | {f"{c}_d": "a coordinate's rate symbol" for b in bodies for c in b.coordinates} \
        | {RATE_PREFIX[c[: len(c) - len(b.label)]] + b.label: "a rate" for b in bodies for c in b.coordinates}
    inputs = _inputs(reader, data.get("inputs"), bodies, ground, joints, drivers, taken)
    drivers = drivers + tuple(Driver(i.name, i.joint, None, None, input=i.name) for i in inputs
                              if i.kind == "position")
    names = {p.name for p in parameters}
    for s in start:
        if s.parameter in names:
            raise reader.fail(f"parameters.{s.parameter}", f"is also made by [start] {s.coordinate}")
    outputs, expression_outputs = None, ()
    if "outputs" in data:
        table = reader.table(data, "outputs", "top level")
        reader.unknown_keys(table, {"variables", "expressions"}, "[outputs]")
        variables = table.get("variables")
        if "variables" in table or "expressions" not in table:
            if not isinstance(variables, list) or not variables or not all(isinstance(v, str) for v in variables):
                raise reader.fail("[outputs]", "'variables' must be a non-empty list of output names")
            if len(set(variables)) != len(variables):
                raise reader.fail("[outputs]", "a variable is listed twice")
            outputs = tuple(variables)
        if "expressions" in table:
            expression_outputs = _expression_outputs(reader, table["expressions"], parameters, bodies, symbols)
    return Mechanism(name, reader.text(head, "description", "[mechanism]", name), source, gravity, parameters,
                     ground, bodies,
                     joints, drivers, start, outputs, expression_outputs, springs, friction, loads, inputs)


def _expression_outputs(reader: _Reader, table, parameters: tuple[Parameter, ...], bodies: tuple[Body, ...],
                        symbols: dict[str, sp.Symbol]) -> tuple[ExpressionOutput, ...]:
    """``[outputs.expressions]``: name = { expression = "...", unit = "...", description = "..." }
    (or name = "..."), each an expression of the parameters, the coordinates and their rates,
    read by the whitelist parser and checked at the parameters' values, the bodies' assembly
    guesses and zero rates."""
    import sympy as sp

    if not isinstance(table, dict) or not table:
        raise reader.fail("[outputs]", "'expressions' must be a table of name = { expression = \"...\", "
                                       "unit = \"...\", description = \"...\" }")
    scope_symbols = dict(symbols)
    values = {p.name: p.value for p in parameters}
    state_names = []
    for body in bodies:
        guesses = dict(zip(("x", "y", "theta"), body.guess))
        for c in body.coordinates:
            prefix = c[: len(c) - len(body.label)]
            rate = RATE_PREFIX[prefix] + body.label
            for name, symbol, value in ((c, sp.Symbol(c, real=True), guesses[prefix]),
                                        (rate, sp.Symbol(f"{c}_d", real=True), 0.0)):
                if name in values:
                    raise reader.fail(f"parameters.{name}", f"has the name of body '{body.name}'s coordinate or "
                                                            f"rate {name}, which [outputs.expressions] may use")
                scope_symbols[name], values[name] = symbol, float(value)
                state_names.append(name)
    out = []
    for name, spec in table.items():
        where = f"outputs.expressions.{name}"
        if not _NAME.match(name) or name in _RESERVED:
            raise reader.fail(where, f"{name!r} cannot be an output name (letters, digits and _, starting with a "
                                     f"letter; not one of {', '.join(sorted(_RESERVED))})")
        if isinstance(spec, str):
            spec = {"expression": spec}
        if not isinstance(spec, dict):
            raise reader.fail(where, "must be an expression (text) or a table { expression = \"...\", "
                                     "unit = \"...\", description = \"...\" }")
        reader.unknown_keys(spec, {"expression", "unit", "description"}, where)
        text = spec.get("expression")
        if not isinstance(text, str):
            raise reader.fail(where, f"'expression' must be text, e.g. \"theta3 - theta2\", got {text!r}")
        unit = reader.string(spec, "unit", where, "1")
        if unit not in _UNITS:
            raise reader.fail(where, f"unit {unit!r} is not one of {', '.join(sorted(_UNITS))}")
        try:
            check_expression(text, values, "parameters, coordinates and rates")
            expr = parse_expression(text, scope_symbols, values, "parameters, coordinates and rates")
        except ExpressionError as exc:
            raise reader.fail(f"{where}.expression", f"{_shown(text)} {exc}") from None
        unit, display = ("rad", "deg") if unit == "deg" else (unit, None)
        out.append(ExpressionOutput(name, expr, unit, reader.text(spec, "description", where, f"{name} = {text}"),
                                    display))
    return tuple(out)

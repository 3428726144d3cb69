"""Expressions in a mechanism file, read as data: a whitelist parser that never runs the text.

A mechanism file comes from anyone (a student, a supplier), so its expressions are parsed here
and nowhere else, without ``eval``, ``exec`` or ``sympify`` of the text (sympify evaluates it:
``"__import__('os').system('id')"`` ran, ``"10**10**10"`` hung).  The text is checked
character by character, parsed by :func:`ast.parse` (which only parses), and the syntax tree is
walked against a whitelist that builds the sympy expression node by node.  Each node is also
evaluated in floating point at the parameters' values *before* its sympy object is built, so
sympy never sees a number it would take long to compute.  :func:`check_expression` does all of
this without importing sympy (the loader checks every expression of a file first, so a refusal
does not wait for sympy's import); :func:`parse_expression` checks and then builds.

The grammar (docs/mechanisms.md, "Expressions")::

    expression := term (("+" | "-") term)*
    term       := factor (("*" | "/") factor)*
    factor     := ("+" | "-") factor | power
    power      := atom ["**" factor]            # the exponent: a constant, |value| <= MAX_EXPONENT
    atom       := number | name | function "(" expression ("," expression)* ")" | "(" expression ")"
    number     := decimal digits, optional fraction and exponent (1, 0.5, 2.5e-3); |value| <= MAX_LITERAL
    name       := a declared parameter | pi
    function   := one of FUNCTIONS (sqrt, sin, cos, tan, asin, acos, atan, atan2, exp, log)

Bounds, and why: MAX_LENGTH characters (the shipped files use at most 20; a parse is linear in
the text); MAX_DEPTH levels of nesting (parentheses, calls, signs and right operands: the walk
recurses once per level; a chain ``a + b - c`` is not nesting); exponents constant and at most
MAX_EXPONENT in magnitude (``2**1000000`` or ``10**10**10`` are big-number bombs, and a
mechanism's geometry needs squares and square roots); a power of numbers at most MAX_EXACT_BITS
long as an exact fraction (sympy computes it exactly: ``(1e-300**16)**16`` is 0.0 as a float
but has 76,800 digits); every intermediate value at the parameters' values finite, real and at
most MAX_MAGNITUDE in magnitude (SI lengths and masses of a linkage are far inside; the bound
keeps sympy's exact arithmetic on small numbers).  A text that breaks one is refused with
:class:`ExpressionError`, whose message says what was refused and why; the loader adds the file
and the field.
"""
from __future__ import annotations

import ast
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import sympy as sp

__all__ = ["ExpressionError", "ExpressionFunction", "parse_expression", "check_expression", "FUNCTIONS", "CONSTANTS", "MAX_LENGTH",
           "MAX_DEPTH", "MAX_EXPONENT", "MAX_LITERAL", "MAX_MAGNITUDE", "MAX_EXACT_BITS"]

#: Longest expression text, characters.
MAX_LENGTH = 500
#: Deepest nesting: parentheses, calls, signs and the right operand of an operator each add a
#: level (a left-to-right chain ``a + b - c * d`` does not).
MAX_DEPTH = 50
#: Largest magnitude of an exponent (which must be a constant: no names in it).
MAX_EXPONENT = 16
#: Largest magnitude of a number written in an expression.
MAX_LITERAL = 1e15
#: Largest magnitude of any intermediate value at the parameters' values.
MAX_MAGNITUDE = 1e30
#: Largest exact number (numerator or denominator, bits) a power of numbers may make: sympy
#: computes ``(1e-300**16)**16`` exactly, and the float check sees only 0.0.  An upper
#: estimate carried by the walk (bits of a literal; sums and products add; a power multiplies).
MAX_EXACT_BITS = 4096

_ALLOWED_CHARACTERS = re.compile(r"[A-Za-z0-9_+\-*/()., \t]*\Z")
_DECIMAL = re.compile(r"(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\Z")


class ExpressionError(ValueError):
    """An expression that is refused; the message says what and why (not the file or field)."""


@dataclass(frozen=True)
class _Function:
    """An allowed function: its sympy name, its float evaluation (real domain), its arity."""

    sympy_name: str
    value: Callable[..., float]
    arity: int
    #: builds the sympy expression from the arguments' (None: ``sympy.<sympy_name>``)
    build: Callable[..., "sp.Expr"] | None = None


#: How another file format (a component's block file, fmu_src/block/) adds functions of its own.
ExpressionFunction = _Function

#: The functions an expression may call (all real-valued on their real domain).
FUNCTIONS: Mapping[str, _Function] = {
    "sqrt": _Function("sqrt", math.sqrt, 1),
    "sin": _Function("sin", math.sin, 1),
    "cos": _Function("cos", math.cos, 1),
    "tan": _Function("tan", math.tan, 1),
    "asin": _Function("asin", math.asin, 1),
    "acos": _Function("acos", math.acos, 1),
    "atan": _Function("atan", math.atan, 1),
    "atan2": _Function("atan2", math.atan2, 2),   # atan2(y, x), as in C and Python
    "exp": _Function("exp", math.exp, 1),
    "log": _Function("log", math.log, 1),          # natural logarithm
}
#: The named constants an expression may use: name -> (sympy name, value).
CONSTANTS: Mapping[str, tuple[str, float]] = {"pi": ("pi", math.pi)}


def check_expression(text: str, values: Mapping[str, float], names: str = "parameters",
                     functions: Mapping[str, _Function] = FUNCTIONS) -> float:
    """The value of ``text`` at the parameters' ``values`` (name -> float, SI), after every check
    of the module doc, without sympy.  Raises :class:`ExpressionError` (and nothing else).
    ``names`` says what the names of ``values`` are, for the message of an unknown name."""
    return _walk(text, values, None, names, functions).value


def parse_expression(text: str, symbols: Mapping[str, sp.Symbol], values: Mapping[str, float],
                     names: str = "parameters", functions: Mapping[str, _Function] = FUNCTIONS) -> sp.Expr:
    """The sympy expression of ``text`` over the parameters ``symbols`` (name -> Symbol), checked
    at the parameters' ``values`` (name -> float, SI).  Raises :class:`ExpressionError` (and
    nothing else) for a text outside the grammar of the module doc or out of its bounds.
    ``names`` says what the names of ``values`` are, for the message of an unknown name;
    ``functions`` the functions it may call (default FUNCTIONS; a block file adds some)."""
    _walk(text, values, None, names, functions)          # every check first: sympy builds only what passed
    import sympy as sp

    expr = _walk(text, values, symbols, names, functions).expr
    if expr.has(sp.zoo, sp.oo, sp.nan, sp.I) or expr.has(-sp.oo):
        raise ExpressionError("is not finite and real (division by an exact zero, or a complex value)")
    return expr


def _walk(text: str, values: Mapping[str, float], symbols: Mapping[str, sp.Symbol] | None,
          names: str = "parameters", functions: Mapping[str, _Function] = FUNCTIONS) -> _Node:
    if not isinstance(text, str):
        raise ExpressionError(f"expected text, got {type(text).__name__}")
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"is {len(text)} characters long; an expression has at most {MAX_LENGTH}")
    if not text.strip():
        raise ExpressionError("is empty")
    if not _ALLOWED_CHARACTERS.match(text):
        bad = next(c for c in text if not _ALLOWED_CHARACTERS.match(c))
        raise ExpressionError(f"contains {bad!r} (U+{ord(bad):04X}); an expression uses ASCII letters, digits, "
                              f"_ + - * / ( ) . , spaces and tabs only")
    depth = 0
    for c in text:
        depth += (c == "(") - (c == ")")
        if depth > MAX_DEPTH:
            raise ExpressionError(f"nests parentheses deeper than {MAX_DEPTH} levels")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise ExpressionError(f"is not an expression ({exc.msg})") from None
    except (RecursionError, MemoryError, ValueError) as exc:
        raise ExpressionError(f"cannot be parsed ({type(exc).__name__})") from None
    try:
        return _Walker(text.strip(), values, symbols, names, functions).node(tree.body, 1)
    except (RecursionError, MemoryError) as exc:
        raise ExpressionError(f"is too complex to read ({type(exc).__name__})") from None


@dataclass(frozen=True)
class _Node:
    """A checked node: its sympy expression (None when only checking), its float value at the
    parameters' values, whether it is constant (no parameters), and for a constant an upper
    bound on the bits of the exact number sympy may make of it (numerator or denominator)."""

    expr: sp.Expr | None
    value: float
    constant: bool
    bits: float = 0.0


class _Walker:
    """Checks each whitelisted node (float value, bounds) and, given ``symbols``, builds its sympy
    expression from its checked children."""

    def __init__(self, text: str, values: Mapping[str, float], symbols: Mapping[str, sp.Symbol] | None,
                 names: str = "parameters", functions: Mapping[str, _Function] = FUNCTIONS):
        self.text, self.values, self.symbols, self.names = text, values, symbols, names
        self.functions = functions
        if symbols is not None:
            import sympy
            self.sp = sympy

    def node(self, node: ast.AST, depth: int) -> _Node:
        if depth > MAX_DEPTH:
            raise ExpressionError(f"nests deeper than {MAX_DEPTH} levels")
        if isinstance(node, ast.Constant):
            return self.number(node)
        if isinstance(node, ast.Name):
            return self.name(node.id)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
            a = self.node(node.operand, depth + 1)
            if isinstance(node.op, ast.UAdd):
                return a
            return _Node(None if a.expr is None else -a.expr, -a.value, a.constant, a.bits)
        if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub, ast.Mult, ast.Div, ast.Pow)):
            return self.binary(node, depth)
        if isinstance(node, ast.Call):
            return self.call(node, depth)
        raise ExpressionError(f"uses {self.describe(node)}, which an expression cannot contain (numbers, "
                              f"parameters, + - * / **, parentheses and {', '.join(self.functions)} only)")

    def describe(self, node: ast.AST) -> str:
        segment = ast.get_source_segment(self.text, node)
        return f"{type(node).__name__} {segment[:40]!r}" if segment else type(node).__name__

    def number(self, node: ast.Constant) -> _Node:
        segment = ast.get_source_segment(self.text, node) or ""
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)) or not _DECIMAL.match(segment):
            raise ExpressionError(f"{segment[:40]!r} is not a decimal number (strings, complex, hexadecimal "
                                  f"and 1_000-style numbers are not allowed)")
        value = float(node.value) if isinstance(node.value, float) or abs(node.value) <= 10**300 else math.inf
        if not math.isfinite(value) or abs(value) > MAX_LITERAL:
            raise ExpressionError(f"the number {segment[:40]} is beyond {MAX_LITERAL:g} in magnitude")
        # the exact number as sympify(..., rational=True) read it: "0.1" is 1/10, "2" is 2
        exact = Fraction(segment)
        bits = max(abs(exact.numerator).bit_length(), exact.denominator.bit_length())
        expr = None
        if self.symbols is not None:
            expr = self.sp.Integer(node.value) if isinstance(node.value, int) else self.sp.Rational(segment)
        return _Node(expr, value, True, bits)

    def name(self, name: str) -> _Node:
        if self.symbols is not None and name in self.symbols:
            return _Node(self.symbols[name], float(self.values[name]), False)
        if name in self.values:
            return _Node(None, float(self.values[name]), False)
        if name in CONSTANTS:
            sympy_name, value = CONSTANTS[name]
            return _Node(None if self.symbols is None else getattr(self.sp, sympy_name), value, True, 64)
        if name in self.functions:
            raise ExpressionError(f"uses the function {name} without calling it")
        what = "a parameter" if self.names == "parameters" else f"one of its {self.names}"
        raise ExpressionError(f"uses {name}, which is not {what} ({self.names}: "
                              f"{', '.join(self.values) or 'none'}; constants: {', '.join(CONSTANTS)})")

    def binary(self, node: ast.BinOp, depth: int) -> _Node:
        # a chain a + b + c ... nests to the left as it is written: its length is bounded by
        # MAX_LENGTH, not counted as nesting
        chained = isinstance(node.op, (ast.Add, ast.Sub, ast.Mult, ast.Div))
        a = self.node(node.left, depth if chained else depth + 1)
        b = self.node(node.right, depth + 1)
        op = type(node.op)
        bits = a.bits + b.bits + 1
        if op is ast.Pow:
            if not b.constant:
                raise ExpressionError(f"raises to {ast.get_source_segment(self.text, node.right)!r}, which uses "
                                      f"parameters; an exponent is a constant")
            if not abs(b.value) <= MAX_EXPONENT:
                raise ExpressionError(f"has the exponent {ast.get_source_segment(self.text, node.right)!r} "
                                      f"(= {b.value:.6g}); an exponent is at most {MAX_EXPONENT} in magnitude")
            bits = a.bits * max(1.0, abs(b.value))
            if a.constant and bits > MAX_EXACT_BITS:
                raise ExpressionError(f"{self.part(node)}is an exact number of about {bits:.0f} bits; "
                                      f"at most {MAX_EXACT_BITS}")
        value = self.checked(node, lambda: _OPERATIONS[op](a.value, b.value))
        expr = None
        if self.symbols is not None:
            expr = {ast.Add: self.sp.Add, ast.Sub: lambda x, y: x - y, ast.Mult: self.sp.Mul,
                    ast.Div: lambda x, y: x / y, ast.Pow: self.sp.Pow}[op](a.expr, b.expr)
        return _Node(expr, value, a.constant and b.constant, bits)

    def call(self, node: ast.Call, depth: int) -> _Node:
        name = node.func.id if isinstance(node.func, ast.Name) else None
        if name not in self.functions:
            what = name if name is not None else ast.get_source_segment(self.text, node.func)
            raise ExpressionError(f"calls {str(what)[:40]!r}, which is not one of the functions "
                                  f"{', '.join(self.functions)}")
        function = self.functions[name]
        if node.keywords or any(isinstance(a, ast.Starred) for a in node.args):
            raise ExpressionError(f"calls {name} with keyword or * arguments; give {function.arity} plain "
                                  f"argument{'s' if function.arity > 1 else ''}")
        if len(node.args) != function.arity:
            raise ExpressionError(f"calls {name} with {len(node.args)} argument{'s' if len(node.args) != 1 else ''}; "
                                  f"it takes {function.arity}")
        args = [self.node(a, depth + 1) for a in node.args]
        value = self.checked(node, lambda: function.value(*(a.value for a in args)))
        expr = None
        if self.symbols is not None:
            build = function.build or getattr(self.sp, function.sympy_name)
            expr = build(*(a.expr for a in args))
        return _Node(expr, value, all(a.constant for a in args), sum(a.bits for a in args) + 1)

    def part(self, node: ast.AST) -> str:
        """How a message names a node: "" for the whole text (the loader quotes it), else
        "its part '...' " (cut after 60 characters)."""
        segment = ast.get_source_segment(self.text, node) or ""
        return "" if segment == self.text else f"its part {segment[:60]!r} "

    def checked(self, node: ast.AST, compute: Callable[[], float]) -> float:
        """The float value of a node, refused unless finite, real and at most MAX_MAGNITUDE."""
        part = self.part(node)
        try:
            value = compute()
        except ZeroDivisionError:
            raise ExpressionError(f"{part}divides by zero at the parameters' values") from None
        except (OverflowError, ValueError) as exc:
            raise ExpressionError(f"{part}has no finite real value at the parameters' values ({exc})") from None
        if isinstance(value, complex):
            raise ExpressionError(f"{part}is complex at the parameters' values")
        if not math.isfinite(value) or abs(value) > MAX_MAGNITUDE:
            raise ExpressionError(f"{part}is {value:.6g} at the parameters' values; at most "
                                  f"{MAX_MAGNITUDE:g} in magnitude")
        return value


_OPERATIONS: dict[type, Callable[[float, float], float]] = {
    ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b, ast.Mult: lambda a, b: a * b,
    ast.Div: lambda a, b: a / b, ast.Pow: lambda a, b: a ** b,
}

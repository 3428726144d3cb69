"""A block's equations with sympy: its states' derivatives f(p, u, x) and outputs y(p, u, x), the
intermediates substituted, their exact Jacobians (Model Exchange's directional derivatives) and
each unknown's dependencies on the inputs and states (the model description's <ModelStructure>)."""
from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from ..mechanism.expressions import ExpressionError, check_expression, parse_expression
from .description import BLOCK_FUNCTIONS, Block, BlockError, load_block

__all__ = ["BlockEquations", "derive_block"]


@dataclass(frozen=True)
class BlockEquations:
    """f and y over the symbols p (parameters), u (inputs), x (states), and their Jacobians
    (row: unknown, column: known).  ``*_dependencies``: per unknown, the names of the inputs and
    states its expression contains (a quantiser's output depends on its input although its
    derivative is zero)."""

    block: Block
    p: tuple[sp.Symbol, ...]
    u: tuple[sp.Symbol, ...]
    x: tuple[sp.Symbol, ...]
    f: tuple[sp.Expr, ...]
    y: tuple[sp.Expr, ...]
    f_x: sp.ImmutableMatrix
    f_u: sp.ImmutableMatrix
    y_x: sp.ImmutableMatrix
    y_u: sp.ImmutableMatrix
    derivative_dependencies: tuple[tuple[str, ...], ...]
    output_dependencies: tuple[tuple[str, ...], ...]


def _steps_as_piecewise(expr: sp.Expr) -> sp.Expr:
    """min/max differentiate to Heaviside steps: written as the C printer can print them
    (1 where the argument is > 0, else 0)."""
    return expr.replace(sp.Heaviside, lambda arg, *_: sp.Piecewise((sp.S.One, arg > 0), (sp.S.Zero, True)))


def _jacobian(exprs, symbols) -> sp.ImmutableMatrix:
    if not exprs or not symbols:
        return sp.ImmutableMatrix(sp.zeros(len(exprs), len(symbols)))
    return sp.ImmutableMatrix([[_steps_as_piecewise(sp.diff(e, s)) for s in symbols] for e in exprs])


def derive_block(source: Block | str) -> BlockEquations:
    """The equations of a Block (or of a shipped name / a path: load_block)."""
    block = source if isinstance(source, Block) else load_block(source)
    p = tuple(sp.Symbol(f"p_{q.name}", real=True) for q in block.parameters)
    u = tuple(sp.Symbol(f"u_{q.name}", real=True) for q in block.inputs)
    x = tuple(sp.Symbol(f"x_{q.name}", real=True) for q in block.states)
    symbols: dict[str, sp.Expr] = {}
    symbols.update(zip((q.name for q in block.parameters), p))
    symbols.update(zip((q.name for q in block.inputs), u))
    symbols.update(zip((q.name for q in block.states), x))
    values = {q.name: q.value for q in block.parameters}
    values.update({q.name: q.start for q in block.inputs})
    values.update({q.name: q.start for q in block.states})
    what = "parameters, inputs, states and intermediates"

    def parse(field: str, text: str) -> sp.Expr:
        try:
            return parse_expression(text, symbols, values, what, BLOCK_FUNCTIONS)
        except ExpressionError as exc:       # load_block checked them: only a changed Block gets here
            raise BlockError(f"{block.source}: {field} = {text!r}: {exc}") from None

    for item in block.intermediates:
        symbols[item.name] = parse(f"[intermediates.{item.name}] expression", item.expression)
        values[item.name] = check_expression(item.expression, values, what, BLOCK_FUNCTIONS)
    f = tuple(parse(f"[states.{s.name}] derivative", s.derivative) for s in block.states)
    y = tuple(parse(f"[outputs.{o.name}] expression", o.expression) for o in block.outputs)
    names = {**{s: q.name for s, q in zip(u, block.inputs)}, **{s: q.name for s, q in zip(x, block.states)}}

    def dependencies(expr: sp.Expr) -> tuple[str, ...]:
        used = expr.free_symbols
        return tuple(names[s] for s in (*x, *u) if s in used)

    return BlockEquations(block, p, u, x, f, y, _jacobian(f, x), _jacobian(f, u), _jacobian(y, x), _jacobian(y, u),
                          tuple(dependencies(e) for e in f), tuple(dependencies(e) for e in y))

"""The orders a system's components are stepped and evaluated in (a system of FMUs: docs/systems.md).

- :func:`step_order`: the order a co-simulation master steps the components in (Jacobi: the
  SSD's; Gauss–Seidel: :func:`gauss_seidel_order`; or the case's ``[master] order``).
- :func:`evaluation_plan`: the order the monolithic master (:mod:`orchestrator.monolithic`)
  reads the connected outputs in, so that every input is known before an output that depends
  on it is read; :class:`AlgebraicLoop` when the connections close a loop of direct
  feed-through.

Both read the outputs' direct dependencies on inputs from the components' modelDescriptions
(``<ModelStructure><Outputs>``; an output that lists no ``dependencies`` depends on every input).
Nothing here runs an FMU.
"""
from __future__ import annotations

from typing import Sequence

from .case import Master
from .system_description import SystemDescription

__all__ = ["AlgebraicLoop", "evaluation_plan", "gauss_seidel_order", "step_order", "suggested_order"]


def gauss_seidel_order(system: SystemDescription) -> tuple[str, ...]:
    """The order the components step in under Gauss–Seidel, from the connections.

    Repeatedly take the first component (in the SSD's order) that no remaining component
    feeds (a topological order along the connections).  When every remaining component is
    fed by another (a loop), take the first whose connected outputs do not depend directly
    on its inputs (the modelDescription's ModelStructure: an output with no ``dependencies``
    attribute depends on every input), else the first in the SSD's order; it steps with the
    previous values of the inputs the loop feeds it.
    """
    names = list(system.ssp.component_names)
    feeds = {(c.start_component, c.end_component) for c in system.ssp.connections
             if c.start_component != c.end_component}
    outputs: dict[str, set[str]] = {}
    for c in system.ssp.connections:
        outputs.setdefault(c.start_component, set()).add(c.start_connector)
    order: list[str] = []
    remaining = list(names)
    while remaining:
        ready = [c for c in remaining if not any((s, c) in feeds for s in remaining if s != c)]
        if not ready:
            ready = [c for c in remaining
                     if not any(system.component(c).direct_inputs(o) for o in outputs.get(c, ()))] or remaining
        order.append(ready[0])
        remaining.remove(ready[0])
    return tuple(order)


def step_order(system: SystemDescription, master: Master) -> tuple[str, ...]:
    """The order the components step in: ``master.order`` when the case gave one, else
    :func:`gauss_seidel_order` for Gauss–Seidel, the SSD's order for Jacobi (where it changes
    nothing: every component steps from the same values); for the monolithic master the order
    its evaluation reads them in (:func:`orchestrator.monolithic.evaluation_plan`)."""
    if master.order:
        return tuple(master.order)
    if master.algorithm == "monolithic":          # the order its evaluation reads the outputs in
        read = list(dict.fromkeys(name for name, _ in evaluation_plan(system)))
        return (*read, *(n for n in system.ssp.component_names if n not in read))
    if master.algorithm == "gauss-seidel":
        return gauss_seidel_order(system)
    return system.ssp.component_names


class AlgebraicLoop(ValueError):
    """The connections close a loop of direct feed-through; the message names it."""


def _direct_inputs(system: SystemDescription, component: str, output: str) -> tuple[str, ...]:
    """The inputs of ``component`` that ``output`` depends on directly (ModelStructure; an output
    that lists no dependencies, or is not listed, depends on every input)."""
    model = system.component(component).model
    inputs = tuple(v.name for v in model.modelVariables if v.causality == "input")
    for unknown in model.outputs:
        if unknown.variable.name == output:
            if unknown.dependencies is None:
                return inputs
            return tuple(d.name for d in unknown.dependencies if d.name in inputs)
    return inputs


def evaluation_plan(system: SystemDescription, order: Sequence[str] = ()) -> tuple[tuple[str, tuple[str, ...]], ...]:
    """The order the connected outputs are read in: ``(component, (output, ...))`` pairs.

    With ``order`` (the case's), each component once in that order with all its connected
    outputs.  Otherwise a topological order of the connected outputs along their direct
    dependencies (ties in the SSD's component order), consecutive outputs of one component
    merged; :class:`AlgebraicLoop` naming the loop when there is none.
    """
    connections = system.ssp.connections
    outputs: dict[str, list[str]] = {}
    for c in connections:
        outputs.setdefault(c.start_component, [])
        if c.start_connector not in outputs[c.start_component]:
            outputs[c.start_component].append(c.start_connector)
    if order:
        return tuple((name, tuple(outputs[name])) for name in order if name in outputs)
    feeder = {(c.end_component, c.end_connector): f"{c.start_component}.{c.start_connector}" for c in connections}
    rank = {name: i for i, name in enumerate(system.ssp.component_names)}
    nodes = sorted((f"{comp}.{out}" for comp, outs in outputs.items() for out in outs),
                   key=lambda key: (rank[key.partition(".")[0]], key))
    needs: dict[str, list[tuple[str, str]]] = {}   # output -> [(source output, the input it feeds)]
    for key in nodes:
        comp, _, out = key.partition(".")
        needs[key] = [(feeder[comp, i], f"{comp}.{i}") for i in _direct_inputs(system, comp, out) if (comp, i) in feeder]
    done: list[str] = []
    remaining = list(nodes)
    while remaining:
        ready = next((key for key in remaining if all(s in done for s, _ in needs[key])), None)
        if ready is None:
            raise AlgebraicLoop(_loop_message(remaining, needs))
        done.append(ready)
        remaining.remove(ready)
    plan: list[tuple[str, list[str]]] = []
    for key in done:
        comp, _, out = key.partition(".")
        if plan and plan[-1][0] == comp:
            plan[-1][1].append(out)
        else:
            plan.append((comp, [out]))
    return tuple((comp, tuple(outs)) for comp, outs in plan)


def _loop_message(remaining: list[str], needs: dict[str, list[tuple[str, str]]]) -> str:
    """'a -> b.in -> b.out -> ... -> a': one loop among the outputs that cannot be ordered."""
    path, key = [], remaining[0]
    while key not in path:
        path.append(key)
        key = next(s for s, _ in needs[key] if s in remaining)
    loop = path[path.index(key):] + [key]
    loop.reverse()          # along the signal: source output -> input -> the output that depends on it
    steps = [loop[0]]
    for source, target in zip(loop, loop[1:]):
        through = next(i for s, i in needs[target] if s == source)
        steps += [through, target]
    return (f"the connections close an algebraic loop: {' -> '.join(steps)} (each output depends directly on "
            f"the input before it, from its FMU's <ModelStructure>; an output that lists no dependencies "
            f"depends on every input); a monolithic integration needs every input known before it is read: "
            f"give [master] order, the order to evaluate the components in, if an output does not really "
            f"depend on its input")


def suggested_order(system: SystemDescription) -> tuple[str, ...]:
    """An order to offer for ``[master] order`` when an FMU that declares no output dependencies
    at all (e.g. a mechanism FMU, whose outputs are its coordinates and their rates: states)
    closes a loop: those components first, then the others along the connections that feed
    through by their declarations; () when every FMU declares its dependencies."""
    undeclared = {c.name for c in system.components
                  if c.model.outputs and all(u.dependencies is None for u in c.model.outputs)}
    if not undeclared:
        return ()
    feeds = set()
    for c in system.ssp.connections:
        if c.end_component not in undeclared:
            outputs = {x.start_connector for x in system.ssp.connections if x.start_component == c.end_component}
            if any(c.end_connector in _direct_inputs(system, c.end_component, o) for o in outputs):
                feeds.add((c.start_component, c.end_component))
    order, remaining = [], list(system.ssp.component_names)
    while remaining:
        ready = [n for n in remaining if n in undeclared] or \
                [n for n in remaining if not any((s, n) in feeds for s in remaining if s != n)] or remaining
        order.append(ready[0])
        remaining.remove(ready[0])
    return tuple(order)

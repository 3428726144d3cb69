"""What only numbers show about a mechanism description: checked before an FMU is built.

The description is consistent in its names (``description``); here its equations are
generated, and the mechanism is assembled at its start values with the same run-time code the
pythonfmu FMU ships (``mechanism_model.dae``).  Each problem raises MechanismError naming it:
- missing constraints: more degrees of freedom than [start] gives independent coordinates;
- too many: fewer degrees of freedom than that (or a structure that cannot move at all);
- redundant constraints: rows of Phi_q that depend on the others at the start configuration;
- a mechanism that cannot be assembled at its start values.
"""
from __future__ import annotations

from dataclasses import dataclass
from types import ModuleType

from pathlib import Path

from .derivation import MechanismEquations, derive
from .description import Mechanism, MechanismError, load_mechanism, resolve_mechanism

__all__ = ["CheckedMechanism", "check_mechanism", "prepare_mechanism", "start_state"]


@dataclass(frozen=True)
class CheckedMechanism:
    """A mechanism that assembles: its description, equations, generated Python module (the
    source and the module loaded in-process) and its degrees of freedom."""

    equations: MechanismEquations
    module: ModuleType
    source: str
    degrees_of_freedom: int

    @property
    def mechanism(self) -> Mechanism:
        return self.equations.mechanism


_PREPARED: dict[tuple, CheckedMechanism] = {}


def prepare_mechanism(spec: str | Path | Mechanism) -> CheckedMechanism:
    """Load (a shipped name, a path or a Mechanism), derive, generate and check a mechanism.

    Raises MechanismError naming what is wrong.  Cached per file and modification time, looked
    up before the file is parsed (a hit costs a stat, not a parse).
    """
    from .python_code import generate_module, load_module

    if isinstance(spec, Mechanism):
        mech, key = spec, ("object", id(spec))
    else:
        path = resolve_mechanism(str(spec)).resolve()
        key = (str(path), path.stat().st_mtime_ns)
    hit = _PREPARED.get(key)
    if hit is not None and (key[0] != "object" or hit.mechanism is spec):
        return hit
    if not isinstance(spec, Mechanism):
        mech = load_mechanism(spec)
    eqs = derive(mech)
    source = generate_module(eqs)
    checked = check_mechanism(eqs, source, load_module(source, mech.name))
    _PREPARED[key] = checked
    return checked


def start_state(module: ModuleType) -> tuple[list[float], list[float], tuple[float, ...]]:
    """(guess, rates, p) of the FMU's start values: the file's guesses with the independent
    coordinates and rates set from their start parameters."""
    starts = {v.name: v.start for v in module.VARIABLES}
    guess, rates = list(module.GUESS), [0.0] * module.N_COORDINATES
    for i, (position, rate) in zip(module.INDEPENDENT, module.START_PARAMETERS):
        guess[i], rates[i] = float(starts[position]), float(starts[rate])
    return guess, rates, tuple(float(starts[name]) for name in module.PARAMETERS)


def check_mechanism(eqs: MechanismEquations, source: str, module: ModuleType) -> CheckedMechanism:
    """Assemble the mechanism at its start values; raise MechanismError naming what is wrong."""
    from ..mechanism_model.dae import AssemblyError, MechanismDAE

    mech = eqs.mechanism
    where = mech.source
    guess, rates, p = start_state(module)
    dae = MechanismDAE(module, p)
    dae.q = guess
    problem = dae.rank_problem()          # at the guess: redundancy that holds everywhere
    if problem:
        raise MechanismError(f"{where}: {problem}")
    dof = eqs.n - eqs.m
    k = len(mech.independent)
    if dof > k:
        raise MechanismError(
            f"{where}: missing constraints: {eqs.n} coordinates and {eqs.m} constraint equations leave {dof} "
            f"degree{'s' if dof != 1 else ''} of freedom, but [start] gives {k} independent coordinate"
            f"{'s' if k != 1 else ''} ({', '.join(mech.independent) or 'none'}); add a joint or a driver, "
            f"or give the start value of each free coordinate in [start]")
    if dof < k or (dof == 0 and not mech.drivers):
        what = "cannot move" if dof <= 0 and not mech.drivers else f"has {max(dof, 0)} degree(s) of freedom"
        raise MechanismError(
            f"{where}: too many constraints: {eqs.n} coordinates and {eqs.m} constraint equations: the mechanism "
            f"{what}, but [start] gives {k} independent coordinate{'s' if k != 1 else ''}"
            f" ({', '.join(mech.independent) or 'none'}): remove a joint or a driver, or a [start] entry")
    try:
        dae.assemble(0.0, guess, rates)
    except AssemblyError as exc:
        given = ", ".join(f"{c} = {guess[module.COORDINATES.index(c)]:.6g}" for c in mech.independent)
        raise MechanismError(f"{where}: cannot be assembled at its start values ({given or 'the drivers at t = 0'}"
                             f", starting from the bodies' x, y, angle): {exc}") from None
    problem = dae.rank_problem()          # at the start configuration: a toggle, a parallel pair...
    if problem:
        raise MechanismError(f"{where}: at its start configuration, {problem}")
    return CheckedMechanism(eqs, module, source, dof)

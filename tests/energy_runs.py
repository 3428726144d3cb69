"""The mechanisms with force elements and their tight-tolerance runs, shared by
tests/test_energy_balance.py and tests/test_fmu_agreement_forces.py.

Every shipped mechanism (``fmu_src/mechanisms/``, the published benchmarks included) and every
test mechanism (``tests/mechanisms/``) with a spring, friction, a load or a torque or force input,
found by reading the files, so that a new one is picked up.  Its torque and force inputs follow
``input_signal`` (a sine each, set before every communication step by FMPy's ``input=``), so
that their work varies during the run.  Each runs once per session and FMU kind (pythonfmu and
native, the FMUs of ``conftest.mechanism_fmus``) at rtol = atol = TIGHT from t = 0 over 10 s, a
published benchmark over its published span (``PUBLISHED_BENCHMARKS``); the run records the
energy, the work outputs (``MechanismEquations.works``: drivers', loads', inputs', ``dissipated``) and
every output in m or rad (the joints' positions among them).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from support import REPO, file_key, shared_folder_of, shared_result

__all__ = ["ForceMechanism", "TIGHT", "KINDS", "force_mechanisms", "force_run", "input_signal"]

#: rtol = atol of the FMUs' integrator: the project's tight tolerances.
TIGHT = 1e-12
KINDS = ("pythonfmu", "native")
#: The span of a mechanism without a published one (s), and the points recorded over it.
STOP = 10.0
POINTS = 500


@dataclass(frozen=True)
class ForceMechanism:
    """A mechanism file with force elements: ``source`` as ``mechanism_fmus.get`` takes it."""

    label: str
    source: str
    stop: float
    works: tuple[str, ...]          # its work outputs, in MechanismEquations.works order
    inputs: tuple[str, ...] = ()    # its torque and force inputs (driven by input_signal)


def input_signal(k: int, t):
    """The k-th torque or force input's value at t (N.m or N): a sine of its own amplitude, period
    and phase, so that every input does work that goes both ways."""
    return (1.0 + 0.25 * k) * np.sin(2 * np.pi * t / (2.0 + 0.5 * k) + 0.7 * k)


def force_mechanisms() -> tuple[ForceMechanism, ...]:
    from fmu_src.mechanism.derivation import derive
    from fmu_src.mechanism.description import PUBLISHED_BENCHMARKS, load_mechanism, shipped_mechanisms

    sources = [(name, name) for name in shipped_mechanisms()]
    sources += [(p.stem, str(p)) for p in sorted((REPO / "tests" / "mechanisms").glob("*.toml"))]
    out = []
    for label, source in sources:
        mech = load_mechanism(source)
        inputs = tuple(i.name for i in mech.inputs if i.kind != "position")
        if mech.springs or mech.friction or mech.loads or inputs:
            works = tuple(w.name for w in derive(mech).works)
            out.append(ForceMechanism(label, source, PUBLISHED_BENCHMARKS.get(label, STOP), works, inputs))
    return tuple(out)


def force_run(mechanism_fmus, tmp_path_factory, mechanism: ForceMechanism, kind: str) -> dict[str, np.ndarray]:
    """``mechanism``'s run on its ``kind`` FMU (once per session: support.shared_result): time,
    ``energy``, its work outputs and every output in m or rad.  A file whose [outputs] leaves
    out one of them fails here, naming it: the balance needs them all."""
    from fmpy import read_model_description, simulate_fmu

    fmu = mechanism_fmus.get(mechanism.source, kind)
    md = read_model_description(str(fmu))
    outputs = {v.name: v.unit for v in md.modelVariables if v.causality == "output"}
    missing = [n for n in ("energy", *mechanism.works) if n not in outputs]
    assert not missing, (f"{mechanism.source}: [outputs] must list {', '.join(missing)} (the energy balance "
                         f"of docs/mechanisms.md needs them)")
    names = ["energy", *mechanism.works] + [n for n, unit in outputs.items() if unit in ("m", "rad")]

    signal = None
    if mechanism.inputs:    # sampled at the communication points, where FMPy sets the inputs
        t = np.linspace(0.0, mechanism.stop, POINTS + 1)
        signal = np.array(list(zip(t, *(input_signal(k, t) for k in range(len(mechanism.inputs))))),
                          dtype=[("time", float)] + [(n, float) for n in mechanism.inputs])

    def run():
        r = simulate_fmu(str(fmu), stop_time=mechanism.stop, output_interval=mechanism.stop / POINTS,
                         output=names, start_values={"rtol": TIGHT, "atol": TIGHT}, input=signal)
        return {n: np.array(r[n]) for n in ("time", *names)}

    key = repr((mechanism.source, kind, mechanism.stop, names, mechanism.inputs)).encode() + file_key(Path(fmu))
    return shared_result(shared_folder_of(tmp_path_factory), "energy-run", key, run)

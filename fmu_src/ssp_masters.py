"""An SSP 1.0 system (``.ssp``) run in three other co-simulation masters: FMPy, libcosim, Ecos.

``run_master("FMPy" | "libcosim" | "Ecos", ssp, stop_time, step, variables)`` runs ``ssp`` from
t = 0 for N = stop_time / step fixed macro steps and returns one ``MasterRun``: a row after
each step (t_1 .. t_N; no row for t = 0, which FMPy cannot give) with a column per
"component.variable" asked for.  What each master does differently is stated here, once, and
in docs/systems.md (*Running the bench in fourbar-run, FMPy, libcosim and Ecos*):

============== ==================== ==================== ====================
               FMPy simulate_ssp    libcosim (libcosimpy) Ecos (ecospy)
============== ==================== ==================== ====================
algorithm      Jacobi: every FMU    Jacobi (fixed_step_  Jacobi: every FMU
               steps from the       algorithm), the      steps (in parallel,
               values of the last   same                 TBB), then the
               exchange, then all                        connections are
               connections copied                        copied
row label      the step's START     the step's end, on   the step's end
               (``time`` before     libcosim's integer-  (``get_time()``
               ``time += step``)    nanosecond grid      after the step)
first step's   0.0 in every input   the connected        the connected
inputs         connector (the       outputs' values      outputs' values
               outputs at t = 0     after initialisation after initialisation
               are never read)      settled through      settled through
                                    feed-through         feed-through
input column   the value set for    the value held over  the value set for
               the next step        the step that ended  the next step
unconnected    fed the source of    left alone (start    left alone (start
input conn.    the input connector  value / binding)     value / binding)
               before it (FMPy
               0.3's get_connections):
               refused here
parameter      read, NOT applied by applied: inline      applied only for the
bindings       simulate_ssp; this   ssv:ParameterSet     ParameterSet NAME
               module passes them   and resources/*.ssv  given to init(); this
               as its parameter_set both                 module passes the
               argument (both forms)                     SSD's one set name, or
                                                         sets the values before
                                                         init() when the sets
                                                         have several names
time           ``time += step``     integer ns: the step (float seconds)
               (accumulates; its    must be a whole
               loop ``while time <  number of ns, t_n =
               stop`` can take one  n * step_ns / 1e9
               step more: this
               module passes stop =
               (N - 1/2) step)
what it        the SSD's input and  any variable         any variable
records        output connectors    (time-series         (``component::
               (a parameter one is  observer)            variable``)
               0.0: refused here)
FMI versions   1.0, 2.0 (3.0 is     1.0, 2.0 (3.0 is     2.0 and 3.0
               loaded as 2.0 and    not loaded):
               fails): refused here refused here
============== ==================== ==================== ====================

So the three agree to round-off when every connected output is 0.0 at t = 0 (or FMPy's first
step differs), no input connector is left unconnected, and rows are matched by step number
(``MasterRun.times``, n * step, not the masters' own ``labels``).  The native FMUs snap every
communication time to whole nanoseconds (docs/contracts.md), so FMPy's accumulated times and
libcosim's nanosecond grid drive identical arithmetic.

Build time and test time only: the masters' packages are imported when a run asks for them; a
missing one raises ``MasterMissing`` whose message says what to install (``available``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Mapping, Sequence

import numpy as np

__all__ = ["MASTERS", "MasterError", "MasterMissing", "MasterRun", "available", "bound_parameters", "main", "run_ecos",
           "run_fmpy", "run_libcosim", "run_master", "steps_of"]

MASTERS = ("FMPy", "libcosim", "Ecos")

_NS = 1_000_000_000         # libcosim counts time in integer nanoseconds


class MasterError(Exception):
    """A run a master cannot make as asked: the message names the SSP, the variable or the value."""


class MasterMissing(MasterError):
    """The master's Python package (or a library it needs) is not installed: the message says which."""


@dataclass(frozen=True)
class MasterRun:
    """One master's run of an .ssp: a row after each macro step n = 1..N.

    ``times[i]`` is (i + 1) * step, the communication point whose values row i holds (the same
    for every master: compare runs on it); ``labels[i]`` is the time the master itself gives
    that row (FMPy: the step's start; libcosim: nanoseconds / 1e9; Ecos: its clock).
    ``columns`` maps "component.variable" to the values."""
    master: str
    ssp: Path
    step: float
    times: np.ndarray
    labels: np.ndarray
    columns: Mapping[str, np.ndarray]

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]


def steps_of(stop_time: float, step: float) -> int:
    """N, the number of macro steps: stop_time / step, which must be a whole number (1e-9)."""
    if not (step > 0 and math.isfinite(step)) or not (stop_time > 0 and math.isfinite(stop_time)):
        raise MasterError(f"stop time {stop_time!r} s and step {step!r} s must be positive and finite")
    n = round(stop_time / step)
    if n < 1 or abs(n * step - stop_time) > 1e-9 * stop_time:
        raise MasterError(f"stop time {stop_time!r} s is not a whole number of steps of {step!r} s")
    return n


def available(master: str) -> str | None:
    """None when ``master`` can run here, else a message saying what to install."""
    try:
        _import(master)
    except MasterMissing as exc:
        return str(exc)
    return None


def _import(master: str):
    if master == "FMPy":
        import fmpy.ssp.simulation as module
        return module
    if master == "libcosim":
        try:
            import libcosimpy.CosimExecution as module
        except ImportError as exc:
            raise MasterMissing(f"libcosim: libcosimpy is not installed (pip install libcosimpy): {exc}") from None
        return module
    if master == "Ecos":
        try:
            import ecospy as module
        except ImportError as exc:
            raise MasterMissing(f"Ecos: ecospy is not installed (pip install ecospy): {exc}") from None
        except OSError as exc:     # its libecosc.so needs Intel TBB's run-time
            raise MasterMissing(f"Ecos: ecospy's library does not load ({exc}); install Debian's libtbb12 "
                                "(apt-get install libtbb12)") from None
        return module
    raise MasterError(f"unknown master {master!r}: one of {', '.join(MASTERS)}")


def _split(variable: str) -> tuple[str, str]:
    component, sep, name = variable.partition(".")
    if not sep or not component or not name:
        raise MasterError(f"variable {variable!r}: expected \"component.variable\"")
    return component, name


@dataclass(frozen=True)
class _Binding:
    component: str
    set_name: str | None
    values: Mapping[str, str]


def _bindings(ssp: Path) -> list[_Binding]:
    """Every component's parameter bindings (inline or resources/*.ssv), read with FMPy's SSD reader."""
    from fmpy.ssp.ssd import find_components, read_ssd

    ssd = read_ssd(str(ssp))
    found = []
    for component in find_components(ssd.system):
        for binding in component.parameterBindings:
            if binding.prefix or binding.parameterMapping:
                raise MasterError(f"{ssp}: component {component.name}: a parameter binding with a prefix or a "
                                  "parameter mapping is not supported here")
            for parameter_set in binding.parameterValues:
                found.append(_Binding(component.name, parameter_set.name,
                                      MappingProxyType({p.name: p.value for p in parameter_set.parameters})))
    if ssd.system.parameterBindings:
        raise MasterError(f"{ssp}: parameter bindings on the system itself are not supported here; bind each "
                          "component's values on the component")
    return found


def bound_parameters(ssp: str | Path) -> dict[str, float]:
    """The SSD's bound parameter values as {"component.parameter": value} (every binding form)."""
    return {f"{b.component}.{name}": float(value) for b in _bindings(Path(ssp)) for name, value in b.values.items()}


def _fmi_versions(ssp: Path) -> dict[str, str]:
    """{component: fmiVersion} of every component FMU, read from the archive's resources."""
    import io
    import xml.etree.ElementTree as ET
    import zipfile

    from fmpy.ssp.ssd import find_components, read_ssd

    versions = {}
    with zipfile.ZipFile(ssp) as archive:
        for component in find_components(read_ssd(str(ssp)).system):
            try:
                with zipfile.ZipFile(io.BytesIO(archive.read(component.source))) as fmu:
                    versions[component.name] = ET.fromstring(fmu.read("modelDescription.xml")).get("fmiVersion", "?")
            except (KeyError, zipfile.BadZipFile, ET.ParseError) as exc:
                raise MasterError(f"{ssp}: component {component.name}: {component.source} is not a readable FMU "
                                  f"({exc})") from None
    return versions


def _refuse_fmi3(ssp: Path, master: str) -> None:
    newer = [f"{name} (FMI {v})" for name, v in _fmi_versions(ssp).items() if not v.startswith(("1.", "2."))]
    if newer:
        raise MasterError(f"{ssp}: {master} runs FMI 1.0 and 2.0 components only, not {', '.join(newer)}: "
                          "use the FMI 2.0 FMUs (<Name>Native.fmu), or Ecos")


# -- FMPy ---------------------------------------------------------------------------------------

def run_fmpy(ssp: str | Path, stop_time: float, step: float, variables: Sequence[str]) -> MasterRun:
    """``fmpy.ssp.simulation.simulate_ssp``: Jacobi; see the module's table for its conventions."""
    ssp = Path(ssp)
    n = steps_of(stop_time, step)
    simulation = _import("FMPy")
    from fmpy.ssp.ssd import Parameter, ParameterSet, find_components, read_ssd

    _refuse_fmi3(ssp, "FMPy's simulate_ssp")
    ssd = read_ssd(str(ssp))
    components = [c.name for c in find_components(ssd.system)]
    for a in components:        # simulate_ssp matches a parameter to a component by str.startswith
        for b in components:
            if a != b and b.startswith(a):
                raise MasterError(f"{ssp}: FMPy's simulate_ssp would give component {b!r}'s parameters to "
                                  f"{a!r} (its name is a prefix of the other's): rename one")
    # The SSD's own connections, not fmpy's get_connections: for an input connector with no
    # connection, get_connections pairs it with the source of the input connector before it
    # (a variable left over from its previous loop turn) or fails when there is none.
    connected = {(c.endElement, c.endConnector) for c in ssd.system.connections}
    loose = [f"{c.name}.{k.name}" for c in find_components(ssd.system) for k in c.connectors
             if k.kind == "input" and (c.name, k.name) not in connected]
    if loose:
        raise MasterError(f"{ssp}: input connector(s) {', '.join(loose)} have no connection: FMPy's simulate_ssp "
                          "would feed each the source of the input connector before it (or 0.0 in the first "
                          "step), never its start value; leave an unconnected input out of the SSD's connectors")
    # simulate_ssp reads the SSD's bindings but applies only its parameter_set argument, whose
    # names are "component.parameter": the SSD's own values passed that way.
    parameters = ParameterSet(name="bindings")
    for name, value in bound_parameters(ssp).items():
        parameter = Parameter(name=name)
        parameter.type, parameter.value = "Real", value
        parameters.parameters.append(parameter)

    # Its loop is `while time < stop_time: ...; time += step_size`: (N - 1/2) steps makes exactly N.
    try:
        result = simulation.simulate_ssp(str(ssp), start_time=0.0, stop_time=(n - 0.5) * step, step_size=step,
                                         parameter_set=parameters if parameters.parameters else None)
    except Exception as exc:          # FMPy raises bare Exceptions (an FMU's failed call, a missing variable)
        raise MasterError(f"{ssp}: FMPy's simulate_ssp failed: {exc}") from None
    missing = [v for v in variables if v not in (result.dtype.names or ())]
    kinds = {f"{c.name}.{k.name}": k.kind for c in find_components(ssd.system) for k in c.connectors}
    unread = [v for v in variables if kinds.get(v, "output") not in ("input", "output")]
    if unread:            # simulate_ssp records such a connector but never reads it: 0.0 throughout
        raise MasterError(f"{ssp}: FMPy's simulate_ssp records {', '.join(unread)} (a {kinds[unread[0]]} "
                          "connector) as 0.0: it reads output connectors only")
    if missing:
        raise MasterError(f"{ssp}: FMPy's simulate_ssp records the SSD's connectors only; {', '.join(missing)} "
                          "is not one (declare it as an output connector)")
    if len(result) != n:
        raise MasterError(f"{ssp}: FMPy made {len(result)} steps, not {n}")
    return MasterRun("FMPy", ssp, step, _grid(n, step), np.asarray(result["time"], dtype=float),
                     MappingProxyType({v: np.array(result[v], dtype=float) for v in variables}))


def _grid(n: int, step: float) -> np.ndarray:
    return np.arange(1, n + 1) * step


# -- libcosim -----------------------------------------------------------------------------------

def run_libcosim(ssp: str | Path, stop_time: float, step: float, variables: Sequence[str]) -> MasterRun:
    """libcosim through libcosimpy's ``CosimExecution.from_ssp_file``: Jacobi, integer nanoseconds."""
    ssp = Path(ssp)
    n = steps_of(stop_time, step)
    step_ns = round(step * _NS)
    if abs(step_ns - step * _NS) > 1e-6 or step_ns < 1:
        raise MasterError(f"step {step!r} s is not a whole number of nanoseconds (libcosim's time unit)")
    module = _import("libcosim")
    _refuse_fmi3(ssp, "libcosim")
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.WARNING)           # it logs every FMI call by default
    try:
        execution = module.CosimExecution.from_ssp_file(str(ssp.resolve()), step_ns)
    except AssertionError as exc:
        raise MasterError(f"{ssp}: libcosim cannot load it: {exc}") from None
    observer = CosimObserver.create_time_series(buffer_size=n + 10)
    execution.add_observer(observer=observer)
    slots = {}
    for variable in variables:
        component, name = _split(variable)
        index = execution.slave_index_from_instance_name(component)
        if index is None or index < 0:
            raise MasterError(f"{ssp}: libcosim has no component {component!r} ({variable})")
        refs = {v.name.decode(): v.reference for v in execution.slave_variables(index)}
        if name not in refs:
            raise MasterError(f"{ssp}: component {component!r} has no variable {name!r}")
        slots[variable] = (index, refs[name])
        observer.start_time_series(index, refs[name], CosimVariableType.REAL)
    if not execution.step(n) or execution.status().current_time != n * step_ns:
        raise MasterError(f"{ssp}: libcosim stopped at {execution.status().current_time / _NS} s, not {n * step_ns / _NS} s")
    columns, labels = {}, None
    for variable, (index, ref) in slots.items():
        # from step 1: libcosimpy 0.0.6 drops a sample when step 0 is among those asked for
        t, steps, values = observer.time_series_real_samples(index, ref, from_step=1, sample_count=n)
        if list(steps) != list(range(1, n + 1)):
            raise MasterError(f"{ssp}: libcosim's observer returned steps {list(steps)[:3]}... for {variable}")
        labels = np.array(t, dtype=np.int64) / _NS
        columns[variable] = np.array(values, dtype=float)
    if labels is None:
        labels = np.arange(1, n + 1) * step_ns / _NS
    return MasterRun("libcosim", ssp, step, _grid(n, step), labels, MappingProxyType(columns))


# -- Ecos ---------------------------------------------------------------------------------------

def run_ecos(ssp: str | Path, stop_time: float, step: float, variables: Sequence[str]) -> MasterRun:
    """Ecos through ecospy's ``EcosSimulation(ssp_path=..., step_size=...)``: Jacobi, steps in parallel."""
    ssp = Path(ssp)
    n = steps_of(stop_time, step)
    ecospy = _import("Ecos")
    # Ecos loads every ParameterSet of the SSD but applies one, the one whose name init() is
    # given.  When every component's set carries the same name, that name is given; else each
    # bound value is set before init() (a start value, as the binding would be).
    bindings = _bindings(ssp)
    names = sorted({b.set_name or "" for b in bindings})
    ecospy.EcosLib.set_log_level("warn")
    try:
        simulation = ecospy.EcosSimulation(ssp_path=str(ssp.resolve()), step_size=step)
    except Exception as exc:          # ecospy raises a bare Exception carrying Ecos's message
        raise MasterError(f"{ssp}: Ecos cannot load it: {exc}") from None
    try:
        identifiers = {}
        for variable in variables:
            component, name = _split(variable)
            identifiers[variable] = f"{component}::{name}"
        if len(names) > 1:
            for binding in bindings:
                for name, value in binding.values.items():
                    simulation.set_real(f"{binding.component}::{name}", float(value))
        if not simulation.init(0.0, names[0] if len(names) == 1 else None):
            raise MasterError(f"{ssp}: Ecos could not initialise it: {ecospy.EcosLib.get_last_error()}")
        rows, labels = [], []
        for _ in range(n):
            simulation.step(1)
            labels.append(simulation.get_time())
            try:
                rows.append([simulation.get_real(identifiers[v]) for v in variables])
            except Exception as exc:
                raise MasterError(f"{ssp}: Ecos cannot read {list(variables)}: {exc}") from None
        simulation.terminate()
    finally:
        simulation.free()
    table = np.array(rows, dtype=float).reshape(n, len(variables))
    return MasterRun("Ecos", ssp, step, _grid(n, step), np.array(labels, dtype=float),
                     MappingProxyType({v: table[:, i].copy() for i, v in enumerate(variables)}))


_RUNNERS = {"FMPy": run_fmpy, "libcosim": run_libcosim, "Ecos": run_ecos}


def run_master(master: str, ssp: str | Path, stop_time: float, step: float, variables: Sequence[str]) -> MasterRun:
    """Run ``ssp`` in ``master`` (one of MASTERS)."""
    if master not in _RUNNERS:
        raise MasterError(f"unknown master {master!r}: one of {', '.join(MASTERS)}")
    return _RUNNERS[master](ssp, stop_time, step, list(variables))


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m fmu_src.ssp_masters SYSTEM.ssp --stop S --step H VAR...``: run the system in
    every master installed here and print, per master, its wall time and its largest difference
    from the first one's values (rows matched by step number).  Exit 2 on bad input."""
    import argparse
    import sys
    import time

    parser = argparse.ArgumentParser(prog="python -m fmu_src.ssp_masters", description=main.__doc__.split("\n\n")[0])
    parser.add_argument("ssp", help="the SSP 1.0 archive (.ssp)")
    parser.add_argument("variables", nargs="+", metavar="COMPONENT.VARIABLE", help="the values to compare")
    parser.add_argument("--stop", type=float, required=True, help="stop time, s (a whole number of steps)")
    parser.add_argument("--step", type=float, required=True, help="macro step, s")
    args = parser.parse_args(argv)
    if not Path(args.ssp).is_file():
        print(f"{parser.prog}: {args.ssp}: no such file", file=sys.stderr)
        return 2
    first: MasterRun | None = None
    for master in MASTERS:
        missing = available(master)
        if missing is not None:
            print(f"{master:9s} skipped: {missing}")
            continue
        began = time.perf_counter()
        try:
            run = run_master(master, args.ssp, args.stop, args.step, args.variables)
        except MasterError as exc:
            print(f"{parser.prog}: {exc}", file=sys.stderr)
            return 2
        wall = time.perf_counter() - began
        if first is None:
            first = run
            print(f"{master:9s} {wall:7.2f} s  {len(run.times)} steps (the reference)")
        else:
            worst, where = max((float(np.max(np.abs(run[v] - first[v]))), v) for v in args.variables)
            print(f"{master:9s} {wall:7.2f} s  largest |{master} - {first.master}| = {worst:.3g} ({where})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

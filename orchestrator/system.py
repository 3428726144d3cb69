"""A system of FMUs run as one instance: :class:`SystemInstance`, the master algorithm.

:class:`SystemInstance` has the interface the run loop (:mod:`orchestrator.run`) drives one
:class:`~orchestrator.fmi_instance.FmuInstance` through (a context manager; ``setup_experiment``,
``set_values``, ``drive_inputs``/``set_inputs``, initialisation mode, ``reader``, ``do_step``,
``abandon``), with variables named ``component.variable``.  So a system run keeps every promise
of a one-FMU run (atomic run.json, heartbeat, signals, nothing lost); a failing component's
error is its own FMI message prefixed with ``component 'name' (its FMU)``.

Set-up, per component in the SSD's order: extract its FMU from the archive (into a temporary
folder removed on leaving), instantiate it (instance name = component name), set up the
experiment, set the SSP's parameter bindings, then the case's start values; every component
enters initialisation mode, where the connections are settled as libcosim and Ecos settle
them (:meth:`SystemInstance._settle`); every component leaves it; every connected output is
read (``y(t0)``).

One macro step ``t_k -> t_{k+1} = t_k + h`` (``do_step``; ``y_k``: a connection's source
output at ``t_k``):

- **Jacobi** (what FMPy's ``simulate_ssp`` and libcosim do): every connected input is set to
  ``y_k``, then every component steps from ``t_k``; then the connected outputs are read
  (``y_{k+1}``).  The components are independent within a step.
- **Gauss–Seidel**: the components step one after the other in :func:`~orchestrator.system_order.gauss_seidel_order`;
  each is given the newest value of each of its inputs: ``y_{k+1}`` of a source that stepped
  before it in this macro step, ``y_k`` of one that did not.
- **Inputs** ``hold`` (default): each input is constant over the step at that value.
  ``extrapolate``: an FMI 2.0 co-simulation component that says ``canInterpolateInputs`` is
  also given the first derivative (``fmi2SetRealInputDerivatives``, order 1), so the input is
  linear within the step: ``(y_k - y_{k-1})/h`` (extrapolated from the last two communication
  points; 0 at the first step) for a source not yet stepped, ``(y_{k+1} - y_k)/h`` with the
  value ``y_k`` (interpolated) for one that stepped before it (Gauss–Seidel).  Components that
  cannot interpolate their inputs get them held.

The first step uses ``y(t0)``, the outputs after initialisation (FMPy's ``simulate_ssp`` gives
every input 0.0 at its first step instead: docs/orchestrator.md, "Systems").

The replay of ``fourbar-diagnose`` (diagnose.simulator) drives the same instance through
``get_state``/``set_state``/``free_state`` (every component's FMU state plus the master's
memory of the connected outputs: a branch restarts exactly where the healthy replay was),
``reset`` and ``step_through``.
"""
from __future__ import annotations

import contextlib
import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from .case import FmuDescription, Master, _stamp
from .fmi_instance import FmuError
from .system_description import SystemDescription
from .system_order import step_order

__all__ = ["SystemInstance"]


class _Link:
    """One connection, resolved: source component and output, target component and input."""

    __slots__ = ("source", "output", "target", "input", "key")

    def __init__(self, source: str, output: str, target: str, input_: str):
        self.source, self.output, self.target, self.input = source, output, target, input_
        self.key = f"{source}.{output}"


class SystemInstance:
    """The components of a system, stepped by the master algorithm ``master`` (module docstring)."""

    def __init__(self, description: SystemDescription, master: Master, instance_name: str = "system"):
        self.description = description
        self.master = master
        self.instance_name = instance_name
        self.path = description.path
        self.names = description.ssp.component_names
        self.order = step_order(description, master)
        self.links = [_Link(c.start_component, c.start_connector, c.end_component, c.end_connector)
                      for c in description.ssp.connections]
        self._feeding = {name: [link for link in self.links if link.target == name] for name in self.names}
        self.instances: dict[str, Any] = {}
        self._stack: contextlib.ExitStack | None = None
        self._folder: Path | None = None
        self._now: dict[str, float] = {}      # each connected output at the last communication point
        self._before: dict[str, float] = {}   # ... and at the one before (extrapolation)
        self._h_before: float | None = None
        self._driven: dict[str, list] = {}
        self._readers: dict[str, Callable[[], dict[str, float]]] = {}
        self._extrapolate = master.inputs == "extrapolate"

    # -- life cycle -------------------------------------------------------------------
    def __enter__(self) -> "SystemInstance":
        from .ssp import component_bytes

        self._stack = contextlib.ExitStack()
        try:
            self._folder = Path(tempfile.mkdtemp(prefix="fourbar-ssp-"))
            for component in self.description.components:
                fmu = self._folder / f"{component.name}.fmu"
                fmu.write_bytes(component_bytes(self.description.ssp, component.name))
                described = FmuDescription(path=fmu, stamp=_stamp(fmu), model=component.model,
                                           own_types=component.own_types)
                instance = self._instance_for(described, component.name)
                self.instances[component.name] = self._named(component.name, lambda: self._stack.enter_context(instance))
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def _instance_for(self, described: FmuDescription, name: str) -> Any:
        """The (not yet entered) instance of one component: its co-simulation interface."""
        from .instance import instance_for

        return instance_for(described, name, "CoSimulation")

    def __exit__(self, exc_type, exc, tb) -> None:
        stack, self._stack = self._stack, None
        try:
            if stack is not None:
                stack.__exit__(exc_type, exc, tb)
        finally:
            folder, self._folder = self._folder, None
            if folder is not None:
                shutil.rmtree(folder, ignore_errors=True)

    def abandon(self) -> None:
        """A thread is stuck inside a component's call: free none of them (see FmuInstance.abandon)."""
        for instance in self.instances.values():
            instance.abandon()

    def _named(self, name: str, call: Callable[[], Any]) -> Any:
        """``call()``, its :class:`FmuError` prefixed with the component's name and FMU."""
        try:
            return call()
        except FmuError as exc:
            source = self.description.component(name).source.rsplit("/", 1)[-1]
            raise FmuError(f"component {name!r} ({source}): {exc}", exc.status) from None

    # -- set-up -------------------------------------------------------------------------
    def setup_experiment(self, start: float, stop: float, tolerance: float | None) -> None:
        """Each component's experiment, then the SSP's parameter bindings."""
        for name, instance in self.instances.items():
            self._named(name, lambda: instance.setup_experiment(start, stop, tolerance))
            bound = self.description.ssp.bindings(name)
            if bound:
                values = [(variable, _typed(instance.variables[variable].type, p.value)) for variable, p in bound.items()]
                self._named(name, lambda: instance.set_values(values))

    def set_values(self, values: Iterable[tuple[str, Any]]) -> None:
        """Set ``component.variable`` values (grouped per component)."""
        for name, items in self._by_component(values).items():
            instance = self.instances[name]
            self._named(name, lambda: instance.set_values(items))

    def _by_component(self, values: Iterable[tuple[str, Any]]) -> dict[str, list[tuple[str, Any]]]:
        groups: dict[str, list[tuple[str, Any]]] = {}
        for full, value in values:
            component, _, variable = full.partition(".")
            groups.setdefault(component, []).append((variable, value))
        return groups

    def drive_inputs(self, names: Sequence[str], signals: Sequence, order: int = 0) -> None:
        """The case's ``[inputs]`` on unconnected component inputs (held over each step)."""
        grouped = self._by_component(zip(names, signals))
        for name, items in grouped.items():
            self.instances[name].drive_inputs([v for v, _ in items], [s for _, s in items], 0)
        self._driven = {name: items for name, items in grouped.items()}

    def set_inputs(self, t: float, derivatives: bool = True) -> None:
        for name in self._driven:
            instance = self.instances[name]
            self._named(name, lambda: instance.set_inputs(t, derivatives=False))

    def enter_initialization_mode(self) -> None:
        """Every component enters initialisation mode; then the connections are settled there."""
        for name, instance in self.instances.items():
            self._named(name, instance.enter_initialization_mode)
        self._readers = {name: self._connected_reader(name) for name in self.names}
        self._settle()

    def _settle(self) -> None:
        """Settle the connections in initialisation mode, as libcosim and Ecos do: N rounds (N
        components) of reading every connected output, each round after the first setting every
        connected input to the previous round's values.  A chain of direct feed-through shorter
        than N reaches its fixed point, so the components leave initialisation with inputs
        consistent with their sources (a motor's initial torque with the crank's initial speed)."""
        values: dict[str, float] = {}
        for round_ in range(len(self.names)):
            if round_:
                for name in self.names:
                    links = self._feeding[name]
                    if links:
                        instance = self.instances[name]
                        self._named(name, lambda: instance.set_values([(link.input, values[link.key])
                                                                        for link in links]))
            values = {}
            for name in self.names:
                values.update(self._named(name, self._readers[name]))

    def exit_initialization_mode(self) -> None:
        for name, instance in self.instances.items():
            self._named(name, instance.exit_initialization_mode)
        for name in self.names:
            self._now.update(self._named(name, self._readers[name]))

    def _connected_reader(self, name: str) -> Callable[[], dict[str, float]]:
        outputs = sorted({link.output for link in self.links if link.source == name})
        if not outputs:
            return dict
        read = self.instances[name].reader(outputs)
        keys = [f"{name}.{o}" for o in outputs]
        return lambda: dict(zip(keys, read()))

    # -- reading rows -----------------------------------------------------------------
    def reader(self, names: Sequence[str]) -> Callable[[], list]:
        """A function returning the current values of ``component.variable`` names, in order."""
        plan = []
        for component, items in self._by_component((n, i) for i, n in enumerate(names)).items():
            plan.append((self.instances[component].reader([v for v, _ in items]), [i for _, i in items]))
        n = len(names)

        def read() -> list:
            row = [0.0] * n
            for read_component, where in plan:
                for i, value in zip(where, read_component()):
                    row[i] = value
            return row

        return read

    # -- the master step --------------------------------------------------------------
    def do_step(self, t: float, h: float) -> None:
        """One macro step from ``t`` to ``t + h`` (module docstring)."""
        start = dict(self._now)           # y_k
        newest = dict(start)              # y_{k+1} of the sources stepped so far (Gauss-Seidel)
        stepped: set[str] = set()
        gauss_seidel = self.master.algorithm == "gauss-seidel"
        if not gauss_seidel:
            for name in self.order:
                self._give_inputs(name, start, newest, stepped, h)
        for name in self.order:
            if gauss_seidel:
                self._give_inputs(name, start, newest, stepped, h)
            instance = self.instances[name]
            self._named(name, lambda: instance.do_step(t, h))
            if gauss_seidel:
                newest.update(self._readers[name]())
                stepped.add(name)
        if not gauss_seidel:
            for name in self.names:
                newest.update(self._readers[name]())
        self._before, self._now, self._h_before = start, newest, h

    def _give_inputs(self, name: str, start: dict, newest: dict, stepped: set, h: float) -> None:
        links = self._feeding[name]
        if not links:
            return
        instance = self.instances[name]
        interpolate = self._extrapolate and self.description.component(name).can_interpolate_inputs
        values, slopes = [], []
        for link in links:
            if link.source in stepped and link.source != name:
                if interpolate:        # linear from y_k to y_{k+1} over this step
                    values.append(start[link.key])
                    slopes.append((newest[link.key] - start[link.key]) / h)
                else:
                    values.append(newest[link.key])
                    slopes.append(0.0)
            else:
                values.append(start[link.key])
                slopes.append((start[link.key] - self._before[link.key]) / self._h_before
                              if interpolate and self._h_before else 0.0)
        self._named(name, lambda: instance.set_values([(link.input, v) for link, v in zip(links, values)]))
        if interpolate:
            self._named(name, lambda: instance.set_real_input_derivatives([link.input for link in links], slopes))

    # -- the replay (fourbar-diagnose) ----------------------------------------------------
    def get_state(self) -> "_SystemState":
        """Every component's FMU state and the master's connected outputs (free it with :meth:`free_state`)."""
        states: dict[str, Any] = {}
        try:
            for name, instance in self.instances.items():
                states[name] = self._named(name, instance.get_state)
        except BaseException:
            for name, state in states.items():
                self.instances[name].free_state(state)
            raise
        return _SystemState(states, dict(self._now), dict(self._before), self._h_before)

    def set_state(self, state: "_SystemState") -> None:
        for name, instance in self.instances.items():
            self._named(name, lambda: instance.set_state(state.components[name]))
        self._now, self._before, self._h_before = dict(state.now), dict(state.before), state.h_before

    def free_state(self, state: "_SystemState") -> None:
        for name, instance in self.instances.items():
            self._named(name, lambda: instance.free_state(state.components[name]))

    def reset(self) -> None:
        for name, instance in self.instances.items():
            self._named(name, instance.reset)
        self._now, self._before, self._h_before = {}, {}, None

    def step_through(self, times: Sequence[float], outputs: Sequence[str], out,
                     changes: tuple[str, Sequence[float]] | None = None) -> None:
        """Macro steps from ``times[0]`` through every later time, the ``component.variable``
        ``outputs`` after step ``i`` in row ``i`` of ``out``; ``changes = (name, values)`` sets
        ``name`` to ``values[i]`` before step ``i`` (as the run sets a fault), as
        :meth:`orchestrator.instance.Fmi2CoSimulation.step_through` does for one FMU."""
        name, values = changes if changes else ("", ())
        if not self._extrapolate and all(hasattr(i, "direct_calls") for i in self.instances.values()):
            self._direct_steps(times, outputs, out, name, values)
            return
        read = self.reader(outputs) if len(outputs) else None
        for i in range(len(times) - 1):
            if i < len(values):
                self.set_values([(name, float(values[i]))])
            self.do_step(times[i], times[i + 1] - times[i])
            if read is not None:
                out[i] = read()


    def _direct_steps(self, times: Sequence[float], outputs: Sequence[str], out, name: str, values) -> None:
        """:meth:`step_through` with held inputs, through each component's own FMI 2.0 functions
        (ctypes, buffers made once): the same calls in the same order as :meth:`do_step`, so
        the same numbers, about three times faster (the replay takes ~10^5 macro steps)."""
        from ctypes import c_double, c_uint

        gauss_seidel = self.master.algorithm == "gauss-seidel"
        plans = []
        for component in self.order:
            instance = self.instances[component]
            handle, do_step, get_real, set_real, failure = instance.direct_calls()
            links = self._feeding[component]
            in_keys = [link.key for link in links]
            in_vrs = (c_uint * len(links))(*(instance.variables[link.input].valueReference for link in links))
            own = sorted({link.output for link in self.links if link.source == component})
            out_keys = [f"{component}.{o}" for o in own]
            out_vrs = (c_uint * len(own))(*(instance.variables[o].valueReference for o in own))
            plans.append((component, handle, do_step, get_real, set_real, failure, in_keys, in_vrs,
                          (c_double * len(links))(), out_keys, out_vrs, (c_double * len(own))()))
        rows = self._by_component((n, i) for i, n in enumerate(outputs))
        readers = []
        for component, items in rows.items():
            instance = self.instances[component]
            vrs = (c_uint * len(items))(*(instance.variables[v].valueReference for v, _ in items))
            readers.append((instance.direct_calls(), vrs, (c_double * len(items))(), [i for _, i in items]))
        row = np.empty(len(outputs))

        def failed(component: str, what: str, status: int, failure) -> FmuError:
            source = self.description.component(component).source.rsplit("/", 1)[-1]
            exc = failure(what, status)
            return FmuError(f"component {component!r} ({source}): {exc}", exc.status)

        def give(plan, now: dict) -> None:
            component, handle, _, _, set_real, failure, in_keys, in_vrs, in_buf = plan[:9]
            if in_keys:
                for j, key in enumerate(in_keys):
                    in_buf[j] = now[key]
                status = set_real(handle, in_vrs, len(in_keys), in_buf)
                if status > 1:
                    raise failed(component, "fmi2SetReal (connected inputs)", status, failure)

        def take(plan, now: dict) -> None:
            component, handle, _, get_real, _, failure = plan[:6]
            out_keys, out_vrs, out_buf = plan[9:]
            if out_keys:
                status = get_real(handle, out_vrs, len(out_keys), out_buf)
                if status > 1:
                    raise failed(component, "fmi2GetReal (connected outputs)", status, failure)
                for j, key in enumerate(out_keys):
                    now[key] = out_buf[j]

        for i in range(len(times) - 1):
            if i < len(values):
                self.set_values([(name, float(values[i]))])
            t = times[i]
            h = times[i + 1] - t
            start = self._now
            newest = dict(start)
            if not gauss_seidel:
                for plan in plans:
                    give(plan, start)
            for plan in plans:
                if gauss_seidel:
                    give(plan, newest)
                status = plan[2](plan[1], t, h, 1)
                if status > 1:
                    raise failed(plan[0], f"fmi2DoStep(t = {t!r} s, h = {h!r} s)", status, plan[5])
                if gauss_seidel:
                    take(plan, newest)
            if not gauss_seidel:
                for plan in plans:
                    take(plan, newest)
            self._before, self._now, self._h_before = start, newest, h
            for (handle, _, get_real, _, failure), vrs, buf, where in readers:
                get_real(handle, vrs, len(where), buf)
                for j, k in enumerate(where):
                    row[k] = buf[j]
            if len(outputs):
                out[i] = row


class _SystemState:
    """A saved system (:meth:`SystemInstance.get_state`)."""

    __slots__ = ("components", "now", "before", "h_before")

    def __init__(self, components: dict, now: dict, before: dict, h_before: float | None):
        self.components, self.now, self.before, self.h_before = components, now, before, h_before


def _typed(kind: str, value: Any) -> Any:
    if kind == "Real":
        return float(value)
    if kind in ("Integer", "Enumeration"):
        return int(value)
    if kind == "Boolean":
        return bool(value)
    return value

"""A system of FMUs integrated as one model: :class:`MonolithicSystem`, the reference without
coupling error (``[master] algorithm = "monolithic"``).

A co-simulation master (:mod:`orchestrator.system`) exchanges the components' values at the
macro steps only, so its result carries a coupling error that shrinks with the step.  The
monolithic master has none: every component is instantiated through its Model Exchange
interface (FMPy's ``FMU2Model``/``FMU3Model``), and the states of all of them are integrated
together as one ODE ``x' = f(t, x)`` by scipy's explicit Runge–Kutta DOP853 (order 8, dense
output of order 7), relative tolerance the case's ``[experiment] tolerance``
(default :data:`DEFAULT_RTOL`), absolute tolerance :data:`ATOL_RATIO` times it.

One evaluation of ``f`` (:meth:`MonolithicSystem._evaluate`): every component gets the time
and its slice of ``x`` (and the case's ``[inputs]`` at that time); then the connected outputs
are read in the :func:`evaluation_plan`'s order, each component's connected inputs set from
its sources' values as soon as they are known, so every output is read after every input it
depends on; then every connected input is set and every component's derivatives are read.

The order comes from the outputs' direct dependencies on inputs (the modelDescription's
``<ModelStructure><Outputs>``; an output that lists no ``dependencies`` depends on every
input).  A cycle of such dependencies through the connections is an algebraic loop, which an
explicit integration cannot solve: the case is refused with a message naming the loop, unless
the case gives ``[master] order``, the components' evaluation order, which the case then vouches
for (an output whose FMU declares no dependencies but that does not really feed through, e.g.
a mechanism's crank speed, which is a state).

The rows are written at the macro step ``[experiment] step``, as for the co-simulation
masters (the integrator's own steps are independent of it: its dense output gives the values
at the rows).  A case's events set their values between macro steps: the components that
change go through event mode, and the integration restarts at that time.  An FMU's step
events (``completedIntegratorStep``) are honoured; state events (event indicators) are not
located: a component with event indicators is refused.
"""
from __future__ import annotations

from typing import Any, Iterable, Sequence

from .fmi_instance import FmuError
from .system import SystemInstance
from .system_description import SystemDescription
from .system_order import AlgebraicLoop, evaluation_plan, suggested_order

__all__ = ["ALGORITHM", "ATOL_RATIO", "DEFAULT_RTOL", "MonolithicSystem", "monolithic_problems"]

#: The ``[master] algorithm`` of this master.
ALGORITHM = "monolithic"
#: DOP853's relative tolerance without ``[experiment] tolerance``: tight, so that the reference's
#: own error is far below the coupling errors it measures (docs/systems.md, "Coupling error").
DEFAULT_RTOL = 1e-10
#: The absolute tolerance is this times the relative one.
ATOL_RATIO = 1e-2


def monolithic_problems(system: SystemDescription, order: Sequence[str] = ()) -> list[str]:
    """Why ``system`` cannot be integrated as one model (empty: it can)."""
    problems = []
    for component in system.components:
        model = component.model
        if model.modelExchange is None:
            problems.append(f"component {component.name!r} ({component.source}) offers no model exchange interface; "
                            f"the monolithic master integrates every component's states itself")
        elif int(getattr(model, "numberOfEventIndicators", 0) or 0):
            problems.append(f"component {component.name!r} ({component.source}) has event indicators; the "
                            f"monolithic master does not locate state events")
    try:
        evaluation_plan(system, order)
    except AlgebraicLoop as exc:
        offer = suggested_order(system)
        problems.append(str(exc) + (f" (e.g. order = [{', '.join(map(repr, offer))}]: first the components whose FMU "
                                    f"declares no dependencies)".replace("'", '"') if offer else ""))
    return problems


class _HostIntegrated:
    """A model-exchange instance whose states the system integrates: no solver of its own;
    after initialisation in continuous-time mode; a value set later goes through event mode."""

    _continuous = False

    def _initialized(self) -> None:
        self._event_iteration()
        self._continuous = True

    def set_values(self, values: Iterable[tuple[str, Any]]) -> None:
        if not self._continuous:
            self._set(values)
            return
        self._call(f"{self.PREFIX}EnterEventMode", self._fmu.enterEventMode)
        self._set(values)
        self._event_iteration()

    def do_step(self, t: float, h: float) -> None:      # the system integrates (MonolithicSystem.do_step)
        raise NotImplementedError("a component of a monolithic system does not step on its own")


def _host_integrated(description, name: str):
    """The model-exchange instance of ``description``'s FMU, integrated by the system."""
    from .instance import FLAVOURS

    version = "3" if str(description.model.fmiVersion).startswith("3") else "2"
    flavour = FLAVOURS[version, "ModelExchange"]
    kind = type(f"HostIntegrated{flavour.__name__}", (_HostIntegrated, flavour), {})
    return kind(description, name)


class MonolithicSystem(SystemInstance):
    """The components of a system integrated as one model (module docstring); the interface of
    :class:`~orchestrator.system.SystemInstance`, which it shares the set-up and reading with."""

    def __init__(self, description: SystemDescription, master, instance_name: str = "system"):
        super().__init__(description, master, instance_name)
        self.plan = evaluation_plan(description, master.order)
        self._solver = None
        self._stop = 0.0
        self._rtol = DEFAULT_RTOL
        self._slices: list[tuple[str, Any, int, int]] = []   # (name, FMPy object, first, count)
        self._t = 0.0
        self._order_checked = False     # the case's order, checked at the first step (_check_order)
        self.evaluations = 0            # evaluations of f (benchmarks report them)

    def _instance_for(self, described, name: str):
        return _host_integrated(described, name)

    def setup_experiment(self, start: float, stop: float, tolerance: float | None) -> None:
        super().setup_experiment(start, stop, tolerance)
        self._t, self._stop = start, stop
        self._rtol = tolerance or DEFAULT_RTOL

    def set_values(self, values: Iterable[tuple[str, Any]]) -> None:
        """Set ``component.variable`` values; after initialisation through event mode, and the
        integration restarts from the current time."""
        super().set_values(values)
        if self._solver is not None:
            self._start_solver()

    def exit_initialization_mode(self) -> None:
        super().exit_initialization_mode()
        first = 0
        self._slices = []
        for name in self.names:
            instance = self.instances[name]
            n = int(instance.md.numberOfContinuousStates)
            self._slices.append((name, instance, first, n))
            first += n
        self._n = first
        self._start_solver()

    # -- the one ODE ----------------------------------------------------------------
    def _states(self):
        import numpy as np

        x = np.empty(self._n)
        for name, instance, first, n in self._slices:
            if n:
                part = np.empty(n)
                self._named(name, lambda: instance._call(f"{instance.PREFIX}GetContinuousStates",
                                                         instance._fmu.getContinuousStates,
                                                         part.ctypes.data_as(_double_p()), n))
                x[first:first + n] = part
        return x

    def _start_solver(self) -> None:
        from scipy.integrate import DOP853

        x0 = self._states()
        if self._stop <= self._t:
            self._solver = _AtEnd(self._t, x0)
            self._evaluate(self._t, x0)
            return
        self._solver = DOP853(self._f, self._t, x0, self._stop, rtol=self._rtol, atol=self._rtol * ATOL_RATIO)
        self._evaluate(self._t, x0)      # the solver's start probed other points: back to (t, x0)

    def _check_order(self, x0) -> None:
        """The case's ``[master] order`` is vouched for, not derived: check that it reads no
        input before it is set.  After an evaluation at perturbed states, two evaluations at
        ``x0`` must give the same connected outputs (an output read before an input it depends
        on is set shows the perturbed point's value in the first); else an :class:`FmuError`
        naming the outputs (a wrong order would make the integrator's steps collapse)."""
        import numpy as np

        self._evaluate(self._t, x0 * (1 + 1e-3) + 1e-3)
        self._evaluate(self._t, x0)
        first = dict(self._now)
        self._evaluate(self._t, x0)
        stale = [k for k, v in self._now.items() if not np.isclose(first[k], v, rtol=1e-9, atol=1e-12)]
        if stale:
            raise FmuError(f"[master] order = {list(self.master.order)} reads {', '.join(stale)} before an input "
                           f"it depends on is set (evaluated twice at t = {self._t!r} s they differ); give an order "
                           f"where each component comes after the components that feed it through", 3)

    def _f(self, t: float, x):
        self._evaluate(t, x)
        return self._dx.copy()

    def _evaluate(self, t: float, x) -> None:
        """Everything of the system at ``(t, x)``; the derivatives into ``self._dx``."""
        import numpy as np

        self.evaluations += 1
        x = np.ascontiguousarray(x, dtype=float)
        for name, instance, first, n in self._slices:
            self._named(name, lambda: instance._call(f"{instance.PREFIX}SetTime", instance._fmu.setTime, t))
            if n:
                part = x[first:first + n]
                self._named(name, lambda: instance._call(f"{instance.PREFIX}SetContinuousStates",
                                                         instance._fmu.setContinuousStates,
                                                         part.ctypes.data_as(_double_p()), n))
            if name in self._driven:
                self._named(name, lambda: instance.set_inputs(t, derivatives=False))
        values: dict[str, float] = {}
        given: set[str] = set()
        for name, outputs in self.plan:
            self._give(name, values, given)
            values.update(self._named(name, self._readers[name]))
        for name in self.names:
            self._give(name, values, given)
        dx = np.empty(len(x))
        for name, instance, first, n in self._slices:
            if n:
                part = np.empty(n)
                self._named(name, lambda: instance._call(f"{instance.PREFIX}GetDerivatives", instance._derivatives(),
                                                         part.ctypes.data_as(_double_p()), n))
                dx[first:first + n] = part
        self._dx = dx
        self._now = values

    def _give(self, name: str, values: dict[str, float], given: set[str]) -> None:
        """Set the connected inputs of ``name`` whose sources' values are known and not yet set."""
        links = [link for link in self._feeding[name] if link.key in values and f"{name}.{link.input}" not in given]
        if not links:
            return
        instance = self.instances[name]
        self._named(name, lambda: instance._call(
            f"{instance.PREFIX}Set{instance.FLOAT}({', '.join(link.input for link in links)})",
            getattr(instance._fmu, f"set{instance.FLOAT}"),
            [instance.variables[link.input].valueReference for link in links], [values[link.key] for link in links]))
        given.update(f"{name}.{link.input}" for link in links)

    def do_step(self, t: float, h: float) -> None:
        """Integrate from ``t`` to ``t + h``; every component is left at ``t + h``."""
        target = t + h
        solver = self._solver
        if self.master.order and not self._order_checked:
            self._check_order(solver.y)
            self._order_checked = True
        while solver.t < target and solver.status == "running":
            message = solver.step()
            if solver.status == "failed":
                raise FmuError(f"the monolithic integration (DOP853) failed between t = {solver.t_old!r} s and "
                               f"{target!r} s: {message}", 3)
            for name, instance, _, _ in self._slices:
                if not getattr(instance.md.modelExchange, "completedIntegratorStepNotNeeded", False):
                    self._named(name, lambda: self._completed(instance, solver.t))
        x = solver.y if solver.t == target or solver.t_old is None else solver.dense_output()(target)
        self._evaluate(target, x)
        self._t = target

    def _completed(self, instance, t: float) -> None:
        step_event, terminate = instance._call(f"{instance.PREFIX}CompletedIntegratorStep",
                                               instance._fmu.completedIntegratorStep)[:2]
        if terminate:
            raise FmuError(f"the FMU asked to end the simulation at t = {t!r} s")
        if step_event:
            raise FmuError(f"the FMU asked for a step event at t = {t!r} s, which the monolithic master does "
                           f"not handle")


class _AtEnd:
    """A solver with nothing left to integrate (the experiment ends where it starts)."""

    status = "finished"
    t_old = None

    def __init__(self, t: float, y):
        self.t, self.y = t, y


def _double_p():
    from ctypes import POINTER, c_double

    return POINTER(c_double)

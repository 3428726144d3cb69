"""One FMI 2.0 or 3.0 instance in the flavour its FMU and case ask for, driven through FMPy's
``FMU2Slave``/``FMU3Slave`` (co-simulation) or ``FMU2Model``/``FMU3Model`` (model exchange,
integrated by FMPy's CVode).

:func:`instance_for` chooses the flavour once, from the model description's FMI version and
the case's ``fmi_type``; the run loop and the diagnosis then use only the interface of
:class:`FmuInstance` (:mod:`orchestrator.fmi_instance`).  Each flavour is one class combining
an FMI version (:mod:`orchestrator.fmi_versions`) with an interface type
(:mod:`orchestrator.fmi_interfaces`).  A new flavour is one more such class and one more entry
in :data:`FLAVOURS`.  Any FMI 2.0 or 3.0 FMU works; nothing here knows about a mechanism.
"""
from __future__ import annotations

from typing import Sequence

from fourbar_common.formatting import format_time

from .case import FmuDescription
from .fmi_instance import FmuError, FmuInstance
from .fmi_interfaces import CoSimulation, ModelExchange
from .fmi_versions import Fmi2Instance, Fmi3Instance

__all__ = ["FLAVOURS", "Fmi2CoSimulation", "Fmi2ModelExchange", "Fmi3CoSimulation", "Fmi3ModelExchange", "FmuError",
           "FmuInstance", "instance_for"]


class Fmi2CoSimulation(CoSimulation, Fmi2Instance):
    """FMI 2.0 co-simulation (``FMU2Slave``), with the replay's fast loop :meth:`step_through`
    and input derivatives (``fmi2SetRealInputDerivatives``, for an FMU that says canInterpolateInputs)."""

    _takes_input_derivatives = True

    def _set_input_derivatives(self, t: float, order: int) -> None:
        values = [s.at(t, order) for s in self._input_signals]
        mark = self._log_count
        try:
            self._fmu.setRealInputDerivatives(self._input_vrs, [order] * len(values), values)
        except self._call_error as exc:
            shown = ", ".join(f"{n} = {v!r}" for n, v in zip(self._input_names, values))
            raise self._failure(f"fmi2SetRealInputDerivatives(order {order}: {shown}) at t = {format_time(t)} s",
                                exc.status, mark) from None

    def set_real_input_derivatives(self, names: Sequence[str], values: Sequence[float], order: int = 1) -> None:
        """``fmi2SetRealInputDerivatives`` of the Real inputs ``names`` (order ``order``), for the
        step that starts next (a system's extrapolated connections, orchestrator.system)."""
        vrs = [self.variables[n].valueReference for n in names]
        shown = ", ".join(f"{n} = {v!r}" for n, v in zip(names, values))
        self._call(f"fmi2SetRealInputDerivatives(order {order}: {shown})", self._fmu.setRealInputDerivatives,
                   vrs, [order] * len(vrs), list(values))

    @staticmethod
    def _fmpy_class() -> type:
        from fmpy.fmi2 import FMU2Slave

        return FMU2Slave

    def direct_calls(self) -> tuple:
        """``(component, fmi2DoStep, fmi2GetReal, fmi2SetReal, failure)``: the FMU's own functions
        for a replay's fast loop (a system's, orchestrator.system); ``failure(what, status)`` is
        the :class:`FmuError` for a call that returned ``status``, with the FMU's recent log."""
        functions = self._fmu._functions
        mark = self._log_count
        return (self._fmu.component, functions["fmi2DoStep"], functions["fmi2GetReal"], functions["fmi2SetReal"],
                lambda what, status: self._failure(what, status, mark))

    def step_through(self, times: Sequence[float], outputs: Sequence[str], out,
                     changes: tuple[str, Sequence[float]] | None = None) -> None:
        """Step from ``times[0]`` through every later time, writing the Real ``outputs`` after
        step ``i`` (to ``times[i + 1]``) into row ``i`` of ``out`` (a float array).

        ``changes = (name, values)`` sets the Real ``name`` to ``values[i]`` before step ``i``
        while ``i < len(values)``.  This is the replay's hot path (a diagnosis takes
        hundreds of thousands of steps): it calls the FMU's ``fmi2DoStep``, ``fmi2GetReal``
        and ``fmi2SetReal`` directly, into buffers made once, instead of one FMPy call and
        Python list per value, which is four times faster.  Failures are reported as by
        :meth:`do_step`.
        """
        from ctypes import c_double, c_uint

        functions = self._fmu._functions
        do_step, get_real, set_real = functions["fmi2DoStep"], functions["fmi2GetReal"], functions["fmi2SetReal"]
        component = self._fmu.component
        for name in (*outputs, *([changes[0]] if changes else [])):
            if self.variables[name].type != "Real":
                raise ValueError(f"step_through: {name} is a {self.variables[name].type}, not a Real")
        n = len(outputs)
        vrs = (c_uint * n)(*(self.variables[name].valueReference for name in outputs))
        buffer = (c_double * n)()
        set_vr = (c_uint * 1)(self.variables[changes[0]].valueReference) if changes else None
        set_value = (c_double * 1)()
        values = changes[1] if changes else ()
        mark = self._log_count
        for i in range(len(times) - 1):
            t = times[i]
            if i < len(values):
                set_value[0] = values[i]
                status = set_real(component, set_vr, 1, set_value)
                if status > 1:
                    raise self._failure(f"fmi2SetReal({changes[0]} = {values[i]!r}) at t = {format_time(t)} s", status, mark)
            h = times[i + 1] - t
            status = do_step(component, t, h, 1)
            if status > 1:
                raise self._failure(f"fmi2DoStep(t = {format_time(t)} s, h = {format_time(h)} s)", status, mark)
            get_real(component, vrs, n, buffer)
            out[i] = buffer


class Fmi2ModelExchange(ModelExchange, Fmi2Instance):
    """FMI 2.0 model exchange (``FMU2Model``) integrated by FMPy's CVode."""

    @staticmethod
    def _fmpy_class() -> type:
        from fmpy.fmi2 import FMU2Model

        return FMU2Model


class Fmi3CoSimulation(CoSimulation, Fmi3Instance):
    """FMI 3.0 co-simulation (``FMU3Slave``)."""

    @staticmethod
    def _fmpy_class() -> type:
        from fmpy.fmi3 import FMU3Slave

        return FMU3Slave


class Fmi3ModelExchange(ModelExchange, Fmi3Instance):
    """FMI 3.0 model exchange (``FMU3Model``) integrated by FMPy's CVode."""

    @staticmethod
    def _fmpy_class() -> type:
        from fmpy.fmi3 import FMU3Model

        return FMU3Model


#: The flavour class by (FMI major version, interface type as the case file names it).
FLAVOURS: dict[tuple[str, str], type[FmuInstance]] = {
    ("2", "CoSimulation"): Fmi2CoSimulation,
    ("2", "ModelExchange"): Fmi2ModelExchange,
    ("3", "CoSimulation"): Fmi3CoSimulation,
    ("3", "ModelExchange"): Fmi3ModelExchange,
}


def instance_for(description: FmuDescription, instance_name: str, fmi_type: str = "CoSimulation",
                 log_size: int = 200) -> FmuInstance:
    """The instance (not yet entered: use it as a context manager) of the flavour that runs
    ``description``'s FMU through ``fmi_type``: its FMI version from the model description
    (3.x is FMI 3.0, anything else is run as FMI 2.0, as case validation accepted it)."""
    version = "3" if str(description.model.fmiVersion).startswith("3") else "2"
    try:
        flavour = FLAVOURS[version, fmi_type]
    except KeyError:
        raise ValueError(f"fmi_type: expected one of {', '.join(sorted({t for _, t in FLAVOURS}))}, "
                         f"got {fmi_type!r}") from None
    return flavour(description, instance_name, log_size)

"""The interface of one FMU instance as the run loop and the diagnosis drive it, and what every
FMI flavour shares.

:class:`FmuInstance` is a context manager: entering it extracts the FMU and instantiates it
with a logger that keeps the FMU's messages (so a failure carries the FMU's own reason);
leaving it terminates the instance (only after a clean run, as FMI allows), frees it, and
removes the extracted files, whatever happened.  Between the two the caller sets up the
experiment, sets and reads variables by name whatever their type, enters and leaves
initialisation mode and steps.  Nothing here knows about a mechanism.

What differs between the flavours is filled in by two layers of subclasses, combined once
per flavour in :mod:`orchestrator.instance` (which also chooses the flavour):

- the FMI version (:mod:`orchestrator.fmi_versions`): the names of the calls, the logger,
  how the experiment reaches the FMU, the FMU-state calls;
- the interface type (:mod:`orchestrator.fmi_interfaces`): co-simulation steps with the
  FMU's own solver; model exchange integrates with FMPy's CVode.
"""
from __future__ import annotations

import abc
import collections
from typing import Any, Callable, ClassVar, Iterable, Sequence

from fourbar_common.formatting import format_time

from .case import FmuDescription
from .pythonfmu_workarounds import clean_message, install_exit_guard, release_library

__all__ = ["FmuError", "FmuInstance"]

_STATUS = ("ok", "warning", "discard", "error", "fatal", "pending")
_FATAL = 4


class FmuError(RuntimeError):
    """An FMI call failed; the message names the call, the status and the FMU's log."""

    def __init__(self, message: str, status: int | None = None):
        super().__init__(message)
        self.status = status


class FmuInstance(abc.ABC):
    """One instance of an FMU for one run (or one diagnosis); make one with
    :func:`orchestrator.instance.instance_for`, which picks the flavour.

    ``description`` is what case validation read from the FMU file.
    """

    #: The prefix of the FMI calls named in messages ("fmi2", "fmi3").
    PREFIX: ClassVar[str]
    #: The interface type, as FMPy and the case file name it ("CoSimulation", "ModelExchange").
    FMI_TYPE: ClassVar[str]
    #: The suffix of FMPy's getter of a float ("Real", "Float64").
    FLOAT: ClassVar[str]

    def __init__(self, description: FmuDescription, instance_name: str, log_size: int = 200):
        self.path = description.path
        self.md = description.model
        self.instance_name = instance_name
        self.fmi_type = self.FMI_TYPE
        self._experiment: tuple[float, float, float | None] = (0.0, 0.0, None)
        self._tolerance: float | None = None
        self._time = 0.0
        self.variables = description.variables
        self._own_types = description.own_types
        self.log = collections.deque(maxlen=log_size)   # (sequence number, status, category, message)
        self._log_count = 0
        self._fmu = None
        self._unzipdir = None
        self._unpacked = None                # the UnpackedFmu that holds _unzipdir
        self._instantiated = False
        self._failed_status: int | None = None
        self._call_error: type = Exception   # fmpy's FMICallException once FMPy is imported
        self._abandoned = False              # a thread is still inside the FMU: never free it

    # -- what each flavour fills in -----------------------------------------------------
    @staticmethod
    @abc.abstractmethod
    def _fmpy_class() -> type:
        """FMPy's class for this flavour (``FMU2Slave``, ``FMU3Model``, ...), imported lazily."""

    @staticmethod
    @abc.abstractmethod
    def _interface(md) -> Any:
        """The model description's entry for this interface type (its ``modelIdentifier``)."""

    @abc.abstractmethod
    def _instantiate(self, kind: type, model_identifier: str) -> None:
        """Load the FMU's library into ``self._fmu`` (an instance of ``kind``) and instantiate
        it with a logger that calls :meth:`_logger`; :class:`FmuError` when it cannot."""

    def _release_logger(self) -> None:
        """Stop routing this instance's messages (on closing, unless abandoned)."""

    @abc.abstractmethod
    def _setup_experiment(self, start: float, stop: float, tolerance: float | None) -> None:
        """Hand the experiment to the FMU where the version does so before initialisation."""

    @abc.abstractmethod
    def enter_initialization_mode(self) -> None:
        """``EnterInitializationMode`` (FMI 3.0 takes the experiment's times and tolerance here)."""

    def _initialized(self) -> None:
        """What the interface type does once initialisation mode is left."""

    @abc.abstractmethod
    def do_step(self, t: float, h: float) -> None:
        """Advance from ``t`` by ``h`` (the hot path: no work beyond the call unless it fails)."""

    @abc.abstractmethod
    def _ends_simulation(self, step_result) -> bool:
        """Whether a co-simulation doStep's result asks to end the simulation."""

    @abc.abstractmethod
    def _update_discrete_states(self) -> tuple:
        """One call of the event iteration: ``(discrete states needed, terminate simulation, ...)``."""

    @abc.abstractmethod
    def _derivatives(self) -> Callable:
        """FMPy's getter of the continuous states' derivatives (model exchange)."""

    @abc.abstractmethod
    def get_state(self):
        """``GetFMUState``: an opaque copy of the instance's state (free it with :meth:`free_state`)."""

    @abc.abstractmethod
    def set_state(self, state) -> None:
        """``SetFMUState``."""

    @abc.abstractmethod
    def free_state(self, state) -> None:
        """``FreeFMUState``."""

    # -- life cycle -------------------------------------------------------------------
    def __enter__(self) -> "FmuInstance":
        try:
            self._open()
        except BaseException:
            self._close(clean=False)
            raise
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self._close(clean=exc_type is None)

    def _open(self) -> None:
        from fmpy.fmi1 import FMICallException

        from .unpacked import UnpackedFmu

        self._call_error = FMICallException
        install_exit_guard()    # also guards FMUs that FMPy loads elsewhere in this process
        self._unpacked = UnpackedFmu(self.path)
        self._unzipdir = self._unpacked.unpack()
        self._instantiate(self._fmpy_class(), self._interface(self.md).modelIdentifier)
        self._instantiated = True

    def abandon(self) -> None:
        """Another thread is inside one of this FMU's calls and will not return soon (a stop
        signal came during a doStep that does not end): closing frees nothing it uses (no
        terminate, free or unload; its log route stays), only the extracted files go (a
        loaded library stays mapped).  The process is about to exit."""
        self._abandoned = True

    def _close(self, clean: bool) -> None:
        if self._abandoned:
            self._remove_unpacked()
            return
        fmu, self._fmu = self._fmu, None
        try:
            if fmu is not None:
                release_library(fmu.dll)      # pythonfmu_workarounds; an instance keeps its own reference
                if self._instantiated:
                    if clean and self._failed_status is None:
                        try:
                            fmu.terminate()
                        except Exception:   # a failing terminate must not hide the run's result
                            pass
                    # FMI 2.0 allows no call after fmi2Fatal, fmi2FreeInstance included, and
                    # pythonfmu's slaves corrupt the interpreter's heap if freed then (a later
                    # segfault in the garbage collector).  The instance is left allocated.
                    if self._failed_status != _FATAL:
                        fmu.freeInstance()
                else:
                    fmu.freeLibrary()
        finally:
            self._release_logger()
            self._remove_unpacked()

    def _remove_unpacked(self) -> None:
        unpacked, self._unpacked, self._unzipdir = self._unpacked, None, None
        if unpacked is not None:
            unpacked.remove()

    # -- logging ----------------------------------------------------------------------
    def _logger(self, component, instance_name, status, category, message) -> None:
        self._log_count += 1
        text = message.decode("utf-8", "replace") if message else ""
        cat = category.decode("utf-8", "replace") if category else ""
        self.log.append((self._log_count, int(status), cat, clean_message(text)))

    def _describe(self, what: str, since: int) -> str:
        """``what`` followed by the FMU's warnings/errors logged since message ``since``."""
        recent = [m for m in self.log if m[0] > since]
        important = [m for m in recent if m[1] >= 1] or recent[-3:]
        if not important:
            return f"{what} (the FMU logged no message)"
        return what + ": " + " | ".join(m[3] for m in important)

    def _failure(self, what: str, status: int, mark: int) -> FmuError:
        """:class:`FmuError` for a call that returned ``status``, with the FMU's log since ``mark``."""
        self._failed_status = status
        label = _STATUS[status] if 0 <= status < len(_STATUS) else str(status)
        return FmuError(self._describe(f"{what} returned {label}", mark), status)

    def _call(self, what: str, function: Callable, *args) -> Any:
        """Run one FMI call; turn FMPy's exception into :class:`FmuError` with the FMU's log."""
        mark = self._log_count
        try:
            return function(*args)
        except self._call_error as exc:
            raise self._failure(what, exc.status, mark) from None

    # -- FMI calls --------------------------------------------------------------------
    def setup_experiment(self, start: float, stop: float, tolerance: float | None) -> None:
        """``fmi2SetupExperiment``; FMI 3.0 takes the same at :meth:`enter_initialization_mode`."""
        self._setup_experiment(start, stop, tolerance)
        self._time, self._tolerance = start, tolerance
        self._experiment = (start, stop, tolerance)

    def exit_initialization_mode(self) -> None:
        self._call(f"{self.PREFIX}ExitInitializationMode", self._fmu.exitInitializationMode)
        self._initialized()

    def step_through(self, times: Sequence[float], outputs: Sequence[str], out,
                     changes: tuple[str, Sequence[float]] | None = None) -> None:
        """Step from ``times[0]`` through every later time, writing the Real ``outputs`` after
        step ``i`` (to ``times[i + 1]``) into row ``i`` of ``out`` (a float array); only an
        FMI 2.0 co-simulation instance has this fast loop (the replay's)."""
        raise ValueError(f"step_through drives an FMI 2.0 co-simulation instance; {self.path.name} is run as FMI "
                         f"{self.md.fmiVersion} {self.fmi_type}")

    def reset(self) -> None:
        self._call(f"{self.PREFIX}Reset", self._fmu.reset)

    def set_values(self, values: Iterable[tuple[str, Any]]) -> None:
        """Set variables by name (grouped per FMI type)."""
        self._set(values)

    def _set(self, values: Iterable[tuple[str, Any]]) -> None:
        groups: dict[str, tuple[list, list]] = {}
        for name, value in values:
            var = self.variables[name]
            vrs, vals = groups.setdefault(_setter_type(var, self._own_types), ([], []))
            vrs.append(var.valueReference)
            vals.append(value)
        for kind, (vrs, vals) in groups.items():
            setter = getattr(self._fmu, f"set{kind}")
            self._call(f"{self.PREFIX}Set{kind}({', '.join(_names(self.md, vrs))})", setter, vrs, vals)

    def drive_inputs(self, names: Sequence[str], signals: Sequence, order: int = 0) -> None:
        """From now on, :meth:`set_inputs` sets the Real inputs ``names`` to ``signals[i].at(t)``
        (each an :mod:`orchestrator.input_signals` signal), with their time derivatives up to
        ``order`` where the flavour takes them (FMI 2.0 co-simulation)."""
        if order and not self._takes_input_derivatives:
            raise ValueError(f"{self.PREFIX} {self.fmi_type} takes no input derivatives (order {order})")
        self._input_vrs = [self.variables[n].valueReference for n in names]
        self._input_signals = tuple(signals)
        self._input_order = order
        self._input_names = tuple(names)

    #: Whether the flavour sets input derivatives (``fmi2SetRealInputDerivatives``).
    _takes_input_derivatives: ClassVar[bool] = False
    _input_signals: tuple = ()

    def set_inputs(self, t: float, derivatives: bool = True) -> None:
        """Set the driven inputs (:meth:`drive_inputs`) to their values at ``t`` (and their
        derivatives, when driven with an order and ``derivatives``), for the step that starts
        at ``t``.  Before initialisation FMI 2.0 allows the values only (``derivatives=False``)."""
        if not self._input_signals:
            return
        values = [s.at(t) for s in self._input_signals]
        mark = self._log_count
        try:
            getattr(self._fmu, f"set{self.FLOAT}")(self._input_vrs, values)
        except self._call_error as exc:
            shown = ", ".join(f"{n} = {v!r}" for n, v in zip(self._input_names, values))
            raise self._failure(f"{self.PREFIX}Set{self.FLOAT}({shown}) at t = {format_time(t)} s", exc.status,
                                mark) from None
        for order in range(1, self._input_order + 1 if derivatives else 1):
            self._set_input_derivatives(t, order)

    def _set_input_derivatives(self, t: float, order: int) -> None:
        """Set the driven inputs' ``order``-th derivatives at ``t`` (flavours that take them)."""

    def reader(self, names: Sequence[str]) -> Callable[[], list]:
        """A function returning the current values of ``names`` (in that order) as Python numbers."""
        kinds = [_setter_type(self.variables[n], self._own_types) for n in names]
        vrs = [self.variables[n].valueReference for n in names]
        slave = self._fmu
        if all(k in ("Real", "Float64") for k in kinds):
            get_real = getattr(slave, f"get{self.FLOAT}")
            return lambda: get_real(vrs)
        groups: dict[str, list[int]] = {}
        for i, kind in enumerate(kinds):
            groups.setdefault(kind, []).append(i)
        plan = [(getattr(slave, f"get{kind}"), [vrs[i] for i in idx], idx, kind == "Boolean")
                for kind, idx in groups.items()]
        n = len(names)

        def read() -> list:
            row = [0] * n
            for getter, group_vrs, idx, is_bool in plan:
                for i, value in zip(idx, getter(group_vrs)):
                    row[i] = int(bool(value)) if is_bool else value
            return row

        return read

    @property
    def guid(self) -> str:
        return self.md.guid


def _setter_type(var, own_types: dict[str, str]) -> str:
    """The suffix of FMPy's getter and setter of ``var``: FMI 2.0's type (an Enumeration is an
    Integer), or FMI 3.0's own (``own_types``: Float64, Int32, ...; an Enumeration is an Int64)."""
    own = own_types.get(var.name)
    if own is not None:
        return "Int64" if own == "Enumeration" else own
    return "Integer" if var.type == "Enumeration" else var.type


def _names(md, vrs) -> list[str]:
    by_vr = {v.valueReference: v.name for v in md.modelVariables}
    return [by_vr.get(vr, str(vr)) for vr in vrs]

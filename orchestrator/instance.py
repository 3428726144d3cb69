"""One FMI 2.0 or 3.0 instance, driven through FMPy's ``FMU2Slave``/``FMU3Slave`` (co-simulation)
or ``FMU2Model``/``FMU3Model`` (model exchange, integrated by FMPy's CVode).

:class:`FmuInstance` extracts the FMU, instantiates it with a logger that keeps the FMU's
messages (so a failure carries the FMU's own reason), reads and writes variables by name
whatever their type, and always frees the instance and removes the extracted files.
Any FMI 2.0 or 3.0 FMU works; nothing here knows about the four-bar.  FMI 3.0 differs in
names (Float64 for Real, updateDiscreteStates, ...), in a logger that gets a finished message
(one ctypes callback per instance, kept as long as the instance), and in an initialisation
that takes the experiment's times and tolerance; the methods below hide it.

Model exchange looks like co-simulation to the caller: :meth:`FmuInstance.do_step` integrates
the states with CVode over the step (``fmi2CompletedIntegratorStep`` at its end, as FMPy's
``simulate_fmu`` does, and an event iteration where the FMU asks for one), and values set after initialisation are set
in event mode, followed by the event iteration and a restart of CVode at that time (a step or
ramp fault is a discontinuity the solver must not integrate across).
"""
from __future__ import annotations

import collections
import itertools
import threading
from typing import Any, Callable, Iterable, Sequence

from fourbar_common.formatting import format_time

from .case import FmuDescription
from .pythonfmu_workarounds import clean_message, forget_other_fmu_modules, install_exit_guard, release_library

__all__ = ["FmuError", "FmuInstance"]

_STATUS = ("ok", "warning", "discard", "error", "fatal", "pending")
_FATAL = 4

# FMPy's logger proxy (fmpy.logging.addLoggerProxy, needed to format the FMU's printf-style
# messages) keeps the Python logger in ONE process-wide C variable, which FMPy's default
# callbacks (simulate_fmu & co.) also go through.  A per-instance ctypes callback would be
# freed with its instance and leave that variable dangling: the next FMU that logs in this
# process would call freed memory (observed: a segfault in simulate_fmu after run_case).
# So there is one callback for the life of the process; it routes each message by the
# componentEnvironment pointer the FMU passes back, and hands unknown ones to FMPy's printer.
_ROUTES: dict[int, "FmuInstance"] = {}
_ENV_IDS = itertools.count(1)
_LOGGER_LOCK = threading.Lock()
_LOGGER = None   # the process-wide ctypes callback, created on first use


def _route_log_message(env, instance_name, status, category, message) -> None:
    target = _ROUTES.get(env or 0)
    if target is not None:
        target._logger(env, instance_name, status, category, message)
        return
    from fmpy.fmi1 import printLogMessage   # what FMPy's default callbacks do

    printLogMessage(env, instance_name, status, category, message)


def _process_logger():
    global _LOGGER
    with _LOGGER_LOCK:
        if _LOGGER is None:
            from fmpy.fmi2 import fmi2CallbackLoggerTYPE

            _LOGGER = fmi2CallbackLoggerTYPE(_route_log_message)
        return _LOGGER


class FmuError(RuntimeError):
    """An FMI call failed; the message names the call, the status and the FMU's log."""

    def __init__(self, message: str, status: int | None = None):
        super().__init__(message)
        self.status = status


class FmuInstance:
    """Context manager around ``fmpy.fmi2.FMU2Slave`` for one run.

    ``description`` is what case validation read from the FMU file.  On leaving the context the
    instance is terminated (only after a clean run, as FMI 2.0 allows), freed, and the
    extracted directory removed, whatever happened.
    """

    def __init__(self, description: FmuDescription, instance_name: str, log_size: int = 200,
                 fmi_type: str = "CoSimulation"):
        self.path = description.path
        self.md = description.model
        self.instance_name = instance_name
        self.fmi_type = fmi_type
        self.model_exchange = fmi_type == "ModelExchange"
        self.fmi3 = str(self.md.fmiVersion).startswith("3")
        self._prefix = "fmi3" if self.fmi3 else "fmi2"      # of the FMI calls named in messages
        self._experiment: tuple[float, float, float | None] = (0.0, 0.0, None)   # FMI 3.0: for initialisation
        self._solver = None                  # model exchange: FMPy's CVodeSolver, after initialisation
        self._tolerance: float | None = None
        self._time = 0.0
        self.variables = description.variables
        self._own_types = description.own_types
        self.log = collections.deque(maxlen=log_size)   # (sequence number, status, category, message)
        self._log_count = 0
        self._fmu = None
        self._callbacks = None
        self._unzipdir = None
        self._unpacked = None                # the UnpackedFmu that holds _unzipdir
        self._env = 0
        self._instantiated = False
        self._failed_status: int | None = None
        self._call_error: type = Exception   # fmpy's FMICallException once FMPy is imported
        self._abandoned = False              # a thread is still inside the FMU: never free it

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
        from ctypes import byref

        from fmpy.fmi1 import FMICallException

        from .unpacked import UnpackedFmu

        self._call_error = FMICallException
        install_exit_guard()    # also guards FMUs that FMPy loads elsewhere in this process
        self._unpacked = UnpackedFmu(self.path)
        self._unzipdir = self._unpacked.unpack()
        interface = self.md.modelExchange if self.model_exchange else self.md.coSimulation
        if self.fmi3:
            from fmpy.fmi3 import FMU3Model, FMU3Slave

            kind = FMU3Model if self.model_exchange else FMU3Slave
            self._fmu = kind(guid=self.md.guid, unzipDirectory=self._unzipdir, modelIdentifier=interface.modelIdentifier,
                             instanceName=self.instance_name)
            try:
                self._fmu.instantiate(loggingOn=True, logMessage=self._logger3)
            except Exception as exc:   # FMPy raises a bare Exception when the instantiation returns NULL
                raise FmuError(self._describe(f"fmi3Instantiate{self.fmi_type} failed ({exc})", 0)) from None
            self._instantiated = True
            return
        from fmpy.fmi2 import (FMU2Model, FMU2Slave, calloc, fmi2CallbackAllocateMemoryTYPE,
                               fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions, free)
        from fmpy.logging import addLoggerProxy

        self._env = next(_ENV_IDS)
        _ROUTES[self._env] = self
        callbacks = fmi2CallbackFunctions()
        callbacks.logger = _process_logger()
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        callbacks.componentEnvironment = self._env   # passed back to the logger: routes the messages
        addLoggerProxy(byref(callbacks))   # formats the FMU's printf-style message before our callback
        self._callbacks = callbacks        # must outlive the instance
        kind = FMU2Model if self.model_exchange else FMU2Slave
        self._fmu = kind(guid=self.md.guid, unzipDirectory=self._unzipdir, modelIdentifier=interface.modelIdentifier,
                         instanceName=self.instance_name)
        forget_other_fmu_modules(self._unzipdir)   # another build's cached Python code
        try:
            # loggingOn: pythonfmu (and many FMUs) forward messages only when logging is on.
            self._fmu.instantiate(callbacks=callbacks, loggingOn=True)
        except Exception as exc:   # FMPy raises a bare Exception when fmi2Instantiate returns NULL
            raise FmuError(self._describe(f"fmi2Instantiate failed ({exc})", 0)) from None
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
            _ROUTES.pop(self._env, None)
            self._remove_unpacked()

    def _remove_unpacked(self) -> None:
        unpacked, self._unpacked, self._unzipdir = self._unpacked, None, None
        if unpacked is not None:
            unpacked.remove()

    # -- logging ----------------------------------------------------------------------
    def _logger3(self, environment, status, category, message) -> None:
        """FMI 3.0's logMessage: the message comes formatted."""
        self._logger(environment, None, status, category, message)

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
        if not self.fmi3:
            self._call("fmi2SetupExperiment", self._fmu.setupExperiment, tolerance, start, stop)
        self._time, self._tolerance = start, tolerance
        self._experiment = (start, stop, tolerance)

    def enter_initialization_mode(self) -> None:
        if self.fmi3:
            start, stop, tolerance = self._experiment
            self._call("fmi3EnterInitializationMode", self._fmu.enterInitializationMode, tolerance, start, stop)
        else:
            self._call("fmi2EnterInitializationMode", self._fmu.enterInitializationMode)

    def exit_initialization_mode(self) -> None:
        self._call(f"{self._prefix}ExitInitializationMode", self._fmu.exitInitializationMode)
        if self.model_exchange:
            self._event_iteration()
            self._start_solver()

    def do_step(self, t: float, h: float) -> None:
        """``fmi2DoStep(t, h)`` (the hot path: no work beyond the call unless it fails); in model
        exchange, CVode over the step."""
        if self.model_exchange:
            self._integrate(t, t + h)
            return
        mark = self._log_count
        try:
            result = self._fmu.doStep(t, h)
        except self._call_error as exc:
            raise self._failure(f"{self._prefix}DoStep(t = {format_time(t)} s, h = {format_time(h)} s)",
                                exc.status, mark) from None
        if self.fmi3 and result[1]:          # terminateSimulation
            raise FmuError(self._describe(f"the FMU asked to end the simulation at t = {format_time(t + h)} s", mark))

    # -- model exchange ---------------------------------------------------------------
    def _event_iteration(self) -> None:
        """``fmi2NewDiscreteStates`` until the FMU needs no more, then continuous-time mode."""
        update = ("fmi3UpdateDiscreteStates", self._fmu.updateDiscreteStates) if self.fmi3 else \
            ("fmi2NewDiscreteStates", self._fmu.newDiscreteStates)
        while True:
            needed, terminate = self._call(*update)[:2]
            if terminate:
                raise FmuError(self._describe(f"the FMU asked to end the simulation at t = "
                                              f"{format_time(self._time)} s", self._log_count - 3))
            if not needed:
                break
        self._call(f"{self._prefix}EnterContinuousTimeMode", self._fmu.enterContinuousTimeMode)

    def _start_solver(self) -> None:
        """FMPy's CVode on the FMU's states, from the current time (the case's tolerance, else FMPy's default)."""
        from fmpy.sundials import CVodeSolver

        md, fmu = self.md, self._fmu
        self._solver = CVodeSolver(
            nx=md.numberOfContinuousStates, nz=md.numberOfEventIndicators, get_x=fmu.getContinuousStates,
            set_x=fmu.setContinuousStates,
            get_dx=fmu.getContinuousStateDerivatives if self.fmi3 else fmu.getDerivatives, get_z=fmu.getEventIndicators,
            get_nominals=fmu.getNominalsOfContinuousStates, set_time=fmu.setTime, input=_NoInputs(),
            startTime=self._time, **({"relativeTolerance": self._tolerance} if self._tolerance else {}))

    def _integrate(self, t: float, t_end: float) -> None:
        """CVode from ``t`` to ``t_end`` (a state event stops it early: the event is handled, and on)."""
        mark = self._log_count
        try:
            while t < t_end:
                state_event, _roots, t = self._solver.step(t, t_end)
                self._fmu.setTime(t)
                step_event, terminate = self._fmu.completedIntegratorStep()
                if terminate:
                    raise FmuError(self._describe(f"the FMU asked to end the simulation at t = {format_time(t)} s",
                                                  mark))
                if state_event or step_event:
                    self._time = t
                    self._fmu.enterEventMode()
                    self._event_iteration()
                    self._solver.reset(t)
        except self._call_error as exc:
            raise self._failure(f"model exchange from t = {format_time(t)} s to {format_time(t_end)} s",
                                exc.status, mark) from None
        except FmuError:
            raise
        except Exception as exc:             # CVode's own failure (fmpy.sundials raises RuntimeError or Exception)
            self._failed_status = 3
            raise FmuError(self._describe(f"CVode failed between t = {format_time(t)} s and "
                                          f"{format_time(t_end)} s ({exc})", mark), 3) from None
        self._time = t_end

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

        if self.fmi3 or self.model_exchange:
            raise ValueError(f"step_through drives an FMI 2.0 co-simulation instance; {self.path.name} is run as FMI "
                             f"{self.md.fmiVersion} {self.fmi_type}")
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

    def get_state(self):
        """``fmi2GetFMUstate``: an opaque copy of the instance's state (free it with :meth:`free_state`)."""
        if self.fmi3:
            return self._call("fmi3GetFMUState", self._fmu.getFMUState)
        return self._call("fmi2GetFMUstate", self._fmu.getFMUstate)

    def set_state(self, state) -> None:
        if self.fmi3:
            self._call("fmi3SetFMUState", self._fmu.setFMUState, state)
        else:
            self._call("fmi2SetFMUstate", self._fmu.setFMUstate, state)

    def free_state(self, state) -> None:
        if self.fmi3:
            self._call("fmi3FreeFMUState", self._fmu.freeFMUState, state)
        else:
            self._call("fmi2FreeFMUstate", self._fmu.freeFMUstate, state)

    def reset(self) -> None:
        self._call(f"{self._prefix}Reset", self._fmu.reset)

    def set_values(self, values: Iterable[tuple[str, Any]]) -> None:
        """Set variables by name (grouped per FMI type); in model exchange after initialisation,
        in event mode at the current time, then the event iteration and CVode restarted."""
        if self._solver is not None:
            self._call(f"{self._prefix}EnterEventMode", self._fmu.enterEventMode)
            self._set(values)
            self._event_iteration()
            self._solver.reset(self._time)
            return
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
            self._call(f"{self._prefix}Set{kind}({', '.join(_names(self.md, vrs))})", setter, vrs, vals)

    def reader(self, names: Sequence[str]) -> Callable[[], list]:
        """A function returning the current values of ``names`` (in that order) as Python numbers."""
        kinds = [_setter_type(self.variables[n], self._own_types) for n in names]
        vrs = [self.variables[n].valueReference for n in names]
        slave = self._fmu
        if all(k in ("Real", "Float64") for k in kinds):
            get_real = slave.getFloat64 if self.fmi3 else slave.getReal
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


class _NoInputs:
    """FMPy's CVodeSolver applies the inputs at every evaluation; the orchestrator sets none."""

    def apply(self, time, continuous=True, discrete=True, after_event=False) -> None:
        return None


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

"""What FMI 2.0 and FMI 3.0 do differently for an :class:`~orchestrator.fmi_instance.FmuInstance`.

FMI 3.0 differs in names (Float64 for Real, updateDiscreteStates, getFMUState, ...), in a
logger that gets a finished message (one ctypes callback per instance, kept as long as the
instance), in an initialisation that takes the experiment's times and tolerance, and in a
doStep that may ask to end the simulation.  FMI 2.0's logger goes through FMPy's logger
proxy, which formats the FMU's printf-style messages; see :data:`_ROUTES`.
"""
from __future__ import annotations

import itertools
import threading

from .fmi_instance import FmuError, FmuInstance
from .pythonfmu_workarounds import forget_other_fmu_modules

__all__ = ["Fmi2Instance", "Fmi3Instance"]

# FMPy's logger proxy (fmpy.logging.addLoggerProxy, needed to format the FMU's printf-style
# messages) keeps the Python logger in ONE process-wide C variable, which FMPy's default
# callbacks (simulate_fmu & co.) also go through.  A per-instance ctypes callback would be
# freed with its instance and leave that variable dangling: the next FMU that logs in this
# process would call freed memory (observed: a segfault in simulate_fmu after run_case).
# So there is one callback for the life of the process; it routes each message by the
# componentEnvironment pointer the FMU passes back, and hands unknown ones to FMPy's printer.
_ROUTES: dict[int, FmuInstance] = {}
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


class Fmi2Instance(FmuInstance):
    """FMI 2.0: the calls' names, the routed logger, ``fmi2SetupExperiment``."""

    PREFIX = "fmi2"
    FLOAT = "Real"

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._env = 0
        self._callbacks = None

    def _instantiate(self, kind: type, model_identifier: str) -> None:
        from ctypes import byref

        from fmpy.fmi2 import calloc, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions, free
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
        self._fmu = kind(guid=self.md.guid, unzipDirectory=self._unzipdir, modelIdentifier=model_identifier,
                         instanceName=self.instance_name)
        forget_other_fmu_modules(self._unzipdir)   # another build's cached Python code
        try:
            # loggingOn: pythonfmu (and many FMUs) forward messages only when logging is on.
            self._fmu.instantiate(callbacks=callbacks, loggingOn=True)
        except Exception as exc:   # FMPy raises a bare Exception when fmi2Instantiate returns NULL
            raise FmuError(self._describe(f"fmi2Instantiate failed ({exc})", 0)) from None

    def _release_logger(self) -> None:
        _ROUTES.pop(self._env, None)

    def _setup_experiment(self, start: float, stop: float, tolerance: float | None) -> None:
        self._call("fmi2SetupExperiment", self._fmu.setupExperiment, tolerance, start, stop)

    def enter_initialization_mode(self) -> None:
        self._call("fmi2EnterInitializationMode", self._fmu.enterInitializationMode)

    def _ends_simulation(self, step_result) -> bool:
        """Whether a doStep's result asks to end the simulation (FMI 2.0's returns a status only)."""
        return False

    def _update_discrete_states(self) -> tuple:
        return self._call("fmi2NewDiscreteStates", self._fmu.newDiscreteStates)

    def _derivatives(self):
        return self._fmu.getDerivatives

    def get_state(self):
        return self._call("fmi2GetFMUstate", self._fmu.getFMUstate)

    def set_state(self, state) -> None:
        self._call("fmi2SetFMUstate", self._fmu.setFMUstate, state)

    def free_state(self, state) -> None:
        self._call("fmi2FreeFMUstate", self._fmu.freeFMUstate, state)


class Fmi3Instance(FmuInstance):
    """FMI 3.0: the calls' names, a logger per instance, the experiment at initialisation."""

    PREFIX = "fmi3"
    FLOAT = "Float64"

    def _instantiate(self, kind: type, model_identifier: str) -> None:
        self._fmu = kind(guid=self.md.guid, unzipDirectory=self._unzipdir, modelIdentifier=model_identifier,
                         instanceName=self.instance_name)
        try:
            self._fmu.instantiate(loggingOn=True, logMessage=self._logger3)
        except Exception as exc:   # FMPy raises a bare Exception when the instantiation returns NULL
            raise FmuError(self._describe(f"fmi3Instantiate{self.fmi_type} failed ({exc})", 0)) from None

    def _logger3(self, environment, status, category, message) -> None:
        """FMI 3.0's logMessage: the message comes formatted."""
        self._logger(environment, None, status, category, message)

    def _setup_experiment(self, start: float, stop: float, tolerance: float | None) -> None:
        return None    # FMI 3.0 takes the experiment at enter_initialization_mode

    def enter_initialization_mode(self) -> None:
        start, stop, tolerance = self._experiment
        self._call("fmi3EnterInitializationMode", self._fmu.enterInitializationMode, tolerance, start, stop)

    def _ends_simulation(self, step_result) -> bool:
        """Whether a doStep's result asks to end the simulation (its terminateSimulation)."""
        return bool(step_result[1])

    def _update_discrete_states(self) -> tuple:
        return self._call("fmi3UpdateDiscreteStates", self._fmu.updateDiscreteStates)

    def _derivatives(self):
        return self._fmu.getContinuousStateDerivatives

    def get_state(self):
        return self._call("fmi3GetFMUState", self._fmu.getFMUState)

    def set_state(self, state) -> None:
        self._call("fmi3SetFMUState", self._fmu.setFMUState, state)

    def free_state(self, state) -> None:
        self._call("fmi3FreeFMUState", self._fmu.freeFMUState, state)

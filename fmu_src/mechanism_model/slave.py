"""Any described mechanism as an FMI 2.0 co-simulation slave (pythonfmu).

A built FMU's script defines a subclass named after the mechanism (``FourBar``,
``SliderCrank``...); everything else is here and in the generated ``equations`` module.

Fault injection: the tunable parameters (lengths, masses, g, a driver's speed) may change
between steps.  ``fmi2SetReal`` only assigns the attribute (pythonfmu); ``do_step`` compares
the parameters with the ones in use and, when they differ, re-assembles the mechanism keeping
the declared ([start]) coordinates and their rates (whatever the integrator uses then:
MechanismDAE.change_parameters) before integrating.  Outputs are updated only at
the end of ``do_step``, so the outputs read at a communication point always show the state
before a change made at that point.

Inputs (``[[inputs]]``, ``causality="input"``) may be set at any time; ``do_step`` applies them
at the step's start and holds them over the step (the dependent coordinates re-solved, the
integrator restarted: a driver's input position moves the linkage there).
"""
import math

from pythonfmu import DefaultExperiment, Fmi2Causality, Fmi2Slave, Fmi2Variability
from pythonfmu.enums import Fmi2Status
from pythonfmu.variables import Real, String

from . import equations
from .dae import INTEGRATORS, AssemblyError, IntegrationError, MechanismDAE, snap_time
from .variables import POSITIVE

__all__ = ["MechanismSlave"]

_CAUSALITY = {"parameter": Fmi2Causality.parameter, "output": Fmi2Causality.output,
              "input": Fmi2Causality.input}
_VARIABILITY = {"tunable": Fmi2Variability.tunable, "fixed": Fmi2Variability.fixed,
                "continuous": Fmi2Variability.continuous}
_OUTPUTS = tuple(v.name for v in equations.VARIABLES if v.causality == "output")
#: Outputs computed only when a host reads them (they need a solve for the multipliers):
#: output name -> its index among ``MechanismDAE.force_outputs``.
_FORCES = {name: k for k, name in enumerate(n for n, kind in zip(_OUTPUTS, equations.OUTPUT_KINDS)
                                            if kind == "force")}
_REAL_PARAMETERS = tuple(v for v in equations.VARIABLES if v.causality == "parameter" and v.type == "Real")


def _problem(var, value) -> str | None:
    """What is wrong with a parameter value (a message naming it), or None."""
    unit = f" {var.unit}" if var.unit not in (None, "1") else ""
    if var.minimum == POSITIVE and not (math.isfinite(value) and value > 0.0):
        return f"{var.name} = {value!r}{unit}: must be a finite positive number"
    if not math.isfinite(value):
        return f"{var.name} = {value!r}: must be finite"
    low = var.minimum if var.minimum not in (None, POSITIVE) else None
    if (low is not None and value < low) or (var.maximum is not None and value > var.maximum):
        return (f"{var.name} = {value!r}{unit}: must be within [{low if low is not None else '-inf'}, "
                f"{var.maximum if var.maximum is not None else 'inf'}]")
    return None


class MechanismSlave(Fmi2Slave):
    author = "fourbar-cosim developers"
    license = "MIT"
    version = "0.2.0"
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=100.0, step_size=0.01, tolerance=1e-9)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        # Registered in the table's order: pythonfmu numbers the value references as registered.
        for var in equations.VARIABLES:
            setattr(self, var.name, 0.0 if var.start is None else var.start)
            kind = Real if var.type == "Real" else String
            getter = None
            if var.name in _FORCES:
                getter = (lambda k=_FORCES[var.name]: self._force(k))
            self.register_variable(kind(var.name, causality=_CAUSALITY[var.causality],
                                        variability=_VARIABILITY[var.variability],
                                        description=var.description, getter=getter))
        self._forces = None
        self._stop_time = math.inf
        self._dae = None

    # -- helpers -------------------------------------------------------------------
    def _parameters(self) -> tuple:
        return tuple(float(getattr(self, name)) for name in equations.PARAMETERS)

    def _inputs(self) -> tuple:
        return tuple(float(getattr(self, name)) for name in equations.INPUTS)

    def _check_parameters(self) -> list:
        """Every problem with the current parameter values, as messages."""
        problems = [_problem(var, getattr(self, var.name)) for var in _REAL_PARAMETERS]
        problems = [p for p in problems if p]
        if self.integrator not in INTEGRATORS:
            problems.append(f"integrator = {self.integrator!r}: must be one of {', '.join(INTEGRATORS)}")
        return problems

    def _fail(self, message: str) -> bool:
        self.log(f"{type(self).__name__} '{self.instance_name}': {message}", Fmi2Status.error)
        return False

    def _publish(self) -> None:
        for name, value in zip(_OUTPUTS, self._dae.outputs(forces=False)):
            if value is not None:
                setattr(self, name, value)
        self._forces = None

    def _force(self, k: int) -> float:
        """A joint reaction or driver torque of the current state, computed at its first read."""
        if self._dae is None:
            return 0.0
        if self._forces is None:
            self._forces = self._dae.force_outputs()
        return float(self._forces[k])

    # -- FMI -----------------------------------------------------------------------
    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self._start_time = float(start_time)
        if stop_time is not None:
            self._stop_time = float(stop_time)

    def exit_initialization_mode(self):
        problems = self._check_parameters()
        if problems:
            raise ValueError("invalid parameters: " + "; ".join(problems))
        start = snap_time(getattr(self, "_start_time", 0.0))
        # Let the integrator step a little past the stop time: a master may end on it by round-off.
        bound = self._stop_time + 1.0 if math.isfinite(self._stop_time) else math.inf
        bad = [f"{name} = {value!r}: must be finite" for name, value in zip(equations.INPUTS, self._inputs())
               if not math.isfinite(value)]
        if bad:
            raise ValueError("invalid inputs: " + "; ".join(bad))
        dae = MechanismDAE(equations, self._parameters() + self._inputs(), method=self.integrator, rtol=self.rtol,
                           atol=self.atol, t_bound=bound)
        guess, rates = list(equations.GUESS), [0.0] * equations.N_COORDINATES
        for i, (position, rate) in zip(equations.INDEPENDENT, equations.START_PARAMETERS):
            guess[i], rates[i] = float(getattr(self, position)), float(getattr(self, rate))
        given = ", ".join(f"{position} = {getattr(self, position)!r}" for position, _ in
                          equations.START_PARAMETERS) or "the drivers' start values"
        try:
            dae.assemble(start, guess, rates)
        except AssemblyError as exc:
            raise ValueError(f"initial assembly with {given} failed: {exc}") from None
        except (ArithmeticError, ValueError) as exc:     # inf or nan from extreme values (L2 = 1e308)
            raise ValueError(f"initial assembly with {given} failed: the arithmetic overflowed "
                             f"({type(exc).__name__}: {exc}); are the parameters of a physical size?") from None
        dae.start()
        self._dae = dae
        self._publish()

    def _bad_step(self, current_time, step_size) -> str | None:
        """Why a communication step cannot be taken as given (the native FMU's model_bad_step), or None."""
        if not math.isfinite(current_time):
            return f"do_step: the current communication point must be finite (got {current_time!r} s)"
        if not (math.isfinite(step_size) and step_size > 0.0 and math.isfinite(current_time + step_size)):
            return (f"do_step: the communication step size must be a finite positive number of seconds "
                    f"(got {step_size!r} s at t = {current_time!r} s)")
        if not snap_time(current_time + step_size) > snap_time(current_time):
            return (f"do_step: a step of {step_size!r} s from t = {current_time!r} s cannot advance the time: the "
                    f"FMU's communication times are whole nanoseconds (give a step of at least 1e-9 s)")
        return None

    def do_step(self, current_time, step_size):
        """One communication step.  A failure (a step that cannot be taken as given, a parameter
        that cannot be applied, an integration failure, more than ``max_evaluations``
        right-hand-side evaluations) is logged with status error and returns False, which
        pythonfmu 0.7 reports as fmi2Discard (it has no way to return fmi2Error from a step; an
        exception would be fmi2Fatal); the native FMU returns fmi2Error."""
        dae = self._dae
        if dae is None:
            return self._fail("do_step called before initialization")
        bad = self._bad_step(current_time, step_size)
        if bad:
            return self._fail(bad)
        if abs(snap_time(current_time) - dae.t) > 1e-9 * max(1.0, abs(dae.t)):
            return self._fail(f"do_step at t = {current_time!r} s, but the model is at t = {dae.t!r} s")
        p = self._parameters()
        if p != dae.p[:len(p)]:
            problems = self._check_parameters()
            if problems:
                return self._fail(f"at t = {current_time:.9g} s: " + "; ".join(problems))
            changed = ", ".join(f"{n} {a:g} -> {b:g}" for n, a, b in zip(equations.PARAMETERS, dae.p, p) if a != b)
            try:
                dae.change_parameters(p + dae.p[len(p):])
            except AssemblyError as exc:
                return self._fail(f"cannot apply {changed} at t = {current_time:.9g} s: {exc}")
            self.log(f"applied {changed} at t = {current_time:.9g} s (re-assembled keeping "
                     f"{', '.join(equations.COORDINATES[i] for i in dae.independent) or 'the drivers'})",
                     Fmi2Status.ok)
        u = self._inputs()
        if u:                           # inputs: from the step's start (MechanismDAE.set_inputs)
            bad = [f"{name} = {value!r}: must be finite" for name, value in zip(equations.INPUTS, u)
                   if not math.isfinite(value)]
            if bad:
                return self._fail(f"at t = {current_time:.9g} s: " + "; ".join(bad))
            try:
                dae.set_inputs(u)
            except AssemblyError as exc:
                return self._fail(f"cannot apply the inputs {', '.join(f'{n} = {v!r}' for n, v in zip(equations.INPUTS, u))}"
                                  f" at t = {current_time:.9g} s: {exc}")
        try:
            dae.advance(snap_time(current_time + step_size), max_evaluations=float(self.max_evaluations))
            self._publish()
        except (IntegrationError, AssemblyError, ArithmeticError) as exc:
            return self._fail(str(exc))
        return True

"""FourBar: the Lagrange-multiplier four-bar linkage as an FMI 2.0 co-simulation slave.

This file is the pythonfmu script; it is copied into the FMU's ``resources/`` together
with the ``fourbar_model`` package (numpy/scipy only).  All state is kept in plain
attributes, each registered with its causality and variability.

Fault injection: the lengths, masses and g are tunable.  ``fmi2SetReal`` only assigns
the attribute (pythonfmu); ``do_step`` compares the parameters with the ones in use and,
when they differ, re-assembles the linkage keeping theta2 and omega2 before integrating.
Outputs are updated only at the end of ``do_step``, so the outputs read at a
communication point always show the state before a change made at that point.
"""
import math

from pythonfmu import DefaultExperiment, Fmi2Causality, Fmi2Slave, Fmi2Variability
from pythonfmu.enums import Fmi2Status
from pythonfmu.variables import Real, String

from fourbar_model import equations
from fourbar_model.variables import PARAMETER_NAMES, VARIABLES
from fourbar_model.dae import INTEGRATORS, AssemblyError, FourBarDAE, IntegrationError, assemble, snap_time

_PARAMETER_ORDER = equations.PARAMETERS   # (L1, L2, L3, L4, m2, m3, m4, g)
if tuple(_PARAMETER_ORDER) != PARAMETER_NAMES:
    raise ImportError("the generated equations and the variable table disagree on the parameter order")

_CAUSALITY = {"parameter": Fmi2Causality.parameter, "output": Fmi2Causality.output}
_VARIABILITY = {"tunable": Fmi2Variability.tunable, "fixed": Fmi2Variability.fixed,
                "continuous": Fmi2Variability.continuous}


class FourBar(Fmi2Slave):
    author = "fourbar-cosim developers"
    description = ("Planar four-bar linkage (Table 1 of Park's integrated engineering education model): "
                   "Lagrange-multiplier DAE derived with sympy, explicit Runge-Kutta (scipy), "
                   "lengths and masses tunable for fault injection")
    license = "MIT"
    version = "0.1.0"
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=100.0, step_size=0.01, tolerance=1e-9)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        # Registered in the table's order: pythonfmu numbers the value references as registered.
        for var in VARIABLES:
            setattr(self, var.name, 0.0 if var.start is None else var.start)
            kind = Real if var.type == "Real" else String
            self.register_variable(kind(var.name, causality=_CAUSALITY[var.causality],
                                        variability=_VARIABILITY[var.variability],
                                        description=var.description))
        self._stop_time = math.inf
        self._dae = None

    # -- helpers -------------------------------------------------------------------
    def _parameters(self) -> tuple:
        return tuple(float(getattr(self, name)) for name in _PARAMETER_ORDER)

    def _check_parameters(self) -> list:
        """Every problem with the current parameter values, as messages."""
        problems = []
        for name in ("L1", "L2", "L3", "L4", "m2", "m3", "m4"):
            value = getattr(self, name)
            unit = "m" if name.startswith("L") else "kg"
            if not (math.isfinite(value) and value > 0.0):
                problems.append(f"{name} = {value!r} {unit}: must be a finite positive number")
        for name in ("g", "theta2_start", "omega2_start"):
            if not math.isfinite(getattr(self, name)):
                problems.append(f"{name} = {getattr(self, name)!r}: must be finite")
        for name in ("rtol", "atol"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                problems.append(f"{name} = {value!r}: must be a finite positive number")
        if self.integrator not in INTEGRATORS:
            problems.append(f"integrator = {self.integrator!r}: must be one of {', '.join(INTEGRATORS)}")
        return problems

    def _fail(self, message: str) -> bool:
        self.log(f"FourBar '{self.instance_name}': {message}", Fmi2Status.error)
        return False

    def _publish(self) -> None:
        dae = self._dae
        q, qd = dae.q, dae.qd
        self.x2, self.y2, self.theta2 = float(q[0]), float(q[1]), float(q[2])
        self.x3, self.y3, self.theta3 = float(q[3]), float(q[4]), float(q[5])
        self.x4, self.y4, self.theta4 = float(q[6]), float(q[7]), float(q[8])
        self.omega2, self.omega3, self.omega4 = float(qd[2]), float(qd[5]), float(qd[8])
        self.energy = dae.energy()
        self.constraint_residual = dae.constraint_residual()

    # -- FMI -----------------------------------------------------------------------
    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self._start_time = float(start_time)
        if stop_time is not None:
            self._stop_time = float(stop_time)

    def exit_initialization_mode(self):
        problems = self._check_parameters()
        if problems:
            raise ValueError("invalid parameters: " + "; ".join(problems))
        p = self._parameters()
        start = getattr(self, "_start_time", 0.0)
        try:
            q, qd = assemble(self.theta2_start, self.omega2_start, p, equations)
        except AssemblyError as exc:
            raise ValueError(f"initial assembly with theta2_start = {self.theta2_start!r} rad failed: {exc}") from None
        # Let the integrator step a little past the stop time: a master may end on it by round-off.
        bound = self._stop_time + 1.0 if math.isfinite(self._stop_time) else math.inf
        self._dae = FourBarDAE(equations, p, method=self.integrator, rtol=self.rtol,
                               atol=self.atol, t_bound=bound)
        self._dae.start(snap_time(start), q, qd)
        self._publish()

    def do_step(self, current_time, step_size):
        dae = self._dae
        if dae is None:
            return self._fail("do_step called before initialization")
        if abs(snap_time(current_time) - dae.t) > 1e-9 * max(1.0, abs(dae.t)):
            return self._fail(f"do_step at t = {current_time!r} s, but the model is at t = {dae.t!r} s")
        p = self._parameters()
        if p != dae.p:
            problems = self._check_parameters()
            if problems:
                return self._fail(f"at t = {current_time:.9g} s: " + "; ".join(problems))
            changed = ", ".join(f"{n} {a:g} -> {b:g}" for n, a, b in zip(_PARAMETER_ORDER, dae.p, p) if a != b)
            try:
                dae.change_parameters(p)
            except AssemblyError as exc:
                return self._fail(f"cannot apply {changed} at t = {current_time:.9g} s: {exc}")
            self.log(f"applied {changed} at t = {current_time:.9g} s (re-assembled keeping theta2, omega2)",
                     Fmi2Status.ok)
        try:
            dae.advance(snap_time(current_time + step_size))
        except (IntegrationError, AssemblyError, ArithmeticError) as exc:
            return self._fail(str(exc))
        self._publish()
        return True

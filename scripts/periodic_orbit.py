#!/usr/bin/env python3
"""A mechanism's stable equilibrium, its normal modes, and a periodic swing in one of them.

A condition monitor learns a period.  A one-degree-of-freedom linkage released from rest
swings periodically; a mechanism with more degrees of freedom in general does not (the
five-bar's free swing is chaotic, like a double pendulum's).  Near a stable equilibrium it
has one normal mode per degree of freedom, and started on one of them, exactly, it swings
periodically.  This script finds such a start for any native FMI 2.0 FMU (``<Name>Native.fmu``:
co-simulation, and model exchange with directional derivatives; ``python build_fmu.py
--mechanism NAME``):

1. the equilibrium: Newton-Raphson on the accelerations at rest, q'' (q, q' = 0) = 0, with
   their Jacobian A = d q'' / d q from the FMU's exact directional derivatives, from the
   FMU's start configuration or ``--near``;
2. the normal modes: A's eigenvectors; stable when every eigenvalue is negative, a mode's
   period then 2 pi / sqrt(-eigenvalue);
3. the periodic orbit of mode ``--mode`` (1: the slowest): released from rest with the
   mode's largest coordinate ``--amplitude`` rad from the equilibrium (either sign: the two
   turning points of one swing), the other
   coordinates are corrected (shooting, from the linear mode shape) until every rate is zero
   again half a period later.  By time reversal the swing then repeats exactly.  The
   nonlinear period is the returned half period times two.

It prints the equilibrium, the modes and the start values for a case file's
``[parameters]`` (``<coordinate>_start``, and the ``--set`` values).  ``cases/fivebar_fault_L5.toml``
is made this way:

    python scripts/periodic_orbit.py build/FiveBarNative.fmu --near -90 -90 --mode 1 --amplitude 0.136

Exit status: 0 found, 1 not found (no equilibrium near the guess, an unstable one, a shooting
that does not converge: the message says which), 2 bad arguments or an FMU that cannot do it.
"""
from __future__ import annotations

import argparse
import ctypes
import math
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import root

#: The FMU's integrator tolerance in the shooting runs: the orbit's rates vanish at the half
#: period to about this (times the rates' size), well below what a monitor can see.
SHOOT_TOL = 1e-13
#: Newton-Raphson on the equilibrium: converged when the largest correction is below this
#: (rad), at most this many iterations.
EQUILIBRIUM_STEP = 1e-12
EQUILIBRIUM_ITERATIONS = 50
#: The shooting converged when every rate at the half period is below this fraction of the
#: swing's peak rate (the mode's angular frequency times the amplitude): the orbit's own rates
#: vanish there to the integrator's tolerance (measured 7e-10 of the peak on the five-bar).
SHOOT_RATES = 1e-7


def _messages_callbacks():
    """FMI 2.0 callbacks whose logger keeps the FMU's messages (FMPy's proxy formats them)."""
    from ctypes import byref
    from fmpy.fmi2 import (calloc, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                           fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, free)
    from fmpy.logging import addLoggerProxy
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(_keep_message)
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    addLoggerProxy(byref(callbacks))
    return callbacks


_MESSAGES: list[str] = []
_CALLBACKS = None          # one for the process: the FMU may call it until its instance is freed


def _keep_message(environment, instance_name, status, category, message) -> None:
    _MESSAGES.append(message.decode("utf-8", "replace") if message else "")


def _last_message(default: str) -> str:
    return _MESSAGES[-1] if _MESSAGES else default


class OrbitError(Exception):
    """Not found: the message says what and why (exit 1)."""


class UsageError(Exception):
    """A bad argument or an FMU that cannot do it (exit 2)."""


@dataclass(frozen=True)
class Modes:
    """The equilibrium at rest and its normal modes (slowest first)."""

    coordinates: tuple[str, ...]
    equilibrium: np.ndarray          # rad (or m), per coordinate
    eigenvalues: np.ndarray          # 1/s^2, of A = d q'' / d q
    shapes: np.ndarray               # columns: mode shapes, largest entry +1

    @property
    def periods(self) -> np.ndarray:
        return 2.0 * math.pi / np.sqrt(-self.eigenvalues)


@dataclass(frozen=True)
class Orbit:
    """A periodic swing from rest: the start and the period."""

    start: np.ndarray                # per coordinate
    period: float                    # s
    rates_at_half: np.ndarray        # rad/s: how far from zero the rates are half a period later


class MechanismFMU:
    """The native FMU twice: model exchange for derivatives at given states, co-simulation for
    the shooting's runs.  ``close()`` frees both, whatever state they are in."""

    def __init__(self, path: Path, workdir: Path, settings: dict[str, float]):
        global _CALLBACKS
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Model, FMU2Slave
        try:
            self.md = read_model_description(str(path))
        except Exception as exc:        # noqa: BLE001  (fmpy raises several kinds on a bad file)
            raise UsageError(f"{path}: not a readable FMU ({exc})") from None
        me, cs = self.md.modelExchange, self.md.coSimulation
        if self.md.fmiVersion != "2.0" or me is None or cs is None or not me.providesDirectionalDerivative:
            raise UsageError(f"{path}: needs an FMI 2.0 FMU with co-simulation, and model exchange with directional "
                             "derivatives (a native FMU: python build_fmu.py --mechanism NAME builds "
                             "build/<Name>Native.fmu)")
        variables = {v.name: v for v in self.md.modelVariables}
        self.vr = {name: v.valueReference for name, v in variables.items()}
        for name in settings:
            if name not in variables:
                raise UsageError(f"--set {name}: no such variable in {path.name}")
            if variables[name].causality != "parameter":
                raise UsageError(f"--set {name}: not a parameter of {path.name} (its causality is "
                                 f"{variables[name].causality})")
        self.states = [d.variable.derivative.name for d in self.md.derivatives]
        # A coordinate's derivative depends on one state, its rate (<Derivatives>, see docs/fmi_hosts.md).
        pairs = [(d.variable.derivative.name, d.dependencies[0].name) for d in self.md.derivatives
                 if d.dependencies is not None and len(d.dependencies) == 1
                 and d.dependencies[0].name in self.states]
        self.coordinates = tuple(q for q, _ in pairs)
        self.rates = tuple(r for _, r in pairs)
        self.units = tuple(variables[q].unit for q in self.coordinates)     # "rad", or "m" for a slider
        if not self.coordinates:
            raise UsageError(f"{path}: the mechanism has no free coordinate (a driven one moves as its driver "
                             "says): nothing swings")
        missing = [name for name in [f"{q}_start" for q in self.coordinates + self.rates] + ["rtol", "atol"]
                   if name not in self.vr]
        if missing:
            raise UsageError(f"{path}: no parameter {', '.join(missing)} (not a native FMU of this project?)")
        self.path, self.settings = path, settings
        if _CALLBACKS is None:
            _CALLBACKS = _messages_callbacks()
        self.unzip = extract(str(path), unzipdir=str(workdir))
        self.model = FMU2Model(guid=self.md.guid, unzipDirectory=self.unzip, modelIdentifier=me.modelIdentifier,
                               instanceName="periodic_orbit")
        self.slave = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzip, modelIdentifier=cs.modelIdentifier,
                               instanceName="periodic_orbit_shooting")
        self._live = []
        try:
            for fmu in (self.model, self.slave):
                fmu.instantiate(callbacks=_CALLBACKS)
                self._live.append(fmu)
            self.model.setupExperiment(startTime=0.0)
            self._set(self.model, settings)
            self.model.enterInitializationMode()
            self.model.exitInitializationMode()
            self.model.newDiscreteStates()
            self.model.enterContinuousTimeMode()
        except Exception as exc:        # noqa: BLE001  (FMICallException: the FMU said why in its log)
            why = _last_message(str(exc))
            self.close()
            raise UsageError(f"{path.name} refused the start: {why}") from None
        self.nx = len(self.states)
        self.x = np.zeros(self.nx)
        self.model.getContinuousStates(self._pointer(self.x), self.nx)
        self.iq = [self.states.index(q) for q in self.coordinates]
        self.iw = [self.states.index(r) for r in self.rates]
        self.der = [d.variable.valueReference for d in self.md.derivatives]

    def _set(self, fmu, values: dict[str, float]) -> None:
        if values:
            fmu.setReal([self.vr[n] for n in values], [float(v) for v in values.values()])

    @staticmethod
    def _pointer(a: np.ndarray):
        return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))

    def start_configuration(self) -> np.ndarray:
        return self.x[self.iq].copy()

    def _at_rest(self, q: np.ndarray) -> None:
        x = self.x.copy()
        x[self.iq], x[self.iw] = q, 0.0
        self.model.setContinuousStates(self._pointer(x), self.nx)

    def accelerations(self, q: np.ndarray) -> np.ndarray:
        try:
            self._at_rest(q)
            f = np.zeros(self.nx)
            self.model.getDerivatives(self._pointer(f), self.nx)
        except Exception as exc:        # noqa: BLE001
            raise OrbitError(f"at {_where(self, q)}: {_last_message(str(exc))}") from None
        return f[self.iw]

    def stiffness(self, q: np.ndarray) -> np.ndarray:
        """A = d q'' / d q at rest, exact (the FMU's directional derivatives)."""
        rows = [self.der[i] for i in self.iw]
        columns = []
        try:
            self._at_rest(q)
            for i in self.iq:
                seed = [0.0] * self.nx
                seed[i] = 1.0
                columns.append(self.model.getDirectionalDerivative(rows, [self.vr[s] for s in self.states], seed))
        except Exception as exc:        # noqa: BLE001
            raise OrbitError(f"at {_where(self, q)}: {_last_message(str(exc))}") from None
        return np.array(columns, dtype=float).T

    def half_swing(self, start: np.ndarray, half: float) -> np.ndarray:
        """The rates ``half`` s after a release from rest at ``start``: one co-simulation step of
        the FMU's own integrator at SHOOT_TOL.  OrbitError with the FMU's words when it fails."""
        values = {**self.settings, "rtol": SHOOT_TOL, "atol": SHOOT_TOL,
                  **{f"{q}_start": float(v) for q, v in zip(self.coordinates, start)},
                  **{f"{r}_start": 0.0 for r in self.rates}}
        try:
            self.slave.reset()
            self.slave.setupExperiment(startTime=0.0)
            self._set(self.slave, values)
            self.slave.enterInitializationMode()
            self.slave.exitInitializationMode()
            self.slave.doStep(currentCommunicationPoint=0.0, communicationStepSize=half)
            return np.array(self.slave.getReal([self.vr[r] for r in self.rates]), dtype=float)
        except Exception as exc:        # noqa: BLE001  (FMICallException)
            raise OrbitError(f"released at {_where(self, start)} for {half:.6g} s: "
                             f"{_last_message(str(exc))}") from None

    def close(self) -> None:
        while self._live:
            fmu = self._live.pop()
            try:
                fmu.terminate()
            except Exception:           # noqa: BLE001  (refused in the error state: freed all the same)
                pass
            finally:
                fmu.freeInstance()


def normal_modes(fmu: MechanismFMU, near: np.ndarray) -> Modes:
    q = near.astype(float).copy()
    for _ in range(EQUILIBRIUM_ITERATIONS):
        try:
            step = np.linalg.solve(fmu.stiffness(q), -fmu.accelerations(q))
        except np.linalg.LinAlgError:
            raise OrbitError(f"d q''/d q is singular at {_where(fmu, q)}: no Newton-Raphson step "
                             "from there; try --near another guess") from None
        q += step
        if not np.all(np.isfinite(q)):
            raise OrbitError(f"Newton-Raphson diverged from {_where(fmu, near)}; try --near closer "
                             "to an equilibrium")
        if np.max(np.abs(step)) < EQUILIBRIUM_STEP:
            eigenvalues, shapes = np.linalg.eig(fmu.stiffness(q))
            if np.any(np.abs(eigenvalues.imag) > 1e-9 * np.abs(eigenvalues.real)) or np.any(eigenvalues.real >= 0):
                raise OrbitError(f"the equilibrium at {_where(fmu, q)} is not stable (eigenvalues of "
                                 f"d q''/d q: {eigenvalues}): nothing swings about it; try --near another one")
            eigenvalues, shapes = eigenvalues.real, shapes.real
            order = np.argsort(-eigenvalues)          # slowest (smallest |eigenvalue|) first
            eigenvalues, shapes = eigenvalues[order], shapes[:, order]
            for k in range(shapes.shape[1]):
                shapes[:, k] /= shapes[np.argmax(np.abs(shapes[:, k])), k]
            return Modes(fmu.coordinates, q, eigenvalues, shapes)
    raise OrbitError(f"no equilibrium found near {_where(fmu, near)}: Newton-Raphson did not converge "
                     f"in {EQUILIBRIUM_ITERATIONS} iterations; try --near closer to one")


def periodic_orbit(fmu: MechanismFMU, modes: Modes, mode: int, amplitude: float) -> Orbit:
    shape = modes.shapes[:, mode - 1]
    lead = int(np.argmax(np.abs(shape)))              # the coordinate held at the amplitude
    others = [i for i in range(len(shape)) if i != lead]
    guess = modes.equilibrium + amplitude * shape
    peak_rate = 2.0 * math.pi / modes.periods[mode - 1] * abs(amplitude)

    def start_of(z: np.ndarray) -> np.ndarray:
        q = guess.copy()
        q[others] = z[:-1]
        return q

    z0 = np.append(guess[others], modes.periods[mode - 1] / 2)
    fmu.half_swing(start_of(z0), float(z0[-1]))       # the first guess must run: else the FMU's reason

    def residual(z: np.ndarray) -> np.ndarray:
        if not z[-1] > 0:
            return np.full(len(z), 1e3 * peak_rate)
        try:
            return fmu.half_swing(start_of(z), float(z[-1]))
        except OrbitError:                             # a trial the linkage cannot take: steer away
            return np.full(len(z), 1e3 * peak_rate)

    found = root(residual, z0, method="hybr", options={"xtol": 1e-14})
    rates = np.asarray(found.fun, dtype=float)
    if not np.all(np.abs(rates) < SHOOT_RATES * peak_rate):
        raise OrbitError(f"the shooting for mode {mode} at amplitude {amplitude:g} did not converge (rates half a "
                         f"period later: {rates}; {found.message}); try a smaller --amplitude")
    return Orbit(start_of(found.x), 2.0 * float(found.x[-1]), rates)


def _where(fmu: "MechanismFMU", q) -> str:
    """The coordinates as a user reads them: angles in degrees, lengths in m."""
    return ", ".join(f"{n} = {math.degrees(v):.4f} deg" if unit == "rad" else f"{n} = {v:.6f} {unit or ''}".rstrip()
                     for n, unit, v in zip(fmu.coordinates, fmu.units, q))


def _setting(text: str) -> tuple[str, float]:
    name, sep, value = text.partition("=")
    try:
        number = float(value)
        if not sep or not name.strip() or not math.isfinite(number):
            raise ValueError
        return name.strip(), number
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected NAME=NUMBER with a finite number, e.g. "
                                         "L5=1.485") from None


def _finite(text: str) -> float:
    try:
        value = float(text)
        if not math.isfinite(value):
            raise ValueError
        return value
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: not a finite number") from None


def _amplitude(text: str) -> float:
    value = _finite(text)
    if value == 0.0:
        raise argparse.ArgumentTypeError("0: a swing needs a nonzero amplitude (either sign)")
    return value


def _mode(text: str) -> int:
    try:
        value = int(text)
        if value < 1:
            raise ValueError
        return value
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: a mode number, 1 for the slowest") from None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="periodic_orbit.py", description=__doc__.split("\n\n")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Prints the equilibrium, the normal modes and, with --amplitude, a case file's start values.\n\n"
               "example (cases/fivebar_fault_L5.toml's start):\n"
               "  python scripts/periodic_orbit.py build/FiveBarNative.fmu --near -90 -90 --mode 1 --amplitude 0.136\n\n"
               "exit status: 0 found, 1 not found (the message says why), 2 bad arguments or an unsuitable FMU")
    parser.add_argument("fmu", type=Path, help="a native FMU (build/<Name>Native.fmu)")
    parser.add_argument("--near", type=_finite, nargs="+", metavar="VALUE",
                        help="where to look for the equilibrium, one value per independent coordinate: an angle "
                             "in degrees, a slider's position in m (default: the FMU's start configuration)")
    parser.add_argument("--mode", type=_mode, default=1, help="which mode to swing in, 1 the slowest (default 1)")
    parser.add_argument("--amplitude", type=_amplitude,
                        help="how far from the equilibrium the mode's largest coordinate is released, in its "
                             "unit (rad, or m for a slider), either sign (nonzero); without it only the equilibrium "
                             "and the modes")
    parser.add_argument("--set", type=_setting, action="append", default=[], metavar="NAME=VALUE",
                        help="a parameter's value (repeatable)")
    args = parser.parse_args(argv)
    if not args.fmu.is_file():
        parser.error(f"{args.fmu}: no such file (python build_fmu.py --mechanism NAME builds it)")
    try:
        with tempfile.TemporaryDirectory() as tmp:
            fmu = MechanismFMU(args.fmu, Path(tmp), dict(args.set))
            try:
                n = len(fmu.coordinates)
                if args.near is not None and len(args.near) != n:
                    raise UsageError(f"--near: {n} angle(s) expected ({', '.join(fmu.coordinates)}), "
                                     f"got {len(args.near)}")
                if not 1 <= args.mode <= n:
                    raise UsageError(f"--mode {args.mode}: the mechanism has {n} mode(s)")
                near = fmu.start_configuration() if args.near is None else \
                    np.array([math.radians(v) if unit == "rad" else v for v, unit in zip(args.near, fmu.units)])
                modes = normal_modes(fmu, near)
                print(f"equilibrium at rest: {_where(fmu, modes.equilibrium)}")
                for k in range(n):
                    shape = " : ".join(f"{v:.4f}" for v in modes.shapes[:, k])
                    print(f"mode {k + 1}: period {modes.periods[k]:.6f} s (small swings), shape "
                          f"{' : '.join(modes.coordinates)} = {shape}")
                if args.amplitude is None:
                    return 0
                orbit = periodic_orbit(fmu, modes, args.mode, args.amplitude)
                rate_unit = " or ".join(dict.fromkeys(f"{unit or '1'}/s" for unit in fmu.units))
                print(f"periodic orbit of mode {args.mode}: period {orbit.period:.10f} s; rates half a period "
                      f"later {np.max(np.abs(orbit.rates_at_half)):.1e} {rate_unit}")
                print("[parameters]")
                for name, value in fmu.settings.items():
                    print(f"{name} = {value!r}")
                for q, unit, v in zip(fmu.coordinates, fmu.units, orbit.start):
                    note = f"rad ({math.degrees(v):.4f} deg)" if unit == "rad" else unit or ""
                    print(f"{q}_start = {float(v)!r}    # {note}")
                for r in fmu.rates:
                    print(f"{r}_start = 0.0")
            finally:
                fmu.close()
    except UsageError as exc:
        print(f"periodic_orbit.py: error: {exc}", file=sys.stderr)
        return 2
    except OrbitError as exc:
        print(f"periodic_orbit.py: not found: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""A small linear system of the shipped components, with a closed-form solution: a current loop.

``controller.voltage -> motor.V``, ``motor.current -> sensor.omega``, ``sensor.measured ->
controller.measured``: the PI controller holds the motor's armature current at ``setpoint``
(1 A) through a sensor of gain 1 and no bias, its resolution 1e-15 A (no quantisation that
matters: below a double's rounding of 1 A's neighbours); the motor's output shaft is held
(``omega_load`` unconnected, 0), so its rotor swings on the shaft's stiffness.  The limits are
far away (+-1e6 V), so nothing saturates and everything is linear:

    z = (i, omega_m, phi, xi),  V = Kp (sp - i) + Ki xi
    L i'  = V - R i - k omega_m
    J omega_m' = k i - b omega_m - (k_s phi + c_s omega_m / N) / N
    phi'  = omega_m / N
    xi'   = sp - i

written here from the block files' physics (not from the derivation), solved exactly by the
augmented matrix's exponential (:func:`exact`).  It is a loop (motor -> sensor -> controller
-> motor) whose outputs feed through only where physics says so: the current is a state, so
the monolithic master evaluates motor, sensor, controller (no algebraic loop), and the
co-simulation masters show their coupling error on it (the loop's fastest pole, the current's
(R + Kp)/L = 150 /s, is resolved by macro steps up to a few ms).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.linalg import expm

from ssp_testing import TestComponent, write_ssp

__all__ = ["BOUND", "COLUMNS", "COMPONENTS", "bench_order", "CONNECTIONS", "MOTOR", "PI", "build_components", "exact", "loop_matrix",
           "loop_ssp", "outputs", "run_system", "write_loop_ssp"]

MOTOR = dict(R=1.0, L=0.01, k=0.5, N=20.0, b=1e-4, J=1e-3, k_s=1250.0, c_s=12.0)
PI = dict(Kp=0.5, Ki=50.0, u_min=-1e6, u_max=1e6, K_aw=0.0)
SETPOINT = 1.0
BOUND = {**{f"motor.{n}": v for n, v in MOTOR.items()}, **{f"controller.{n}": v for n, v in PI.items()},
         "controller.setpoint": SETPOINT, "sensor.gain": 1.0, "sensor.bias": 0.0, "sensor.resolution": 1e-15}
COMPONENTS = {"motor": {"V": "input", "current": "output"},
              "controller": {"measured": "input", "voltage": "output"},
              "sensor": {"omega": "input", "measured": "output"}}
CONNECTIONS = [("controller.voltage", "motor.V"), ("motor.current", "sensor.omega"),
               ("sensor.measured", "controller.measured")]
BLOCKS = {"motor": "dc_motor", "controller": "pi_controller", "sensor": "speed_sensor"}


def build_components(folder: Path) -> dict[str, Path]:
    """The three shipped components' native FMI 2.0 FMUs, built into ``folder`` (about 3 s each)."""
    from fmu_src.block_build import build_block_fmu

    return {name: build_block_fmu(block, folder / f"{block}.fmu") for name, block in BLOCKS.items()}


def write_loop_ssp(path: Path, fmus: dict[str, Path]) -> Path:
    components = [TestComponent(name, fmus[name],
                                inputs=tuple(v for v, kind in connectors.items() if kind == "input"),
                                outputs=tuple(v for v, kind in connectors.items() if kind == "output"))
                  for name, connectors in COMPONENTS.items()]
    return write_ssp(path, "CurrentLoop", components, CONNECTIONS, bindings="none", system_parameters=BOUND)


_MADE: dict[str, Path] = {}


def loop_ssp(tmp_path_factory) -> Path:
    """The loop's .ssp, its components built once per test process (tests/test_run_system_me.py
    and tests/test_coupling_order.py share it)."""
    if "ssp" not in _MADE:
        folder = tmp_path_factory.mktemp("loop_system")
        _MADE["ssp"] = write_loop_ssp(folder / "Loop.ssp", build_components(folder))
    return _MADE["ssp"]


def loop_matrix(setpoint: float = SETPOINT, Kp: float = PI["Kp"], Ki: float = PI["Ki"]):
    """``z' = A z + c`` of the module docstring."""
    R, L, k, N, b, J, k_s, c_s = (MOTOR[n] for n in ("R", "L", "k", "N", "b", "J", "k_s", "c_s"))
    A = np.array([[-(R + Kp) / L, -k / L, 0.0, Ki / L],
                  [k / J, -(b + c_s / N**2) / J, -k_s / (N * J), 0.0],
                  [0.0, 1.0 / N, 0.0, 0.0],
                  [-1.0, 0.0, 0.0, 0.0]])
    c = np.array([Kp * setpoint / L, 0.0, 0.0, setpoint])
    return A, c


def exact(times, z0=(0.0, 0.0, 0.0, 0.0), **kw) -> np.ndarray:
    """z at ``times`` (from ``times[0]``, z0 there): exp of the augmented matrix [[A, c], [0, 0]]."""
    A, c = loop_matrix(**kw)
    M = np.zeros((5, 5))
    M[:4, :4], M[:4, 4] = A, c
    start = np.concatenate([z0, [1.0]])
    return np.array([(expm(M * (t - times[0])) @ start)[:4] for t in times])


def outputs(z, setpoint: float = SETPOINT) -> dict[str, np.ndarray]:
    """The columns of the loop's run from its states: the current, the rotor's speed, the voltage."""
    i, w, _, xi = np.asarray(z).T
    return {"motor.current": i, "motor.omega_motor": w, "controller.voltage": PI["Kp"] * (setpoint - i) + PI["Ki"] * xi}


COLUMNS = ("motor.current", "motor.omega_motor", "controller.voltage")


def run_system(folder: Path, ssp: Path, name: str, *, step: float, stop: float, algorithm: str = "jacobi",
               inputs: str = "hold", columns=COLUMNS, extra: str = "") -> np.ndarray:
    """fourbar-run's rows of ``ssp`` under the master ``algorithm`` (a (rows, 1 + columns) array, time first)."""
    import json

    from orchestrator import run_case

    master = f'algorithm = "{algorithm}"\n' + (f'inputs = "{inputs}"\n' if algorithm != "monolithic" else "")
    case = folder / f"{name}.toml"
    case.write_text(f'name = "{name}"\nsystem = {json.dumps(str(ssp))}\n[experiment]\nstop = {stop!r}\nstep = {step!r}\n'
                    f"[outputs]\nvariables = {json.dumps(list(columns))}\n[master]\n{master}{extra}", encoding="utf-8")
    result = run_case(case, folder / f"out_{name}")
    assert result.status == "finished", result.error
    return np.loadtxt(result.exchange_path, delimiter=",", skiprows=1, ndmin=2)


def bench_order(ssp: Path) -> str:
    """The ``[master] order = [...]`` line the monolithic master needs for ``ssp`` ("" when its
    FMUs' declared dependencies order it): :func:`orchestrator.system_order.suggested_order`."""
    import json

    from orchestrator.system_order import AlgebraicLoop, evaluation_plan, suggested_order
    from orchestrator.system_description import describe_system

    system = describe_system(ssp)
    try:
        evaluation_plan(system)
        return ""
    except AlgebraicLoop:
        return f"order = {json.dumps(list(suggested_order(system)))}\n"

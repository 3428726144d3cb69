"""The shipped components' native FMUs (fmu_src/block_build.py) on real runs: the motor and the
unsaturated PI against the closed-form solution of their linear equations (scipy's expm of A and
B written here from the physics, not from the derivation), the PI's saturation and anti-windup,
the sensor's quantisation, fmpy validate and fmusim, parameter changes, FMU states, input
derivatives, directional derivatives and the declared dependencies.

Each FMU (3 components x FMI 2.0/3.0) is built once per session (about 3 s each)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from fmpy import extract, read_model_description, simulate_fmu
from scipy.linalg import expm

from fmu_src import fmi_hosts
from fmu_src.block_build import build_block_fmu_result
from tests.support import fmusim_or_skip

COMPONENTS = ("dc_motor", "pi_controller", "speed_profile", "speed_sensor")
MOTOR = dict(R=1.0, L=0.01, k=0.5, N=20.0, b=1e-4, J=1e-3, k_s=1250.0, c_s=12.0)   # the file's defaults
#: Co-simulation at rtol = atol = 1e-12 (DOP853, restarted at each communication step) against the
#: exact solution: within 1e-9 relative to the state's scale (max(1, |x|)); measured worst 1.8e-11
#: over 0.5 s (the tolerance leaves room for the platform's libm and the step selection).
CS_TOL = 1e-9
#: Model exchange in FMPy's CVode at relative tolerance 1e-10 (its default max step): within 1e-6
#: relative to the scale (CVode's error control is local; the global error measured 3.4e-8).
ME_TOL = 1e-6


@pytest.fixture(scope="session")
def block_fmus(tmp_path_factory):
    """(component, FMI version) -> (path, fmpy validate's problems)."""
    folder = tmp_path_factory.mktemp("blocks")
    built = {}
    for name in COMPONENTS:
        for version in (2, 3):
            result = build_block_fmu_result(name, folder / f"{name}{version}.fmu", fmi_version=version)
            built[name, version] = (result.path, result.problems)
    return built


# -- helpers: the FMU through FMPy's low-level classes ---------------------------------------------

class Instance:
    """An instance of a component FMU (co-simulation or model exchange, FMI 2.0 or 3.0), its
    variables by name."""

    def __init__(self, fmu, model_exchange=False, start=None):
        from fmpy.fmi2 import FMU2Model, FMU2Slave
        from fmpy.fmi3 import FMU3Model, FMU3Slave

        self.md = read_model_description(str(fmu))
        self.v3 = self.md.fmiVersion.startswith("3")
        self.vr = {v.name: v.valueReference for v in self.md.modelVariables}
        kind = self.md.modelExchange if model_exchange else self.md.coSimulation
        cls = {(False, False): FMU2Slave, (False, True): FMU2Model, (True, False): FMU3Slave,
               (True, True): FMU3Model}[self.v3, model_exchange]
        token = self.md.instantiationToken if self.v3 else self.md.guid
        self.fmu = cls(guid=token, unzipDirectory=extract(str(fmu)), modelIdentifier=kind.modelIdentifier,
                       instanceName="test")
        self.fmu.instantiate()
        if self.v3:
            self.fmu.enterInitializationMode(startTime=0.0)
        else:
            self.fmu.setupExperiment(startTime=0.0)
        self.set(**(start or {}))
        if not self.v3:
            self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()
        self.t = 0.0

    def set(self, **values):
        if values:
            setter = self.fmu.setFloat64 if self.v3 else self.fmu.setReal
            setter([self.vr[n] for n in values], [float(v) for v in values.values()])

    def get(self, *names):
        getter = self.fmu.getFloat64 if self.v3 else self.fmu.getReal
        return np.array(getter([self.vr[n] for n in names]))

    def step(self, h):
        self.fmu.doStep(currentCommunicationPoint=self.t, communicationStepSize=h)
        self.t = round(self.t + h, 12)

    def close(self):
        self.fmu.terminate()
        self.fmu.freeInstance()


def motor_ab(R, L, k, N, b, J, k_s, c_s):
    """dx/dt = A x + B u for x = (i, omega_m, phi), u = (V, omega_load), from the physics: the
    armature's voltage balance L di/dt = V - R i - k omega_m; the rotor's torque balance
    J d omega_m/dt = k i - b omega_m - T/N with the shaft torque T = k_s phi + c_s (omega_m/N -
    omega_load); the shaft's twist d phi/dt = omega_m/N - omega_load."""
    A = np.array([[-R / L, -k / L, 0.0],
                  [k / J, -(b + c_s / N**2) / J, -k_s / (N * J)],
                  [0.0, 1.0 / N, 0.0]])
    B = np.array([[1.0 / L, 0.0], [0.0, c_s / (N * J)], [0.0, -1.0]])
    return A, B


def exact(A, B, x0, u, t, du=None):
    """x(t) for dx/dt = A x + B (u + du t) from x0: the augmented matrix's exponential."""
    n, m = B.shape
    du = np.zeros(m) if du is None else np.asarray(du, float)
    M = np.zeros((n + 2 * m, n + 2 * m))
    M[:n, :n], M[:n, n:n + m], M[n:n + m, n + m:] = A, B, np.eye(m)
    z = expm(M * t) @ np.concatenate([x0, u, du])
    return z[:n]


def motor_outputs(x, u, p=MOTOR):
    i, w, phi = x
    torque = p["k_s"] * phi + p["c_s"] * (w / p["N"] - u[1])
    return np.array([torque, i, w])


def rel_error(a, b):
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b)) / np.maximum(1.0, np.abs(np.asarray(b)))))


# -- validation, fmusim -------------------------------------------------------------------------

@pytest.mark.parametrize("version", (2, 3))
@pytest.mark.parametrize("name", COMPONENTS)
def test_fmpy_validate_finds_no_problem(block_fmus, name, version):
    path, problems = block_fmus[name, version]
    assert problems == ()
    md = read_model_description(str(path))
    assert md.coSimulation is not None and md.modelExchange is not None


@pytest.mark.parametrize("version", (2, 3))
@pytest.mark.parametrize("model_exchange", (False, True), ids=("cs", "me"))
@pytest.mark.parametrize("name", COMPONENTS)
def test_fmusim_runs_each_component(block_fmus, name, model_exchange, version, tmp_path):
    """fmusim (CS; ME with its CVode) runs every component from its defaults; the motor's run
    under constant inputs agrees with the closed form (CS_TOL in co-simulation, ME_TOL in model
    exchange)."""
    fmusim = fmusim_or_skip()
    path, _ = block_fmus[name, version]
    outputs = {"dc_motor": ("torque", "current", "omega_motor"), "pi_controller": ("voltage",),
               "speed_profile": ("setpoint",), "speed_sensor": ("measured",)}[name]
    starts = {"dc_motor": {"V": 60.0, "omega_load": 6.0}, "pi_controller": {"measured": 6.0},
              "speed_profile": {}, "speed_sensor": {"omega": 3.14159}}[name]
    run = _fmusim(fmusim, path, outputs, starts, tmp_path, 1e-10 if model_exchange else None)
    assert run.exit_code == 0 and run.values is not None, run.message
    assert np.all(np.isfinite(run.values)) and len(run.time) == 21
    if name == "dc_motor":
        A, B = motor_ab(**MOTOR)
        u = np.array([60.0, 6.0])
        want = np.array([motor_outputs(exact(A, B, np.zeros(3), u, t), u) for t in run.time])
        assert rel_error(run.values, want) <= (ME_TOL if model_exchange else CS_TOL)
    if name == "speed_sensor":
        assert np.all(run.values[:, 0] == 3.14)      # 0.01 rad/s resolution
    if name == "speed_profile":                      # the soft start: speed (1 - exp(-t / tau)), from 0
        want = 2 * np.pi * (1 - np.exp(-np.asarray(run.time) / 0.5))
        assert run.values[0, 0] == 0.0
        assert rel_error(run.values, want[:, None]) <= (ME_TOL if model_exchange else CS_TOL)


def _fmusim(fmusim, fmu, outputs, starts, workdir, me_tolerance):
    """fmusim with start values (fmi_hosts.run_fmusim's command, with --start-value)."""
    import subprocess
    out = workdir / "fmusim.csv"
    interface = ["cs"] if me_tolerance is None else ["me", "--solver", "cvode", "--tolerance", repr(me_tolerance)]
    command = [str(fmusim), "--interface-type", *interface, "--stop-time", "0.2", "--output-interval", "0.01"]
    for key, value in starts.items():
        command += ["--start-value", key, repr(value)]
    if me_tolerance is None:
        command += ["--start-value", "rtol", "1e-12", "--start-value", "atol", "1e-12"]
    for key in outputs:
        command += ["--output-variable", key]
    command += ["--output-file", str(out), str(fmu)]
    proc = subprocess.run(command, cwd=workdir, env={}, capture_output=True, text=True, timeout=600)  # hang guard
    if proc.returncode != 0 or not out.exists():
        return fmi_hosts.HostRun("fmusim", outputs, None, None, proc.returncode, 0.0, proc.stderr[-2000:])
    data = np.loadtxt(out, delimiter=",", skiprows=1, ndmin=2)
    return fmi_hosts.HostRun("fmusim", outputs, data[:, 0], data[:, 1:], proc.returncode, 0.0)


# -- closed form ------------------------------------------------------------------------------------

@pytest.mark.parametrize("version", (2, 3))
def test_the_motor_follows_the_closed_form_in_co_simulation(block_fmus, version):
    path, _ = block_fmus["dc_motor", version]
    A, B = motor_ab(**MOTOR)
    x0 = np.array([1.0, 50.0, 0.01])
    u = np.array([60.0, 6.0])
    inst = Instance(path, start=dict(i_start=x0[0], omega_m_start=x0[1], phi_start=x0[2], V=u[0], omega_load=u[1],
                                     rtol=1e-12, atol=1e-12))
    worst = 0.0
    for _ in range(50):
        inst.step(0.01)
        want = exact(A, B, x0, u, inst.t)
        worst = max(worst, rel_error(inst.get("i", "omega_m", "phi"), want),
                    rel_error(inst.get("torque", "current", "omega_motor"), motor_outputs(want, u)))
    inst.close()
    assert worst <= CS_TOL, worst


@pytest.mark.parametrize("version", (2, 3))
def test_the_motor_follows_the_closed_form_in_model_exchange(block_fmus, version):
    path, _ = block_fmus["dc_motor", version]
    A, B = motor_ab(**MOTOR)
    u = np.array([60.0, 6.0])
    result = simulate_fmu(str(path), fmi_type="ModelExchange", stop_time=0.5, output_interval=0.01,
                          relative_tolerance=1e-10, start_values={"V": u[0], "omega_load": u[1]},
                          output=["torque", "current", "omega_motor"])
    got = np.column_stack([result[n] for n in ("torque", "current", "omega_motor")])
    want = np.array([motor_outputs(exact(A, B, np.zeros(3), u, t), u) for t in result["time"]])
    assert rel_error(got, want) <= ME_TOL


def test_the_unsaturated_pi_follows_the_closed_form(block_fmus):
    """Inside its limits the PI is linear: d xi/dt = e (A = 0, B = (1, -1)), voltage = Kp e + Ki xi."""
    path, _ = block_fmus["pi_controller", 2]
    Kp, Ki = 10.0, 100.0
    setpoint, measured = 2 * math.pi, 2 * math.pi - 0.1
    for model_exchange in (False, True):
        if model_exchange:
            result = simulate_fmu(str(path), fmi_type="ModelExchange", stop_time=0.5, output_interval=0.01,
                                  relative_tolerance=1e-10, start_values={"measured": measured},
                                  output=["voltage"])
            t, got = result["time"], result["voltage"]
        else:
            inst = Instance(path, start=dict(measured=measured, rtol=1e-12, atol=1e-12))
            t, got = [], []
            for _ in range(50):
                inst.step(0.01)
                t.append(inst.t)
                got.append(inst.get("voltage")[0])
            inst.close()
        xi = np.array([exact(np.zeros((1, 1)), np.array([[1.0, -1.0]]), np.zeros(1),
                             np.array([setpoint, measured]), tk)[0] for tk in t])
        want = Kp * (setpoint - measured) + Ki * xi
        assert rel_error(got, want) <= (ME_TOL if model_exchange else CS_TOL)


# -- PI saturation and anti-windup ---------------------------------------------------------------

def _saturate_then_recover(path, K_aw):
    """Saturated for 2 s (measured 0, setpoint 2 pi), then measured above the setpoint: the
    voltage's values, the integral after saturation and the time to leave the limit."""
    inst = Instance(path, start=dict(measured=0.0, K_aw=K_aw))
    voltages, xi = [], []
    for _ in range(200):
        inst.step(0.01)
        voltages.append(inst.get("voltage")[0])
        xi.append(inst.get("xi")[0])
    inst.set(measured=2 * math.pi + 1.0)
    recovery = None
    for k in range(2000):
        if inst.get("voltage")[0] < 100.0:
            recovery = k * 0.01
            break
        inst.step(0.01)
    inst.close()
    return np.array(voltages), np.array(xi), recovery


def test_the_pi_output_is_clamped_and_back_calculation_stops_the_windup(block_fmus):
    """With K_aw = 0.1 the integral settles where Kp e + Ki xi = u_max + e / K_aw, i.e. xi = 1 rad
    (time constant 1 / (K_aw Ki) = 0.1 s): after 2 s it is there within 1e-6 (e^-20) and the
    controller leaves the limit as soon as the error changes sign; without anti-windup the
    integral grows as e t (12.6 rad after 2 s) and the voltage stays at the limit for
    (Ki xi - Kp - u_max) / Ki ~ 11.5 s."""
    path, _ = block_fmus["pi_controller", 2]
    voltages, xi, recovery = _saturate_then_recover(path, 0.1)
    assert np.max(voltages) == 100.0 and voltages[-1] == 100.0
    assert abs(xi[-1] - 1.0) <= 1e-6
    assert recovery is not None and recovery <= 0.01
    voltages0, xi0, recovery0 = _saturate_then_recover(path, 0.0)
    assert np.max(voltages0) == 100.0
    assert abs(xi0[-1] - 2 * math.pi * 2.0) <= 1e-6          # e t: the integral winds up
    assert recovery0 is not None and 11.0 <= recovery0 <= 12.0


# -- the sensor -------------------------------------------------------------------------------------

@pytest.mark.parametrize("version", (2, 3))
def test_the_sensor_quantises_with_gain_and_bias_exactly(block_fmus, version):
    """measured = resolution * round((gain omega + bias) / resolution), halves away from zero, to
    the last bit; read right after the input is set (direct feedthrough), before and after a step."""
    path, _ = block_fmus["speed_sensor", version]
    gain, bias, resolution = 1.5, 0.2, 0.05
    inst = Instance(path, start=dict(gain=gain, bias=bias, resolution=resolution))
    omegas = np.array([-7.3, -0.21, 0.0, 0.013, 1.0, 3.14159, 6.2831853, 12.345678])
    for omega in omegas:
        v = (gain * omega + bias) / resolution
        want = resolution * math.copysign(math.floor(abs(v) + 0.5), v)
        inst.set(omega=omega)
        assert inst.get("measured")[0] == want
        inst.step(0.001)
        assert inst.get("measured")[0] == want
    inst.close()


@pytest.mark.parametrize("version", (2, 3))
def test_the_sensor_at_resolution_zero_does_not_quantise(block_fmus, version):
    """resolution = 0 (docs/components.md): measured = gain omega + bias exactly (no division by
    zero, no NaN), set at the start or between steps; back on a grid when resolution is set again."""
    path, _ = block_fmus["speed_sensor", version]
    gain, bias = 1.5, 0.2
    inst = Instance(path, start=dict(gain=gain, bias=bias, resolution=0.0))
    for omega in (-7.3, 0.013, 3.14159, 12.345678):
        inst.set(omega=omega)
        assert inst.get("measured")[0] == gain * omega + bias
        inst.step(0.001)
        assert inst.get("measured")[0] == gain * omega + bias
    inst.set(resolution=0.05)
    inst.step(0.001)
    v = (gain * 12.345678 + bias) / 0.05
    assert inst.get("measured")[0] == 0.05 * math.copysign(math.floor(abs(v) + 0.5), v)
    inst.close()


def test_the_sensor_refuses_a_negative_resolution(block_fmus):
    """min = 0: a negative step set between steps is refused by the next step (as every
    parameter outside its range: fmu_src/native/block/block.c, check_parameters)."""
    from fmpy.fmi1 import FMICallException
    path, _ = block_fmus["speed_sensor", 2]
    inst = Instance(path)
    inst.set(resolution=-0.01)
    with pytest.raises(FMICallException):
        inst.step(0.001)
    inst.fmu.freeInstance()                 # after a failed step FMI allows no fmi2Terminate


# -- FMI behaviour ----------------------------------------------------------------------------------

def test_a_parameter_changed_mid_run_applies_from_the_next_step(block_fmus):
    path, _ = block_fmus["dc_motor", 2]
    u = np.array([60.0, 6.0])
    inst = Instance(path, start=dict(V=u[0], omega_load=u[1], rtol=1e-12, atol=1e-12))
    for _ in range(10):
        inst.step(0.01)
    x1 = exact(*motor_ab(**MOTOR), np.zeros(3), u, 0.1)
    inst.set(R=2.0)
    for _ in range(10):
        inst.step(0.01)
    want = exact(*motor_ab(**{**MOTOR, "R": 2.0}), x1, u, 0.1)
    got = inst.get("i", "omega_m", "phi")
    inst.close()
    assert rel_error(got, want) <= CS_TOL
    assert rel_error(got, exact(*motor_ab(**MOTOR), np.zeros(3), u, 0.2)) > 1e-3    # R = 1 would differ


@pytest.mark.parametrize("version", (2, 3))
def test_the_fmu_state_round_trips(block_fmus, version):
    """Get the state at 0.1 s, run on, set it back and run again: the same values, bit for bit;
    the same through its serialized bytes."""
    path, _ = block_fmus["dc_motor", version]
    inst = Instance(path, start=dict(V=60.0, omega_load=6.0))
    for _ in range(10):
        inst.step(0.01)
    f = inst.fmu
    state = f.getFMUState() if version == 3 else f.getFMUstate()
    serialize = f.serializeFMUState if version == 3 else f.serializeFMUstate
    deserialize = f.deserializeFMUState if version == 3 else f.deSerializeFMUstate
    restore = f.setFMUState if version == 3 else f.setFMUstate
    data = serialize(state)
    for _ in range(10):
        inst.step(0.01)
    first = inst.get("i", "omega_m", "phi", "torque")
    for recovered in (state, deserialize(data)):
        restore(recovered)
        inst.t = 0.1
        for _ in range(10):
            inst.step(0.01)
        assert np.array_equal(inst.get("i", "omega_m", "phi", "torque"), first)
    inst.close()


def test_input_derivatives_are_honoured(block_fmus):
    """A voltage ramp V = 60 + 200 t given as fmi2SetRealInputDerivatives (order 1) at each step
    follows the closed form with the ramp (held, the error is of the ramp's size)."""
    path, _ = block_fmus["dc_motor", 2]
    A, B = motor_ab(**MOTOR)
    inst = Instance(path, start=dict(V=60.0, omega_load=6.0, rtol=1e-12, atol=1e-12))
    vr = inst.vr["V"]
    for _ in range(20):
        inst.set(V=60.0 + 200.0 * inst.t)
        inst.fmu.setRealInputDerivatives([vr], [1], [200.0])
        inst.step(0.01)
    got = inst.get("i", "omega_m", "phi")
    inst.close()
    want = exact(A, B, np.zeros(3), np.array([60.0, 6.0]), 0.2, du=[200.0, 0.0])
    assert rel_error(got, want) <= CS_TOL
    held = exact(A, B, np.zeros(3), np.array([60.0, 6.0]), 0.2)
    assert rel_error(held, want) > 1e-2                   # the ramp matters: holding would fail


def test_directional_derivatives_are_the_physics_jacobians(block_fmus):
    """Model exchange: d der(x)/d (x, u) and d torque/d (x, u) at a point are A, B and the torque's
    coefficients, to round-off (1e-12 relative: the generated Jacobian is exact)."""
    from fmpy.fmi2 import FMU2Model
    path, _ = block_fmus["dc_motor", 2]
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Model(guid=md.guid, unzipDirectory=extract(str(path)), modelIdentifier=md.modelExchange.modelIdentifier,
                    instanceName="jac")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.enterContinuousTimeMode()
    import ctypes
    fmu.setContinuousStates((ctypes.c_double * 3)(2.0, 100.0, 0.02), 3)
    fmu.setReal([vr["V"], vr["omega_load"]], [55.0, 5.0])
    A, B = motor_ab(**MOTOR)
    knowns = ["i", "omega_m", "phi", "V", "omega_load"]
    unknowns = ["der(i)", "der(omega_m)", "der(phi)", "torque"]
    torque_row = [0.0, MOTOR["c_s"] / MOTOR["N"], MOTOR["k_s"], 0.0, -MOTOR["c_s"]]
    want = np.vstack([np.hstack([A, B]), torque_row])
    got = np.zeros_like(want)
    for j, known in enumerate(knowns):
        got[:, j] = fmu.getDirectionalDerivative([vr[n] for n in unknowns], [vr[known]], [1.0])
    fmu.terminate()
    fmu.freeInstance()
    assert np.allclose(got, want, rtol=1e-12, atol=0)


def test_the_model_structure_declares_direct_feedthrough(block_fmus):
    """A master reads direct feedthrough from <ModelStructure>: the PI's and the sensor's outputs
    depend on their inputs, the motor's torque on omega_load, its current on no input."""
    def inputs_of(component, output):
        md = read_model_description(str(block_fmus[component, 2][0]))
        unknown = next(u for u in md.outputs if u.variable.name == output)
        return sorted(v.name for v in unknown.dependencies if v.causality == "input")

    assert inputs_of("dc_motor", "torque") == ["omega_load"]
    assert inputs_of("dc_motor", "current") == []
    assert inputs_of("dc_motor", "omega_motor") == []
    assert inputs_of("pi_controller", "voltage") == ["measured", "setpoint"]
    assert inputs_of("speed_sensor", "measured") == ["omega"]

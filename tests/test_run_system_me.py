"""The monolithic master (``[master] algorithm = "monolithic"``, orchestrator/monolithic.py): a
system's components through Model Exchange, all their states integrated as one ODE by DOP853.

On tests/loop_system.py's current loop (motor, PI controller, sensor: linear, a closed-form
solution; components built once per session, about 6 s CPU): the reference follows the exact
solution, also across an event; Jacobi converges to it at first order as its step shrinks (so
the reference carries none of the co-simulation's coupling error).  On the bench (build/
MotorFourBar.ssp, skipped when it is not built) Jacobi at a small step agrees with it.  An
algebraic loop, inputs = "extrapolate" and the order are checked at validation.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from loop_system import COLUMNS, bench_order, exact, loop_ssp, outputs, run_system
from ssp_testing import TestComponent, write_ssp

from fourbar_common.contract.run_record import read_run_record

STOP = 0.2
BENCH = Path(__file__).resolve().parents[1] / "build" / "MotorFourBar.ssp"


@pytest.fixture(scope="module")
def loop(tmp_path_factory) -> Path:
    return loop_ssp(tmp_path_factory)


def scaled_error(rows: np.ndarray, expected: dict[str, np.ndarray]) -> float:
    """Largest difference of the columns from ``expected``, each relative to max(1, its largest |value|)."""
    return max(float(np.max(np.abs(rows[:, j + 1] - expected[c])) / max(1.0, np.max(np.abs(expected[c]))))
               for j, c in enumerate(COLUMNS))


def test_the_reference_follows_the_closed_form(loop, tmp_path):
    """DOP853 at the default relative tolerance 1e-10 (absolute 1e-12) over 0.2 s: within 1e-7 of
    each column's scale (measured 5e-10 A on the current and 2.4e-8 rad/s on the rotor's speed;
    the bound leaves room for the platform's libm and the step selection)."""
    rows = run_system(tmp_path, loop, "mono", step=0.002, stop=STOP, algorithm="monolithic")
    assert rows.shape == (101, 4)
    expected = outputs(exact(rows[:, 0]))
    assert np.max(np.abs(expected["motor.current"])) > 0.5           # it moved: the loop drove the current
    assert scaled_error(rows, expected) < 1e-7


def test_an_event_applies_between_macro_steps(loop, tmp_path):
    """The setpoint steps 1 -> 2 A at 0.1 s: the rows follow the closed form from 0.1 s on with the
    new setpoint (the integration restarts there), within the same 1e-7 of the scale."""
    event = '[[events]]\ntype = "step"\ntime = 0.1\nvariable = "controller.setpoint"\nvalue = 2.0\n'
    rows = run_system(tmp_path, loop, "event", step=0.002, stop=STOP, algorithm="monolithic", extra=event)
    k = 50                                    # the row at 0.1 s: before the change (docs/orchestrator.md)
    assert rows[k, 0] == pytest.approx(0.1)
    before = exact(rows[:k + 1, 0])
    after = exact(rows[k:, 0], z0=before[-1], setpoint=2.0)
    expected = {c: np.concatenate([outputs(before)[c], outputs(after, setpoint=2.0)[c][1:]]) for c in COLUMNS}
    assert scaled_error(rows, expected) < 1e-7
    assert rows[-1, 1] > 1.5                  # it followed the new setpoint


def test_jacobi_converges_to_the_reference_at_first_order(loop, tmp_path):
    """Jacobi's rows (held inputs) differ from the reference's by its coupling error, which is of
    first order in the step: dividing the step by 4 divides the difference by about 4 (bound 0.3
    leaves room for the higher-order terms; a reference with coupling error of its own, or a
    different model, would leave a floor and fail this).  Measured: 7.8e-3 A at 0.4 ms."""
    reference = run_system(tmp_path, loop, "ref", step=0.0004, stop=STOP, algorithm="monolithic")
    coarse = run_system(tmp_path, loop, "j4", step=0.0004, stop=STOP)
    fine = run_system(tmp_path, loop, "j1", step=0.0001, stop=STOP)[::4]
    assert np.allclose(fine[:, 0], reference[:, 0], rtol=0, atol=1e-12)
    e_coarse = float(np.max(np.abs(coarse[:, 1] - reference[:, 1])))
    e_fine = float(np.max(np.abs(fine[:, 1] - reference[:, 1])))
    assert 1e-4 < e_coarse < 0.05, e_coarse
    assert e_fine < 0.3 * e_coarse, (e_fine, e_coarse)


def test_run_json_records_the_monolithic_master(loop, tmp_path):
    run_system(tmp_path, loop, "rec", step=0.01, stop=0.05, algorithm="monolithic")
    record = read_run_record(tmp_path / "out_rec" / "run.json")
    assert record.status == "finished"
    assert record.system is not None and record.system.algorithm == "monolithic"
    assert record.system.order == ("motor", "sensor", "controller")     # the current feeds the sensor, ...


def _case(tmp_path: Path, ssp: Path, master: str) -> Path:
    case = tmp_path / "c.toml"
    case.write_text(f'name = "c"\nsystem = {json.dumps(str(ssp))}\n[experiment]\nstop = 0.1\nstep = 0.01\n'
                    f'[outputs]\nvariables = ["controller.voltage"]\n'
                    f"[master]\n{master}\n", encoding="utf-8")
    return case


def _refusal(tmp_path: Path, ssp: Path, master: str) -> str:
    from orchestrator.config import load_case
    from orchestrator.validation import ConfigError

    with pytest.raises(ConfigError) as caught:
        load_case(_case(tmp_path, ssp, master))
    return str(caught.value)


def test_a_true_algebraic_loop_is_refused_naming_it(loop, tmp_path):
    """controller.voltage -> sensor.omega and sensor.measured -> controller.measured: each output
    depends directly on the input the other feeds (both FMUs declare it), so no order reads every
    input before it is used."""
    with __import__("zipfile").ZipFile(loop) as z:
        fmus = {}
        for name in ("controller", "sensor"):
            fmus[name] = tmp_path / f"{name}.fmu"
            fmus[name].write_bytes(z.read(f"resources/{name}.fmu"))
    ssp = write_ssp(tmp_path / "Loop2.ssp", "Loop2",
                    [TestComponent("controller", fmus["controller"], inputs=("measured",), outputs=("voltage",)),
                     TestComponent("sensor", fmus["sensor"], inputs=("omega",), outputs=("measured",))],
                    [("controller.voltage", "sensor.omega"), ("sensor.measured", "controller.measured")])
    message = _refusal(tmp_path, ssp, 'algorithm = "monolithic"')
    assert "master.algorithm" in message and "algebraic loop" in message
    assert ("controller.voltage -> sensor.omega -> sensor.measured -> controller.measured -> controller.voltage"
            in message), message
    assert "e.g. order" not in message           # both FMUs declare their dependencies: no order to offer
    from orchestrator.config import load_case

    load_case(_case(tmp_path, ssp, 'algorithm = "jacobi"'))   # a co-simulation master takes it (a step's delay)


def test_extrapolated_inputs_are_refused_for_the_monolithic_master(loop, tmp_path):
    message = _refusal(tmp_path, loop, 'algorithm = "monolithic"\ninputs = "extrapolate"')
    assert "master.inputs" in message and "jacobi and gauss-seidel" in message


@pytest.mark.skipif(not BENCH.exists(), reason="the bench is not built (build_fmu.py --system motor_fourbar)")
def test_the_bench_agrees_with_jacobi_at_a_small_step(tmp_path):
    """The bench (its sensor's quantisation switched off: resolution 1e-12 rad/s, a discontinuity
    that an explicit integrator crosses only at great cost) over 0.2 s: Jacobi at 0.1 ms is within
    its first-order coupling error of the reference: measured 1.1e-3 rad/s on the crank's speed
    and 1.6e-3 A on the current (1.1e-2 and 1.6e-2 at 1 ms: first order); the bounds, 0.01 rad/s
    and 0.02 A, allow a factor 10 for a changed bench and are 20 times below the signals' range."""
    columns = ("fourbar.omega2", "motor.current")
    extra = bench_order(BENCH) + '[parameters]\n"sensor.resolution" = 1e-12\n'
    reference = run_system(tmp_path, BENCH, "bench_ref", step=0.001, stop=STOP, algorithm="monolithic",
                           columns=columns, extra=extra)
    jacobi = run_system(tmp_path, BENCH, "bench_j", step=0.0001, stop=STOP, columns=columns,
                        extra='[parameters]\n"sensor.resolution" = 1e-12\n')[::10]
    assert np.allclose(jacobi[:, 0], reference[:, 0], rtol=0, atol=1e-12)
    assert np.max(np.abs(jacobi[:, 1] - reference[:, 1])) < 0.01
    assert np.max(np.abs(jacobi[:, 2] - reference[:, 2])) < 0.02
    assert np.max(np.abs(reference[:, 1])) > 0.5                      # the crank turned


def test_a_wrong_order_from_the_case_fails_the_run_naming_it(loop, tmp_path):
    """The case vouches for [master] order; one that reads the controller before the sensor it
    depends on is caught at the first step (two evaluations at one point differ) instead of
    letting DOP853's steps collapse on a right-hand side that is not a function of the states
    (without the check this run crawled for over 10 minutes)."""
    from orchestrator import run_case

    case = _case(tmp_path, loop, 'algorithm = "monolithic"\norder = ["controller", "sensor", "motor"]')
    result = run_case(case, tmp_path / "out")
    assert result.status == "failed"
    assert "reads controller.voltage" in result.error and "before an input it depends on is set" in result.error

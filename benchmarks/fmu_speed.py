#!/usr/bin/env python3
"""Wall time of FourBar.fmu through FMPy against the pythonfmu/FMPy floor.

The floor is a trivial pythonfmu FMU built here with the same variables as FourBar
(same parameters, same 14 outputs) whose do_step only copies numbers: FMPy records
every output for both, so the ratio isolates the cost of FourBar's numerics.
Also reports right-hand-side evaluations per simulated second (counted by running the
FMU's own integrator, fmu_src/mechanism_model/dae.py, outside the FMU), and how much of the
time is scipy's own stepping: the same run replayed with the model's arithmetic replaced by
table look-ups (see ``in_process``).

``--quick`` is the smoke setting (tests/test_benchmarks_smoke.py): every run cut to
``QUICK_STOP`` s (Case 2's step at 10 s included), one round.  Its figures are not the benchmark's.

Usage: python benchmarks/fmu_speed.py [--fmu build/FourBar.fmu] [--repeat 5] [--quick]
"""
from __future__ import annotations

import argparse
import platform
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
#: The runs' length (s), and ``--quick``'s: still past Case 2's L2 step at 10 s.
STOP, QUICK_STOP = 100.0, 12.0
#: Communication step (s).
STEP = 0.01

FLOOR_SOURCE = textwrap.dedent('''
    from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, DefaultExperiment
    from pythonfmu.variables import Real, String

    PARAMS = {"L1": 3.0, "L2": 1.0, "L3": 4.0, "L4": 2.5, "m2": 1.0, "m3": 1.0, "m4": 1.0, "g": 9.81}
    FIXED = {"theta2_start": 0.5235987755982988, "omega2_start": 0.0, "rtol": 1e-9, "atol": 1e-6}
    OUTPUTS = ["x2", "y2", "x3", "y3", "x4", "y4", "theta2", "theta3", "theta4",
               "omega2", "omega3", "omega4", "energy", "constraint_residual"]

    class Floor(Fmi2Slave):
        default_experiment = DefaultExperiment(0.0, 100.0, 0.01, 1e-9)

        def __init__(self, **kwargs):
            super().__init__(**kwargs)
            for name, value in PARAMS.items():
                setattr(self, name, value)
                self.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                            variability=Fmi2Variability.tunable))
            for name, value in FIXED.items():
                setattr(self, name, value)
                self.register_variable(Real(name, causality=Fmi2Causality.parameter,
                                            variability=Fmi2Variability.fixed))
            self.integrator = "DOP853"
            self.register_variable(String("integrator", causality=Fmi2Causality.parameter,
                                          variability=Fmi2Variability.fixed))
            for name in OUTPUTS:
                setattr(self, name, 0.0)
                self.register_variable(Real(name, causality=Fmi2Causality.output,
                                            variability=Fmi2Variability.continuous))

        def do_step(self, current_time, step_size):
            self.x2 = current_time + step_size
            return True
''')


def build_floor(directory: Path) -> Path:
    script = directory / "floor_slave.py"
    script.write_text(FLOOR_SOURCE)
    subprocess.run([sys.executable, "-c",
                    "import sys; from pythonfmu.builder import FmuBuilder; "
                    "FmuBuilder.build_FMU(sys.argv[1], dest=sys.argv[2])", str(script), str(directory)],
                   check=True, cwd=directory, capture_output=True)
    return directory / "Floor.fmu"


def l2_step():
    return np.array([(0.0, 1.0), (10.0, 1.0), (10.0, 1.1)], dtype=[("time", float), ("L2", float)])


def time_run(fmu: Path, fault: bool, stop: float = STOP) -> tuple[float, float]:
    """(wall s, CPU s) of one ``stop`` s run through fmpy.simulate_fmu."""
    from fmpy import simulate_fmu
    t0, c0 = time.perf_counter(), time.process_time()
    simulate_fmu(str(fmu), stop_time=stop, output_interval=STEP, input=l2_step() if fault else None)
    return time.perf_counter() - t0, time.process_time() - c0


def _generated_equations():
    """The four-bar's generated equations module, as the FMU ships it."""
    from fmu_src.mechanism.check import prepare_mechanism
    return prepare_mechanism("fourbar").module


def _run_dae(cls, eq, fault: bool, stop: float = STOP):
    """Cases 1/2 through MechanismDAE.advance as the FMU's do_step calls it; returns (wall s, dae)."""
    from fmu_src.mechanism.check import start_state
    guess, rates, p = start_state(eq)
    dae = cls(eq, p, rtol=1e-9, atol=1e-6, t_bound=stop + 1.0)
    dae.assemble(0.0, guess, rates)
    dae.start()
    faulty = tuple(1.1 if name == "L2" else value for name, value in zip(eq.PARAMETERS, p))
    t0 = time.perf_counter()
    for k in range(1, round(stop / STEP) + 1):
        if fault and k == round(10.0 / STEP) + 1:
            dae.change_parameters(faulty)
        dae.advance(k * STEP)
        dae.outputs()
    return time.perf_counter() - t0, dae


class InProcess:
    """The FMU's integrator run in this process: the model, and scipy's share by replay.

    The model is run once recording every right-hand-side value; ``replay`` then runs
    the same communication steps with the right-hand side and the state recovery
    replaced by table look-ups.  scipy's DOP853 sees identical numbers, takes the identical
    step sequence (steps, rejections, dense output), so the replay's wall time is what the
    integrator and the stepping logic cost before any model arithmetic: a lower bound for
    this design whatever the model code costs.
    """

    def __init__(self, fault: bool, stop: float = STOP):
        from fmu_src.mechanism_model.dae import MechanismDAE
        self.fault, self.stop = fault, stop
        self.eq = _generated_equations()
        record: list = []
        self._record = record

        class Recording(MechanismDAE):
            def _rhs(self, t, y):
                value = super()._rhs(t, y)
                record.append(value)
                return value

        class Replay(MechanismDAE):
            def _rhs(self, t, y):
                return next(self.values)

            def _state(self, t, y):
                return self.q, self.qd

            def outputs(self):
                return []

            def _better_partition(self, q):
                return None

        self._model, self._replay = MechanismDAE, Replay
        _, dae = _run_dae(Recording, self.eq, fault, stop)
        self.rhs_evaluations = dae.rhs_evaluations

    def model(self) -> float:
        return _run_dae(self._model, self.eq, self.fault, self.stop)[0]

    def replay(self) -> float:
        self._replay.values = iter(self._record)
        return _run_dae(self._replay, self.eq, self.fault, self.stop)[0]


def main(argv=None) -> int:
    from orchestrator import install_pythonfmu_exit_guard
    install_pythonfmu_exit_guard()   # pythonfmu 0.7.0 can abort the process at exit otherwise
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fmu", default=str(REPO / "build" / "FourBar.fmu"))
    parser.add_argument("--repeat", type=int, default=None, help="rounds (default 5; 1 with --quick)")
    parser.add_argument("--quick", action="store_true",
                        help=f"the smoke setting: {QUICK_STOP:g} s runs, one round (not the benchmark's figures)")
    args = parser.parse_args(argv)
    stop = QUICK_STOP if args.quick else STOP
    repeat = args.repeat if args.repeat is not None else 1 if args.quick else 5
    from fmpy import simulate_fmu
    med = statistics.median
    with tempfile.TemporaryDirectory() as tmp:
        floor = build_floor(Path(tmp))
        fourbar = Path(args.fmu)
        for fmu in (floor, fourbar):                 # warm-up: imports, first load
            simulate_fmu(str(fmu), stop_time=1.0, output_interval=0.01)
        rows = []
        for case, fault in (("Case 1", False), ("Case 2", True)):
            # The runs alternate (floor, FourBar, model in-process, replay), so that a change
            # in the machine's speed during the benchmark hits all of them alike; ratios are
            # medians of the per-round ratios.  The floor gets the same FMPy input (the L2
            # step) as FourBar: FMPy's input handling costs time every step.
            ip = InProcess(fault, stop)
            rounds = []
            for _ in range(repeat):
                rounds.append((time_run(floor, fault, stop), time_run(fourbar, fault, stop), ip.model(), ip.replay()))
            rows.append((case, rounds, ip.rhs_evaluations))
    print(f"Machine: {platform.processor() or platform.machine()}, {platform.python_implementation()} "
          f"{platform.python_version()}, {__import__('os').cpu_count()} cores; median of {repeat} "
          "alternating rounds")
    print()
    print(f"| run ({stop:g} s, step {STEP:g} s, rtol 1e-9, atol 1e-6) | wall s | floor wall s | ratio (wall) "
          "| CPU s | floor CPU s | ratio (CPU) | RHS evals / sim s |")
    print("|---|---|---|---|---|---|---|---|")
    for case, rounds, rhs in rows:
        fw, fc = med(r[0][0] for r in rounds), med(r[0][1] for r in rounds)
        tw, tc = med(r[1][0] for r in rounds), med(r[1][1] for r in rounds)
        rw, rc = med(r[1][0] / r[0][0] for r in rounds), med(r[1][1] / r[0][1] for r in rounds)
        print(f"| FourBar {case} | {tw:.3f} | {fw:.3f} | {rw:.2f}x | {tc:.3f} | {fc:.3f} | {rc:.2f}x "
              f"| {rhs / stop:.0f} |")
    print()
    print(f"Where the time goes, in-process (the same {round(stop / STEP):,} steps through MechanismDAE.advance, without FMPy):")
    print()
    print("| run | model, wall s | of which scipy DOP853 + stepping logic (replay), wall s "
          "| floor + replay, ratio to floor |")
    print("|---|---|---|---|")
    for case, rounds, _ in rows:
        model, replay = med(r[2] for r in rounds), med(r[3] for r in rounds)
        bound = med((r[0][0] + r[3]) / r[0][0] for r in rounds)
        print(f"| FourBar {case} | {model:.3f} | {replay:.3f} | {bound:.2f}x |")
    print()
    print("The replay runs scipy's integrator on the recorded right-hand-side values, so it takes the "
          "identical steps with no model arithmetic: no model code can bring the ratio below the last column.")
    return 0


if __name__ == "__main__":
    sys.exit(main())

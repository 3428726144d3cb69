"""Case 2 of the paper under libcosim (via libcosimpy): L2 = 1.0 m -> 1.1 m at t = 10 s.

Runs build/FourBar.fmu for 0-100 s with a fixed 0.01 s step, changes the tunable
parameter L2 with an override manipulator once the execution has reached t = 10.00 s
(so the sample at 10.00 s still shows the old geometry and the one at 10.01 s the new,
exactly as FMPy's `simulate_fmu(..., input=...)` does), records x2, y2, x3, y3, x4, y4
with a time-series observer and writes them as CSV.

    .venv/bin/python examples/libcosim_case2.py [--fmu build/FourBar.fmu] [--out out/examples/case2_libcosim.csv]

libcosim steps the FMU in one of its worker threads; pythonfmu's binary takes the GIL of
this interpreter for every call, so nothing else is needed inside a Python process.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from libcosimpy.CosimEnums import CosimVariableType
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimManipulator import CosimManipulator
from libcosimpy.CosimObserver import CosimObserver
from libcosimpy.CosimSlave import CosimLocalSlave

OUTPUTS = ("x2", "y2", "x3", "y3", "x4", "y4")
NS = 1_000_000_000          # libcosim counts time in integer nanoseconds


def run_case2(fmu: str | Path, stop_time: float = 100.0, step: float = 0.01,
              change_time: float = 10.0, L2_new: float = 1.1,
              outputs=OUTPUTS) -> dict[str, np.ndarray]:
    """Simulate Case 2 with libcosim; return {'time': ..., name: ...} at every communication point."""
    step_ns = round(step * NS)
    n_total = round(stop_time * NS) // step_ns          # 10000 steps
    n_change = round(change_time * NS) // step_ns       # 1000 steps

    execution = CosimExecution.from_step_size(step_size=step_ns)
    slave = CosimLocalSlave(fmu_path=str(Path(fmu).resolve()), instance_name="fourbar")
    index = execution.add_local_slave(local_slave=slave)
    if index < 0:
        raise RuntimeError(f"libcosim could not load {fmu}")
    refs = {v.name.decode(): v.reference for v in execution.slave_variables(index)}

    observer = CosimObserver.create_time_series(buffer_size=n_total + 10)
    execution.add_observer(observer=observer)
    for name in outputs:
        observer.start_time_series(index, refs[name], CosimVariableType.REAL)
    manipulator = CosimManipulator.create_override()
    execution.add_manipulator(manipulator=manipulator)

    # Step to t = change_time, then override L2: libcosim applies it before the next doStep,
    # the one that starts at t = change_time.
    if not execution.step(n_change):
        raise RuntimeError("libcosim step failed before the L2 change")
    manipulator.slave_real_values(index, [refs["L2"]], [L2_new])
    if not execution.step(n_total - n_change):
        raise RuntimeError("libcosim step failed after the L2 change")
    if execution.status().current_time != n_total * step_ns:
        raise RuntimeError(f"execution stopped at {execution.status().current_time} ns")

    result = {}
    for name in outputs:
        # libcosimpy 0.0.6 trims the returned samples by counting zero step numbers, which
        # also drops one real sample when step 0 is included; read step 0 and steps 1..N apart.
        t0, s0, v0 = observer.time_series_real_samples(index, refs[name], from_step=0, sample_count=1 + n_total)
        t1, s1, v1 = observer.time_series_real_samples(index, refs[name], from_step=1, sample_count=n_total)
        steps = np.array(s0[:1] + s1)
        if not np.array_equal(steps, np.arange(n_total + 1)):
            raise RuntimeError(f"{name}: observer returned steps {steps[:3]}...{steps[-3:]}, expected 0..{n_total}")
        result["time"] = np.array(t0[:1] + t1, dtype=np.int64) / NS
        result[name] = np.array(v0[:1] + v1)
    return result


def main() -> None:
    from orchestrator import install_pythonfmu_exit_guard
    install_pythonfmu_exit_guard()   # pythonfmu 0.7.0 can abort the process at exit otherwise
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fmu", default=str(Path(__file__).resolve().parents[1] / "build" / "FourBar.fmu"))
    parser.add_argument("--out", default="out/examples/case2_libcosim.csv",
                        help="CSV file to write ('' for none; the default is under out/, which make clean removes)")
    args = parser.parse_args()

    log_output_level(CosimLogLevel.WARNING)   # libcosim logs every FMI call at the default level
    start = time.perf_counter()
    result = run_case2(args.fmu)
    elapsed = time.perf_counter() - start
    names = ["time", *OUTPUTS]
    print(f"libcosim: {len(result['time'])} samples, t = {result['time'][0]:g}..{result['time'][-1]:g} s, "
          f"{elapsed:.2f} s wall")
    for t in (9.99, 10.0, 10.01, 100.0):
        i = int(round(t / 0.01))
        print(f"  t = {result['time'][i]:6.2f} s  " + "  ".join(f"{n} = {result[n][i]: .6f}" for n in OUTPUTS))
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        np.savetxt(args.out, np.column_stack([result[n] for n in names]), delimiter=",",
                   header=",".join(names), comments="", fmt="%.17g")
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Orchestrator overhead: Case 2 through ``run_case`` (what ``fourbar-run`` calls) against
plain ``fmpy.simulate_fmu`` with the same settings, as a ratio of median wall times.

Both sides load the same FMU from its .fmu file, apply Table 1's start values, step
L2 1.0 -> 1.1 m at t = 10 s (simulate_fmu: as an input signal) and produce the six
outputs every 0.01 s over 0-100 s.  ``run_case`` also writes exchange.csv (flushed every
simulated second) and run.json; ``simulate_fmu`` keeps its result in memory.  Runs
alternate (orchestrator, FMPy, orchestrator, ...) in one process after one warm-up of
each, so drifting machine load hits both alike.  Target: ratio <= 1.2.

Usage: python benchmarks/orchestrator_overhead.py [--repeat 5] [--fmu build/FourBar.fmu]
Prints a markdown table on stdout.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
COLUMNS = ["x2", "y2", "x3", "y3", "x4", "y4"]
START_VALUES = {"L1": 3.0, "L2": 1.0, "L3": 4.0, "L4": 2.5, "m2": 1.0, "m3": 1.0, "m4": 1.0, "g": 9.81,
                "theta2_start": 0.5235987755982988, "omega2_start": 0.0, "rtol": 1e-9, "atol": 1e-6}


def main(argv=None) -> int:
    from orchestrator import install_pythonfmu_exit_guard
    install_pythonfmu_exit_guard()   # pythonfmu 0.7.0 can abort the process at exit otherwise
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=5, help="timed runs of each (default: %(default)s)")
    parser.add_argument("--fmu", default=str(REPO / "build" / "FourBar.fmu"), help="the FourBar FMU")
    args = parser.parse_args(argv)
    if args.repeat < 1:
        parser.error("--repeat must be >= 1")

    import dataclasses

    import numpy as np
    from fmpy import simulate_fmu

    from orchestrator import load_case, run_case

    fmu = Path(args.fmu).resolve()
    if not fmu.is_file():
        print(f"orchestrator_overhead.py: error: {fmu} not found; run `python build_fmu.py`", file=sys.stderr)
        return 2
    case = dataclasses.replace(load_case(REPO / "cases" / "case2_fault_L2.toml"), fmu=fmu)
    signal = np.array([(0.0, 1.0), (10.0, 1.0), (10.0, 1.1), (100.0, 1.1)], dtype=[("time", float), ("L2", float)])

    def plain() -> float:
        t0 = time.perf_counter()
        result = simulate_fmu(str(fmu), start_time=0.0, stop_time=100.0, output_interval=0.01,
                              relative_tolerance=1e-9, start_values=START_VALUES, input=signal, output=COLUMNS)
        elapsed = time.perf_counter() - t0
        assert len(result) == 10_001
        return elapsed

    with tempfile.TemporaryDirectory() as tmp:
        def orchestrated() -> tuple[float, float]:
            t0 = time.perf_counter()
            result = run_case(case, Path(tmp) / "case2")
            elapsed = time.perf_counter() - t0
            if not result.ok or result.rows_written != 10_001:
                raise RuntimeError(f"run_case failed: {result.error}")
            return elapsed, result.sim_wall_time_s

        orchestrated(), plain()                      # warm-up: imports, FMU's own imports, file cache
        ours, loops, theirs = [], [], []
        for _ in range(args.repeat):
            elapsed, loop = orchestrated()
            ours.append(elapsed)
            loops.append(loop)
            theirs.append(plain())

    med_ours, med_theirs = statistics.median(ours), statistics.median(theirs)
    pairwise = statistics.median(a / b for a, b in zip(ours, theirs))
    print(f"Case 2 (0-100 s, step 0.01 s, 10,001 rows), {args.repeat} alternating runs each, FMU {fmu.name}\n")
    print("| | median wall time [s] | min [s] | max [s] |")
    print("|---|---|---|---|")
    print(f"| `run_case` (fourbar-run), incl. exchange.csv + run.json | {med_ours:.3f} | {min(ours):.3f} | {max(ours):.3f} |")
    print(f"| of which the stepping loop (first row to last row) | {statistics.median(loops):.3f} | "
          f"{min(loops):.3f} | {max(loops):.3f} |")
    print(f"| `fmpy.simulate_fmu`, same settings, L2 step as input | {med_theirs:.3f} | {min(theirs):.3f} | "
          f"{max(theirs):.3f} |")
    print(f"\nratio of medians (orchestrator / FMPy): **{med_ours / med_theirs:.3f}** "
          f"(median of pairwise ratios {pairwise:.3f}; target <= 1.2)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

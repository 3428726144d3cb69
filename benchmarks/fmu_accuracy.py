#!/usr/bin/env python3
"""Accuracy of FourBar.fmu: position error against the independent theta2 formulation
(tests/reference_theta2.py, rtol = atol = 1e-12), energy drift and constraint residual,
for Cases 1 and 2 at Table 1's tolerances and at rtol = atol = 1e-12.

``--quick`` is the smoke setting (tests/test_benchmarks_smoke.py): ``QUICK_STOP`` s instead of
100 s (Case 2's step at 10 s included); its figures are not the benchmark's.

Usage: python benchmarks/fmu_accuracy.py [--fmu build/FourBar.fmu] [--quick]
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

CENTRES = ["x2", "y2", "x3", "y3", "x4", "y4"]
TABLE1 = dict(L1=3.0, L2=1.0, L3=4.0, L4=2.5, m2=1.0, m3=1.0, m4=1.0, g=9.81)
#: The runs' length (s), and ``--quick``'s: still past Case 2's L2 step at 10 s.
STOP, QUICK_STOP = 100.0, 12.0


def main(argv=None) -> int:
    from orchestrator import install_pythonfmu_exit_guard
    install_pythonfmu_exit_guard()   # pythonfmu 0.7.0 can abort the process at exit otherwise
    from fmpy import simulate_fmu
    from reference_theta2 import simulate as reference

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fmu", default=str(REPO / "build" / "FourBar.fmu"))
    parser.add_argument("--quick", action="store_true",
                        help=f"the smoke setting: {QUICK_STOP:g} s runs (not the benchmark's figures)")
    args = parser.parse_args(argv)
    stop = QUICK_STOP if args.quick else STOP
    times = np.round(np.arange(round(stop / 0.01) + 1) * 0.01, 10)
    th0 = math.radians(30)
    refs = {"Case 1": reference(times, th0, **TABLE1),
            "Case 2": reference(times, th0, switches=((10.0, {"L2": 1.1}),), **TABLE1)}
    step = np.array([(0.0, 1.0), (10.0, 1.0), (10.0, 1.1)], dtype=[("time", float), ("L2", float)])
    print("| case | FMU tolerances | max position error vs theta2 formulation (m) "
          "| energy drift, max-min (J) | max constraint residual |")
    print("|---|---|---|---|---|")
    for case in ("Case 1", "Case 2"):
        for label, tol in (("Table 1: rtol 1e-9, atol 1e-6", {"rtol": 1e-9, "atol": 1e-6}), ("rtol = atol = 1e-12", {"rtol": 1e-12, "atol": 1e-12})):
            r = simulate_fmu(args.fmu, stop_time=stop, output_interval=0.01, start_values=tol,
                             input=step if case == "Case 2" else None)
            err = np.abs(np.column_stack([r[n] for n in CENTRES]) - refs[case]).max()
            e = r["energy"]
            if case == "Case 2":      # energy is conserved on each side of the fault
                t = r["time"]
                drift = max(np.ptp(e[t <= 10 + 1e-9]), np.ptp(e[t > 10 + 1e-9]))
            else:
                drift = np.ptp(e)
            print(f"| {case} | {label} | {err:.2e} | {drift:.2e} | {r['constraint_residual'].max():.1e} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())

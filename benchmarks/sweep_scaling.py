#!/usr/bin/env python3
"""Sweep throughput: scenarios per minute with 1 and 2 Dask worker processes, and the ratio.

Each measurement runs the same N scenarios (L2 steps of N sizes at t = 10 s, no noise,
harmonic model, stop 20 s by default: one FMU run + one monitor replay each) into a fresh
output directory, so nothing is skipped.

``warm``  the cluster is started and every worker has already run one scenario (imports,
          first FMU load done) before the clock starts: the steady throughput of a long sweep.
          Repeated, with the worker counts interleaved (1, 2, 1, 2, ...), median reported;
``cold``  ``run_sweep(workers=n)`` from nothing: cluster start, imports in every worker, the
          scenarios, plots -- what a short sweep costs end to end.

Prints a markdown table (for docs/benchmarks.md).  ``--quick`` is the smoke setting
(tests/test_benchmarks_smoke.py): 2 scenarios, stop 12 s (the step at 10 s included), 1
worker, 1 warm measurement; its figures are not the benchmark's.

Usage: python benchmarks/sweep_scaling.py [--fmu build/FourBar.fmu] [--scenarios 24] [--stop 20]
       [--model harmonic] [--workers 1 2] [--repeat 3] [--quick]
"""
from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
FULL = {"scenarios": 24, "stop": 20.0, "workers": [1, 2], "repeat": 3}
#: ``--quick``: two scenarios (the task medians take more than one), one cluster, one warm run
QUICK = {"scenarios": 2, "stop": 12.0, "workers": [1], "repeat": 1}


def write_sweep(directory: Path, fmu: Path, n: int, stop: float, model: str, name: str) -> Path:
    case_text = (REPO / "cases" / "case1_normal.toml").read_text()
    case = directory / "case.toml"
    case.write_text(case_text.replace('fmu = "../build/FourBar.fmu"', f'fmu = "{fmu.resolve()}"'))
    # n distinct sizes from +0.2 % to +10 %, rounded so the ids are stable
    sizes = [round(0.002 * (50 ** (i / max(1, n - 1))), 6) for i in range(n)]
    path = directory / f"{name}.toml"
    path.write_text(f'name = "{name}"\ncase = "{case}"\nstop = {stop!r}\n'
                    f'[fault]\nvariable = "L2"\nrelative = {sizes!r}\ntime = 10.0\n'
                    f'[monitor]\nmodel = "{model}"\nthreshold = "auto"\n')
    return path


def cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


class ScenarioFailed(RuntimeError):
    """A scenario of the benchmark's sweep did not run: the figures would be meaningless."""


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--fmu", type=Path, default=REPO / "build" / "FourBar.fmu")
    parser.add_argument("--scenarios", type=int, help=f"default {FULL['scenarios']}")
    parser.add_argument("--stop", type=float, help=f"s, default {FULL['stop']:g}")
    parser.add_argument("--model", default="harmonic", choices=("harmonic", "prophet"))
    parser.add_argument("--workers", type=int, nargs="+", help=f"default {' '.join(map(str, FULL['workers']))}")
    parser.add_argument("--repeat", type=int,
                        help=f"warm measurements per worker count, interleaved (default {FULL['repeat']})")
    parser.add_argument("--quick", action="store_true",
                        help=f"smoke setting, not the benchmark: {QUICK['scenarios']} scenarios, stop "
                             f"{QUICK['stop']:g} s, workers {' '.join(map(str, QUICK['workers']))}, repeat "
                             f"{QUICK['repeat']} (options given explicitly still apply)")
    args = parser.parse_args(argv)
    for key, value in (QUICK if args.quick else FULL).items():
        if getattr(args, key) is None:
            setattr(args, key, value)
    if args.scenarios < 1 or args.repeat < 1 or min(args.workers) < 1:
        parser.error(f"--scenarios, --repeat and --workers must be at least 1, not {args.scenarios}, "
                     f"{args.repeat} and {' '.join(map(str, args.workers))}")
    if not args.stop > 10.0:
        parser.error(f"--stop must be after the step at 10 s, not {args.stop:g}")
    if not args.fmu.is_file():
        parser.error(f"--fmu {args.fmu}: no such file (build it first: python build_fmu.py)")
    try:
        run(args)
    except ScenarioFailed as exc:
        print(f"sweep_scaling: {exc}", file=sys.stderr)
        return 1
    return 0


def check(result, n: int, what: str) -> None:
    if result.ran != n or result.failed:
        raise ScenarioFailed(f"{what}: {result.ran} of {n} scenarios ran, {result.failed} failed:\n"
                             f"{result.table[['status', 'error']]}")


def run(args) -> None:
    import statistics
    from contextlib import ExitStack

    import dask
    from dask.distributed import Client, LocalCluster

    from sweep import load_sweep, run_sweep

    load0 = os.getloadavg()
    warm: dict[int, list[float]] = {n: [] for n in args.workers}
    task_wall: dict[int, list[float]] = {n: [] for n in args.workers}
    task_cpu: dict[int, list[float]] = {n: [] for n in args.workers}
    cold: dict[int, float] = {}
    with tempfile.TemporaryDirectory(prefix="sweep_scaling_") as tmp, ExitStack() as stack:
        tmp = Path(tmp)
        bench = load_sweep(write_sweep(tmp, args.fmu, args.scenarios, args.stop, args.model, "bench"))
        clients = {}
        for n in args.workers:
            # one cluster per worker count, each warmed up by one scenario per worker
            lc = stack.enter_context(LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                                  dashboard_address=None))
            clients[n] = stack.enter_context(Client(lc))
            warm_up = load_sweep(write_sweep(tmp, args.fmu, n, args.stop, args.model, f"warm{n}"))
            run_sweep(warm_up, tmp / f"warmup-{n}", client=clients[n])
        # interleaved (1, 2, 1, 2, ...) so a change of the machine's background load hits both
        for r in range(args.repeat):
            for n in args.workers:
                t0 = time.perf_counter()
                result = run_sweep(bench, tmp / f"warm-{n}-{r}", client=clients[n])
                warm[n].append(time.perf_counter() - t0)
                check(result, args.scenarios, f"warm run {r + 1} on {n} worker(s)")
                task_wall[n].extend(result.table["wall_seconds"])
                task_cpu[n].extend(result.table["cpu_seconds"])
        stack.close()
        for n in args.workers:
            # cold: everything, from no cluster to plots
            t0 = time.perf_counter()
            result = run_sweep(bench, tmp / f"cold-{n}", workers=n)
            cold[n] = time.perf_counter() - t0
            check(result, args.scenarios, f"cold run on {n} worker(s)")

    rate = {n: [60 * args.scenarios / w for w in warm[n]] for n in args.workers}
    base = args.workers[0]
    print(f"### Sweep throughput ({args.scenarios} scenarios: L2 step, stop {args.stop:g} s, "
          f"{args.model} model, auto threshold)\n")
    print(f"Machine: {cpu_name()}, {os.cpu_count()} logical CPUs; Python {platform.python_version()}, "
          f"dask {dask.__version__}.\n")
    print(f"| workers | warm: scenarios/min, median (min-max of {args.repeat}) | warm: speed-up | "
          "cold: scenarios/min | cold: speed-up | task wall (s), median | task CPU (s), median |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for n in args.workers:
        ratios = [a / b for a, b in zip(rate[n], rate[base])]
        print(f"| {n} | {statistics.median(rate[n]):.1f} ({min(rate[n]):.1f}-{max(rate[n]):.1f}) "
              f"| {statistics.median(ratios):.2f} | {60 * args.scenarios / cold[n]:.1f} "
              f"| {cold[base] / cold[n]:.2f} | {statistics.median(task_wall[n]):.2f} "
              f"| {statistics.median(task_cpu[n]):.2f} |")
    print("\nwarm: clusters started and used once before timing, runs of the two sizes interleaved; speed-up: "
          "median of the per-repeat ratios. cold: `run_sweep(workers=n)` from nothing (cluster start, imports, "
          "plots included), once. A task's CPU time below its wall time means its worker waited for a CPU.")
    load1 = os.getloadavg()
    print(f"\nLoad average (1 min) before / after: {load0[0]:.2f} / {load1[0]:.2f} "
          "(other processes on the machine lower the figures and the speed-up).")


if __name__ == "__main__":
    sys.exit(main())

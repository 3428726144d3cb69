#!/usr/bin/env python3
"""Run every benchmark and print (or write) docs/benchmarks.md.

Usage: python benchmarks/run_all.py [--write docs/benchmarks.md] [--only NAME ...]

Each section shows the command that produced it; run that command alone to reproduce one
table.  Timings depend on load: run on an otherwise idle machine.  With ``--only`` and
``--write`` the named sections are replaced in the existing file and the others kept.
"""
from __future__ import annotations

import argparse
import datetime as dt
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

SECTIONS = [
    ("fmu_speed", "FMU speed against the pythonfmu/FMPy floor (issue 2)", ["benchmarks/fmu_speed.py"]),
    ("native_fmu", "Native FMU against the pythonfmu FMU and the FMPy floor (issue 10)",
     ["benchmarks/native_fmu.py", "--sweep"]),
    ("native_forces", "Mechanisms with forces against the VanDerPol floor (issue 39)",
     ["benchmarks/native_fmu.py", "--forces"]),         # VanDerPol: FOURBAR_VANDERPOL, as for native_fmu
    ("fmu_accuracy", "FMU accuracy: independent formulation, energy, constraints (issue 2)",
     ["benchmarks/fmu_accuracy.py"]),
    ("orchestrator_overhead", "Orchestrator overhead against plain simulate_fmu (issue 3)",
     ["benchmarks/orchestrator_overhead.py"]),
    ("monitor_replay", "Monitor replay speed and detection against the paper (issue 4)",
     ["benchmarks/monitor_replay.py"]),
    ("sweep_scaling", "Sweep throughput on Dask, 1 and 2 workers (issue 6)", ["benchmarks/sweep_scaling.py"]),
    ("view_load", "Live view following an hour-long run at 100 Hz (issue 25)", ["benchmarks/view_load.py"]),
    ("startup", "Start-up time of the commands (issue 38)", ["benchmarks/startup.py"]),
    ("coupling_error", "Coupling error of the co-simulation masters on the bench (issue 40)",
     ["benchmarks/coupling_error.py"]),
]


def machine() -> str:
    try:
        model = next(line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo")
                     if line.startswith("model name"))
    except (OSError, StopIteration):
        model = platform.processor() or platform.machine()
    mem = ""
    try:
        kb = int(next(line.split()[1] for line in open("/proc/meminfo") if line.startswith("MemTotal")))
        mem = f", {kb / 2**20:.0f} GiB RAM"
    except (OSError, StopIteration):
        pass
    return (f"{model}, {os.cpu_count()} cores{mem}, {platform.system()} {platform.release()}, "
            f"CPython {platform.python_version()}")


def sections_of(text: str) -> dict[str, str]:
    """The sections of a report, by the titles in ``SECTIONS`` (title -> text up to the next
    such title; a script's own ``##`` headings stay inside its section)."""
    found = sorted((text.find(f"\n## {title}\n"), title) for _, title, _ in SECTIONS
                   if f"\n## {title}\n" in text)
    out: dict[str, str] = {}
    for (start, title), (end, _) in zip(found, found[1:] + [(len(text), "")]):
        out[title] = text[start + len(f"\n## {title}\n"):end].strip("\n")
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", metavar="PATH", help="also write the report to PATH")
    parser.add_argument("--only", nargs="*", choices=[s[0] for s in SECTIONS], help="run only these")
    args = parser.parse_args(argv)
    parts = [
        "# Benchmarks",
        "",
        f"Measured {dt.date.today().isoformat()} on: {machine()}.",
        "Produced by `python benchmarks/run_all.py --write docs/benchmarks.md` (`make benchmarks`); "
        "each section names the script that prints its table.",
        "",
    ]
    failed = False
    kept = {}
    if args.only and args.write and Path(args.write).exists():
        kept = sections_of(Path(args.write).read_text(encoding="utf-8"))
    for name, title, command in SECTIONS:
        if args.only and name not in args.only:
            if title in kept:
                parts += [f"## {title}", "", kept[title], ""]
            continue
        print(f"== {title}: python {' '.join(command)}", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, *command], cwd=REPO, capture_output=True, text=True)
        took = time.perf_counter() - t0
        parts += [f"## {title}", "", f"`python {' '.join(command)}` ({took:.0f} s)", ""]
        if proc.returncode != 0:
            failed = True
            parts += ["```", f"FAILED (exit {proc.returncode})", proc.stderr.strip()[-2000:], "```", ""]
        else:
            parts += [proc.stdout.strip(), ""]
    report = "\n".join(parts)
    print(report)
    if args.write:
        Path(args.write).write_text(report + "\n")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())

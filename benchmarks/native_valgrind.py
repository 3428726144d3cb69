#!/usr/bin/env python3
"""The native FMU's FMI layer under valgrind: the strict host's every call, memory-checked.

Compiles tests/native_host/fmi2_strict_host.c (every exported fmi2* function with a NULL
instance, NULL arguments and in every reachable state, plus a short run with a parameter
change and an FMU-state replay), runs it once with each case in its own process (a crash
would be a failed case), then once in one process under valgrind's memcheck, and prints:
cases and failed checks, valgrind's error count, invalid reads/writes/frees, bytes
"definitely lost" and the heap summary.

valgrind is not installed by default; without it this prints how to install it and exits 0
(nothing measured).  Exit status: 0 when everything holds or valgrind is absent, 1 when a
check or valgrind failed, 2 when the FMU or a C compiler is missing.

``--mechanism NAME`` checks that shipped mechanism's native FMU instead (built here into a
temporary folder; the host drives its L2, x2 and integrator, which every shipped one has).

Usage: python benchmarks/native_valgrind.py [--fmu build/FourBarNative.fmu | --mechanism slider_crank]
"""
from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))          # the host and its runner live with the tests
sys.path.insert(0, str(REPO))

from native_host.strict_host import compile_host, find_cc, run_host, unpack  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fmu", type=Path, default=REPO / "build" / "FourBarNative.fmu",
                        help="the native FMU (default: build/FourBarNative.fmu)")
    parser.add_argument("--mechanism", help="a shipped mechanism whose native FMU is built and checked instead")
    args = parser.parse_args(argv)
    valgrind = shutil.which("valgrind")
    if valgrind is None:
        print("valgrind not found: apt-get install valgrind")
        print("skipped: the native FMU's FMI layer was not checked under valgrind")
        return 0
    compiler = find_cc()
    if compiler is None:
        print("error: no C compiler (cc, gcc or clang) to build the strict host", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="native_valgrind_") as tmp:
        if args.mechanism:
            from fmu_src.mechanism.description import MechanismError, shipped_mechanisms
            if args.mechanism not in shipped_mechanisms():
                print(f"error: --mechanism {args.mechanism!r}: not shipped (the shipped ones: "
                      f"{', '.join(shipped_mechanisms())})", file=sys.stderr)
                return 2
            from fmu_src.native_build import build_native_fmu
            try:
                args.fmu = build_native_fmu(Path(tmp) / "native.fmu", mechanism=args.mechanism, validate=False).path
            except (MechanismError, RuntimeError) as exc:
                print(f"error: the native FMU of {args.mechanism} cannot be built: {exc}", file=sys.stderr)
                return 2
        if not args.fmu.is_file():
            print(f"error: {args.fmu}: no such FMU (build it with: python build_fmu.py)", file=sys.stderr)
            return 2
        exe = compile_host(Path(tmp), compiler)
        try:
            target = unpack(args.fmu, Path(tmp) / "fmu")
        except KeyError as exc:
            print(f"error: {args.fmu}: the strict host drives variables L2, x2 and integrator; it has no {exc}",
                  file=sys.stderr)
            return 2
        t0 = time.perf_counter()
        isolated = run_host(exe, target)
        t1 = time.perf_counter()
        checked = run_host(exe, target, valgrind=valgrind)
        t2 = time.perf_counter()
    report = checked.valgrind
    print(f"native FMU: {args.fmu} (GUID {target.guid})")
    print(f"strict host, one process per case: {isolated.cases} cases, {len(isolated.failures)} failed check(s), "
          f"exit {isolated.returncode}, {t1 - t0:.1f} s")
    print(f"strict host under valgrind (memcheck, one process): {checked.cases} cases, "
          f"{len(checked.failures)} failed check(s), exit {checked.returncode}, {t2 - t1:.1f} s")
    print(f"  valgrind: {report.errors} error(s), {report.invalid_accesses} invalid read/write/free, "
          f"{report.definitely_lost} bytes definitely lost; {report.heap_summary}")
    for run in (isolated, checked):
        if run.returncode < 0:
            print(f"  the host was killed by signal {-run.returncode} ({' '.join(run.command[:2])} ...)")
    for line in (*isolated.failures, *checked.failures):
        print("  " + line)
    ok = (isolated.returncode == 0 and checked.returncode == 0 and report.errors == 0
          and report.invalid_accesses == 0 and report.definitely_lost == 0)
    if not ok and checked.returncode not in (0, 1):
        print(checked.stderr[-3000:], file=sys.stderr)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

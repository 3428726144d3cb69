#!/usr/bin/env python3
"""The native FMU's FMI layers under valgrind: the strict hosts' every call, memory-checked.

FMI 2.0: compiles tests/native_host/fmi2_strict_host.c (every exported fmi2* function with a NULL
instance, NULL arguments and in every reachable state, plus a short run with a parameter change and
an FMU-state replay).  FMI 3.0: compiles tests/native_host/fmi3_strict_host.c (every fmi3* function
in every reachable state, with a NULL instance and NULL arguments, every variable kind in every
state, Case 2 and a model-exchange run against the FMI 2.0 twin bit for bit, FMU-state round trips,
fmi3Reset and fmi3FreeInstance in every state).  Each host runs once with each case in its own
process (a crash would be a failed case), then once in one process under valgrind's memcheck; this
prints cases and failed checks (FMI 3.0: the known deviations from the standard, reported, listed
apart), valgrind's error count, invalid reads/writes/frees, bytes "definitely lost" and the heap
summary.

valgrind is not installed by default; without it this prints how to install it and exits 0
(nothing measured).  Exit status: 0 when everything holds (FMI 3.0's known deviations aside) or
valgrind is absent, 1 when a check or valgrind failed, 2 when an FMU or a C compiler is missing.

``--mechanism NAME`` checks that shipped mechanism's native FMUs instead (built here into a
temporary folder; the hosts drive its L2, x2 and integrator, which every shipped one has);
``--mechanism all`` every shipped one.  ``--fmi 2`` or ``--fmi 3`` checks one layer only.
``--component NAME`` checks a shipped component's FMI 2.0 native FMU (fmu_src/components/NAME.toml,
built here; the host drives its first parameter that must not be negative, its first output and
its integrator; a component without states is skipped: the host needs one); ``--component all``
every shipped one.

Usage: python benchmarks/native_valgrind.py [--fmi 2|3] [--fmu build/FourBarNative.fmu]
           [--fmu3 build/FourBarNative3.fmu] [--mechanism slider_crank|all] [--component dc_motor|all]
"""
from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))          # the hosts and their runners live with the tests
sys.path.insert(0, str(REPO))

from native_host import strict_host, strict_host3  # noqa: E402


def _component_variables(name: str) -> tuple[str, str, str]:
    """The host's (tunable that -1 makes invalid, output, String) of a shipped component."""
    from fmu_src.block.description import load_block

    block = load_block(name)
    tunable = next(p.name for p in block.parameters if p.positive or (p.minimum is not None and p.minimum >= 0))
    return tunable, block.outputs[0].name, "integrator"


def _check_fmi2(fmu: Path, tmp: Path, compiler: str, valgrind: str,
                variables: tuple[str, str, str] | None = None) -> bool | None:
    """The FMI 2.0 host on ``fmu`` (driving ``variables``, default strict_host.VARIABLES): True when
    it all holds, False when not, None when it cannot run."""
    if not fmu.is_file():
        print(f"error: {fmu}: no such FMU (build it with: python build_fmu.py)", file=sys.stderr)
        return None
    exe = strict_host.compile_host(tmp, compiler)
    try:
        target = strict_host.unpack(fmu, tmp / "fmu2", variables or strict_host.VARIABLES)
    except KeyError as exc:
        print(f"error: {fmu}: the strict host drives variables L2, x2 and integrator; it has no {exc}",
              file=sys.stderr)
        return None
    t0 = time.perf_counter()
    isolated = strict_host.run_host(exe, target)
    t1 = time.perf_counter()
    checked = strict_host.run_host(exe, target, valgrind=valgrind)
    t2 = time.perf_counter()
    report = checked.valgrind
    print(f"native FMU: {fmu} (GUID {target.guid})")
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
    return ok


def _unexpected(run: strict_host3.HostRun) -> list[str]:
    return [f for case in run.cases if strict_host3.deviation_of(case.label) is None for f in case.failures]


def _check_fmi3(fmu: Path, twin: Path | None, tmp: Path, compiler: str, valgrind: str) -> bool | None:
    """The FMI 3.0 host on ``fmu`` (with its FMI 2.0 twin when there is one): True when everything but
    the known deviations holds, False when not, None when it cannot run."""
    if not fmu.is_file():
        print(f"error: {fmu}: no such FMU (build it with: python build_fmu.py --fmi 3)", file=sys.stderr)
        return None
    try:
        exe = strict_host3.compile_host(tmp, compiler)
    except strict_host3.HostBuildError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return None
    labels = strict_host3.list_cases(exe)
    try:
        target = strict_host3.unpack(fmu, tmp / "fmu3", twin if twin is not None and twin.is_file() else None)
    except KeyError as exc:
        print(f"error: {fmu}: the strict FMI 3.0 host drives variables L2 and x2; it has no {exc}", file=sys.stderr)
        return None
    except strict_host3.DescriptionError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return None
    t0 = time.perf_counter()
    isolated = strict_host3.run_host(exe, target)
    t1 = time.perf_counter()
    checked = strict_host3.run_host(exe, target, valgrind=valgrind)
    t2 = time.perf_counter()
    report = checked.valgrind
    print(f"FMI 3.0 native FMU: {fmu} (token {target.token})"
          + (f", against its FMI 2.0 twin {twin}" if target.twin else ", no FMI 2.0 twin (no bit-for-bit comparisons)"))
    for what, run, seconds in (("one process per case", isolated, t1 - t0),
                               ("under valgrind (memcheck, one process)", checked, t2 - t1)):
        known = sum(1 for case in run.cases if case.failures and strict_host3.deviation_of(case.label))
        print(f"strict FMI 3.0 host, {what}: {len(run.cases)} cases, {len(run.failures)} failed check(s) "
              f"({known} case(s) of known deviations, {len(_unexpected(run))} unexpected), "
              f"heap check {'on' if run.heap_checked else 'off (valgrind checks the heap)'}, exit {run.returncode}, "
              f"{seconds:.1f} s")
        if run.returncode < 0:
            print(f"  the host was killed by signal {-run.returncode} ({' '.join(run.command[:2])} ...)")
    print(f"  valgrind: {report.errors} error(s), {report.invalid_accesses} invalid read/write/free, "
          f"{report.definitely_lost} bytes definitely lost; {report.heap_summary}")
    counts = Counter(strict_host3.deviation_of(case.label).name for case in isolated.cases
                     if case.failures and strict_host3.deviation_of(case.label))
    for name, n in counts.items():
        print(f"  known deviation from FMI 3.0 (reported): {name}: {n} case(s)")
    for line in (*_unexpected(isolated), *_unexpected(checked)):
        print("  " + line)
    complete = all(len(run.cases) == len(labels) for run in (isolated, checked))
    if not complete:
        print(f"  the host ran {len(isolated.cases)} and {len(checked.cases)} of its {len(labels)} cases")
    ok = (complete and not _unexpected(isolated) and not _unexpected(checked)
          and isolated.returncode in (0, 1) and checked.returncode in (0, 1) and isolated.heap_checked
          and report.errors == 0 and report.invalid_accesses == 0 and report.definitely_lost == 0)
    if not ok and checked.returncode not in (0, 1):
        print(checked.stderr[-3000:], file=sys.stderr)
    return ok


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fmu", type=Path, default=REPO / "build" / "FourBarNative.fmu",
                        help="the FMI 2.0 native FMU (default: build/FourBarNative.fmu); the FMI 3.0 host's twin too")
    parser.add_argument("--fmu3", type=Path, default=REPO / "build" / "FourBarNative3.fmu",
                        help="the FMI 3.0 native FMU (default: build/FourBarNative3.fmu)")
    parser.add_argument("--mechanism", help="a shipped mechanism (or 'all') whose native FMUs are built and checked "
                                            "instead")
    parser.add_argument("--component", help="a shipped component (or 'all') whose FMI 2.0 native FMU is built and "
                                            "checked instead")
    parser.add_argument("--fmi", choices=("2", "3"), help="check the FMI 2.0 or the FMI 3.0 layer only (default both)")
    args = parser.parse_args(argv)
    valgrind = shutil.which("valgrind")
    if valgrind is None:
        print("valgrind not found: apt-get install valgrind")
        print("skipped: the native FMU's FMI layers were not checked under valgrind")
        return 0
    compiler = strict_host.find_cc()
    if compiler is None:
        print("error: no C compiler (cc, gcc or clang) to build the strict hosts", file=sys.stderr)
        return 2
    versions = (2, 3) if args.fmi is None else (int(args.fmi),)
    results = []
    with tempfile.TemporaryDirectory(prefix="native_valgrind_") as tmp:
        if args.component:
            return _components(args.component, Path(tmp), compiler, valgrind)
        if args.mechanism:
            from fmu_src.mechanism.description import MechanismError, shipped_mechanisms
            # "all": the machines; a published benchmark (seconds of runs) only when named
            names = shipped_mechanisms(benchmarks=False) if args.mechanism == "all" else (args.mechanism,)
            if any(name not in shipped_mechanisms() for name in names):
                print(f"error: --mechanism {args.mechanism!r}: not shipped (the shipped ones: "
                      f"{', '.join(shipped_mechanisms())}, or all)", file=sys.stderr)
                return 2
            from fmu_src.native_build import build_native_fmu
            pairs = []
            for name in names:
                folder = Path(tmp) / name
                try:
                    fmu2 = build_native_fmu(folder / "native.fmu", mechanism=name, validate=False).path
                    fmu3 = (build_native_fmu(folder / "native3.fmu", mechanism=name, validate=False, fmi_version=3).path
                            if 3 in versions else None)
                except (MechanismError, RuntimeError) as exc:
                    print(f"error: the native FMU of {name} cannot be built: {exc}", file=sys.stderr)
                    return 2
                pairs.append((name, fmu2, fmu3))
        else:
            pairs = [(None, args.fmu, args.fmu3)]
        for name, fmu2, fmu3 in pairs:
            if name:
                print(f"== {name}")
            work = Path(tmp) / f"work_{name or 'given'}"
            for version in versions:
                folder = work / f"fmi{version}"
                folder.mkdir(parents=True)
                results.append(_check_fmi2(fmu2, folder, compiler, valgrind) if version == 2
                               else _check_fmi3(fmu3, fmu2, folder, compiler, valgrind))
    if any(r is None for r in results):
        return 2
    return 0 if all(results) else 1


def _components(which: str, tmp: Path, compiler: str, valgrind: str) -> int:
    """--component: each named component's FMI 2.0 FMU under the strict host and valgrind."""
    from fmu_src.block.description import BlockError, load_block, shipped_components
    from fmu_src.block_build import build_block_fmu

    names = shipped_components() if which == "all" else (which,)
    if any(name not in shipped_components() for name in names):
        print(f"error: --component {which!r}: not shipped (the shipped ones: {', '.join(shipped_components())}, "
              f"or all)", file=sys.stderr)
        return 2
    results = []
    for name in names:
        print(f"== {name}")
        if not load_block(name).states:
            print("skipped: the strict FMI 2.0 host drives model exchange with 1 to 64 continuous states; this "
                  "component has none")
            continue
        folder = tmp / f"component_{name}"
        folder.mkdir()
        try:
            fmu = build_block_fmu(name, folder / "native.fmu", validate=False)
        except (BlockError, RuntimeError) as exc:
            print(f"error: the native FMU of {name} cannot be built: {exc}", file=sys.stderr)
            return 2
        work = folder / "fmi2"
        work.mkdir()
        results.append(_check_fmi2(fmu, work, compiler, valgrind, _component_variables(name)))
    if any(r is None for r in results):
        return 2
    return 0 if all(results) else 1


if __name__ == "__main__":
    sys.exit(main())

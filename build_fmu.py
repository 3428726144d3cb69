#!/usr/bin/env python3
"""Build a mechanism's FMUs from one sympy derivation and validate them with FMPy.

- build/<Name>.fmu        pythonfmu (the FMU of record; needs Python in the host)
- build/<Name>Native.fmu  the same equations printed as C and compiled (needs nothing), FMI 2.0
                          co-simulation and model exchange; built when a C compiler is found
- build/<Name>Native3.fmu the same C model behind the FMI 3.0 layer (co-simulation and model
                          exchange); built beside it (--fmi picks: 2, 3 or all)

The mechanism is a description file (docs/mechanisms.md): a name shipped in
fmu_src/mechanisms/ (default: fourbar, Table 1's linkage, giving FourBar.fmu) or a path.

A system of FMUs (docs/systems.md: a name in systems/ or a path) builds into one SSP 1.0 file,
build/<Name>.ssp, holding every component's native FMI 2.0 FMU.

A component (docs/components.md: a motor, a controller, a sensor) is a block file shipped in
fmu_src/components/ or a path: --component NAME|PATH builds build/<Name>Native.fmu and
build/<Name>Native3.fmu (native only; --out names the FMI 2.0 one).

Usage: python build_fmu.py [--mechanism NAME|PATH | --component NAME|PATH] [--only {pythonfmu,native}]
                           [--fmi {2,3,all}] [--out PATH] [--native-out PATH] [--native3-out PATH] [--force]
                           [--no-validate] [--list]
       python build_fmu.py --system NAME|PATH [--out PATH] [--force] [--no-validate]
"""
from __future__ import annotations

import argparse
import sys
import zipfile
from pathlib import Path

_EPILOG = """\
examples:
  python build_fmu.py                      # build/FourBar.fmu, FourBarNative.fmu and FourBarNative3.fmu (Table 1)
  python build_fmu.py --mechanism slider_crank      # build/SliderCrank.fmu and SliderCrankNative.fmu
  python build_fmu.py --mechanism my_machine.toml   # your own mechanism file (docs/mechanisms.md)
  python build_fmu.py --list               # the shipped mechanisms and systems
  python build_fmu.py --system motor_fourbar        # build/MotorFourBar.ssp (SSP 1.0, docs/systems.md)
  python build_fmu.py --system my_bench.toml        # your own system file
  python build_fmu.py --component dc_motor # build/DCMotorNative.fmu and DCMotorNative3.fmu (docs/components.md)
  python build_fmu.py --only native        # just the native FMUs (FMI 2.0 and 3.0)
  python build_fmu.py --only native --fmi 3 # just build/FourBarNative3.fmu (FMI 3.0)
  CC=clang python build_fmu.py             # choose the C compiler

--out, --native-out and --native3-out name files: an existing FMU there is replaced, any other existing
file only with --force, a directory never, nor a file in a folder this user cannot write in
(exit 2, nothing written).  The new FMU replaces the old one only once it is complete.
exit status: 0 built (and valid), 1 a build failed or fmpy validate found problems, 2 usage error
or a mistake in the mechanism or system file (the message names the item), 130 interrupted (Ctrl-C), 143 terminated (SIGTERM); an interrupted build leaves no partial file.
"""


def _is_fmu(path: Path) -> bool:
    """A zip archive with a modelDescription.xml (what this script would overwrite freely)."""
    try:
        with zipfile.ZipFile(path) as z:
            return "modelDescription.xml" in z.namelist()
    except (OSError, zipfile.BadZipFile):
        return False


def _destination_problem(option: str, value: str, force: bool, name: str = "FourBar") -> str | None:
    """Why ``value`` cannot be written as an FMU (a message naming ``option``), or None."""
    path = Path(value)
    if path.is_dir():
        example = path / {"--out": f"{name}.fmu", "--native3-out": f"{name}Native3.fmu"}.get(option, f"{name}Native.fmu")
        return f"{option} {value}: is a directory; expected the path of the .fmu file to write, e.g. {example}"
    if path.exists() and not force and not _is_fmu(path):
        return (f"{option} {value}: exists and is not an FMU (no zip with a modelDescription.xml); "
                f"not overwritten: choose another path, or add --force to replace it")
    parent = next((p for p in path.absolute().parents if p.exists()), None)
    if parent is not None and not parent.is_dir():
        return f"{option} {value}: {parent} is a file, not a directory"
    if parent is not None:
        reason = _cannot_write_in(parent)
        if reason:
            return f"{option} {value}: cannot write in {parent}: {reason}; choose a writable folder"
    return None


def _cannot_write_in(folder: Path) -> str | None:
    """Why no file can be created in ``folder`` (the OS's words), or None.  A real file is
    created and removed: permission bits alone do not say it (root ignores them, a
    read-only mount does not show in them)."""
    import os
    import secrets

    probe = folder / f".build_fmu-probe-{secrets.token_hex(6)}"
    try:
        os.close(os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
    except OSError as exc:
        return exc.strerror or str(exc)
    probe.unlink(missing_ok=True)
    return None


def _write_failure(dest: str, exc: OSError) -> str:
    """A file operation that failed during the build (disk full, the folder became read-only
    or a directory...): the OS's words and file, and that ``dest`` is as it was (the builds
    write a temporary file beside it, renamed over it only when complete, removed on failure)."""
    named = exc.filename2 or exc.filename       # a failed rename names the destination second
    where = f": {named}" if named else ""
    return f"{exc.strerror or exc}{where}; {dest} is unchanged and no temporary file was left"


def _report(label: str, path, guid: str, problems, validate: bool, extra: str = "") -> bool:
    print(f"built {label}: {path} (GUID {guid}){extra}")
    if not validate:
        print(f"  {label}: validation skipped")
        return True
    if problems:
        print(f"  {label}: fmpy validate: {len(problems)} problem(s):")
        for problem in problems:
            print(f"    - {problem}")
        return False
    print(f"  {label}: fmpy validate: no problems")
    return True


def main(argv=None) -> int:
    """The command; Ctrl-C or SIGTERM at any point (the imports of a build included) ends it with
    one line and the signal's exit status, no traceback and no partial FMU."""
    from fourbar_common.signals import StopSignals, exit_code, signal_of, stop_reason

    try:
        with StopSignals():
            return _main(argv)
    except KeyboardInterrupt as exc:
        signum = signal_of(exc)
        print(f"build_fmu.py: {stop_reason(signum)}; no partial FMU was left", file=sys.stderr)
        return exit_code(signum)


def _main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="build_fmu.py", epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Build a planar mechanism (default: Table 1's four-bar) as FMUs: <Name>.fmu (pythonfmu, "
                    "FMI 2.0 co-simulation), <Name>Native.fmu and <Name>Native3.fmu (generated C, no Python "
                    "needed; FMI 2.0 and FMI 3.0, co-simulation and model exchange each), then validate them "
                    "with FMPy.")
    parser.add_argument("--mechanism", metavar="NAME|PATH",
                        help="a mechanism shipped in fmu_src/mechanisms/ or the path of a mechanism file "
                             "(default: fourbar)")
    parser.add_argument("--system", metavar="NAME|PATH",
                        help="build a system of FMUs instead: a system shipped in systems/ or the path of a "
                             "system file (docs/systems.md), into build/<Name>.ssp (or --out)")
    parser.add_argument("--component", metavar="NAME|PATH",
                        help="build a component instead: a block file shipped in fmu_src/components/ or a path "
                             "(docs/components.md): build/<Name>Native.fmu and build/<Name>Native3.fmu (--out: the "
                             "FMI 2.0 one's path, the FMI 3.0 one beside it with 3 appended)")
    parser.add_argument("--list", action="store_true", help="list the shipped mechanisms and exit")
    parser.add_argument("--only", choices=("pythonfmu", "native"),
                        help="build just one of the two FMUs (default: both; native only if a C compiler exists)")
    parser.add_argument("--fmi", choices=("2", "3", "all"), default="all",
                        help="the FMI versions of the native FMU: 2 (<Name>Native.fmu), 3 (<Name>Native3.fmu) "
                             "or all (default: %(default)s; the pythonfmu FMU is FMI 2.0 only)")
    parser.add_argument("--out", help="where to write the pythonfmu FMU (default: build/<Name>.fmu); "
                                      "with --system, the .ssp (default: build/<Name>.ssp)")
    parser.add_argument("--native-out", help="where to write the FMI 2.0 native FMU (default: build/<Name>Native.fmu)")
    parser.add_argument("--native3-out",
                        help="where to write the FMI 3.0 native FMU (default: beside --native-out, its name with a 3 "
                             "appended, e.g. N.fmu -> N3.fmu; without --native-out build/<Name>Native3.fmu)")
    parser.add_argument("--force", action="store_true",
                        help="replace an existing --out/--native-out file even if it is not an FMU "
                             "(an existing FMU is always replaced; a directory never is)")
    parser.add_argument("--no-validate", dest="validate", action="store_false",
                        help="skip `fmpy validate` (not recommended)")
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    chosen = [f"--{name}" for name in ("mechanism", "component", "system") if getattr(args, name) is not None]
    if len(chosen) > 1:
        print(f"build_fmu.py: error: {' and '.join(chosen)} cannot be given together: one build at a time", file=sys.stderr)
        return 2
    if args.component is not None:
        return _component(args)
    from fmu_src.mechanism.description import MechanismError, load_mechanism, shipped_mechanisms

    if args.list:
        for name in shipped_mechanisms(systems=True):
            try:
                mech = load_mechanism(name)
                print(f"{name:16s} {mech.name}.fmu / {mech.name}Native.fmu / {mech.name}Native3.fmu: "
                      f"{mech.description}")
            except MechanismError as exc:
                print(f"{name:16s} (broken: {exc})")
        from fmu_src.system import SystemFileError, load_system, shipped_systems
        for name in shipped_systems():
            try:
                system = load_system(name)
                print(f"{name:16s} {system.name}.ssp (system): {system.description}")
            except SystemFileError as exc:
                print(f"{name:16s} (broken: {exc})")
        return 0
    if args.system is not None:
        return _system_main(args)
    args.mechanism = args.mechanism or "fourbar"
    try:
        mech = load_mechanism(args.mechanism)
    except MechanismError as exc:
        print(f"build_fmu.py: error: {exc}", file=sys.stderr)
        return 2
    args.out = args.out or f"build/{mech.name}.fmu"
    native_named = args.native_out is not None and not Path(args.native_out).is_dir()
    args.native_out = args.native_out or f"build/{mech.name}Native.fmu"
    # FMI 3.0's beside FMI 2.0's: next to --native-out when that is given (N.fmu -> N3.fmu)
    args.native3_out = args.native3_out or (str(Path(args.native_out).with_name(Path(args.native_out).stem + "3.fmu"))
                                            if native_named else f"build/{mech.name}Native3.fmu")
    args.fmi_versions = (2, 3) if args.fmi == "all" else (int(args.fmi),)
    targets = [("--out", args.out)] if args.only in (None, "pythonfmu") else []
    if args.only in (None, "native"):
        targets += [("--native-out", args.native_out)] if 2 in args.fmi_versions else []
        targets += [("--native3-out", args.native3_out)] if 3 in args.fmi_versions else []
    problems = [p for p in (_destination_problem(option, value, args.force, mech.name) for option, value in targets)
                if p]
    for problem in problems:
        print(f"build_fmu.py: error: {problem}", file=sys.stderr)
    if problems:
        return 2
    from fourbar_common.signals import StopSignals, exit_code, signal_of, stop_reason

    with StopSignals():
        try:
            return _build(args)
        except MechanismError as exc:
            print(f"build_fmu.py: error: {exc}", file=sys.stderr)
            return 2
        except KeyboardInterrupt as exc:   # Ctrl-C or SIGTERM: the builds remove their partial files
            signum = signal_of(exc)
            print(f"build_fmu.py: {stop_reason(signum)}; no partial FMU was left", file=sys.stderr)
            return exit_code(signum)


def _is_ssp(path: Path) -> bool:
    """A zip archive with a SystemStructure.ssd (what --system would overwrite freely)."""
    try:
        with zipfile.ZipFile(path) as z:
            return "SystemStructure.ssd" in z.namelist()
    except (OSError, zipfile.BadZipFile):
        return False


def _system_main(args) -> int:
    """--system: build the system's component FMUs and its .ssp (fmu_src/system/)."""
    from fourbar_common.signals import StopSignals, exit_code, signal_of, stop_reason
    from fmu_src.system import ComponentBuildError, SystemFileError, build_system, load_system

    unused = [option for option, value in (("--mechanism", args.mechanism), ("--only", args.only),
                                           ("--native-out", args.native_out), ("--native3-out", args.native3_out))
              if value is not None] + (["--fmi"] if args.fmi != "all" else [])
    if unused:
        print(f"build_fmu.py: error: --system builds an .ssp with each component's FMI 2.0 native FMU inside; "
              f"{', '.join(unused)} {'does' if len(unused) == 1 else 'do'} not apply to it", file=sys.stderr)
        return 2
    try:
        system = load_system(args.system)
    except SystemFileError as exc:
        print(f"build_fmu.py: error: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out or f"build/{system.name}.ssp")
    problem = None
    if out.is_dir():
        problem = f"--out {out}: is a directory; expected the path of the .ssp file to write, e.g. {out / (system.name + '.ssp')}"
    elif out.exists() and not args.force and not _is_ssp(out):
        problem = (f"--out {out}: exists and is not an SSP file (no zip with a SystemStructure.ssd); not "
                   f"overwritten: choose another path, or add --force to replace it")
    else:
        parent = next((p for p in out.absolute().parents if p.exists()), None)
        if parent is not None and not parent.is_dir():
            problem = f"--out {out}: {parent} is a file, not a directory"
        elif parent is not None and (reason := _cannot_write_in(parent)):
            problem = f"--out {out}: cannot write in {parent}: {reason}; choose a writable folder"
    if problem:
        print(f"build_fmu.py: error: {problem}", file=sys.stderr)
        return 2
    with StopSignals():
        try:
            result = build_system(args.system, out, validate=args.validate)
        except SystemFileError as exc:
            print(f"build_fmu.py: error: {exc}", file=sys.stderr)
            return 2
        except ComponentBuildError as exc:
            print(f"build_fmu.py: error: {exc}; {out} was not written", file=sys.stderr)
            return 1
        except OSError as exc:
            print(f"build_fmu.py: error: {_write_failure(str(out), exc)}", file=sys.stderr)
            return 1
        except KeyboardInterrupt as exc:
            signum = signal_of(exc)
            print(f"build_fmu.py: {stop_reason(signum)}; no partial file was left", file=sys.stderr)
            return exit_code(signum)
    if result.problems:
        print(f"build_fmu.py: error: SystemStructure.ssd does not follow the SSP 1.0 schema; {out} was not "
              f"written:", file=sys.stderr)
        for problem in result.problems:
            print(f"    - {problem}", file=sys.stderr)
        return 1
    print(f"built system: {result.path} (SSP 1.0)")
    for c in result.components:
        print(f"  {c.name}: {c.kind} {c.source} -> {c.resource} (GUID {c.guid})")
    print("  SystemStructure.ssd: " + ("SSP 1.0 schema: no problems" if args.validate else "validation skipped"))
    return 0


def _component(args) -> int:
    """build_fmu.py --component: a block file's native FMUs (FMI 2.0 and/or 3.0)."""
    from fmu_src.block.description import BlockError, load_block

    try:
        block = load_block(args.component)
    except BlockError as exc:
        print(f"build_fmu.py: error: {exc}", file=sys.stderr)
        return 2
    out2 = args.out or args.native_out or f"build/{block.name}Native.fmu"
    named = (args.out or args.native_out) is not None
    out3 = args.native3_out or (str(Path(out2).with_name(Path(out2).stem + "3.fmu")) if named
                                else f"build/{block.name}Native3.fmu")
    versions = (2, 3) if args.fmi == "all" else (int(args.fmi),)
    targets = [(2, "--out", out2), (3, "--native3-out", out3)]
    problems = [p for p in (_destination_problem(option, value, args.force, block.name)
                            for version, option, value in targets if version in versions) if p]
    for problem in problems:
        print(f"build_fmu.py: error: {problem}", file=sys.stderr)
    if problems:
        return 2
    from fmu_src.block_build import build_block_fmu_result
    from fmu_src.native_build import CompilerNotFound

    ok = True
    for version, _, dest in targets:
        if version not in versions:
            continue
        label = f"component FMU (FMI {version}.0)"
        try:
            result = build_block_fmu_result(block.source, Path(dest), fmi_version=version, validate=args.validate)
        except BlockError as exc:
            print(f"build_fmu.py: error: {exc}", file=sys.stderr)
            return 2
        except (CompilerNotFound, RuntimeError) as exc:
            print(f"build_fmu.py: error: {label}: {exc}", file=sys.stderr)
            return 1
        except OSError as exc:
            print(f"build_fmu.py: error: {label}: {_write_failure(dest, exc)}", file=sys.stderr)
            return 1
        ok &= _report(label, result.path, result.guid, result.problems, args.validate,
                      f", binaries: {', '.join(result.platforms)}")
    return 0 if ok else 1


def _build(args) -> int:
    ok = True
    if args.only in (None, "pythonfmu"):
        from fmu_src.build import build_fmu
        try:
            result = build_fmu(args.out, validate=args.validate, mechanism=args.mechanism)
        except RuntimeError as exc:
            print(f"build_fmu.py: error: pythonfmu FMU: {exc}", file=sys.stderr)
            return 1
        except OSError as exc:
            print(f"build_fmu.py: error: pythonfmu FMU: {_write_failure(args.out, exc)}", file=sys.stderr)
            return 1
        ok &= _report("pythonfmu FMU", result.path, result.guid, result.problems, args.validate)
    if args.only in (None, "native"):
        from fmu_src.native_build import CompilerNotFound, build_native_fmu
        for version in args.fmi_versions:
            label = "native FMU" if version == 2 else "native FMU (FMI 3.0)"
            dest = args.native_out if version == 2 else args.native3_out
            try:
                native = build_native_fmu(dest, validate=args.validate, mechanism=args.mechanism,
                                          fmi_version=version)
            except CompilerNotFound as exc:
                if args.only == "native":
                    print(f"build_fmu.py: error: {label}: {exc}", file=sys.stderr)
                    return 1
                print(f"native FMU not built: {exc}; then run `python build_fmu.py --only native`")
                return 0 if ok else 1
            except RuntimeError as exc:
                print(f"build_fmu.py: error: {label}: {exc}", file=sys.stderr)
                return 1
            except OSError as exc:
                print(f"build_fmu.py: error: {label}: {_write_failure(dest, exc)}", file=sys.stderr)
                return 1
            ok &= _report(label, native.path, native.guid, native.problems, args.validate,
                          f", binaries: {', '.join(native.platforms)}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

#!/usr/bin/env python3
"""Build the four-bar FMUs from one sympy derivation and validate them with FMPy.

- build/FourBar.fmu        pythonfmu (the FMU of record; needs Python in the host)
- build/FourBarNative.fmu  the same equations printed as C and compiled (needs nothing);
                           built when a C compiler is found

Usage: python build_fmu.py [--only {pythonfmu,native}] [--out PATH] [--native-out PATH] [--no-validate]
"""
from __future__ import annotations

import argparse
import sys

_EPILOG = """\
examples:
  python build_fmu.py                      # both FMUs (the native one when a C compiler exists)
  python build_fmu.py --only native        # just build/FourBarNative.fmu
  CC=clang python build_fmu.py             # choose the C compiler

exit status: 0 built (and valid), 1 a build failed or fmpy validate found problems, 2 usage error.
"""


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
    parser = argparse.ArgumentParser(
        prog="build_fmu.py", epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Build the four-bar linkage as FMI 2.0 co-simulation FMUs: FourBar.fmu (pythonfmu) and "
                    "FourBarNative.fmu (generated C, no Python needed), then validate them with FMPy.")
    parser.add_argument("--only", choices=("pythonfmu", "native"),
                        help="build just one of the two FMUs (default: both; native only if a C compiler exists)")
    parser.add_argument("--out", default="build/FourBar.fmu",
                        help="where to write the pythonfmu FMU (default: %(default)s)")
    parser.add_argument("--native-out", default="build/FourBarNative.fmu",
                        help="where to write the native FMU (default: %(default)s)")
    parser.add_argument("--no-validate", dest="validate", action="store_false",
                        help="skip `fmpy validate` (not recommended)")
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return int(exc.code or 0)

    ok = True
    if args.only in (None, "pythonfmu"):
        from fmu_src.build import build_fmu
        try:
            result = build_fmu(args.out, validate=args.validate)
        except (RuntimeError, OSError) as exc:
            print(f"build_fmu.py: error: pythonfmu FMU: {exc}", file=sys.stderr)
            return 1
        ok &= _report("pythonfmu FMU", result.path, result.guid, result.problems, args.validate)
    if args.only in (None, "native"):
        from fmu_src.native_build import CompilerNotFound, build_native_fmu
        try:
            native = build_native_fmu(args.native_out, validate=args.validate)
        except CompilerNotFound as exc:
            if args.only == "native":
                print(f"build_fmu.py: error: native FMU: {exc}", file=sys.stderr)
                return 1
            print(f"native FMU not built: {exc}; then run `python build_fmu.py --only native`")
            return 0 if ok else 1
        except (RuntimeError, OSError) as exc:
            print(f"build_fmu.py: error: native FMU: {exc}", file=sys.stderr)
            return 1
        ok &= _report("native FMU", native.path, native.guid, native.problems, args.validate,
                      f", binaries: {', '.join(native.platforms)}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

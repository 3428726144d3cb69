#!/usr/bin/env python3
"""Build build/FourBar.fmu: sympy derivation -> generated numpy code -> pythonfmu -> validation.

Usage: python build_fmu.py [--out build/FourBar.fmu] [--no-validate]
"""
from __future__ import annotations

import argparse
import sys


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="build_fmu.py",
        description="Build the four-bar linkage as an FMI 2.0 co-simulation FMU (pythonfmu) "
                    "and validate it with FMPy.")
    parser.add_argument("--out", default="build/FourBar.fmu", help="where to write the FMU (default: %(default)s)")
    parser.add_argument("--no-validate", dest="validate", action="store_false",
                        help="skip `fmpy validate` (not recommended)")
    args = parser.parse_args(argv)

    from fmu_src.build import build_fmu
    try:
        result = build_fmu(args.out, validate=args.validate)
    except (RuntimeError, OSError) as exc:
        print(f"build_fmu.py: error: {exc}", file=sys.stderr)
        return 1
    print(f"built {result.path} (GUID {result.guid})")
    if not args.validate:
        print("validation skipped")
        return 0
    if result.problems:
        print(f"fmpy validate: {len(result.problems)} problem(s):")
        for problem in result.problems:
            print(f"  - {problem}")
        return 1
    print("fmpy validate: no problems")
    return 0


if __name__ == "__main__":
    sys.exit(main())

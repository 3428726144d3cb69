#!/usr/bin/env python3
"""Every shipped mechanism's native FMU in every FMI flavour, against FMI 2.0 co-simulation.

For each shipped mechanism the native FMUs (FMI 2.0 and 3.0, each with co-simulation and model
exchange) are built afresh (``build_fmu.py --only native``, into a temporary folder), and every
flavour is run and compared with FMI 2.0 co-simulation as ``fmu_src/fmi_flavours.py`` says: the
hosts, the tolerances (``COSIM_TOL``, ``CVODE_RTOL``, ``FLAVOUR_AGREE``), the span and the table
live there, and the tests run the same comparisons (tests/test_fmu_fmi3.py,
tests/test_fmu_model_exchange.py); this script puts the measured figures in one table.

``--write FILE`` puts the table between the two marker lines of FILE (``BEGIN``/``END`` of
``fmu_src/fmi_flavours.py``; docs/fmi_hosts.md, "Every flavour in every host"); it needs an fmusim.

Usage: python benchmarks/fmi_flavours.py [--fmusim PATH] [--mechanism NAME ...] [--write docs/fmi_hosts.md]

Exit status: 0 every flavour agrees, 1 a build failed or a flavour disagrees (the table says
which), 2 usage error.
"""
from __future__ import annotations

import datetime as dt
import sys
import tempfile
from importlib import metadata
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
HERE = Path(__file__).resolve().parent
for _path in (REPO, HERE):
    if str(_path) not in sys.path:
        sys.path.insert(0, str(_path))

import fmi_hosts  # noqa: E402   (builds, fmusim, the marked sections)

from fmu_src.fmi_flavours import (BEGIN, COSIM_TOL, CVODE_RTOL, END, FLAVOUR_AGREE, FLAVOURS, Row,  # noqa: E402
                                  flavour_span, run_mechanism, table)


def run_benchmark(mechanisms: tuple[str, ...], fmusim: Path | None, progress=None) -> list[Row]:
    from fmu_src.mechanism.description import load_mechanism
    rows = []
    with tempfile.TemporaryDirectory(prefix="fmi_flavours_") as tmp:
        for mechanism in mechanisms:
            folder = Path(tmp) / mechanism
            folder.mkdir()
            name = load_mechanism(mechanism).name
            if progress:
                progress(f"{mechanism}: building {name}Native.fmu and {name}Native3.fmu")
            fmu2, problem = fmi_hosts.build_native(mechanism, folder / f"{name}Native.fmu")
            fmu3 = folder / f"{name}Native3.fmu"
            if fmu2 is None or not fmu3.exists():
                rows.append(Row(mechanism, flavour_span(mechanism), problem or "no FMI 3.0 FMU built", ()))
                continue
            if progress:
                progress(f"{mechanism}: running {len(FLAVOURS)} flavour(s)")
            span, cells = run_mechanism(mechanism, {2: fmu2, 3: fmu3}, fmusim, folder)
            rows.append(Row(mechanism, span, "", cells))
    return rows


def report(rows: list[Row], fmusim: Path | None, command: str) -> list[str]:
    from run_all import machine
    versions = [f"FMPy {metadata.version('fmpy')}", fmi_hosts.fmusim_version(fmusim) if fmusim else "no fmusim"]
    return [
        f"Measured {dt.date.today().isoformat()} on {machine()}; {', '.join(versions)}. Produced by `{command}`.",
        "",
        f"Largest |difference| over the lengths and angles (m or rad) from the FMI 2.0 co-simulation FMU run by "
        f"FMPy at rtol = atol = {COSIM_TOL:g}, on its 0.01 s grid. Co-simulation: the same start values; model "
        f"exchange: the host's CVode at relative tolerance {CVODE_RTOL:g}. Bound: {FLAVOUR_AGREE:g}. fmusim "
        "writes 16 significant digits, so its co-simulation cells cannot be below that rounding; a model-exchange "
        "cell is the host's CVode error.",
        "",
        *table(rows),
    ]


def main(argv=None) -> int:
    cli = fmi_hosts.command_line(argv, __doc__.splitlines()[0],
                                 "0 every flavour agrees, 1 a build failed or a flavour disagrees", "FMPy only",
                                 "fmusim's columns too", BEGIN, END)
    if cli.fmusim is None:
        print("no fmusim (--fmusim, $FMUSIM or PATH): FMPy's columns only", file=sys.stderr)
    rows = run_benchmark(cli.mechanisms, cli.fmusim, progress=lambda s: print(s, file=sys.stderr, flush=True))
    lines = report(rows, cli.fmusim, "python benchmarks/fmi_flavours.py --fmusim PATH --write docs/fmi_hosts.md")
    print("\n".join(lines))
    if cli.write:
        fmi_hosts.write_section(cli.write, lines, BEGIN, END)
        print(f"wrote the table into {cli.write}", file=sys.stderr)
    return 0 if all(r.ok for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())

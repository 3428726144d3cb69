#!/usr/bin/env python3
"""How long a mechanism file's injection or bomb takes to be refused (issue 36: <= 2 s each).

Every entry of tests/corpus/mechanism_expressions.toml is put into the crank's length and into
ground point O4's x of fmu_src/mechanisms/fourbar.toml (tests/corpus/mechanism_corpus.py) and
loaded with ``load_mechanism`` in this process, in an empty working directory; the time of each
load or refusal is measured (after one warm-up load: sympy's first use builds caches).
``--build`` also times ``build_fmu.py --mechanism FILE`` as a subprocess for a few entries
(the wall time a user waits and the child's CPU time, Python's start and imports included),
beside a file that does not exist and ``python -c "import sympy"`` for comparison.

Prints a table of the slowest entries, the maximum and the count over the target, and exits 1
if an entry is over the target, has the wrong outcome or leaves a file in the working
directory (the injections write ``canary*`` files if they run).

Usage:
  python benchmarks/untrusted_expressions.py [--build] [--all] [--target 2.0]
"""
from __future__ import annotations

import argparse
import os
import resource
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO), str(REPO / "tests")]

from corpus.mechanism_corpus import FIELDS, corpus, mechanism_file  # noqa: E402
from fmu_src.mechanism.description import MechanismError, load_mechanism  # noqa: E402

#: A hang guard per entry: an entry that takes this long is reported as a hang.
HANG_S = 60
#: The entries --build runs through build_fmu.py.
BUILD_TEXTS = ("__import__('os').system('id > canary_system') * 0 + L3", "10**10**10", "9**9**9**9",
               "exp(1000)", "(" * 100000 + "L2" + ")" * 100000)


class _Hang(Exception):
    pass


def _alarm(signum, frame):
    raise _Hang


def measure_load(text: str, field: str) -> tuple[str, float, bool]:
    """(outcome "load"/"refuse"/"hang"/"error: ...", seconds, whether a file appeared in the cwd)."""
    with tempfile.TemporaryDirectory() as folder:
        path = mechanism_file(Path(folder), text, field)
        work = Path(folder) / "work"
        work.mkdir()
        here = os.getcwd()
        os.chdir(work)
        signal.signal(signal.SIGALRM, _alarm)
        signal.alarm(HANG_S)
        start = time.perf_counter()
        try:
            load_mechanism(path)
            outcome = "load"
        except MechanismError:
            outcome = "refuse"
        except _Hang:
            outcome = "hang"
        except Exception as exc:          # noqa: BLE001  (reported: the test suite fails on it too)
            outcome = f"error: {type(exc).__name__}"
        finally:
            seconds = time.perf_counter() - start
            signal.alarm(0)
            os.chdir(here)
        return outcome, seconds, bool(os.listdir(work))


def _timed(command: list[str], cwd: Path) -> tuple[int, float, float]:
    """(exit code, wall seconds, CPU seconds of the child) of a command."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=600)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return proc.returncode, wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def measure_build(text: str | None) -> tuple[int, float, float, bool]:
    """(exit code, wall s, CPU s, whether a file appeared) of build_fmu.py on the entry (crank
    length); ``None``: a file that does not exist (the refusal that needs no expression)."""
    with tempfile.TemporaryDirectory() as folder:
        path = mechanism_file(Path(folder), text) if text is not None else Path(folder) / "missing.toml"
        work = Path(folder) / "work"
        work.mkdir()
        code, wall, cpu = _timed([sys.executable, str(REPO / "build_fmu.py"), "--mechanism", str(path), "--only",
                                  "pythonfmu", "--out", str(Path(folder) / "X.fmu"), "--no-validate"], work)
        return code, wall, cpu, bool(os.listdir(work))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--build", action="store_true", help="also time build_fmu.py on a few entries")
    parser.add_argument("--all", action="store_true", help="print every entry, not only the 10 slowest")
    parser.add_argument("--target", type=float, default=2.0, help="seconds an entry may take (default 2.0)")
    args = parser.parse_args(argv)

    measure_load("L2", "length")                     # warm-up: sympy's caches
    cases = corpus()
    rows = []
    for case in cases:
        for field in FIELDS:
            outcome, seconds, leaked = measure_load(case.text, field)
            rows.append((case, field, outcome, seconds, leaked))
    bad = [r for r in rows if r[2] != r[0].expect or r[4] or r[3] > args.target]
    shown = sorted(rows, key=lambda r: -r[3]) if not args.all else rows
    print(f"{'entry':48s} {'field':7s} {'outcome':8s} {'ms':>9s}")
    for case, field, outcome, seconds, leaked in shown[: None if args.all else 10]:
        print(f"{case.label[:48]:48s} {field:7s} {outcome:8s} {seconds * 1e3:9.2f}{'  FILE WRITTEN' if leaked else ''}")
    loads = [r for r in rows if r[2] == "load"]
    refusals = [r for r in rows if r[2] == "refuse"]
    print(f"\n{len(cases)} entries x {len(FIELDS)} fields = {len(rows)} loads: {len(loads)} loaded, "
          f"{len(refusals)} refused, {sum(r[4] for r in rows)} with a side effect, "
          f"{sum(r[2] != r[0].expect for r in rows)} with an unexpected outcome")
    worst = max(rows, key=lambda r: r[3])
    print(f"maximum {worst[3] * 1e3:.1f} ms ({worst[0].label}, {worst[1]}); "
          f"median {sorted(r[3] for r in rows)[len(rows) // 2] * 1e3:.2f} ms; "
          f"{sum(r[3] > args.target for r in rows)} over {args.target:g} s")
    if args.build:
        print(f"\n{'build_fmu.py --mechanism FILE; crank length':52s} {'exit':>4s} {'wall s':>7s} {'CPU s':>6s}")
        for text in (None,) + BUILD_TEXTS:
            code, wall, cpu, leaked = measure_build(text)
            label = "(no such file: the refusal without expressions)" if text is None else repr(text[:48])
            print(f"{label:52s} {code:4d} {wall:7.2f} {cpu:6.2f}{'  FILE WRITTEN' if leaked else ''}")
            if code != 2 or leaked:
                bad.append(text)
        code, wall, cpu = _timed([sys.executable, "-c", "import sympy"], REPO)
        label = 'python -c "import sympy" (for comparison)'
        print(f"{label:52s} {code:4d} {wall:7.2f} {cpu:6.2f}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())

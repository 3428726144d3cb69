#!/usr/bin/env python3
"""Fuzzing the input files: what the real CLIs do with case, mechanism, sweep and exchange files
that a clumsy user, a damaged disk or an attacker could hand them (issue 36, item 7).

Families (``--families``, default all):

``case``       case files (``cases/*.toml``): run by ``fourbar-run --fmu build/FourBarNative.fmu
               CASE --stop 12 --realtime 0 --out TMP --quiet`` (the corpus entries that are about
               the run's length keep their own stop);
``mechanism``  mechanism files (``fmu_src/mechanisms/*.toml``): built by ``build_fmu.py --mechanism
               FILE --only pythonfmu --no-validate --out TMP/M.fmu`` (the cheapest command that
               loads, checks and derives a mechanism: no C compiler, no FMPy validation);
``sweep``      sweep files (``sweeps/*.toml``, their base case and FMU made absolute): checked by
               ``fourbar-sweep SWEEP --dry-run --out TMP``;
``exchange``   run folders (exchange.csv, run.json, monitor/summary.json) copied from one real
               16 s run of case 2 on the native FMU and then damaged: each folder is replayed by
               ``fourbar-monitor EXCHANGE --model harmonic --no-plots --quiet --out TMP`` and
               diagnosed by ``fourbar-diagnose RUN --no-plot --quiet --out TMP``.

Inputs of each family, in this order: the fixed corpus (the files of issue 36's probe:
injections and bombs in mechanism expressions, the stuck cases, the gap, jump, FIFO and
nested-JSON exchange folders, and more; every one of them, whatever ``--examples``); then
``--examples`` mutations of the shipped files (seeded byte and line edits: truncation, deleted,
doubled and swapped lines, NUL and garbage bytes, numbers and strings replaced by extreme ones);
then ``--examples`` hypothesis-generated edits of the parsed files (a key set to a drawn value
of any TOML type, nested arrays and tables included, or deleted, or an unknown key added;
exchange rows and cells replaced by drawn values).  The same ``--seed`` gives the same inputs.

Each program run is one outcome:

``ok``          an exit status the program documents for a run it could do (fourbar-run 0/1,
                fourbar-monitor 0/1/3/5, fourbar-diagnose 0/1/4, fourbar-sweep 0/1,
                build_fmu.py 0/1) and no traceback;
``refused``     exit 2 with a message on stderr that is not a traceback;
``silent``      exit 2 with nothing on stderr;
``wrong_verdict`` an exit status the corpus entry rules out: fourbar-monitor's 0 ("no alarm") on
                the gap and jump files (issue 36: the grid is not what run.json says, so "no
                alarm" cannot be known);
``traceback``   "Traceback (most recent call last)" on stderr, or an exit status the program does
                not document;
``hang``        still running after ``--timeout`` s (default 60 s; the process group is killed).
                There is no documented pacing here: fourbar-run gets ``--realtime 0`` (the file's
                realtime_factor is overridden) and the monitor replays (no ``--follow``);
``crash``       ended by a signal (SIGSEGV, SIGABRT, or SIGKILL by the memory limit);
``side_effect`` the program ran code from the file: the corpus's injections would create a file
                named ``PWNED`` in the input's folder, which is checked after every run.

Each child runs in its own process group with its address space limited to ``--memory`` GiB
(default 4; a bomb then fails with MemoryError, a traceback, instead of taking the machine).
Every failing input (silent, traceback, hang, crash, side_effect) is kept under ``--keep``
(default out/benchmarks/fuzz_inputs/failing/<family>/<input>/) with the command, its exit,
and its stderr, so it can be run again by hand.

``--write FILE`` puts the figures between the marker lines of FILE (``BEGIN``/``END`` below;
docs/robustness.md, "Fuzzed input files"), with benchmarks/fmi_hosts.py's ``write_section``.

For a small sample (tests/test_fuzz_inputs.py runs one, as a program): ``--fmu`` names the
native FMU, ``--family-examples`` sets ``--examples`` per family, ``--only`` keeps some of the
drawn inputs, ``--jobs`` runs inputs side by side, ``--json`` writes every outcome;
``--list`` prints the drawn inputs (name, SHA-256 of their files) and runs nothing;
``--probe CODE`` classifies one ``python -c CODE`` run as a program run on an input (a check
of the classifier) and prints its outcome as JSON.

Usage:
  python benchmarks/fuzz_inputs.py [--examples N] [--seed S] [--timeout S] [--memory GIB]
                                   [--families case,mechanism,sweep,exchange] [--keep DIR]
                                   [--write docs/robustness.md]
                                   [--fmu FMU] [--family-examples FAMILY=N,...] [--only FAMILY/NAME,...]
                                   [--jobs N] [--json FILE] [--list | --probe CODE]

Exit status: 0 no failing outcome, 1 some input failed (listed), 2 usage error.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import random
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(HERE))

from fmi_hosts import markers_problem, write_section  # noqa: E402

__all__ = ["FAMILIES", "FuzzInput", "Outcome", "Special", "KINDS", "FAILURES", "Program", "PROGRAMS",
           "corpus", "mutations", "generated", "inputs", "exchange_base", "run_input", "main"]

BIN = Path(sys.executable).parent
NATIVE = REPO / "build" / "FourBarNative.fmu"
FAMILIES = ("case", "mechanism", "sweep", "exchange")
#: Every outcome kind, and those that count as failures.
KINDS = ("ok", "refused", "silent", "wrong_verdict", "traceback", "hang", "crash", "side_effect")
FAILURES = ("silent", "wrong_verdict", "traceback", "hang", "crash", "side_effect")
TRACEBACK = "Traceback (most recent call last)"
#: The file the corpus's code injections try to create in the input's folder (the child's cwd).
SIDE_EFFECT = "PWNED"
SEED = 36
STOP = 12.0                 # s: fourbar-run's --stop for fuzzed cases (past case 2's fault at 10 s)
EXCHANGE_STOP = 16.0        # s: the real run behind the exchange family (the fault at 10 s alarms)
TIMEOUT = 60.0              # s per program run
MEMORY_GIB = 4.0            # address-space limit of each child
KEEP = REPO / "out" / "benchmarks" / "fuzz_inputs" / "failing"
BEGIN = "<!-- BEGIN generated by benchmarks/fuzz_inputs.py: do not edit by hand -->"
END = "<!-- END generated by benchmarks/fuzz_inputs.py -->"


class Special(str):
    """A file-system object that is not a regular file with contents (``FIFO``, ``DIR`` or a
    symlink ``LINK:target``)."""


FIFO = Special("FIFO")
DIR = Special("DIR")


@dataclass(frozen=True)
class FuzzInput:
    """One input: its family, a name unique in the family, where it came from ("corpus",
    "mutation", "hypothesis"), its files (path in the input's folder -> bytes or a
    :class:`Special`) and the file the command is given."""

    family: str
    name: str
    origin: str
    files: tuple[tuple[str, bytes | Special], ...]
    what: str = ""                           # one line: what was done to the file
    extra_args: tuple[str, ...] | None = None  # replaces the family's default extra arguments
    fmu_flag: bool = True                    # case family: pass --fmu (False: the file's own fmu is the test)
    #: Exit statuses that are a wrong verdict for this input, by program (issue 36: a replay of a file
    #: with a gap or a jump must never end "0, no alarm")
    wrong_exits: tuple[tuple[str, tuple[int, ...]], ...] = ()


@dataclass(frozen=True)
class Program:
    """A CLI run on an input: its name, the exit statuses it documents for a run it could do."""

    name: str
    ok_exits: tuple[int, ...]
    argv: Callable[[Path, Path, FuzzInput], list[str]]   # (input folder, output folder, input) -> argv


@dataclass(frozen=True)
class Outcome:
    """What one program did with one input."""

    input: FuzzInput
    program: str
    kind: str
    exit: int | None          # None: killed at the timeout
    seconds: float
    stderr: str
    argv: tuple[str, ...]

    @property
    def failed(self) -> bool:
        return self.kind in FAILURES


# -- the programs -------------------------------------------------------------------------------

def _case_argv(folder: Path, out: Path, item: FuzzInput) -> list[str]:
    extra = ["--stop", repr(STOP)] if item.extra_args is None else list(item.extra_args)
    fmu = ["--fmu", str(NATIVE)] if item.fmu_flag else []
    return [str(BIN / "fourbar-run"), *fmu, str(folder / "case.toml"), *extra,
            "--realtime", "0", "--out", str(out / "run"), "--quiet"]


def _mechanism_argv(folder: Path, out: Path, item: FuzzInput) -> list[str]:
    return [sys.executable, str(REPO / "build_fmu.py"), "--mechanism", str(folder / "mechanism.toml"),
            "--only", "pythonfmu", "--no-validate", "--out", str(out / "M.fmu")]


def _sweep_argv(folder: Path, out: Path, item: FuzzInput) -> list[str]:
    return [str(BIN / "fourbar-sweep"), str(folder / "sweep.toml"), "--dry-run", "--out", str(out / "sweep")]


def _monitor_argv(folder: Path, out: Path, item: FuzzInput) -> list[str]:
    return [str(BIN / "fourbar-monitor"), str(folder / "run" / "exchange.csv"), "--model", "harmonic",
            "--no-plots", "--quiet", "--out", str(out / "monitor")]


def _diagnose_argv(folder: Path, out: Path, item: FuzzInput) -> list[str]:
    return [str(BIN / "fourbar-diagnose"), str(folder / "run"), "--no-plot", "--quiet", "--out",
            str(out / "diagnosis")]


#: Exit statuses from each CLI's --help ("exit status: ..."); 2 is a refusal, 130/143 are signals
#: (never sent here).  fourbar-monitor's 5 is the "indeterminate" verdict (a grid the monitor
#: cannot trust) that issue 36 adds; it is accepted before it exists.
PROGRAMS: dict[str, tuple[Program, ...]] = {
    "case": (Program("fourbar-run", (0, 1), _case_argv),),
    "mechanism": (Program("build_fmu.py", (0, 1), _mechanism_argv),),
    "sweep": (Program("fourbar-sweep --dry-run", (0, 1), _sweep_argv),),
    "exchange": (Program("fourbar-monitor", (0, 1, 3, 5), _monitor_argv),
                 Program("fourbar-diagnose", (0, 1, 4), _diagnose_argv)),
}


# -- TOML written back ------------------------------------------------------------------------

def _toml_key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key)


def toml_value(value: Any) -> str:
    """``value`` as a TOML value (inline tables and arrays; floats nan/inf as TOML spells them)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_toml_key(str(k))} = {toml_value(v)}" for k, v in value.items()) + " }"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if hasattr(value, "isoformat"):
        return value.isoformat()
    return json.dumps(str(value))


def toml_dumps(doc: dict) -> str:
    """A TOML document: top-level values, then one ``[table]`` per table and ``[[name]]`` per
    element of an array of tables (deeper tables inline)."""
    lines = [f"{_toml_key(k)} = {toml_value(v)}" for k, v in doc.items()
             if not isinstance(v, dict) and not _table_array(v)]
    for k, v in doc.items():
        if isinstance(v, dict):
            lines += ["", f"[{_toml_key(k)}]", *(f"{_toml_key(str(kk))} = {toml_value(vv)}" for kk, vv in v.items())]
        elif _table_array(v):
            for item in v:
                lines += ["", f"[[{_toml_key(k)}]]",
                          *(f"{_toml_key(str(kk))} = {toml_value(vv)}" for kk, vv in item.items())]
    return "\n".join(lines) + "\n"


def _table_array(value: Any) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)


# -- the shipped files the fuzzing starts from ------------------------------------------------

def _absolute_fmu(text: str) -> str:
    return re.sub(r"(?m)^fmu\s*=.*$", lambda m: f"fmu = {json.dumps(NATIVE.as_posix())}", text)


def case_bases() -> dict[str, str]:
    """The shipped four-bar cases (the native FMU, absolute), by name."""
    return {p.stem: _absolute_fmu(p.read_text(encoding="utf-8"))
            for p in sorted((REPO / "cases").glob("case*.toml"))}


def mechanism_bases() -> dict[str, str]:
    return {p.stem: p.read_text(encoding="utf-8") for p in sorted((REPO / "fmu_src" / "mechanisms").glob("*.toml"))}


def sweep_bases() -> dict[str, str]:
    """The shipped sweeps with their base case and FMU as absolute paths (the file is fuzzed in
    another folder)."""
    out = {}
    for p in sorted((REPO / "sweeps").glob("*.toml")):
        text = p.read_text(encoding="utf-8")
        text = re.sub(r'(?m)^case\s*=\s*"([^"]*)"',
                      lambda m: f"case = {json.dumps((p.parent / m.group(1)).resolve().as_posix())}", text)
        text = re.sub(r"(?m)^fmu\s*=.*$", "", text) + ""
        text = re.sub(r"(?m)^(case\s*=.*)$", lambda m: m.group(1) + f"\nfmu = {json.dumps(NATIVE.as_posix())}",
                      text, count=1)
        out[p.stem] = text
    return out


@dataclass(frozen=True)
class ExchangeBase:
    """The files of one real run folder: exchange.csv, run.json, monitor/summary.json."""

    csv: bytes
    run_json: bytes
    summary: bytes

    def files(self, csv: bytes | Special | None = None, run_json: bytes | Special | None = None
              ) -> tuple[tuple[str, bytes | Special], ...]:
        return (("run/exchange.csv", self.csv if csv is None else csv),
                ("run/run.json", self.run_json if run_json is None else run_json),
                ("run/monitor/summary.json", self.summary))


def exchange_base(work: Path, timeout: float = 300.0) -> ExchangeBase:
    """Run case 2 for ``EXCHANGE_STOP`` s on the native FMU and monitor it (harmonic): the
    folder the exchange family damages."""
    work.mkdir(parents=True, exist_ok=True)
    case = work / "case2.toml"
    case.write_text(case_bases()["case2_fault_L2"], encoding="utf-8")
    run = work / "run"
    subprocess.run([str(BIN / "fourbar-run"), str(case), "--stop", repr(EXCHANGE_STOP), "--out", str(run),
                    "--quiet"], check=True, timeout=timeout, capture_output=True)
    subprocess.run([str(BIN / "fourbar-monitor"), str(run / "exchange.csv"), "--model", "harmonic", "--no-plots",
                    "--quiet", "--out", str(run / "monitor")], timeout=timeout, capture_output=True)
    summary = run / "monitor" / "summary.json"
    if not summary.is_file():
        raise RuntimeError(f"the monitor wrote no {summary}")
    return ExchangeBase((run / "exchange.csv").read_bytes(), (run / "run.json").read_bytes(), summary.read_bytes())


# -- the fixed corpus ---------------------------------------------------------------------------

#: Mechanism expressions of issue 36's probe and more: code injections (each would create
#: PWNED), exponent bombs, values that are not finite or not real, and Python syntax that is
#: no arithmetic.  Each is set as the coupler's length.
MECHANISM_EXPRESSIONS = (
    "__import__('os').system('touch PWNED') * 0 + L3",
    "open('PWNED', 'w').write('x') * 0 + L3",
    "open('/etc/passwd').read()",
    "__builtins__",
    "().__class__.__bases__[0].__subclasses__()",
    "Symbol('L3').__class__",
    "lambda: 0",
    "[x for x in ()]",
    "L3 if 1 else 0",
    "L3; import os",
    "10**10**10",
    "9**9**9**9",
    "2**(2**64)",
    "factorial(10**9)",
    "zoo", "oo", "-oo", "nan", "I", "E", "pi", "1/0", "0/0", "1e400", "-1e400", "exp(1000)", "sqrt(-1)",
    "log(0)", "L3**1e300", "(" * 200 + "L3" + ")" * 200, "(" * 5000 + "L3" + ")" * 5000,
    "-" * 10000 + "L3", "L3 + " * 2000 + "L3", "L9", "", " ", "L3 +", "L3 L3", "\x00", "L3\nL3",
    "L3 * 1e308 * 10", "Abs(L3)", "Max(L3, 1)", "L3._mpf_", "S('L3')",
)


def _mechanism_with(base: str, key: str, text: str) -> str:
    """The four-bar mechanism with the coupler's ``key`` set to the string ``text``."""
    marker = 'name = "coupler"'
    head, sep, tail = base.partition(marker)
    tail = re.sub(rf"(?m)^{key}\s*=.*$", lambda m: f"{key} = {json.dumps(text)}", tail, count=1)
    return head + sep + tail


def _corpus_case(bases: dict[str, str]) -> list[FuzzInput]:
    base = bases["case1_normal"]
    out = []

    def add(name: str, text: str, what: str, extra: tuple[str, ...] | None = None, fmu_flag: bool = True) -> None:
        out.append(FuzzInput("case", name, "corpus", (("case.toml", text.encode("utf-8", "surrogateescape")),),
                             what, extra, fmu_flag))

    add("outputs_nested_list", re.sub(r"(?m)^variables\s*=.*$", 'variables = ["x2", [1, 2]]', base),
        '[outputs] variables = ["x2", [1, 2]] (issue 36: TypeError traceback)')
    add("step_1e9", re.sub(r"(?m)^stop\s*=.*$", "stop = 1e9", re.sub(r"(?m)^step\s*=.*$", "step = 1e9", base)),
        "step = 1e9, stop = 1e9 (issue 36: one doStep of days)", ())
    add("omega2_start_1e15", re.sub(r"(?m)^omega2_start\s*=.*$", "omega2_start = 1e15", base),
        "omega2_start = 1e15 (issue 36: a doStep that never returns)")
    add("omega2_start_1e6", re.sub(r"(?m)^omega2_start\s*=.*$", "omega2_start = 1e6", base),
        "omega2_start = 1e6 (issue 36: 0.55 s per 0.01 s step)")
    add("theta2_start_1e308", re.sub(r"(?m)^theta2_start\s*=.*$", "theta2_start = 1e308", base),
        "theta2_start = 1e308 (issue 36: accepted)")
    add("step_1e-12", re.sub(r"(?m)^step\s*=.*$", "step = 1e-12", base), "step = 1e-12 s (rows without end)")
    add("stop_inf", re.sub(r"(?m)^stop\s*=.*$", "stop = inf", base), "stop = inf", ())
    add("tolerance_nan", re.sub(r"(?m)^tolerance\s*=.*$", "tolerance = nan", base), "tolerance = nan")
    add("flush_interval_1e9", re.sub(r"(?m)^flush_interval\s*=.*$", "flush_interval = 1e9", base),
        "flush_interval = 1e9")
    add("max_rows_huge", base.replace("[exchange]", "[exchange]\nmax_rows = 99999999999999999999999"),
        "exchange.max_rows = 1e23 (beyond int64)")
    add("empty", "", "an empty file")
    add("nul_bytes", "\x00" * 64, "NUL bytes only")
    add("not_utf8", "name = \"\udcff\udcfe\"", "not UTF-8")
    add("binary_garbage", "".join(chr(c) for c in range(1, 32)) * 3, "control characters")
    add("deep_array", base + "\n[extra]\nx = " + "[" * 5000 + "]" * 5000 + "\n", "an array nested 5000 deep")
    add("fmu_is_case", re.sub(r"(?m)^fmu\s*=.*$", 'fmu = "case.toml"', base), "fmu = the case file itself", fmu_flag=False)
    add("fmu_dev_zero", re.sub(r"(?m)^fmu\s*=.*$", 'fmu = "/dev/zero"', base), "fmu = /dev/zero", fmu_flag=False)
    return out


def _corpus_mechanism(bases: dict[str, str]) -> list[FuzzInput]:
    base = bases["fourbar"]
    out = [FuzzInput("mechanism", f"length_{i:02d}", "corpus",
                     (("mechanism.toml", _mechanism_with(base, "length", expr).encode()),),
                     f"coupler length = {expr[:60]!r}{'...' if len(expr) > 60 else ''}")
           for i, expr in enumerate(MECHANISM_EXPRESSIONS)]
    out.append(FuzzInput("mechanism", "mass_injection", "corpus",
                         (("mechanism.toml", _mechanism_with(base, "mass", "__import__('os').system('touch PWNED') "
                                                             "* 0 + m3").encode()),),
                         "coupler mass = an os.system injection"))
    for name, text, what in (("empty", "", "an empty file"), ("nul", "\x00" * 100, "NUL bytes"),
                             ("deep_table", base + "\n[x]\ny = " + "{a = " * 3000 + "1" + "}" * 3000 + "\n",
                              "an inline table nested 3000 deep")):
        out.append(FuzzInput("mechanism", name, "corpus", (("mechanism.toml", text.encode()),), what))
    return out


def _corpus_sweep(bases: dict[str, str]) -> list[FuzzInput]:
    base = bases["smoke"]
    out = []

    def add(name: str, text: str, what: str) -> None:
        out.append(FuzzInput("sweep", name, "corpus", (("sweep.toml", text.encode()),), what))

    add("sample_n_1e9", base.replace("std = [0.0, 0.005]", "std = { min = 0.0, max = 0.01 }")
        + "\n[sample]\nn = 1000000000\nseed = 1\n", "[sample] n = 1e9 draws")
    add("grid_1e12", base.replace("relative = [0.005, 0.02, 0.1]",
                                  "relative = [" + ", ".join(f"{0.001 * (i + 1):.3f}" for i in range(999)) + "]")
        .replace("std = [0.0, 0.005]", "std = [" + ", ".join(f"{1e-5 * i:.5f}" for i in range(1000)) + "]")
        .replace("seed = 1", "seed = [" + ", ".join(str(i) for i in range(1000)) + "]"),
        "a grid of 999 x 1000 x 1000 scenarios")
    add("seed_huge", base.replace("seed = 1", "seed = 99999999999999999999999"), "noise.seed beyond int64")
    add("sample_seed_huge", base.replace("std = [0.0, 0.005]", "std = { min = 0.0, max = 0.01 }")
        + "\n[sample]\nn = 2\nseed = 99999999999999999999999\n", "sample.seed beyond int64")
    add("seed_range_huge", base.replace("seed = 1", "seed = { min = 0, max = 1e300 }")
        + "\n[sample]\nn = 2\nseed = 1\n", "noise.seed sampled in [0, 1e300]")
    add("relative_inf", base.replace("relative = [0.005, 0.02, 0.1]", "relative = [inf, nan, 1e308]"),
        "fault.relative = [inf, nan, 1e308]")
    add("value_overflow", base.replace("relative = [0.005, 0.02, 0.1]", "value = 1e308"), "fault.value = 1e308")
    add("stop_1e300", base.replace("stop = 20.0", "stop = 1e300"), "stop = 1e300")
    add("time_1e300", base.replace("time = 10.0", "time = 1e300"), "fault.time = 1e300")
    add("ramp_huge", base.replace('kind = "step"', 'kind = "ramp"\nramp_duration = 1e300'), "ramp_duration = 1e300")
    add("ramp_tiny", base.replace('kind = "step"', 'kind = "ramp"\nramp_duration = 1e-300'),
        "ramp_duration = 1e-300")
    add("log_range_overflow", base.replace("std = [0.0, 0.005]", "std = { min = 1e-300, max = 1e308, scale = \"log\" }")
        + "\n[sample]\nn = 3\nseed = 1\n", "noise.std sampled log in [1e-300, 1e308]")
    add("range_inf", base.replace("std = [0.0, 0.005]", "std = { min = 0.0, max = inf }")
        + "\n[sample]\nn = 3\nseed = 1\n", "noise.std sampled in [0, inf]")
    add("threshold_inf", base.replace('threshold = "auto"', "threshold = inf"), "monitor.threshold = inf")
    add("monitor_train_nested", base.replace('threshold = "auto"', 'threshold = "auto"\ntrain = [[0], [9]]'),
        "monitor.train = [[0], [9]]")
    add("case_dir", re.sub(r'(?m)^case\s*=.*$', 'case = "/"', base), "case = a directory")
    add("case_dev_zero", re.sub(r'(?m)^case\s*=.*$', 'case = "/dev/zero"', base), "case = /dev/zero")
    add("case_self", re.sub(r'(?m)^case\s*=.*$', 'case = "sweep.toml"', base), "case = the sweep file itself")
    add("deep_array", base + "\n[report]\nx = " + "[" * 5000 + "]" * 5000 + "\n", "an array nested 5000 deep")
    add("empty", "", "an empty file")
    add("nul", "\x00" * 100, "NUL bytes")
    return out


def _csv_rows(csv: bytes) -> tuple[bytes, list[bytes]]:
    lines = csv.split(b"\n")
    if lines and lines[-1] == b"":
        lines = lines[:-1]
    return lines[0], lines[1:]


def _join(header: bytes, rows: Sequence[bytes]) -> bytes:
    return b"\n".join([header, *rows]) + b"\n"


def _times(rows: Sequence[bytes]) -> list[float]:
    return [float(r.split(b",", 1)[0]) for r in rows]


def _shift(rows: Sequence[bytes], by: float) -> list[bytes]:
    out = []
    for r in rows:
        t, _, rest = r.partition(b",")
        out.append(repr(float(t) + by).encode() + b"," + rest)
    return out


def _corpus_exchange(base: ExchangeBase) -> list[FuzzInput]:
    header, rows = _csv_rows(base.csv)
    times = _times(rows)
    out = []

    def add(name: str, what: str, csv: bytes | Special | None = None, run_json: bytes | Special | None = None,
            wrong_exits: tuple[tuple[str, tuple[int, ...]], ...] = ()) -> None:
        out.append(FuzzInput("exchange", name, "corpus", base.files(csv, run_json), what, wrong_exits=wrong_exits))

    not_clean = (("fourbar-monitor", (0,)),)

    kept = [r for r, t in zip(rows, times) if not 1.37 <= t <= 6.88]
    add("gap_1.37_6.88", "rows 1.37-6.88 s missing (issue 36: 'NOT detected', exit 0)", _join(header, kept),
        wrong_exits=not_clean)
    cut = next(i for i, t in enumerate(times) if t >= 12.0)
    add("jump_1e6", "a +1e6 s time jump at 12 s (issue 36: the gap evaluated every 0.1 s)",
        _join(header, rows[:cut] + _shift(rows[cut:], 1e6)), wrong_exits=not_clean)
    tiny = [repr(1e6 + 12.0 + 1e-9 * k).encode() + b"," + r.partition(b",")[2] for k, r in enumerate(rows[cut:])]
    add("jump_1e6_then_1e-9_steps", "a +1e6 s jump, then 1e-9 s steps (issue 36: 149 GiB allocation)",
        _join(header, rows[:cut] + tiny), wrong_exits=not_clean)
    add("fifo", "exchange.csv is a FIFO with no writer (issue 36: monitor and diagnose hang)", FIFO)
    add("directory", "exchange.csv is a directory", DIR)
    add("symlink_dev_zero", "exchange.csv is a symlink to /dev/zero", Special("LINK:/dev/zero"))
    add("run_json_nested", "run.json nested 100000 deep (issue 36: RecursionError)",
        run_json=b"[" * 100000 + b"]" * 100000)
    add("run_json_nested_object", "run.json: an object nested 100000 deep",
        run_json=b'{"a":' * 100000 + b"1" + b"}" * 100000)
    add("run_json_empty", "run.json empty (issue 36: 'fault time unknown', alarm called false)", run_json=b"")
    add("run_json_empty_object", "run.json = {}", run_json=b"{}")
    add("run_json_array", "run.json = []", run_json=b"[]")
    add("run_json_garbage", "run.json holds bytes that are not UTF-8", run_json=b"\xff\xfe\x00garbage")
    add("run_json_fifo", "run.json is a FIFO with no writer", run_json=FIFO)
    add("run_json_directory", "run.json is a directory", run_json=DIR)
    add("empty_csv", "exchange.csv empty", b"")
    add("header_only", "exchange.csv has its header only", header + b"\n")
    add("nul_block", "a 4096-byte block of NUL bytes in the middle (issue 36: two writers)",
        base.csv[:len(base.csv) // 2] + b"\x00" * 4096 + base.csv[len(base.csv) // 2 + 4096:])
    add("all_nul", "exchange.csv is NUL bytes only", b"\x00" * len(base.csv))
    add("duplicate_times", "every row written twice", _join(header, [r for r in rows for _ in (0, 1)]))
    add("reversed", "rows in reverse time order", _join(header, rows[::-1]))
    add("long_line", "one 64 MB line", _join(header, rows[:500] + [b"1" * (64 << 20)] + rows[500:]))
    return out


def corpus(family: str, exchange: ExchangeBase | None = None) -> list[FuzzInput]:
    """The fixed corpus of ``family`` (issue 36's probe, and more of the same kind)."""
    if family == "case":
        return _corpus_case(case_bases())
    if family == "mechanism":
        return _corpus_mechanism(mechanism_bases())
    if family == "sweep":
        return _corpus_sweep(sweep_bases())
    assert exchange is not None
    return _corpus_exchange(exchange)


# -- mutations of the shipped files (seeded) -----------------------------------------------------

NASTY_NUMBERS = ("0", "-0.0", "-1", "1e308", "-1e308", "1e-320", "inf", "-inf", "nan", "99999999999999999999999",
                 "1e9", "1e15", "0.1e-12", "3.0e+00", "0x7fffffffffffffff", "1_000")
NASTY_STRINGS = ('""', '"x2"', '"L2"', '"../../../etc/passwd"', '"/dev/zero"', '"\\u0000"', '"nan"', '"inf"',
                 '"' + "A" * 10000 + '"', '"ramp"', '"step"', '"auto"', '"prophet"', '"PWNED"', "'''\n'''")
NASTY_BYTES = (b"\x00", b"\xff", b"\"", b"[", b"]", b"{", b"=", b"\n", b"#", b"\x00" * 64, b"\r", b"\t", b"[[")


def _text_mutation(text: bytes, rng: random.Random) -> tuple[bytes, str]:
    """One seeded edit of a text file's bytes; returns the new bytes and what was done."""
    lines = text.split(b"\n")
    op = rng.choice(("truncate", "delete_line", "double_line", "swap_lines", "insert_bytes", "number", "string",
                     "number", "string", "flip_byte"))
    if op == "truncate":
        at = rng.randrange(len(text) + 1)
        return text[:at], f"truncated at byte {at} of {len(text)}"
    if op in ("delete_line", "double_line", "swap_lines"):
        i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
        if op == "delete_line":
            return b"\n".join(lines[:i] + lines[i + 1:]), f"line {i + 1} deleted"
        if op == "double_line":
            return b"\n".join(lines[:i + 1] + lines[i:]), f"line {i + 1} doubled"
        lines[i], lines[j] = lines[j], lines[i]
        return b"\n".join(lines), f"lines {i + 1} and {j + 1} swapped"
    if op == "insert_bytes":
        at, junk = rng.randrange(len(text) + 1), rng.choice(NASTY_BYTES)
        return text[:at] + junk + text[at:], f"{junk[:8]!r} inserted at byte {at}"
    if op == "flip_byte":
        at = rng.randrange(len(text))
        return text[:at] + bytes([text[at] ^ (1 << rng.randrange(8))]) + text[at + 1:], f"a bit of byte {at} flipped"
    pattern = rb"(?<=[=\[, ])-?\d[\d._eE+-]*" if op == "number" else rb'"[^"\n]*"'
    found = list(re.finditer(pattern, text))
    if not found:
        return text, "unchanged (no token)"
    m = rng.choice(found)
    new = rng.choice(NASTY_NUMBERS if op == "number" else NASTY_STRINGS).encode()
    line = text.count(b"\n", 0, m.start()) + 1
    return text[:m.start()] + new + text[m.end():], f"line {line}: {m.group()[:30]!r} -> {new[:30]!r}"


def _csv_mutation(base: ExchangeBase, rng: random.Random) -> tuple[bytes, bytes, str]:
    """One seeded damage to an exchange folder: (exchange.csv, run.json, what was done)."""
    header, rows = _csv_rows(base.csv)
    n = len(rows)
    op = rng.choice(("truncate", "torn_last_line", "nul_block", "wrong_header", "non_numeric", "extreme", "swap",
                     "duplicate", "gap", "jump", "run_json_text", "run_json_truncate", "columns"))
    csv, run_json = base.csv, base.run_json
    if op == "truncate":
        at = rng.randrange(len(csv))
        return csv[:at], run_json, f"exchange.csv truncated at byte {at} of {len(csv)}"
    if op == "torn_last_line":
        i = rng.randrange(1, n)
        cut = rng.randrange(1, len(rows[i]))
        return _join(header, rows[:i])[:] + rows[i][:cut], run_json, f"cut inside row {i} (byte {cut})"
    if op == "nul_block":
        at, size = rng.randrange(len(csv)), rng.choice((1, 17, 512, 4096))
        return csv[:at] + b"\x00" * size + csv[at + size:], run_json, f"{size} NUL bytes at byte {at}"
    if op == "wrong_header":
        cols = header.split(b",")
        k = rng.randrange(len(cols))
        new = rng.choice((b"", b"Time", b"x2", b"\x00", b"time,time", b'"x2"'))
        cols[k] = new
        return _join(b",".join(cols), rows), run_json, f"header column {k} -> {new!r}"
    if op in ("non_numeric", "extreme"):
        i = rng.randrange(n)
        cells = rows[i].split(b",")
        k = rng.randrange(len(cells))
        new = rng.choice((b"abc", b"", b"1,2", b"0x10", b"--1", b" ", b'"1"') if op == "non_numeric" else
                         (b"1e308", b"-1e308", b"nan", b"inf", b"-inf", b"1e400", b"5e-324", b"1e30"))
        cells[k] = new
        rows = rows[:i] + [b",".join(cells)] + rows[i + 1:]
        return _join(header, rows), run_json, f"row {i}, column {k} -> {new!r}"
    if op == "swap":
        i, j = rng.randrange(n), rng.randrange(n)
        rows = list(rows)
        rows[i], rows[j] = rows[j], rows[i]
        return _join(header, rows), run_json, f"rows {i} and {j} swapped"
    if op == "duplicate":
        i, k = rng.randrange(n), rng.choice((1, 10, 1000))
        return _join(header, rows[:i] + [rows[i]] * k + rows[i:]), run_json, f"row {i} written {k} more times"
    if op == "gap":
        i = rng.randrange(n)
        j = min(n, i + rng.choice((1, 10, 300, 1000)))
        return _join(header, rows[:i] + rows[j:]), run_json, f"rows {i}-{j - 1} removed"
    if op == "jump":
        i, by = rng.randrange(n), rng.choice((1e6, -5.0, 0.005, 1e300, -1e300))
        return _join(header, rows[:i] + _shift(rows[i:], by)), run_json, f"times from row {i} on shifted by {by!r}"
    if op == "columns":
        i = rng.randrange(n)
        cells = rows[i].split(b",")
        new = b",".join(cells[:-1]) if rng.random() < 0.5 else rows[i] + b",1.0"
        return _join(header, rows[:i] + [new] + rows[i + 1:]), run_json, f"row {i} with a cell too few or too many"
    if op == "run_json_truncate":
        at = rng.randrange(len(run_json))
        return csv, run_json[:at], f"run.json truncated at byte {at}"
    new, what = _text_mutation(run_json, rng)
    return csv, new, f"run.json: {what}"


def mutations(family: str, n: int, seed: int, exchange: ExchangeBase | None = None) -> list[FuzzInput]:
    """``n`` seeded byte and line edits of the shipped files of ``family``."""
    rng = random.Random(f"{seed}:{family}")
    out = []
    if family == "exchange":
        assert exchange is not None
        for i in range(n):
            csv, run_json, what = _csv_mutation(exchange, rng)
            out.append(FuzzInput("exchange", f"mutation_{i:03d}", "mutation", exchange.files(csv, run_json), what))
        return out
    bases = {"case": case_bases, "mechanism": mechanism_bases, "sweep": sweep_bases}[family]()
    file = {"case": "case.toml", "mechanism": "mechanism.toml", "sweep": "sweep.toml"}[family]
    names = sorted(bases)
    for i in range(n):
        name = rng.choice(names)
        text, what = bases[name].encode(), []
        for _ in range(rng.choice((1, 1, 1, 2, 3))):
            text, step = _text_mutation(text, rng)
            what.append(step)
        out.append(FuzzInput(family, f"mutation_{i:03d}", "mutation", ((file, text),), f"{name}: " + "; ".join(what)))
    return out


# -- hypothesis-generated edits ------------------------------------------------------------------

def _strategies():
    """The value strategies: any TOML scalar (extreme numbers included), nested arrays and tables."""
    from hypothesis import strategies as st

    names = st.sampled_from(["x2", "y2", "L2", "L3", "m2", "g", "theta2_start", "omega2_start", "time", "step",
                             "ramp", "auto", "harmonic", "prophet", "cusum", "mae", "revolute", "prismatic", "rod",
                             "crank", "coupler", "ground.O2", "crank.tip", "m", "kg", "deg", "../cases/case1_normal.toml"])
    scalars = st.one_of(
        st.integers(min_value=-(10 ** 30), max_value=10 ** 30),
        st.sampled_from([0, 1, -1, 2 ** 63 - 1, -(2 ** 63), 2 ** 64, 10 ** 9]),
        st.floats(allow_nan=True, allow_infinity=True),
        st.sampled_from([0.0, -0.0, 1e308, -1e308, 5e-324, 1e-12, 1e9, 1e15, 0.01, 0.005, 10.0]),
        st.text(max_size=12), names, st.booleans(), st.dates())
    values = st.recursive(scalars, lambda c: st.lists(c, max_size=4) | st.dictionaries(st.text(max_size=6) | names,
                                                                                          c, max_size=3),
                          max_leaves=8)
    return st, values, names


def _paths(doc: Any, prefix: tuple = ()) -> list[tuple]:
    """Every key path of a parsed document (tables, arrays' items and leaves)."""
    out = []
    items = doc.items() if isinstance(doc, dict) else enumerate(doc) if isinstance(doc, list) else ()
    for k, v in items:
        out.append(prefix + (k,))
        out += _paths(v, prefix + (k,))
    return out


def _apply(doc: Any, edits: Iterable[tuple[str, tuple, Any]]) -> tuple[Any, list[str]]:
    """``doc`` (a deep copy) with the edits applied: ("set" | "delete" | "add", path, value)."""
    doc = json.loads(json.dumps(doc, default=str))
    what = []
    for op, path, value in edits:
        parent = doc
        try:
            for k in path[:-1]:
                parent = parent[k]
            key = path[-1]
            if op == "delete":
                del parent[key]
                what.append(f"{'.'.join(map(str, path))} deleted")
            elif op == "add" and isinstance(parent, dict):
                parent[f"{key}_extra"] = value
                what.append(f"{'.'.join(map(str, path))}_extra = {_short(value)} added")
            else:
                parent[key] = value
                what.append(f"{'.'.join(map(str, path))} = {_short(value)}")
        except (KeyError, IndexError, TypeError):
            continue
    return doc, what


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _collect(strategy, n: int, seed: int) -> list:
    """``n`` examples of ``strategy``, drawn by hypothesis from ``seed`` (no database, no shrinking)."""
    from hypothesis import HealthCheck, Phase, given, settings
    from hypothesis import seed as hseed

    drawn: list = []

    @hseed(seed)
    @settings(max_examples=n, database=None, phases=[Phase.generate], deadline=None,
              suppress_health_check=list(HealthCheck))
    @given(strategy)
    def collect(example):
        drawn.append(example)

    collect()
    return drawn[:n]


def _json_safe(doc: Any) -> Any:
    """TOML dates as text, so the parsed document survives a JSON round trip."""
    return json.loads(json.dumps(doc, default=str))


def generated(family: str, n: int, seed: int, exchange: ExchangeBase | None = None) -> list[FuzzInput]:
    """``n`` hypothesis-generated edits of the parsed shipped files of ``family``."""
    if n <= 0:
        return []
    st, values, names = _strategies()
    if family == "exchange":
        assert exchange is not None
        header, rows = _csv_rows(exchange.csv)
        ncols = len(header.split(b","))
        run_doc = json.loads(exchange.run_json)
        cells = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(lambda x: repr(x).encode()),
                          st.binary(max_size=6), st.text(max_size=6).map(lambda s: s.encode("utf-8", "surrogatepass")))
        strategy = st.tuples(
            st.lists(st.tuples(st.integers(0, len(rows) - 1), st.integers(0, ncols - 1), cells), max_size=4),
            st.none() | st.integers(0, len(exchange.csv)),
            st.lists(st.tuples(st.sampled_from(("set", "delete", "add")), st.sampled_from(_paths(run_doc)), values),
                     max_size=3))
        out = []
        for i, (edits, cut, json_edits) in enumerate(_collect(strategy, n, seed)):
            new_rows = list(rows)
            what = []
            for r, c, cell in edits:
                parts = new_rows[r].split(b",")
                parts[min(c, len(parts) - 1)] = cell
                new_rows[r] = b",".join(parts)
                what.append(f"row {r} column {c} -> {cell[:20]!r}")
            csv = _join(header, new_rows)
            if cut is not None:
                csv = csv[:cut]
                what.append(f"truncated at byte {cut}")
            doc, json_what = _apply(run_doc, json_edits)
            run_json = json.dumps(doc, default=str).encode()
            out.append(FuzzInput("exchange", f"hypothesis_{i:03d}", "hypothesis", exchange.files(csv, run_json),
                                 "; ".join(what + [f"run.json: {w}" for w in json_what]) or "unchanged"))
        return out
    bases = {"case": case_bases, "mechanism": mechanism_bases, "sweep": sweep_bases}[family]()
    file = {"case": "case.toml", "mechanism": "mechanism.toml", "sweep": "sweep.toml"}[family]
    docs = {name: _json_safe(tomllib.loads(text)) for name, text in bases.items()}
    edit = lambda doc: st.tuples(st.sampled_from(("set", "set", "delete", "add")),  # noqa: E731
                                 st.sampled_from(_paths(doc)), values)
    strategy = st.sampled_from(sorted(docs)).flatmap(
        lambda name: st.tuples(st.just(name), st.lists(edit(docs[name]), min_size=1, max_size=3)))
    out = []
    for i, (name, edits) in enumerate(_collect(strategy, n, seed)):
        doc, what = _apply(docs[name], edits)
        if family == "case" and isinstance(doc, dict) and not isinstance(doc.get("fmu"), str):
            pass    # the fmu key itself was fuzzed: keep it (--fmu overrides it anyway)
        text = toml_dumps(doc) if isinstance(doc, dict) else ""
        out.append(FuzzInput(family, f"hypothesis_{i:03d}", "hypothesis", ((file, text.encode("utf-8", "surrogatepass")),),
                             f"{name}: " + ("; ".join(what) or "unchanged")))
    return out


def inputs(family: str, n: int, seed: int, exchange: ExchangeBase | None = None, *,
           with_corpus: bool = True) -> list[FuzzInput]:
    """The corpus, then ``n`` mutations, then ``n`` hypothesis-generated inputs of ``family``."""
    return [*(corpus(family, exchange) if with_corpus else ()), *mutations(family, n, seed, exchange),
            *generated(family, n, seed, exchange)]


# -- running ------------------------------------------------------------------------------------

def materialise(item: FuzzInput, folder: Path) -> None:
    """Write ``item``'s files into ``folder``."""
    for rel, content in item.files:
        path = folder / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        if content == FIFO and isinstance(content, Special):
            os.mkfifo(path)
        elif content == DIR and isinstance(content, Special):
            path.mkdir()
        elif isinstance(content, Special) and content.startswith("LINK:"):
            path.symlink_to(content[len("LINK:"):])
        else:
            path.write_bytes(content)


def _limit_memory(gib: float) -> Callable[[], None]:
    def limit() -> None:
        size = int(gib * (1 << 30))
        resource.setrlimit(resource.RLIMIT_AS, (size, size))
    return limit


def classify(program: Program, exit_code: int | None, stderr: str, side_effect: bool,
             wrong_exits: tuple[int, ...] = ()) -> str:
    """The outcome kind of one run (see the module docstring)."""
    if side_effect:
        return "side_effect"
    if exit_code is None:
        return "hang"
    if TRACEBACK in stderr:
        return "traceback"
    if exit_code < 0:
        return "crash"
    if exit_code == 2:
        return "refused" if stderr.strip() else "silent"
    if exit_code in wrong_exits:
        return "wrong_verdict"
    return "ok" if exit_code in program.ok_exits else "traceback"


def run_input(item: FuzzInput, work: Path, *, timeout: float = TIMEOUT, memory_gib: float = MEMORY_GIB
              ) -> list[Outcome]:
    """Every program of ``item``'s family on ``item`` (in a fresh folder under ``work``)."""
    outcomes = []
    for program in PROGRAMS[item.family]:
        folder = Path(tempfile.mkdtemp(prefix=f"{item.family}-{item.name}-", dir=work))
        materialise(item, folder)
        out = folder / "_out"
        out.mkdir()
        argv = program.argv(folder, out, item)
        env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1", "MPLBACKEND": "Agg"}
        start = time.monotonic()
        proc = subprocess.Popen(argv, cwd=folder, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                stderr=subprocess.PIPE, start_new_session=True, env=env,
                                preexec_fn=_limit_memory(memory_gib))
        try:
            _, err = proc.communicate(timeout=timeout)
            code: int | None = proc.returncode
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            _, err = proc.communicate()
            code = None
        seconds = time.monotonic() - start
        stderr = err.decode("utf-8", "replace")
        side = (folder / SIDE_EFFECT).exists() or (out / SIDE_EFFECT).exists()
        wrong = dict(item.wrong_exits).get(program.name, ())
        outcomes.append(Outcome(item, program.name, classify(program, code, stderr, side, wrong), code, seconds,
                                stderr, tuple(argv)))
        shutil.rmtree(folder, ignore_errors=True)
    return outcomes


def keep_failure(outcome: Outcome, keep: Path) -> Path:
    """Save a failing input (its files, the command, the exit, stderr) under ``keep``."""
    folder = keep / outcome.input.family / f"{outcome.input.name}-{outcome.program.split()[0]}"
    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir(parents=True)
    materialise(outcome.input, folder)
    (folder / "README.txt").write_text(
        f"{outcome.input.family} input {outcome.input.name} ({outcome.input.origin}): {outcome.input.what}\n"
        f"outcome: {outcome.kind} (exit {outcome.exit}, {outcome.seconds:.1f} s)\n"
        f"command (the input's files were in a temporary folder; run it with this folder's files):\n"
        f"  {' '.join(outcome.argv)}\n\nstderr:\n{outcome.stderr}", encoding="utf-8")
    return folder


# -- the report ---------------------------------------------------------------------------------

def _last_line(text: str) -> str:
    lines = [line for line in text.strip().splitlines() if line.strip()]
    line = lines[-1] if lines else ""
    return line if len(line) <= 160 else line[:157] + "..."


def report(outcomes: Sequence[Outcome], command: str, args: argparse.Namespace, seconds: float) -> list[str]:
    lines = [
        f"Generated by `{command}` (do not edit by hand; rerun after a change to any CLI or loader): "
        f"seed {args.seed}, {args.examples} mutations and {args.examples} hypothesis-generated inputs per family "
        f"besides the fixed corpus, timeout {args.timeout:g} s per program run, address space "
        f"{args.memory:g} GiB; {seconds / 60:.1f} min wall time.",
        "",
        "| family | program | inputs | ok | refused | silent | wrong verdict | traceback | hang | crash | side effect |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    keys = []
    for o in outcomes:
        if (o.input.family, o.program) not in keys:
            keys.append((o.input.family, o.program))
    for family, program in keys:
        mine = [o for o in outcomes if o.input.family == family and o.program == program]
        counts = [sum(o.kind == k for o in mine) for k in KINDS]
        lines.append(f"| {family} | {program} | {len(mine)} | " + " | ".join(map(str, counts)) + " |")
    failing = [o for o in outcomes if o.failed]
    lines += ["", f"Failing inputs: {len(failing)}."]
    if failing:
        lines += ["", "| family | input | what | program | outcome | last line of stderr |", "|---|---|---|---|---|---|"]
        for o in failing:
            what = o.input.what.replace("|", "\\|")
            what = what if len(what) <= 90 else what[:87] + "..."
            tail = _last_line(o.stderr).replace("|", "\\|") or "-"
            exit_text = "timeout" if o.exit is None else f"exit {o.exit}"
            lines.append(f"| {o.input.family} | {o.input.name} | {what} | {o.program} | {o.kind} ({exit_text}, "
                         f"{o.seconds:.1f} s) | `{tail}` |")
    return lines


def _parse(argv) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog="exit status: 0 no failing input, "
                                "1 some input failed, 2 usage error")
    p.add_argument("--examples", type=int, default=20, metavar="N",
                   help="mutations and hypothesis-generated inputs per family, each (default: %(default)s; the "
                        "fixed corpus is always run)")
    p.add_argument("--seed", type=int, default=SEED, help="seed of the mutations and of hypothesis (default %(default)s)")
    p.add_argument("--timeout", type=float, default=TIMEOUT, metavar="S",
                   help="seconds a program may run on one input before it counts as a hang (default %(default)s)")
    p.add_argument("--memory", type=float, default=MEMORY_GIB, metavar="GIB",
                   help="address-space limit of each program run (default %(default)s GiB)")
    p.add_argument("--families", default=",".join(FAMILIES), metavar="LIST",
                   help=f"comma-separated subset of {','.join(FAMILIES)} (default: all)")
    p.add_argument("--no-corpus", action="store_true", help="leave out the fixed corpus")
    p.add_argument("--keep", type=Path, default=KEEP, metavar="DIR",
                   help="where failing inputs are saved for reproduction (default %(default)s)")
    p.add_argument("--write", type=Path, metavar="FILE",
                   help="also put the figures between the marker lines of FILE (docs/robustness.md)")
    p.add_argument("--fmu", type=Path, default=NATIVE, metavar="FMU",
                   help="the native FMU the case and sweep inputs run (default %(default)s)")
    p.add_argument("--family-examples", default="", metavar="FAMILY=N,...",
                   help="--examples for these families instead (e.g. exchange=1)")
    p.add_argument("--only", default="", metavar="FAMILY/NAME,...", help="run only these of the drawn inputs")
    p.add_argument("--jobs", type=int, default=1, metavar="N", help="inputs run side by side (default %(default)s)")
    p.add_argument("--json", type=Path, metavar="FILE", help="also write every outcome to FILE (a JSON list)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--list", action="store_true",
                      help="print each drawn input (family, name, SHA-256 of its files, what) and run nothing")
    mode.add_argument("--probe", metavar="CODE",
                      help="classify one `python -c CODE` run as a program run on an input (a check of the "
                           "classifier); print its outcome as JSON and run nothing else")
    args = p.parse_args(argv)
    per_family: dict[str, int] = {}
    for entry in filter(None, (e.strip() for e in args.family_examples.split(","))):
        family, _, count = entry.partition("=")
        if family not in FAMILIES or not count.isdigit():
            p.error(f"--family-examples: expected FAMILY=N with FAMILY one of {', '.join(FAMILIES)} and N >= 0, "
                    f"got {entry!r}")
        per_family[family] = int(count)
    only = set()
    for entry in filter(None, (e.strip() for e in args.only.split(","))):
        family, _, name = entry.partition("/")
        if family not in FAMILIES or not name:
            p.error(f"--only: expected FAMILY/NAME with FAMILY one of {', '.join(FAMILIES)}, got {entry!r}")
        only.add((family, name))
    if args.jobs < 1:
        p.error(f"--jobs: expected a number >= 1, got {args.jobs}")
    families = tuple(f.strip() for f in args.families.split(",") if f.strip())
    unknown = [f for f in families if f not in FAMILIES]
    if unknown or not families:
        p.error(f"--families: unknown {', '.join(map(repr, unknown)) or 'empty list'}; expected some of "
                f"{', '.join(FAMILIES)}")
    if args.examples < 0:
        p.error(f"--examples: expected a number >= 0, got {args.examples}")
    if not (math.isfinite(args.timeout) and args.timeout > 0):
        p.error(f"--timeout: expected a positive number of seconds, got {args.timeout}")
    if not (math.isfinite(args.memory) and args.memory > 0):
        p.error(f"--memory: expected a positive number of GiB, got {args.memory}")
    if args.write:
        problem = markers_problem(args.write, BEGIN, END)
        if problem:
            p.error(problem)
    if args.probe is None and not args.fmu.is_file():
        p.error(f"{args.fmu} not found: run `make fmu` first")
    args.families = families
    args.per_family = {family: per_family.get(family, args.examples) for family in families}
    args.only = only
    return args


def _outcome_json(o: Outcome) -> dict:
    return {"family": o.input.family, "name": o.input.name, "origin": o.input.origin, "what": o.input.what,
            "program": o.program, "kind": o.kind, "exit": o.exit, "seconds": o.seconds, "stderr": o.stderr,
            "argv": list(o.argv)}


def probe(code: str, timeout: float, memory_gib: float) -> int:
    """``--probe``: ``python -c code`` as the one program of a one-file input, classified; its outcome as JSON."""
    PROGRAMS["probe"] = (Program("python -c", (0, 1), lambda folder, out, item: [sys.executable, "-c", code]),)
    try:
        item = FuzzInput("probe", "probe", "corpus", (("x.txt", b"x"),))
        with tempfile.TemporaryDirectory(prefix="fuzz_probe-") as tmp:
            (outcome,) = run_input(item, Path(tmp), timeout=timeout, memory_gib=memory_gib)
    finally:
        del PROGRAMS["probe"]
    print(json.dumps(_outcome_json(outcome)))
    return 0


def _digest(item: FuzzInput) -> str:
    h = hashlib.sha256()
    for rel, content in item.files:
        h.update(rel.encode() + b"\0" + (content if isinstance(content, bytes) else f"<{content}>".encode()) + b"\0")
    return h.hexdigest()[:16]


def main(argv=None) -> int:
    global NATIVE
    args = _parse(argv)
    NATIVE = args.fmu
    if args.probe is not None:
        return probe(args.probe, args.timeout, args.memory)
    started = time.monotonic()
    outcomes: list[Outcome] = []
    with tempfile.TemporaryDirectory(prefix="fuzz_inputs-") as tmp:
        work = Path(tmp)
        exchange = exchange_base(work / "base") if "exchange" in args.families else None
        drawn = {family: inputs(family, args.per_family[family], args.seed, exchange, with_corpus=not args.no_corpus)
                 for family in args.families}
        unknown = args.only - {(family, item.name) for family, items in drawn.items() for item in items}
        if unknown:
            print(f"fuzz_inputs.py: --only: no input {', '.join(sorted(f'{f}/{n}' for f, n in unknown))} was drawn",
                  file=sys.stderr)
            return 2
        if args.list:
            for family, items in drawn.items():
                for item in items:
                    print(f"{family} {item.name} {_digest(item)} {item.what}")
            return 0
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(max_workers=args.jobs) as pool:
            runs = [(family, k, len(items), item,
                     pool.submit(run_input, item, work, timeout=args.timeout, memory_gib=args.memory))
                    for family, items in drawn.items() for k, item in enumerate(items, 1)
                    if not args.only or (family, item.name) in args.only]
            for family, k, n, item, future in runs:
                for o in future.result():
                    outcomes.append(o)
                    mark = "" if not o.failed else f"  <- {o.kind.upper()}: {_last_line(o.stderr)}"
                    print(f"[{family} {k}/{n}] {item.name} {o.program}: {o.kind} "
                          f"({'timeout' if o.exit is None else o.exit}, {o.seconds:.1f} s){mark}",
                          file=sys.stderr, flush=True)
                    if o.failed:
                        keep_failure(o, args.keep)
    seconds = time.monotonic() - started
    if args.json:
        args.json.write_text(json.dumps([_outcome_json(o) for o in outcomes], indent=1), encoding="utf-8")
    options = [(f"--examples {args.examples}", args.examples != 20), (f"--seed {args.seed}", args.seed != SEED),
               (f"--timeout {args.timeout:g}", args.timeout != TIMEOUT),
               (f"--memory {args.memory:g}", args.memory != MEMORY_GIB),
               (f"--families {','.join(args.families)}", args.families != FAMILIES),
               ("--no-corpus", args.no_corpus)]
    command = " ".join(["python benchmarks/fuzz_inputs.py", *(o for o, given in options if given),
                        "--write docs/robustness.md"])
    lines = report(outcomes, command, args, seconds)
    print("\n".join(lines))
    if any(o.failed for o in outcomes):
        print(f"failing inputs saved under {args.keep}", file=sys.stderr)
    if args.write:
        write_section(args.write, lines, BEGIN, END)
        print(f"wrote the figures into {args.write}", file=sys.stderr)
    return 1 if any(o.failed for o in outcomes) else 0


if __name__ == "__main__":
    sys.exit(main())

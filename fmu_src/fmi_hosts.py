"""FMUs run in other FMI hosts (FMPy, libcosim, fmusim, the FMU Compliance Checker), and each
run compared with FMPy's: what tests/test_mechanism_hosts.py and the FMI tests check and
benchmarks/fmi_hosts.py and benchmarks/fmi_flavours.py tabulate (one home for the runners and
their tolerances).

Each host runs as a process of its own with an **empty environment** (``env={}``: no PATH,
no LD_PRELOAD, PYTHONHOME or PYTHONPATH; issue 24: "with no environment variables"); the two
Python hosts are this interpreter started as ``python -c``.  A host agrees when it exits 0,
returns the same communication points, and every value is within ``AGREEMENT[host]`` (reasons
there).  Wall time: the ``simulate_fmu`` call, libcosim's execution from loading the FMU to the
last sample read, and the whole fmusim process (its start-up is milliseconds).

Build time and test time only: no FMU imports this, and fmusim, fmuCheck and libcosimpy are
looked for only when a run asks for them.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["AGREEMENT", "HOSTS", "TIMEOUT", "Agreement", "CheckerRun", "Experiment", "HostError", "HostRun", "compare",
           "find_fmucheck", "find_fmusim", "fmusim_version", "output_names", "run_fmpy", "run_fmucheck", "run_fmusim",
           "run_libcosim"]

HOSTS = ("FMPy", "libcosim", "fmusim")

#: Largest |host - FMPy| allowed, relative to max(1, |FMPy's value|) (outputs are m, rad, N, J
#: of order 1..100; a value below 1 in magnitude is held to the absolute bound).
#: libcosim: the same binary on the same communication grid.  libcosim's integer-nanosecond
#: times and FMPy's start + n * step differ by an ulp at some steps, but the FMU snaps every
#: communication time to whole nanoseconds (docs/contracts.md, "Time resolution 1 ns"), so
#: both drive identical arithmetic and agree to round-off (measured: 0.0).
#: fmusim: the same, but its CSV has 16 significant digits (%.16g): a printed value is within
#: 5e-16 of the double relative to its magnitude, reading it back adds at most 1.1e-16
#: (measured 5.3e-16), so 1e-15 admits that and nothing more.
#: fmuCheck (co-simulation, -k cs): the same binary; its clock accumulates the step (9.99999999999983
#: for 10 s), which the FMU's nanosecond snapping absorbs, and its CSV has 17 significant digits
#: (%.16E), which read back exactly (measured 0.0); held to fmusim's bound.
AGREEMENT = {"libcosim": 1e-12, "fmusim": 1e-15, "fmuCheck": 1e-15}

#: How long one host may take for one mechanism (s).
TIMEOUT = 600.0


class HostError(Exception):
    """Bad input for a host run (no such fmusim, ...): the message names what is wrong."""


@dataclass(frozen=True)
class Experiment:
    """One run: 0..stop s, communication step ``step`` s, the FMU's rtol and atol start values."""

    stop: float = 20.0
    step: float = 0.01
    rtol: float = 1e-12
    atol: float = 1e-12

    @property
    def steps(self) -> int:
        return round(self.stop / self.step)

    @property
    def start_values(self) -> dict[str, float]:
        return {"rtol": self.rtol, "atol": self.atol}


@dataclass(frozen=True)
class HostRun:
    """What one host produced: ``values[i, j]`` is output ``outputs[j]`` at ``time[i]``.

    ``time`` and ``values`` are None when the host gave no readable result; ``message`` then
    says why (the host's own last words).  ``exit_code`` is the host process's status.
    """

    host: str
    outputs: tuple[str, ...]
    time: np.ndarray | None
    values: np.ndarray | None
    exit_code: int
    wall_s: float
    message: str = ""

    @property
    def ok(self) -> bool:
        return self.exit_code == 0 and self.values is not None


@dataclass(frozen=True)
class Agreement:
    """A host's run against FMPy's: the largest |difference| and whether it is within the bound."""

    host: str
    rows: int
    max_difference: float | None     # over every output and row, in the output's unit
    worst_output: str | None         # the output and time of max_difference
    worst_time: float | None
    max_scaled: float | None         # max of |difference| / max(1, |FMPy's value|): what the bound limits
    exit_code: int
    wall_s: float
    tolerance: float | None          # AGREEMENT[host], None for FMPy itself
    problem: str                     # "" when the host agrees

    @property
    def agrees(self) -> bool:
        return not self.problem


# --- the hosts ---------------------------------------------------------------------------------

def output_names(fmu: Path) -> tuple[str, ...]:
    """The FMU's outputs in model-description order."""
    from fmpy import read_model_description
    return tuple(v.name for v in read_model_description(str(fmu)).modelVariables if v.causality == "output")


_FMPY_CHILD = """
import json, sys, time
import numpy as np
from fmpy import simulate_fmu
fmu, out, spec = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
start = time.perf_counter()
result = simulate_fmu(fmu, stop_time=spec["stop"], output_interval=spec["step"],
                      start_values=spec["start_values"], output=spec["outputs"])
wall = time.perf_counter() - start
np.savez(out, time=result["time"], values=np.column_stack([result[n] for n in spec["outputs"]]), wall=wall)
"""

# libcosimpy 0.0.6 trims time_series_real_samples' result by counting zero step numbers, so
# with from_step=0 it drops the last real sample; steps 0 and 1..N are read apart and their
# numbers checked (as examples/libcosim_case2.py does; docs/fmi_hosts.md, "libcosimpy 0.0.6 bug").
_LIBCOSIM_CHILD = """
import json, sys, time
import numpy as np
from libcosimpy.CosimEnums import CosimVariableType
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimObserver import CosimObserver
from libcosimpy.CosimSlave import CosimLocalSlave
log_output_level(CosimLogLevel.WARNING)          # libcosim logs every FMI call by default
fmu, out, spec = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
NS = 1_000_000_000                               # libcosim counts time in integer nanoseconds
step_ns = round(spec["step"] * NS)
n = round(spec["stop"] * NS) // step_ns
start = time.perf_counter()
execution = CosimExecution.from_step_size(step_size=step_ns)
index = execution.add_local_slave(local_slave=CosimLocalSlave(fmu_path=fmu, instance_name="mechanism"))
if index < 0:
    sys.exit(f"libcosim could not load {fmu}")
refs = {v.name.decode(): v.reference for v in execution.slave_variables(index)}
for name, value in spec["start_values"].items():
    if not execution.real_initial_value(index, refs[name], value):
        sys.exit(f"libcosim refused the initial value {name} = {value}")
observer = CosimObserver.create_time_series(buffer_size=n + 10)
execution.add_observer(observer=observer)
for name in spec["outputs"]:
    observer.start_time_series(index, refs[name], CosimVariableType.REAL)
if not execution.step(n) or execution.status().current_time != n * step_ns:
    sys.exit(f"libcosim's execution stopped at t = {execution.status().current_time / NS} s of {spec['stop']} s")
columns = []
for name in spec["outputs"]:
    t0, s0, v0 = observer.time_series_real_samples(index, refs[name], from_step=0, sample_count=1 + n)
    t1, s1, v1 = observer.time_series_real_samples(index, refs[name], from_step=1, sample_count=n)
    steps = list(s0[:1]) + list(s1)
    if steps != list(range(n + 1)):
        sys.exit(f"{name}: the observer returned steps {steps[:3]}...{steps[-3:]}, expected 0..{n}")
    times = np.array(list(t0[:1]) + list(t1), dtype=np.int64) / NS
    columns.append(list(v0[:1]) + list(v1))
wall = time.perf_counter() - start
np.savez(out, time=times, values=np.array(columns).T, wall=wall)
"""


def _python_host(host: str, code: str, fmu: Path, outputs: tuple[str, ...], experiment: Experiment,
                 workdir: Path) -> HostRun:
    """``python -c code FMU OUT.npz SPEC`` with an empty environment; its arrays, or why not."""
    out = workdir / f"{host}.npz"
    spec = json.dumps({"stop": experiment.stop, "step": experiment.step,
                       "start_values": experiment.start_values, "outputs": list(outputs)})
    start = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, "-c", code, str(Path(fmu).resolve()), str(out), spec],
                              cwd=workdir, env={}, capture_output=True, text=True, timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        return HostRun(host, outputs, None, None, -1, time.perf_counter() - start, f"no result after {TIMEOUT:g} s")
    if proc.returncode != 0 or not out.exists():
        return HostRun(host, outputs, None, None, proc.returncode, time.perf_counter() - start,
                       _last_words(proc.stderr or proc.stdout) or "no output file")
    with np.load(out) as data:
        return HostRun(host, outputs, data["time"], np.atleast_2d(data["values"]), 0, float(data["wall"]))


def run_fmpy(fmu: Path, outputs: tuple[str, ...], experiment: Experiment, workdir: Path) -> HostRun:
    """``fmpy.simulate_fmu`` in a child process with an empty environment."""
    return _python_host("FMPy", _FMPY_CHILD, fmu, outputs, experiment, workdir)


def run_libcosim(fmu: Path, outputs: tuple[str, ...], experiment: Experiment, workdir: Path) -> HostRun:
    """libcosim (libcosimpy) in a child process with an empty environment."""
    return _python_host("libcosim", _LIBCOSIM_CHILD, fmu, outputs, experiment, workdir)


def _find_tool(explicit: str | None, option: str, variable: str, program: str, build: str) -> Path | None:
    """``explicit`` (given as ``option``), else the environment variable ``variable``, else
    ``program`` on PATH; None when there is none.  A named path that is not an executable file
    raises HostError saying how to ``build`` one."""
    named, where = (explicit, option) if explicit else (os.environ.get(variable), f"${variable}")
    if named:
        path = Path(named).expanduser()
        if not path.is_file() or not os.access(path, os.X_OK):
            raise HostError(f"{where} = {named}: not an executable file ({build})")
        return path.resolve()
    found = shutil.which(program)
    return Path(found).resolve() if found else None


def find_fmusim(explicit: str | None = None) -> Path | None:
    """``explicit``, else $FMUSIM, else ``fmusim`` on PATH; None when there is none.

    A path that is named (argument or $FMUSIM) but is not an executable file raises HostError.
    """
    return _find_tool(explicit, "--fmusim", "FMUSIM", "fmusim",
                      "build fmusim with scripts/build_fmusim.sh SRC_DIR OUT_DIR")


def fmusim_version(fmusim: Path) -> str:
    proc = subprocess.run([str(fmusim), "--version"], env={}, capture_output=True, text=True, timeout=60)
    return proc.stdout.strip() or f"fmusim (--version exited {proc.returncode})"


def run_fmusim(fmusim: Path, fmu: Path, outputs: tuple[str, ...], experiment: Experiment,
               workdir: Path, model_exchange_tolerance: float | None = None) -> HostRun:
    """fmusim's run with an empty environment, its CSV read back: co-simulation, or with
    ``model_exchange_tolerance`` model exchange integrated by fmusim's CVode at that relative
    tolerance."""
    out = workdir / "fmusim.csv"
    interface = ["cs"] if model_exchange_tolerance is None else \
        ["me", "--solver", "cvode", "--tolerance", repr(model_exchange_tolerance)]
    command = [str(fmusim), "--interface-type", *interface, "--stop-time", repr(experiment.stop),
               "--output-interval", repr(experiment.step)]
    for name, value in experiment.start_values.items():
        command += ["--start-value", name, repr(value)]
    for name in outputs:
        command += ["--output-variable", name]
    command += ["--output-file", str(out), str(Path(fmu).resolve())]
    out.unlink(missing_ok=True)          # never read an earlier run's file as this one's
    start = time.perf_counter()
    try:
        proc = subprocess.run(command, cwd=workdir, env={}, capture_output=True, text=True, timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        return HostRun("fmusim", outputs, None, None, -1, time.perf_counter() - start,
                       f"no result after {TIMEOUT:g} s")
    wall = time.perf_counter() - start
    if proc.returncode != 0 or not out.exists():
        return HostRun("fmusim", outputs, None, None, proc.returncode, wall,
                       _last_words(proc.stderr + proc.stdout) or "no output file")
    with open(out, encoding="utf-8") as file:
        header = [name.strip('"') for name in file.readline().strip().split(",")]
    if header != ["time", *outputs]:
        return HostRun("fmusim", outputs, None, None, proc.returncode, wall,
                       f"its CSV has the columns {header}, expected time and {list(outputs)}")
    data = np.loadtxt(out, delimiter=",", skiprows=1, ndmin=2)
    return HostRun("fmusim", outputs, data[:, 0], data[:, 1:], proc.returncode, wall)


def find_fmucheck(explicit: str | None = None) -> Path | None:
    """``explicit``, else $FMUCHECK, else ``fmuCheck.linux64`` on PATH; None when there is none
    (scripts/build_fmucheck.sh builds it).  A named path that is not an executable raises HostError."""
    return _find_tool(explicit, "--fmucheck", "FMUCHECK", "fmuCheck.linux64",
                      "build the FMU Compliance Checker with scripts/build_fmucheck.sh CHECKER_SRC FMIL_SRC OUT_DIR")


@dataclass(frozen=True)
class CheckerRun:
    """The FMU Compliance Checker's run: its table (None when it failed) and its own count of
    errors and warnings in the FMU (``checker_errors``: what it found wrong, XML included)."""

    run: HostRun
    checker_errors: int | None
    checker_warnings: int | None
    log: str


def run_fmucheck(fmucheck: Path, fmu: Path, outputs: tuple[str, ...], stop: float, step: float, points: int,
                 workdir: Path, interface: str = "me") -> CheckerRun:
    """fmuCheck ``-k interface`` (``me``: forward Euler with step ``step``; ``cs``: communication
    step ``step``) to ``stop``, ``points`` output rows taken at the steps, with an empty environment."""
    out = workdir / "fmucheck.csv"
    command = [str(fmucheck), "-k", interface, "-h", repr(step), "-s", repr(stop), "-n", str(points), "-l", "3",
               "-t", str(workdir), "-o", str(out), str(Path(fmu).resolve())]
    start = time.perf_counter()
    try:
        proc = subprocess.run(command, cwd=workdir, env={}, capture_output=True, text=True, timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        return CheckerRun(HostRun("fmuCheck", outputs, None, None, -1, time.perf_counter() - start,
                                  f"no result after {TIMEOUT:g} s"), None, None, "")
    wall = time.perf_counter() - start
    log = proc.stderr + proc.stdout

    def count(label: str) -> int | None:
        found = [line for line in log.splitlines() if line.strip().endswith(label)]
        return int(found[-1].split()[0]) if found and found[-1].split()[0].isdigit() else None

    errors, warnings = count("Error(s)"), count("Warning(s)")
    if proc.returncode != 0 or not out.exists() or out.stat().st_size == 0:
        return CheckerRun(HostRun("fmuCheck", outputs, None, None, proc.returncode, wall,
                                  _last_words(log) or "no output file"), errors, warnings, log)
    with open(out, encoding="utf-8") as file:
        header = [name.strip('"') for name in file.readline().strip().split(",")]
    data = np.loadtxt(out, delimiter=",", skiprows=1, ndmin=2)
    columns = [header.index(name) for name in ("time", *outputs) if name in header]
    if len(columns) != len(outputs) + 1:
        return CheckerRun(HostRun("fmuCheck", outputs, None, None, proc.returncode, wall,
                                  f"its CSV lacks some of {list(outputs)}"), errors, warnings, log)
    return CheckerRun(HostRun("fmuCheck", outputs, data[:, columns[0]], data[:, columns[1:]], proc.returncode, wall),
                      errors, warnings, log)


def _last_words(text: str, lines: int = 3) -> str:
    return " | ".join(line.strip() for line in text.strip().splitlines()[-lines:] if line.strip())


# --- the comparison ----------------------------------------------------------------------------

def compare(run: HostRun, reference: HostRun, experiment: Experiment) -> Agreement:
    """``run`` against FMPy's ``reference``: every output, every communication point."""
    tolerance = AGREEMENT.get(run.host)
    rows = 0 if run.values is None else len(run.values)

    def result(problem: str, diff: float | None = None, worst: str | None = None, when: float | None = None,
               scaled: float | None = None):
        return Agreement(run.host, rows, diff, worst, when, scaled, run.exit_code, run.wall_s, tolerance, problem)

    if not run.ok:
        return result(f"exit {run.exit_code}: {run.message}")
    expected_rows = experiment.steps + 1
    if rows != expected_rows:
        return result(f"{rows} rows, expected {expected_rows} (0..{experiment.stop:g} s every {experiment.step:g} s)")
    grid = experiment.step * np.arange(expected_rows)
    # libcosim reports ns / 1e9, fmusim prints 16 digits, FMPy n * step: round-off apart at most
    off_grid = np.abs(run.time - grid) > 1e-9
    if off_grid.any():
        i = int(np.argmax(off_grid))
        return result(f"communication point {i} at t = {run.time[i]!r} s, expected {grid[i]:g} s")
    if run is reference:
        return result("")
    if reference.values is None or reference.values.shape != run.values.shape:
        return result("no FMPy result to compare with")
    diff = np.abs(run.values - reference.values)
    if not np.isfinite(run.values).all():
        return result("non-finite outputs")
    row, col = np.unravel_index(int(np.argmax(diff)), diff.shape)
    worst, when, largest = run.outputs[col], float(reference.time[row]), float(diff[row, col])
    scaled = diff / np.maximum(1.0, np.abs(reference.values))
    if scaled.max() > tolerance:
        r, c = np.unravel_index(int(np.argmax(scaled)), scaled.shape)
        return result(f"{run.outputs[c]} at t = {reference.time[r]:.2f} s differs by {diff[r, c]:.3e} "
                      f"(FMPy {reference.values[r, c]!r}), more than {tolerance:g} x max(1, |value|)",
                      largest, worst, when, float(scaled.max()))
    return result("", largest, worst, when, float(scaled.max()))


# --- building and the whole benchmark ----------------------------------------------------------

"""What many test modules share: the repository's paths and the one case-file helper."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
FOURBAR_RUN = str(BIN / "fourbar-run")
FOURBAR_MONITOR = str(BIN / "fourbar-monitor")


def case_file(case: str, fmu: Path, dest: Path, *, name: str | None = None, extra: str = "", **settings) -> Path:
    """``cases/<case>.toml`` copied with its ``fmu`` set to the FMU under test; returns the copy.

    ``dest`` is a directory (the copy is ``dest/<case>.toml``) or a file path.  ``name``
    replaces the case's name; ``settings`` replace existing ``key = value`` lines (e.g.
    ``flush_interval=0.5``); ``extra`` TOML is appended.
    """
    text = (REPO / "cases" / f"{case}.toml").read_text(encoding="utf-8")
    text, count = re.subn(r"(?m)^fmu\s*=.*$", f"fmu = {json.dumps(Path(fmu).as_posix())}", text)
    assert count == 1, f"cases/{case}.toml: no fmu line"
    if name is not None:
        text, count = re.subn(r"(?m)^name\s*=.*$", f"name = {json.dumps(name)}", text)
        assert count == 1, f"cases/{case}.toml: no name line"
    for key, value in settings.items():
        text, count = re.subn(rf"(?m)^{key} = \S+", f"{key} = {value!r}", text)
        assert count == 1, f"cases/{case}.toml: no {key} line"
    path = dest / f"{case}.toml" if dest.is_dir() else dest
    path.write_text(text + extra, encoding="utf-8")
    return path


#: Table 1's link centres: the paper's exchange columns, and fourbar-run's default outputs.
CENTRES = ("x2", "y2", "x3", "y3", "x4", "y4")


def recorded_columns(fmu: Path, named=CENTRES) -> list[str]:
    """The exchange file's columns after ``time`` for a case naming ``named`` on ``fmu``:
    ``named``, then the columns of the FMU's drawing (read here from modelDescription.xml,
    not through the orchestrator) that ``named`` lacks."""
    import zipfile

    from fourbar_common import Drawing

    with zipfile.ZipFile(fmu) as z:
        drawing = Drawing.from_model_description(z.read("modelDescription.xml"))
    extra = [c for c in drawing.columns if c not in named] if drawing is not None else []
    return [*named, *extra]


def unwritable_folder(tmp_path: Path) -> Path:
    """An existing folder this process cannot create files in: a 0o555 folder, or for root (who
    ignores modes) a read-only system folder; skips the test when there is none."""
    import pytest

    folder = tmp_path / "read-only"
    folder.mkdir()
    folder.chmod(0o555)
    for candidate in [folder] + ([Path("/sys"), Path("/proc")] if os.geteuid() == 0 else []):
        try:
            (candidate / ".fourbar-probe").mkdir()
        except OSError:
            return candidate
        (candidate / ".fourbar-probe").rmdir()
    pytest.skip("no folder here refuses this process's writes")


# -- one FMU flavour against another (tests/test_fmu_model_exchange.py, test_fmu_fmi3.py) --------
# Their tolerances and the outputs compared live in fmu_src/fmi_flavours.py, which the benchmark
# that reports the same comparisons (benchmarks/fmi_flavours.py, docs/fmi_hosts.md's flavour
# table) imports too: one home.
from fmu_src import fmi_hosts  # noqa: E402
from fmu_src.fmi_flavours import (COSIM_TOL, CVODE_RTOL, FLAVOUR_AGREE, flavour_span,  # noqa: E402,F401
                                  lengths_and_angles)


def fmusim_or_skip() -> Path:
    """The fmusim to test with ($FMUSIM or PATH); the test is skipped where there is none, and
    fails when $FMUSIM names something that is not one (say so, do not skip)."""
    try:
        found = fmi_hosts.find_fmusim()
    except fmi_hosts.HostError as exc:
        pytest.fail(str(exc))
    if found is None:
        pytest.skip("no fmusim: set FMUSIM=/path/to/fmusim or put fmusim on PATH. fmusim is built from the "
                    "Modelica Reference-FMUs' sources (v0.0.39, the last version with fmusim) by "
                    "scripts/build_fmusim.sh SRC_DIR OUT_DIR; docs/fmi_hosts.md, 'Every shipped mechanism in "
                    "three hosts'")
    return found


def fmucheck_or_skip() -> Path:
    """The FMU Compliance Checker ($FMUCHECK or fmuCheck.linux64 on PATH), as fmusim_or_skip."""
    try:
        found = fmi_hosts.find_fmucheck()
    except fmi_hosts.HostError as exc:
        pytest.fail(str(exc))
    if found is None:
        pytest.skip("no FMU Compliance Checker: set FMUCHECK=/path/to/fmuCheck.linux64 or put it on PATH "
                    "(scripts/build_fmucheck.sh builds it)")
    return found

#: constraint_residual of every row whatever the host's tolerances (coordinate partitioning).
RESIDUAL = 1e-12




# -- FMU log messages in a test ----------------------------------------------------------
# FMPy's logger proxy (fmpy.logging.addLoggerProxy formats an FMU's printf-style message) keeps
# the Python logger of the LAST callbacks given to it in one process-wide C variable, which
# FMPy's own default callbacks (simulate_fmu, an FMU2Slave instantiated without callbacks) go
# through too.  A test's own ctypes logger would be freed with the test and leave that variable
# dangling (the next FMU that logs in the worker segfaults), or, kept alive, would swallow the
# messages FMPy prints for the tests after it.  So every test logger is this one router, alive
# for the process: a message goes to the sink registered for the instance's componentEnvironment,
# any other to FMPy's printer (orchestrator/fmi_versions.py does the same for fourbar-run).
_SINKS: dict[int, object] = {}
_KEPT: list = []


def _route_message(env, instance_name, status, category, message) -> None:
    from fmpy.fmi1 import printLogMessage

    sink = _SINKS.get(env or 0)
    if sink is None:
        printLogMessage(env, instance_name, status, category, message)
    else:
        sink(status, message.decode(errors="replace"))


_ROUTER = None


def logged_callbacks(sink):
    """FMI 2.0 callbacks (for ``FMU2Slave.instantiate(callbacks=...)``) whose messages, formatted,
    go to ``sink(status, text)``; kept alive for the process."""
    global _ROUTER
    from ctypes import byref

    from fmpy.fmi2 import (calloc, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                           fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, free)
    from fmpy.logging import addLoggerProxy

    if _ROUTER is None:
        _ROUTER = fmi2CallbackLoggerTYPE(_route_message)
    env = 1_000_000 + len(_KEPT)            # apart from the orchestrator's ids (1, 2, ...)
    _SINKS[env] = sink
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = _ROUTER
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    callbacks.componentEnvironment = env
    addLoggerProxy(byref(callbacks))
    _KEPT.append(callbacks)
    return callbacks


def wait_for_rows(out: Path, proc: subprocess.Popen, rows: int = 1, guard: float = 120.0) -> dict:
    """run.json of ``out`` once it says ``running`` with at least ``rows`` rows; fails the test
    if ``proc`` ends first or nothing comes within ``guard`` s (a hang guard, not a timing)."""
    deadline = time.monotonic() + guard
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        try:
            record = json.loads((out / "run.json").read_text())
        except (OSError, ValueError):
            record = {}
        if record.get("status") == "running" and record.get("rows_written", 0) >= rows:
            return record
        time.sleep(0.05)
    proc.kill()
    pytest.fail(f"the run into {out} never started writing rows")


# -- the independent theta2 formulation, computed once per test session -------------------------
def cached_theta2_reference(folder: Path, times, th2_0: float, switches: tuple = (), **params):
    """``reference_theta2.simulate(times, th2_0, switches=switches, **params)``, read from ``folder``
    when a process of this session (an xdist worker too) has computed it already.  A 100 s run of
    the reference costs ~15 s of CPU, and test_fmu_physics.py (each FMU) and test_fmu_native.py
    ask for the same Cases 1 and 2.  The key hashes the arguments and reference_theta2.py's own
    text; the file is written whole (os.replace) under a lock, so a reader never sees a part."""
    import numpy as np

    import reference_theta2

    times = np.asarray(times, dtype=float)
    key = (repr((th2_0, tuple((t, sorted(p.items())) for t, p in switches), sorted(params.items()))).encode()
           + times.tobytes() + Path(reference_theta2.__file__).read_bytes())
    return shared_result(folder, "theta2", key,
                         lambda: reference_theta2.simulate(times, th2_0, switches=switches, **params))


def shared_result(folder: Path, name: str, key: bytes, compute):
    """``compute()``, or its result as a process of this test session (an xdist worker too)
    computed it already with the same ``key`` (bytes: every input the result depends on).

    The suite's workers are separate processes, and a module's tests (with its module-scoped
    fixtures) can run on both of them when one steals the other's tests: an expensive run made
    by a fixture would then be made twice.  The result is pickled to ``folder`` (the session's
    shared temporary folder, so nothing outlives the session) whole (os.replace) under a lock
    file, so the other worker waits for it instead of computing it again and never reads a
    part.  Numpy arrays come back read-only (a test cannot change what another one reads)."""
    import hashlib
    import pickle

    import numpy as np

    digest = hashlib.sha256(key).hexdigest()[:32]
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{name}-{digest}.pickle"
    try:
        import fcntl
    except ImportError:                         # no flock (Windows): each process computes its own
        fcntl = None
    with open(folder / f"{name}-{digest}.lock", "w") as lock:
        if fcntl is not None:
            fcntl.flock(lock, fcntl.LOCK_EX)    # the other worker waits for the file, not computes it again
        if not path.exists():
            result = compute()
            partial = path.with_suffix(f".{os.getpid()}.tmp")
            with open(partial, "wb") as f:
                pickle.dump(result, f, protocol=pickle.HIGHEST_PROTOCOL)
            os.replace(partial, path)
    with open(path, "rb") as f:
        result = pickle.load(f)
    for value in (result.values() if isinstance(result, dict) else [result]):
        if isinstance(value, np.ndarray):
            value.setflags(write=False)
    return result


def shared_folder_of(tmp_path_factory) -> Path:
    """The folder of this test session that every xdist worker sees (``shared_result``'s)."""
    base = tmp_path_factory.getbasetemp()
    # under xdist every worker's basetemp is <the session's folder>/popen-gwN: share the parent
    shared = base.parent if base.name.startswith("popen-gw") else base
    return shared / "shared-results"


def file_key(*paths: Path) -> bytes:
    """The contents of ``paths`` as part of a ``shared_result`` key (an FMU rebuilt mid-session
    is a different input)."""
    import hashlib

    return b"".join(hashlib.sha256(Path(p).read_bytes()).digest() for p in paths)


# -- the order of the suite's modules (conftest.pytest_collection_modifyitems) ------------------
def two_halves(modules: dict[str, tuple[float, int]]) -> list[str]:
    """The modules (name: (cost, number of tests)) in the order they should be collected: two
    groups of about equal cost, the first holding at least half of the tests (so the second
    worker's share begins inside it at the latest), each group's modules by cost per test, the
    costliest first (a module of many cheap tests last: the first worker's half ends in it)."""
    groups: list[list[str]] = [[], []]
    cost, count = [0.0, 0.0], [0, 0]
    for name in sorted(modules, key=lambda m: -modules[m][0]):       # stable: ties keep their order
        g = 0 if (cost[0], count[0]) <= (cost[1], count[1]) else 1
        groups[g].append(name)
        cost[g] += modules[name][0]
        count[g] += modules[name][1]
    first, second = groups if count[0] >= count[1] else groups[::-1]
    density = {m: c / max(n, 1) for m, (c, n) in modules.items()}
    return sorted(first, key=lambda m: -density[m]) + sorted(second, key=lambda m: -density[m])


def edited_mechanism_message(mechanism: Path, old: str, new: str, tmp_path: Path) -> tuple[Path, str]:
    """``mechanism``'s text with ``old`` replaced by ``new`` once, loaded from ``tmp_path/mine.toml``:
    the file and the MechanismError's message (the edit must apply and the load must fail)."""
    from fmu_src.mechanism.description import MechanismError, load_mechanism

    text = mechanism.read_text()
    assert old in text
    path = tmp_path / "mine.toml"
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(MechanismError) as info:
        load_mechanism(path)
    return path, str(info.value)


def build_fmu_refusal(path: Path, tmp_path: Path) -> subprocess.CompletedProcess:
    """``build_fmu.py`` run on the mechanism file ``path``, into ``tmp_path/out``: expected to refuse it."""
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "build_fmu.py", "--mechanism", str(path), "--out", str(out / "a.fmu"),
                           "--native-out", str(out / "b.fmu")], cwd=REPO, capture_output=True, text=True,
                          timeout=600)     # a hang guard only: a refusal takes seconds
    proc.out = out
    return proc


# -- the shipped mechanisms the per-mechanism loops sweep ----------------------------------------
#: Shipped published benchmarks (fmu_src.mechanism.description.PUBLISHED_BENCHMARKS), each checked
#: against its publication's reference solution in its own test file.
BENCHMARK_MECHANISMS = {"andrews_squeezer": "tests/test_andrews_squeezer.py",
                       "iftomm_pendulum": "tests/test_iftomm_pendulum.py"}


def swept_mechanisms() -> tuple[str, ...]:
    """The shipped mechanisms but the published benchmarks, which run only over their short span."""
    from fmu_src.mechanism.description import PUBLISHED_BENCHMARKS, shipped_mechanisms

    assert set(BENCHMARK_MECHANISMS) == set(PUBLISHED_BENCHMARKS), "name each benchmark's test file"
    return shipped_mechanisms(benchmarks=False)

"""Shared fixtures: the built FourBar FMU and the repository paths.

`make test` builds build/FourBar.fmu before running pytest; when it is missing (pytest run
by hand on a fresh clone) the fixture builds a private copy, in a child process.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest


# A job started in the background by a non-interactive shell (as CI or `make test &` may
# be) inherits SIGINT *ignored*, and so does every child; Python then installs no
# KeyboardInterrupt handler, and the Ctrl-C tests of fourbar-run and fourbar-sweep would see
# no Ctrl-C at all.  Restore the terminal's disposition: a handler here (unlike SIG_IGN)
# is reset to the default across exec, so the children start as from a terminal.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# The tests load pythonfmu FMUs with plain FMPy and libcosim too; without this guard the
# test process can abort at exit after all tests passed (orchestrator/pythonfmu_workarounds.py).
from orchestrator import install_pythonfmu_exit_guard  # noqa: E402
from support import REPO

install_pythonfmu_exit_guard()


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return REPO


def _fresh(built: Path, patterns: tuple[str, ...] = ("*.py", "*.c", "*.h", "*.toml")) -> bool:
    """``built`` exists and is newer than every source file matching ``patterns`` under fmu_src/."""
    sources = [p for pattern in patterns for p in (REPO / "fmu_src").rglob(pattern)] + [REPO / "build_fmu.py"]
    return built.exists() and built.stat().st_mtime >= max(p.stat().st_mtime for p in sources)


@pytest.fixture(scope="session")
def native_fmu(tmp_path_factory) -> Path:
    """Path of a valid FourBarNative.fmu (FOURBAR_NATIVE_FMU, else build/, else a fresh build).

    Skips the test when no C compiler is available (the native FMU cannot be built then).
    """
    env = os.environ.get("FOURBAR_NATIVE_FMU")
    if env:
        return Path(env)
    built = REPO / "build" / "FourBarNative.fmu"
    if _fresh(built, ("*.py", "*.c", "*.h")):
        return built
    from fmu_src.native_build import find_compiler
    if find_compiler() is None:
        pytest.skip("no C compiler: the native FMU cannot be built here")
    dest = tmp_path_factory.mktemp("native") / "FourBarNative.fmu"
    subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--only", "native", "--native-out", str(dest)],
                   check=True, cwd=REPO)
    return dest


@pytest.fixture(scope="session")
def fourbar_fmu(tmp_path_factory) -> Path:
    """Path of a valid FourBar.fmu (FOURBAR_FMU, else build/FourBar.fmu, else a fresh build)."""
    env = os.environ.get("FOURBAR_FMU")
    if env:
        return Path(env)
    built = REPO / "build" / "FourBar.fmu"
    if _fresh(built, ("*.py", "*.toml")):
        return built
    dest = tmp_path_factory.mktemp("fmu") / "FourBar.fmu"
    subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--only", "pythonfmu", "--out", str(dest)],
                   check=True, cwd=REPO)
    return dest


@pytest.fixture(scope="session", params=["pythonfmu", "native"])
def either_fmu(request) -> Path:
    """Each of the two FMUs in turn (tests that must hold for both: parametrized, not copied)."""
    return request.getfixturevalue("fourbar_fmu" if request.param == "pythonfmu" else "native_fmu")


class MechanismFMUs:
    """The FMUs of the shipped mechanisms, built once per session on first use.

    ``get("slider_crank", "native")`` is the path of SliderCrankNative.fmu (``"native3"``: its
    FMI 3.0 twin SliderCrankNative3.fmu): build/'s copy when it is newer than every source
    (``python build_fmu.py --mechanism slider_crank`` writes them), else a private build in the
    session's temporary folder, made once for every xdist worker (support.shared_result).  A
    test mechanism file's path works too.  The native kinds skip the test when there is no C
    compiler.
    """

    def __init__(self, factory):
        self._factory = factory
        self._built: dict[tuple[str, str], Path] = {}
        from support import shared_folder_of
        self._shared = shared_folder_of(factory)

    def get(self, mechanism: str, kind: str = "pythonfmu") -> Path:
        key = (mechanism, kind)
        if key in self._built:
            return self._built[key]
        from fmu_src.mechanism.description import load_mechanism
        name = load_mechanism(mechanism).name + {"pythonfmu": "", "native": "Native", "native3": "Native3"}[kind]
        built = REPO / "build" / f"{name}.fmu"
        if not _fresh(built, ("*.py", "*.toml") if kind == "pythonfmu" else ("*.py", "*.c", "*.h", "*.toml")):
            if kind != "pythonfmu":
                from fmu_src.native_build import find_compiler
                if find_compiler() is None:
                    pytest.skip("no C compiler: the native FMU cannot be built here")
            option = {"native": ["--only", "native", "--fmi", "2", "--native-out"],
                      "native3": ["--only", "native", "--fmi", "3", "--native3-out"],
                      "pythonfmu": ["--only", "pythonfmu", "--out"]}[kind]

            def build() -> Path:
                fmu = self._factory.mktemp(name) / f"{name}.fmu"
                subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--mechanism", mechanism, *option,
                                str(fmu)], check=True, cwd=REPO, capture_output=True)
                return fmu

            # one build per session, also when both xdist workers ask (a test mechanism file, as
            # tests/mechanisms/quick_return.toml, is asked for by several modules: ~10-25 s a build)
            from support import file_key, shared_result
            source = Path(mechanism)
            shared_key = repr((str(mechanism), kind)).encode() + (file_key(source) if source.is_file() else b"")
            built = shared_result(self._shared, "mechanism-fmu", shared_key, build)
        self._built[key] = built
        return built


@pytest.fixture(scope="session")
def mechanism_fmus(tmp_path_factory) -> MechanismFMUs:
    """Builds (once) and finds the FMUs of the shipped mechanisms: ``mechanism_fmus.get(name, kind)``."""
    return MechanismFMUs(tmp_path_factory)


@pytest.fixture(scope="session")
def shared_folder(tmp_path_factory) -> Path:
    """A folder of this test session that every xdist worker sees (support.shared_result's)."""
    from support import shared_folder_of

    return shared_folder_of(tmp_path_factory)


@pytest.fixture(scope="session")
def theta2_reference(shared_folder):
    """``reference_theta2.simulate`` computed once per session, shared by the xdist workers
    (support.cached_theta2_reference): ``theta2_reference(times, th2_0, switches=(), **params)``."""
    import functools

    from support import cached_theta2_reference

    return functools.partial(cached_theta2_reference, shared_folder)


# -- the order the tests run in: each worker's expensive modules first -------------------------
# `make test` runs on two xdist workers with --dist worksteal: the first worker starts with the
# first half of the collected tests (by count), the second with the rest, and one that runs out
# steals half of what the other has left, from its end.  In pytest's order (by file name) a slow
# module collected late ran alone at the end while the other core idled, and a module split by a
# steal made its module-scoped fixtures on both workers.  So whole modules (their tests kept
# together and in pytest's order, so a module-scoped fixture is made once per worker) are dealt
# into two halves of about equal cost, each half with its costly modules first: each worker
# begins with its share of the slow work, and what is left to steal at the end is the fast tests.
# A module's cost: the seconds it took in the last run that ran it whole (recorded in pytest's
# cache, .pytest_cache/, by the process that runs the session), or on a first run 20 s per test
# marked slow.  Only the order changes: every test still runs.
_DURATIONS_KEY = "fourbar/module_seconds"


def _module(nodeid: str) -> str:
    return nodeid.split("::", 1)[0]


@pytest.hookimpl(trylast=True)          # after pytest's own reordering (by fixture parameters)
def pytest_collection_modifyitems(session, config, items):
    cache = getattr(config, "cache", None)            # None with -p no:cacheprovider
    recorded = cache.get(_DURATIONS_KEY, {}) if cache is not None else {}
    slow: dict[str, int] = {}
    count: dict[str, int] = {}
    for item in items:
        module = _module(item.nodeid)
        count[module] = count.get(module, 0) + 1
        slow[module] = slow.get(module, 0) + (item.get_closest_marker("slow") is not None)

    def cost(module: str) -> float:
        seconds = recorded.get(module)
        return float(seconds) if isinstance(seconds, (int, float)) else 20.0 * slow[module] + 0.05 * count[module]

    from support import two_halves

    rank = {m: n for n, m in enumerate(two_halves({m: (cost(m), count[m]) for m in count}))}
    items.sort(key=lambda item: rank[_module(item.nodeid)])     # stable: a module's own order kept


class _ModuleSeconds:
    """Adds up each module's setup, call and teardown seconds (on the process that receives
    every report: the controller under xdist) and records them in pytest's cache."""

    def __init__(self, config):
        self.config = config
        self.seconds: dict[str, float] = {}

    def pytest_runtest_logreport(self, report):
        module = _module(report.nodeid)
        self.seconds[module] = self.seconds.get(module, 0.0) + report.duration

    def pytest_sessionfinish(self, session, exitstatus):
        cache = getattr(self.config, "cache", None)
        option = self.config.option
        # a selection (-k, -m, a test's id) or an interrupted run times part of a module: keep the
        # whole module's figure
        partial = (option.keyword or option.markexpr or any("::" in str(a) for a in self.config.args)
                   or exitstatus == pytest.ExitCode.INTERRUPTED)
        if cache is None or partial or not self.seconds:
            return
        recorded = dict(cache.get(_DURATIONS_KEY, {}))
        recorded.update({module: round(s, 2) for module, s in self.seconds.items()})
        cache.set(_DURATIONS_KEY, recorded)


def pytest_configure(config):
    if not hasattr(config, "workerinput"):        # not on an xdist worker: its controller gets every report
        config.pluginmanager.register(_ModuleSeconds(config), "fourbar-module-seconds")


@pytest.fixture(scope="session")
def motor_fourbar_ssp(mechanism_fmus, tmp_path_factory) -> Path:
    """The shipped bench (systems/motor_fourbar.toml): build/MotorFourBar.ssp when it is newer
    than every source and the system file, else built once into the session's folder."""
    built = REPO / "build" / "MotorFourBar.ssp"
    system_file = REPO / "systems" / "motor_fourbar.toml"
    if _fresh(built) and built.stat().st_mtime >= system_file.stat().st_mtime:
        return built
    from fmu_src.system import build_system

    out = tmp_path_factory.mktemp("bench") / "MotorFourBar.ssp"
    return build_system("motor_fourbar", out, validate=False,
                        prebuilt={"fourbar_motor": mechanism_fmus.get("fourbar_motor", "native")}).path

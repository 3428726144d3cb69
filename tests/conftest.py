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
    session's temporary folder.  The native kinds skip the test when there is no C compiler.
    """

    def __init__(self, factory):
        self._factory = factory
        self._built: dict[tuple[str, str], Path] = {}

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
            built = self._factory.mktemp(name) / f"{name}.fmu"
            option = {"native": ["--only", "native", "--fmi", "2", "--native-out"],
                      "native3": ["--only", "native", "--fmi", "3", "--native3-out"],
                      "pythonfmu": ["--only", "pythonfmu", "--out"]}[kind]
            subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--mechanism", mechanism, *option,
                            str(built)], check=True, cwd=REPO, capture_output=True)
        self._built[key] = built
        return built


@pytest.fixture(scope="session")
def mechanism_fmus(tmp_path_factory) -> MechanismFMUs:
    """Builds (once) and finds the FMUs of the shipped mechanisms: ``mechanism_fmus.get(name, kind)``."""
    return MechanismFMUs(tmp_path_factory)


@pytest.fixture(scope="session")
def theta2_reference(tmp_path_factory):
    """``reference_theta2.simulate`` computed once per session, shared by the xdist workers
    (support.cached_theta2_reference): ``theta2_reference(times, th2_0, switches=(), **params)``."""
    import functools

    from support import cached_theta2_reference

    base = tmp_path_factory.getbasetemp()
    # under xdist every worker's basetemp is <the session's folder>/popen-gwN: share the parent
    shared = base.parent if base.name.startswith("popen-gw") else base
    return functools.partial(cached_theta2_reference, shared / "theta2-reference")

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


def _fresh(built: Path, patterns: tuple[str, ...]) -> bool:
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
    if _fresh(built, ("*.py",)):
        return built
    dest = tmp_path_factory.mktemp("fmu") / "FourBar.fmu"
    subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--only", "pythonfmu", "--out", str(dest)],
                   check=True, cwd=REPO)
    return dest


@pytest.fixture(scope="session", params=["pythonfmu", "native"])
def either_fmu(request) -> Path:
    """Each of the two FMUs in turn (tests that must hold for both: parametrized, not copied)."""
    return request.getfixturevalue("fourbar_fmu" if request.param == "pythonfmu" else "native_fmu")

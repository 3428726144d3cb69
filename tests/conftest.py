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

REPO = Path(__file__).resolve().parents[1]

# A job started in the background by a non-interactive shell (as CI or `make test &` may
# be) inherits SIGINT *ignored*, and so does every child; Python then installs no
# KeyboardInterrupt handler, and the Ctrl-C tests of fourbar-run and fourbar-sweep would see
# no Ctrl-C at all.  Restore the terminal's disposition: a handler here (unlike SIG_IGN)
# is reset to the default across exec, so the children start as from a terminal.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# The tests load pythonfmu FMUs with plain FMPy and libcosim too; without this guard the
# test process can abort at exit after all tests passed (orchestrator/pythonfmu_exit.py).
from orchestrator.pythonfmu_exit import install_exit_hook  # noqa: E402

install_exit_hook()


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return REPO


@pytest.fixture(scope="session")
def fourbar_fmu(tmp_path_factory) -> Path:
    """Path of a valid FourBar.fmu (FOURBAR_FMU, else build/FourBar.fmu, else a fresh build)."""
    env = os.environ.get("FOURBAR_FMU")
    if env:
        return Path(env)
    built = REPO / "build" / "FourBar.fmu"
    sources = list((REPO / "fmu_src").rglob("*.py")) + [REPO / "build_fmu.py"]
    if built.exists() and built.stat().st_mtime >= max(p.stat().st_mtime for p in sources):
        return built
    dest = tmp_path_factory.mktemp("fmu") / "FourBar.fmu"
    subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--out", str(dest)], check=True, cwd=REPO)
    return dest

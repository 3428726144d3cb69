"""The pythonfmu workarounds (orchestrator/pythonfmu_workarounds.py), each shown by its effect.

1. The exit guard: a process that loads a pythonfmu FMU and exits may abort in glibc
   ("corrupted double-linked list", status 134) without the guard, depending on the heap
   layout, so an exit status is no reliable witness.  valgrind is: it reports the exit
   destructor's access to freed memory in the unguarded process and none in the guarded one.
2. The module cache: two builds of FourBar.fmu in one process each run their own code.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import shutil
import subprocess
import sys
import zipfile

import pytest

from orchestrator.pythonfmu_workarounds import release_library
from support import case_file

linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the exit crash is on Linux")

_EXIT_PROGRAM = """
import sys
from fmpy import simulate_fmu
if sys.argv[2] == "guard":
    from orchestrator import install_pythonfmu_exit_guard
    install_pythonfmu_exit_guard()
simulate_fmu(sys.argv[1], stop_time=0.05, output_interval=0.01)
print("simulated")
"""


@linux_only
@pytest.mark.slow
@pytest.mark.skipif(shutil.which("valgrind") is None, reason="needs valgrind (apt install valgrind)")
def test_exit_guard_removes_the_use_after_free_at_exit(fourbar_fmu, repo_root):
    """valgrind sees pythonfmu's exit destructor touch freed memory without the guard, and
    not with it.  (Whether glibc then aborts depends on the heap layout; valgrind does not.)"""
    procs = {mode: subprocess.Popen(["valgrind", "--leak-check=no", sys.executable, "-c", _EXIT_PROGRAM,
                                     str(fourbar_fmu), mode], cwd=repo_root, stdout=subprocess.PIPE,
                                    stderr=subprocess.PIPE, text=True) for mode in ("none", "guard")}
    reports = {}
    for mode, proc in procs.items():
        out, err = proc.communicate(timeout=600)
        assert "simulated" in out, err
        lines = err.splitlines()
        # an error's first frame follows its headline: "Invalid read of size 4" / "at 0x...: finalizePythonInterpreter"
        reports[mode] = [lines[i - 1] + " / " + line for i, line in enumerate(lines)
                         if "finalizePythonInterpreter" in line and i > 0]
    assert any("Invalid" in r for r in reports["none"]), reports["none"]
    assert reports["guard"] == []


@linux_only
def test_finds_and_releases_the_library_fmpy_loaded(fourbar_fmu, repo_root):
    code = f"""
from fmpy import simulate_fmu
from orchestrator.pythonfmu_workarounds import _loaded_fmu_libraries, release_loaded_libraries
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


def patched_copy(fmu, dest):
    """FourBar.fmu whose slave reports x2 = 42 m (same module names, same GUID)."""
    with zipfile.ZipFile(fmu) as zin, zipfile.ZipFile(dest, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "resources/fourbar_model/slave.py":
                text = data.decode()
                line = "            setattr(self, name, value)\n"
                assert text.count(line) == 1
                data = text.replace(line, line + "        self.x2 = 42.0\n").encode()
            zout.writestr(item, data)
    return dest


def test_each_build_runs_its_own_code(fourbar_fmu, tmp_path, repo_root):
    other = patched_copy(fourbar_fmu, tmp_path / "Patched.fmu")
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    case_a = case_file("case1_normal", fourbar_fmu, tmp_path / "a", stop=0.1)
    case_b = case_file("case1_normal", other, tmp_path / "b", stop=0.1)
    code = f"""
import pandas as pd
from orchestrator import run_case
for i, case in enumerate([{str(case_a)!r}, {str(case_b)!r}, {str(case_a)!r}]):
    result = run_case(case, {str(tmp_path)!r} + f"/out{{i}}")
    print(pd.read_csv(result.exchange_path)["x2"].max())
"""
    result = subprocess.run([sys.executable, "-c", code], cwd=repo_root, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    first, patched, again = map(float, result.stdout.split())
    assert first < 1.0            # the crank's centre stays within L2/2 = 0.5 m of the origin
    assert patched == 42.0        # build B's own slave ran
    assert again == first         # and build A's again after it


def test_runs_of_the_same_build_keep_its_modules(fourbar_fmu, tmp_path, repo_root):
    # A sweep worker runs the same FMU hundreds of times, each from a fresh extraction:
    # identical Python files are not imported again.
    case = case_file("case1_normal", fourbar_fmu, tmp_path, stop=0.05)
    code = f"""
import sys
from orchestrator import run_case
ids = []
for i in range(3):
    run_case({str(case)!r}, {str(tmp_path)!r} + f"/out{{i}}")
    ids.append(id(sys.modules["fourbar_slave"]))
print(len(set(ids)))
"""
    result = subprocess.run([sys.executable, "-c", code], cwd=repo_root, capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["1"]

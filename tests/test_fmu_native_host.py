"""The native FMU in a host that is not Python: libcosim's C API from a C program.

tests/native_host/cosim_host.c (the host of docs/fmi_hosts.md) is compiled against the
libcosimc library that the libcosimpy wheel ships, and run with an EMPTY environment
(``env -i``: no PATH, no PYTHONHOME, no LD_PRELOAD).  The native FMU must run Case 2 there,
exit 0, and give FMPy's outputs.  The pythonfmu FMU cannot do this (it needs libpython
preloaded, PYTHONHOME and PYTHONPATH; docs/fmi_hosts.md), which the last test shows.
"""
from __future__ import annotations

import glob
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

libcosimpy = pytest.importorskip("libcosimpy", reason="libcosimpy ships the libcosim C library")

HERE = Path(__file__).resolve().parent
CENTRES = ["x2", "y2", "x3", "y3", "x4", "y4"]


@pytest.fixture(scope="module")
def host(tmp_path_factory) -> Path:
    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        pytest.skip("no C compiler to build the host")
    lib = Path(libcosimpy.__file__).resolve().parent / "libcosimc"
    if not list(lib.glob("libcosimc.so*")):
        pytest.skip(f"libcosimc.so not found in {lib}")
    exe = tmp_path_factory.mktemp("host") / "cosim_host"
    subprocess.run([compiler, "-o", str(exe), str(HERE / "native_host" / "cosim_host.c"), f"-L{lib}", "-lcosimc",
                    f"-Wl,-rpath,{lib}", "-ldl"], check=True, capture_output=True)
    return exe


def _libcosim_leftovers() -> set[str]:
    return set(glob.glob("/tmp/libcosim_*"))


def test_native_fmu_runs_in_a_c_host_with_an_empty_environment(host, native_fmu, tmp_path):
    from fmpy import simulate_fmu

    before = _libcosim_leftovers()
    out = tmp_path / "case2.csv"
    proc = subprocess.run(["env", "-i", str(host), str(native_fmu), str(out)], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    rows = np.loadtxt(out, delimiter=",", skiprows=1)
    assert rows.shape == (10000, 7)
    signal = np.array([(0.0, 1.0), (10.0, 1.0), (10.0, 1.1)], dtype=[("time", float), ("L2", float)])
    ref = simulate_fmu(str(native_fmu), stop_time=100.0, output_interval=0.01, input=signal, output=CENTRES)
    expected = np.column_stack([ref[n] for n in CENTRES])[1:]
    # The FMU snaps communication times to whole nanoseconds, so libcosim's integer-nanosecond
    # grid and FMPy's n * 0.01 drive the same arithmetic: identical numbers are expected
    # (1e-12 m allows for nothing but that).
    assert np.abs(rows[:, 1:] - expected).max() <= 1e-12
    assert _libcosim_leftovers() <= before          # the host cleaned up after itself


def test_pythonfmu_fmu_needs_python_set_up_in_the_same_host(host, fourbar_fmu, tmp_path):
    proc = subprocess.run(["env", "-i", str(host), str(fourbar_fmu), str(tmp_path / "out.csv")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0
    assert "_Py_NoneStruct" in proc.stderr or "cannot load" in proc.stderr, proc.stderr[-2000:]

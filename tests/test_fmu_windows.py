"""The native FMUs' Windows binaries (issue 26), in each of their four flavours: built by the
mingw-w64 cross-compiler when it is installed (``x86_64-w64-mingw32-gcc``, Debian's
gcc-mingw-w64-x86-64), run under wine (Debian's wine64) by tests/native_host/portable_host.c
compiled for Windows, and compared with the same host compiled for Linux on the Linux binary:
the paper's Case 2 (L2 1.0 -> 1.1 m at t = 10 s) for 20 s.

- FMI 2.0 and FMI 3.0 co-simulation: the FMU's own integrator at rtol = atol = 1e-12.
- FMI 2.0 and FMI 3.0 model exchange: the host's fixed-step classic Runge-Kutta (0.5 ms) on the
  FMU's derivatives, L2 set in event mode at 10 s; also checked against the FMI 2.0
  co-simulation FMU run through FMPy (fourbar-run's ``run_case``) at rtol = atol = 1e-12.

Skipped where the cross-compiler or wine is missing (CI has neither)."""
from __future__ import annotations

import csv
import os
import shutil
import subprocess
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from support import CENTRES, FLAVOUR_AGREE, REPO, case_file

MINGW = shutil.which("x86_64-w64-mingw32-gcc")
WINE = shutil.which("wine64") or shutil.which("wine")
pytestmark = pytest.mark.skipif(not (MINGW and WINE and shutil.which("gcc")),
                                reason="needs x86_64-w64-mingw32-gcc, wine and gcc (Debian: gcc-mingw-w64-x86-64, "
                                       "wine64)")
#: |Windows - Linux| on x2..y4 (m), every flavour: the same C, two compilers and two maths
#: libraries (glibc's libm and the mingw runtime's): round-off differences only.  Measured
#: (gcc 12, mingw-w64 gcc 12, wine 8.0): co-simulation 3.1e-14 m (FMI 2.0 and 3.0 alike, the
#: FMU's DOP853 at 1e-12 over 20 s); model exchange 0.0 (bit for bit).  The issue's bound.
AGREE = 1e-9
#: |model exchange through the host's Runge-Kutta - FMPy's co-simulation at 1e-12| on x2..y4 (m)
#: over the 20 s of Case 2: the fixed-step method's own error.  The host's classic RK4 with
#: h = 0.5 ms (portable_host.c's SUBSTEPS = 20 per 0.01 s row) measured 3.3e-11 m (h = 1 ms
#: 4.8e-10 m, 2 ms 1.05e-8 m: fourth order; 0.25 ms 2.0e-11 m, where it levels off at the
#: reference's own error and round-off).  The bound is issue 26's flavour bound, the one CVode
#: at rtol 1e-14 meets (tests/support.py), 30x above RK4's measured error.
ME_AGREE = FLAVOUR_AGREE
ROWS = 2001                  # 0 to 20 s every 0.01 s
FAULT_TIME = 10.0            # s; the row at 10.00 s still shows L2 = 1.0 m
L2_BEFORE, L2_AFTER = 1.0, 1.1


@dataclass(frozen=True)
class Flavour:
    """One of portable_host.c's modes."""
    mode: str                # fmi2-cs | fmi2-me | fmi3-cs | fmi3-me

    @property
    def fmi_version(self) -> int:
        return int(self.mode[3])

    @property
    def model_exchange(self) -> bool:
        return self.mode.endswith("-me")


FLAVOURS = tuple(Flavour(m) for m in ("fmi2-cs", "fmi2-me", "fmi3-cs", "fmi3-me"))
MODEL_EXCHANGE = tuple(f for f in FLAVOURS if f.model_exchange)


@dataclass(frozen=True)
class Unzipped:
    """An extracted native FMU: its two binaries and the host's FMU arguments (token, value references, states)."""
    linux: Path
    windows: Path
    token: str
    vr_l2: int
    vr_rtol: int
    vr_atol: int
    vr_x2: int
    n_states: int

    def arguments(self, flavour: Flavour) -> list[str]:
        nx = self.n_states if flavour.model_exchange else 0
        return [self.token, *(str(v) for v in (self.vr_l2, self.vr_rtol, self.vr_atol, self.vr_x2, nx))]


@dataclass(frozen=True)
class HostRun:
    """portable_host.c's CSV: the rows' times (s), x2..y4 (m, one column each) and L2 (m; None
    for FMPy's run, whose exchange file does not record it)."""
    time: np.ndarray
    centres: np.ndarray
    l2: np.ndarray | None


#: Where each FMI version keeps its binaries (platform folder, library suffix).
_PLATFORMS = {2: (("linux64", ".so"), ("win64", ".dll")),
              3: (("x86_64-linux", ".so"), ("x86_64-windows", ".dll"))}


def _with_windows_binary(fmu: Path, fmi_version: int, tmp: Path) -> Path:
    """``fmu`` when it carries the Windows binary (built with the cross-compiler), else a fresh build."""
    folder = _PLATFORMS[fmi_version][1][0]
    with zipfile.ZipFile(fmu) as z:
        if any(n.startswith(f"binaries/{folder}/") for n in z.namelist()):
            return fmu
    from fmu_src.native_build import build_native_fmu
    return build_native_fmu(tmp / fmu.name, validate=False, fmi_version=fmi_version).path


def _unzip(fmu: Path, fmi_version: int, dest: Path) -> Unzipped:
    with zipfile.ZipFile(fmu) as z:
        z.extractall(dest)
    root = ET.parse(dest / "modelDescription.xml").getroot()
    if fmi_version == 2:
        variables = root.iter("ScalarVariable")
        token = root.get("guid")
        n_states = len(root.findall("ModelStructure/Derivatives/Unknown"))
    else:
        variables = root.find("ModelVariables")
        token = root.get("instantiationToken")
        n_states = len(root.findall("ModelStructure/ContinuousStateDerivative"))
    vr = {v.get("name"): int(v.get("valueReference")) for v in variables}
    assert [vr[n] for n in CENTRES] == list(range(vr["x2"], vr["x2"] + 6)), "the host reads x2..y4 from VR_X2 on"
    identifier = root.find("CoSimulation").get("modelIdentifier")
    (linux, so), (windows, dll) = _PLATFORMS[fmi_version]
    return Unzipped(linux=dest / "binaries" / linux / f"{identifier}{so}",
                    windows=dest / "binaries" / windows / f"{identifier}{dll}", token=token, vr_l2=vr["L2"],
                    vr_rtol=vr["rtol"], vr_atol=vr["atol"], vr_x2=vr["x2"], n_states=n_states)


def _read(path: Path) -> HostRun:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["time", *CENTRES, "L2"], rows[0]
    values = np.array([[float(x) for x in row] for row in rows[1:]])
    return HostRun(time=values[:, 0], centres=values[:, 1:7], l2=values[:, 7])


class Hosts:
    """portable_host.c built for Linux and for Windows, the two FMUs extracted, one wine prefix;
    :meth:`run` runs a flavour on one platform's binary (once: later calls return the same run)."""

    def __init__(self, folder: Path, fmus: dict[int, Path]):
        self.folder = folder
        headers = Path(__import__("fmpy").__file__).parent / "c-code"
        source = REPO / "tests" / "native_host" / "portable_host.c"
        flags = ["-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", f"-I{headers}"]
        self.linux_host, self.windows_host = folder / "host_linux", folder / "host.exe"
        subprocess.run(["gcc", *flags, "-o", str(self.linux_host), str(source), "-ldl", "-lm"], check=True)
        subprocess.run([MINGW, *flags, "-o", str(self.windows_host), str(source)], check=True)
        self.fmus = {v: _unzip(fmu, v, folder / f"fmi{v}") for v, fmu in fmus.items()}
        self.wine_env = {**os.environ, "WINEDEBUG": "-all", "WINEPREFIX": str(folder / "wineprefix")}
        self._runs: dict[tuple[str, str], HostRun] = {}

    def run(self, flavour: Flavour, platform: str) -> HostRun:
        key = (flavour.mode, platform)
        if key not in self._runs:
            fmu = self.fmus[flavour.fmi_version]
            out = self.folder / f"{flavour.mode}-{platform}.csv"
            if platform == "linux":
                command, env, timeout = [str(self.linux_host), flavour.mode, str(fmu.linux)], None, 120
            else:
                command, env, timeout = ([WINE, str(self.windows_host), flavour.mode, str(fmu.windows)],
                                         self.wine_env, 600)
            # Output to a file, not a pipe: wine's wineserver and services inherit the host's
            # stdout and stderr and keep a pipe open for seconds after the host has exited.
            log = self.folder / f"{flavour.mode}-{platform}.log"
            with open(log, "w") as sink:
                done = subprocess.run([*command, *fmu.arguments(flavour), str(out)], stdout=sink,
                                      stderr=subprocess.STDOUT, timeout=timeout, env=env)
            text = log.read_text()
            assert done.returncode == 0 and "ok" in text, (flavour.mode, platform, text)
            self._runs[key] = _read(out)
        return self._runs[key]


@pytest.fixture(scope="module")
def hosts(tmp_path_factory, native_fmu, mechanism_fmus) -> Hosts:
    folder = tmp_path_factory.mktemp("windows")
    fmus = {2: _with_windows_binary(native_fmu, 2, folder),
            3: _with_windows_binary(mechanism_fmus.get("fourbar", "native3"), 3, folder)}
    return Hosts(folder, fmus)


def _assert_case2(run: HostRun) -> None:
    """2001 rows on the 0.01 s grid, the fault read back after 10 s."""
    assert run.time.shape == (ROWS,)
    assert np.allclose(run.time, np.arange(ROWS) * 0.01, rtol=0, atol=1e-9)     # printed with %.2f
    assert np.array_equal(run.l2, np.where(run.time > FAULT_TIME, L2_AFTER, L2_BEFORE))


@pytest.mark.parametrize("flavour", FLAVOURS, ids=lambda f: f.mode)
def test_the_windows_dll_gives_the_linux_numbers_under_wine(hosts, flavour):
    linux, windows = hosts.run(flavour, "linux"), hosts.run(flavour, "windows")
    _assert_case2(linux)
    _assert_case2(windows)
    worst = float(np.max(np.abs(windows.centres - linux.centres)))
    assert worst <= AGREE, (flavour.mode, worst)


@pytest.fixture(scope="module")
def fmpy_case2(tmp_path_factory, native_fmu) -> HostRun:
    """Case 2 on the FMI 2.0 co-simulation FMU through FMPy (fourbar-run's run_case), 20 s at
    rtol = atol = 1e-12: L2 set before the step from 10 s."""
    from orchestrator import run_case

    folder = tmp_path_factory.mktemp("fmpy_case2")
    case = case_file("case2_fault_L2", Path(native_fmu).resolve(), folder, stop=20.0, rtol=1e-12, atol=1e-12)
    result = run_case(case, folder / "out")
    assert result.ok, result.error
    with open(result.exchange_path, newline="") as f:
        rows = list(csv.DictReader(f))
    return HostRun(time=np.array([float(r["time"]) for r in rows]),
                   centres=np.array([[float(r[n]) for n in CENTRES] for r in rows]),
                   l2=None)


@pytest.mark.parametrize("flavour", MODEL_EXCHANGE, ids=lambda f: f.mode)
def test_model_exchange_in_the_hosts_runge_kutta_follows_co_simulation(hosts, fmpy_case2, flavour):
    """Physically sane: the host's RK4 on the FMU's derivatives, with the fault in event mode,
    gives FMPy's co-simulation of the same linkage (the Windows run equals this one, above)."""
    me = hosts.run(flavour, "linux")
    _assert_case2(me)
    assert np.allclose(fmpy_case2.time, me.time, rtol=0, atol=1e-9)   # both printed: 17 digits, %.2f
    worst = float(np.max(np.abs(me.centres - fmpy_case2.centres)))
    assert worst <= ME_AGREE, (flavour.mode, worst)


@pytest.mark.parametrize("arguments, message", [
    (["fmi4-cs"], "MODE must be fmi2-cs, fmi2-me, fmi3-cs or fmi3-me (got 'fmi4-cs')"),
    (["fmi2-me", "NX=2"], "NX must be a whole number from 0 to 64 (got 'NX=2')"),
    (["fmi2-me", "0"], "NX must be 0 in co-simulation and the number of continuous states"),
], ids=["mode", "nx-not-a-number", "nx-zero-in-model-exchange"])
def test_the_host_names_a_bad_argument(hosts, arguments, message):
    mode, *nx = arguments
    fmu = hosts.fmus[2]
    args = fmu.arguments(Flavour("fmi2-me"))
    if nx:
        args[-1] = nx[0]
    done = subprocess.run([str(hosts.linux_host), mode, str(fmu.linux), *args, str(hosts.folder / "bad.csv")],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and message in done.stderr, done.stderr

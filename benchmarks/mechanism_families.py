"""User-style mechanisms for the robustness benchmark: mechanism files the project does not ship
(tests/mechanisms/) and two it ships, each a *family* of configurations drawn from a seed.

A family is one mechanism file with the runs a user would make of it: a start (crank angle and
rate) drawn from the family's start ranges, then a 1 % step of one of its lengths or a 10 % step
of one of its masses at a drawn time, and a healthy run.  A drawn start is kept only when the
healthy motion, simulated once beforehand (``PRE_RUN`` s on the native FMU), runs to the end
and repeats with a period the monitor can learn in its 0-9 s training window
(``PERIOD_RANGE``); otherwise the next start is drawn.  The period is the one of the monitored
column, from the FFT peak of the pre-run.

Every family's mechanism is chosen without a dead point on the motions drawn (each file's
header says why), so a 1 % or 10 % step at any phase leaves a steady motion: a run that fails
anyway is reported as a run that did not complete, never dropped.

The native FMI 2.0 FMU of each mechanism file is built once into the benchmark's folder
(``fmu_for``) and built again when the file or the code generator changes.
"""
from __future__ import annotations

import hashlib
import math
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent

__all__ = ["FAMILIES", "Family", "Start", "UserConfiguration", "defaults", "draw_configuration", "fmu_for",
           "outputs", "stepped"]

#: s, the healthy pre-run that accepts a drawn start.
PRE_RUN = 40.0
#: s, the monitored column's period must lie here: at least two periods in the 0-9 s training.
PERIOD_RANGE = (0.4, 4.4)
#: drawn starts tried per configuration before the family is reported as having none.
ATTEMPTS = 12


@dataclass(frozen=True)
class Start:
    """A range of starts: crank angle (degrees) and rate (rad/s), each drawn uniformly."""

    theta_deg: tuple[float, float]
    omega: tuple[float, float]


@dataclass(frozen=True)
class Family:
    """One mechanism file and what the benchmark does with it."""

    name: str
    file: str                        # relative to the repository
    signal: str                      # the monitored column
    starts: tuple[Start, ...]        # one range drawn per configuration, in turn
    lengths: tuple[str, ...] = ()    # parameters stepped by 1 % (default: every tunable one in m, nonzero)
    masses: tuple[str, ...] = ()     # parameters stepped by 10 % (default: every tunable one in kg)
    independent: tuple[str, str] = ("theta2_start", "omega2_start")

    @property
    def path(self) -> Path:
        return REPO / self.file


FAMILIES: tuple[Family, ...] = (
    Family("quick_return", "tests/mechanisms/quick_return.toml", "x2",
           starts=(Start((-60.0, -10.0), (0.0, 0.0)), Start((-180.0, 180.0), (5.5, 7.0)))),
    Family("stephenson_sixbar", "tests/mechanisms/stephenson3_sixbar.toml", "x2",
           starts=(Start((0.0, 60.0), (0.0, 0.0)),)),
    Family("watt_sixbar", "fmu_src/mechanisms/watt_sixbar.toml", "x2",
           starts=(Start((0.0, 60.0), (0.0, 0.0)),)),
    Family("drag_link", "tests/mechanisms/drag_link.toml", "x2",
           starts=(Start((-180.0, 180.0), (3.0, 6.0)),)),
    Family("inverted_slider_crank", "tests/mechanisms/inverted_slider_crank.toml", "x2",
           starts=(Start((0.0, 60.0), (0.0, 0.0)),)),
)


@dataclass(frozen=True)
class UserConfiguration:
    """A drawn start of a family's mechanism and what its healthy pre-run showed."""

    family: str
    index: int
    theta: float                     # rad, the crank's start angle
    omega: float                     # rad/s, its start rate
    period: float                    # s, the monitored column's period in the pre-run
    values: dict                     # parameter name -> default value (for the faults' "before")

    def describe(self) -> str:
        return (f"{self.family} #{self.index}: theta2 = {math.degrees(self.theta):.4g} deg, "
                f"omega2 = {self.omega:.4g} rad/s, period {self.period:.3g} s")


def _digest(*paths: Path) -> str:
    h = hashlib.sha256()
    for p in paths:
        h.update(p.read_bytes())
    return h.hexdigest()[:16]


def _generator_digest() -> str:
    """What a built FMU depends on besides its mechanism file: the code generator's sources."""
    files = sorted((REPO / "fmu_src").rglob("*.py")) + sorted((REPO / "fmu_src" / "native").rglob("*.[ch]"))
    return _digest(*files)


def fmu_for(family: Family, folder: Path) -> Path:
    """The family's native FMI 2.0 FMU, built into ``folder`` unless the one there was built from
    the same mechanism file and code generator.  Raises RuntimeError with build_fmu.py's
    message when the build fails."""
    folder.mkdir(parents=True, exist_ok=True)
    fmu = folder / f"{family.name}Native.fmu"
    stamp = folder / f"{family.name}.built"
    want = _digest(family.path) + _generator_digest()
    if fmu.exists() and stamp.exists() and stamp.read_text() == want:
        return fmu
    done = subprocess.run([sys.executable, str(REPO / "build_fmu.py"), "--mechanism", str(family.path), "--only",
                           "native", "--fmi", "2", "--native-out", str(fmu), "--force"],
                          capture_output=True, text=True, cwd=REPO)
    if done.returncode != 0:
        raise RuntimeError(f"build_fmu.py --mechanism {family.file} failed: {done.stderr.strip()[-500:]}")
    stamp.write_text(want)
    return fmu


def defaults(fmu: Path) -> dict[str, float]:
    """Every real parameter's start value in the FMU's modelDescription.xml."""
    return {name: value for name, (value, _unit, _tunable) in _parameters(fmu).items()}


def stepped(family: Family, fmu: Path) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The lengths and masses a fault may step: the family's lists, else every tunable
    parameter in m with a nonzero value (an offset of 0 has no 1 % step) and every one in kg."""
    params = _parameters(fmu)
    lengths = family.lengths or tuple(n for n, (v, unit, tunable) in params.items() if tunable and unit == "m" and v)
    masses = family.masses or tuple(n for n, (v, unit, tunable) in params.items() if tunable and unit == "kg" and v)
    return lengths, masses


def outputs(family: Family) -> tuple[str, ...]:
    """The columns a run of the family writes: its file's ``[outputs]`` list (a test file of
    this repository, read as TOML data)."""
    import tomllib

    with open(family.path, "rb") as f:
        listed = tomllib.load(f).get("outputs", {}).get("variables", [])
    return tuple(str(v) for v in listed)


def _parameters(fmu: Path) -> dict[str, tuple[float, str | None, bool]]:
    from fmpy import read_model_description

    md = read_model_description(str(fmu), validate=False)
    return {v.name: (float(v.start), v.unit, v.variability == "tunable") for v in md.modelVariables
            if v.causality == "parameter" and v.type == "Real" and v.start is not None}


def _period(t: np.ndarray, x: np.ndarray) -> float:
    """The FFT peak's period of x(t) (s); inf for a flat signal."""
    x = np.asarray(x, dtype=float) - float(np.mean(x))
    if not np.ptp(x) > 1e-6:
        return math.inf
    spectrum = np.abs(np.fft.rfft(x * np.hanning(x.size)))
    k = int(np.argmax(spectrum[1:])) + 1
    return float(t[-1] - t[0]) / k


def draw_configuration(rng: np.random.Generator, family: Family, index: int, fmu: Path,
                       values: dict[str, float]) -> UserConfiguration | None:
    """A start of ``family`` whose healthy pre-run is steady with a learnable period; None when
    ATTEMPTS draws give none."""
    from fmpy import simulate_fmu

    theta_name, omega_name = family.independent
    start = family.starts[index % len(family.starts)]
    for _ in range(ATTEMPTS):
        theta = math.radians(float(rng.uniform(*start.theta_deg)))
        omega = float(rng.uniform(*start.omega)) if start.omega[1] > start.omega[0] else start.omega[0]
        try:
            result = simulate_fmu(str(fmu), stop_time=PRE_RUN, output_interval=0.01,
                                  start_values={theta_name: theta, omega_name: omega}, output=[family.signal])
        except Exception:       # the FMU refused the start or failed a step: draw another
            continue
        t = result["time"]
        if t.size < 2 or t[-1] < PRE_RUN - 1e-6:
            continue
        period = _period(t, result[family.signal])
        if PERIOD_RANGE[0] <= period <= PERIOD_RANGE[1]:
            return UserConfiguration(family.name, index, theta, omega, period, dict(values))
    return None

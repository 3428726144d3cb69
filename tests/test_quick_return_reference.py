"""The quick-return's FMUs against an independent two-loop reference, through a length step and
a mass step (issue 37, item 1: a fault keeps theta2 and omega2 whatever the crank's phase).

tests/reference_quick_return.py integrates Lagrange's equation in theta2 with closed-form
positions and no project code; its own checks come first here (the loops close, its energies
are those of its positions, T + V is conserved), then both FMI 2.0 FMUs of
tests/mechanisms/quick_return.toml (pythonfmu and native, built once per session) run through
FMPy with a parameter step mid-run, the standard FMI way (a tunable parameter set at a
communication point; the row at t_f still shows the old value).

The crank is given omega2 = 3 rad/s at theta2 = 30 deg: more than the 2.42 rad/s it needs to
pass over the top (V is largest at theta2 = 90 deg), so it turns fully, about once every 2.5 s,
and every phase of the cycle, the ram's quick return included, comes by within the runs; the
steps are struck where the case says.  Two geometries:

- the file's (L4 = 2.0, H = 2.2): with theta2 as independent coordinate the dependent block's
  pivot ratio stays >= 0.124 over the whole cycle, above the partition review's 0.1
  (fmu_src/mechanism_model/dae.py, REPARTITION_REVIEW), so the FMUs never switch: these cases
  pass on the current code, in the band theta2 = -1.9..-1.1 rad too;
- a longer lever (L4 = 2.5, H = 2.7, set as start values: H - B_y stays in 0.2..0.54 m < L5,
  no toggle): the ratio dips to 0.098 near the bottom of the crank's turn, and the review
  switches the independent coordinate to the ram's x6 while theta2 is in about -2.06..-0.67 rad
  (measured with MechanismDAE at rtol = atol = 1e-10: to x6 and back 4 times in 10 s).  A
  length step struck there re-assembles keeping x6 and vx6 instead of theta2 and omega2:
  test_fmus_follow_the_reference_through_a_step[L4-long-lever-*] fails on the current code
  (both FMUs: theta2 off by 2.1e-3 rad in the row after the step, 0.8 rad later; a reference
  that keeps x6 and vx6 matches that row to 5e-12) and passes once the re-assembly keeps the
  [start] coordinates (issue 37's fix in fmu_src).  A mass step does not move the kinematics,
  so keeping x6 there is keeping theta2: it passes either way.
"""
from __future__ import annotations

import ast
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from fmpy import simulate_fmu

import reference_quick_return
from reference_quick_return import Motion, Parameters, lagrange_terms, positions, simulate
from support import REPO

MECHANISM = str(REPO / "tests" / "mechanisms" / "quick_return.toml")
THETA2_0 = math.radians(30.0)     # the file's [start]
OMEGA2_0 = 3.0                    # rad/s: the crank turns (see the module doc)
STEP = 0.01                       # s, communication step
STOP = 10.0                       # s
TIMES = np.round(np.arange(int(round(STOP / STEP)) + 1) * STEP, 10)
#: Both integrations at rtol = atol = 1e-12 (the FMUs through their parameters).  Their local
#: errors, ~1e-12 per step, add up to a phase error growing about linearly (a one-degree-of-
#: freedom conservative motion, not chaotic): measured <= 4e-10 m/rad over 10 s.  The bound is
#: the issue's; a re-assembly that keeps the ram instead of theta2 is off by ~1e-3.
TIGHT = 1e-12
AGREE = 1e-8                      # m, rad
COMPARED = ("x2", "y2", "x4", "y4", "x6", "theta2", "theta4")
#: The crank's phases (rad, wrapped to (-pi, pi]) where the issue saw the FMUs keep the ram.
BAND = (-1.9, -1.1)
LONG_LEVER = {"L4": 2.5, "H": 2.7}


@dataclass(frozen=True)
class Case:
    """One run: the geometry set at the start, one parameter stepped at t_f."""

    id: str
    base: dict[str, float]
    name: str
    value: float          # the new value at t_f
    t_f: float            # s, on the communication grid
    in_band: bool         # theta2 at t_f lies in BAND (checked on the reference)

    @property
    def parameters(self) -> Parameters:
        return Parameters().replace(**self.base)

    @property
    def old(self) -> float:
        return getattr(self.parameters, self.name)


CASES = (
    # The file's geometry: the review never switches.
    Case("L4-file", {}, "L4", 2.02, 4.5, True),             # theta2 = -1.47 rad at t_f
    Case("m6-file", {}, "m6", 3.3, 5.5, False),             # theta2 = +1.42 rad
    # The long lever: the FMUs have switched to x6 at t_f (window 3.99..4.85 s).
    Case("L4-long-lever", LONG_LEVER, "L4", 2.525, 4.4, True),   # theta2 = -1.56 rad; fails today
    Case("m6-long-lever", LONG_LEVER, "m6", 3.3, 4.4, True),
)


def _wrapped(angle: float) -> float:
    return math.remainder(angle, 2 * math.pi)


# -- the reference, checked on its own --------------------------------------------------------

def test_reference_imports_no_project_code():
    # Independence: only the standard library, numpy, scipy and sympy.
    tree = ast.parse(Path(reference_quick_return.__file__).read_text(encoding="utf-8"))
    modules = {alias.name.split(".")[0] for node in ast.walk(tree) if isinstance(node, ast.Import)
               for alias in node.names}
    modules |= {node.module.split(".")[0] for node in ast.walk(tree)
                if isinstance(node, ast.ImportFrom) and node.module}
    assert modules <= {"__future__", "dataclasses", "functools", "typing", "numpy", "scipy", "sympy"}, modules


def _joint_residuals(theta2: np.ndarray, p: Parameters) -> np.ndarray:
    """The joints of quick_return.toml as equations in absolute coordinates (each body's centre
    and angle, a rod's tail and tip at -+L/2 along it), at the reference's positions: what the
    closed forms must satisfy.  Rows: joints O2, A, S, O4, B, C, P; columns: theta2."""
    q = positions(theta2, p)
    e = lambda a: np.array([np.cos(a), np.sin(a)])       # noqa: E731
    c2, c3, c4, c5 = (np.array([q.column(f"x{k}"), q.column(f"y{k}")]) for k in "2345")
    c6 = np.array([q.x6, q.y6])
    th5 = q.theta5
    u, s = e(q.theta4), c3 - (c4 - p.L4 / 2 * e(q.theta4))         # the lever's axis; its tail to the pin
    rows = [
        c2 - p.r / 2 * e(theta2) - np.array([[0.0], [p.d]]),           # O2: crank tail on O2
        c2 + p.r / 2 * e(theta2) - c3,                                 # A: crank tip on the block's pin
        [u[0] * s[1] - u[1] * s[0],                                   # S: pin on the lever's axis
         q.theta3 - q.theta4],                                         #    and the block turns with it
        c4 - p.L4 / 2 * e(q.theta4),                                   # O4: lever tail on O4
        c4 + p.L4 / 2 * e(q.theta4) - (c5 - p.L5 / 2 * e(th5)),        # B: lever tip on the link's tail
        c5 + p.L5 / 2 * e(th5) - c6,                                   # C: link tip on the ram's pin
        [q.y6 - p.H],                                                  # P: ram on y = H
    ]
    return np.vstack([np.atleast_2d(np.asarray(r, dtype=float)) for r in rows])


@pytest.mark.parametrize("base", [{}, LONG_LEVER], ids=["file", "long-lever"])
def test_reference_positions_close_both_loops(base):
    # Round-off: the closed forms chain atan2, sqrt and asin on lengths of ~2 m, measured
    # <= 9e-16 m; 1e-13 leaves a margin and catches any wrong term (>= 1e-3 m).
    p = Parameters().replace(**base)
    theta2 = np.linspace(-math.pi, math.pi, 721)
    worst = float(np.max(np.abs(_joint_residuals(theta2, p))))
    assert worst <= 1e-13, worst
    q = positions(theta2, p)
    assert np.all(q.x6 > q.x4 * 2)                  # the ram right of B: the file's branch
    assert np.all((q.slide > 0) & (q.slide < p.L4))  # the block within the slot
    assert np.ptp(q.x6) > 0.5 and np.ptp(q.theta4) > 0.9     # it is a mechanism that moves


@pytest.mark.parametrize("theta2", [-2.5, -1.5, -0.3, 0.7, 1.6, 2.9])
def test_reference_energies_are_those_of_its_positions(theta2):
    # M and V come from sympy's derivatives; here from the positions by central differences
    # (h = 1e-5 rad: truncation ~1e-10, round-off ~1e-11 relative; measured <= 2e-10): T = M w^2 / 2
    # of the bodies' velocities, rods I = m L^2 / 12 about their centres.  A wrong inertia or a
    # body left out is off by >= 1e-4.
    p = Parameters()
    h = 1e-5
    ahead, back, here = positions(theta2 + h, p), positions(theta2 - h, p), positions(theta2, p)
    rate = lambda name: (float(ahead.column(name)) - float(back.column(name))) / (2 * h)   # noqa: E731
    speed2 = lambda k: rate(f"x{k}") ** 2 + rate(f"y{k}") ** 2                             # noqa: E731
    M = (p.m2 * speed2(2) + p.m2 * p.r**2 / 12
         + p.m3 * speed2(3) + p.I3 * rate("theta3") ** 2
         + p.m4 * speed2(4) + p.m4 * p.L4**2 / 12 * rate("theta4") ** 2
         + p.m5 * speed2(5) + p.m5 * p.L5**2 / 12 * rate("theta5") ** 2
         + p.m6 * speed2(6))
    V = p.g * sum(m * float(here.column(f"y{k}")) for k, m in zip("23456", (p.m2, p.m3, p.m4, p.m5, p.m6)))
    terms = lagrange_terms(theta2, p)
    assert terms.M == pytest.approx(M, rel=1e-8)
    assert terms.V == pytest.approx(V, rel=1e-13)


@pytest.mark.parametrize("omega2", [0.0, OMEGA2_0], ids=["swinging", "turning"])
def test_reference_conserves_energy(omega2):
    # DOP853 at rtol = atol = 1e-12 over 20 s: measured |dE| / |E| <= 3e-12 (E ~ 125 J).
    motion = simulate(np.round(np.arange(2001) * STEP, 10), THETA2_0, omega2)
    assert np.ptp(motion.theta2) > 3.0                  # swings through the bottom, or turns
    drift = float(np.ptp(motion.energy) / abs(motion.energy[0]))
    assert drift <= 1e-10, drift


# -- the FMUs against it -----------------------------------------------------------------------

_MOTIONS: dict[str, Motion] = {}


def _reference(case: Case) -> Motion:
    if case.id not in _MOTIONS:
        _MOTIONS[case.id] = simulate(TIMES, THETA2_0, OMEGA2_0, case.parameters,
                                     changes=((case.t_f, {case.name: case.value}),), rtol=TIGHT, atol=TIGHT)
    return _MOTIONS[case.id]


def _run(fmu, case: Case) -> np.ndarray:
    signal = np.array([(0.0, case.old), (case.t_f, case.old), (case.t_f, case.value)],
                      dtype=[("time", float), (case.name, float)])
    return simulate_fmu(str(fmu), stop_time=STOP, output_interval=STEP, input=signal, output=list(COMPARED),
                        start_values={"rtol": TIGHT, "atol": TIGHT, "omega2_start": OMEGA2_0, **case.base})


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_the_step_strikes_at_the_intended_phase(case):
    theta2 = _wrapped(float(_reference(case).theta2[int(round(case.t_f / STEP))]))
    assert (BAND[0] <= theta2 <= BAND[1]) == case.in_band, theta2


@pytest.mark.slow        # the two FMUs' builds and four pythonfmu runs at 1e-12: ~38 s CPU in all
@pytest.mark.parametrize("kind", ["pythonfmu", "native"])
@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_fmus_follow_the_reference_through_a_step(case, kind, mechanism_fmus):
    run = _run(mechanism_fmus.get(MECHANISM, kind), case)
    ref = _reference(case)
    assert np.array_equal(np.round(run["time"], 10), TIMES)
    k = int(round(case.t_f / STEP))
    errors = {n: np.abs(run[n] - ref.positions.column(n)) for n in COMPARED}
    worst = {n: float(e.max()) for n, e in errors.items()}
    before = max(float(e[:k + 1].max()) for e in errors.values())
    after = {n: float(e[k + 1]) for n, e in errors.items()}
    assert max(worst.values()) <= AGREE, (
        f"{case.id} ({kind}): {case.name} {case.old} -> {case.value} at t = {case.t_f} s, theta2 = "
        f"{_wrapped(float(ref.theta2[k])):.3f} rad: worst |FMU - reference| {max(worst.values()):.3g} "
        f"(up to t_f {before:.3g}; row after the step: theta2 {after['theta2']:.3g} rad, "
        f"x6 {after['x6']:.3g} m); per output {worst}")

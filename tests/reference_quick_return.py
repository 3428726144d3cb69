"""An independent reference for the crank-shaper quick-return, in its one coordinate theta2.

Written from the physics of tests/mechanisms/quick_return.toml alone: nothing here comes from
``fmu_src`` or any other project module (and the file is not read: the numbers of its
``[parameters]`` are repeated in :class:`Parameters`).  Every position is a closed-form
function of the crank angle ``theta2``, and the motion follows from Lagrange's equation in that
single coordinate.

Geometry (m, rad; angles counter-clockwise from +x, gravity ``g`` along -y)::

    crank 2       pinned at O2 = (0, d), length r:      A = O2 + r (cos th2, sin th2)
    block 3       its pin (its centre) on A, sliding along the lever, turning with it
    lever 4       pinned at O4 = (0, 0), length L4:     th4 = atan2(d + r sin th2, r cos th2)
                  (r < d: A_y > 0, so th4 stays in (0, pi)); the block sits at
                  s = |A| = sqrt(d^2 + r^2 + 2 d r sin th2) along it;   B = L4 (cos th4, sin th4)
    link 5        from B to the ram's pin C, length L5
    ram 6         translates along y = H:  C = (x6, H),  x6 = B_x + sqrt(L5^2 - (H - B_y)^2)
                  (the branch with the ram right of B, the file's assembly guess), and
                  th5 = asin((H - B_y) / L5)

Centres of mass: the rods' midpoints (crank, lever, link: uniform slender rods, ``I = m L^2 /
12`` about the centre), the block's and the ram's pins.  The block's angle is the lever's
(``th3 = th4``); the ram does not rotate.

Dynamics: with ``x_i(th2)`` the centres and ``phi_i(th2)`` the angles,

    M(th2) = sum_i m_i |dx_i/dth2|^2 + I_i (dphi_i/dth2)^2,    V(th2) = g sum_i m_i y_i,

the kinetic energy is ``T = M w2^2 / 2`` and Lagrange's equation ``d/dt dL/dw2 - dL/dth2 = 0``
reads

    M(th2) th2'' + 1/2 M'(th2) w2^2 + V'(th2) = 0.

The closed forms are written once, as sympy expressions (``_geometry``): :func:`positions`
evaluates them, and ``M``, ``M'``, ``V`` and ``V'`` are their exact sympy derivatives (no finite
differences), evaluated with common-subexpression elimination; the state ``(th2, w2)`` is
integrated by scipy's DOP853.

A parameter change at ``t`` keeps ``th2`` and ``w2`` (the README's rule, "Fault injection": the
linkage is re-assembled keeping the ``[start]`` coordinates and their rates) and the motion
continues with the new parameters; the row *at* ``t`` still shows the old ones (the FMUs'
output convention: a value set at a communication point acts on the step that follows it).
"""
from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import Callable

import numpy as np
import sympy
from scipy.integrate import solve_ivp

__all__ = ["Parameters", "Positions", "Motion", "LagrangeTerms", "positions", "lagrange_terms", "energy", "simulate"]


@dataclass(frozen=True)
class Parameters:
    """The mechanism's parameters (SI units), defaults as in quick_return.toml."""

    d: float = 1.0       # m, height of the crank pivot O2 above the lever pivot O4
    r: float = 0.5       # m, crank length
    L4: float = 2.0      # m, slotted lever length
    L5: float = 1.0      # m, connecting link length
    H: float = 2.2       # m, height of the ram's line
    m2: float = 1.0      # kg, crank
    m3: float = 0.5      # kg, block
    I3: float = 0.002    # kg m^2, block, about its centre
    m4: float = 2.0      # kg, lever
    m5: float = 1.0      # kg, link
    m6: float = 3.0      # kg, ram
    g: float = 9.81      # m/s^2, along -y

    def replace(self, **changes: float) -> Parameters:
        return dataclasses.replace(self, **changes)

    def values(self) -> tuple[float, ...]:
        return tuple(getattr(self, f.name) for f in dataclasses.fields(self))


@dataclass(frozen=True)
class Positions:
    """Every body's centre (m) and angle (rad), as floats or as arrays over rows.

    The names are the mechanism file's: ``x<label>``, ``y<label>``, ``theta<label>``.
    """

    theta2: np.ndarray
    x2: np.ndarray
    y2: np.ndarray
    x3: np.ndarray       # the block's centre = A, the crank's tip
    y3: np.ndarray
    theta3: np.ndarray   # = theta4
    x4: np.ndarray
    y4: np.ndarray
    theta4: np.ndarray
    x5: np.ndarray
    y5: np.ndarray
    theta5: np.ndarray
    x6: np.ndarray
    y6: np.ndarray       # = H
    slide: np.ndarray    # the block's distance from O4 along the lever (m)

    def column(self, name: str) -> np.ndarray:
        return np.asarray(getattr(self, name))


@dataclass(frozen=True)
class Motion:
    """The reference at the requested times: the state, T + V and every position."""

    t: np.ndarray
    theta2: np.ndarray
    omega2: np.ndarray
    energy: np.ndarray       # J, T + V with V = 0 at y = 0, with the parameters of each row
    positions: Positions


def _geometry(th, P) -> dict:
    """The closed forms of the module doc as sympy expressions of ``th`` (theta2) and the
    parameters ``P`` (in Parameters' order): every Positions field but theta2."""
    d, r, L4, L5, H = P[:5]
    ax, ay = r * sympy.cos(th), d + r * sympy.sin(th)
    th4 = sympy.atan2(ay, ax)
    bx, by = L4 * sympy.cos(th4), L4 * sympy.sin(th4)
    x6 = bx + sympy.sqrt(L5**2 - (H - by) ** 2)
    return dict(x2=r / 2 * sympy.cos(th), y2=d + r / 2 * sympy.sin(th), x3=ax, y3=ay, theta3=th4,
                x4=L4 / 2 * sympy.cos(th4), y4=L4 / 2 * sympy.sin(th4), theta4=th4,
                x5=(bx + x6) / 2, y5=(by + H) / 2, theta5=sympy.asin((H - by) / L5),
                x6=x6, y6=H, slide=sympy.sqrt(ax**2 + ay**2))


def _symbols():
    th = sympy.Symbol("theta2", real=True)
    P = sympy.symbols([f.name for f in dataclasses.fields(Parameters)], positive=True)
    return th, P


@functools.cache
def _positions_function() -> Callable:
    th, P = _symbols()
    return sympy.lambdify([th, *P], list(_geometry(th, P).values()), modules="numpy", cse=True)


def positions(theta2, p: Parameters) -> Positions:
    """The closed-form positions at ``theta2`` (a float or an array), see the module doc."""
    th2 = np.asarray(theta2, dtype=float)
    values = _positions_function()(th2, *p.values())
    names = [f.name for f in dataclasses.fields(Positions)][1:]
    return Positions(theta2=th2, **{n: np.broadcast_to(np.asarray(v, dtype=float), th2.shape).copy()
                                    for n, v in zip(names, values)})


@functools.cache
def _dynamics() -> Callable:
    """f(theta2, *Parameters.values()) -> (M, M', V, V'), derived with sympy from the closed forms."""
    th, P = _symbols()
    m2, m3, I3, m4, m5, m6, g = P[5:]
    r, L4, L5 = P[1], P[2], P[3]
    x = _geometry(th, P)
    # (mass, centre x, centre y, inertia about the centre, angle) of each moving body.
    bodies = [
        (m2, x["x2"], x["y2"], m2 * r**2 / 12, th),
        (m3, x["x3"], x["y3"], I3, x["theta3"]),
        (m4, x["x4"], x["y4"], m4 * L4**2 / 12, x["theta4"]),
        (m5, x["x5"], x["y5"], m5 * L5**2 / 12, x["theta5"]),
        (m6, x["x6"], x["y6"], 0, sympy.Integer(0)),          # the ram only translates
    ]
    M = sum(m * (sympy.diff(cx, th) ** 2 + sympy.diff(cy, th) ** 2) + inertia * sympy.diff(phi, th) ** 2
            for m, cx, cy, inertia, phi in bodies)
    V = g * sum(m * cy for m, _, cy, _, _ in bodies)
    return sympy.lambdify([th, *P], [M, sympy.diff(M, th), V, sympy.diff(V, th)], modules="math", cse=True)


@dataclass(frozen=True)
class LagrangeTerms:
    """The terms of Lagrange's equation at one crank angle."""

    M: float      # kg m^2, generalized mass
    dM: float     # kg m^2 / rad, dM/dtheta2
    V: float      # J, potential energy (V = 0 at y = 0)
    dV: float     # J / rad, dV/dtheta2


def lagrange_terms(theta2: float, p: Parameters) -> LagrangeTerms:
    """M, M', V and V' at ``theta2``."""
    return LagrangeTerms(*(float(v) for v in _dynamics()(theta2, *p.values())))


def energy(theta2: float, omega2: float, p: Parameters) -> float:
    """T + V (J) at the state (theta2, omega2)."""
    M, _, V, _ = _dynamics()(theta2, *p.values())
    return 0.5 * M * omega2 * omega2 + V


def _rhs(p: Parameters):
    f, values = _dynamics(), p.values()

    def rhs(t, y):
        M, dM, _, dV = f(y[0], *values)
        return [y[1], -(0.5 * dM * y[1] * y[1] + dV) / M]
    return rhs


def simulate(times: np.ndarray, theta2: float, omega2: float, parameters: Parameters = Parameters(),
             changes: tuple[tuple[float, dict[str, float]], ...] = (),
             rtol: float = 1e-12, atol: float = 1e-12) -> Motion:
    """The motion at ``times`` (increasing, from the start time) from ``(theta2, omega2)``.

    ``changes`` = ((t, {name: value}), ...), in time order: parameters changed at ``t`` keeping
    theta2 and omega2; the row at ``t`` shows the state before the change.
    """
    times = np.asarray(times, dtype=float)
    th = np.empty(len(times))
    w = np.empty(len(times))
    energies = np.empty(len(times))
    fields = {f.name: np.empty(len(times)) for f in dataclasses.fields(Positions)}
    p, y, t0 = parameters, [float(theta2), float(omega2)], float(times[0])
    bounds = [float(t) for t, _ in changes] + [float(times[-1])]
    updates = [None] + [c for _, c in changes]
    for t_end, update in zip(bounds, updates):
        if update:
            p = p.replace(**update)
        rows = np.flatnonzero(((times >= t0) if t0 == times[0] else (times > t0)) & (times <= t_end))
        if t_end > t0:
            sol = solve_ivp(_rhs(p), (t0, t_end), y, method="DOP853", rtol=rtol, atol=atol, dense_output=True)
            if not sol.success:
                raise RuntimeError(f"reference integration failed at t = {sol.t[-1]}: {sol.message}")
            th[rows], w[rows] = sol.sol(times[rows])
            y = list(sol.y[:, -1])
        else:
            th[rows], w[rows] = y
        here = positions(th[rows], p)
        for name, column in fields.items():
            column[rows] = here.column(name)
        energies[rows] = [energy(a, b, p) for a, b in zip(th[rows], w[rows])]
        t0 = t_end
    return Motion(t=times, theta2=th, omega2=w, energy=energies, positions=Positions(**fields))

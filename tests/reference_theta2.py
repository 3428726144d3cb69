"""An independent formulation of the four-bar for the tests: one coordinate, theta2.

Written without any code from fmu_src/: the loop closure L2 e^{i th2} + L3 e^{i th3} =
L1 + L4 e^{i th4} is solved in closed form with complex numbers, the velocity
coefficients dth3/dth2 and dth4/dth2 come from its derivative, and the motion follows
from Lagrange's equation in the single coordinate theta2::

    m(th) th'' + 1/2 m'(th) th'^2 + V'(th) = 0

with the generalized mass m(th) = sum_i m_i |dr_i/dth|^2 + I_i (dphi_i/dth)^2 and
V(th) = g sum_i m_i y_i.  m' and V' are taken by central differences.
"""
from __future__ import annotations

import cmath
import math

import numpy as np
from scipy.integrate import solve_ivp


class Linkage:
    def __init__(self, L1=3.0, L2=1.0, L3=4.0, L4=2.5, m2=1.0, m3=1.0, m4=1.0, g=9.81, branch=+1):
        self.L = (L1, L2, L3, L4)
        self.m = (m2, m3, m4)
        self.g = g
        self.branch = branch

    def angles(self, th2: float) -> tuple[float, float]:
        """(th3, th4): intersection of circle(A, L3) and circle(O4, L4)."""
        L1, L2, L3, L4 = self.L
        A = L2 * cmath.exp(1j * th2)
        O4 = complex(L1, 0.0)
        d = abs(O4 - A)
        # Law of cosines at A in the triangle A-O4-B.
        cos_alpha = (L3 * L3 + d * d - L4 * L4) / (2 * L3 * d)
        if abs(cos_alpha) > 1:
            raise ValueError("not assemblable")
        alpha = math.acos(cos_alpha)
        B = A + L3 * (O4 - A) / d * cmath.exp(1j * self.branch * alpha)
        return cmath.phase(B - A), cmath.phase(B - O4)

    def rates(self, th2: float) -> tuple[float, float, float, float]:
        """(th3, th4, dth3/dth2, dth4/dth2)."""
        L1, L2, L3, L4 = self.L
        th3, th4 = self.angles(th2)
        # d/dth2 of the loop: i L2 e2 + i L3 e3 k3 = i L4 e4 k4.
        e2, e3, e4 = (cmath.exp(1j * a) for a in (th2, th3, th4))
        a, b = (L3 * e3).real, -(L4 * e4).real
        c, d = (L3 * e3).imag, -(L4 * e4).imag
        r, s = -(L2 * e2).real, -(L2 * e2).imag
        det = a * d - b * c                      # Cramer's rule for the 2x2 system
        return th3, th4, (r * d - b * s) / det, (a * s - c * r) / det

    def centres(self, th2: float) -> np.ndarray:
        """[x2, y2, x3, y3, x4, y4] in m."""
        L1, L2, L3, L4 = self.L
        th3, th4 = self.angles(th2)
        r2 = L2 / 2 * cmath.exp(1j * th2)
        r3 = L2 * cmath.exp(1j * th2) + L3 / 2 * cmath.exp(1j * th3)
        r4 = L1 + L4 / 2 * cmath.exp(1j * th4)
        return np.array([r2.real, r2.imag, r3.real, r3.imag, r4.real, r4.imag])

    def mass_and_potential(self, th2: float) -> tuple[float, float]:
        """(m(th2), V(th2)): generalized mass (kg m^2) and potential energy (J)."""
        L1, L2, L3, L4 = self.L
        m2, m3, m4 = self.m
        th3, th4, k3, k4 = self.rates(th2)
        e2, e3, e4 = (cmath.exp(1j * a) for a in (th2, th3, th4))
        v2 = L2 / 2 * 1j * e2
        v3 = L2 * 1j * e2 + L3 / 2 * 1j * e3 * k3
        v4 = L4 / 2 * 1j * e4 * k4
        mass = (m2 * abs(v2) ** 2 + m3 * abs(v3) ** 2 + m4 * abs(v4) ** 2
                + m2 * L2**2 / 12 + m3 * L3**2 / 12 * k3**2 + m4 * L4**2 / 12 * k4**2)
        y2, y3, y4 = (L2 / 2 * e2).imag, (L2 * e2 + L3 / 2 * e3).imag, (L4 / 2 * e4).imag
        return mass, self.g * (m2 * y2 + m3 * y3 + m4 * y4)

    def energy(self, th2: float, w2: float) -> float:
        m, V = self.mass_and_potential(th2)
        return 0.5 * m * w2 * w2 + V

    def rhs(self, t, y, h=1e-5):
        # Central differences with a 1e-5 rad step: truncation and round-off both ~1e-11.
        th, w = y
        m, _ = self.mass_and_potential(th)
        mp, Vp = self.mass_and_potential(th + h)
        mm, Vm = self.mass_and_potential(th - h)
        dm, dV = (mp - mm) / (2 * h), (Vp - Vm) / (2 * h)
        return [w, -(0.5 * dm * w * w + dV) / m]


def simulate(times: np.ndarray, th2_0: float, w2_0: float = 0.0, switches: tuple = (),
             rtol: float = 1e-12, atol: float = 1e-12, **params) -> np.ndarray:
    """Centres [x2..y4] at ``times``.

    ``switches`` = ((t, {name: value}), ...): parameter changes applied at t keeping theta2
    and omega2 (the FMU's re-assembly rule); the row at t still shows the old geometry.
    """
    params = dict(params)
    out = np.empty((len(times), 6))
    y = [th2_0, w2_0]
    t0 = times[0]
    bounds = [s[0] for s in switches] + [times[-1]]
    changes = [None] + [s[1] for s in switches]
    for t_end, change in zip(bounds, changes):
        if change:
            params.update(change)
        link = Linkage(**params)
        first = t0 == times[0]
        mask = ((times >= t0) if first else (times > t0)) & (times <= t_end)
        sol = solve_ivp(link.rhs, (t0, t_end), y, method="DOP853", rtol=rtol, atol=atol,
                        dense_output=True)
        if not sol.success:
            raise RuntimeError(sol.message)
        for idx in np.flatnonzero(mask):
            out[idx] = link.centres(float(sol.sol(times[idx])[0]))
        y = sol.y[:, -1]
        t0 = t_end
    return out

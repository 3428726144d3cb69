"""An independent formulation of a planar mechanism file, for the tests.

Nothing here comes from ``fmu_src``: the TOML file is read with ``tomllib``, and the
equations are the textbook absolute-coordinate ones (Haug, *Computer-Aided Kinematics and
Dynamics of Mechanical Systems*, ch. 3 and 6; Nikravesh, *Computer-Aided Analysis of
Mechanical Systems*), written out by hand as numbers, with no symbolic differentiation and no
coordinate partitioning.

Coordinates.  Every body has its centre of mass at its origin; its coordinates are the centre
``(x, y)`` and, if it rotates, its angle ``theta`` (counter-clockwise from +x), named
``x<label>``, ``y<label>``, ``theta<label>`` as in the mechanism file's outputs.  A point with
local coordinates ``s'`` is at ``r = R + A(theta) s'``, with ``A`` the rotation matrix; with
``s = A s'`` and ``K = [[0, -1], [1, 0]]`` (a quarter turn), ``dr/dtheta = K s`` and
``d2r/dt2 = Rdd + K s thetadd - s thetad^2``.

Constraints ``Phi(q, t) = 0`` (``Phi_q qd = nu``, ``Phi_q qdd = gamma``):

- revolute joint, point a of the first body i on point b of the second body j (2 rows)::

      Phi = r_a - r_b,   Phi_q = [I, K s_a] on i, -[I, K s_b] on j,
      gamma = s_a thetad_i^2 - s_b thetad_j^2

- prismatic joint: point b of the second body stays on the line through point a of the first
  body f, of direction ``u = A_f u'`` (``u'`` at the joint's angle in f's frame), normal
  ``n = K u``, ``d = r_b - r_a``::

      Phi = n . d,   Phi_q = n on R_b, n . K s_b on theta_b, -n on R_f, -(u . d + n . K s_a) on theta_f,
      gamma = thetad_f^2 (n . d) + 2 thetad_f (u . dd) + n . (s_b thetad_b^2 - s_a thetad_f^2)

  and, when the second body rotates, ``theta_b - theta_f = 0`` (``gamma = 0``: the slider's
  frame turns with the guide's, as the project's file format defines it);
- driver on a revolute joint: ``theta_second - theta_first - (start + speed t) = 0``,
  ``nu = speed``, ``gamma = 0``.

Applied forces: a point-to-point spring-damper from point a to point b, ``d = r_b - r_a``,
``l = |d|``, ``e = d / l``, pulls with the tension ``F = preload + k (l - l0) + c (e . (v_b - v_a))``:
``-F e`` on b at r_b, ``+F e`` on a at r_a.  Friction at a revolute joint, ``w = thetad_second -
thetad_first``, is the torque ``T = viscous w + coulomb tanh(w / v_s)``: ``-T`` on the second
body, ``+T`` on the first.  (Rotational springs and prismatic friction: not read.)

Dynamics: ``M = diag(m, m, I)`` per body, gravity ``g`` along -y, and the augmented system
``[[M, Phi_q^T], [Phi_q, 0]] [qdd; lambda] = [Q; gamma]`` solved in full by LU (numpy).  The
state ``(q, qd)`` is integrated as a whole by scipy's DOP853; after every output step it is
projected back onto the constraint manifold (positions by Gauss-Newton on ``Phi = 0``, the
least-squares correction; velocities onto ``Phi_q qd = nu``).  A mechanism with no degree of
freedom left (driven) is solved by kinematics alone at every time.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import sympy
from scipy.integrate import solve_ivp

__all__ = ["ReferenceModel", "Spring", "Friction", "Trajectory", "read_model", "MECHANISM_FOLDER"]

MECHANISM_FOLDER = Path(__file__).resolve().parents[1] / "fmu_src" / "mechanisms"
K = np.array([[0.0, -1.0], [1.0, 0.0]])      # a quarter turn: dA/dtheta = K A
#: Newton and Gauss-Newton stop after a correction below this times (1 + |q|): they converge
#: quadratically, so what is left is of the order of its square, far below round-off.
_CONVERGED = 1e-11


def _rate_name(coordinate: str) -> str:
    """theta2 -> omega2, x4 -> vx4, y4 -> vy4 (the file's [start] names)."""
    for prefix, rate in (("theta", "omega"), ("x", "vx"), ("y", "vy")):
        if coordinate.startswith(prefix):
            return rate + coordinate[len(prefix):]
    raise ValueError(coordinate)


def _rotation(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


@dataclass(frozen=True)
class Body:
    """A rigid body: mass, inertia about its centre, its named points in its own frame."""

    name: str
    label: str
    mass: float
    inertia: float
    rotates: bool
    points: dict[str, np.ndarray]
    guess: tuple[float, float, float]           # x (m), y (m), angle (rad) where assembly starts


@dataclass(frozen=True)
class Attachment:
    """A point of a body, or of the ground (``body`` None: ``local`` is then global)."""

    body: int | None      # index into ReferenceModel.bodies
    local: np.ndarray


@dataclass(frozen=True)
class Joint:
    name: str
    type: str             # "revolute" or "prismatic"
    first: Attachment
    second: Attachment
    angle: float          # prismatic: the line's direction in the first body's frame (rad)


@dataclass(frozen=True)
class Driver:
    name: str
    joint: int            # index into ReferenceModel.joints
    start: float          # rad
    speed: float          # rad/s


@dataclass(frozen=True)
class Spring:
    """A point-to-point spring-damper: tension (N) preload + stiffness (l - length) + damping dl/dt."""

    name: str
    a: Attachment
    b: Attachment
    stiffness: float      # N/m
    damping: float        # N.s/m
    length: float         # m
    preload: float        # N


@dataclass(frozen=True)
class Friction:
    """Friction at a revolute joint: torque viscous w + coulomb tanh(w / velocity_scale)."""

    name: str
    joint: int            # index into ReferenceModel.joints
    viscous: float        # N.m.s/rad
    coulomb: float        # N.m
    velocity_scale: float  # rad/s


@dataclass(frozen=True)
class Trajectory:
    """Consistent states at the output times: ``q[k]``, ``qd[k]`` at ``t[k]``."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray


class ReferenceModel:
    """The equations of one mechanism file, evaluated numerically (see the module doc)."""

    def __init__(self, name, parameters, gravity, bodies, joints, drivers, start, springs=(), friction=()):
        self.name = name
        self.parameters: dict[str, float] = parameters
        self.g = gravity
        self.bodies: tuple[Body, ...] = bodies
        self.joints: tuple[Joint, ...] = joints
        self.drivers: tuple[Driver, ...] = drivers
        self.start: dict[str, float] = start     # independent coordinate or rate -> value (SI)
        self.springs: tuple[Spring, ...] = tuple(springs)
        self.friction: tuple[Friction, ...] = tuple(friction)
        self.coordinates: list[str] = []
        self._index: list[tuple[int, int, int | None]] = []     # per body: indices of x, y, theta
        for b in bodies:
            i = len(self.coordinates)
            self.coordinates += [f"x{b.label}", f"y{b.label}"] + ([f"theta{b.label}"] if b.rotates else [])
            self._index.append((i, i + 1, i + 2 if b.rotates else None))
        self.n = len(self.coordinates)
        self.m = sum(self._rows(j) for j in joints) + len(drivers)
        masses = []
        for b in bodies:
            masses += [b.mass, b.mass] + ([b.inertia] if b.rotates else [])
        self.mass = np.array(masses)

    # -- geometry --------------------------------------------------------------------------
    def _rows(self, joint: Joint) -> int:
        if joint.type == "revolute":
            return 2
        second = joint.second.body
        return 2 if second is not None and self.bodies[second].rotates else 1

    def angle(self, q, body: int | None) -> float:
        if body is None:
            return 0.0
        k = self._index[body][2]
        return 0.0 if k is None else float(q[k])

    def rate(self, qd, body: int | None) -> float:
        if body is None:
            return 0.0
        k = self._index[body][2]
        return 0.0 if k is None else float(qd[k])

    def centre(self, q, body: int) -> np.ndarray:
        ix, iy, _ = self._index[body]
        return np.array([q[ix], q[iy]])

    def arm(self, q, a: Attachment) -> np.ndarray:
        """s = A(theta) s': from the body's centre to the point, in global axes."""
        return a.local if a.body is None else _rotation(self.angle(q, a.body)) @ a.local

    def position(self, q, a: Attachment) -> np.ndarray:
        return a.local if a.body is None else self.centre(q, a.body) + self.arm(q, a)

    def velocity(self, q, qd, a: Attachment) -> np.ndarray:
        if a.body is None:
            return np.zeros(2)
        return self.centre(qd, a.body) + K @ self.arm(q, a) * self.rate(qd, a.body)

    def _add(self, row: np.ndarray, body: int | None, on_centre: np.ndarray, on_angle: float) -> None:
        """Add to a Jacobian block (rows x n) the derivatives with respect to ``body``'s coordinates."""
        if body is None:
            return
        ix, iy, it = self._index[body]
        row[:, ix] += on_centre[:, 0]
        row[:, iy] += on_centre[:, 1]
        if it is not None:
            row[:, it] += on_angle

    # -- constraints -----------------------------------------------------------------------
    def constraints(self, q, t: float):
        """(Phi, Phi_q, nu) at (q, t)."""
        phi, jac, nu = [], [], []
        for joint in self.joints:
            a, b = joint.first, joint.second
            if joint.type == "revolute":
                phi += list(self.position(q, a) - self.position(q, b))
                block = np.zeros((2, self.n))
                self._add(block, a.body, np.eye(2), K @ self.arm(q, a))
                self._add(block, b.body, -np.eye(2), -(K @ self.arm(q, b)))
                jac.append(block)
                nu += [0.0, 0.0]
                continue
            u = _rotation(self.angle(q, a.body)) @ np.array([math.cos(joint.angle), math.sin(joint.angle)])
            n = K @ u
            d = self.position(q, b) - self.position(q, a)
            block = np.zeros((1, self.n))
            self._add(block, b.body, n[None, :], float(n @ K @ self.arm(q, b)))
            self._add(block, a.body, -n[None, :], -float(u @ d + n @ K @ self.arm(q, a)))
            phi.append(float(n @ d))
            jac.append(block)
            nu.append(0.0)
            if self._rows(joint) == 2:
                phi.append(self.angle(q, b.body) - self.angle(q, a.body))
                block = np.zeros((1, self.n))
                self._add(block, b.body, np.zeros((1, 2)), 1.0)
                self._add(block, a.body, np.zeros((1, 2)), -1.0)
                jac.append(block)
                nu.append(0.0)
        for driver in self.drivers:
            joint = self.joints[driver.joint]
            a, b = joint.first.body, joint.second.body
            phi.append(self.angle(q, b) - self.angle(q, a) - (driver.start + driver.speed * t))
            block = np.zeros((1, self.n))
            self._add(block, b, np.zeros((1, 2)), 1.0)
            self._add(block, a, np.zeros((1, 2)), -1.0)
            jac.append(block)
            nu.append(driver.speed)
        return np.array(phi), np.vstack(jac), np.array(nu)

    def gamma(self, q, qd) -> np.ndarray:
        """gamma with Phi_q qdd = gamma (no constraint of these depends on t twice)."""
        out = []
        for joint in self.joints:
            a, b = joint.first, joint.second
            wa, wb = self.rate(qd, a.body), self.rate(qd, b.body)
            sa, sb = self.arm(q, a), self.arm(q, b)
            if joint.type == "revolute":
                out += list(sa * wa**2 - sb * wb**2)
                continue
            u = _rotation(self.angle(q, a.body)) @ np.array([math.cos(joint.angle), math.sin(joint.angle)])
            n = K @ u
            d = self.position(q, b) - self.position(q, a)
            dd = self.velocity(q, qd, b) - self.velocity(q, qd, a)
            out.append(float(wa**2 * (n @ d) + 2 * wa * (u @ dd) + n @ (sb * wb**2 - sa * wa**2)))
            if self._rows(joint) == 2:
                out.append(0.0)
        return np.array(out + [0.0] * len(self.drivers))

    # -- dynamics --------------------------------------------------------------------------
    def spring_tension(self, q, qd, spring: Spring) -> float:
        """The spring's tension F (N), positive pulling its two points together."""
        d = self.position(q, spring.b) - self.position(q, spring.a)
        length = float(np.hypot(*d))
        rate = float(d @ (self.velocity(q, qd, spring.b) - self.velocity(q, qd, spring.a))) / length
        return spring.preload + spring.stiffness * (length - spring.length) + spring.damping * rate

    def friction_torque(self, qd, friction: Friction) -> float:
        """The friction torque T (N.m), positive opposing a positive relative rate."""
        joint = self.joints[friction.joint]
        w = self.rate(qd, joint.second.body) - self.rate(qd, joint.first.body)
        return friction.viscous * w + friction.coulomb * math.tanh(w / friction.velocity_scale)

    def applied(self, q, qd) -> dict[int, tuple[np.ndarray, float]]:
        """Per body: the springs' and friction's resultant force (N) on its centre and moment
        (N.m) about it (gravity not included)."""
        out = {b: (np.zeros(2), 0.0) for b in range(len(self.bodies))}

        def push(attachment: Attachment, force: np.ndarray, moment: float = 0.0) -> None:
            if attachment.body is None:
                return
            f, m = out[attachment.body]
            s = self.arm(q, attachment)
            out[attachment.body] = (f + force, m + float(s[0] * force[1] - s[1] * force[0]) + moment)

        for spring in self.springs:
            d = self.position(q, spring.b) - self.position(q, spring.a)
            e = d / float(np.hypot(*d))
            F = self.spring_tension(q, qd, spring)
            push(spring.b, -F * e)
            push(spring.a, F * e)
        for friction in self.friction:
            joint, T = self.joints[friction.joint], self.friction_torque(qd, friction)
            push(joint.second, np.zeros(2), -T)
            push(joint.first, np.zeros(2), T)
        return out

    def forces(self, q=None, qd=None) -> np.ndarray:
        """Q: gravity on every centre (no velocity terms in centroidal coordinates), and with
        the state (q, qd) the springs' and friction's forces and moments."""
        Q = np.zeros(self.n)
        for body, (_, iy, _) in zip(self.bodies, self._index):
            Q[iy] = -body.mass * self.g
        if q is not None:
            for b, (force, moment) in self.applied(q, qd).items():
                ix, iy, it = self._index[b]
                Q[ix] += force[0]
                Q[iy] += force[1]
                if it is not None:
                    Q[it] += moment
        return Q

    def accelerations(self, q, qd, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(qdd, lambda) of [[M, Phi_q^T], [Phi_q, 0]] [qdd; lambda] = [Q; gamma], by LU."""
        _, J, _ = self.constraints(q, t)
        n, m = self.n, self.m
        A = np.zeros((n + m, n + m))
        A[:n, :n] = np.diag(self.mass)
        A[:n, n:] = J.T
        A[n:, :n] = J
        x = np.linalg.solve(A, np.concatenate([self.forces(q, qd), self.gamma(q, qd)]))
        return x[:n], x[n:]

    def energy(self, q, qd) -> float:
        """T + V (J), V = 0 at y = 0."""
        T = 0.5 * float(self.mass @ (np.asarray(qd) ** 2))
        V = sum(b.mass * self.g * q[iy] for b, (_, iy, _) in zip(self.bodies, self._index))
        return T + V

    def power(self, q, qd, qdd) -> float:
        """d(T + V)/dt (W): what the drivers put in (the joints do no work)."""
        V_rate = sum(b.mass * self.g * qd[iy] for b, (_, iy, _) in zip(self.bodies, self._index))
        return float(self.mass @ (np.asarray(qd) * np.asarray(qdd))) + V_rate

    # -- kinematics: assembly and projection -----------------------------------------------
    def assemble(self, t: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """The state at ``t`` with the [start] coordinates and rates (and the drivers) imposed,
        the others by Newton-Raphson from the bodies' x, y, angle in the file."""
        q = np.array([v for b in self.bodies for v in (b.guess if b.rotates else b.guess[:2])], dtype=float)
        fixed = [c for c in self.start if c in self.coordinates]
        E = np.zeros((len(fixed), self.n))
        for r, c in enumerate(fixed):
            E[r, self.coordinates.index(c)] = 1.0
            q[self.coordinates.index(c)] = self.start[c]
        for _ in range(50):
            phi, J, _ = self.constraints(q, t)
            step = np.linalg.solve(np.vstack([J, E]), np.concatenate([phi, np.zeros(len(fixed))]))
            q -= step
            if np.max(np.abs(step)) < _CONVERGED * (1 + np.max(np.abs(q))):
                break
        phi, J, nu = self.constraints(q, t)
        if np.max(np.abs(phi)) > 1e-12:
            raise ValueError(f"{self.name}: cannot be assembled (residual {np.max(np.abs(phi)):.3g})")
        rates = [self.start.get(_rate_name(c), 0.0) for c in fixed]
        qd = np.linalg.solve(np.vstack([J, E]), np.concatenate([nu, rates]))
        return q, qd

    def project(self, q, qd, t: float) -> tuple[np.ndarray, np.ndarray]:
        """The nearest consistent state: Gauss-Newton on Phi(q, t) = 0 with the least-squares
        correction dq = -Phi_q^T (Phi_q Phi_q^T)^-1 Phi, then qd projected onto Phi_q qd = nu."""
        q = np.array(q, dtype=float)
        for _ in range(10):
            phi, J, nu = self.constraints(q, t)
            step = J.T @ np.linalg.solve(J @ J.T, phi)
            q -= step
            if np.max(np.abs(step)) < _CONVERGED * (1 + np.max(np.abs(q))):
                break
        phi, J, nu = self.constraints(q, t)
        qd = np.asarray(qd, dtype=float)
        qd = qd - J.T @ np.linalg.solve(J @ J.T, J @ qd - nu)
        return q, qd

    def kinematics(self, q_guess, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q, qd, qdd) at t of a mechanism with no degree of freedom (Phi_q square)."""
        q = np.array(q_guess, dtype=float)
        for _ in range(50):
            phi, J, nu = self.constraints(q, t)
            step = np.linalg.solve(J, phi)
            q -= step
            if np.max(np.abs(step)) < _CONVERGED * (1 + np.max(np.abs(q))):
                break
        phi, J, nu = self.constraints(q, t)
        qd = np.linalg.solve(J, nu)
        qdd = np.linalg.solve(J, self.gamma(q, qd))
        return q, qd, qdd

    @property
    def degrees_of_freedom(self) -> int:
        return self.n - self.m

    # -- simulation ------------------------------------------------------------------------
    def simulate(self, times, rtol: float = 1e-12, atol: float = 1e-12) -> Trajectory:
        """Consistent states at ``times`` (starting at times[0] from the assembled start state).

        With degrees of freedom: DOP853 on the whole state (q, qd), one output step at a time,
        each followed by the projection.  Without: kinematics at every time.
        """
        times = np.asarray(times, dtype=float)
        q, qd = self.assemble(float(times[0]))
        qs, qds = [q], [qd]
        n = self.n
        for t0, t1 in zip(times[:-1], times[1:]):
            if self.degrees_of_freedom == 0:
                q, qd, _ = self.kinematics(q + qd * (t1 - t0), t1)
            else:
                def rhs(t, y):
                    return np.concatenate([y[n:], self.accelerations(y[:n], y[n:], t)[0]])
                sol = solve_ivp(rhs, (t0, t1), np.concatenate([q, qd]), method="DOP853", rtol=rtol, atol=atol)
                if not sol.success:
                    raise RuntimeError(f"{self.name}: DOP853 failed at t = {sol.t[-1]}: {sol.message}")
                q, qd = self.project(sol.y[:n, -1], sol.y[n:, -1], t1)
            qs.append(q)
            qds.append(qd)
        return Trajectory(times, np.array(qs), np.array(qds))


# -- reading the file ------------------------------------------------------------------------
def _value(text, params: dict[str, float]) -> float:
    """A number, or an arithmetic expression of the parameters ("L1", "a4 - L4/2")."""
    if isinstance(text, (int, float)):
        return float(text)
    symbols = {name: sympy.Symbol(name) for name in params}
    expr = sympy.sympify(text, locals=symbols)
    return float(expr.subs({symbols[k]: v for k, v in params.items()}))


def read_model(name_or_path: str | Path, overrides: dict[str, float] | None = None) -> ReferenceModel:
    """The mechanism of a shipped name (``fivebar``) or a .toml path; ``overrides`` replace
    parameter values (SI units)."""
    path = Path(name_or_path)
    if path.suffix != ".toml":
        path = MECHANISM_FOLDER / f"{name_or_path}.toml"
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    params = {}
    for key, spec in data["parameters"].items():
        value = float(spec["value"])
        params[key] = math.radians(value) if spec.get("unit") == "deg" else value
    params.update(overrides or {})
    head = data["mechanism"]
    gravity = params[head["gravity"]] if "gravity" in head else 0.0

    bodies = []
    for spec in data["bodies"]:
        mass = _value(spec["mass"], params)
        points = {"centre": np.zeros(2)}
        rotates = spec.get("rotates", True)
        if spec["kind"] == "rod":
            length = _value(spec["length"], params)
            inertia = mass * length**2 / 12.0          # slender uniform rod about its centre
            points["tail"] = np.array([-length / 2, 0.0])
            points["tip"] = np.array([length / 2, 0.0])
        else:
            inertia = _value(spec["inertia"], params) if rotates else 0.0
        for pname, (x, y) in spec.get("points", {}).items():
            points[pname] = np.array([_value(x, params), _value(y, params)])
        guess = (float(spec.get("x", 0.0)), float(spec.get("y", 0.0)), math.radians(spec.get("angle", 0.0)))
        bodies.append(Body(spec["name"], str(spec.get("label", spec["name"])), mass, inertia, rotates, points,
                           guess))
    index = {b.name: k for k, b in enumerate(bodies)}
    ground = {k: np.array([_value(x, params), _value(y, params)])
              for k, (x, y) in data.get("ground", {}).get("points", {}).items()}

    def attachment(text: str) -> Attachment:
        body, point = text.split(".")
        if body == "ground":
            return Attachment(None, ground[point])
        return Attachment(index[body], bodies[index[body]].points[point])

    joints = tuple(Joint(j["name"], j["type"], attachment(j["connects"][0]), attachment(j["connects"][1]),
                         math.radians(j.get("angle", 0.0))) for j in data["joints"])
    joint_index = {j.name: k for k, j in enumerate(joints)}
    drivers = []
    for d in data.get("drivers", []):
        if joints[joint_index[d["joint"]]].type != "revolute":
            raise NotImplementedError(f"{path}: the reference drives revolute joints only ({d['name']})")
        drivers.append(Driver(d["name"], joint_index[d["joint"]], params[d["start"]], params[d["speed"]]))
    start = {}
    for key, spec in data.get("start", {}).items():
        spec = spec if isinstance(spec, dict) else {"value": spec}
        unit = spec.get("unit", "deg" if key.startswith("theta") else None)
        start[key] = math.radians(spec["value"]) if unit == "deg" else float(spec["value"])
    if data.get("loads"):
        raise NotImplementedError(f"{path}: the reference does not read [[loads]]")
    springs = []
    for s in data.get("springs", []):
        if "connects" not in s:
            raise NotImplementedError(f"{path}: the reference reads point-to-point springs only ({s['name']})")
        springs.append(Spring(s["name"], attachment(s["connects"][0]), attachment(s["connects"][1]),
                              _value(s["stiffness"], params), _value(s.get("damping", 0.0), params),
                              _value(s["length"], params), _value(s.get("preload", 0.0), params)))
    friction = []
    for f in data.get("friction", []):
        if joints[joint_index[f["joint"]]].type != "revolute":
            raise NotImplementedError(f"{path}: the reference reads friction at revolute joints only ({f['name']})")
        friction.append(Friction(f["name"], joint_index[f["joint"]], _value(f.get("viscous", 0.0), params),
                                 _value(f.get("coulomb", 0.0), params),
                                 _value(f.get("velocity_scale", 1.0), params)))
    return ReferenceModel(head["name"], params, gravity, tuple(bodies), joints, tuple(drivers), start, springs,
                          friction)

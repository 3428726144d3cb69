"""The constrained equations of motion of any described planar mechanism (sympy, build time).

From a :class:`~fmu_src.mechanism.description.Mechanism`:

- coordinates ``q``: for every body its centre ``(x, y)`` and, if it rotates, its angle
  ``theta`` (counter-clockwise from +x); ``qd = dq/dt``;
- the Lagrangian ``L = T - V`` (the paper's eq. 1) of the bodies, each with its mass at its
  origin and its inertia about it; ``M = d2L/dqd2`` and ``Q = dL/dq - (d2L/dqd dq) qd``
  (eq. 2/10), so that ``M`` is diagonal (centroidal coordinates);
- the holonomic constraints ``Phi(q, t) = 0``, two rows per revolute joint (the two points
  coincide), two per prismatic joint (the point stays on the line; the relative angle is
  fixed at zero, so the slider's frame turns with the guide's, if the sliding body rotates,
else one row), one per driver (the joint coordinate
  equals ``s_ref + v (t - t_ref)``, or the file's function of the parameters and ``t``);
- eq. (11)::

      [[M,     Phi_q^T],   [qdd   ]   [Q    ]
       [Phi_q, 0      ]] . [lambda] = [gamma],   gamma = -(Phi_q qd)_q qd - 2 Phi_qt qd - Phi_tt

  with ``nu = -Phi_t`` on the velocity level (``Phi_q qd = nu``).

Sign convention, stated once for the whole project: ``M qdd + Phi_q^T lambda = Q``, so the
constraint forces on the bodies are ``-Phi_q^T lambda``.  A joint's reaction output
``<joint>_Fx, <joint>_Fy`` is the force (N, global axes) that the joint applies to the body of
its *second* point (when that is the ground: the force on the ground, i.e. minus the force on
the first body).  A prismatic joint whose slider rotates adds
``<joint>_M``, the moment (N.m) it applies to the second body about the sliding point.  A
driver's ``<driver>_torque`` (revolute) or ``<driver>_force`` (prismatic) is what the motor
applies to the second body, ``<driver>_work`` the work it has done since the start (J), so that
``energy - sum(work)`` is conserved.

After the outputs the file selects come, always, the joints' positions a view draws the
mechanism from (``drawing``): ``<joint>_x, <joint>_y`` (m), the joint's second point in the
ground frame, and for a prismatic joint its guide line ``<joint>_gx, <joint>_gy`` (m, its
first point) and ``<joint>_gangle`` (rad).  They are expressions of ``q`` and ``p`` like the
centres' coordinates, so each FMU computes them with its other state outputs.

Nothing here knows a particular mechanism: the four-bar is ``fmu_src/mechanisms/fourbar.toml``.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from .description import RATE_PREFIX, Friction, Input, Joint, Load, Mechanism, MechanismError, PointRef, Spring
from .drawing import joint_columns

__all__ = ["MechanismEquations", "OutputSpec", "derive", "RUNTIME_OUTPUTS"]

#: Outputs computed by the run-time code rather than from an expression of the state.
RUNTIME_OUTPUTS = ("constraint_residual",)


@dataclass(frozen=True)
class OutputSpec:
    """One output variable: its expression in (q, qd, lambda, t, p, d) or, for a driver's
    work, the index of the integrated work (``work``); ``constraint_residual`` has neither."""

    name: str
    unit: str
    description: str
    expression: sp.Expr | None = None
    work: int | None = None
    display_unit: str | None = None


@dataclass(frozen=True)
class MechanismEquations:
    """The symbolic pieces of the DAE of one mechanism (read-only; sympy objects)."""

    mechanism: Mechanism
    coordinates: tuple[str, ...]
    q: sp.Matrix                # n x 1
    qd: sp.Matrix               # n x 1
    t: sp.Symbol
    params: tuple[sp.Symbol, ...]    # the run-time array p: the [parameters] in file order, then the inputs
    inputs: tuple[sp.Symbol, ...]    # the FMI input variables (the end of params), in file order
    drive: tuple[sp.Symbol, ...]     # per driver (s_ref, t_ref, v): the run-time array d
    mass_matrix: sp.Matrix      # n x n, diagonal
    forces: sp.Matrix           # n x 1, Q
    constraints: sp.Matrix      # m x 1, Phi(q, t)
    jacobian: sp.Matrix         # m x n, Phi_q (independent of t)
    nu: sp.Matrix               # m x 1, -Phi_t
    gamma: sp.Matrix            # m x 1
    kinetic_energy: sp.Expr
    potential_energy: sp.Expr
    multipliers: sp.Matrix      # m x 1
    joint_rows: dict[str, tuple[int, ...]]     # joint or driver name -> its rows of Phi
    driver_rows: tuple[int, ...]               # the row of each driver, in driver order
    outputs: tuple[OutputSpec, ...]            # in the FMU's output order
    available: tuple[str, ...]                 # every output name the mechanism offers
    #: A driver input's (u, u_d) and (u_d, u_dd): each input symbol whose time derivative is another
    input_rates: tuple[tuple[sp.Symbol, sp.Symbol], ...] = ()

    def time_partial(self, expr):
        """The partial time derivative of ``expr`` (a matrix or an expression of q, t and the
        inputs; q held): d/dt through t and through each driver input u (u_d, then u_dd)."""
        out = expr.diff(self.t)
        for u, rate in self.input_rates:
            out += expr.diff(u) * rate
        return out

    @property
    def n(self) -> int:
        return self.q.rows

    @property
    def m(self) -> int:
        return self.constraints.rows

    @property
    def independent(self) -> tuple[int, ...]:
        """Indices in q of the coordinates whose start values the file gives."""
        return tuple(self.coordinates.index(c) for c in self.mechanism.independent)


def _rotation(theta) -> sp.Matrix:
    c, s = sp.cos(theta), sp.sin(theta)
    return sp.Matrix([[c, -s], [s, c]])


class _Frames:
    """Global positions of body points as expressions of q and p."""

    def __init__(self, mech: Mechanism, q: dict[str, sp.Symbol], params: dict[str, sp.Symbol]):
        self.mech, self.q, self.params = mech, q, params
        self.bodies = {b.name: b for b in mech.bodies}

    def angle(self, body: str) -> sp.Expr:
        if body == "ground":
            return sp.Integer(0)
        b = self.bodies[body]
        return self.q[f"theta{b.label}"] if b.rotates else sp.Integer(0)

    def point(self, ref: PointRef) -> sp.Matrix:
        if ref.body == "ground":
            return sp.Matrix(self.mech.ground[ref.point])
        b = self.bodies[ref.body]
        local = sp.Matrix(b.points[ref.point])
        return sp.Matrix([self.q[f"x{b.label}"], self.q[f"y{b.label}"]]) + _rotation(self.angle(ref.body)) * local

    def direction(self, body: str, angle: float) -> sp.Matrix:
        """Unit vector of a line at ``angle`` (rad) in ``body``'s frame."""
        return _rotation(self.angle(body)) * sp.Matrix([sp.cos(sp.Float(angle)) if angle else 1,
                                                         sp.sin(sp.Float(angle)) if angle else 0])


def _joint_constraints(joint: Joint, frames: _Frames) -> list[sp.Expr]:
    a, b = frames.point(joint.first), frames.point(joint.second)
    if joint.type == "revolute":
        return [a[0] - b[0], a[1] - b[1]]
    u = frames.direction(joint.first.body, joint.angle)
    normal = sp.Matrix([-u[1], u[0]])
    rows = [((b - a).T * normal)[0]]
    second = frames.bodies[joint.second.body]
    if second.rotates:
        rows.append(frames.angle(joint.second.body) - frames.angle(joint.first.body))
    return rows


def _joint_coordinate(joint: Joint, frames: _Frames) -> sp.Expr:
    """What a driver prescribes: the relative angle (revolute) or the position along the line."""
    if joint.type == "revolute":
        return frames.angle(joint.second.body) - frames.angle(joint.first.body)
    u = frames.direction(joint.first.body, joint.angle)
    return ((frames.point(joint.second) - frames.point(joint.first)).T * u)[0]


_CACHE: dict[int, tuple[Mechanism, "MechanismEquations"]] = {}


def derive(mech: Mechanism) -> MechanismEquations:
    """The DAE of ``mech`` (cached per mechanism object: treat the result as read-only)."""
    hit = _CACHE.get(id(mech))
    if hit is None or hit[0] is not mech:
        hit = _CACHE[id(mech)] = (mech, _derive(mech))
    return hit[1]


def _derive(mech: Mechanism) -> MechanismEquations:
    names = mech.coordinates
    q = sp.Matrix(sp.symbols(" ".join(names), real=True)) if len(names) > 1 else sp.Matrix([sp.Symbol(names[0], real=True)])
    qd = sp.Matrix([sp.Symbol(f"{n}_d", real=True) for n in names])
    qsym = dict(zip(names, q))
    params = {p.name: sp.Symbol(p.name, real=True) for p in mech.parameters}
    t = sp.Symbol("t", real=True)
    frames = _Frames(mech, qsym, params)

    # Lagrangian (eq. 1): each body's mass at its origin, its inertia about it.
    T, V = sp.Integer(0), sp.Integer(0)
    g = params[mech.gravity] if mech.gravity else sp.Integer(0)
    for body in mech.bodies:
        xd, yd = (qd[names.index(f"{c}{body.label}")] for c in ("x", "y"))
        T += sp.Rational(1, 2) * body.mass * (xd**2 + yd**2)
        if body.rotates:
            T += sp.Rational(1, 2) * body.inertia * qd[names.index(f"theta{body.label}")]**2
        V += body.mass * g * qsym[f"y{body.label}"]
    lagrangian = T - V
    dL_dqd = sp.Matrix([sp.diff(lagrangian, s) for s in qd])
    M = sp.simplify(dL_dqd.jacobian(qd))
    Q = sp.simplify(sp.Matrix([sp.diff(lagrangian, s) for s in q]) - dL_dqd.jacobian(q) * qd)
    if not M.is_diagonal():
        raise ValueError("centroidal coordinates give a diagonal mass matrix; this one is not")
    # Force elements: their generalized forces from their virtual work, their potential into V.
    spring_outputs = []
    if mech.springs:
        Q = sp.Matrix(Q)
        for spring in mech.springs:
            element = _spring(spring, frames, q, qd, {j.name: j for j in mech.joints})
            Q += element.forces
            V += element.potential
            spring_outputs.append(element)
    friction_outputs = _friction_terms(mech, frames, q, qd)
    if friction_outputs:
        Q = sp.Matrix(Q)
        for element in friction_outputs:
            Q += element.forces
    load_outputs = []
    if mech.loads:
        Q = sp.Matrix(Q)
        for load in mech.loads:
            element = _load(load, frames, q, qd)
            Q += element.forces
            load_outputs.append(element)
    inputs = {v.name: sp.Symbol(v.name, real=True) for i in mech.inputs for v in i.variables}
    input_outputs = []
    for entry in mech.inputs:
        if entry.kind != "position":
            element = _input(entry, inputs[entry.name], frames, q, qd, {j.name: j for j in mech.joints})
            Q = sp.Matrix(Q) + element.forces
            input_outputs.append(element)

    # Constraints: joints in file order, then drivers.
    rows: list[sp.Expr] = []
    joint_rows: dict[str, tuple[int, ...]] = {}
    for joint in mech.joints:
        new = _joint_constraints(joint, frames)
        joint_rows[joint.name] = tuple(range(len(rows), len(rows) + len(new)))
        rows += new
    drive: list[sp.Symbol] = []
    signals: dict = {}
    driver_rows = []
    joints = {j.name: j for j in mech.joints}
    for driver in mech.drivers:
        s_ref, t_ref, v = sp.symbols(f"{driver.name}_s_ref {driver.name}_t_ref {driver.name}_v", real=True)
        drive += [s_ref, t_ref, v]
        driver_rows.append(len(rows))
        joint_rows[driver.name] = (len(rows),)
        if driver.input is not None:        # u(t) from the inputs: differentiated, then u, u_d, u_dd put in
            prescribed = sp.Function(f"_{driver.input}_of_t", real=True)(t)
            signals[prescribed] = tuple(inputs[n] for n in (driver.input, f"{driver.input}_d", f"{driver.input}_dd"))
        elif driver.position is None:
            prescribed = s_ref + v * (t - t_ref)
        else:
            prescribed = driver.position    # (s_ref, t_ref, v) unused
        rows.append(_joint_coordinate(joints[driver.joint], frames) - prescribed)
    Phi = sp.Matrix(rows)
    Phi_q = Phi.jacobian(q)
    if t in Phi_q.free_symbols:
        raise ValueError("a constraint Jacobian that depends on time is not supported")
    Phi_t = Phi.diff(t)
    nu = -Phi_t
    gamma = -(Phi_q * qd).jacobian(q) * qd - 2 * Phi_t.jacobian(q) * qd - Phi_t.diff(t)
    if signals:     # a driver input's u(t), u'(t), u''(t) are the input variables u, u_d, u_dd
        put = {}
        for function, (u, u_d, u_dd) in signals.items():
            put |= {function.diff(t, 2): u_dd, function.diff(t): u_d}
        Phi, nu, gamma = (x.subs(put).subs({f: u for f, (u, _, _) in signals.items()}) for x in (Phi, nu, gamma))
        Phi_t = -nu
    gamma = gamma.applyfunc(sp.simplify)
    lam = sp.Matrix([sp.Symbol(f"lambda_{k}", real=True) for k in range(Phi.rows)])

    outputs, available = _outputs(mech, names, q, qd, lam, Phi_q, Phi_t, joint_rows, frames, T + V, spring_outputs,
                                  friction_outputs, load_outputs, input_outputs)
    eqs = MechanismEquations(
        mechanism=mech, coordinates=names, q=q, qd=qd, t=t, params=tuple(params.values()) + tuple(inputs.values()),
        inputs=tuple(inputs.values()), drive=tuple(drive),
        mass_matrix=M, forces=Q, constraints=Phi, jacobian=Phi_q, nu=nu, gamma=gamma,
        kinetic_energy=T, potential_energy=V, multipliers=lam, joint_rows=joint_rows,
        driver_rows=tuple(driver_rows), outputs=outputs, available=available,
        input_rates=tuple(pair for u, u_d, u_dd in signals.values() for pair in ((u, u_d), (u_d, u_dd))))
    return eqs


@dataclass(frozen=True)
class _SpringTerms:
    """A spring-damper's pieces: its coordinate s (``length``: the distance l, or the joint's
    relative angle), its rate ds/dt, what it exerts F (``tension``: positive pulling its points
    together, or turning its second body clockwise), potential energy and generalized forces."""

    spring: Spring
    length: sp.Expr
    rate: sp.Expr
    tension: sp.Expr
    potential: sp.Expr
    forces: sp.Matrix          # n x 1


def _spring(spring: Spring, frames: _Frames, q: sp.Matrix, qd: sp.Matrix, joints: dict[str, Joint]
            ) -> _SpringTerms:
    """A spring-damper on a coordinate s: l = |b - a| (point-to-point) or the revolute joint's
    relative angle; F = preload + k (s - s0) + c ds/dt.

    Its virtual work is -F ds, so its generalized forces are Q = -F (ds/dq)^T (for the
    distance, ds/dq = (b - a)^T d(b - a)/dq / l); the conservative part has the potential
    preload s + k (s - s0)^2 / 2 (the damping has none: it dissipates c (ds/dt)^2).  A
    point-to-point spring is not defined where its points meet (l = 0)."""
    if spring.joint is not None:
        coordinate = _joint_coordinate(joints[spring.joint], frames)
        grad = sp.Matrix([coordinate]).jacobian(q)                 # 1 x n: ds/dq
    else:
        d = frames.point(spring.second) - frames.point(spring.first)
        coordinate = sp.sqrt(d[0]**2 + d[1]**2)
        grad = (d.T * d.jacobian(q)) / coordinate
    rate = (grad * qd)[0]
    tension = spring.preload + spring.stiffness * (coordinate - spring.length) + spring.damping * rate
    potential = spring.preload * coordinate + spring.stiffness * (coordinate - spring.length)**2 / 2
    return _SpringTerms(spring, coordinate, rate, tension, potential, -tension * grad.T)


@dataclass(frozen=True)
class _LoadTerms:
    """An applied load's generalized forces and its power Q^T qd."""

    load: Load
    forces: sp.Matrix          # n x 1
    power: sp.Expr


def _load(load: Load, frames: _Frames, q: sp.Matrix, qd: sp.Matrix) -> _LoadTerms:
    """A constant torque tau on a body: virtual work tau dtheta, so Q = tau (dtheta/dq)^T; a
    constant force F at a point p: virtual work F . dp, so Q = (dp/dq)^T F, with F turned by the
    body's angle when it is given in the body's frame.  Its power is Q^T qd."""
    if load.torque is not None:
        grad = sp.Matrix([frames.angle(load.body)]).jacobian(q)
        forces = load.torque * grad.T
    else:
        force = sp.Matrix(load.force)
        if load.frame == "body":
            force = _rotation(frames.angle(load.body)) * force
        forces = frames.point(load.point).jacobian(q).T * force
    forces = forces.applyfunc(sp.simplify)
    return _LoadTerms(load, forces, sp.simplify((forces.T * qd)[0]))


@dataclass(frozen=True)
class _InputTerms:
    """An input torque's or force's generalized forces and its power Q^T qd (u times them)."""

    input: Input
    forces: sp.Matrix          # n x 1
    power: sp.Expr


def _input(entry: Input, u: sp.Symbol, frames: _Frames, q: sp.Matrix, qd: sp.Matrix, joints: dict[str, Joint]
           ) -> _InputTerms:
    """An input u acting like a load (``_load``), through its virtual work: a torque on a body
    u dtheta; at a revolute joint u ds, s the relative angle (on the second body, minus on the
    first); at a prismatic joint u ds, s the position along the line; a force at a point
    u e . dp, e the unit direction (turned with the body in the body frame).  Q = u (ds/dq)^T."""
    if entry.kind == "torque" and entry.body is not None:
        coordinate = frames.angle(entry.body)
        grad = sp.Matrix([coordinate]).jacobian(q).T
    elif entry.joint is not None:
        grad = sp.Matrix([_joint_coordinate(joints[entry.joint], frames)]).jacobian(q).T
    else:
        e = sp.Matrix([sp.Integer(int(v)) if v == int(v) else sp.Float(v) for v in entry.direction])
        if entry.frame == "body":
            e = _rotation(frames.angle(entry.point.body)) * e
        grad = frames.point(entry.point).jacobian(q).T * e
    forces = (u * grad).applyfunc(sp.simplify)
    return _InputTerms(entry, forces, sp.simplify((forces.T * qd)[0]))


@dataclass(frozen=True)
class _FrictionTerms:
    """A joint friction's pieces: the joint's rate v, what it exerts F (opposing v) and its
    generalized forces."""

    friction: Friction
    rate: sp.Expr
    force: sp.Expr
    forces: sp.Matrix          # n x 1


def _friction_terms(mech: Mechanism, frames: _Frames, q: sp.Matrix, qd: sp.Matrix) -> tuple[_FrictionTerms, ...]:
    """Joint friction on the joint's coordinate s (the driver's: relative angle or position
    along the line), v = ds/dt: F = viscous v + coulomb tanh(v / v_s).  Its virtual work is
    -F ds, so Q = -F (ds/dq)^T; it has no potential and dissipates F v >= 0."""
    joints = {j.name: j for j in mech.joints}
    out = []
    for friction in mech.friction:
        grad = sp.Matrix([_joint_coordinate(joints[friction.joint], frames)]).jacobian(q)
        rate = (grad * qd)[0]
        force = friction.viscous * rate + friction.coulomb * sp.tanh(rate / friction.velocity_scale)
        out.append(_FrictionTerms(friction, rate, force, -force * grad.T))
    return tuple(out)


def _friction_outputs(mech: Mechanism, offered: dict, friction: tuple[_FrictionTerms, ...]) -> None:
    """``<name>_torque`` (revolute) or ``<name>_force`` (prismatic) and ``<name>_power``."""
    for element in friction:
        f = element.friction
        kind, unit = ("torque", "N.m") if f.kind == "revolute" else ("force", "N")
        rows = ((kind, unit, f"{kind.capitalize()} of friction {f.name} at joint {f.joint}, positive opposing a "
                             f"positive joint rate (acting on the second body against it) [{unit}]", element.force),
                ("power", "W", f"Power dissipated by friction {f.name} at joint {f.joint} (>= 0) [W]",
                 element.force * element.rate))
        for suffix, unit, text, expr in rows:
            if f"{f.name}_{suffix}" in offered:
                raise MechanismError(f"{mech.source}: friction '{f.name}': its output {f.name}_{suffix!r} would have "
                                     f"the name of another output; rename it")
            offered[f"{f.name}_{suffix}"] = OutputSpec(f"{f.name}_{suffix}", unit, text, expr)


def _outputs(mech, names, q, qd, lam, Phi_q, Phi_t, joint_rows, frames, energy, springs=(), friction=(),
             loads=(), inputs=()):
    """Every output the mechanism offers, then the ones the file selects, in its order."""
    offered: dict[str, OutputSpec] = {}
    for body in mech.bodies:
        for c in body.coordinates:
            i = names.index(c)
            prefix = c[: len(c) - len(body.label)]
            if prefix == "theta":
                offered[c] = OutputSpec(c, "rad", f"{body.name.capitalize()} angle from +x [rad]", q[i],
                                        display_unit="deg")
            else:
                offered[c] = OutputSpec(c, "m", f"{prefix} of the {body.name}'s centre [m]", q[i])
        for c in body.coordinates:
            i = names.index(c)
            prefix = c[: len(c) - len(body.label)]
            rate = RATE_PREFIX[prefix] + body.label
            if prefix == "theta":
                offered[rate] = OutputSpec(rate, "rad/s", f"{body.name.capitalize()} angular velocity [rad/s]", qd[i])
            else:
                offered[rate] = OutputSpec(rate, "m/s", f"{prefix}-velocity of the {body.name}'s centre [m/s]", qd[i])
    offered["energy"] = OutputSpec("energy", "J", "Total mechanical energy T + V, V = 0 at y = 0 [J]" if not springs
                                   else "Total mechanical energy T + V: gravity's (0 at y = 0) and the springs' "
                                        "[J]", energy)
    offered["constraint_residual"] = OutputSpec(
        "constraint_residual", "1", "max(|Phi|, |Phi_q qd - nu|) of the reported state [m, m/s, rad, rad/s]")
    index = {n: k for k, n in enumerate(names)}
    for joint in mech.joints:
        r = list(joint_rows[joint.name])
        forces = -(Phi_q.extract(r, list(range(len(names)))).T * lam.extract(r, [0]))   # on every coordinate
        on_second = joint.second.body != "ground"
        body = frames.bodies[(joint.second if on_second else joint.first).body]
        sign = 1 if on_second else -1
        fx, fy = (sign * forces[index[f"{c}{body.label}"]] for c in ("x", "y"))
        whom = f"the {body.name}" if on_second else f"the ground (minus the force on the {body.name})"
        offered[f"{joint.name}_Fx"] = OutputSpec(f"{joint.name}_Fx", "N", f"x-force of joint {joint.name} on "
                                                 f"{whom} [N]", sp.simplify(fx))
        offered[f"{joint.name}_Fy"] = OutputSpec(f"{joint.name}_Fy", "N", f"y-force of joint {joint.name} on "
                                                 f"{whom} [N]", sp.simplify(fy))
        if joint.type == "prismatic" and body.rotates:
            torque = forces[index[f"theta{body.label}"]]
            arm = frames.point(joint.second) - sp.Matrix([q[index[f"x{body.label}"]], q[index[f"y{body.label}"]]])
            moment = torque - (arm[0] * fy - arm[1] * fx)
            offered[f"{joint.name}_M"] = OutputSpec(f"{joint.name}_M", "N.m", f"moment of joint {joint.name} on "
                                                    f"the {body.name} about the sliding point [N.m]", sp.simplify(moment))
    for element in springs:
        name = element.spring.name
        rows = ((("force", "N", f"Tension of spring {name}, positive pulling its points together [N]"),
                 ("length", "m", f"Length of spring {name} [m]")) if element.spring.joint is None else
                (("torque", "N.m", f"Torque of rotational spring {name} at joint {element.spring.joint}, positive "
                                   f"turning its second body clockwise [N.m]"),
                 ("angle", "rad", f"Relative angle of joint {element.spring.joint} (second body minus first) [rad]")))
        for (suffix, unit, text), expr in zip(rows, (element.tension, element.length)):
            if f"{name}_{suffix}" in offered:
                raise MechanismError(f"{mech.source}: springs '{name}': its output {name}_{suffix!r} would have the "
                                     f"name of another output; rename the spring")
            offered[f"{name}_{suffix}"] = OutputSpec(f"{name}_{suffix}", unit, text, expr,
                                                     display_unit="deg" if suffix == "angle" else None)
    _friction_outputs(mech, offered, friction)
    for element in loads:
        name = f"{element.load.name}_power"
        if name in offered:
            raise MechanismError(f"{mech.source}: loads '{element.load.name}': its output {name!r} would have "
                                 f"the name of another output; rename the load")
        offered[name] = OutputSpec(name, "W", f"Power of load {element.load.name} on the {element.load.body} [W]",
                                   element.power)
    for element in inputs:
        name = f"{element.input.name}_power"
        if name in offered:
            raise MechanismError(f"{mech.source}: inputs '{element.input.name}': its output {name!r} would have "
                                 f"the name of another output; rename the input")
        offered[name] = OutputSpec(name, "W", f"Power of input {element.input.name} [W]", element.power)
    joints = {j.name: j for j in mech.joints}
    for k, driver in enumerate(mech.drivers):
        (row,) = joint_rows[driver.name]
        joint = joints[driver.joint]
        kind, unit = ("torque", "N.m") if joint.type == "revolute" else ("force", "N")
        offered[f"{driver.name}_{kind}"] = OutputSpec(
            f"{driver.name}_{kind}", unit, f"{kind.capitalize()} of driver {driver.name} on the second body of "
            f"joint {joint.name} [{unit}]", -lam[row])
        offered[f"{driver.name}_work"] = OutputSpec(
            f"{driver.name}_work", "J", f"Work done by driver {driver.name} since the start [J]", work=k)
    drawn = _joint_position_outputs(mech, frames, offered)
    available = tuple(offered) + tuple(drawn)
    chosen = mech.outputs or tuple(n for n in offered if not n.startswith(("vx", "vy")))
    listed = [n for n in chosen if n in drawn]
    if listed:
        raise MechanismError(f"{mech.source}: [outputs]: {', '.join(map(repr, listed))}: the joints' positions "
                             f"are always outputs, after those [outputs] lists; remove "
                             f"{'it' if len(listed) == 1 else 'them'} from the list")
    unknown = [n for n in chosen if n not in offered]
    if unknown:
        raise MechanismError(f"{mech.source}: [outputs]: {', '.join(map(repr, unknown))} "
                             f"{'is' if len(unknown) == 1 else 'are'} not an output of this mechanism "
                             f"(available: {', '.join(available)})")
    defined = _expression_outputs(mech, offered, drawn)
    return tuple(offered[n] for n in chosen) + defined + tuple(drawn.values()), available + tuple(
        o.name for o in defined)


def _expression_outputs(mech: Mechanism, offered: dict[str, OutputSpec],
                        drawn: dict[str, OutputSpec]) -> tuple[OutputSpec, ...]:
    """The file's ``[outputs.expressions]``, after the outputs it selects: expressions the loader
    built over the same symbols as q, qd and the parameters.  A name that is already a
    variable's is a MechanismError naming the entry."""
    taken = {p.name: "a parameter" for p in mech.parameters}
    taken |= {s.parameter: "a start-value parameter" for s in mech.start}
    taken |= {name: "a parameter of the integrator" for name in ("rtol", "atol", "integrator", "max_evaluations")}
    taken |= {name: "an output the mechanism offers" for name in offered}
    taken |= {name: "a joint's position output" for name in drawn}
    out = []
    for e in mech.expression_outputs:
        if e.name in taken:
            raise MechanismError(f"{mech.source}: outputs.expressions.{e.name}: has the name of {taken[e.name]}; "
                                 f"choose another name")
        out.append(OutputSpec(e.name, e.unit, e.description, e.expression, display_unit=e.display_unit))
    return tuple(out)


def _point_words(ref: PointRef) -> str:
    return f"{ref.body} {ref.point}"


def _joint_position_outputs(mech: Mechanism, frames: _Frames, offered: dict[str, OutputSpec]) -> dict[str, OutputSpec]:
    """Per joint, in file order, where it is (``J_x J_y``, its second point) and, for a prismatic
    joint, its guide line (``J_gx J_gy``, its first point; ``J_gangle``, the line's direction:
    the joint's angle plus the first body's).  What a view draws the mechanism from
    (``drawing``).  A name that is already a variable's is a MechanismError naming the joint."""
    taken = {p.name: "a parameter" for p in mech.parameters}
    taken |= {s.parameter: "a start-value parameter" for s in mech.start}
    taken |= {name: "a parameter of the integrator" for name in ("rtol", "atol", "integrator")}
    taken |= {name: "an output" for name in offered}
    out: dict[str, OutputSpec] = {}
    for k, joint in enumerate(mech.joints):
        names = joint_columns(joint.name, joint.type)
        clash = [(n, taken[n]) for n in names if n in taken]
        if clash:
            n, what = clash[0]
            raise MechanismError(f"{mech.source}: joints[{k}] '{joint.name}': its position output {n!r} would "
                                 f"have the name of {what} of the mechanism; rename the joint (or the {n!r})")
        where = f"{_point_words(joint.first)} / {_point_words(joint.second)}"
        position = frames.point(joint.second)
        specs = [("x", position[0]), ("y", position[1])]
        if joint.type == "prismatic":
            guide = frames.point(joint.first)
            angle = frames.angle(joint.first.body) + (sp.Float(joint.angle) if joint.angle else 0)
            specs += [("gx", guide[0]), ("gy", guide[1]), ("gangle", angle)]
        for name, (suffix, expr) in zip(names, specs):
            if suffix in ("x", "y"):
                text = f"{suffix} of joint {joint.name} ({where}) [m]"
            elif suffix == "gangle":
                turns = "" if joint.first.body == "ground" or not frames.bodies[joint.first.body].rotates \
                    else f", turning with the {joint.first.body}"
                text = f"Direction of joint {joint.name}'s guide line from +x{turns} [rad]"
            else:
                text = f"{suffix[1]} of joint {joint.name}'s guide point ({_point_words(joint.first)}) [m]"
            unit, display = ("rad", "deg") if suffix == "gangle" else ("m", None)
            out[name] = OutputSpec(name, unit, text, sp.sympify(expr, strict=True), display_unit=display)
    return out

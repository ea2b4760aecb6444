"""MuJoCo model of the vehicle: the bodies behind the lumped parameters of eq. (18), and its MJCF.

The lumped model (eq. 16) has the mass matrix ``diag(m_ch, m_ch, C_ch + C_l + C_r, C_l, C_r, B_w I4)``.
A multibody vehicle has it exactly (at every steering angle) when

* every steering unit (unit body + wheel) has its centre of mass on its steering axis: the unit's
  own centre of mass sits at ``e = -m_w a / m_u`` along the axle (a counterweight opposite the wheel,
  which is at the offset ``a``), so the assembly's mass and yaw inertia do not move with alpha, and
* the front and rear unit of a side have the same yaw inertia: the mirrored coupling
  (``theta_rear = -alpha``) then cancels their cross terms with the chassis yaw, ``J_f omega alpha_dot
  - J_r omega alpha_dot = 0``.

The mapping, per wheel ``i`` (fl, rl, fr, rr) with steering axis ``c_i`` (PLATFORM.md):

* ``m_ch = m_c + sum_i (m_u,i + m_w,i)`` (chassis body, units and wheels: the whole vehicle translates);
* ``J_i = I_u,zz + m_u e_i^2 + I_w,zz + m_w a^2``: yaw inertia of unit i about its steering axis
  (parallel-axis terms of the unit's counterweight and of the wheel at the offset ``a``);
  ``C_l = J_fl + J_rl``, ``C_r = J_fr + J_rr``: the coupling ``theta_rear = -alpha`` reflects the rear
  unit with ratio (-1)^2 = 1;
* ``C_ch = I_c,zz + sum_i [m_u |c_i + e_i n_i|^2 + m_w |c_i + a n_i|^2] - sum_i (m_u e_i^2 + m_w a^2)``
  (``n_i`` the outward axle at alpha = 0): the chassis body plus the units as point masses at their
  steering axes; with balanced units it is ``I_c,zz + sum_i (m_u + m_w) |c_i|^2``;
* ``B_w = I_w,yy + J_armature`` (wheel spin inertia plus the reflected motor inertia ``i_G^2 J_mot``,
  MuJoCo's joint armature);
* viscous and dry friction: ``d_vl = damping_fl + damping_rl``, ``d_cl = frictionloss_fl + frictionloss_rl``
  (the coupled joints turn at equal rates), ``d_vw``, ``d_cw`` the damping and frictionloss of each
  wheel joint. MuJoCo's frictionloss is a dry friction (a constraint that holds the joint below the
  level, slides at it above), not the model's ``d_c tanh(v / epsilon)``.

:func:`vehicle_bodies` goes lumped -> bodies with the split of :class:`BodySplit` (the lumped values
do not fix how mass and inertia divide between chassis, units and wheels; the defaults are stated
there); :func:`lumped_parameters` goes bodies -> lumped, exactly (the yaw terms at alpha = 0, which is
every alpha for balanced units). :func:`mjcf` writes the MJCF of a vehicle.

Payload (issue 31, :mod:`agvdyn.simulation.payload`): the loads on board are one body ``payload``
welded to the chassis (no joint), massless until the first event; after each event it carries the
sums so far ``(m_p, S_x, S_y, J_p)`` (:func:`agvdyn.simulation.mujoco_payload.payload_inertial`). The
MuJoCo plant adds the body when a run has payload events; the MJCF of :func:`mjcf` never has it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from agvdyn.platform import WHEELS, Geometry, Parameters

__all__ = ["BodySplit", "VehicleBodies", "EngineOptions", "vehicle_bodies", "lumped_parameters", "mjcf",
           "body_names", "PAYLOAD_BODY"]

#: Name of the body welded to the chassis that carries the payload (added only to runs with payload events).
PAYLOAD_BODY = "payload"

#: Side sign (+1 left, -1 right) and heading sign (+1 front, -1 rear) in wheel order fl, rl, fr, rr.
_SIDE = (1.0, 1.0, -1.0, -1.0)
_HEADING = (1.0, -1.0, 1.0, -1.0)


@dataclass(frozen=True)
class BodySplit:
    """How the lumped parameters divide between the bodies (the lumped values do not fix it).

    unit_mass_fraction : mass of one steering unit without its wheel, as a fraction of ``m_ch``
        (default 0.03: 25 kg on the prototype).
    wheel_spin_share : share of ``B_w`` that is the wheel's own spin inertia ``m_w r^2 / 2`` (uniform
        cylinder); the rest is the reflected motor inertia (armature). Default 0.3.
    wheel_width : wheel width over ``r`` (default 0.5); enters the wheel's yaw inertia
        ``m_w (3 r^2 + w^2) / 12``.
    chassis_height : height (m) of the box whose shape sets the chassis body's roll and pitch inertia
        (its yaw inertia is what the lumped parameters leave); default 0.3.
    com_height : height (m) of the chassis body's centre of mass above the floor; None = ``r`` (the
        axle height, the height of the chassis frame).
    """

    unit_mass_fraction: float = 0.03
    wheel_spin_share: float = 0.3
    wheel_width: float = 0.5
    chassis_height: float = 0.3
    com_height: float | None = None

    def __post_init__(self) -> None:
        checks = {"unit_mass_fraction": (0.0, 0.2), "wheel_spin_share": (0.0, 1.0), "wheel_width": (0.0, 5.0),
                  "chassis_height": (0.0, 10.0)}
        for key, (low, high) in checks.items():
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and low < v <= high):
                raise ValueError(f"body split {key}={v!r}: expected a number in ({low}, {high}]")
        if self.com_height is not None and not (math.isfinite(self.com_height) and self.com_height > 0):
            raise ValueError(f"body split com_height={self.com_height!r}: expected > 0 m or None")

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True, eq=False)
class VehicleBodies:
    """Masses, inertias and joint properties of the multibody vehicle; per-wheel arrays in the order
    fl, rl, fr, rr. Inertias are principal moments (xx, yy, zz) about each body's centre of mass in
    its body frame (wheel: yy is the spin axis). ``unit_offset`` is the unit's centre of mass along
    the axle from the steering axis, positive outboard (m); the wheel centre is at ``a`` outboard."""

    chassis_mass: float
    chassis_inertia: np.ndarray          # (3,)
    chassis_com_height: float            # m above the chassis frame (which is at the axle height)
    unit_mass: np.ndarray                # (4,)
    unit_offset: np.ndarray              # (4,)
    unit_inertia: np.ndarray             # (4, 3)
    wheel_mass: np.ndarray               # (4,)
    wheel_inertia: np.ndarray            # (4, 3)
    wheel_armature: np.ndarray           # (4,) reflected motor inertia i_G^2 J_mot, kg m^2
    steering_damping: np.ndarray         # (4,) N m s/rad
    steering_frictionloss: np.ndarray    # (4,) N m
    wheel_damping: np.ndarray            # (4,) N m s/rad (wheel side)
    wheel_frictionloss: np.ndarray       # (4,) N m (wheel side)

    def __post_init__(self) -> None:
        shapes = {"chassis_inertia": (3,), "unit_mass": (4,), "unit_offset": (4,), "unit_inertia": (4, 3),
                  "wheel_mass": (4,), "wheel_inertia": (4, 3), "wheel_armature": (4,), "steering_damping": (4,),
                  "steering_frictionloss": (4,), "wheel_damping": (4,), "wheel_frictionloss": (4,)}
        for key, shape in shapes.items():
            v = np.asarray(getattr(self, key), dtype=float)
            if v.shape != shape or not np.all(np.isfinite(v)):
                raise ValueError(f"vehicle bodies {key}={v!r}: expected finite numbers of shape {shape}")
            if key != "unit_offset" and np.any(v < 0):
                raise ValueError(f"vehicle bodies {key}={v.tolist()}: expected values >= 0")
            object.__setattr__(self, key, v)
        if not self.chassis_mass > 0:
            raise ValueError(f"vehicle bodies chassis_mass={self.chassis_mass!r}: expected > 0 kg")
        for key in ("chassis_inertia", *(f"{b}_inertia[{w}]" for b in ("unit", "wheel") for w in WHEELS)):
            if "[" in key:
                name, w = key[:-1].split("[")
                I = getattr(self, name)[WHEELS.index(w)]
            else:
                I = self.chassis_inertia
            if any(I[k] > I[(k + 1) % 3] + I[(k + 2) % 3] + 1e-12 for k in range(3)):
                raise ValueError(f"vehicle bodies {key}={I.tolist()}: principal moments break the triangle "
                                 "inequality (each at most the sum of the other two)")

    def yaw_inertia_about_axis(self, a: float) -> np.ndarray:
        """J_i (4,): yaw inertia of steering unit i (unit body + wheel) about its steering axis, kg m^2."""
        return (self.unit_inertia[:, 2] + self.unit_mass * self.unit_offset ** 2
                + self.wheel_inertia[:, 2] + self.wheel_mass * a ** 2)

    def total_mass(self) -> float:
        return float(self.chassis_mass + self.unit_mass.sum() + self.wheel_mass.sum())

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for f in fields(self):
            v = getattr(self, f.name)
            out[f.name] = v.tolist() if isinstance(v, np.ndarray) else float(v)
        return out


def _chassis_inertia(I_zz: float, geom: Geometry, height: float) -> np.ndarray:
    """Principal moments of the chassis body: yaw ``I_zz``, roll and pitch in the proportions of a
    box of l x b x height (satisfies the triangle inequality)."""
    l2, b2, h2 = geom.l ** 2, geom.b ** 2, height ** 2
    return np.array([I_zz * (b2 + h2) / (l2 + b2), I_zz * (l2 + h2) / (l2 + b2), I_zz])


def vehicle_bodies(geom: Geometry, params: Parameters, split: BodySplit = BodySplit()) -> VehicleBodies:
    """Bodies whose lumped parameters (:func:`lumped_parameters`) are ``params``, with the split ``split``.

    Wheel: a uniform cylinder of radius r and width ``split.wheel_width r`` with spin inertia
    ``split.wheel_spin_share B_w``; armature the rest of ``B_w``. Unit: mass ``split.unit_mass_fraction
    m_ch``, centre of mass at ``-m_w a / m_u`` (balanced), yaw inertia the rest of ``C_l / 2``
    (``C_r / 2``); front and rear alike; friction split equally front and rear.

    Raises
    ------
    ValueError : a body would get a negative mass or inertia (the message names the parameter and the
        share of the split to change).

    Examples
    --------
    >>> from agvdyn.platform import PROTOTYPE, PAPER_PARAMETERS
    >>> b = vehicle_bodies(PROTOTYPE, PAPER_PARAMETERS)
    >>> round(b.total_mass(), 4), round(float(b.wheel_mass[0]), 3)
    (842.0684, 7.26)
    """
    p = params
    r, a = geom.r, geom.a
    for name in ("C_l", "C_r", "m_ch", "C_ch", "B_w", "d_vl", "d_cl", "d_vr", "d_cr", "d_vw", "d_cw"):
        if getattr(p, name) < 0 or (name in ("m_ch", "B_w", "C_l", "C_r") and getattr(p, name) <= 0):
            raise ValueError(f"parameter {name}={getattr(p, name)!r}: a multibody vehicle needs "
                             f"{'> 0' if name in ('m_ch', 'B_w', 'C_l', 'C_r') else '>= 0'}")
    width = split.wheel_width * r
    m_w = 2.0 * split.wheel_spin_share * p.B_w / r ** 2
    I_w = np.array([m_w * (3 * r ** 2 + width ** 2) / 12, m_w * r ** 2 / 2, m_w * (3 * r ** 2 + width ** 2) / 12])
    m_u = split.unit_mass_fraction * p.m_ch
    e = -m_w * a / m_u
    unit_I = []
    for side, C in (("C_l", p.C_l), ("C_r", p.C_r)):
        I_zz = C / 2 - (m_u * e ** 2 + I_w[2] + m_w * a ** 2)
        if I_zz < 0:
            raise ValueError(f"parameter {side}={C!r}: smaller than the wheels' share 2 (I_w,zz + m_w a^2 + m_u e^2) = "
                             f"{C - 2 * I_zz:.6g} kg m^2 of the split; lower wheel_spin_share ({split.wheel_spin_share})")
        unit_I.append(I_zz)
    m_c = p.m_ch - 4 * (m_u + m_w)
    if m_c <= 0:
        raise ValueError(f"parameter m_ch={p.m_ch!r}: not more than the units and wheels (4 x {m_u + m_w:.6g} kg); "
                         f"lower unit_mass_fraction ({split.unit_mass_fraction})")
    corner2 = (geom.l ** 2 + geom.b ** 2) / 4
    I_c = p.C_ch - 4 * (m_u + m_w) * corner2
    if I_c <= 0:
        raise ValueError(f"parameter C_ch={p.C_ch!r}: not more than the units and wheels at the steering axes "
                         f"4 x {m_u + m_w:.6g} kg x {corner2:.6g} m^2; lower unit_mass_fraction or wheel_spin_share")
    unit_inertia = np.array([[I, I, I] for I in (unit_I[0], unit_I[0], unit_I[1], unit_I[1])])
    com = (split.com_height if split.com_height is not None else r) - r
    return VehicleBodies(
        chassis_mass=m_c, chassis_inertia=_chassis_inertia(I_c, geom, split.chassis_height), chassis_com_height=com,
        unit_mass=np.full(4, m_u), unit_offset=np.full(4, e), unit_inertia=unit_inertia,
        wheel_mass=np.full(4, m_w), wheel_inertia=np.tile(I_w, (4, 1)),
        wheel_armature=np.full(4, (1.0 - split.wheel_spin_share) * p.B_w),
        steering_damping=np.array([p.d_vl, p.d_vl, p.d_vr, p.d_vr]) / 2,
        steering_frictionloss=np.array([p.d_cl, p.d_cl, p.d_cr, p.d_cr]) / 2,
        wheel_damping=np.full(4, p.d_vw), wheel_frictionloss=np.full(4, p.d_cw),
    )


def lumped_parameters(geom: Geometry, bodies: VehicleBodies) -> Parameters:
    """The 11 lumped parameters of eq. (18) of a multibody vehicle, exactly (module docstring).

    The yaw terms are those at alpha = 0; they hold at every alpha when each unit is balanced
    (``m_u e + m_w a = 0``). The wheel parameters are the means of the four wheels (equal in a
    vehicle of :func:`vehicle_bodies`).
    """
    b = bodies
    J = b.yaw_inertia_about_axis(geom.a)
    axes = geom.steering_axes
    side = np.array(_SIDE)
    C_total = b.chassis_inertia[2]
    for i in range(4):
        n = np.array([0.0, side[i]])
        C_total += (b.unit_inertia[i, 2] + b.unit_mass[i] * np.sum((axes[i] + b.unit_offset[i] * n) ** 2)
                    + b.wheel_inertia[i, 2] + b.wheel_mass[i] * np.sum((axes[i] + geom.a * n) ** 2))
    C_l, C_r = J[0] + J[1], J[2] + J[3]
    return Parameters(
        C_l=C_l, d_vl=b.steering_damping[0] + b.steering_damping[1],
        d_cl=b.steering_frictionloss[0] + b.steering_frictionloss[1],
        C_r=C_r, d_vr=b.steering_damping[2] + b.steering_damping[3],
        d_cr=b.steering_frictionloss[2] + b.steering_frictionloss[3],
        m_ch=b.total_mass(), C_ch=C_total - C_l - C_r,
        d_vw=float(np.mean(b.wheel_damping)), d_cw=float(np.mean(b.wheel_frictionloss)),
        B_w=float(np.mean(b.wheel_inertia[:, 1] + b.wheel_armature)),
    )


@dataclass(frozen=True)
class EngineOptions:
    """MuJoCo settings of the generated model (not vehicle parameters).

    timestep : s (default 1 ms: two steps per 2 ms sample). friction : tyre-floor friction
    coefficient (sliding; condim 3, no torsional or rolling friction). contact : collision shape
    of the wheels: ``"cylinder"`` (radius r, the wheel's width: MuJoCo puts a contact at each rim
    edge, so turning a standing wheel scrubs) or ``"sphere"`` (radius r at the wheel centre: one
    contact point below the centre, the point contact of the rolling constraints, eq. 1-2).
    impratio, solref, solimp : MuJoCo's contact softness (elliptic friction cones).
    friction_solref : softness of the tyre-floor friction (MuJoCo's ``solreffriction`` of the floor-wheel
        contact pairs; time constant s, damping ratio): the tangential creep of a sticking tyre, about
        1.7 um/s per N with the default (0.1, 1), i.e. a slip stiffness of ~3e5 N at 0.5 m/s (our plant's
        tyres: 3-4e4 N); the normal direction keeps ``solref``. None: the contact's ``solref`` (MuJoCo's
        default; 0.08 um/s per N: a tyre without lateral give scrubs at the friction limit on any toe
        misalignment, and the identification reads the scrub as wheel friction, docs/simulation.md).
    coupling_solref : softness of the steering coupling's joint equality (time constant, damping ratio).
    wheel_radii : the wheels' true radii (4,), m; None = r (the controller and odometry use r).
    """

    timestep: float = 1e-3
    friction: float = 0.8
    contact: str = "sphere"
    impratio: float = 10.0
    solref: tuple[float, float] = (0.004, 1.0)
    solimp: tuple[float, float, float] = (0.95, 0.99, 0.001)
    friction_solref: tuple[float, float] | None = (0.1, 1.0)
    coupling_solref: tuple[float, float] = (0.004, 1.0)
    wheel_radii: tuple[float, float, float, float] | None = None

    def __post_init__(self) -> None:
        if self.contact not in ("cylinder", "sphere"):
            raise ValueError(f"contact={self.contact!r}: expected 'cylinder' or 'sphere'")
        for key in ("timestep", "friction", "impratio"):
            v = getattr(self, key)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"engine option {key}={v!r}: expected a finite number > 0")
        if self.friction_solref is not None and not (len(self.friction_solref) == 2
                                                     and all(math.isfinite(v) and v > 0 for v in self.friction_solref)):
            raise ValueError(f"friction_solref={self.friction_solref!r}: expected (time constant s, damping ratio) > 0 "
                             "or None")
        if self.wheel_radii is not None and (len(self.wheel_radii) != 4 or min(self.wheel_radii) <= 0):
            raise ValueError(f"wheel_radii={self.wheel_radii!r}: expected 4 radii > 0 m")

    def to_dict(self) -> dict[str, Any]:
        return {f.name: (list(v) if isinstance(v := getattr(self, f.name), tuple) else v) for f in fields(self)}


def body_names() -> dict[str, list[str]]:
    """Names of the generated model's elements: bodies, joints, actuators, the floor-wheel contact pairs
    (wheel order fl, rl, fr, rr)."""
    return {"bodies": ["chassis", *(f"unit_{w}" for w in WHEELS), *(f"wheel_{w}" for w in WHEELS)],
            "joints": ["root", *(f"steer_{w}" for w in WHEELS), *(f"wheel_{w}" for w in WHEELS)],
            "actuators": [f"motor_{w}" for w in WHEELS],
            "pairs": [f"tyre_{w}_floor" for w in WHEELS]}


def _v(x) -> str:
    return " ".join(f"{float(v):.17g}" for v in np.atleast_1d(x))


def mjcf(geom: Geometry, bodies: VehicleBodies, options: EngineOptions = EngineOptions(), *,
         name: str | None = None) -> str:
    """MJCF text of the vehicle: chassis on a free joint over a floor plane, four steering units on
    hinges at (+-l/2, +-b/2) (range +-pi/2, the stops), wheels on hinges about the axle at ``a``
    outboard, in frictional contact with the floor (one explicit contact pair per wheel,
    ``tyre_*_floor``, which carries the friction, its softness ``friction_solref`` and the contact's
    ``solref``/``solimp``); the rear unit of each side coupled to the front
    (``theta_rear = -alpha``, a joint equality); joint damping and frictionloss; one motor per wheel
    with gear ``i_G`` (control = motor torque, N m). Geometry ``(l, b, a, r, i_G)`` is also stored as
    the custom numeric ``agvdyn_platform``."""
    o = options
    radii = np.full(4, geom.r) if o.wheel_radii is None else np.asarray(o.wheel_radii, dtype=float)
    width = max(0.2 * geom.r, 0.02)
    solref, solimp = _v(o.solref), _v(o.solimp)
    lines = [
        f'<mujoco model="{name or geom.name}">',
        '  <compiler angle="radian" autolimits="true"/>',
        f'  <option timestep="{o.timestep:.17g}" integrator="implicitfast" cone="elliptic" impratio="{o.impratio:.17g}">',
        '    <flag energy="enable"/>',
        '  </option>',
        '  <custom>',
        f'    <numeric name="agvdyn_platform" data="{_v([geom.l, geom.b, geom.a, geom.r, geom.i_G])}"/>',
        '  </custom>',
        '  <worldbody>',
        f'    <geom name="floor" type="plane" size="0 0 1" friction="{o.friction:.17g} 0 0" condim="3" priority="1"'
        f' solref="{solref}" solimp="{solimp}"/>',
        f'    <body name="chassis" pos="0 0 {geom.r:.17g}">',
        '      <freejoint name="root"/>',
        f'      <inertial pos="0 0 {bodies.chassis_com_height:.17g}" mass="{bodies.chassis_mass:.17g}" '
        f'diaginertia="{_v(bodies.chassis_inertia)}"/>',
        f'      <geom name="chassis_box" type="box" size="{geom.l / 2:.17g} {geom.b / 2 - width:.17g} 0.02" pos="0 0 0.1" '
        'contype="0" conaffinity="0" mass="0"/>',
    ]
    for i, w in enumerate(WHEELS):
        cx, cy = geom.steering_axes[i]
        s = _SIDE[i]
        lo, hi = -math.pi / 2, math.pi / 2
        r_i = radii[i]
        lines += [
            f'      <body name="unit_{w}" pos="{cx:.17g} {cy:.17g} 0">',
            f'        <joint name="steer_{w}" type="hinge" axis="0 0 1" range="{lo:.17g} {hi:.17g}" '
            f'damping="{bodies.steering_damping[i]:.17g}" frictionloss="{bodies.steering_frictionloss[i]:.17g}"/>',
            f'        <inertial pos="0 {s * bodies.unit_offset[i]:.17g} 0" mass="{bodies.unit_mass[i]:.17g}" '
            f'diaginertia="{_v(bodies.unit_inertia[i])}"/>',
            f'        <geom name="strut_{w}" type="capsule" fromto="0 0 0.12 0 {s * geom.a:.17g} 0" size="0.01" '
            'contype="0" conaffinity="0" mass="0"/>',
            # the wheel centre is r_i above the floor: the chassis frame is at the nominal r
            f'        <body name="wheel_{w}" pos="0 {s * geom.a:.17g} {r_i - geom.r:.17g}">',
            f'          <joint name="wheel_{w}" type="hinge" axis="0 1 0" damping="{bodies.wheel_damping[i]:.17g}" '
            f'frictionloss="{bodies.wheel_frictionloss[i]:.17g}" armature="{bodies.wheel_armature[i]:.17g}"/>',
            f'          <inertial pos="0 0 0" mass="{bodies.wheel_mass[i]:.17g}" diaginertia="{_v(bodies.wheel_inertia[i])}"/>',
        ]
        hidden = ' rgba="0 0 0 0"' if o.contact == "sphere" else ""
        if o.contact == "cylinder":
            shape = f'type="cylinder" size="{r_i:.17g} {width / 2:.17g}" zaxis="0 1 0"'
        else:
            shape = f'type="sphere" size="{r_i:.17g}"'
            lines.append(f'          <geom name="tyre_{w}" type="cylinder" size="{r_i:.17g} {width / 2:.17g}" '
                         'zaxis="0 1 0" contype="0" conaffinity="0" mass="0"/>')
        lines += [
            # contacts with the floor come from the pairs below (contype/conaffinity 0: no other contacts)
            f'          <geom name="contact_{w}" {shape} friction="{o.friction:.17g} 0 0" condim="3" priority="2" '
            f'solref="{solref}" solimp="{solimp}" contype="0" conaffinity="0" mass="0"{hidden}/>',
            '        </body>',
            '      </body>',
        ]
    lines += ['    </body>', '  </worldbody>', '  <contact>']
    # pair friction: two sliding (condim 3 uses these), torsional, two rolling (unused with condim 3)
    soft = "0 0" if o.friction_solref is None else _v(o.friction_solref)  # "0 0": the pair's solref
    for w in WHEELS:
        lines.append(f'    <pair name="tyre_{w}_floor" geom1="floor" geom2="contact_{w}" condim="3" '
                     f'friction="{o.friction:.17g} {o.friction:.17g} 0.005 0.0001 0.0001" solref="{solref}" '
                     f'solimp="{solimp}" solreffriction="{soft}"/>')
    lines += ['  </contact>', '  <equality>']
    for front, rear in (("fl", "rl"), ("fr", "rr")):
        lines.append(f'    <joint name="coupling_{front[1]}" joint1="steer_{rear}" joint2="steer_{front}" '
                     f'polycoef="0 -1 0 0 0" solref="{_v(o.coupling_solref)}"/>')
    lines += ['  </equality>', '  <actuator>']
    for w in WHEELS:
        lines.append(f'    <motor name="motor_{w}" joint="wheel_{w}" gear="{geom.i_G:.17g}"/>')
    lines += ['  </actuator>', '</mujoco>', '']
    return "\n".join(lines)
